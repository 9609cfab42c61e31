"""Hypothesis stress: random conics, tilts, mirror points and depths (up to 1e9 mm and
inf). No NaN, unit-sum kernels, no energy lost outside the fitted sampling box, and
float32 within a stated tolerance of float64."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from mitsweep.config import Lens, Mirror, Sensor, Setup, Sweep
from mitsweep.optics import image_distance
from mitsweep.tracer.focus import numeric_focus
from mitsweep.tracer.kernel import TraceParams, trace_arrays
from mitsweep.tracer.ipsf import fit_sampling_box, render_source
from mitsweep.tracer.source import source_from_mirror


@st.composite
def cases(draw):
    R = draw(st.floats(8.0, 60.0))
    k = draw(st.floats(-4.0, 1.5))
    rim_max = R / math.sqrt(1 + k) if 1 + k > 0 else 40.0
    rim = min(30.0, 0.98 * rim_max)
    tilt = draw(st.floats(-30.0, 30.0))
    vd = draw(st.floats(150.0, 600.0))
    mirror = Mirror(radius=R, conic=k, rim_radius=rim, vertex_distance=vd, tilt_deg=tilt)
    setup = Setup(mirror=mirror, lens=Lens(focal_length=50.0, f_number=2.8),
                  sensor=Sensor(resolution=(512, 512), pixel_pitch=0.02),
                  sweep=Sweep(fov_deg=90.0))
    frac = draw(st.floats(0.0, 0.9))
    phi = draw(st.floats(0.0, 2 * math.pi))
    x, y = rim * frac * math.cos(phi), rim * frac * math.sin(phi)
    depth = draw(st.one_of(st.floats(30.0, 1e9), st.just(1e9), st.just(math.inf)))
    return setup, x, y, depth


def _source(setup, x, y, depth):
    try:
        # these random mirrors need not have a sweep range for FOV 90: refer the image
        # point to the sensor distance focusing the mirror's vertex (near all its foci)
        i_vertex = image_distance(setup.lens.focal_length, setup.mirror.vertex_distance)
        return source_from_mirror(setup, x, y, depth, reference_sensor_distance=i_vertex)
    except ValueError as exc:  # the lens cannot see this point of a tilted mirror
        assert "not visible" in str(exc)
        return None


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_random_setups_trace_cleanly(case):
    setup, x, y, depth = case
    src = _source(setup, x, y, depth)
    if src is None:
        return
    geom = src.geometry(setup)
    try:
        params, _ = fit_sampling_box(geom)
    except ValueError as exc:  # rays from this point cannot reach the lens at all
        assert "no ray" in str(exc)
        return
    # Energy: the rim-free landed flux estimated in the fitted box equals the flux
    # estimated in a box 3x larger per side (nothing lands outside the fitted box).
    # QMC with 2^16 / 2^19 rays: relative error ~1e-3; bound 2 %.
    def flux(p, n):
        r = trace_arrays(geom, p, n)
        area = p.area  # the fitted ellipse's, or the box's
        return r["weight"][r["landed_free"]].sum() * area / n, r
    e_fit, r = flux(params, 1 << 16)
    for key in ("Au", "Av", "Bu", "Bv", "weight"):
        assert np.all(np.isfinite(r[key][r["landed"]]))
    wa, wb = params.a1 - params.a0, params.b1 - params.b0
    big = TraceParams(params.a0 - wa, params.a1 + wa, params.b0 - wb, params.b1 + wb, seed=3)
    e_big, _ = flux(big, 1 << 19)
    assert e_fit == pytest.approx(e_big, rel=0.02)

    # PSF at the traced radial focus, float32 against float64 on the same samples.
    i = numeric_focus(setup, src).radial_sensor
    if not (math.isfinite(i) and i > setup.lens.focal_length):
        return
    try:
        k32, info32 = render_source(setup, src, times=[i], rays=200_000, kernel_size=63)
    except ValueError as exc:  # a strongly astigmatic line longer than the window
        assert "outside" in str(exc) or "vignetted" in str(exc)
        return
    k64, info64 = render_source(setup, src, times=[i], rays=200_000, kernel_size=63,
                                double=True)
    for k, info in ((k32, info32), (k64, info64)):
        assert np.all(np.isfinite(k)) and k.sum() == pytest.approx(1.0, abs=1e-5)
        assert 0.0 <= info["vignetted_fraction"] <= 1.0
        assert 0.0 <= info["outside_kernel_fraction"] <= 1.0
    # float32 vs float64: only rays within rounding (~1e-5 px) of a pixel border move;
    # bound 2e-3 in L1 (measured <= 3e-4 over these cases).
    assert np.abs(k32 - k64).sum() < 2e-3
    assert info32["vignetted_fraction"] == pytest.approx(info64["vignetted_fraction"],
                                                         abs=1e-3)


@pytest.mark.xfail(strict=True, reason=(
    "found by the random test above (2026-12-03): this tilted hyperboloid's source at 16 km "
    "traces in float32 0.002 px off its float64 trace (L1 4.1e-3; 3e-4 at 1e4-1e6 mm, at 1e8, "
    "1e9 mm and at infinity), so the float32 rounding is not the pixel-border-only kind the "
    "bound assumes; cause not found yet (the same on the code before the kernel's split)"))
def test_far_source_of_a_tilted_hyperboloid_float32_matches_float64():
    setup = Setup(mirror=Mirror(radius=8.0, conic=-4.0, rim_radius=30.0, vertex_distance=234.0,
                                tilt_deg=7.412109375),
                  lens=Lens(focal_length=50.0, f_number=2.8),
                  sensor=Sensor(resolution=(512, 512), pixel_pitch=0.02), sweep=Sweep(fov_deg=90.0))
    src = _source(setup, 18.984375, 0.0, 16172169.0)
    i = numeric_focus(setup, src).radial_sensor
    k32, _ = render_source(setup, src, times=[i], rays=200_000, kernel_size=63)
    k64, _ = render_source(setup, src, times=[i], rays=200_000, kernel_size=63, double=True)
    assert np.abs(k32 - k64).sum() < 2e-3
