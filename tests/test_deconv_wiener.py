"""Wiener deconvolution: inversion, dtype policy, padding, regularisers, stress cases."""

import numpy as np
import pytest
from scipy.signal import fftconvolve
from skimage import data, transform

from mitsweep.deconv.wiener import estimate_nsr, kernel_spectrum, regulariser, wiener_deconvolve


def gaussian_psf(sigma, size=15):
    c = size // 2
    y, x = np.mgrid[-c:c + 1, -c:c + 1]
    k = np.exp(-0.5 * (x * x + y * y) / sigma ** 2)
    return k / k.sum()


def blur_symmetric(x, k):
    """Blur with the symmetric boundary that wiener_deconvolve assumes."""
    p = k.shape[0]
    xp = np.pad(x, [(p, p), (p, p)] + [(0, 0)] * (x.ndim - 2), mode="symmetric")
    if x.ndim == 3:
        y = np.stack([fftconvolve(xp[..., c], k, mode="same") for c in range(x.shape[2])], -1)
    else:
        y = fftconvolve(xp, k, mode="same")
    return y[p:-p, p:-p]


def psnr(a, b):
    return 10 * np.log10(1.0 / np.mean((a - b) ** 2))


@pytest.fixture(scope="module")
def camera():
    return transform.resize(data.camera() / 255.0, (128, 128), anti_aliasing=True)


# Measured gains (noiseless, nsr 1e-6): sigma 1 px: 25-27 dB; sigma 2 px: 6.8-7.0 dB
# (a 2 px Gaussian leaves |H|^2 < 1e-6 beyond ~0.2 cycles/px: that content is gone).
# The thresholds sit a few dB below, and far above what a flipped kernel, a missing
# normalisation or a circular boundary give (those lose the gain entirely).
@pytest.mark.parametrize("sigma,min_gain_db", [(1.0, 20.0), (2.0, 4.0)])
@pytest.mark.parametrize("prior", ["constant", "natural"])
def test_wiener_restores_gaussian_blur(camera, sigma, min_gain_db, prior):
    y = blur_symmetric(camera, gaussian_psf(sigma))
    x = wiener_deconvolve(y, gaussian_psf(sigma), nsr=1e-6, prior=prior)
    assert psnr(x, camera) > psnr(y, camera) + min_gain_db


def test_shifted_kernel_is_undone_with_its_phase(camera):
    k = np.zeros((9, 9))
    k[4, 7] = 1.0                     # a pure shift by 3 px: |H| = 1, all in the phase
    y = blur_symmetric(camera, k)
    x = wiener_deconvolve(y, k, nsr=1e-9)
    inner = (slice(8, -8), slice(8, -8))
    # scikit-image's wiener drops the imaginary part and cannot undo this
    np.testing.assert_allclose(x[inner], camera[inner], atol=1e-6)


def test_delta_kernel_without_regulariser_is_identity(camera):
    delta = np.zeros((7, 7))
    delta[3, 3] = 1
    x = wiener_deconvolve(camera, delta, nsr=0.0)
    np.testing.assert_allclose(x, camera, atol=1e-12)  # float64 FFT round-off ~1e-16


@pytest.mark.parametrize("dtype,expected", [(np.float32, np.float32), (np.float64, np.float64),
                                            (np.uint8, np.float64), (np.int32, np.float64)])
def test_dtype_policy(camera, dtype, expected):
    img = (camera * 200).astype(dtype)
    out = wiener_deconvolve(img, gaussian_psf(1.0), nsr=1e-3)
    assert out.dtype == expected
    assert out.shape == img.shape


def test_float32_agrees_with_float64(camera):
    k = gaussian_psf(1.5)
    y = blur_symmetric(camera, k)
    a = wiener_deconvolve(y.astype(np.float32), k, nsr=1e-4)
    b = wiener_deconvolve(y, k, nsr=1e-4)
    # float32 FFTs carry ~1e-7 relative error amplified by at most 1/(2 sqrt(nsr)) = 50
    np.testing.assert_allclose(a, b, atol=5e-5)


def test_colour_image_is_restored_channel_by_channel():
    img = transform.resize(data.astronaut() / 255.0, (96, 96), anti_aliasing=True)
    k = gaussian_psf(1.5)
    y = blur_symmetric(img, k)
    out = wiener_deconvolve(y, k, nsr=1e-4)
    for c in range(3):
        np.testing.assert_allclose(out[..., c], wiener_deconvolve(y[..., c], k, nsr=1e-4),
                                   atol=1e-12)


def test_no_clipping_of_out_of_range_values(camera):
    img = 4 * camera - 1.5                      # values in [-1.5, 2.5]
    delta = np.zeros((5, 5))
    delta[2, 2] = 1
    out = wiener_deconvolve(img, delta, nsr=0.0)
    assert out.min() < -1.4 and out.max() > 2.4


def test_padding_prevents_circular_wrap_around():
    img = np.zeros((96, 96))
    img[:, :8] = 1.0                            # a bright strip on the left border only
    k = gaussian_psf(2.5, size=21)
    y = blur_symmetric(img, k)
    right = (slice(None), slice(-10, None))
    padded = wiener_deconvolve(y, k, nsr=1e-4)
    wrapped = wiener_deconvolve(y, k, nsr=1e-4, pad=0, pad_mode="wrap")
    # the right border is black: with padding it stays black to 1e-3; without padding
    # the filter smears the strip across the wrap (measured > 0.05)
    assert np.abs(padded[right]).max() < 1e-3
    assert np.abs(wrapped[right]).max() > 1e-2


N_PAD = 128   # upper bound of the padded FFT size of a 64 px image with a 15 px kernel


def _two_point(size=15, sep=6):
    k = np.zeros((size, size))
    k[size // 2, size // 2 - sep // 2] = k[size // 2, size // 2 + sep // 2] = 0.5
    return k   # its spectrum cos(pi f sep) has exact zeros


@pytest.mark.parametrize("kernel", ["box", "two_point"])
@pytest.mark.parametrize("scene", ["black", "saturated", "random"])
@pytest.mark.parametrize("nsr", [0.0, 1e-6, 1e-2])
@pytest.mark.parametrize("prior", ["constant", "natural"])
def test_stable_for_kernels_with_spectral_zeros(kernel, scene, nsr, prior):
    k = np.ones((7, 7)) / 49 if kernel == "box" else _two_point()
    rng = np.random.default_rng(3)
    img = {"black": np.zeros((64, 64)), "saturated": np.ones((64, 64)),
           "random": rng.random((64, 64))}[scene]
    y = blur_symmetric(img, k)
    out = wiener_deconvolve(y, k, nsr=nsr, prior=prior)
    assert np.all(np.isfinite(out))
    if scene == "black":
        assert np.abs(out).max() < 1e-12
    elif scene == "saturated":
        # DC passes exactly (both priors exempt it) and a constant has no other content
        np.testing.assert_allclose(out, 1.0, atol=1e-9)
    elif nsr > 0:
        # the Wiener gain is bounded by 1/(2 sqrt(R)); energy can grow at most that much
        # (for the natural prior the smallest R, at the lowest non-zero frequency 1/N)
        from mitsweep.deconv.wiener import natural_prior_scale
        r_min = nsr * (1 if prior == "constant" else natural_prior_scale(64) / N_PAD ** 2)
        gain = 1 / (2 * np.sqrt(r_min))
        assert np.linalg.norm(out) <= max(1.0, gain) * np.linalg.norm(y) * 1.01


def test_kernel_spectrum_is_unit_dc_and_zero_phase_for_symmetric_kernel():
    H = kernel_spectrum(gaussian_psf(2.0), (64, 64))
    assert H[0, 0] == pytest.approx(1.0, abs=1e-12)
    assert np.abs(H.imag).max() < 1e-12        # a centred symmetric kernel has no phase


def test_regulariser_priors():
    R = regulariser((64, 64), 1e-2, "constant")
    assert R[0, 0] == 0 and np.all(R.ravel()[1:] == 1e-2)
    Rn = regulariser((256, 256), 1e-2, "natural")
    assert Rn[0, 0] == 0
    # a 1/|f|^2 spectrum from 1/256 to 1/2 cycles/px holding the variance: at f the
    # NSR is nsr * 2 pi ln(128) |f|^2 (regulariser docstring)
    assert Rn[0, 128] == pytest.approx(1e-2 * 2 * np.pi * np.log(128) * 0.25, rel=1e-6)
    assert Rn[3, 4] == pytest.approx(1e-2 * 2 * np.pi * np.log(128) * 25 / 256 ** 2, rel=1e-6)
    with pytest.raises(ValueError, match="prior"):
        regulariser((8, 8), 1e-2, "laplacian")


@pytest.mark.parametrize("sigma_noise", [0.03, 0.05])
def test_estimate_nsr_matches_added_noise(sigma_noise):
    clean = data.camera() / 255.0
    rng = np.random.default_rng(1)
    noisy = clean + rng.normal(0, sigma_noise, clean.shape)
    true = sigma_noise ** 2 / clean.var()
    # fine texture (the grass) leaks into the finest Haar band and biases sigma up
    # (sigma 0.005 measured on the clean image): the estimate errs on the safe side,
    # measured 1.2-1.4 x the true NSR here; more than 1.6 x or less than 0.9 x is wrong
    ratio = estimate_nsr(noisy) / true
    assert 0.9 < ratio < 1.6


def test_estimate_nsr_of_noiseless_and_constant_images_is_the_floor(camera):
    from mitsweep.deconv.wiener import DEFAULT_NSR_FLOOR
    assert estimate_nsr(np.ones((32, 32))) == DEFAULT_NSR_FLOOR
    assert DEFAULT_NSR_FLOOR <= estimate_nsr(camera) < 1e-2


@pytest.mark.parametrize("bad,match", [(np.zeros((4, 4, 4, 4)), "image must be"),
                                       (np.full((16, 16), np.nan), "NaN")])
def test_bad_images_are_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        wiener_deconvolve(bad, gaussian_psf(1.0), nsr=1e-3)


def test_bad_psf_is_refused(camera):
    with pytest.raises(ValueError, match="psf"):
        wiener_deconvolve(camera, np.ones(5), nsr=1e-3)
    with pytest.raises(ValueError, match="positive"):
        wiener_deconvolve(camera, np.zeros((5, 5)), nsr=1e-3)
