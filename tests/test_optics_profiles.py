"""Profiles: analytic sag, slope, curvature and principal radii."""

import numpy as np
import pytest

from mitsweep.optics import Profile, conic_sag

PROFILES = [Profile(25.0, 0.0), Profile(28.2, -1.0), Profile(20.0, -2.5), Profile(25.0, -0.5),
            Profile(25.0, 0.6), Profile(30.0, -0.8, (2e-6, -1e-9))]


@pytest.mark.parametrize("prof", PROFILES, ids=lambda p: f"R{p.radius}k{p.conic}a{len(p.aspheric)}")
def test_slope_and_curvature_match_finite_differences(prof):
    rho = np.linspace(0.5, 0.9 * min(prof.max_rho(), 30.0), 25)
    h = 1e-4
    # Central differences: truncation O(h²) ≈ 1e-8 relative, rounding ≈ 1e-16/h² · s.
    ds = (prof.sag(rho + h) - prof.sag(rho - h)) / (2 * h)
    d2s = (prof.sag(rho + h) - 2 * prof.sag(rho) + prof.sag(rho - h)) / h ** 2
    np.testing.assert_allclose(prof.slope(rho), ds, rtol=1e-6)
    np.testing.assert_allclose(prof.curvature(rho), d2s, rtol=1e-4)
    r_m, r_s = prof.principal_radii(rho)
    np.testing.assert_allclose(r_m, (1 + ds ** 2) ** 1.5 / d2s, rtol=1e-4)
    np.testing.assert_allclose(r_s, rho * np.sqrt(1 + ds ** 2) / ds, rtol=1e-6)


@pytest.mark.parametrize("prof", PROFILES[:5], ids=lambda p: f"k{p.conic}")
def test_principal_radii_on_axis_equal_vertex_radius(prof):
    r_m, r_s = prof.principal_radii(np.array([0.0, 1e-12]))
    np.testing.assert_allclose(r_m, prof.radius, rtol=1e-15)
    np.testing.assert_allclose(r_s, prof.radius, rtol=1e-15)


def test_conic_closed_forms():
    """Pure conics: R_s = sqrt(R² − kρ²), R_m = R_s³/R²."""
    prof = Profile(20.0, -2.5)
    rho = np.linspace(0, 40, 9)
    r_m, r_s = prof.principal_radii(rho)
    np.testing.assert_allclose(r_s, np.sqrt(400 + 2.5 * rho ** 2), rtol=1e-14)
    np.testing.assert_allclose(r_m, r_s ** 3 / 400, rtol=1e-13)


def test_sag_is_cancellation_free_near_axis():
    """Naive R − sqrt(R² − ρ²) loses all digits at ρ = 1e-9; ρ²/(R + q) does not."""
    np.testing.assert_allclose(conic_sag(1e-9, 25.0, 0.0), 1e-18 / 50.0, rtol=1e-15)


def test_hemisphere_rim_normal_is_horizontal():
    nr, nz = Profile(25.0, 0.0).normal_components(np.array(25.0))
    assert float(nr) == pytest.approx(1.0) and float(nz) == pytest.approx(0.0, abs=1e-15)
