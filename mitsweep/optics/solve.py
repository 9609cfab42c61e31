"""Scalar root bracketing and bounded minimisation for the optics' one-dimensional solves.

The sweep-range solves need a root in a bracket and a minimum in an interval, to 1e-10 mm
or better, a few dozen times per setup. ``scipy.optimize`` does both, but importing it
costs about a second of start-up (it pulls in ``scipy.linalg`` and ``scipy.stats``
machinery) on every command that computes a sweep range, which is most of them. These
two routines are the textbook guaranteed methods — bisection and golden-section search —
whose error bounds are exact: the answer lies within ``xtol`` of the true root (a sign
change of a continuous function) or of a local minimum of a unimodal function.
"""

from __future__ import annotations

import math
from collections.abc import Callable

__all__ = ["bracketed_root", "bounded_minimum"]

_INV_PHI = (math.sqrt(5.0) - 1.0) / 2.0  # 1/φ


def bracketed_root(f: Callable[[float], float], a: float, b: float, *,
                   xtol: float = 1e-12, max_iter: int = 200) -> float:
    """A root of continuous ``f`` in ``[a, b]``, where ``f(a)`` and ``f(b)`` differ in
    sign (or one is zero), to within ``xtol`` (bisection: ``⌈log2(|b − a| / xtol)⌉`` steps).

    Parameters
    ----------
    f : callable
        ``f(x) -> float``, continuous on ``[a, b]``.
    a, b : float
        The bracket's ends (either order).
    xtol : float, optional
        Absolute tolerance on the root, in ``x``'s unit (default 1e-12).
    max_iter : int, optional
        Most bisections (default 200); the bracket's midpoint is returned if they run
        out.

    Raises
    ------
    ValueError
        When ``[a, b]`` does not bracket a sign change (or ``f`` is not finite at an
        end).
    """
    fa, fb = float(f(a)), float(f(b))
    if fa == 0.0:
        return float(a)
    if fb == 0.0:
        return float(b)
    if not (math.isfinite(fa) and math.isfinite(fb)) or (fa > 0) == (fb > 0):
        raise ValueError(f"f({a!r}) = {fa!r} and f({b!r}) = {fb!r} do not bracket a root")
    a, b = float(a), float(b)
    for _ in range(max_iter):
        m = 0.5 * (a + b)
        if abs(b - a) <= 2.0 * xtol or m in (a, b):
            return m
        fm = float(f(m))
        if fm == 0.0:
            return m
        if (fm > 0) == (fa > 0):
            a, fa = m, fm
        else:
            b = m
    return 0.5 * (a + b)


def bounded_minimum(f: Callable[[float], float], lo: float, hi: float, *,
                    xatol: float = 1e-10, max_iter: int = 500) -> tuple[float, float]:
    """``(x, f(x))`` at a local minimum of ``f`` on ``[lo, hi]``, ``x`` within ``xatol``
    (golden-section search; exact for a unimodal ``f``). The ends are candidates too, so
    a minimum at a bound is found.

    Parameters
    ----------
    f : callable
        ``f(x) -> float`` on ``[lo, hi]``.
    lo, hi : float
        The interval's ends (either order).
    xatol : float, optional
        Absolute tolerance on ``x`` (default 1e-10).
    max_iter : int, optional
        Most golden-section steps (default 500).
    """
    lo, hi = float(min(lo, hi)), float(max(lo, hi))
    a, b = lo, hi
    c = b - _INV_PHI * (b - a)
    d = a + _INV_PHI * (b - a)
    fc, fd = float(f(c)), float(f(d))
    for _ in range(max_iter):
        if b - a <= xatol:
            break
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - _INV_PHI * (b - a)
            fc = float(f(c))
        else:
            a, c, fc = c, d, fd
            d = a + _INV_PHI * (b - a)
            fd = float(f(d))
    x = 0.5 * (a + b)
    best = min(((float(f(x)), x), (float(f(lo)), lo), (float(f(hi)), hi)))
    return best[1], best[0]
