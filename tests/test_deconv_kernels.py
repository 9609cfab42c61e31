"""Choosing and checking a bank's kernels for deconvolution."""

import numpy as np
import pytest

from mitsweep.deconv.kernels import check_bank_matches, optical_center, select_depth
from mitsweep.io.bank import BankError, IPSFBank


def bank_with_depths(depths, K=5, resolution=(64, 48)):
    n = len(depths)
    k = np.zeros((n, 2, K, K), np.float32)
    for d in range(n):
        k[d, :, K // 2, K // 2] = d + 1.0          # depth index encoded in the value
        k[d, :, 0, 0] = 1.0
    radii = np.array([0.0, 0.1])
    return IPSFBank(kernels=k, points_uv=np.stack([radii, 0 * radii], 1),
                    depths=np.asarray(depths, float), pixel_pitch=0.01,
                    reference_sensor_distance=30.0, kind="radial", radii=radii,
                    metadata={"setup": {"sensor": {"resolution": list(resolution)}}})


@pytest.mark.parametrize("depth,expected_index", [(None, 1), (500.0, 1), (450.0, 1),
                                                  (1e9, 3), (300.0, 0), (5000.0, 2)])
def test_select_depth_picks_nearest_in_inverse_depth(depth, expected_index):
    bank = bank_with_depths([300.0, 500.0, 5000.0, np.inf])
    k = select_depth(bank, depth)
    c = k.shape[-1] // 2
    # kernels come back normalised: centre value (index+1) / (index+2)
    i = expected_index
    assert k[0, c, c] == pytest.approx((i + 1) / (i + 2))
    np.testing.assert_allclose(k.sum(axis=(-2, -1)), 1.0)


def test_select_depth_mean_averages_normalised_kernels():
    bank = bank_with_depths([300.0, 500.0])
    k = select_depth(bank, "mean")
    np.testing.assert_allclose(k.sum(axis=(-2, -1)), 1.0)
    c = k.shape[-1] // 2
    assert k[0, c, c] == pytest.approx((1 + 2) / (2 + 3))   # (1 + 2) / (2 + 3) of the mass


@pytest.mark.parametrize("bad", ["near", -5.0, 0.0])
def test_select_depth_rejects_bad_values(bad):
    with pytest.raises(ValueError, match="depth"):
        select_depth(bank_with_depths([500.0]), bad)


def test_check_bank_matches():
    bank = bank_with_depths([500.0], resolution=(64, 48))
    check_bank_matches(bank, (48, 64))
    check_bank_matches(bank, (48, 64, 3), pixel_pitch=0.01)
    with pytest.raises(BankError, match="64x48 sensor"):
        check_bank_matches(bank, (64, 48))
    with pytest.raises(BankError, match="pixel pitch"):
        check_bank_matches(bank, (48, 64), pixel_pitch=0.012)
    with pytest.raises(BankError, match=r"\(H, W\)"):
        check_bank_matches(bank, (48,))


def test_optical_center_is_the_image_centre_between_pixels():
    assert optical_center((48, 64)) == (23.5, 31.5)
    assert optical_center((5, 5, 3)) == (2.0, 2.0)
