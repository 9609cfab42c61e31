"""Metrics: kurtosis definition, cross-sections, V (Eq. 2), V_avg (Eq. 3), Table 1 trends."""

import math

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.tracer.metrics import (cross_section, cross_sections, depth_variance,
                                     kurtosis, v_avg)
from mitsweep.tracer.table1 import conventional_psf, conventional_v_avg, table1

SPHERE = load_setup("scenes/sphere.toml")


@pytest.mark.parametrize("sigma", [2.0, 5.0, 11.0])
def test_kurtosis_of_a_gaussian_is_three(sigma):
    x = np.arange(-200, 201, dtype=float)
    # Sampled at sigma >= 2 pixels over +-18 sigma: discretisation error < 1e-6.
    assert kurtosis(np.exp(-0.5 * (x / sigma) ** 2), x) == pytest.approx(3.0, abs=1e-6)


def test_kurtosis_of_uniform_and_laplace():
    x = np.linspace(-1, 1, 200001)
    assert kurtosis(np.ones_like(x), x) == pytest.approx(1.8, abs=1e-4)
    y = np.linspace(-60, 60, 400001)
    assert kurtosis(np.exp(-np.abs(y)), y) == pytest.approx(6.0, abs=1e-3)


def test_kurtosis_rejects_bad_profiles():
    with pytest.raises(ValueError, match="non-negative"):
        kurtosis([1.0, -1.0, 2.0])
    with pytest.raises(ValueError, match="zero variance"):
        kurtosis([0.0, 1.0, 0.0])


def test_cross_sections_of_an_elongated_kernel():
    K = 31
    r, c = np.indices((K, K)) - K // 2
    # Long along u (columns), narrow along v (rows).
    k = np.exp(-0.5 * ((c / 6.0) ** 2 + (r / 1.5) ** 2))
    x, rad, tan = cross_sections(k, 0.0)
    assert (rad > 0.5 * rad.max()).sum() > 3 * (tan > 0.5 * tan.max()).sum()
    # Rotating the direction by 90 degrees swaps the two.
    _, rad90, tan90 = cross_sections(k, math.pi / 2)
    np.testing.assert_allclose(rad90, tan, atol=1e-12)
    np.testing.assert_allclose(tan90, rad[::-1], atol=1e-12)
    # Through a given point, bilinear sampling at integer positions is exact.
    _, v = cross_section(k, (1, 0), through=(15, 15))
    np.testing.assert_allclose(v, k[15], atol=1e-12)


def test_depth_variance_properties():
    rng = np.random.default_rng(1)
    a = rng.random((31, 31))
    b = rng.random((31, 31))
    assert depth_variance(a, a) == 0.0
    assert depth_variance(a, b) == pytest.approx(depth_variance(b, a), rel=1e-12)
    assert depth_variance(a, b) > 0
    # Scale of the inputs does not matter (kernels are normalised).
    assert depth_variance(3 * a, b) == pytest.approx(depth_variance(a, b), rel=1e-12)


def test_conventional_defocus_disk_has_the_thin_lens_radius():
    k = conventional_psf(SPHERE, 500.0, 1000.0, kernel_size=101)
    pitch = SPHERE.sensor.pixel_pitch
    i_s, i_o = 50 * 1000 / 950, 50 * 500 / 450
    r_px = SPHERE.lens.aperture_radius * abs(1 - i_s / i_o) / pitch
    area = (k > 0).sum()
    # Pixel count of the disk within its boundary pixels (2 pi r).
    assert abs(area - math.pi * r_px ** 2) < 2 * math.pi * r_px
    assert k.sum() == pytest.approx(1.0, abs=1e-6)


def test_v_avg_counts_the_reference_depth():
    k = np.zeros((2, 1, 5, 5))
    k[:, :, 2, 2] = 1
    k[1, 0, 2, 3] = 1
    assert v_avg(k) == pytest.approx(depth_variance(k[1, 0], k[0, 0]) / 2)


@pytest.mark.slow
def test_table1_trends_match_the_paper():
    t = table1(SPHERE, rays=400_000)
    rows = t["rows"][:3]  # the paper's 339-348, 339-357, 339-374
    assert [round(r["focus_max_mm"]) for r in rows] == [348, 357, 374]
    per_t = [r["kurtosis"]["periphery"]["tangential"] for r in rows]
    per_r = [r["kurtosis"]["periphery"]["radial"] for r in rows]
    # Paper: a longer sweep sharpens the periphery tangentially, blurs it radially.
    assert per_t[0] < per_t[1] < per_t[2]
    assert per_r[0] > per_r[1] > per_r[2]
    # Symmetric centre: radial and tangential agree (Monte Carlo, 2 %).
    for r in rows:
        c = r["kurtosis"]["center"]
        assert c["radial"] == pytest.approx(c["tangential"], rel=0.02)
    # Depth invariance: V_avg is orders of magnitude below a conventional camera's.
    conv = t["conventional"]["v_avg"]
    assert all(r["v_avg"] * 100 < conv for r in t["rows"])


def test_conventional_camera_is_depth_variant():
    v, focus = conventional_v_avg(SPHERE)
    assert 500 < focus < 10000
    assert v > 1e4  # Kuthirummal et al.: ~1e4 for a conventional camera
