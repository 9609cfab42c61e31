"""Each stage of the ray kernel against a small NumPy reference written here.

The stages run in float64 (``Float64``/``Array3f64``) on a few hundred random rays; the
references are independent formulations (a polynomial root finder, bisection, numerical
gradients, the thin-lens equation, pixel-boundary crossings), so the tolerances are
float64 round-off amplified by the conditioning of each step (stated per test).
"""

import math

import numpy as np
import pytest

from mitsweep import backend
from mitsweep.tracer import deposit as dep
from mitsweep.tracer import stages
from mitsweep.tracer.sampling import R2, R3, lattice_coordinates

m = backend.drjit_module()
F64, A3 = m.Float64, m.Array3f64
RNG = np.random.default_rng(26)


def _np(x):
    return np.asarray(x.numpy(), dtype=np.float64)


def _vec(v):
    return np.stack([_np(v.x), _np(v.y), _np(v.z)], axis=-1)


def _arr3(a):
    a = np.asarray(a, dtype=np.float64)
    return A3(F64(a[:, 0]), F64(a[:, 1]), F64(a[:, 2]))


# --- sample -----------------------------------------------------------------------------

@pytest.mark.parametrize("generators", [R2, R3])
def test_lattice_coordinates_are_fixed_point_fractions(generators):
    idx = np.array([0, 1, 2, 1000, 2 ** 20 + 7, 2 ** 32 - 1], dtype=np.uint64)
    shifts = [123456789, 3 ** 19, 2 ** 31 + 5][:len(generators)]
    got = lattice_coordinates(m.UInt32(idx.astype(np.uint32)),
                              [m.UInt32(s) for s in shifts], generators, F64)
    for g, s, u in zip(generators, shifts, got):
        frac = (idx * np.uint64(g) + np.uint64(s)) % np.uint64(2 ** 32)
        ref = (frac >> np.uint64(8)).astype(np.float64) / 2 ** 24
        assert np.array_equal(_np(u), ref)
        assert (_np(u) >= 0).all() and (_np(u) < 1).all()


def test_aim_box_and_ellipse_map_the_unit_square():
    ua, ub = RNG.random(500), RNG.random(500)
    a, b = stages.aim_box(F64(ua), F64(ub), -1.5, 2.0, 0.25, 3.0)
    np.testing.assert_allclose(_np(a), -1.5 + 3.5 * ua, rtol=0, atol=1e-15)
    np.testing.assert_allclose(_np(b), 0.25 + 2.75 * ub, rtol=0, atol=1e-15)
    c, M = (0.3, -0.2), np.array([[2.0, 0.5], [-0.4, 1.5]])
    a, b = stages.aim_ellipse(F64(ua), F64(ub), c, M.ravel().tolist())
    x = np.sqrt(ua)[:, None] * np.stack([np.cos(2 * np.pi * ub), np.sin(2 * np.pi * ub)], 1)
    ref = np.asarray(c) + x @ M.T
    np.testing.assert_allclose(np.stack([_np(a), _np(b)], 1), ref, rtol=0, atol=1e-14)
    # every point inside the ellipse |M^-1 (p - c)| <= 1
    inv = np.linalg.solve(M, (np.stack([_np(a), _np(b)], 1) - c).T)
    assert (np.hypot(*inv) <= 1 + 1e-12).all()


def _frame():
    w = RNG.normal(size=3)
    w /= np.linalg.norm(w)
    e1 = np.cross(w, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return w, e1, np.cross(w, e1)


@pytest.mark.parametrize("depth", [300.0, 5000.0, math.inf])
def test_source_rays_start_on_the_line_from_the_source(depth):
    """Direction (Q − S)/|Q − S|, weight cos³ of the angle to the chief ray, start at
    most ``margin`` before Q on that line (for l = inf: parallel to −w)."""
    w, e1, e2 = _frame()
    pr, margin, n = np.array([1.0, -2.0, 0.5]), 40.0, 200
    a, b = RNG.uniform(-8, 8, n), RNG.uniform(-8, 8, n)
    inv_l = 0.0 if math.isinf(depth) else 1.0 / depth
    o, d, wt = stages.source_rays(F64(a), F64(b), *(A3(*map(float, v)) for v in (w, e1, e2, pr)),
                                  F64(inv_l), F64(margin),
                                  None if math.isinf(depth) else F64(depth))
    q = pr + a[:, None] * e1 + b[:, None] * e2
    if math.isinf(depth):
        d_ref = np.broadcast_to(-w, q.shape)
        back = np.full(n, margin)
    else:
        sq = q - (pr + depth * w)
        dist = np.linalg.norm(sq, axis=1)
        d_ref = sq / dist[:, None]
        back = np.minimum(margin, dist)
    np.testing.assert_allclose(_vec(d), d_ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(_np(wt), (-(d_ref @ w)) ** 3, rtol=1e-13)
    np.testing.assert_allclose(_vec(o), q - back[:, None] * d_ref, rtol=0, atol=1e-12)


# --- intersect --------------------------------------------------------------------------

def _rays_at_mirror(n, R, rho_max, parallel=False):
    """Rays from z = 60 mm toward points of the mirror's zone (|ρ| < rho_max)."""
    target = np.column_stack([RNG.uniform(-rho_max, rho_max, (n, 2)), np.zeros(n)])
    o = np.column_stack([RNG.uniform(-5, 5, (n, 2)), np.full(n, 60.0)])
    if parallel:
        o[:, :2] = target[:, :2]
    d = target - o
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def _conic_roots(o, d, R, k):
    """Nearest positive root on the branch R + (1+k) z >= 0, by numpy.roots, else nan."""
    out = np.full(len(o), np.nan)
    for j, (oj, dj) in enumerate(zip(o, d)):
        def form(p, q):
            return p[0] * q[0] + p[1] * q[1] + (1 + k) * p[2] * q[2]
        coeffs = [form(dj, dj), 2 * (form(oj, dj) + R * dj[2]), form(oj, oj) + 2 * R * oj[2]]
        roots = np.roots(coeffs) if abs(coeffs[0]) > 1e-14 else np.array([-coeffs[2] / coeffs[1]])
        roots = roots[np.isreal(roots)].real
        ok = [t for t in roots if t > 0 and R + (1 + k) * (oj[2] + t * dj[2]) >= 0]
        if ok:
            out[j] = min(ok)
    return out


@pytest.mark.parametrize("R,k,parallel", [(25.0, 0.0, False), (28.2, -1.0, False),
                                          (28.2, -1.0, True), (20.0, -2.5, False),
                                          (30.0, 0.6, False)])
def test_intersect_conic_matches_polynomial_roots(R, k, parallel):
    """Sphere, paraboloid (also rays parallel to its axis: α = 0), hyperboloid, oblate
    ellipsoid. numpy.roots (companion-matrix eigenvalues) agrees to ~1e-12 relative for
    these well-separated roots; the hit lies on the surface (F = 0 to 1e-9 mm²)."""
    o, d = _rays_at_mirror(300, R, 0.6 * R, parallel)
    t, hit = stages.intersect_conic(_arr3(o), _arr3(d), F64(R), F64(1 + k))
    ref = _conic_roots(o, d, R, k)
    hit = np.asarray(hit.numpy())
    assert np.array_equal(hit, np.isfinite(ref))
    assert hit.mean() > 0.75  # most rays aimed at the zone meet the mirror
    np.testing.assert_allclose(_np(t)[hit], ref[hit], rtol=1e-11)
    p = o + _np(t)[:, None] * d
    f = p[:, 0] ** 2 + p[:, 1] ** 2 + (1 + k) * p[:, 2] ** 2 + 2 * R * p[:, 2]
    assert np.abs(f[hit]).max() < 1e-9


def _sag(rho2, R, k, coeffs):
    return rho2 / (R + np.sqrt(R * R - (1 + k) * rho2)) + sum(
        c * rho2 ** (j + 2) for j, c in enumerate(coeffs))


def test_intersect_asphere_matches_bisection():
    """Newton from the conic root against bisection of z + s(ρ) = 0 along the ray (60
    halvings of a bracket: exact to float64 spacing)."""
    R, k, coeffs = 28.2, -1.0, (2e-6, -3e-9)
    o, d = _rays_at_mirror(200, R, 12.0)
    t0, _ = stages.intersect_conic(_arr3(o), _arr3(d), F64(R), F64(1 + k))
    t = _np(stages.intersect_asphere(_arr3(o), _arr3(d), t0, F64(R), F64(1 + k), coeffs))

    def g(tt):
        p = o + tt[:, None] * d
        return p[:, 2] + _sag(p[:, 0] ** 2 + p[:, 1] ** 2, R, k, coeffs)

    lo, hi = _np(t0) - 1.0, _np(t0) + 1.0
    assert (np.sign(g(lo)) != np.sign(g(hi))).all()
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        left = np.sign(g(mid)) == np.sign(g(lo))
        lo, hi = np.where(left, mid, lo), np.where(left, hi, mid)
    np.testing.assert_allclose(t, 0.5 * (lo + hi), rtol=0, atol=1e-10)
    assert stages.intersect_asphere(_arr3(o), _arr3(d), t0, F64(R), F64(1 + k),
                                    (0.0, 0.0)) is t0


# --- reflect ----------------------------------------------------------------------------

@pytest.mark.parametrize("coeffs", [(), (3e-5, -2e-8)])
def test_surface_normal_is_the_numerical_gradient(coeffs):
    """The unnormalised normal is parallel to the central-difference gradient of
    z + s(ρ) (step 1e-5 mm: error ~1e-10 relative) and points toward +z (the camera)."""
    R, k, n = 28.2, -1.0, 100
    xy = RNG.uniform(-12, 12, (n, 2))
    rho2 = (xy ** 2).sum(1)
    p = np.column_stack([xy, -_sag(rho2, R, k, coeffs)])
    nrm = _vec(stages.surface_normal(_arr3(p), F64(rho2), F64(R), F64(1 + k), coeffs))
    h = 1e-5
    grad = np.empty((n, 3))
    for ax in range(2):
        e = np.zeros(2)
        e[ax] = h
        grad[:, ax] = (_sag(((xy + e) ** 2).sum(1), R, k, coeffs)
                       - _sag(((xy - e) ** 2).sum(1), R, k, coeffs)) / (2 * h)
    grad[:, 2] = 1.0
    unit = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    np.testing.assert_allclose(unit, grad / np.linalg.norm(grad, axis=1, keepdims=True),
                               rtol=0, atol=1e-8)


def test_reflect_mirrors_about_the_unit_normal():
    d = RNG.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nrm = RNG.normal(size=(300, 3)) * RNG.uniform(0.1, 30, (300, 1))
    refl, d_dot_n = stages.reflect(_arr3(d), _arr3(nrm))
    u = nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    ref = d - 2 * (d * u).sum(1, keepdims=True) * u
    np.testing.assert_allclose(_vec(refl), ref, rtol=0, atol=1e-14)
    np.testing.assert_allclose(_np(d_dot_n), (d * nrm).sum(1), rtol=1e-13)


# --- lens -------------------------------------------------------------------------------

@pytest.mark.parametrize("tilt_deg", [0.0, 90.0, 17.3])
def test_rotate_is_the_matrix_product(tilt_deg):
    c, s = math.cos(math.radians(tilt_deg)), math.sin(math.radians(tilt_deg))
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    if tilt_deg == 90.0:
        rot = np.round(rot)  # exact zeros and ones: the skipped products
    v = RNG.normal(size=(50, 3))
    np.testing.assert_allclose(_vec(stages.rotate(_arr3(v), rot, F64)), v @ rot.T,
                               rtol=0, atol=1e-14)


def test_thin_lens_images_through_the_lens_equation():
    """The sensor hit ``A + B i`` is where the ray to the image of a point P of the
    incoming ray (1/o + 1/i' = 1/f, magnification −i'/o) crosses the sensor plane at
    distance i, seen upright (both axes flipped); ``passes`` is ``r_z > 0`` and
    ``|L| <= aperture``."""
    vd, f, ap, n = 350.0, 12.0, 3.0, 400
    p = np.column_stack([RNG.uniform(-10, 10, (n, 2)), RNG.uniform(-5, 0, n)])
    target = np.column_stack([RNG.uniform(-4, 4, (n, 2)), np.full(n, vd)])
    r = target - p
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    r[:5] *= -1  # away from the lens
    out = stages.thin_lens(_arr3(p), _arr3(r), F64(vd), F64(1 / f), F64(ap ** 2))
    tl = (vd - p[:, 2]) / r[:, 2]
    L = p[:, :2] + tl[:, None] * r[:, :2]
    passes = (r[:, 2] > 0) & (np.hypot(*L.T) <= ap)
    assert np.array_equal(np.asarray(out["passes"].numpy()), passes)
    o = vd - p[:, 2]
    i_img = 1 / (1 / f - 1 / o)
    img = -p[:, :2] * (i_img / o)[:, None]
    for i in (12.5, 13.1):
        hit = L + (img - L) * (i / i_img)[:, None]
        got = np.column_stack([_np(out["Au"]) + _np(out["Bu"]) * i,
                               _np(out["Av"]) + _np(out["Bv"]) * i])
        np.testing.assert_allclose(got[passes], -hit[passes], rtol=0, atol=1e-11)


# --- deposit ----------------------------------------------------------------------------

K, PITCH, CU, CV = 7, 0.01, 0.013, -0.021


def _hits(n, spread=0.04, seed=0):
    """Hits around the window (half-width K·PITCH/2 = 0.035): with ``spread`` 0.04 and the
    slopes' shift (up to 0.03 mm at i = 15) about 40 % of their weight lands outside it
    (0.38-0.42 over seeds 0-4; 0.5 with the former spread 0.05, a coin toss). Their own generator: the same hits whatever ran
    before (the module's RNG is consumed in test order, which xdist may change)."""
    rng = np.random.default_rng(seed)
    Au, Av = rng.uniform(-spread, spread, (2, n)) + [[CU], [CV]]
    Bu, Bv = rng.uniform(-2e-3, 2e-3, (2, n))
    landed_free = rng.random(n) < 0.9
    landed = landed_free & (rng.random(n) < 0.9)
    weight = rng.uniform(0.5, 1.0, n)
    arrays = {"Au": Au, "Av": Av, "Bu": Bu, "Bv": Bv, "weight": weight}
    hits = {k: F64(v) for k, v in arrays.items()}
    hits.update(landed=m.Bool(landed), landed_free=m.Bool(landed_free))
    return hits, dict(arrays, landed=landed, landed_free=landed_free)


def _cell_of(u, v):
    """Window pixel of upright image point (u, v), or K·K outside: col right, row down."""
    col = np.floor((u - CU) / PITCH + K / 2).astype(int)
    row = np.floor((CV - v) / PITCH + K / 2).astype(int)
    ok = (col >= 0) & (col < K) & (row >= 0) & (row < K)
    return np.where(ok, row * K + col, K * K)


def test_deposit_time_samples_bins_each_hit():
    import drjit as dr

    hits, h = _hits(2000)
    dists = [10.0, 12.5, 15.0]
    buf = dep.deposit_time_samples(dr.zeros(F64, K * K + 2), hits, [F64(x) for x in dists],
                                   center=(CU, CV), pixel_pitch=PITCH, kernel_size=K)
    ref = np.zeros(K * K + 2)
    landed, free_only = h["landed"], h["landed_free"] & ~h["landed"]
    for i in dists:
        cells = _cell_of(h["Au"] + h["Bu"] * i, h["Av"] + h["Bv"] * i)
        np.add.at(ref, cells[landed], h["weight"][landed] / len(dists))
    ref[K * K + 1] = h["weight"][free_only].sum()
    np.testing.assert_allclose(dep.fold_buffer(buf, 1, K)[0], ref, rtol=1e-12, atol=1e-12)
    assert 0 < ref[K * K] < ref.sum() / 2  # some, not most, weight leaves the window


def _segment_times(x0, y0, dx, dy, cdf):
    """Exposure fraction per cell of the segment (x0 + s dx, y0 + s dy), s in [0, 1]:
    cut at every pixel edge it crosses, each piece assigned by its midpoint."""
    cuts = [0.0, 1.0]
    for p0, dp in ((x0, dx), (y0, dy)):
        if dp != 0:
            edges = np.arange(math.floor(min(p0, p0 + dp)), math.ceil(max(p0, p0 + dp)) + 1)
            cuts += [float(s) for s in (edges - p0) / dp if 0 < s < 1]
    cuts = np.unique(cuts)
    out = {}
    for s0, s1 in zip(cuts[:-1], cuts[1:]):
        sm = 0.5 * (s0 + s1)
        col, row = math.floor(x0 + sm * dx), math.floor(y0 + sm * dy)
        cell = row * K + col if 0 <= col < K and 0 <= row < K else K * K
        out[cell] = out.get(cell, 0.0) + cdf(s1) - cdf(s0)
    return out


@pytest.mark.parametrize("table", [None, np.linspace(0, 1, 9) ** 1.5])
def test_deposit_sweeps_integrates_each_segment(table):
    """The DDA's pixel times against pixel-edge crossings in NumPy (linear and
    tabulated time CDFs); exact to float64 round-off."""
    import drjit as dr

    hits, h = _hits(300)
    span = (10.0, 15.0)
    buf = dep.deposit_sweeps(dr.zeros(F64, K * K + 2), hits, center=(CU, CV), pixel_pitch=PITCH,
                             kernel_size=K, span=span, cdf_table=table)

    def cdf(s):
        return s if table is None else float(np.interp(s, np.linspace(0, 1, len(table)), table))

    ref = np.zeros(K * K + 2)
    for j in np.flatnonzero(h["landed"]):
        x0 = (h["Au"][j] + h["Bu"][j] * span[0] - CU) / PITCH + K / 2
        y0 = (CV - h["Av"][j] - h["Bv"][j] * span[0]) / PITCH + K / 2
        dx = h["Bu"][j] * (span[1] - span[0]) / PITCH
        dy = -h["Bv"][j] * (span[1] - span[0]) / PITCH
        for cell, frac in _segment_times(x0, y0, dx, dy, cdf).items():
            ref[cell] += h["weight"][j] * frac
    ref[K * K + 1] = h["weight"][h["landed_free"] & ~h["landed"]].sum()
    np.testing.assert_allclose(dep.fold_buffer(buf, 1, K)[0], ref, rtol=1e-9, atol=1e-12)
    assert ref[:K * K].sum() > 0.3 * ref.sum()


def test_sensor_distances_map_stratified_times():
    xi = RNG.random(100)
    lin = dep.sensor_distances(F64(xi), time_samples=3, linear=(10.0, 16.0), Float=F64)
    for j, dist in enumerate(lin):
        np.testing.assert_allclose(_np(dist), 10.0 + 6.0 * (xi + j) / 3, rtol=1e-15)
    table = np.array([10.0, 11.0, 13.0, 16.0])
    tab = dep.sensor_distances(F64(xi), time_samples=2, sensor_table=table, Float=F64)
    for j, dist in enumerate(tab):
        ref = np.interp((xi + j) / 2, np.linspace(0, 1, 4), table)
        np.testing.assert_allclose(_np(dist), ref, rtol=1e-14)
    fixed = dep.sensor_distances(None, times=[11.0, 12.0], Float=F64)
    assert [float(_np(x)[0]) for x in fixed] == [11.0, 12.0]
