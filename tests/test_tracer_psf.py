"""PSFs and IPSFs of the Dr.Jit tracer: normalisation, geometry, sweep sampling,
precision, and an independent float64 re-trace of the kernel's rays."""

import dataclasses
import math

import numpy as np
import pytest

from mitsweep.config import Mirror, SetupError, load_setup
from mitsweep.optics import image_distance, intersect_mirror, optimal_sweep_range, placement_of
from mitsweep.optics.reference import reference_geometry
from mitsweep.optics.motion import MotionProfile
from mitsweep.tracer import TraceSettings, integrated_psf, psf
from mitsweep.tracer.kernel import trace_arrays
from mitsweep.tracer.ipsf import fit_sampling_box
from mitsweep.tracer.source import source_from_mirror

SPHERE = load_setup("scenes/sphere.toml")
SR = optimal_sweep_range(SPHERE)
REF = SR.reference_sensor_distance


def _with_mirror(**kw):
    base = dict(radius=25.0, conic=0.0, rim_radius=25.0, vertex_distance=327.0)
    base.update(kw)
    return dataclasses.replace(SPHERE, mirror=Mirror(**base))


@pytest.mark.parametrize("u,v", [(0.0, 0.0), (2.0, 0.0), (0.0, -3.0), (2.5, 2.5)])
def test_ipsf_is_unit_sum_finite_and_centred(u, v):
    k, info = integrated_psf(SPHERE, u, v, 500.0, settings=TraceSettings(rays=400_000))
    assert k.dtype == np.float32 and k.shape == (31, 31)
    assert np.all(np.isfinite(k)) and np.all(k >= 0)
    assert k.sum() == pytest.approx(1.0, abs=1e-5)
    # The focal sweep blurs symmetrically about the chief ray up to aberrations and
    # breathing: the centroid stays within half a pixel of the chief-ray image.
    assert abs(info["centroid_px"][0]) < 0.5 and abs(info["centroid_px"][1]) < 0.5
    assert info["vignetted_fraction"] == pytest.approx(0.0, abs=1e-9)
    # Importance sampling: an elliptic footprint fills ~pi/4 of its fitted box.
    assert info["landed_fraction"] > 0.6


def test_defocused_axial_psf_is_the_thin_lens_disk():
    """On the axis the mirror images the source at the Coddington distance; a sensor
    defocused by di sees a uniform disk of radius ~ a |di| / i_f (a = aperture radius),
    whose second moment is r²/4 per axis."""
    from mitsweep.optics import focal_image_axial_distances, image_distance
    d_m, _ = focal_image_axial_distances(SPHERE, np.array(0.0), 500.0)
    i_f = image_distance(SPHERE.lens.focal_length, float(d_m))
    i = i_f + 0.5
    k, info = psf(SPHERE, 0.0, 0.0, 500.0, i, rays=2_000_000, kernel_size=41)
    pitch = SPHERE.sensor.pixel_pitch
    x = (np.arange(41) - 20) * pitch
    var_u = float((k.sum(axis=0) * x ** 2).sum()) - pitch ** 2 / 12  # remove pixel box
    r = SPHERE.lens.aperture_radius * 0.5 / i_f
    # 2 %: the exact disk is slightly non-uniform (source at finite depth, the mirror's
    # spherical aberration over the full aperture), measured ~0.3 %.
    assert math.sqrt(4 * var_u) == pytest.approx(r, rel=0.02)


def test_rotational_symmetry_of_the_sphere():
    k1, _ = integrated_psf(SPHERE, 3.0, 0.0, 1000.0, settings=TraceSettings(rays=2_000_000))
    k2, _ = integrated_psf(SPHERE, 0.0, 3.0, 1000.0, settings=TraceSettings(rays=2_000_000))
    # (0, 3) is (3, 0) rotated 90° counter-clockwise; rows go down (-v), so that is
    # np.rot90 of the array. L1 tolerance: Monte Carlo error of 2e6 QMC rays ~1e-3.
    assert np.abs(np.rot90(k1) - k2).sum() < 5e-3


@pytest.mark.parametrize("u", [0.5, 3.4])
def test_continuous_sweep_and_plane_sum_converge_to_the_same_ipsf(u):
    k_c, _ = integrated_psf(SPHERE, u, 0.0, 800.0, settings=TraceSettings(rays=2_000_000))
    k_p, _ = integrated_psf(SPHERE, u, 0.0, 800.0,
                            settings=TraceSettings(rays=2_000_000, method="planes", n_planes=64))
    k_16, _ = integrated_psf(SPHERE, u, 0.0, 800.0,
                             settings=TraceSettings(rays=2_000_000, method="planes", n_planes=4))
    d64 = np.abs(k_c - k_p).sum()
    d4 = np.abs(k_c - k_16).sum()
    # 64 planes approximate the continuous sweep to ~1e-3 in L1; 4 planes are
    # visibly coarser (the plane sum is a rectangle rule in time).
    assert d64 < 4e-3
    assert d4 > 2 * d64


def test_ipsf_is_the_time_average_of_psfs():
    """The N-plane IPSF equals the mean of the N single-distance PSFs on the same grid."""
    n = 4
    motion = MotionProfile.linear(SR.sensor_start, SR.sensor_end)
    k, _ = integrated_psf(SPHERE, 2.0, 0.0, 500.0, motion=motion, reference_sensor_distance=REF,
                          settings=TraceSettings(rays=1_000_000, method="planes", n_planes=n))
    dists = motion.sensor_distance((np.arange(n) + 0.5) / n)
    mean = sum(psf(SPHERE, 2.0, 0.0, 500.0, i, rays=1_000_000,
                   reference_sensor_distance=REF)[0] for i in dists) / n
    # Same rays in both (same seed): only float32 rounding of the sums differs.
    assert np.abs(k - mean).sum() < 1e-4


def test_trapezoidal_motion_dwells_longer_at_the_ends():
    lin = MotionProfile.linear(SR.sensor_start, SR.sensor_end)
    trap = MotionProfile.trapezoidal(SR.sensor_start, SR.sensor_end, 0.4)
    kl, _ = integrated_psf(SPHERE, 0.0, 0.0, 10000.0, motion=lin, sweep=SR,
                           settings=TraceSettings(rays=1_000_000))
    kt, _ = integrated_psf(SPHERE, 0.0, 0.0, 10000.0, motion=trap, sweep=SR,
                           settings=TraceSettings(rays=1_000_000))
    # A far source focuses near the start of the sweep; the slow trapezoidal start
    # spends more time near focus, so its IPSF peak is higher.
    assert kt.max() > 1.05 * kl.max()


@pytest.mark.parametrize("u", [0.0, 3.0])
def test_float32_matches_float64(u):
    k32, _ = integrated_psf(SPHERE, u, 0.0, 500.0, settings=TraceSettings(rays=1_000_000))
    k64, _ = integrated_psf(SPHERE, u, 0.0, 500.0, double=True,
                            settings=TraceSettings(rays=1_000_000))
    # Same sample stream: only rounding differs; measured ~2e-5 L1, stated bound 2e-4
    # (a ray moving across a pixel border flips ~1 pitch of its weight).
    assert np.abs(k32 - k64).sum() < 2e-4


def test_vignetting_is_reported_at_the_rim():
    """A paraboloid cut at a small rim vignettes peripheral pencils."""
    setup = _with_mirror(radius=28.2, conic=-1.0, rim_radius=10.0, vertex_distance=352.0)
    src_rho = 9.95
    from mitsweep.optics import chief_ray, image_point
    pl = placement_of(setup.mirror)
    geometry = reference_geometry(setup, sweep=optimal_sweep_range(setup, fov_deg=60.0))
    u, _ = image_point(chief_ray(pl, pl.surface(np.array([src_rho]), np.array([0.0]))),
                       geometry.sensor_distance)
    k, info = integrated_psf(setup, float(u[0]), 0.0, 500.0, sweep=geometry.sweep,
                             settings=TraceSettings(rays=400_000))
    assert 0.05 < info["vignetted_fraction"] < 0.95
    assert k.sum() == pytest.approx(1.0, abs=1e-5)


FEW = TraceSettings(rays=1000)


@pytest.mark.parametrize("call,err,match", [
    (lambda: integrated_psf(SPHERE, 50.0, 0.0, 500.0, settings=FEW), ValueError, "outside"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, 0.0, settings=FEW), ValueError, "depth"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, -5.0, settings=FEW), ValueError, "depth"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, 500.0, settings=TraceSettings(method="magic")),
     ValueError, "method"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, 500.0, settings=TraceSettings(kernel_size=30)),
     ValueError, "kernel_size"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, 500.0, motion="linear"), TypeError,
     "MotionProfile"),
    (lambda: integrated_psf(SPHERE, 1.0, 0.0, 500.0,
                            motion=MotionProfile.linear(REF, REF)), SetupError, "empty"),
])
def test_bad_input_gets_a_clear_error(call, err, match):
    with pytest.raises(err, match=match):
        call()


def _numpy_retrace(setup, geom, r):
    """Independent float64 trace of the kernel's own samples with optics.intersect_mirror."""
    pl = placement_of(setup.mirror)
    rot = geom.rotation
    a, b = r["a"], r["b"]
    inv_l = 0.0 if math.isinf(geom.depth) else 1.0 / geom.depth
    d = -geom.w + np.outer(a * inv_l, geom.e1) + np.outer(b * inv_l, geom.e2)
    d /= np.linalg.norm(d, axis=1)[:, None]
    q = geom.origin_pr + np.outer(a, geom.e1) + np.outer(b, geom.e2)
    back = np.full_like(a, geom.margin) if math.isinf(geom.depth) else np.minimum(
        geom.margin, geom.depth * np.sqrt(1 + (a * inv_l) ** 2 + (b * inv_l) ** 2))
    o = q - d * back[:, None]
    ow, dw = o @ rot.T, d @ rot.T
    t = intersect_mirror(pl, ow, dw)
    hit = np.isfinite(t)
    p = ow + np.where(hit, t, 0)[:, None] * dw
    loc = pl.to_local(p)
    n = pl.surface(loc[:, 0], loc[:, 1]).normal
    front = hit & (np.sum(dw * n, axis=1) < 0)
    refl = dw - 2 * np.sum(dw * n, axis=1)[:, None] * n
    tl = (geom.vertex_distance - p[:, 2]) / refl[:, 2]
    L = p + tl[:, None] * refl
    landed = front & (refl[:, 2] > 0) & (np.hypot(L[:, 0], L[:, 1]) <= geom.aperture_radius)
    A = -L[:, :2]
    B = L[:, :2] / geom.focal_length - refl[:, :2] / refl[:, 2:3]
    return landed, A, B


@pytest.mark.parametrize("name,setup,rho,depth", [
    ("sphere axis", SPHERE, 0.0, 500.0),
    ("sphere grazing", SPHERE, 24.6, 300.0),
    ("sphere far", SPHERE, 20.0, 1e9),
    ("hyperboloid steep", _with_mirror(radius=10.0, conic=-4.0, rim_radius=30.0), 29.0, 400.0),
    ("oblate rim", _with_mirror(radius=25.0, conic=0.8, rim_radius=18.6), 18.5, 300.0),
    ("tilted", load_setup("scenes/paraboloid_tilted.toml"), -27.0, 300.0),
    ("asphere", dataclasses.replace(SPHERE, mirror=Mirror(
        kind="asphere", radius=25.0, conic=-0.5, rim_radius=20.0, vertex_distance=327.0,
        aspheric=(2e-6, -1e-9))), 15.0, 500.0),
])
def test_kernel_agrees_with_independent_float64_retrace(name, setup, rho, depth):
    # the retrace compares rays, whatever grid they are binned on: refer the image point
    # to the sensor distance that focuses the mirror's vertex
    i_vertex = image_distance(setup.lens.focal_length, setup.mirror.vertex_distance)
    src = source_from_mirror(setup, rho, 0.0, depth, reference_sensor_distance=i_vertex)
    geom = src.geometry(setup)
    params, _ = fit_sampling_box(geom, double=True)
    r = trace_arrays(geom, params, 20000, double=True)
    landed, A, B = _numpy_retrace(setup, geom, r)
    both = landed & r["landed"]
    # Masks may differ only for rays within rounding of the aperture edge or the rim.
    assert (landed != r["landed"]).sum() <= 2
    assert both.sum() > 1000
    # 1e-7 mm on A (lens-plane hit) and 1e-8 on B (slope): float64 rounding after
    # hundreds of mm of propagation and a Newton-polished root.
    np.testing.assert_allclose(r["Au"][both], A[both, 0], atol=1e-7)
    np.testing.assert_allclose(r["Av"][both], A[both, 1], atol=1e-7)
    np.testing.assert_allclose(r["Bu"][both], B[both, 0], atol=1e-8)
    np.testing.assert_allclose(r["Bv"][both], B[both, 1], atol=1e-8)
