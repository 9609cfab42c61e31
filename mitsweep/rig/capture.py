"""Capture orchestration: plan → devices → sweep → record, with a safety path.

:func:`run_capture` opens the ports, identifies the devices, sets the soft limits on the
devices themselves, homes if the position is unknown, moves (shutter closed) to the
approach position, runs the sweep with the shutter open only at constant velocity, and
writes a capture record (:mod:`mitsweep.rig.record`).

Two rig configurations:

- ``arduino``: the Arduino sweep controller drives the stepper *and* the shutter; one
  ``SWEEP`` command runs the whole move and the board opens/closes the shutter at the
  planned step positions. Times and positions come from the board's events (µs clock).
- ``zaber``: a Zaber stage moves, the Arduino only fires the shutter. The host starts the
  move, then sends ``SHUTTER <delay> <duration>`` timed so that the shutter opens after
  the ramp and settle distance; exposure times come from the board, positions from
  ``get pos`` polls of the stage interpolated at those times (the board clock is mapped
  onto the host clock at the ``SHUTTER`` exchange; uncertainty = half its round trip).
  The host's time from sending the move to the ``SHUTTER`` reply bounds how far from its
  planned time the shutter opened; while it exceeds the settle time (settle distance /
  velocity: how far off the exposure may be and still lie at constant velocity) the
  attempt is abandoned, shutter released and stage back to the approach position, and
  after :data:`SHUTTER_ATTEMPTS` such attempts the capture fails with
  :class:`~mitsweep.rig.errors.HostTooSlow` (status ``"host too slow"``).

Deadlines are checked against when a poll was *sent*, and a read past its deadline
first takes what has arrived, so a host descheduled for a while (a busy laptop) does
not blame the devices for its own lateness.

Safety: any exception — a timeout, a lost port, a device fault, a protocol error — and
the signals SIGINT (Ctrl-C), SIGTERM (``kill``) and SIGHUP (the terminal closed) during
the device phase first release the shutter and stop the stage, then write the record
marked incomplete with the reason (a signal: status ``"interrupted"``, ``"signal":
"SIGTERM"``), then propagate (a signal as :class:`~mitsweep.rig.errors.CaptureInterrupted`,
a ``KeyboardInterrupt``). The signal handlers are installed only when
:func:`run_capture` runs on the main thread, and the previous ones are restored after
it; a second signal while the safety path runs is recorded (``signals_during_safety``)
but does not cut it short. Each safety step is recorded with whether the device
confirmed it (:func:`safety_summary`); the exception carries the record as
``exc.capture_record``.

What the host cannot catch — SIGKILL, a crash, a hung host — the board handles itself:
the driver turns on the firmware's watchdog (``WATCHDOG``, ``setup.rig.watchdog_s``,
default 1 s, or ``RigPorts.watchdog_s``) and sends heartbeats while it waits, so a silent host gets the
shutter released and the motor stopped within that time (``EV FAULT ... WATCHDOG``), in
both configurations (in ``zaber`` mode the board guards its pending exposure). A Zaber
stage has no such watchdog here: a move it was already given runs to its target, which
lies inside the soft limits set on the device itself (a limitation of this driver).

A record marked ``"running"`` is written before any motion, so even a killed process
leaves one.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from dataclasses import dataclass, field
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any

import numpy as np

from ..config import Setup
from ..optics.kinematics import Trapezoid
from ..optics.motion_file import MotionFile
from .arduino import MAX_WATCHDOG_MS, ArduinoSweepController
from .errors import (CaptureInterrupted, DeviceFault, HostTooSlow, PlanError, PortLost,
                     ReplyTimeout, RigError)
from .plan import CapturePlan, plan_capture
from .record import CaptureRecord
from .transport import CommandLog, LineTransport, open_port
from .zaber import ZaberStage, accel_data, accel_mm_s2, speed_mm_s

__all__ = ["RigPorts", "run_capture", "capture", "safety_summary", "status_of",
           "CAPTURE_SIGNALS"]

logger = logging.getLogger(__name__)

#: Slack added to every motion deadline: serial latency and the host's scheduling.
#: Measured against the simulators with 2 and 6 busy processes on 2 cores (10 Zaber
#: captures each): round trips 0.1 ms median, 24 ms worst but for rare 0.24-0.31 s
#: spikes; board events read at most 22 ms after their time. A deadline is judged at a
#: poll's send time and after reading what has arrived, so a longer stall of the host
#: itself does not count against the device.
DEADLINE_SLACK_S = 0.5
#: Extra fraction of a move's planned duration allowed before it counts as late.
DEADLINE_FRACTION = 0.25
#: Zaber position polling period during the sweep, s.
POLL_PERIOD_S = 0.01
#: Zaber mode: sweeps attempted before a host too slow to time the shutter fails the
#: capture (:class:`~mitsweep.rig.errors.HostTooSlow`). A slow attempt is a load spike of
#: the host (seen: one round trip of 0.3 s among ~300 of 0.1 ms with two busy processes
#: on two cores); three in a row is a host that cannot run this capture.
SHUTTER_ATTEMPTS = 3
#: Signals that run the safety path (those that exist on this platform).
#: What :func:`signal.signal` returns and takes: a handler, SIG_DFL/SIG_IGN, or None (one
#: not installed from Python).
_Handler = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None
CAPTURE_SIGNALS = tuple(name for name in ("SIGINT", "SIGTERM", "SIGHUP")
                        if hasattr(signal, name))


@dataclass
class RigPorts:
    """Serial ports of the rig: ``arduino`` (always: the shutter, and the stepper when no
    Zaber stage is given) and ``zaber`` (optional stage). ``watchdog_s``: the board's
    watchdog, s (None: ``setup.rig.watchdog_s``; 0 turns it off; else 0.1 .. 600).

    Parameters
    ----------
    arduino : str
        Serial port of the Arduino sweep controller, e.g. ``/dev/ttyACM0``.
    zaber : str, optional
        Serial port of a Zaber ASCII stage (the Arduino then only fires the shutter).
    checksums : bool, optional
        Send and check Zaber's message checksums.
    ready_timeout_s : float, optional
        How long to wait for the board's ``READY`` line after opening its port, s.
    watchdog_s : float, optional
        The board's watchdog, s.
    """

    arduino: str
    zaber: str | None = None
    checksums: bool = False
    ready_timeout_s: float = 3.0
    watchdog_s: float | None = None

    def __post_init__(self) -> None:
        w = self.watchdog_s
        if w is not None and not (w == 0 or 0.1 <= w <= MAX_WATCHDOG_MS / 1000):
            raise PlanError(f"watchdog_s must be 0 (off) or in [0.1, "
                            f"{MAX_WATCHDOG_MS / 1000:g}] s, got {w!r}")

    @property
    def stage_kind(self) -> str:
        return "zaber" if self.zaber else "arduino"


@dataclass
class _Devices:
    arduino: ArduinoSweepController
    zaber: ZaberStage | None = None
    transports: list[LineTransport] = field(default_factory=list)

    @property
    def stage(self):
        return self.zaber if self.zaber is not None else self.arduino

    def close(self) -> None:
        for t in self.transports:
            t.close()


def _open_devices(ports: RigPorts, plan: CapturePlan, setup, log: CommandLog) -> _Devices:
    timeout = setup.rig.reply_timeout_s
    baud = setup.rig.baudrate
    ser_a = open_port(ports.arduino, baudrate=baud, name="arduino port")
    transports = [LineTransport(ser_a, name="arduino", log=log, timeout_s=timeout)]
    try:
        zaber = None
        if ports.zaber:
            ser_z = open_port(ports.zaber, baudrate=baud, name="zaber port")
            transports.append(LineTransport(ser_z, name="zaber", log=log, timeout_s=timeout))
            zaber = ZaberStage(transports[1], steps_per_mm=plan.steps_per_mm)
        # in zaber mode the Arduino's stepper is unused: its step scale does not matter
        arduino = ArduinoSweepController(transports[0], steps_per_mm=plan.steps_per_mm)
    except BaseException:
        for t in transports:
            t.close()
        raise
    return _Devices(arduino=arduino, zaber=zaber, transports=transports)


class _SignalGuard:
    """SIGINT, SIGTERM and SIGHUP raise :class:`CaptureInterrupted` while ``armed``;
    once disarmed (the safety path runs) they are only noted in :attr:`during_safety`.

    The first signal disarms the guard before it raises, so a second one arriving at
    any point of the safety path cannot interrupt it. Installed on the main thread only
    (Python runs signal handlers there); :meth:`restore` puts the previous handlers back.
    """

    def __init__(self) -> None:
        self.armed = True
        self.during_safety: list[str] = []
        self._previous: dict[int, _Handler] = {}

    def install(self) -> _SignalGuard:
        if threading.current_thread() is threading.main_thread():
            for name in CAPTURE_SIGNALS:
                signum = getattr(signal, name)
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def restore(self) -> None:
        for signum, handler in self._previous.items():
            # None: the previous handler was not installed from Python; SIG_DFL is
            # the nearest Python can put back
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)
        self._previous.clear()

    def _handle(self, signum, frame) -> None:
        name = signal.Signals(signum).name
        if self.armed:
            self.armed = False
            raise CaptureInterrupted(signum, name)
        self.during_safety.append(name)   # no logging here: the handler may interrupt it


def _safe_stop(dev: _Devices, record: CaptureRecord) -> None:
    """Release the shutter, then stop the stage; every step is recorded, none raises."""
    zaber = dev.zaber
    if zaber is not None:
        steps = [("arduino", "release shutter (STOP)", "shutter released",
                  lambda: dev.arduino.safe_stop()),
                 ("zaber", "stop stage", "stage stopped", lambda: zaber.safe_stop())]
    else:
        steps = [("arduino", "release shutter and stop stage (STOP)",
                  "shutter released and stage stopped", lambda: dev.arduino.safe_stop())]
    for device, action, confirms, fn in steps:
        try:
            fn()
            record.safety(device, action, ok=True, confirms=confirms)
        except Exception as exc:  # noqa: BLE001 - the safety path reports, never raises
            record.safety(device, action, ok=False, detail=str(exc), confirms=confirms,
                          reason=_failure_reason(exc))
            logger.error("safety: %s: %s failed: %s", device, action, exc)


def _failure_reason(exc: BaseException) -> str:
    if isinstance(exc, PortLost):
        return "port lost"
    if isinstance(exc, ReplyTimeout):
        return "no reply"
    return str(exc) or type(exc).__name__


def safety_summary(record: CaptureRecord) -> tuple[bool, str]:
    """Whether every step of the safety path was confirmed by its device, and one line
    saying which were and which were not, e.g. ``"shutter released: confirmed; stage
    stopped: NOT confirmed (port lost)"``.

    Parameters
    ----------
    record : CaptureRecord
        A capture's record, complete or not.
    """
    steps = record.safety_actions
    if not steps:
        return False, "safety path not run: state of the stage and shutter unknown"
    parts = [f"{a['confirms']}: confirmed" if a["ok"] else
             f"{a['confirms']}: NOT confirmed ({a['reason']})" for a in steps]
    return all(a["ok"] for a in steps), "; ".join(parts)


def status_of(exc: BaseException) -> str:
    """The record's status for the exception that ended a capture.

    Parameters
    ----------
    exc : BaseException
        The exception that ended it.

    Returns
    -------
    str
        ``"interrupted"``, ``"port lost"``, ``"timeout"``, ``"fault"``,
        ``"host too slow"`` or ``"error"``.
    """
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, PortLost):
        return "port lost"
    if isinstance(exc, ReplyTimeout):
        return "timeout"
    if isinstance(exc, DeviceFault):
        return "fault"
    if isinstance(exc, HostTooSlow):
        return "host too slow"
    return "error"


def _deadline(duration_s: float) -> float:
    return time.monotonic() + duration_s * (1 + DEADLINE_FRACTION) + DEADLINE_SLACK_S


def _positioning_time(plan: CapturePlan, distance: float) -> float:
    return Trapezoid(abs(distance), plan.positioning_velocity_mm_s,
                     plan.positioning_acceleration_mm_s2).duration


def _prepare(dev: _Devices, plan: CapturePlan, setup, ports: RigPorts,
             record: CaptureRecord) -> None:
    a = dev.arduino
    a.wait_ready(ports.ready_timeout_s)
    if ports.checksums:
        a.enable_checksums()
    record.devices["arduino"] = a.identify()
    if plan.profile is not None and dev.zaber is None:
        a.require_tables()                  # before any motion: a protocol-2 board
    if dev.zaber is not None:
        if ports.checksums:
            dev.zaber.enable_checksums()
        record.devices["zaber"] = dev.zaber.identify()
    stage = dev.stage
    lo, hi = plan.soft_limit_min, plan.soft_limit_max
    stage.set_soft_limits(lo, hi)
    watchdog_s = setup.rig.watchdog_s if ports.watchdog_s is None else ports.watchdog_s
    if watchdog_s:
        a.set_watchdog(watchdog_s)          # from here on a silent host stops the board
    state = stage.state()
    if state.fault:
        raise DeviceFault(f"{stage.name}: fault {state.fault} before the capture; clear it "
                          f"and check the stage")
    if not state.homed:
        logger.info("%s: position unknown, homing", stage.name)
        stage.home(velocity_mm_s=plan.positioning_velocity_mm_s,
                   timeout_s=_positioning_time(plan, setup.rig.travel) * 1.5 + 2.0)
        record.homed = True
        state = stage.state()
    record.mark("homed" if record.homed else "position known")
    here = state.position if state.position is not None else 0.0
    _move_to_approach(stage, plan, here=here)
    record.mark("at approach position")


def _move_to_approach(stage, plan: CapturePlan, *, here: float) -> None:
    stage.move_to(plan.approach_position, velocity_mm_s=plan.positioning_velocity_mm_s,
                  acceleration_mm_s2=plan.positioning_acceleration_mm_s2,
                  timeout_s=_positioning_time(plan, plan.approach_position - here) * 1.5 + 1.0)


def _sweep_arduino(dev: _Devices, plan: CapturePlan, record: CaptureRecord) -> None:
    a = dev.arduino
    if plan.profile is None:
        a.start_sweep(target=plan.end_steps, velocity_mm_s=plan.velocity_actual_mm_s,
                      acceleration_mm_s2=plan.acceleration_mm_s2,
                      open_at=plan.open_steps, close_at=plan.close_steps)
    else:
        a.load_table(plan.profile.steps, plan.profile.driver)
        record.mark(f"table loaded ({len(plan.profile.steps)} segments)")
        a.start_table_sweep(target=plan.end_steps, acceleration_mm_s2=plan.acceleration_mm_s2,
                            open_at=plan.open_steps, close_at=plan.close_steps)
    record.mark("sweep started")
    deadline = _deadline(plan.sweep_duration_s)
    a.wait_event("DONE", deadline=deadline)
    record.mark("sweep done")
    record.set_board_events(a.events)


def _sweep_zaber(dev: _Devices, plan: CapturePlan, record: CaptureRecord) -> None:
    """The host-timed sweep, attempted up to :data:`SHUTTER_ATTEMPTS` times: an attempt
    whose shutter timing the host cannot vouch for is abandoned (shutter released, stage
    stopped and sent back to the approach position) before its exposure counts."""
    a, z = dev.arduino, _zaber_of(dev)
    allowed_s = _shutter_timing_allowance_s(plan)
    if plan.profile is not None:
        z.load_stream(_stream_lines(plan), accel=accel_data(plan.acceleration_mm_s2,
                                                            plan.steps_per_mm))
        record.mark(f"stream stored ({len(plan.profile.steps) + 2} lines)")
    for attempt in range(1, SHUTTER_ATTEMPTS + 1):
        placement_s = _start_zaber_sweep(dev, plan, record)
        if placement_s <= allowed_s:
            break
        logger.warning("zaber: attempt %d of %d: the host took %.3f s from the move to the "
                       "SHUTTER reply, more than the %.3f s the settle distance allows; "
                       "shutter released, trying again", attempt, SHUTTER_ATTEMPTS,
                       placement_s, allowed_s)
        record.mark(f"attempt {attempt}: host too slow to time the shutter "
                    f"({placement_s:.3f} s > {allowed_s:.3f} s), abandoned")
        a.close_shutter()
        z.stop()
        if attempt == SHUTTER_ATTEMPTS:
            raise HostTooSlow(
                f"host too slow to time the shutter: {SHUTTER_ATTEMPTS} attempts took "
                f"{placement_s:.3f} s (last) from the move to the SHUTTER reply; the "
                f"settle distance {plan.settle_distance:g} mm at {plan.velocity_actual_mm_s:g} "
                f"mm/s allows {allowed_s:.3f} s. Close other programs, or raise "
                f"rig.settle_distance")
        z.wait_idle(timeout_s=_positioning_time(plan, plan.translation) * 1.5 + 1.0)
        _move_to_approach(dev.stage, plan, here=plan.end_position)
    deadline = _deadline(plan.sweep_duration_s)
    while True:
        a.keep_alive()
        a.poll_events()
        t_poll = time.monotonic()
        pos, reply = z.get_position()
        if not reply.busy:
            break
        if t_poll > deadline:     # the poll's send time: a host starved after it is no fault
            raise ReplyTimeout(f"zaber: still moving {plan.sweep_duration_s:.2f} s "
                               f"after the sweep started")
        time.sleep(POLL_PERIOD_S)
    if pos != plan.end_steps:
        raise RigError(f"zaber: sweep ended at {pos} microsteps, not {plan.end_steps}")
    a.wait_event("CLOSE", deadline=deadline)
    record.mark("sweep done")
    record.set_board_events(a.events)
    record.set_stage_samples(z.samples)


def _zaber_of(dev: _Devices) -> ZaberStage:
    """The Zaber stage of a rig in ``zaber`` mode (a :class:`ValueError` without one)."""
    if dev.zaber is None:
        raise ValueError("a Zaber sweep needs a Zaber stage (RigPorts.zaber)")
    return dev.zaber


def _stream_lines(plan: CapturePlan) -> list[tuple[int, int]]:
    """A profile's Zaber stream: ``(target microsteps, maxspeed data)`` of each line —
    to the open position at the entry speed, one line per table segment, and on to the
    end position at the exit speed."""
    p = plan.profile
    if p is None:
        raise ValueError("a Zaber stream needs a plan with a motion profile")
    knots = plan.open_steps + plan.direction * np.cumsum(p.steps)
    return ([(plan.open_steps, p.driver[0])]
            + [(int(x), v) for x, v in zip(knots, p.driver)]
            + [(plan.end_steps, p.driver[-1])])


def _time_to_open_s(plan: CapturePlan) -> float:
    """Time from the start of the sweep's move to the shutter's opening position."""
    if plan.profile is None:
        move = Trapezoid(abs(plan.end_position - plan.approach_position), plan.velocity_actual_mm_s,
                         plan.acceleration_mm_s2)
        return float(move.time_at(abs(plan.open_position - plan.approach_position)))
    # the stream's first line: ramp from rest at tanaccel, then the entry speed
    v = speed_mm_s(plan.profile.driver[0], plan.steps_per_mm)
    a = accel_mm_s2(accel_data(plan.acceleration_mm_s2, plan.steps_per_mm), plan.steps_per_mm)
    return v / a + (abs(plan.open_position - plan.approach_position) - v * v / (2 * a)) / v


def _shutter_timing_allowance_s(plan: CapturePlan) -> float:
    """How far (s) the host-timed shutter may open from its planned time with the whole
    exposure still at constant velocity: the settle distance at the sweep velocity."""
    return plan.settle_distance / plan.velocity_actual_mm_s


def _start_zaber_sweep(dev: _Devices, plan: CapturePlan, record: CaptureRecord) -> float:
    """Start the move and time the shutter; returns the placement uncertainty (s): the
    host's time from sending the move to the SHUTTER reply, which bounds how far from
    ``t_to_open`` after the move's start the shutter opens."""
    a, z = dev.arduino, _zaber_of(dev)
    if plan.profile is None:
        z.set_motion(plan.velocity_actual_mm_s, plan.acceleration_mm_s2)
    # time from the start of the move to the open position: ramp, then cruise
    t_to_open = _time_to_open_s(plan)
    z.samples.clear()
    t_move = record.log.now()
    if plan.profile is None:
        z.start_move(plan.end_position)
    else:
        z.start_stream()
    elapsed = record.log.now() - t_move
    delay_us = max(0, int(round((t_to_open - elapsed) * 1e6)))
    duration_us = int(round(plan.planned_exposure_s * 1e6))
    t_tx = record.log.now()
    board_t = a.fire(delay_us=delay_us, duration_us=duration_us)
    t_rx = record.log.now()
    # the shutter opens t_to_open after the move started, up to the host's latency from
    # sending the move to the SHUTTER reply (on a loaded host, more than a few ms)
    record.clock_map = {"board_t_us": board_t, "host_t_s": 0.5 * (t_tx + t_rx),
                        "uncertainty_s": 0.5 * (t_rx - t_tx),
                        "placement_uncertainty_s": t_rx - t_move}
    record.mark("sweep started")
    return t_rx - t_move


def run_capture(setup: Setup, ports: RigPorts, *, out: str | Path | None = None,
                plan: CapturePlan | None = None,
                motion_file: MotionFile | None = None) -> CaptureRecord:
    """Run one focal-sweep capture on the rig and return its record.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup to capture: its sweep and ``[rig]`` (limits, motion, serial links).
    ports : RigPorts
        ``ports.zaber`` given: Zaber stage + Arduino shutter; else the Arduino does both.
    out : path, optional
        Capture record (JSON), written atomically: once marked ``"running"`` before any
        motion, and again at the end (complete, or incomplete with the reason).
    plan : CapturePlan, optional
        Default: :func:`plan_capture` of the setup for the chosen stage (a motion
        profile's plan: ``plan_capture(setup, motion=..., exposure_s=...)``).
    motion_file : mitsweep.optics.motion_file.MotionFile, optional
        The file the plan's profile came from: the record keeps its source, exposure
        and provenance.

    Raises
    ------
    PlanError
        Before any port is opened (bad sweep for this rig), or when a port cannot be
        opened (:class:`~mitsweep.rig.errors.PortUnavailable`).
    RigError, KeyboardInterrupt
        During the capture, after the safety path tried to release the shutter and stop
        the stage and the record was written incomplete; ``exc.capture_record`` is the
        record (:func:`safety_summary` says which steps the devices confirmed). SIGINT,
        SIGTERM and SIGHUP raise :class:`~mitsweep.rig.errors.CaptureInterrupted` (a
        ``KeyboardInterrupt``) when running on the main thread.
    """
    if plan is None:
        plan = plan_capture(setup, stage=ports.stage_kind)
    if plan.stage != ports.stage_kind:
        raise ValueError(f"plan is for the {plan.stage} stage, ports are for "
                         f"{ports.stage_kind}")
    if out is not None:
        from ..io.atomic import check_writable

        try:
            check_writable(out)
        except OSError as exc:
            raise PlanError(f"capture record: {exc}") from None
    log = CommandLog()
    record = CaptureRecord(setup=setup, plan=plan, log=log, ports=ports, path=out)
    if motion_file is not None:
        record.motion = {"file": motion_file.source, "exposure_s": motion_file.exposure_s,
                         "provenance": motion_file.provenance}
    guard = _SignalGuard()
    dev = _open_devices(ports, plan, setup, log)   # PortUnavailable: nothing moved
    try:
        guard.install()
        try:
            record.save()                          # "running": never lost
            _prepare(dev, plan, setup, ports, record)
            if dev.zaber is not None:
                _sweep_zaber(dev, plan, record)
            else:
                _sweep_arduino(dev, plan, record)
            guard.armed = False                    # a signal now can wait for the record
            record.finish(complete=True, status="complete")   # checks the measurement
        except BaseException as exc:
            guard.armed = False                    # nothing may cut the safety path short
            _stop_and_record(dev, record, exc, guard)
            exc.capture_record = record  # type: ignore[attr-defined]  # any exception carries it
            raise
        record.save()
        if guard.during_safety:
            logger.warning("%s received after the sweep had finished: capture complete",
                           ", ".join(guard.during_safety))
        return record
    finally:
        guard.restore()
        dev.close()


def _stop_and_record(dev: _Devices, record: CaptureRecord, exc: BaseException,
                     guard: _SignalGuard) -> None:
    """The safety path: stop everything, then write the incomplete record."""
    logger.error("capture failed (%s): releasing the shutter, stopping the stage",
                 exc or type(exc).__name__)
    _safe_stop(dev, record)
    record.set_board_events(dev.arduino.events)
    if dev.zaber is not None:
        record.set_stage_samples(dev.zaber.samples)
    if isinstance(exc, KeyboardInterrupt):
        record.signal = getattr(exc, "signal_name", "SIGINT")
    record.signals_during_safety = list(guard.during_safety)
    record.finish(complete=False, status=status_of(exc),
                  error=str(exc) or type(exc).__name__)
    try:
        record.save()
    except OSError as save_exc:
        logger.error("could not write the capture record: %s", save_exc)
    if guard.during_safety:
        logger.warning("%s received during the safety path: it ran to its end",
                       ", ".join(guard.during_safety))


def capture(setup: Setup, *, port: str, zaber_port: str | None = None,
            out: str | Path | None = None, checksums: bool = False) -> CaptureRecord:
    """Convenience wrapper of :func:`run_capture`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup to capture (its sweep, motion and ``[rig]``).
    port : str
        Serial port of the Arduino sweep controller.
    zaber_port : str, optional
        Serial port of a Zaber stage, if the rig has one.
    out : str or Path, optional
        Where to write the capture record (JSON, atomically); none: not written.
    checksums : bool, optional
        Use Zaber's message checksums.

    Returns
    -------
    CaptureRecord
        The record, complete or marked incomplete with its reason.
    """
    return run_capture(setup, RigPorts(arduino=port, zaber=zaber_port, checksums=checksums),
                       out=out)
