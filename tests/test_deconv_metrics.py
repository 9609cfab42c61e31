"""PSNR / SSIM inside masks, per radius and per depth band."""

import math

import numpy as np
import pytest
from skimage import data, transform
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from mitsweep.deconv.metrics import (WANG_SSIM, disk_mask, per_depth_band, per_radius, psnr,
                                     radial_bins, ssim)


@pytest.fixture(scope="module")
def pair():
    ref = transform.resize(data.camera() / 255.0, (96, 96), anti_aliasing=True)
    rng = np.random.default_rng(0)
    return ref + rng.normal(0, 0.02, ref.shape), ref


def test_psnr_whole_image_matches_scikit_image(pair):
    img, ref = pair
    assert psnr(img, ref) == pytest.approx(peak_signal_noise_ratio(ref, img, data_range=1.0),
                                           rel=1e-12)


def test_psnr_ignores_pixels_outside_the_mask(pair):
    img, ref = pair
    m = disk_mask(ref.shape, 30)
    spoiled = img.copy()
    spoiled[~m] = 100.0
    assert psnr(spoiled, ref, mask=m) == pytest.approx(psnr(img, ref, mask=m), rel=1e-12)
    assert psnr(ref, ref) == math.inf
    assert math.isnan(psnr(img, ref, mask=np.zeros(ref.shape, bool)))


def test_ssim_uses_wang_settings_and_matches_scikit_image_on_its_crop(pair):
    img, ref = pair
    # skimage averages its SSIM map over the image minus a border of (win - 1) / 2;
    # with Gaussian weights sigma 1.5 the window is 11 px, the border 5 px
    crop = np.zeros(ref.shape, bool)
    crop[5:-5, 5:-5] = True
    expect = structural_similarity(ref, img, data_range=1.0, **WANG_SSIM)
    assert ssim(img, ref, mask=crop) == pytest.approx(expect, rel=1e-9)
    assert WANG_SSIM == dict(gaussian_weights=True, sigma=1.5, K1=0.01, K2=0.03,
                             use_sample_covariance=False)


def test_colour_ssim_is_the_channel_mean(pair):
    img, ref = pair
    rgb_i, rgb_r = np.stack([img, ref, img], -1), np.stack([ref, ref, ref], -1)
    assert ssim(rgb_i, rgb_r) == pytest.approx((2 * ssim(img, ref) + 1.0) / 3, rel=1e-9)


def test_per_radius_bins_partition_the_disk(pair):
    img, ref = pair
    edges = np.array([0, 10, 20, 30, 40])
    res = per_radius(img, ref, edges)
    assert res["pixels"].sum() == disk_mask(ref.shape, 40 - 1e-9).sum() - \
        np.sum(np.isclose(np.hypot(*(np.mgrid[0:96, 0:96] - 47.5)), 40))
    np.testing.assert_allclose(res["radius_px"], [5, 15, 25, 35])
    # noise is uniform: each ring's PSNR is near the whole disk's (within the
    # ~ 2/sqrt(pixels) relative scatter of the MSE, < 1 dB for these rings)
    whole = psnr(img, ref, mask=disk_mask(ref.shape, 39.9))
    assert np.all(np.abs(res["psnr"] - whole) < 1.0)


def test_per_radius_sees_where_the_error_is(pair):
    _, ref = pair
    img = ref.copy()
    labels = radial_bins(ref.shape, [0, 20, 45])
    img[labels == 1] += 0.1                      # error only in the outer ring
    res = per_radius(img, ref, [0, 20, 45])
    assert res["psnr"][0] == math.inf and res["psnr"][1] == pytest.approx(20.0, abs=1e-9)


def test_per_depth_band(pair):
    img, ref = pair
    depth = np.full(ref.shape, 400.0)
    depth[:, 48:] = 5000.0
    depth[0, 95] = np.inf                        # a pixel with no hit (right half)
    res = per_depth_band(img, ref, depth, [300, 1000, np.inf])
    assert res["pixels"].tolist() == [96 * 48, 96 * 48 - 1]
    left = np.zeros(ref.shape, bool)
    left[:, :48] = True
    assert res["psnr"][0] == pytest.approx(psnr(img, ref, mask=left), rel=1e-12)


@pytest.mark.parametrize("bad", [dict(edges=[100]), dict(edges=[5, 1])])
def test_bad_depth_edges_are_refused(pair, bad):
    img, ref = pair
    with pytest.raises(ValueError, match="edges"):
        per_depth_band(img, ref, np.ones(ref.shape), **bad)


def test_shape_mismatch_is_refused(pair):
    img, ref = pair
    with pytest.raises(ValueError, match="differ"):
        psnr(img[:-1], ref)
