"""The exact sweep deposit (each ray's sensor-hit segment, walked pixel by pixel) against
a brute-force NumPy time average of the same rays, and against the stratified method."""

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.optics.motion import MotionProfile
from mitsweep.optics.reference import reference_geometry
from mitsweep.tracer import TraceSettings, integrated_psf
from mitsweep.tracer.bank import field_radius
from mitsweep.tracer.ipsf import fit_sampling_box, sweep_cdf
from mitsweep.tracer.kernel import deposit_segments, fold_buffer, trace_arrays
from mitsweep.tracer.source import source_from_image

SPHERE = load_setup("scenes/sphere.toml")
TILTED = load_setup("scenes/paraboloid_tilted.toml")
GEOM = reference_geometry(SPHERE)
EDGE = field_radius(SPHERE, GEOM)
LO, HI = GEOM.motion.span


def _dense_time_average(setup, src, geom, params, n, motion, K, times=1000):
    """The same rays' hits at ``times`` midpoint times of ``motion.sensor_distance``,
    binned in NumPy: the sweep integral by brute force (no segment, no CDF)."""
    r = trace_arrays(geom, params, n)
    ok, free = r["landed"], r["landed_free"]
    i = motion.sensor_distance((np.arange(times) + 0.5) / times)
    p = setup.sensor.pixel_pitch
    img = np.zeros(K * K + 2)
    w = r["weight"][ok]
    for part in np.array_split(np.arange(ok.sum()), 32):
        hu = r["Au"][ok][part, None] + r["Bu"][ok][part, None] * i
        hv = r["Av"][ok][part, None] + r["Bv"][ok][part, None] * i
        col = np.floor((hu - src.image_uv[0]) / p + K // 2 + 0.5).astype(np.int64)
        row = np.floor(-(hv - src.image_uv[1]) / p + K // 2 + 0.5).astype(np.int64)
        inside = (col >= 0) & (col < K) & (row >= 0) & (row < K)
        np.add.at(img, np.where(inside, row * K + col, K * K).ravel(),
                  np.repeat(w[part] / times, times))
    img[K * K + 1] = r["weight"][free & ~ok].sum()
    return img


def _exact(setup, src, geom, params, n, motion, K):
    buf = deposit_segments(geom, params, n, offset=0, kernel_size=K,
                           pixel_pitch=setup.sensor.pixel_pitch, center_uv=src.image_uv,
                           span=motion.span, cdf_table=sweep_cdf(motion))
    return fold_buffer(buf, 1, K)[0]


MOTIONS = {
    "linear": GEOM.motion,
    "trapezoidal": MotionProfile.trapezoidal(GEOM.motion.start, GEOM.motion.end, 0.3),
    # a measured stage that overshoots and comes back: the CDF is not the inverse of i(t)
    "tabulated back and forth": MotionProfile.tabulated(
        [0.0, 0.5, 0.8, 1.0], [LO, HI + 0.2 * (HI - LO), HI, HI + 0.1 * (HI - LO)]),
}


@pytest.mark.parametrize("motion_name", sorted(MOTIONS))
@pytest.mark.parametrize("setup,u,v,K", [
    (SPHERE, 0.0, 0.0, 31),
    (SPHERE, EDGE, 0.0, 31),
    (SPHERE, 0.6 * EDGE, 0.5 * EDGE, 7),  # segments leave a small window
    (TILTED, 1.0, -2.0, 31),
])
def test_exact_deposit_is_the_time_average_of_the_same_rays(setup, u, v, K, motion_name):
    motion = MOTIONS[motion_name]
    ref = reference_geometry(setup).sensor_distance
    src = source_from_image(setup, u, v, 700.0, reference_sensor_distance=ref)
    geom = src.geometry(setup)
    params, _ = fit_sampling_box(geom)
    n = 1 << 14
    exact = _exact(setup, src, geom, params, n, motion, K)
    dense = _dense_time_average(setup, src, geom, params, n, motion, K)
    total = dense[:K * K + 1].sum()
    # Same rays: only the brute force's midpoint rule in time differs. Each pixel
    # crossing is off by < 1/(2·1000) of the ray's weight, with random sign over rays:
    # measured 5e-6 to 4e-5 in L1; bound 3e-4. The trapezoidal CDF is tabulated on 4097
    # nodes (interpolation error ~1e-7).
    assert np.abs(exact[:K * K] - dense[:K * K]).sum() / total < 3e-4
    assert exact[K * K] / total == pytest.approx(dense[K * K] / total, abs=3e-4)
    assert exact[K * K + 1] == pytest.approx(dense[K * K + 1], rel=1e-5, abs=1e-9)
    # mass: every landed ray's weight is deposited once, in the window or in cell K·K
    assert exact[:K * K + 1].sum() == pytest.approx(total, rel=1e-5)
    if K == 7:
        assert exact[K * K] > 0.01 * total  # the case is exercised


@pytest.mark.parametrize("u", [0.0, 0.9])
def test_exact_and_stratified_sweeps_converge_to_the_same_ipsf(u):
    k_e, _ = integrated_psf(SPHERE, u * EDGE, 0.0, 800.0, settings=TraceSettings(rays=2_000_000))
    k_c, _ = integrated_psf(SPHERE, u * EDGE, 0.0, 800.0, settings=TraceSettings(
        rays=4_000_000, method="continuous", time_samples=8, seed=5))
    # Independent estimates of one IPSF: Monte Carlo L1 of 4e6 stratified rays
    # ~2e-4 to 5e-4 (seed to seed), of the exact 2e6 ~1e-4; bound 1.5e-3.
    assert np.abs(k_e - k_c).sum() < 1.5e-3


def test_exact_method_needs_fewer_rays_for_the_same_error():
    u = EDGE
    ref, _ = integrated_psf(SPHERE, u, 0.0, 500.0, settings=TraceSettings(rays=1 << 23, seed=77))
    errs = {}
    for method, kw in (("exact", {}), ("continuous", {"time_samples": 4})):
        errs[method] = max(np.abs(integrated_psf(SPHERE, u, 0.0, 500.0, settings=TraceSettings(
            rays=1 << 19, method=method, seed=s, **kw))[0] - ref).sum() for s in (1, 2))
    # measured 1e-4 (exact) and 6e-4 (4 times per ray) at 2^19 rays
    assert errs["exact"] < 0.6 * errs["continuous"]


def test_rim_bookkeeping_does_not_depend_on_the_deposit():
    """Vignetted and outside-window fractions come from the same rays (the same lattice)
    whether each ray's sweep is deposited exactly or at 64 planes."""
    import dataclasses

    from mitsweep.config import Mirror
    from mitsweep.optics import chief_ray, image_point, optimal_sweep_range, placement_of

    # a paraboloid cut at a small rim vignettes pencils near it (as in test_tracer_psf)
    setup = dataclasses.replace(SPHERE, mirror=Mirror(radius=28.2, conic=-1.0, rim_radius=10.0,
                                                      vertex_distance=352.0))
    pl = placement_of(setup.mirror)
    g = reference_geometry(setup, sweep=optimal_sweep_range(setup, fov_deg=60.0))
    u, _ = image_point(chief_ray(pl, pl.surface(np.array([9.95]), np.array([0.0]))),
                       g.sensor_distance)
    cases = [(setup, float(u[0]), 31, {"sweep": g.sweep}),
             (SPHERE, EDGE, 5, {})]  # a window too small
    (rim_e, rim_c), (small_e, small_c) = [
        (integrated_psf(su, uu, 0.0, 500.0, **kw,
                        settings=TraceSettings(rays=200_000, kernel_size=K))[1],
         integrated_psf(su, uu, 0.0, 500.0, **kw, settings=TraceSettings(
             rays=200_000, kernel_size=K, method="planes", n_planes=64))[1])
        for su, uu, K, kw in cases]
    assert 0.05 < rim_e["vignetted_fraction"] < 0.95
    assert small_e["outside_kernel_fraction"] > 0.01
    for ie, ic in ((rim_e, rim_c), (small_e, small_c)):
        assert ie["vignetted_fraction"] == pytest.approx(ic["vignetted_fraction"], abs=1e-7)
        # 64 planes place each ray's exit from the window to ~1/64 of its sweep, with
        # either sign over rays: measured 2e-5 (0.2086 in the small window)
        assert ie["outside_kernel_fraction"] == pytest.approx(
            ic["outside_kernel_fraction"], abs=2e-3)
