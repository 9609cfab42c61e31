"""Stage motion during a focal sweep: sensor distance as a function of normalised time.

A :class:`MotionProfile` maps the normalised exposure time ``t ∈ [0, 1]`` (0 = shutter
opens, 1 = shutter closes) to the lens-to-sensor distance ``i(t)`` in mm. The IPSF is the
time average of the PSF over the exposure,

.. math:: \\mathrm{IPSF}(x) = \\int_0^1 \\mathrm{PSF}(x; i(t))\\,dt,

so the tracer and the renderer only need ``i(t)`` (for stratified time samples) and,
for exact deposition, a piecewise-linear description of it (:meth:`MotionProfile.segments`).

Kinds
-----
- ``linear``: constant stage velocity, ``i(t) = start + (end − start) t`` (the paper).
- ``trapezoidal``: constant acceleration for the first and last ``accel_fraction`` of
  the exposure, constant velocity between (a real stage that starts and stops inside
  the exposure). ``accel_fraction = 0.5`` is a triangular velocity profile.
- ``tabulated``: piecewise-linear interpolation of measured ``(times, positions)``, e.g.
  a rig log; times are rescaled to [0, 1].

Pure NumPy: shared by ``mitsweep.tracer`` and ``mitsweep.render``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import MOTION_PROFILES, Setup, SetupError
from .kinematics import Trapezoid
from .sweep import SweepRange

__all__ = ["MotionProfile", "motion_for", "MOTION_PROFILES"]


def _check_distance(x, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise SetupError(f"motion.{name}: expected a sensor distance in mm, got {x!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise SetupError(f"motion.{name}: must be a finite sensor distance > 0 mm, got {x!r}")
    return v


@dataclass(frozen=True)
class MotionProfile:
    """Sensor distance ``i(t)`` (mm) over the normalised exposure time ``t ∈ [0, 1]``.

    Build one with :meth:`linear`, :meth:`trapezoidal`, :meth:`tabulated` or
    :func:`motion_for`; do not call the constructor directly.

    Attributes
    ----------
    kind : str
        ``"linear"``, ``"trapezoidal"`` or ``"tabulated"``.
    start, end : float
        Sensor distance at t = 0 and t = 1, mm.
    accel_fraction : float
        Trapezoidal only: fraction of the exposure spent accelerating (and, the same,
        decelerating), in (0, 0.5].
    times, positions : (n,) ndarray
        Tabulated only: knots, times normalised to [0, 1], strictly increasing.
    """

    kind: str
    start: float
    end: float
    accel_fraction: float = 0.0
    # None for the linear and trapezoidal kinds; typed as arrays for the tabulated kind's
    # readers (an Optional type would make every reader in other packages check it)
    times: np.ndarray = field(default=None, repr=False)      # type: ignore[arg-type]
    positions: np.ndarray = field(default=None, repr=False)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        if self.kind not in MOTION_PROFILES:
            raise SetupError(f"sweep.profile: must be one of {', '.join(MOTION_PROFILES)}, "
                             f"got {self.kind!r}")

    # -- constructors -------------------------------------------------------------------
    @classmethod
    def linear(cls, start: float, end: float) -> MotionProfile:
        """Constant velocity from ``start`` to ``end`` (mm); ``start == end`` is refused.

        Parameters
        ----------
        start : float
            Sensor distance when the shutter opens, mm (finite, > 0).
        end : float
            Sensor distance when it closes, mm (finite, > 0, != ``start``).
        """
        s, e = _check_distance(start, "start"), _check_distance(end, "end")
        if s == e:
            raise SetupError(f"motion: empty sweep (start = end = {s:g} mm); a focal sweep "
                             f"needs start != end")
        return cls("linear", s, e)

    @classmethod
    def trapezoidal(cls, start: float, end: float, accel_fraction: float) -> MotionProfile:
        """Accelerate for ``accel_fraction`` of the exposure, cruise, decelerate.

        With ``a = accel_fraction`` and ``Δ = end − start`` the peak normalised velocity
        is ``Δ / (1 − a)``; ``i(t) = start + Δ t² / (2 a (1 − a))`` for ``t < a``,
        ``start + Δ (t − a/2) / (1 − a)`` in the cruise, symmetric at the end.

        Parameters
        ----------
        start : float
            Sensor distance when the shutter opens, mm (finite, > 0).
        end : float
            Sensor distance when it closes, mm (finite, > 0, != ``start``).
        accel_fraction : float
            Fraction ``a`` of the exposure spent in each ramp, in (0, 0.5] (0.5: a
            triangular velocity profile).
        """
        s, e = _check_distance(start, "start"), _check_distance(end, "end")
        if s == e:
            raise SetupError(f"motion: empty sweep (start = end = {s:g} mm)")
        a = float(accel_fraction)
        if not (0.0 < a <= 0.5):
            raise SetupError(f"motion.accel_fraction: must be in (0, 0.5], got {accel_fraction!r}")
        return cls("trapezoidal", s, e, accel_fraction=a)

    @classmethod
    def tabulated(cls, times: ArrayLike, positions: ArrayLike) -> MotionProfile:
        """Piecewise-linear profile through measured ``(times, positions)``.

        Parameters
        ----------
        times : (n,) array_like
            Strictly increasing sample times (any unit, e.g. seconds of a rig log);
            rescaled to [0, 1] over the exposure.
        positions : (n,) array_like
            Sensor distance at each time, mm (> 0, finite). n >= 2.
        """
        t = np.asarray(times, dtype=float).ravel()
        p = np.asarray(positions, dtype=float).ravel()
        if t.shape != p.shape or t.size < 2:
            raise SetupError(f"motion: a tabulated profile needs >= 2 (time, position) pairs "
                             f"of equal length, got {t.size} times and {p.size} positions")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
            raise SetupError("motion: tabulated times and positions must be finite")
        if np.any(p <= 0):
            raise SetupError(f"motion: tabulated positions are sensor distances and must be "
                             f"> 0 mm, got min {p.min():g}")
        if np.any(np.diff(t) <= 0):
            raise SetupError("motion: tabulated times must be strictly increasing")
        if np.ptp(p) == 0:
            raise SetupError(f"motion: empty sweep (all positions = {p[0]:g} mm)")
        tn = (t - t[0]) / (t[-1] - t[0])
        tn[-1] = 1.0
        return cls("tabulated", float(p[0]), float(p[-1]), times=tn, positions=p)

    def _trapezoid(self) -> Trapezoid:
        """The trapezoidal profile as a move over the normalised exposure (duration 1)."""
        return Trapezoid.with_accel_fraction(abs(self.end - self.start), 1.0,
                                             self.accel_fraction)

    # -- evaluation ---------------------------------------------------------------------
    def sensor_distance(self, t: ArrayLike) -> float | NDArray[np.float64]:
        """Sensor distance (mm) at normalised time(s) ``t`` ∈ [0, 1] (clipped), vectorised.

        Parameters
        ----------
        t : float or array_like
            Normalised exposure time(s): 0 = shutter opens, 1 = closes; a float gives a
            float.
        """
        tc = np.clip(np.asarray(t, dtype=float), 0.0, 1.0)
        delta = self.end - self.start
        out: NDArray[np.float64]
        if self.kind == "linear":
            out = self.start + delta * tc
        elif self.kind == "trapezoidal":
            move = self._trapezoid()   # its duration is 1 up to rounding: t scaled onto it
            out = self.start + np.sign(delta) * np.asarray(move.position_at(tc * move.duration))
        else:
            out = np.asarray(np.interp(tc, self.times, self.positions))
        return out if out.ndim else float(out)

    def velocity(self, t: ArrayLike) -> float | NDArray[np.float64]:
        """d i / d t in mm per unit normalised time (multiply by 1/exposure_s for mm/s).

        Parameters
        ----------
        t : float or array_like
            Normalised exposure time(s) in [0, 1] (clipped); a float gives a float.
        """
        tc = np.clip(np.asarray(t, dtype=float), 0.0, 1.0)
        delta = self.end - self.start
        out: NDArray[np.float64]
        if self.kind == "linear":
            out = np.full_like(tc, delta)
        elif self.kind == "trapezoidal":
            # velocity_at is 0 at the very ends, where the ramps' own limit is also 0
            move = self._trapezoid()
            out = np.sign(delta) * move.duration * np.asarray(move.velocity_at(tc * move.duration))
        else:
            j = np.clip(np.searchsorted(self.times, tc, side="right") - 1, 0, len(self.times) - 2)
            out = np.diff(self.positions)[j] / np.diff(self.times)[j]
        return out if out.ndim else float(out)

    @property
    def span(self) -> tuple[float, float]:
        """(min, max) sensor distance reached during the exposure, mm."""
        if self.kind == "tabulated":
            return float(self.positions.min()), float(self.positions.max())
        return min(self.start, self.end), max(self.start, self.end)

    @property
    def midpoint(self) -> float:
        """Mid-travel sensor distance, mm: the reference distance of IPSFs (docs/design.md)."""
        lo, hi = self.span
        return 0.5 * (lo + hi)

    def segments(self, n: int = 32) -> tuple[np.ndarray, np.ndarray]:
        """A piecewise-linear description of ``i(t)`` for exact segment deposition.

        Parameters
        ----------
        n : int, optional
            Trapezoidal only: chords per ramp, >= 1 (default 32); ignored by the other
            kinds, whose description is exact.

        Returns
        -------
        times, positions : (m + 1,) ndarray
            Knots; ``i(t)`` is linear between consecutive knots. Exact for ``linear``
            (one segment) and ``tabulated`` (its knots); for ``trapezoidal`` each ramp is
            split into ``n`` chords (error bound in Notes).

        Notes
        -----
        A chord of the parabola ``v t²/(2a)`` over a step h deviates from it by at most
        ``v h² / (8 a)``; with ``h = a / n`` that is ``|Δ| a / (8 n² (1 − a))`` mm.
        """
        if self.kind == "linear":
            t = np.array([0.0, 1.0])
        elif self.kind == "tabulated":
            return self.times.copy(), self.positions.copy()
        else:
            if n < 1:
                raise ValueError(f"segments: n must be >= 1, got {n}")
            a = self.accel_fraction
            ramp = np.linspace(0.0, a, n + 1)
            t = np.unique(np.concatenate([ramp, 1.0 - ramp[::-1]]))
        return t, np.asarray(self.sensor_distance(t), dtype=float)

    def sample(self, n: int, *, rng: np.random.Generator | None = None) -> np.ndarray:
        """``n`` stratified times' sensor distances (mm): one jittered sample per stratum,
        or stratum centres when ``rng`` is None.

        Parameters
        ----------
        n : int
            Number of strata of [0, 1], >= 1.
        rng : numpy.random.Generator, optional
            Draws each time uniformly within its stratum; None (default) takes the
            centres, deterministic.
        """
        if n < 1:
            raise ValueError(f"sample: n must be >= 1, got {n}")
        u = 0.5 if rng is None else rng.random(n)
        t = (np.arange(n) + u) / n
        return np.asarray(self.sensor_distance(t), dtype=float)

    def as_dict(self) -> dict:
        """Provenance (JSON-serialisable)."""
        d = {"kind": self.kind, "start_mm": self.start, "end_mm": self.end}
        if self.kind == "trapezoidal":
            d["accel_fraction"] = self.accel_fraction
        if self.kind == "tabulated":
            d["times"] = self.times.tolist()
            d["positions_mm"] = self.positions.tolist()
        return d


def motion_for(setup: Setup, sweep_range: SweepRange | None = None, *,
               table: tuple[ArrayLike, ArrayLike] | None = None) -> MotionProfile:
    """The stage motion a setup asks for, over a sweep range.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        ``setup.sweep.profile`` picks the kind; ``setup.sweep.velocity`` (mm/s) and
        ``setup.rig.acceleration`` (mm/s²) set the trapezoidal ramps.
    sweep_range : mitsweep.optics.SweepRange, optional
        Default: :func:`mitsweep.optics.optimal_sweep_range` of the setup. The sensor
        moves from ``sensor_start`` (focus at focus_min) to ``sensor_end``.
    table : (times, positions), optional
        Required for ``profile = "tabulated"``: a measured rig log, positions as sensor
        distances in mm.

    Notes
    -----
    Trapezoidal: the stage ramps to the sweep velocity ``v`` at acceleration ``A`` in
    ``v/A`` seconds over ``v²/(2A)`` mm. If the two ramps fit in the travel ``Δ``, the
    exposure is ``Δ/v + v/A`` and ``accel_fraction = (v/A) / (Δ/v + v/A)``; otherwise the
    profile is triangular (``accel_fraction = 0.5``). See
    :class:`mitsweep.optics.kinematics.Trapezoid`.
    """
    if sweep_range is None:
        from .sweep import optimal_sweep_range

        sweep_range = optimal_sweep_range(setup)
    start, end = sweep_range.sensor_start, sweep_range.sensor_end
    kind = setup.sweep.profile
    if kind == "linear":
        return MotionProfile.linear(start, end)
    if kind == "trapezoidal":
        move = Trapezoid(abs(end - start), setup.sweep.velocity, setup.rig.acceleration)
        return MotionProfile.trapezoidal(start, end, move.accel_fraction)
    if kind == "tabulated":
        if table is None:
            raise SetupError("sweep.profile: 'tabulated' needs a measured motion table "
                             "(times, sensor positions in mm), e.g. from a rig log")
        times, positions = table
        return MotionProfile.tabulated(times, positions)
    raise SetupError(f"sweep.profile: must be one of {', '.join(MOTION_PROFILES)}, got {kind!r}")
