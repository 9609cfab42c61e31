"""From a motion profile to a step-rate table the controllers run (pure, no I/O).

An optimised sweep (``mitsweep design-sweep``) is a :class:`~mitsweep.optics.motion.MotionProfile`:
the sensor distance ``i(t)`` over the normalised exposure, piecewise linear between its
knots. The stage runs it as a *step-rate table*: segment ``k`` moves ``n_k`` whole steps
(microsteps on a Zaber stage) at a constant rate in ``T_k`` seconds, so the commanded
travel is piecewise linear through the cumulative knots ``(Σ T_j, Σ n_j)``.

Quantisation (what the table differs from the profile by)
---------------------------------------------------------
- positions: each knot's travel is rounded to the nearest step (cumulatively, so the
  error never accumulates): ≤ 0.5 step at the knots; the stepper's position between
  steps is the floor of its travel, so the stage is within 1.5 steps of the profile;
- times: Arduino segments last whole microseconds of its ``micros()`` timer (knot times
  rounded cumulatively: ≤ 0.5 µs); a Zaber segment lasts its step count over the speed
  its ``maxspeed`` data value gives (1/1.6384 microstep/s resolution), which the table
  keeps exactly: the exposure is the sum;
- profiles with more segments than the board holds
  (:data:`~mitsweep.rig.arduino.MAX_TABLE_SEGMENTS`) are re-knotted at evenly spaced times: the chord error is reported.

:attr:`ProfileTable.max_deviation_steps` is the largest difference between the table's
travel and the profile's over the exposure (exact: both are piecewise linear, compared
at every knot of either).

What the stage can follow
-------------------------
The profile's velocity in each segment ``v_k`` must not exceed ``rig.max_velocity`` (and
the controller's top rate), and the change between consecutive segments must be
reachable at ``rig.acceleration`` ``A`` between the segments' midpoints:

.. math:: |v_{k+1} - v_k| \\le A \\, \\frac{T_k + T_{k+1}}{2}.

A stepper takes such a change as a rate jump of at most that size (the Arduino
firmware); a stage that ramps at ``A`` centred on the knot deviates from the table by
at most ``|Δv|² / (8 A)``, reported as :attr:`ProfileTable.ramp_deviation_mm`. The
first and last segments must move (the stage ramps from rest to the entry rate before
the shutter opens and from the exit rate to rest after it closes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import PlanError

__all__ = ["ProfileTable", "profile_knots", "quantise_table", "check_followable",
           "KNOTS_PER_RAMP"]

#: Chords per ramp when a trapezoidal profile is turned into knots.
KNOTS_PER_RAMP = 16
#: Relative slack on the stage limits, as :mod:`mitsweep.optics.motion_file` allows: a
#: profile designed exactly at a limit (an optimiser's active constraint) passes.
LIMIT_RTOL = 1e-6


@dataclass(frozen=True)
class ProfileTable:
    """A step-rate table: segment ``k`` moves ``steps[k]`` steps (>= 0, along the plan's
    direction) in ``durations_s[k]`` seconds at a constant rate, from the step at which
    the shutter opens; the shutter closes on its last step.

    ``driver`` holds each segment in the controller's units: Arduino ``duration_us``;
    Zaber ``maxspeed`` data values. ``knot_times_s`` / ``knot_travel_steps`` are the
    profile's own knots (time from shutter open, travel from the open step, unrounded).
    """

    stage: str
    steps: tuple[int, ...]
    durations_s: tuple[float, ...]
    driver: tuple[int, ...]
    knot_times_s: tuple[float, ...]
    knot_travel_steps: tuple[float, ...]
    max_deviation_steps: float
    ramp_deviation_mm: float
    resample_deviation_mm: float
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

    def travel_at(self, t_s):
        """Commanded travel (steps, continuous) ``t_s`` seconds after the shutter opened;
        the stepper stands at its floor."""
        t, x = self.cumulative()
        return np.interp(np.asarray(t_s, dtype=float), t, x)

    def as_dict(self) -> dict:
        return {"stage": self.stage, "segments": len(self.steps),
                "steps": list(self.steps), "durations_s": list(self.durations_s),
                "driver": list(self.driver), "total_steps": self.total_steps,
                "duration_s": self.duration_s, "entry_rate_steps_s": self.entry_rate,
                "exit_rate_steps_s": self.exit_rate,
                "max_deviation_steps": self.max_deviation_steps,
                "ramp_deviation_mm": self.ramp_deviation_mm,
                "resample_deviation_mm": self.resample_deviation_mm,
                "max_velocity_mm_s": self.max_velocity_mm_s,
                "max_acceleration_mm_s2": self.max_acceleration_mm_s2,
                "knot_times_s": list(self.knot_times_s),
                "knot_travel_steps": list(self.knot_travel_steps)}


def profile_knots(motion, *, max_segments: int, focal_length_mm: float
                  ) -> tuple[np.ndarray, np.ndarray, float]:
    """The profile's knots ``(t ∈ [0, 1], sensor distance mm)``, checked: monotonic,
    moving, beyond the focal length; re-knotted at ``max_segments`` evenly spaced times
    when it has more. Returns the knots and the re-knotting's chord error (mm)."""
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
    if p.min() <= focal_length_mm:
        raise PlanError(f"motion profile: its span {p.min():.4f} .. {p.max():.4f} mm reaches "
                        f"the lens's focal length ({focal_length_mm:g} mm): every sensor "
                        f"distance must be > lens.focal_length")
    chord = 0.0
    if t.size - 1 > max_segments:
        tn = np.linspace(0.0, 1.0, max_segments + 1)
        pn = np.asarray(motion.sensor_distance(tn), dtype=float)
        chord = float(np.max(np.abs(np.interp(t, tn, pn) - p)))
        t, p = tn, pn
    return t, p, chord


def check_followable(times_s: np.ndarray, travel_mm: np.ndarray, *, max_velocity: float,
                     acceleration: float, sensor_mm: np.ndarray) -> tuple[float, float, float]:
    """Refuse (:class:`PlanError`) what the stage cannot follow (module docstring).

    ``travel_mm`` is the stage travel from the shutter's opening along the motion,
    non-decreasing. Returns (largest velocity mm/s, largest acceleration mm/s², the
    centred-ramp deviation bound mm)."""
    dt = np.diff(times_s)
    if np.any(dt <= 0):
        raise PlanError("motion profile: knot times must be strictly increasing")
    v = np.diff(travel_mm) / dt
    k = int(np.argmax(v))
    if v[k] > max_velocity * (1 + LIMIT_RTOL):
        raise PlanError(f"motion profile: the stage cannot follow it: {v[k]:.4g} mm/s at "
                        f"{sensor_mm[k]:.4f} .. {sensor_mm[k + 1]:.4f} mm (t = "
                        f"{times_s[k]:.4f} s), more than rig.max_velocity = "
                        f"{max_velocity:g} mm/s; lengthen the exposure")
    if v[0] <= 0 or v[-1] <= 0:
        end = "starts" if v[0] <= 0 else "ends"
        raise PlanError(f"motion profile: it {end} at rest; the shutter must open and "
                        f"close with the stage moving (drop the dwell knots)")
    if v.size < 2:
        return float(v.max()), 0.0, 0.0
    dv = np.abs(np.diff(v))
    acc = dv / (0.5 * (dt[:-1] + dt[1:]))
    j = int(np.argmax(acc))
    if acc[j] > acceleration * (1 + LIMIT_RTOL):
        raise PlanError(f"motion profile: the stage cannot follow it: the velocity changes "
                        f"from {v[j]:.4g} to {v[j + 1]:.4g} mm/s at {sensor_mm[j + 1]:.4f} mm "
                        f"(t = {times_s[j + 1]:.4f} s), {acc[j]:.4g} mm/s^2, more than "
                        f"rig.acceleration = {acceleration:g} mm/s^2")
    return float(v.max()), float(acc.max()), float(np.max(dv) ** 2 / (8 * acceleration))


def quantise_table(times_s: np.ndarray, travel_steps: np.ndarray, *, stage: str,
                   max_step_rate: float | None, speed_unit: float, max_segment_steps: int
                   ) -> tuple[tuple[int, ...], tuple[float, ...], tuple[int, ...]]:
    """Whole steps per segment, and each segment's time as the controller runs it.

    ``travel_steps``: the profile's travel from the open step at ``times_s`` (unrounded).
    Returns (steps, durations s, driver values): Arduino durations in whole µs; Zaber
    ``maxspeed`` data values (``speed_unit`` per microstep/s) and the durations they give.
    """
    cum = np.rint(travel_steps).astype(np.int64)
    steps = np.diff(cum)
    if np.any(steps > max_segment_steps):
        k = int(np.argmax(steps))
        raise PlanError(f"motion profile: segment {k} moves {steps[k]} steps, more than the "
                        f"{max_segment_steps} one segment holds; add knots")
    if steps[0] < 1 or steps[-1] < 1:
        raise PlanError("motion profile: its first and last segments must each move at "
                        "least one step (the shutter opens and closes on a step)")
    if stage == "arduino":
        us = np.diff(np.rint(np.asarray(times_s) * 1e6).astype(np.int64))
        if np.any(us < 1):
            raise PlanError("motion profile: a segment shorter than 1 µs (the board's timer)")
        rate = steps * 1e6 / us
        if max_step_rate is not None and np.any(rate > max_step_rate):
            k = int(np.argmax(rate))
            raise PlanError(f"motion profile: segment {k} needs {rate[k]:.1f} steps/s; the "
                            f"Arduino controller runs at most {max_step_rate:g} steps/s")
        return (tuple(int(s) for s in steps), tuple(float(u) * 1e-6 for u in us),
                tuple(int(u) for u in us))
    if np.any(steps < 1):
        k = int(np.argmin(steps))
        raise PlanError(f"motion profile: segment {k} moves no microstep (a dwell), which "
                        f"a Zaber stream line cannot run; merge it with its neighbours")
    dt = np.diff(np.asarray(times_s, dtype=float))
    data = np.maximum(1, np.rint(steps / dt * speed_unit)).astype(np.int64)
    durations = steps / (data / speed_unit)
    return (tuple(int(s) for s in steps), tuple(float(d) for d in durations),
            tuple(int(d) for d in data))


def max_deviation(table_t: np.ndarray, table_x: np.ndarray, knot_t: np.ndarray,
                  knot_x: np.ndarray) -> float:
    """Largest |table − profile| of two piecewise-linear travels (steps), exact: at every
    knot of either (each is linear between the union of the knots)."""
    t = np.union1d(table_t, knot_t)
    t = t[(t >= 0) & (t <= min(table_t[-1], knot_t[-1]))]
    return float(np.max(np.abs(np.interp(t, table_t, table_x) - np.interp(t, knot_t, knot_x))))


def ramp_steps(rate: float, accel: float) -> int:
    """Steps to ramp from rest to ``rate`` at ``accel`` (ceil, as the firmware checks)."""
    return math.ceil(rate * rate / (2.0 * accel) - 1e-9)
