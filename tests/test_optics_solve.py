"""optics.solve: bisection and golden-section search against SciPy's brentq and bounded
Brent, and their refusals."""

import math

import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import brentq, minimize_scalar

from mitsweep.optics.solve import bounded_minimum, bracketed_root


@settings(max_examples=200, deadline=None)
@given(root=st.floats(-50, 50), scale=st.floats(0.01, 100), width=st.floats(0.1, 100),
       frac=st.floats(0.01, 0.99), power=st.sampled_from([1, 3, 5]))
def test_root_agrees_with_brentq(root, scale, width, frac, power):
    f = lambda x: scale * math.tanh(x - root) ** power
    a, b = root - frac * width, root + (1 - frac) * width
    x = bracketed_root(f, a, b, xtol=1e-12)
    assert abs(x - root) <= 1e-12 + 4 * abs(root) * 2.2e-16
    if power == 1:  # brentq itself stalls on the flat odd powers at this xtol
        assert abs(x - brentq(f, a, b, xtol=1e-12)) <= 3e-12 + 8 * abs(root) * 2.2e-16


def test_root_at_an_end_and_refusals():
    assert bracketed_root(lambda x: x - 1.0, 1.0, 2.0) == 1.0
    assert bracketed_root(lambda x: x - 2.0, 1.0, 2.0) == 2.0
    with pytest.raises(ValueError, match="do not bracket"):
        bracketed_root(lambda x: x * x + 1.0, -1.0, 1.0)
    with pytest.raises(ValueError, match="do not bracket"):
        bracketed_root(lambda x: math.nan, -1.0, 1.0)


@settings(max_examples=200, deadline=None)
@given(centre=st.floats(-10, 10), lo_off=st.floats(0.01, 5), hi_off=st.floats(0.01, 5),
       curv=st.floats(0.01, 100))
def test_minimum_agrees_with_bounded_brent(centre, lo_off, hi_off, curv):
    f = lambda x: curv * (x - centre) ** 2 + math.cosh(0.1 * (x - centre))
    lo, hi = centre - lo_off, centre + hi_off
    x, fx = bounded_minimum(f, hi, lo, xatol=1e-10)       # bounds in either order
    ref = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    # f is flat at a minimum: in float64 x is determined only to about
    # sqrt(2 eps f / f''), for any minimiser; the value is what the sweep-range solve uses
    f2 = 2 * curv + 0.01
    assert abs(x - centre) <= 4 * math.sqrt(2.2e-16 * 2 * f(centre) / f2) + 1e-10
    assert fx <= ref.fun + 4 * 2.2e-16 * abs(ref.fun)


def test_minimum_at_a_bound():
    x, fx = bounded_minimum(lambda x: x, 2.0, 5.0)
    assert x == 2.0 and fx == 2.0
