"""The Dr.Jit cubic B-spline kernels (mitsweep.jit.spline) against scipy.ndimage."""

import math

import numpy as np
import pytest
import scipy.ndimage as ndi
from hypothesis import given, settings, strategies as st

from mitsweep import jit
from mitsweep.jit import spline

# Same spline, another summation order (rows of four taps, then the four rows, with
# FMAs; ndimage sums the 16 products), on standard-normal coefficients (values up to
# about 4). Largest differences measured over 200 random polar grids: float64 1.0e-15,
# float32 kernels against the float64 reference 5.6e-7 (float32 round-off of the sum);
# pixels from a polar image in float64 1.6e-14 (their angle is Dr.Jit's atan2, not
# NumPy's: the last bits differ, and a column is 64/2π of them).
TOL = {np.float32: 1e-6, np.float64: 5e-14}


def _polar_reference(coef, center, radii, n):
    th = np.arange(n) * (2 * math.pi / n)
    r = np.asarray(radii, dtype=np.float64)[:, None]
    return ndi.map_coordinates(coef.astype(np.float64),
                               [center[0] - r * np.sin(th), center[1] + r * np.cos(th)],
                               order=3, prefilter=False)


def test_a_backend_is_available_here():
    assert jit.available() in ("llvm", "cuda")


@settings(max_examples=40, deadline=None)
@given(h=st.integers(8, 40), w=st.integers(8, 40), dtype=st.sampled_from([np.float32, np.float64]),
       fy=st.floats(0.0, 1.0), fx=st.floats(0.0, 1.0), n=st.integers(1, 64),
       r_frac=st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=12), seed=st.integers(0, 9))
def test_polar_samples_match_map_coordinates(h, w, dtype, fy, fx, n, r_frac, seed):
    """Any pole inside the image, any radii that keep the taps inside (negative ones,
    zero: the pole itself at every angle, the largest reaching the edge), any angle count."""
    coef = np.random.default_rng(seed).standard_normal((h, w)).astype(dtype)
    cy, cx = 3 + fy * (h - 7), 3 + fx * (w - 7)
    reach = max(0.0, min(cy - 2, h - 3 - cy, cx - 2, w - 3 - cx) - 1e-9)
    radii = np.asarray(r_frac) * reach
    out = spline.polar_samples(coef, (cy, cx), radii, n)
    assert out.shape == (radii.size, n) and out.dtype == dtype
    np.testing.assert_allclose(out, _polar_reference(coef, (cy, cx), radii, n),
                               rtol=0, atol=TOL[dtype])


def test_polar_samples_at_integer_points_are_the_spline_values():
    """At pixel centres the cubic B-spline of coefficients c is (c[i-1] + 4c[i] + c[i+1])/6
    in each axis: an exact check that needs no reference."""
    c = np.random.default_rng(3).standard_normal((12, 12))
    # angle 0 and radius 2 from the pole (5, 5): the point (5, 7)
    (v,), = spline.polar_samples(c, (5.0, 5.0), [2.0], 1)
    k = np.array([1.0, 4.0, 1.0]) / 6
    assert v == pytest.approx(k @ c[4:7, 6:9] @ k, abs=1e-14)


@pytest.mark.parametrize("center", [(1.9, 10.0), (10.0, 1.9), (17.0, 10.0), (10.0, 17.0)])
def test_polar_samples_refuse_a_grid_that_reads_beyond_the_coefficients(center):
    """On 20 x 20 coefficients a point's taps stay inside for 1 <= floor(y) <= 17: a
    radius of 1 px from these poles crosses that, 0.5 px does not."""
    c = np.zeros((20, 20))
    with pytest.raises(ValueError, match="pad them"):
        spline.polar_samples(c, center, [1.0], 8)
    assert np.all(spline.polar_samples(c, center, [0.5], 8) == 0)


def test_bad_arguments_are_refused_with_their_name():
    with pytest.raises(TypeError, match="float32 or float64"):
        spline.polar_samples(np.zeros((8, 8), dtype=np.int32), (4, 4), [0.0], 4)
    with pytest.raises(ValueError, match="2-D array of at least 4 x 4"):
        spline.polar_samples(np.zeros((3, 8)), (1, 4), [0.0], 4)
    with pytest.raises(ValueError, match="at least one radius"):
        spline.polar_samples(np.zeros((8, 8)), (4, 4), [], 4)
    flat = np.zeros(30 * 20)
    lv = spline.PolarLevel(0, 30, 20, 5.0, 8, 2.0, 0.0)
    box = dict(center=(5, 5), radial_step=1.0, box=(0, 9, 0, 9))
    with pytest.raises(ValueError, match="1 to 3 levels"):
        spline.pixels_from_polar(flat, [lv] * 4, r_max=4.0, **box)
    with pytest.raises(ValueError, match="1 to 3 levels"):
        spline.pixels_from_polar(flat, [], r_max=4.0, **box)
    with pytest.raises(ValueError, match="lie inside the 600 coefficients"):
        spline.pixels_from_polar(flat, [lv._replace(offset=1)], r_max=4.0, **box)
    with pytest.raises(ValueError, match="rise from <= 0"):
        spline.pixels_from_polar(flat, [lv._replace(r_from=1.0)], r_max=4.0, **box)
    with pytest.raises(ValueError, match="read beyond its rows"):
        spline.pixels_from_polar(flat, [lv], r_max=40.0, **box)
    with pytest.raises(ValueError, match="read beyond its rows"):       # θ = 2π's taps
        spline.pixels_from_polar(flat, [lv._replace(n_angles=16)], r_max=4.0, **box)
    with pytest.raises(ValueError, match="non-empty"):
        spline.pixels_from_polar(flat, [lv], r_max=4.0, center=(5, 5), radial_step=1.0,
                                 box=(0, 0, 0, 9))
    with pytest.raises(TypeError, match="float32 or float64"):
        spline.pixels_from_polar(flat.astype(np.float16), [lv], r_max=4.0, **box)


def _levels(rng, dtype, step):
    """(flat coefficients, levels, arrays): 32 angles out to radius 6, 64 beyond, the
    columns periodically padded (2, 3)."""
    pad = lambda p: np.pad(p, ((0, 0), (2, 3)), mode="wrap")
    inner = pad(rng.standard_normal((16, 32))).astype(dtype)
    outer = pad(rng.standard_normal((40, 64))).astype(dtype)
    flat = np.concatenate([inner.ravel(), outer.ravel()])
    # inner rows start 3 steps inside the pole, outer rows at radius 6 - 8 steps
    levels = [spline.PolarLevel(0, 16, 37, 3.0, 32, 2.0, 0.0),
              spline.PolarLevel(inner.size, 40, 69, 8.0 - 6.0 / step, 64, 2.0, 6.0)]
    return flat, levels, (inner, outer)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pixels_from_polar_match_map_coordinates(dtype):
    rng = np.random.default_rng(7)
    step = 0.8
    flat, levels, arrays = _levels(rng, dtype, step)
    cy, cx, r_max = 14.3, 15.6, 17.0
    vals, inside = spline.pixels_from_polar(flat, levels, center=(cy, cx), radial_step=step,
                                            box=(0, 30, 0, 32), r_max=r_max)
    yy, xx = np.mgrid[0:30, 0:32].astype(float)
    dy, dx = cy - yy, xx - cx
    r = np.hypot(dy, dx)
    th = np.mod(np.arctan2(dy, dx), 2 * math.pi)
    ref = np.zeros_like(r)
    for c, (_, _, _, row_off, n, col_off, _), sel in zip(arrays, levels, (r < 6, r >= 6)):
        sel = sel & (r <= r_max)
        ref[sel] = ndi.map_coordinates(c.astype(np.float64),
                                       [r[sel] / step + row_off, th[sel] * n / (2 * math.pi)
                                        + col_off], order=3, prefilter=False)
    np.testing.assert_array_equal(inside, r <= r_max)
    assert vals.dtype == dtype and np.all(vals[~inside] == 0)
    np.testing.assert_allclose(vals, ref, rtol=0, atol=TOL[dtype])


def test_results_do_not_depend_on_the_thread_count():
    import drjit as dr

    rng = np.random.default_rng(2)
    coef = rng.standard_normal((300, 300)).astype(np.float32)
    flat, levels, _ = _levels(rng, np.float32, 0.8)
    before = dr.thread_count()
    outs = []
    try:
        for n in (1, max(2, before)):
            dr.set_thread_count(n)
            outs.append((spline.polar_samples(coef, (150.2, 149.7), np.linspace(-140, 140, 211),
                                              1000),
                         spline.pixels_from_polar(flat, levels, center=(14.3, 15.6),
                                                  radial_step=0.8, box=(0, 30, 0, 32),
                                                  r_max=17.0)[0]))
    finally:
        dr.set_thread_count(before)
    np.testing.assert_array_equal(outs[0][0], outs[1][0])
    np.testing.assert_array_equal(outs[0][1], outs[1][1])


@pytest.mark.parametrize("failure", ["no llvm", "scalar"])
def test_no_backend_means_no_kernels(monkeypatch, failure):
    """Where Dr.Jit cannot run (no libLLVM >= 19) or MITSWEEP_BACKEND=scalar, available()
    says None, and the polar deconvolution uses its SciPy reference."""
    from mitsweep import backend
    from mitsweep.deconv import polar

    def select(prefer=None):
        if failure == "scalar":
            return "scalar"
        raise backend.BackendError("Dr.Jit found no libLLVM")

    monkeypatch.setattr(backend, "select_backend", select)
    jit.available.cache_clear()
    try:
        assert jit.available() is None
        assert polar.spline.jit_kernels() is None
    finally:
        monkeypatch.undo()
        jit.available.cache_clear()
    assert jit.available() is not None
