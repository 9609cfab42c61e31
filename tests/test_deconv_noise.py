"""Poisson-Gaussian sensor noise (Cossairt, Gupta & Nayar 2013)."""

import math

import numpy as np
import pytest

from mitsweep.deconv.noise import PHOTONS_PER_LUX_S_M2, SensorNoise, paper_fig10_settings


def model(**kw):
    base = dict(illuminance_lux=50.0, exposure_s=0.6, f_number=2.8, pixel_pitch=0.0064)
    base.update(kw)
    return SensorNoise(**base)


def test_photo_electrons_follow_cossairt_formula():
    m = model(reflectance=0.5, quantum_efficiency=0.5)
    expect = PHOTONS_PER_LUX_S_M2 * 0.6 * 50 * 0.5 * 0.5 * (6.4e-6) ** 2 / 2.8 ** 2
    assert m.electrons_per_unit == pytest.approx(expect, rel=1e-12)
    # light scales as 1/N²: F11 collects (2.8/11)² of F2.8's
    assert model(f_number=11).electrons_per_unit / m.electrons_per_unit == \
        pytest.approx((2.8 / 11) ** 2, rel=1e-12)


@pytest.mark.parametrize("lux", [0.5, 5.0, 50.0])
@pytest.mark.parametrize("level", [0.05, 0.5])
def test_noisy_image_mean_and_variance_match_the_model(lux, level):
    m = model(illuminance_lux=lux)
    n = 200_000
    out = m.apply(np.full(n, level), rng=7)
    var = float(m.variance(level))
    # the mean of n samples has std sqrt(var/n): 5 of those; the sample variance of
    # n samples has relative std ~ sqrt(2/n) = 0.3 %: 3 % allows for the Poisson's
    # excess kurtosis and the quantisation's non-Gaussian error
    assert out.mean() == pytest.approx(level, abs=5 * math.sqrt(var / n))
    assert out.var() == pytest.approx(var, rel=0.03)


def test_seeded_noise_is_reproducible_and_seeds_differ():
    m = model()
    img = np.full((32, 32), 0.4, np.float32)
    a, b, c = m.apply(img, rng=1), m.apply(img, rng=1), m.apply(img, rng=2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.dtype == np.float32
    gen = np.random.default_rng(5)
    assert m.apply(img, rng=gen).shape == img.shape


def test_seed_is_required():
    with pytest.raises(ValueError, match="seed"):
        model().apply(np.zeros(4), rng=None)


def test_black_image_reads_only_dark_noise():
    m = model(illuminance_lux=5.0)
    out = m.apply(np.zeros(100_000), rng=3)
    dark_var = float(m.variance(0.0))
    assert out.mean() == pytest.approx(0.0, abs=5 * math.sqrt(dark_var / 1e5))
    assert out.var() == pytest.approx(dark_var, rel=0.05)
    assert out.min() < 0            # unbiased dark noise: not clipped at zero


def test_saturation_is_reported_and_clips_at_full_well():
    m = model()
    info = {}
    out = m.apply(np.full(1000, 10 * m.saturation), rng=0, info=info)
    assert info["saturated_fraction"] == 1.0
    assert out.max() <= m.saturation * 1.01   # read noise after the well, < 1 %


def test_snr_falls_with_light_and_stopping_down():
    assert model(illuminance_lux=500).snr(0.5) > model(illuminance_lux=50).snr(0.5) > \
        model(illuminance_lux=5).snr(0.5)
    s = paper_fig10_settings(0.0064)
    # F11 collects 15x less light; ISO 1600 cannot give the photons back
    assert s["sweep"].snr(0.5) > 3 * s["stopped"].snr(0.5)
    assert s["stopped"].nsr() > 10 * s["sweep"].nsr()


def test_higher_iso_lowers_input_referred_noise():
    lo, hi = model(illuminance_lux=1.0, iso=100), model(illuminance_lux=1.0, iso=1600)
    assert hi.variance(0.0) < lo.variance(0.0)


def test_nsr_is_variance_over_signal_power():
    m = model()
    assert m.nsr(0.5) == pytest.approx(float(m.variance(0.5)) / 0.25)
    assert m.nsr(0.5, signal_std=0.1) == pytest.approx(float(m.variance(0.5)) / 0.01)


@pytest.mark.parametrize("field,value", [("illuminance_lux", -1.0), ("f_number", 0.0),
                                         ("reflectance", 1.5), ("exposure_s", math.nan),
                                         ("bits", 0)])
def test_invalid_settings_name_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        model(**{field: value})


def test_negative_pixels_expose_nothing_and_nonfinite_are_refused():
    np.testing.assert_array_equal(model().apply(np.array([-0.1, -1e-9]), rng=0),
                                  model().apply(np.zeros(2), rng=0))
    with pytest.raises(ValueError, match="NaN"):
        model().apply(np.array([np.nan]), rng=0)


def test_pixel_pitch_keeps_its_former_name_as_a_deprecated_alias():
    """``pixel_size_mm`` (the name before the unit rule) still works, with a warning;
    provenance keeps the JSON key ``pixel_size_mm``."""
    import dataclasses

    new = model()
    with pytest.warns(DeprecationWarning, match="pixel_pitch"):
        old = SensorNoise(illuminance_lux=50.0, exposure_s=0.6, f_number=2.8,
                          pixel_size_mm=0.0064)
    assert old == new
    with pytest.warns(DeprecationWarning, match="pixel_pitch"):
        assert new.pixel_size_mm == 0.0064
    with pytest.warns(DeprecationWarning), pytest.raises(TypeError, match="not both"):
        SensorNoise(illuminance_lux=50.0, exposure_s=0.6, f_number=2.8, pixel_pitch=0.0064,
                    pixel_size_mm=0.0064)
    with pytest.warns(DeprecationWarning):
        assert paper_fig10_settings(pixel_size_mm=0.0064) == paper_fig10_settings(0.0064)
    assert new.as_dict()["pixel_size_mm"] == 0.0064 and "pixel_pitch" not in new.as_dict()
    # the provenance reads back to the same model, without the deprecation warning
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert SensorNoise.from_dict(new.as_dict()) == new
    assert dataclasses.replace(new, iso=200.0).pixel_pitch == 0.0064
    with pytest.raises(ValueError, match="noise.pixel_pitch"):
        model(pixel_pitch=0.0)
