"""From a setup's sweep range to a stage move: the capture plan (pure, no I/O).

The optical sweep (:func:`mitsweep.optics.optimal_sweep_range`) says the sensor must
travel from ``sensor_start`` to ``sensor_end`` at ``velocity_mm_s`` with the
shutter open, for ``exposure_s = translation / velocity_mm_s``. A real stage must
also accelerate to that velocity, run a little further so that vibrations settle, and
decelerate afterwards, all inside its soft limits:

.. math::

    x_\\mathrm{approach} = x_\\mathrm{open} - \\sigma (d_r + d_s), \\qquad
    x_\\mathrm{end} = x_\\mathrm{close} + \\sigma (d_s + d_r), \\qquad
    d_r = \\frac{v^2}{2 a},

with σ the direction of motion, d_s the settle distance and a the acceleration. The
shutter is open only between ``x_open`` and ``x_close``, at constant velocity.

Stage position x (mm, the stage's own coordinates) and sensor distance s (mm, lens to
sensor) are related by ``s = s_0 + δ x`` with ``s_0 = rig.sensor_distance_at_zero`` and
``δ = rig.sensor_direction``. An uncalibrated rig (no ``sensor_distance_at_zero``)
centres the sweep within the soft limits; the record says so.

Every check that can fail fails here, before a port is opened: a sweep longer than the
travel, a velocity the stage cannot hold, an exposure outside the camera's range.

A motion profile (``plan_capture(setup, motion=profile, exposure_s=T)``, e.g. an
optimised sweep from ``mitsweep design-sweep``) is planned as a step-rate table
(:mod:`mitsweep.rig.profile`): the stage ramps from rest to the table's entry rate, runs
the settle distance at it, runs the table with the shutter open (open on its first
step, closed on its last), runs the settle distance at the exit rate and ramps to rest.
Refused before any motion: a table that is empty or not monotonic, a span reaching the
lens's focal length, velocities or accelerations beyond ``rig.max_velocity`` and
``rig.acceleration``, and everything the linear sweep is refused for.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass
from typing import overload

import numpy as np
from numpy.typing import NDArray

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_fields, renamed_keywords

from ..config import Rig, Setup
from ..optics.kinematics import Trapezoid
from ..optics.motion import MotionProfile
from ..optics.sweep import SweepRange
from .arduino import MAX_SEGMENT_STEPS, MAX_STEP_RATE, MAX_TABLE_SEGMENTS, step_accel, step_rate
from .errors import PlanError
from .profile import (TOLERANCE_MM, TOLERANCE_STEPS, ProfileTable, check_followable, max_deviation,
                      profile_knots, quantise_table, ramp_steps)
from .zaber import SPEED_UNIT, accel_data, accel_mm_s2, speed_data, speed_mm_s

__all__ = ["CapturePlan", "plan_capture", "STAGE_KINDS"]

STAGE_KINDS = ("arduino", "zaber")
#: Largest relative difference between the requested velocity and the nearest one the
#: controller can produce (integer steps/s, or Zaber speed units) that is accepted.
VELOCITY_TOLERANCE = 0.01
#: The capture record's key of each :class:`CapturePlan` field renamed to the unit rule
#: (a length in mm carries no suffix): records keep the keys they were written with.
RECORD_KEYS = {"sensor_start": "sensor_start_mm", "sensor_end": "sensor_end_mm",
               "translation": "translation_mm", "ramp_distance": "ramp_mm",
               "settle_distance": "settle_mm",
               "sensor_distance_at_zero": "sensor_distance_at_zero_mm",
               "soft_limit_min": "soft_limit_min_mm", "soft_limit_max": "soft_limit_max_mm",
               "exit_ramp_distance": "exit_ramp_mm"}


@renamed_fields(**{old: new for new, old in RECORD_KEYS.items()},
                approach_mm="approach_position", open_mm="open_position",
                close_mm="close_position", end_mm="end_position")
@dataclass(frozen=True)
class CapturePlan:
    """A capture, fully resolved into stage positions, rates and times.

    Lengths mm, named without a unit (stage coordinates unless named ``sensor_*``; the
    capture record keeps their former ``*_mm`` keys, :data:`RECORD_KEYS`), velocities
    mm/s, accelerations mm/s², times s; each driver converts them to its own units
    (:meth:`driver_units`). The four positions are kept as integer controller steps
    (``*_steps``: Arduino steps or Zaber microsteps, ``steps_per_mm`` of them per mm;
    the ``*_position`` properties give them in mm) because the plan needs them exact:
    the board triggers the shutter at those step positions, the exposure is a whole
    number of steps, and a move is checked to end on its target step.

    Attributes
    ----------
    setup : str
        The setup's name.
    stage : str
        ``"arduino"`` or ``"zaber"``.
    steps_per_mm : float
        Controller steps (or microsteps) per mm of stage travel.
    sensor_start, sensor_end : float
        Sensor distances at the start and end of the exposure, mm.
    translation : float
        Sensor travel during the exposure, mm.
    exposure_s : float
        The optical exposure: translation over the requested velocity, s.
    velocity_mm_s : float
        The requested sweep velocity (``sweep.velocity``; with a profile, its mean), mm/s.
    velocity_actual_mm_s : float
        The velocity the controller will run, mm/s.
    acceleration_mm_s2 : float
        The acceleration the controller will run, mm/s².
    ramp_distance : float
        Acceleration ramp before the shutter opens, mm (v²/2a).
    settle_distance : float
        Constant-velocity travel between the ramp and the shutter's opening, mm.
    direction : int
        Sign of the stage's motion during the sweep (+1 or −1).
    sensor_distance_at_zero : float
        Sensor distance at stage position 0, mm.
    sensor_direction : int
        Sign relating stage position to sensor distance.
    mapping : str
        ``"calibrated"`` or ``"centred (uncalibrated rig)"``.
    soft_limit_min, soft_limit_max : float
        The soft limits set on the device, mm (stage coordinates).
    approach_steps, open_steps, close_steps, end_steps : int
        Stage positions, in controller steps: start of the approach, shutter open, shutter
        closed, end of the move.
    planned_exposure_s : float
        The exposure after quantisation to whole steps: what the shutter will be held for, s.
    ramp_time_s : float
        Duration of the acceleration ramp, s.
    sweep_duration_s : float
        Approach to end at the sweep velocity, s.
    positioning_velocity_mm_s, positioning_acceleration_mm_s2 : float
        Velocity and acceleration of the positioning moves (homing, approach).
    profile : ProfileTable, optional
        A motion profile's step-rate table (None: the linear sweep).
    exit_ramp_distance : float
        Deceleration after the shutter closes, mm (with a profile).
    """

    setup: str
    stage: str
    steps_per_mm: float
    sensor_start: float
    sensor_end: float
    translation: float
    exposure_s: float            # optical: translation / requested velocity
    velocity_mm_s: float         # requested (sweep.velocity)
    velocity_actual_mm_s: float  # what the controller will run
    acceleration_mm_s2: float    # what the controller will run
    ramp_distance: float
    settle_distance: float
    direction: int               # +1 / -1: sign of the stage motion during the sweep
    sensor_distance_at_zero: float
    sensor_direction: int
    mapping: str                 # "calibrated" or "centred (uncalibrated rig)"
    soft_limit_min: float
    soft_limit_max: float
    approach_steps: int
    open_steps: int
    close_steps: int
    end_steps: int
    planned_exposure_s: float    # after quantisation: what the shutter will be held for
    ramp_time_s: float
    sweep_duration_s: float      # approach -> end, at the sweep velocity
    positioning_velocity_mm_s: float
    positioning_acceleration_mm_s2: float
    #: A motion profile's step-rate table (None: the linear sweep). With one,
    #: ``velocity_mm_s`` is the mean velocity (travel / exposure), ``velocity_actual_mm_s``
    #: and ``ramp_distance`` those of the table's entry rate (run from the ramp to the open
    #: step); the exit ramp is ``exit_ramp_distance``.
    profile: ProfileTable | None = None
    exit_ramp_distance: float = 0.0

    # -- derived ------------------------------------------------------------------------
    def mm(self, steps: float) -> float:
        """A position in controller steps, in mm.

        Parameters
        ----------
        steps : float
            Position, steps (or microsteps).
        """
        return steps / self.steps_per_mm

    @property
    def approach_position(self) -> float:
        """Start of the approach (the sweep's move starts here at rest), mm."""
        return self.mm(self.approach_steps)

    @property
    def open_position(self) -> float:
        """Where the shutter opens, mm (stage coordinates)."""
        return self.mm(self.open_steps)

    @property
    def close_position(self) -> float:
        """Where the shutter closes, mm (stage coordinates)."""
        return self.mm(self.close_steps)

    @property
    def end_position(self) -> float:
        """End of the move, at rest, mm (stage coordinates)."""
        return self.mm(self.end_steps)

    @overload
    def sensor_distance(self, position: float) -> float: ...

    @overload
    def sensor_distance(self, position: NDArray[np.float64]) -> NDArray[np.float64]: ...

    @renamed_keywords(position_mm="position")
    def sensor_distance(self, position: float | NDArray[np.float64]
                        ) -> float | NDArray[np.float64]:
        """Sensor distance (mm) at stage position(s) ``position``.

        Parameters
        ----------
        position : float or ndarray
            Stage position(s), mm (stage coordinates).
        """
        return self.sensor_distance_at_zero + self.sensor_direction * position

    def driver_units(self) -> dict:
        """The sweep's velocity and acceleration in the controller's own units (derived,
        for the record): Arduino ``steps/s``, ``steps/s^2``; Zaber ``maxspeed`` and
        ``accel`` data values."""
        v, a, spm = self.velocity_actual_mm_s, self.acceleration_mm_s2, self.steps_per_mm
        if self.stage == "arduino":
            # a profile's entry rate need not be whole steps/s (the table is timed in µs)
            rate = step_rate(v, spm) if self.profile is None else round(v * spm, 6)
            return {"step_rate_steps_s": rate, "accel_steps_s2": step_accel(a, spm)}
        return {"maxspeed": speed_data(v, spm), "accel": accel_data(a, spm)}

    def as_dict(self) -> dict:
        """The plan for the capture record: the record's keys are those it always had
        (``sensor_start_mm``, ``approach_mm``, ...; :data:`RECORD_KEYS`), so that records
        written before the fields were renamed read the same."""
        d = {RECORD_KEYS.get(k, k): v for k, v in asdict(self).items()}
        if self.profile is not None:
            d["profile"] = self.profile.as_dict()
        d.update(approach_mm=self.approach_position, open_mm=self.open_position,
                 close_mm=self.close_position, end_mm=self.end_position,
                 open_sensor_distance_mm=self.sensor_distance(self.open_position),
                 close_sensor_distance_mm=self.sensor_distance(self.close_position),
                 driver_units=self.driver_units())
        return d

    def summary(self) -> str:
        """Human-readable plan (``--dry-run``)."""
        return "\n".join([
            f"setup              {self.setup} (stage: {self.stage}, {self.steps_per_mm:g} steps/mm)",
            f"sensor distance    {self.sensor_start:.4f} -> {self.sensor_end:.4f} mm "
            f"(travel {self.translation:.4f} mm)",
            (f"velocity           {self.velocity_mm_s:g} mm/s requested, "
             f"{self.velocity_actual_mm_s:.6g} mm/s run" if self.profile is None else
             f"velocity           {self.velocity_mm_s:.6g} mm/s mean (travel / exposure), "
             f"entering at {self.velocity_actual_mm_s:.6g} mm/s"),
            f"exposure           {self.planned_exposure_s:.6f} s "
            f"(optical {self.exposure_s:.6f} s)",
            f"ramp / settle      {self.ramp_distance:.4f} mm ({self.ramp_time_s:.3f} s at "
            f"{self.acceleration_mm_s2:g} mm/s^2) / {self.settle_distance:.4f} mm",
            f"stage positions    approach {self.approach_position:.4f}, open {self.open_position:.4f}, "
            f"close {self.close_position:.4f}, end {self.end_position:.4f} mm",
            f"soft limits        {self.soft_limit_min:g} .. {self.soft_limit_max:g} mm",
            f"sensor mapping     s = {self.sensor_distance_at_zero:.4f} "
            f"{'+' if self.sensor_direction > 0 else '-'} x mm ({self.mapping})",
            f"sweep duration     {self.sweep_duration_s:.3f} s",
            self._driver_units_line(),
        ] + self._profile_lines())

    def _profile_lines(self) -> list[str]:
        p = self.profile
        if p is None:
            return []
        spm = self.steps_per_mm
        return [
            f"motion profile     {len(p.steps)} segments, {p.total_steps} steps in "
            f"{p.duration_s:.6f} s; entry {p.entry_rate / spm:.4g} mm/s, exit "
            f"{p.exit_rate / spm:.4g} mm/s, peak {p.max_velocity_mm_s:.4g} mm/s, "
            f"acceleration up to {p.max_acceleration_mm_s2:.4g} mm/s^2",
            f"profile tolerance  table within {p.max_deviation_steps:.3f} steps "
            f"({p.max_deviation_steps / spm * 1e3:.3f} um) of the profile's shape, placed "
            f"{p.offset_steps:+.3f} steps from it"
            + (f", re-knotted ({p.resample_deviation * 1e3:.3f} um chords)"
               if p.resample_deviation else "")
            + f"; a ramping stage within {p.ramp_deviation * 1e3:.3f} um more",
        ]

    def _driver_units_line(self) -> str:
        u = self.driver_units()
        if self.stage == "arduino":
            return (f"arduino units      {u['step_rate_steps_s']} steps/s, "
                    f"{u['accel_steps_s2']} steps/s^2")
        return f"zaber units        maxspeed {u['maxspeed']}, accel {u['accel']} (data values)"


def _check_soft_limits(what: str, approach_steps: int, end_steps: int, spm: float,
                       lo: float, hi: float, s0: float, delta: float) -> None:
    """Refuse a plan whose approach or end position (steps) is outside the soft limits
    ``lo .. hi`` mm; ``s0 + delta · x`` is the sensor distance at stage position x."""
    for name, steps in (("approach", approach_steps), ("end", end_steps)):
        x = steps / spm
        if not lo - 1e-9 <= x <= hi + 1e-9:
            raise PlanError(f"the {what}'s {name} position {x:.4f} mm (sensor distance "
                            f"{s0 + delta * x:.4f} mm) is outside the soft limits "
                            f"{lo:g} .. {hi:g} mm; check rig.sensor_distance_at_zero")


@functools.lru_cache(maxsize=16)
def _cached_sweep_range(setup: Setup) -> SweepRange:
    from ..optics import optimal_sweep_range

    return optimal_sweep_range(setup)


def _optimal_sweep_range(setup: Setup) -> SweepRange:
    """``optimal_sweep_range(setup)``, computed once per setup in a process: a pure
    function of the frozen setup (~0.1-0.4 s of solving), which a dry run then the
    capture, or a sequence of plans for one setup, would otherwise repeat."""
    try:
        return _cached_sweep_range(setup)
    except TypeError:        # a setup holding something unhashable: not cached
        from ..optics import optimal_sweep_range

        return optimal_sweep_range(setup)


def plan_capture(setup: Setup, *, stage: str = "arduino",
                 sweep_range: SweepRange | None = None,
                 motion: MotionProfile | None = None,
                 exposure_s: float | None = None) -> CapturePlan:
    """Resolve a setup's focal sweep into a stage move.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        ``setup.sweep.velocity`` (mm/s) and ``setup.rig`` (limits, acceleration, settle
        distance, steps per mm, sensor mapping, camera exposure range).
    stage : {"arduino", "zaber"}
        Which controller moves the stage (sets the velocity quantisation).
    sweep_range : mitsweep.optics.SweepRange, optional
        Default: ``optimal_sweep_range(setup)``. Not with ``motion``.
    motion : mitsweep.optics.motion.MotionProfile, optional
        Run this profile (e.g. an optimised one from ``design-sweep``) instead of the
        linear sweep: a step-rate table (:mod:`mitsweep.rig.profile`), checked against
        ``rig.max_velocity`` and ``rig.acceleration``.
    exposure_s : float, optional
        The profile's exposure, s (default: its travel at ``sweep.velocity``, the linear
        sweep's exposure over the same span).

    Raises
    ------
    PlanError
        The sweep cannot be run on this rig; the message says why and what is allowed.
    """
    if stage not in STAGE_KINDS:
        raise PlanError(f"stage must be one of {', '.join(STAGE_KINDS)}, got {stage!r}")
    if motion is not None:
        if sweep_range is not None:
            raise ValueError("plan_capture: give a sweep_range or a motion profile, not both")
        return _plan_profile(setup, stage, motion, exposure_s)
    if exposure_s is not None:
        raise ValueError("plan_capture: exposure_s is the exposure of a motion profile")
    if sweep_range is None:
        sweep_range = _optimal_sweep_range(setup)
    rig = setup.rig
    spm = rig.steps_per_mm
    v = float(sweep_range.velocity_mm_s)
    s_start, s_end = float(sweep_range.sensor_start), float(sweep_range.sensor_end)
    travel = abs(s_end - s_start)

    if v > rig.max_velocity:
        raise PlanError(f"sweep velocity {v:g} mm/s is more than the stage can hold "
                        f"(rig.max_velocity = {rig.max_velocity:g} mm/s)")
    # quantised as each controller does: what it will actually run, in mm/s and mm/s²
    if stage == "arduino":
        rate = step_rate(v, spm)
        if not 1 <= rate <= MAX_STEP_RATE:
            raise PlanError(f"sweep velocity {v:g} mm/s is {v * spm:.4g} steps/s at "
                            f"{spm:g} steps/mm; the Arduino controller holds 1..{MAX_STEP_RATE}"
                            f" steps/s ({1 / spm:g}..{MAX_STEP_RATE / spm:g} mm/s)")
        accel = step_accel(rig.acceleration, spm)
        v_run = rate / spm
        a_run = accel / spm
    else:
        rate = speed_data(v, spm)
        accel = accel_data(rig.acceleration, spm)
        if rate < 1 or accel < 1:
            raise PlanError(f"sweep velocity {v:g} mm/s or acceleration {rig.acceleration:g} "
                            f"mm/s² is below the Zaber stage's resolution at {spm:g} "
                            f"microsteps/mm")
        v_run = speed_mm_s(rate, spm)
        a_run = accel_mm_s2(accel, spm)
    if abs(v_run - v) > VELOCITY_TOLERANCE * v:
        raise PlanError(f"sweep velocity {v:g} mm/s cannot be held: the nearest the "
                        f"{stage} controller runs is {v_run:.6g} mm/s "
                        f"({abs(v_run - v) / v:.1%} off, {VELOCITY_TOLERANCE:.0%} allowed)")

    travel_steps = int(round(travel * spm))
    if travel_steps < 1:
        raise PlanError(f"sensor travel {travel:g} mm is less than one step "
                        f"({1 / spm:g} mm)")
    if stage == "arduino":   # in the board's integer units, as the firmware checks it
        ramp_steps = math.ceil(Trapezoid.reaching(rate, accel).ramp_distance)
    else:
        ramp_steps = math.ceil(Trapezoid.reaching(v_run, a_run).ramp_distance * spm)
    settle_steps = math.ceil(rig.settle_distance * spm - 1e-9)
    margin = ramp_steps + settle_steps
    planned_exposure = travel_steps / (v_run * spm)
    if stage == "zaber":
        planned_exposure = round(travel / v_run * 1e6) * 1e-6   # the Arduino's µs timer
    if not rig.min_exposure_s <= planned_exposure <= rig.max_exposure_s:
        raise PlanError(f"exposure {planned_exposure:.6g} s is outside the camera's range "
                        f"{rig.min_exposure_s:g} .. {rig.max_exposure_s:g} s "
                        f"(rig.min_exposure_s, rig.max_exposure_s); change sweep.velocity")

    lo, hi = _soft_limits(rig)
    span = (travel_steps + 2 * margin) / spm
    if span > hi - lo + 1e-9:
        raise PlanError(f"the sweep needs {span:.4f} mm of stage travel (sensor travel "
                        f"{travel:.4f} + 2 x (ramp {ramp_steps / spm:.4f} + settle "
                        f"{settle_steps / spm:.4f})), more than the soft limits allow "
                        f"({lo:g} .. {hi:g} mm = {hi - lo:g} mm)")

    delta = rig.sensor_direction
    s0, mapping = _sensor_mapping(rig, min(s_start, s_end), max(s_start, s_end))
    x_open = (s_start - s0) / delta
    x_close = (s_end - s0) / delta
    direction = 1 if x_close > x_open else -1
    open_steps = int(round(x_open * spm))
    close_steps = open_steps + direction * travel_steps
    approach_steps = open_steps - direction * margin
    end_steps = close_steps + direction * margin
    _check_soft_limits("sweep", approach_steps, end_steps, spm, lo, hi, s0, delta)
    sweep = Trapezoid((travel_steps + 2 * margin) / spm, v_run, a_run)   # approach -> end
    return CapturePlan(
        setup=setup.name, stage=stage, steps_per_mm=spm,
        sensor_start=s_start, sensor_end=s_end, translation=travel,
        exposure_s=float(sweep_range.exposure_s), velocity_mm_s=v, velocity_actual_mm_s=v_run,
        acceleration_mm_s2=a_run,
        ramp_distance=ramp_steps / spm, settle_distance=settle_steps / spm, direction=direction,
        sensor_distance_at_zero=s0, sensor_direction=delta, mapping=mapping,
        soft_limit_min=lo, soft_limit_max=hi,
        approach_steps=approach_steps, open_steps=open_steps, close_steps=close_steps,
        end_steps=end_steps, planned_exposure_s=planned_exposure,
        ramp_time_s=sweep.ramp_time, sweep_duration_s=sweep.duration,
        positioning_velocity_mm_s=rig.max_velocity,
        positioning_acceleration_mm_s2=rig.acceleration)


def _soft_limits(rig: Rig) -> tuple[float, float]:
    """The rig's soft limits, mm (stage coordinates); an absent upper one is the travel,
    as :class:`~mitsweep.config.Rig` resolves it."""
    hi = rig.travel if rig.soft_limit_max is None else rig.soft_limit_max
    return rig.soft_limit_min, hi


def _sensor_mapping(rig: Rig, lo_s: float, hi_s: float) -> tuple[float, str]:
    """``s_0`` of ``s = s_0 + δ x`` and how it was found: the rig's calibration, or the
    sensor span ``lo_s .. hi_s`` centred within the soft limits."""
    if rig.sensor_distance_at_zero is not None:
        return rig.sensor_distance_at_zero, "calibrated"
    lo, hi = _soft_limits(rig)
    return 0.5 * (lo_s + hi_s) - rig.sensor_direction * 0.5 * (lo + hi), \
        "centred (uncalibrated rig)"


def _plan_profile(setup, stage: str, motion, exposure_s: float | None) -> CapturePlan:
    """The capture plan of a motion profile: a step-rate table between a ramp from rest
    to its entry rate and a ramp from its exit rate to rest (module
    :mod:`mitsweep.rig.profile` says what is checked and how close the table is)."""
    rig = setup.rig
    spm = rig.steps_per_mm
    t, p, chord = profile_knots(motion, max_segments=MAX_TABLE_SEGMENTS,
                                focal_length=setup.lens.focal_length)
    travel = float(abs(p[-1] - p[0]))
    if exposure_s is None:
        exposure_s = travel / setup.sweep.velocity
    if not (math.isfinite(exposure_s) and exposure_s > 0):
        raise PlanError(f"motion profile: exposure must be a finite time > 0 s, got "
                        f"{exposure_s!r}")
    times = t * exposure_s
    delta = rig.sensor_direction
    s0, mapping = _sensor_mapping(rig, float(p.min()), float(p.max()))
    x = (p - s0) / delta                       # stage positions at the knots, mm
    direction = 1 if x[-1] > x[0] else -1
    v_max, a_max, ramp_dev = check_followable(
        times, direction * (x - x[0]), max_velocity=rig.max_velocity,
        acceleration=rig.acceleration, sensor_distance=p)
    open_steps = int(round(x[0] * spm))
    travel_steps = direction * (x * spm - open_steps)    # from the open step, unrounded
    max_rate = rig.max_velocity * spm
    if stage == "arduino":
        max_rate = min(max_rate, MAX_STEP_RATE)
    steps, durations, driver, _ = quantise_table(
        times, travel_steps, stage=stage, max_rate=max_rate, speed_unit=SPEED_UNIT,
        max_segment_steps=MAX_SEGMENT_STEPS, max_segments=MAX_TABLE_SEGMENTS)
    table_t = np.concatenate([[0.0], np.cumsum(durations)])
    table_x = np.concatenate([[0], np.cumsum(steps)]).astype(float)
    deviation = max_deviation(table_t, table_x, times, travel_steps - travel_steps[0])
    tolerance = max(TOLERANCE_STEPS, TOLERANCE_MM * spm)
    if deviation > tolerance:
        raise PlanError(f"motion profile: the best table of whole steps deviates from it by "
                        f"{deviation:.2f} steps ({deviation / spm * 1e3:.3f} um), more than "
                        f"{tolerance:.4g} steps ({tolerance / spm * 1e3:.3g} um) at "
                        f"{spm:g} steps/mm")
    table = ProfileTable(
        stage=stage, steps=steps, durations_s=durations, driver=driver,
        knot_times_s=tuple(float(v) for v in times),
        knot_travel_steps=tuple(float(v) for v in travel_steps),
        offset_steps=float(travel_steps[0]), max_deviation_steps=deviation,
        ramp_deviation=ramp_dev, resample_deviation=chord,
        max_velocity_mm_s=v_max, max_acceleration_mm_s2=a_max)

    if stage == "arduino":
        accel = step_accel(rig.acceleration, spm)          # steps/s², as the board runs it
        a_run = accel / spm
        entry_ramp = ramp_steps(table.entry_rate, accel)
        exit_ramp = ramp_steps(table.exit_rate, accel)
        planned_exposure = table.duration_s
    else:
        accel = accel_data(rig.acceleration, spm)
        if accel < 1:
            raise PlanError(f"acceleration {rig.acceleration:g} mm/s² is below the Zaber "
                            f"stage's resolution at {spm:g} microsteps/mm")
        a_run = accel_mm_s2(accel, spm)
        entry_ramp = ramp_steps(table.entry_rate, a_run * spm)
        exit_ramp = ramp_steps(table.exit_rate, a_run * spm)
        planned_exposure = round(table.duration_s * 1e6) * 1e-6   # the Arduino's µs timer
    if not rig.min_exposure_s <= planned_exposure <= rig.max_exposure_s:
        raise PlanError(f"exposure {planned_exposure:.6g} s is outside the camera's range "
                        f"{rig.min_exposure_s:g} .. {rig.max_exposure_s:g} s "
                        f"(rig.min_exposure_s, rig.max_exposure_s)")
    settle = math.ceil(rig.settle_distance * spm - 1e-9)
    close_steps = open_steps + direction * table.total_steps
    approach_steps = open_steps - direction * (entry_ramp + settle)
    end_steps = close_steps + direction * (settle + exit_ramp)
    lo, hi = _soft_limits(rig)
    span = abs(end_steps - approach_steps) / spm
    if span > hi - lo + 1e-9:
        raise PlanError(f"the profile needs {span:.4f} mm of stage travel (sensor travel "
                        f"{travel:.4f} mm, ramps and settle distances), more than the soft "
                        f"limits allow ({lo:g} .. {hi:g} mm = {hi - lo:g} mm)")
    _check_soft_limits("profile", approach_steps, end_steps, spm, lo, hi, s0, delta)
    v_in, v_out = table.entry_rate / spm, table.exit_rate / spm
    def ramp_and_settle_s(v: float, ramp: int) -> float:   # ramp at a_run, then cruise
        return v / a_run + ((ramp + settle) / spm - v * v / (2 * a_run)) / v

    duration = (ramp_and_settle_s(v_in, entry_ramp) + table.duration_s
                + ramp_and_settle_s(v_out, exit_ramp))
    return CapturePlan(
        setup=setup.name, stage=stage, steps_per_mm=spm,
        sensor_start=float(p[0]), sensor_end=float(p[-1]), translation=travel,
        exposure_s=float(exposure_s), velocity_mm_s=travel / exposure_s,
        velocity_actual_mm_s=v_in, acceleration_mm_s2=a_run,
        ramp_distance=entry_ramp / spm, settle_distance=settle / spm, direction=direction,
        sensor_distance_at_zero=s0, sensor_direction=delta, mapping=mapping,
        soft_limit_min=lo, soft_limit_max=hi,
        approach_steps=approach_steps, open_steps=open_steps, close_steps=close_steps,
        end_steps=end_steps, planned_exposure_s=planned_exposure,
        ramp_time_s=v_in / a_run, sweep_duration_s=duration,
        positioning_velocity_mm_s=rig.max_velocity,
        positioning_acceleration_mm_s2=rig.acceleration,
        profile=table, exit_ramp_distance=exit_ramp / spm)
