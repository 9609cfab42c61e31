"""Wiener's NSR from what is known (mitsweep.deconv.weights): the noise variance of a
sensor model against its own simulation, the least-error NSR against the Wiener NSR of a
signal whose spectrum is known, and the chosen NSR against the oracle's on an
independent spatially varying blur; the dataset's restorations use it."""

import math

import numpy as np
import pytest
import scipy.fft as sfft

from mitsweep.deconv import SensorNoise, polar_deconvolve
from mitsweep.deconv.synthetic import synthetic_grid_bank, synthetic_radial_bank
from mitsweep.deconv.weight_bench import independent_blur_problem, weight_rows
from mitsweep.deconv.weights import (blind_nsr, kernel_shares, model_nsr, noise_variance,
                                     ring_spectrum, spectrum_window, wiener_risk)
from mitsweep.deconv.wiener import natural_prior_scale

N = 256


def power_law_image(n: int, A: float, seed: int) -> np.ndarray:
    """A Gaussian image of power spectrum exactly A / |f|² (cycles/pixel, DC 0)."""
    rng = np.random.default_rng(seed)
    f = sfft.fftfreq(n)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    amp = np.where(f2 > 0, np.sqrt(A / np.where(f2 > 0, f2, 1.0)), 0.0)
    return np.real(sfft.ifft2(sfft.fft2(rng.standard_normal((n, n))) * amp))


def delta_bank(n: int):
    """A radial bank of identity kernels: no blur."""
    return synthetic_radial_bank((n, n), size=3, n_radii=3, core=1e-3, radial=0.0,
                                 tangential=0.0)


def test_sensor_noise_variance_is_the_models_at_the_mean_exposure():
    """Shot + read + ADC noise is affine in the exposure, so the mean variance of an
    image's pixels is the variance at its mean; checked against the model's own
    simulation (200 000 pixels: the sample variance is within 1 % at 4.5 σ)."""
    noise = SensorNoise(illuminance_lux=2.0, exposure_s=0.6, f_number=2.8,
                        pixel_pitch=0.0064)
    level = 0.37
    x = np.tile(np.array([0.1, 0.3, 0.9, 0.5]), (500, 100))    # mean 0.45
    expected = level ** 2 * float(noise.variance(0.45))
    assert noise_variance(level * x, noise, level=level) == pytest.approx(expected, rel=1e-12)
    residual = level * (noise.apply(x, rng=0) - x)
    assert np.var(residual) == pytest.approx(expected, rel=0.01)
    # a given σ, and a mask that picks the bright quarter
    assert noise_variance(x, 0.02) == pytest.approx(4e-4)
    bright = x > 0.8
    assert noise_variance(level * x, noise, level=level, mask=bright) == pytest.approx(
        level ** 2 * float(noise.variance(0.9)), rel=1e-12)


@pytest.mark.parametrize("sigma", [0.03, 0.1])
def test_least_error_nsr_is_the_wiener_nsr_of_a_known_spectrum(sigma):
    """For a sharp image of spectrum A/|f|² and white noise σ², with no blur, the
    natural-prior Wiener filter with NSR σ² / (2π A ln(n/2)) is the exact Wiener filter
    (wiener.regulariser), so the least-error NSR the rule finds from the image alone
    must be it. Tolerance 20 %: the spectrum is read off one periodogram (48 rings of
    ~2000 coefficients each, ~2 % each) and the risk is flat near its minimum."""
    A = 1e-3
    x = power_law_image(N, A, seed=1)
    y = x + np.random.default_rng(2).normal(0.0, sigma, x.shape)
    exact = sigma ** 2 / (A * natural_prior_scale(N))
    found = model_nsr(y, delta_bank(N), sigma, unexplained=False)
    assert found == pytest.approx(exact, rel=0.2)
    # with a flat signal spectrum (white signal) the least-error natural-prior NSR is
    # another one: the rule reads the spectrum, it does not assume it
    white = np.random.default_rng(3).normal(0.0, float(np.std(x)), x.shape)
    nsr_white, _ = wiener_risk(white + (y - x), delta_bank(N), sigma ** 2)
    assert not nsr_white == pytest.approx(exact, rel=0.5)


def test_kernel_shares_follow_the_pixels_radii():
    bank = synthetic_radial_bank((64, 64), size=5, n_radii=3, r_max_px=30.0)
    w = kernel_shares(bank, (64, 64))
    assert w.sum() == pytest.approx(1.0) and np.all(w > 0)
    inner = np.zeros((64, 64), bool)
    inner[30:34, 30:34] = True                   # within 2.2 px of the axis
    w_in = kernel_shares(bank, (64, 64), mask=inner)
    assert w_in[0] > 0.9 and w_in[2] == 0


@pytest.fixture(scope="module")
def blur_case():
    return independent_blur_problem(N, 0.005)


def test_model_and_blind_nsr_are_within_0p3_db_of_the_oracle(blur_case):
    """The issue's bar on an independent spatially varying blur (a 49 × 49 product
    convolution, restored with a 19-radius polar bank), 256 px, σ = 0.005: the
    noise-model NSR and the blind one lose < 0.3 dB against the best NSR by search,
    where the former estimate (σ² over the image's variance) lost 0.81 dB when this
    test was written (asserted only to be worse than the new rule)."""
    p = blur_case
    y, bank, mask = p["blurred"], p["bank"], p["mask"]
    from mitsweep.deconv.wiener import estimate_nsr

    rows = weight_rows(y, p["sharp"], lambda x, w: polar_deconvolve(x, bank, nsr=w),
                       {"model": model_nsr(y, bank, p["sigma"], mask=mask),
                        "blind": blind_nsr(y, bank, mask=mask),
                        "before": estimate_nsr(y)}, mask=mask)
    assert rows["model"]["loss_db"] < 0.3
    assert rows["blind"]["loss_db"] < 0.3
    assert rows["before"]["loss_db"] > rows["model"]["loss_db"]
    assert rows["model"]["loss_db"] > -0.05          # the oracle is the best (its tolerance)


def test_model_nsr_refuses_what_it_cannot_use(blur_case):
    y, bank = blur_case["blurred"], blur_case["bank"]
    with pytest.raises(ValueError, match="noise must be a SensorNoise"):
        model_nsr(y, bank, "loud")
    with pytest.raises(ValueError, match="mask selects no pixel"):
        model_nsr(y, bank, 0.01, mask=np.zeros(y.shape, bool))
    with pytest.raises(ValueError, match="noise sigma must be"):
        model_nsr(y, bank, -1.0)
    assert math.isfinite(model_nsr(np.zeros_like(y), bank, 0.01, unexplained=False))


def disk_mask(n: int, radius: float) -> np.ndarray:
    yy, xx = np.mgrid[:n, :n]
    return np.hypot(yy - n / 2, xx - n / 2) < radius


def test_a_window_reads_white_noise_inside_it_whatever_lies_outside():
    """White noise of σ = 0.1 inside a disk and a bright, sharp checkerboard outside:
    through the disk's taper every ring reads σ² (within the periodogram's own scatter,
    ±10-20 % per ring here), where the frame's spectrum is the checkerboard's."""
    n = 256
    rng = np.random.default_rng(3)
    mask = disk_mask(n, 90)
    yy, xx = np.mgrid[:n, :n]
    board = 5.0 * (((yy // 4) + (xx // 4)) % 2)
    img = np.where(mask, 0.1 * rng.standard_normal((n, n)), board)
    f, p = ring_spectrum(img, window=spectrum_window(mask))
    ok = (f > 0.1) & (f < 0.5)             # rings of a few hundred independent values
    np.testing.assert_allclose(p[ok], 0.01, rtol=0.25)
    # ~20 rings of a few hundred values each: their mean scatters by ~2 %
    assert np.mean(p[ok]) == pytest.approx(0.01, rel=0.05)
    _, p_frame = ring_spectrum(img)
    assert p_frame[ok].max() > 10 * 0.01       # the board's harmonics: ~1e4 times σ²
    with pytest.raises(ValueError, match="window must be"):
        ring_spectrum(img, window=-np.ones((n, n)))
    with pytest.raises(ValueError, match="window must be"):
        ring_spectrum(img, window=np.ones((n, n - 1)))


def test_the_mirrors_spectrum_ignores_what_lies_outside_the_mirror(blur_case):
    """With the noise known (σ, nothing estimated from the image), the NSR of
    ``spectrum="mirror"`` depends on the mirror's pixels only; the frame's rule
    changes with the content outside."""
    p = blur_case
    y, bank, mask = p["blurred"], p["bank"], p["mask"]
    rng = np.random.default_rng(0)
    other = np.where(mask, y, rng.uniform(0, 1, y.shape))
    kw = dict(mask=mask, unexplained=False)
    assert model_nsr(other, bank, p["sigma"], spectrum="mirror", **kw) == pytest.approx(
        model_nsr(y, bank, p["sigma"], spectrum="mirror", **kw), rel=1e-9)
    frame_a = model_nsr(y, bank, p["sigma"], spectrum="frame", **kw)
    frame_b = model_nsr(other, bank, p["sigma"], spectrum="frame", **kw)
    # uniform noise outside (variance 1/12) swamps the frame's spectrum: the NSR moves by
    # far more than 10 % (by e^12 here; 10 %: a margin over the search's 1 % tolerance)
    assert abs(math.log(frame_a / frame_b)) > 0.1
    # with every pixel restored the two rules are one
    full = np.ones(y.shape, bool)
    assert model_nsr(y, bank, p["sigma"], mask=full, spectrum="mirror") == model_nsr(
        y, bank, p["sigma"], mask=full, spectrum="frame")
    with pytest.raises(ValueError, match="spectrum must be 'mirror' or 'frame'"):
        model_nsr(y, bank, p["sigma"], spectrum="disk")


def test_kernel_shares_without_stand_ins_drop_the_nodes_off_the_mirror():
    bank = synthetic_grid_bank((64, 64), (3, 3), size=5)
    valid = np.ones(9, bool)
    valid[[0, 2]] = False
    from dataclasses import replace

    marked = replace(bank, metadata={**bank.metadata, "valid": valid.tolist()})
    w_all = kernel_shares(marked, (64, 64))
    w_traced = kernel_shares(marked, (64, 64), stand_ins=False)
    assert w_all[0] > 0 and w_traced[0] == 0 and w_traced[2] == 0
    assert w_traced.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(w_traced[valid], w_all[valid] / w_all[valid].sum())
    # a bank that marks nothing, or nothing valid, keeps every share
    np.testing.assert_array_equal(kernel_shares(bank, (64, 64), stand_ins=False),
                                  kernel_shares(bank, (64, 64)))
    none = replace(bank, metadata={**bank.metadata, "valid": [False] * 9})
    np.testing.assert_array_equal(kernel_shares(none, (64, 64), stand_ins=False),
                                  kernel_shares(none, (64, 64)))
