"""From a motion profile to a step-rate table the controllers run (pure, no I/O).

An optimised sweep (``mitsweep design-sweep``) is a :class:`~mitsweep.optics.motion.MotionProfile`:
the sensor distance ``i(t)`` over the normalised exposure, piecewise linear between its
knots. The stage runs it as a *step-rate table*: segment ``k`` moves ``n_k`` whole steps
(microsteps on a Zaber stage) at a constant rate in ``T_k`` seconds, so the commanded
travel is piecewise linear through the cumulative knots ``(Σ T_j, Σ n_j)``.

Quantisation (what the table differs from the profile by)
---------------------------------------------------------
- placement: the shutter opens on a whole step, the one nearest the profile's start:
  the profile is placed within half a step (:attr:`ProfileTable.offset_steps`), as the
  linear sweep's window is;
- shape: segment boundaries lie where the profile crosses a whole step next to each of
  its knots (the one crossed nearest in time: its own step times), the last at the
  exposure's end; a segment's rate is then the profile's mean velocity between two of
  its step crossings, never more than its peak, and the travel between boundaries
  differs from the profile's only by the bend of a knot less than one step's time
  (at the faster side) from a boundary: under a step (knots within a step share one);
- times: Arduino segments last whole microseconds of its ``micros()`` timer (cumulative
  rounding: no drift); a Zaber segment lasts its microsteps over the speed of its
  ``maxspeed`` data value (1/1.6384 microstep/s resolution), chosen so that each
  boundary comes nearest its time given the earlier segments' (no drift either);
- profiles with more knots than the board holds
  (:data:`~mitsweep.rig.arduino.MAX_TABLE_SEGMENTS`) are re-knotted at evenly spaced
  times: the chord error is reported.

:attr:`ProfileTable.max_deviation_steps` is the largest difference between the table's
travel and the profile's shape over the exposure (exact: both are piecewise linear,
compared at every knot of either); a plan refuses more than :data:`TOLERANCE_STEPS`
(or :data:`TOLERANCE_MM`, where that is more steps).
The stepper stands at the floor of its travel: one step more between steps.

What the stage can follow
-------------------------
The profile's velocity in each interval ``v_k`` (duration ``T_k``) must not exceed
``rig.max_velocity`` (and the controller's top rate), must not be 0 (a dwell is no
sweep), and the change at each knot must fit, at ``rig.acceleration`` ``A``, within the
shorter of the two intervals beside it:

.. math:: |v_{k+1} - v_k| \\le A \\, \\min(T_k, T_{k+1}).

A ramp centred on the knot then takes at most half of each interval (ramps never
overlap), and a stage that ramps so deviates from the profile by at most ``|Δv|² /
(8 A)`` between knots (:attr:`ProfileTable.ramp_deviation`); the Arduino's stepper
takes the change as a rate jump of at most ``A T_min``. For knots evenly spaced in
sensor distance (``Δi``), as ``design-sweep`` writes them, the rule is ``v |Δv| <= A Δi``
at the faster side: the stage's ``v dv/dx <= A``. (The mean of the two intervals in
place of the shorter would let a profile jump from a slow, long interval to a fast,
short one that no stage at ``A`` reaches in time.) The first and last intervals must
move: the stage ramps from rest to the entry rate before the shutter opens and from
the exit rate to rest after it closes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_fields, renamed_keywords

from ..optics.motion import MotionProfile
from .errors import PlanError

__all__ = ["ProfileTable", "profile_knots", "quantise_table", "check_followable",
           "max_deviation", "ramp_steps", "KNOTS_PER_RAMP", "LIMIT_RTOL", "TOLERANCE_STEPS",
           "TOLERANCE_MM"]

#: Chords per ramp when a trapezoidal profile is turned into knots.
KNOTS_PER_RAMP = 16
#: Largest deviation of a table from its profile's shape that a plan accepts: one step,
#: or 1 µm where steps are finer (a Zaber microstep is ~0.05 µm; a speed quantum over a
#: long slow segment moves the next boundary by ~10 µs, ~0.5 µm at 10 mm/s). 1 µm is a
#: few % of the depth of focus (2 N × pixel = 36 µm at F2.8, 6.4 µm pixels).
TOLERANCE_STEPS = 1.0
TOLERANCE_MM = 1e-3
#: Relative slack on the stage limits, as :mod:`mitsweep.optics.motion_file` allows: a
#: profile designed exactly at a limit (an optimiser's active constraint) passes.
LIMIT_RTOL = 1e-6


@renamed_fields(ramp_deviation_mm="ramp_deviation",
                resample_deviation_mm="resample_deviation")
@dataclass(frozen=True)
class ProfileTable:
    """A step-rate table: segment ``k`` moves ``steps[k]`` steps (>= 0, along the plan's
    direction) in ``durations_s[k]`` seconds at a constant rate, from the step at which
    the shutter opens; the shutter closes on its last step.

    ``driver`` holds each segment in the controller's units: Arduino ``duration_us``;
    Zaber ``maxspeed`` data values. ``knot_times_s`` / ``knot_travel_steps`` are the
    profile's own knots (time from shutter open, travel from the open step, unrounded);
    ``offset_steps`` (the first knot's travel, in [-0.5, 0.5]) is where the profile
    starts relative to the open step, and ``max_deviation_steps`` the table's largest
    difference from the profile's shape (``knot_travel_steps - offset_steps``).

    Attributes
    ----------
    stage : str
        ``"arduino"`` or ``"zaber"``: whose units ``driver`` is in.
    steps : tuple of int
        Steps (or microsteps) of each segment, >= 0.
    durations_s : tuple of float
        Duration of each segment as the controller runs it, s.
    driver : tuple of int
        Each segment in the controller's units: Arduino ``duration_us``, Zaber
        ``maxspeed`` data values.
    knot_times_s : tuple of float
        The profile's knots: time from the shutter's opening, s.
    knot_travel_steps : tuple of float
        The profile's travel at its knots from the open step, steps (unrounded).
    offset_steps : float
        The first knot's travel: where the profile starts relative to the open step, in
        [-0.5, 0.5] steps.
    max_deviation_steps : float
        The table's largest difference from the profile's shape, steps.
    ramp_deviation : float
        Bound on how far a stage that ramps between rates (centred on each knot) leaves
        the profile, mm (``|Δv|² / (8 A)``).
    resample_deviation : float
        Chord error of re-knotting a profile with more knots than a table holds, mm (0:
        not re-knotted).
    max_velocity_mm_s : float
        The profile's largest velocity, mm/s.
    max_acceleration_mm_s2 : float
        Its largest acceleration as the followability rule measures it, mm/s².
    """

    stage: str
    steps: tuple[int, ...]
    durations_s: tuple[float, ...]
    driver: tuple[int, ...]
    knot_times_s: tuple[float, ...]
    knot_travel_steps: tuple[float, ...]
    offset_steps: float
    max_deviation_steps: float
    ramp_deviation: float
    resample_deviation: float
    max_velocity_mm_s: float
    max_acceleration_mm_s2: float

    @property
    def total_steps(self) -> int:
        return int(sum(self.steps))

    @property
    def duration_s(self) -> float:
        return float(sum(self.durations_s))

    @property
    def entry_rate(self) -> float:
        """Step rate of the first segment (steps/s): run before the shutter opens."""
        return self.steps[0] / self.durations_s[0]

    @property
    def exit_rate(self) -> float:
        """Step rate of the last segment (steps/s): run after the shutter closes."""
        return self.steps[-1] / self.durations_s[-1]

    def cumulative(self) -> tuple[np.ndarray, np.ndarray]:
        """Segment boundaries: (times s from shutter open, travel steps), each (n + 1,)."""
        t = np.concatenate([[0.0], np.cumsum(self.durations_s)])
        x = np.concatenate([[0], np.cumsum(self.steps)]).astype(float)
        return t, x

    def travel_at(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """Commanded travel (steps, continuous) ``t_s`` seconds after the shutter opened;
        the stepper stands at its floor.

        Parameters
        ----------
        t_s : array_like
            Times from the shutter's opening, s (clamped to the table's span).

        Returns
        -------
        ndarray
            Travel from the open step, steps, of the shape of ``t_s``.
        """
        t, x = self.cumulative()
        return np.interp(np.asarray(t_s, dtype=float), t, x)

    def as_dict(self) -> dict:
        return {"stage": self.stage, "segments": len(self.steps),
                "steps": list(self.steps), "durations_s": list(self.durations_s),
                "driver": list(self.driver), "total_steps": self.total_steps,
                "duration_s": self.duration_s, "entry_rate_steps_s": self.entry_rate,
                "exit_rate_steps_s": self.exit_rate,
                "offset_steps": self.offset_steps,
                "max_deviation_steps": self.max_deviation_steps,
                "ramp_deviation_mm": self.ramp_deviation,
                "resample_deviation_mm": self.resample_deviation,
                "max_velocity_mm_s": self.max_velocity_mm_s,
                "max_acceleration_mm_s2": self.max_acceleration_mm_s2,
                "knot_times_s": list(self.knot_times_s),
                "knot_travel_steps": list(self.knot_travel_steps)}


@renamed_keywords(focal_length_mm="focal_length")
def profile_knots(motion: MotionProfile, *, max_segments: int, focal_length: float
                  ) -> tuple[np.ndarray, np.ndarray, float]:
    """The profile's knots ``(t ∈ [0, 1], sensor distance mm)``, checked: monotonic,
    moving, beyond the focal length; re-knotted at ``max_segments`` evenly spaced times
    when it has more. Returns the knots and the re-knotting's chord error (mm).

    Parameters
    ----------
    motion : mitsweep.optics.motion.MotionProfile
        The profile (its ramps as :data:`KNOTS_PER_RAMP` chords each).
    max_segments : int
        Most segments a table holds: a profile with more is re-knotted.
    focal_length : float
        The lens's focal length, mm: every sensor distance must exceed it.

    Returns
    -------
    t : (n,) ndarray
        Knot times, normalised to the exposure (0 .. 1).
    p : (n,) ndarray
        Sensor distances at the knots, mm.
    chord : float
        The re-knotting's chord error, mm (0: not re-knotted).

    Raises
    ------
    PlanError
        Fewer than two finite knots, no motion, a profile that turns back, or one that
        reaches the focal length.
    """
    t, p = motion.segments(KNOTS_PER_RAMP)
    t, p = np.asarray(t, dtype=float), np.asarray(p, dtype=float)
    if t.size < 2 or not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise PlanError(f"motion profile: needs >= 2 finite (time, sensor distance) knots, "
                        f"got {t.size}")
    d = np.diff(p)
    if np.all(d == 0):
        raise PlanError(f"motion profile: empty sweep (every sensor distance is "
                        f"{p[0]:g} mm)")
    if np.any(d > 0) and np.any(d < 0):
        k = int(np.flatnonzero(np.sign(d) != np.sign(d[np.flatnonzero(d)[0]]))[0])
        raise PlanError(f"motion profile: sensor distances must be monotonic (the stage "
                        f"runs one way during the exposure); it turns back at knot {k + 1} "
                        f"({p[k + 1]:.4f} mm at t = {t[k + 1]:.4f})")
    if p.min() <= focal_length:
        raise PlanError(f"motion profile: its span {p.min():.4f} .. {p.max():.4f} mm reaches "
                        f"the lens's focal length ({focal_length:g} mm): every sensor "
                        f"distance must be > lens.focal_length")
    chord = 0.0
    if t.size - 1 > max_segments:
        tn = np.linspace(0.0, 1.0, max_segments + 1)
        pn = np.asarray(motion.sensor_distance(tn), dtype=float)
        chord = float(np.max(np.abs(np.interp(t, tn, pn) - p)))
        t, p = tn, pn
    return t, p, chord


@renamed_keywords(travel_mm="travel", sensor_mm="sensor_distance")
def check_followable(times_s: np.ndarray, travel: np.ndarray, *, max_velocity: float,
                     acceleration: float, sensor_distance: np.ndarray) -> tuple[float, float, float]:
    """Refuse (:class:`PlanError`) what the stage cannot follow (module docstring).

    ``travel`` is the stage travel from the shutter's opening along the motion,
    non-decreasing. Returns (largest velocity mm/s, largest acceleration mm/s² as the
    rule measures it, the centred-ramp deviation bound mm).

    Parameters
    ----------
    times_s : (n,) ndarray
        Knot times from the shutter's opening, s (strictly increasing).
    travel : (n,) ndarray
        Stage travel at the knots from the shutter's opening, mm, non-decreasing.
    max_velocity : float
        The stage's top velocity, mm/s (``rig.max_velocity``).
    acceleration : float
        The stage's acceleration, mm/s² (``rig.acceleration``).
    sensor_distance : (n,) ndarray
        Sensor distances at the knots, mm (for the messages).

    Raises
    ------
    PlanError
        Times not increasing, a velocity above the limit, a dwell, or a velocity change
        the stage cannot make within the shorter of its two intervals.
    """
    dt = np.diff(times_s)
    if np.any(dt <= 0):
        raise PlanError("motion profile: knot times must be strictly increasing")
    v = np.diff(travel) / dt
    k = int(np.argmax(v))
    if v[k] > max_velocity * (1 + LIMIT_RTOL):
        raise PlanError(f"motion profile: the stage cannot follow it: {v[k]:.4g} mm/s at "
                        f"{sensor_distance[k]:.4f} .. {sensor_distance[k + 1]:.4f} mm (t = "
                        f"{times_s[k]:.4f} s), more than rig.max_velocity = "
                        f"{max_velocity:g} mm/s; lengthen the exposure")
    if np.any(v <= 0):
        k = int(np.flatnonzero(v <= 0)[0])
        raise PlanError(f"motion profile: the sensor rests at {sensor_distance[k]:.4f} mm from "
                        f"t = {times_s[k]:.4f} to {times_s[k + 1]:.4f} s; a sweep moves "
                        f"throughout the exposure (drop the dwell)")
    if v.size < 2:
        return float(v.max()), 0.0, 0.0
    dv = np.abs(np.diff(v))
    acc = dv / np.minimum(dt[:-1], dt[1:])
    j = int(np.argmax(acc))
    if acc[j] > acceleration * (1 + LIMIT_RTOL):
        raise PlanError(f"motion profile: the stage cannot follow it: the velocity changes "
                        f"from {v[j]:.4g} to {v[j + 1]:.4g} mm/s at {sensor_distance[j + 1]:.4f} mm "
                        f"(t = {times_s[j + 1]:.4f} s) within {min(dt[j], dt[j + 1]):.4g} s, "
                        f"{acc[j]:.4g} mm/s^2, more than rig.acceleration = "
                        f"{acceleration:g} mm/s^2")
    return float(v.max()), float(acc.max()), float(np.max(dv) ** 2 / (8 * acceleration))


def _first_crossings(times_s: np.ndarray, travel: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """When the (non-decreasing, piecewise-linear) ``travel`` first reaches each level."""
    j = np.clip(np.searchsorted(travel, levels, side="left"), 1, travel.size - 1)
    x0, x1 = travel[j - 1], travel[j]
    f = np.where(x1 > x0, (levels - x0) / np.where(x1 > x0, x1 - x0, 1.0), 1.0)
    return times_s[j - 1] + np.clip(f, 0.0, 1.0) * (times_s[j] - times_s[j - 1])


def quantise_table(times_s: np.ndarray, travel_steps: np.ndarray, *, stage: str,
                   max_rate: float, speed_unit: float, max_segment_steps: int,
                   max_segments: int
                   ) -> tuple[tuple[int, ...], tuple[float, ...], tuple[int, ...], float]:
    """Whole steps per segment, and each segment's time as the controller runs it.

    ``travel_steps``: the profile's travel at ``times_s`` (steps, unrounded, increasing),
    measured from where the shutter opens; the table starts from the open step, so its
    shape is ``travel_steps - travel_steps[0]``. Segment boundaries lie where that shape
    crosses a whole step next to each knot (the one crossed nearest in time: the
    profile's own step times), so every segment's rate is the profile's mean velocity
    between two of its step crossings, at most its peak: quantisation never asks for
    more than the profile does. The last boundary is the exposure's end. Returns (steps,
    durations s, driver values, the table's time at the last knot).

    Arduino durations are whole µs (cumulative rounding), at least the firmware's
    ``max_rate`` allows for their steps; Zaber segments get the ``maxspeed`` data value
    (``speed_unit`` per microstep/s) that brings each boundary nearest its time given
    the time the earlier segments took (no accumulated drift).

    Parameters
    ----------
    times_s : (n,) ndarray
        Knot times from the shutter's opening, s.
    travel_steps : (n,) ndarray
        The profile's travel at those times, steps (unrounded, increasing).
    stage : {"arduino", "zaber"}
        Which controller runs the table (how its times are quantised).
    max_rate : float
        The highest step rate allowed, steps/s.
    speed_unit : float
        Zaber ``maxspeed`` data value per microstep/s (unused for the Arduino).
    max_segment_steps : int
        Most steps one segment holds.
    max_segments : int
        Most segments a table holds.

    Raises
    ------
    PlanError
        Less than one step of travel, too many segments, or a segment too long.
    """
    shape = np.asarray(travel_steps, dtype=float) - float(travel_steps[0])
    t = np.asarray(times_s, dtype=float)
    exposure = float(t[-1])
    total = int(np.rint(shape[-1]))
    if total < 1:
        raise PlanError("motion profile: the stage moves less than one step during it")
    # at each inner knot, the whole step (below or above it) crossed nearest in time:
    # a boundary then sits on the profile, off its knot by less than one step's time at
    # the faster of the two velocities, so the knot's bend moves it by under a step
    inner, t_inner = shape[1:-1], t[1:-1]
    below, above = np.floor(inner), np.ceil(inner)
    t_below, t_above = _first_crossings(t, shape, below), _first_crossings(t, shape, above)
    pick = np.abs(t_above - t_inner) < np.abs(t_below - t_inner)
    levels = np.where(pick, above, below).astype(np.int64)
    keep = (levels > 0) & (levels < total)
    levels, first = np.unique(levels[keep], return_index=True)
    bounds = np.concatenate([[0], levels, [total]]).astype(np.int64)
    bt = np.concatenate([[0.0], np.where(pick, t_above, t_below)[keep][first], [exposure]])
    # the last segment: rounding its steps up must not ask for more than the limit
    if (bounds[-1] - bounds[-2]) / (bt[-1] - bt[-2]) > max_rate * (1 + LIMIT_RTOL):
        bounds[-1] = int(np.floor(shape[-1]))
        if bounds[-1] <= bounds[-2]:
            bounds, bt = np.delete(bounds, -2), np.delete(bt, -2)
    steps = np.diff(bounds)
    if steps.size > max_segments:
        raise PlanError(f"motion profile: {steps.size} segments of whole steps, more than "
                        f"the {max_segments} a table holds")
    if np.any(steps > max_segment_steps):
        k = int(np.argmax(steps))
        raise PlanError(f"motion profile: segment {k} moves {steps[k]} steps, more than the "
                        f"{max_segment_steps} one segment holds; add knots")
    if stage == "arduino":
        us = np.diff(np.rint(bt * 1e6).astype(np.int64))
        least = np.ceil(steps * 1e6 / max_rate - 1e-9).astype(np.int64)
        for k in range(us.size):          # µs rounding above the firmware's top rate
            deficit = least[k] - us[k]
            if deficit > 0:
                us[k] = least[k]
                if k + 1 < us.size and us[k + 1] - deficit >= least[k + 1]:
                    us[k + 1] -= deficit
        return (tuple(int(k) for k in steps), tuple(float(u) * 1e-6 for u in us),
                tuple(int(u) for u in us), exposure)
    data, durations, now = [], [], 0.0
    top = int(np.floor(max_rate * speed_unit * (1 + LIMIT_RTOL)))
    for k in range(steps.size):
        want = max(bt[k + 1] - now, 1e-9)
        d = int(min(max(1, round(steps[k] / want * speed_unit)), top))
        data.append(d)
        durations.append(steps[k] / (d / speed_unit))
        now += durations[-1]
    return (tuple(int(k) for k in steps), tuple(float(d) for d in durations),
            tuple(data), exposure)


def max_deviation(table_t: np.ndarray, table_x: np.ndarray, knot_t: np.ndarray,
                  knot_x: np.ndarray) -> float:
    """Largest ``|table − profile|`` of two piecewise-linear travels (steps), exact: at every
    knot of either (each is linear between the union of the knots).

    Parameters
    ----------
    table_t, table_x : (n,) ndarray
        The table's boundaries: times, s, and travel, steps.
    knot_t, knot_x : (m,) ndarray
        The profile's knots: times, s, and travel, steps.

    Returns
    -------
    float
        The largest difference, steps, over the span both cover.
    """
    t = np.union1d(table_t, knot_t)
    t = t[(t >= 0) & (t <= min(table_t[-1], knot_t[-1]))]
    return float(np.max(np.abs(np.interp(t, table_t, table_x) - np.interp(t, knot_t, knot_x))))


def ramp_steps(rate: float, accel: float) -> int:
    """Steps to ramp from rest to ``rate`` at ``accel`` (ceil, as the firmware checks).

    Parameters
    ----------
    rate : float
        The rate reached, steps/s.
    accel : float
        The acceleration, steps/s².
    """
    return math.ceil(rate * rate / (2.0 * accel) - 1e-9)
