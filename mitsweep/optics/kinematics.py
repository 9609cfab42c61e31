"""Point-to-point stage kinematics: the trapezoidal velocity profile (pure NumPy).

A stage that moves a distance ``D`` with top speed ``v`` and acceleration ``a``
accelerates at ``a``, cruises at ``v``, and decelerates at ``a`` to rest at the target.
Each ramp lasts ``t_r = v / a`` and covers ``d_r = v² / (2a)``. When the two ramps do
not fit (``v² / a > D``) the move never reaches ``v``: the profile is triangular, with
peak velocity ``√(a D)`` and ramps of ``√(D / a)`` s over ``D / 2`` each.

.. math::

    T = \\frac{D}{v} + \\frac{v}{a} \\quad (\\text{trapezoid}), \\qquad
    T = 2 \\sqrt{D / a} \\quad (\\text{triangle}).

One implementation for every user: the optical motion profile
(:func:`mitsweep.optics.motion.motion_for`), the capture plan and the host-timed
shutter (:mod:`mitsweep.rig`), and the simulated stages. Units are the caller's, as long
as they agree (mm, mm/s, mm/s², s; or steps, steps/s, steps/s², s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["Trapezoid"]


@dataclass(frozen=True)
class Trapezoid:
    """A move of ``distance`` from rest to rest, at most ``velocity``, at ``acceleration``.

    Parameters
    ----------
    distance : float
        Length of the move, >= 0 (a length unit: mm, steps).
    velocity : float
        Top speed, > 0 (length/s).
    acceleration : float
        Acceleration and deceleration, > 0 (length/s²).

    Examples
    --------
    >>> move = Trapezoid(10.0, velocity=2.0, acceleration=4.0)
    >>> move.ramp_time, move.ramp_distance, move.duration
    (0.5, 0.5, 5.5)
    >>> move.position_at(0.5), move.time_at(move.distance)
    (0.5, 5.5)
    """

    distance: float
    velocity: float
    acceleration: float

    def __post_init__(self) -> None:
        for name, value, lowest in (("distance", self.distance, 0.0),
                                    ("velocity", self.velocity, None),
                                    ("acceleration", self.acceleration, None)):
            ok = math.isfinite(value) and (value >= lowest if lowest is not None else value > 0)
            if not ok:
                rule = ">= 0" if lowest is not None else "> 0"
                raise ValueError(f"Trapezoid: {name} must be finite and {rule}, got {value!r}")

    @classmethod
    def reaching(cls, velocity: float, acceleration: float, *,
                 cruise_distance: float = 0.0) -> Trapezoid:
        """The move that ramps to ``velocity``, cruises ``cruise_distance`` and stops:
        its :attr:`ramp_time` and :attr:`ramp_distance` are those of a full ramp.

        Parameters
        ----------
        velocity : float
            Top speed, > 0 (length/s).
        acceleration : float
            Acceleration and deceleration, > 0 (length/s²).
        cruise_distance : float, optional
            Length covered at ``velocity`` between the ramps, >= 0 (default 0: the
            ramps meet at the top speed).
        """
        return cls(cruise_distance + velocity * velocity / acceleration, velocity,
                   acceleration)

    @classmethod
    def with_accel_fraction(cls, distance: float, duration: float,
                            accel_fraction: float) -> Trapezoid:
        """The move of ``distance`` in ``duration`` whose ramps each take
        ``accel_fraction`` of it, in (0, 0.5] (0.5: triangular): peak velocity
        ``D / (T (1 − f))``, acceleration ``D / (T² f (1 − f))``.

        Parameters
        ----------
        distance : float
            Length of the move D, >= 0 (a length unit: mm, steps).
        duration : float
            Time of the move T, > 0 (s, or 1 for a normalised exposure).
        accel_fraction : float
            Fraction f of ``duration`` spent in each ramp, in (0, 0.5].
        """
        f = accel_fraction
        if not 0.0 < f <= 0.5:
            raise ValueError(f"Trapezoid: accel_fraction must be in (0, 0.5], got {f!r}")
        v = distance / (duration * (1.0 - f))
        return cls(distance, v, v / (f * duration))

    # -- shape -----------------------------------------------------------------------------
    @property
    def is_triangular(self) -> bool:
        """True when the move is too short to reach :attr:`velocity`.

        Within a relative 1e-12 of ``v² = a D`` both shapes are the same move (no cruise,
        peak ``v``); the move counts as reaching ``v`` there, so that :meth:`reaching`
        with no cruise keeps its full ramp despite the rounding of ``v² / a``."""
        return self.velocity * self.velocity > self.acceleration * self.distance * (1 + 1e-12)

    @property
    def peak_velocity(self) -> float:
        """Highest speed reached: :attr:`velocity`, or ``√(a D)`` when triangular."""
        if self.is_triangular:
            return math.sqrt(self.acceleration * self.distance)
        return self.velocity

    @property
    def ramp_time(self) -> float:
        """Duration of each ramp (acceleration, and deceleration), s."""
        return self.peak_velocity / self.acceleration

    @property
    def ramp_distance(self) -> float:
        """Distance covered by each ramp: ``v² / (2a)``, or ``D / 2`` when triangular."""
        if self.is_triangular:
            return 0.5 * self.distance
        return self.velocity * self.velocity / (2.0 * self.acceleration)

    @property
    def cruise_time(self) -> float:
        """Time at constant :attr:`velocity` (0 when triangular), s."""
        if self.is_triangular:
            return 0.0
        return max(self.distance - 2.0 * self.ramp_distance, 0.0) / self.velocity

    @property
    def duration(self) -> float:
        """Time from start to rest at the target, s."""
        return 2.0 * self.ramp_time + self.cruise_time

    @property
    def accel_fraction(self) -> float:
        """Fraction of :attr:`duration` spent in each ramp, in (0, 0.5] (0.5 when
        triangular, and for a move of length 0, the triangle's limit)."""
        if self.distance == 0.0:
            return 0.5
        return self.ramp_time / self.duration

    # -- motion (scalars or arrays: a float in, a float out) ------------------------------
    def velocity_at(self, t: ArrayLike) -> float | NDArray[np.float64]:
        """Speed ``t`` seconds after the start (0 before and after the move).

        Parameters
        ----------
        t : float or array_like
            Time(s) since the start, s; a float gives a float.
        """
        t = np.asarray(t, dtype=float)
        ramps = self.acceleration * np.minimum(np.minimum(t, self.ramp_time), self.duration - t)
        return _out(np.where((t <= 0.0) | (t >= self.duration), 0.0, ramps))

    def position_at(self, t: ArrayLike) -> float | NDArray[np.float64]:
        """Distance covered ``t`` seconds after the start, in [0, :attr:`distance`]
        (``t`` is clipped to the move).

        Parameters
        ----------
        t : float or array_like
            Time(s) since the start, s; a float gives a float.
        """
        tau = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        t_r, a = self.ramp_time, self.acceleration
        rest = self.duration - tau
        return _out(np.where(
            tau <= t_r, 0.5 * a * tau * tau,
            np.where(tau <= t_r + self.cruise_time,
                     self.ramp_distance + self.peak_velocity * (tau - t_r),
                     self.distance - 0.5 * a * rest * rest)))

    def time_at(self, position: ArrayLike) -> float | NDArray[np.float64]:
        """When the move has covered ``position`` (clipped to [0, :attr:`distance`]):
        the inverse of :meth:`position_at`, s.

        Parameters
        ----------
        position : float or array_like
            Distance(s) covered since the start, in the move's length unit; a float
            gives a float.
        """
        d = np.clip(np.asarray(position, dtype=float), 0.0, self.distance)
        if self.distance == 0.0:        # no cruise velocity to divide by: it is over at once
            return _out(np.zeros_like(d))
        d_r, a = self.ramp_distance, self.acceleration
        return _out(np.where(
            d <= d_r, np.sqrt(2.0 * d / a),
            np.where(d <= self.distance - d_r,
                     self.ramp_time + (d - d_r) / self.peak_velocity,
                     self.duration - np.sqrt(2.0 * np.maximum(self.distance - d, 0.0) / a))))


def _out(x: np.ndarray):
    return x if x.ndim else float(x)
