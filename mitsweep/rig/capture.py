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

Safety: any exception — Ctrl-C, a timeout, a lost port, a device fault, a protocol
error — during the device phase first releases the shutter and stops the stage, then
writes the record marked incomplete with the reason, then propagates. A record marked
``"running"`` is written before any motion, so even a killed process leaves one.
"""

from __future__ import annotations

import logging
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from .arduino import ArduinoSweepController
from .errors import DeviceFault, PlanError, PortLost, ReplyTimeout, RigError
from .plan import CapturePlan, plan_capture
from .record import CaptureRecord
from .transport import CommandLog, LineTransport, open_port
from .zaber import ZaberStage

__all__ = ["RigPorts", "run_capture", "capture"]

logger = logging.getLogger(__name__)

#: Slack added to every motion deadline: serial latency and the host's scheduling.
DEADLINE_SLACK_S = 0.5
#: Extra fraction of a move's planned duration allowed before it counts as late.
DEADLINE_FRACTION = 0.25
#: Zaber position polling period during the sweep, s.
POLL_PERIOD_S = 0.01


@dataclass
class RigPorts:
    """Serial ports of the rig: ``arduino`` (always: the shutter, and the stepper when no
    Zaber stage is given) and ``zaber`` (optional stage)."""

    arduino: str
    zaber: str | None = None
    checksums: bool = False
    ready_timeout_s: float = 3.0

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


@contextmanager
def _sigint_deferred():
    """Ignore Ctrl-C while the safety path runs (a second Ctrl-C must not cut it short)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _safe_stop(dev: _Devices, record: CaptureRecord) -> None:
    """Release the shutter, then stop the stage; every step is recorded, none raises."""
    with _sigint_deferred():
        if dev.zaber is not None:
            steps = [("arduino", "release shutter", lambda: dev.arduino.safe_stop()),
                     ("zaber", "stop stage", lambda: dev.zaber.safe_stop())]
        else:
            steps = [("arduino", "release shutter and stop stage (STOP)",
                      lambda: dev.arduino.safe_stop())]
        for device, action, fn in steps:
            try:
                fn()
                record.safety(device, action, ok=True)
            except Exception as exc:  # noqa: BLE001 - the safety path reports, never raises
                record.safety(device, action, ok=False, detail=str(exc))
                logger.error("safety: %s: %s failed: %s", device, action, exc)


def status_of(exc: BaseException) -> str:
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted"
    if isinstance(exc, PortLost):
        return "port lost"
    if isinstance(exc, ReplyTimeout):
        return "timeout"
    if isinstance(exc, DeviceFault):
        return "fault"
    return "error"


def _deadline(duration_s: float) -> float:
    return time.monotonic() + duration_s * (1 + DEADLINE_FRACTION) + DEADLINE_SLACK_S


def _positioning_time(plan: CapturePlan, distance_mm: float) -> float:
    v, a = plan.positioning_velocity_mm_s, plan.positioning_acceleration_mm_s2
    return abs(distance_mm) / v + v / a


def _prepare(dev: _Devices, plan: CapturePlan, setup, ports: RigPorts,
             record: CaptureRecord) -> None:
    a = dev.arduino
    a.wait_ready(ports.ready_timeout_s)
    if ports.checksums:
        a.enable_checksums()
    record.devices["arduino"] = a.identify()
    if dev.zaber is not None:
        if ports.checksums:
            dev.zaber.enable_checksums()
        record.devices["zaber"] = dev.zaber.identify()
    stage = dev.stage
    lo, hi = plan.soft_limit_min_mm, plan.soft_limit_max_mm
    stage.set_soft_limits(lo, hi)
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
    here = state.position_mm if state.position_mm is not None else 0.0
    stage.move_to(plan.approach_mm, velocity_mm_s=plan.positioning_velocity_mm_s,
                  acceleration_mm_s2=plan.positioning_acceleration_mm_s2,
                  timeout_s=_positioning_time(plan, plan.approach_mm - here) * 1.5 + 1.0)
    record.mark("at approach position")


def _sweep_arduino(dev: _Devices, plan: CapturePlan, record: CaptureRecord) -> None:
    a = dev.arduino
    a.start_sweep(target=plan.end_steps, rate=plan.step_rate, accel=plan.accel_rate,
                  open_at=plan.open_steps, close_at=plan.close_steps)
    record.mark("sweep started")
    deadline = _deadline(plan.sweep_duration_s)
    a.wait_event("DONE", deadline=deadline)
    record.mark("sweep done")
    record.set_board_events(a.events)


def _sweep_zaber(dev: _Devices, plan: CapturePlan, record: CaptureRecord) -> None:
    a, z = dev.arduino, dev.zaber
    z.set_motion(plan.velocity_mm_s, plan.acceleration_mm_s2)
    # time from the start of the move to the open position: ramp, then cruise
    v = plan.velocity_actual_mm_s * plan.steps_per_mm
    acc = plan.acceleration_mm_s2 * plan.steps_per_mm
    d_r = v * v / (2 * acc)
    margin = abs(plan.open_steps - plan.approach_steps)
    t_to_open = v / acc + (margin - d_r) / v
    z.samples.clear()
    t_move = record.log.now()
    z.start_move(plan.end_mm)
    elapsed = record.log.now() - t_move
    delay_us = max(0, int(round((t_to_open - elapsed) * 1e6)))
    duration_us = int(round(plan.planned_exposure_s * 1e6))
    t_tx = record.log.now()
    board_t = a.fire(delay_us=delay_us, duration_us=duration_us)
    t_rx = record.log.now()
    record.clock_map = {"board_t_us": board_t, "host_t_s": 0.5 * (t_tx + t_rx),
                        "uncertainty_s": 0.5 * (t_rx - t_tx)}
    record.mark("sweep started")
    deadline = _deadline(plan.sweep_duration_s)
    while True:
        a.poll_events()
        pos, reply = z.get_position()
        if not reply.busy:
            break
        if time.monotonic() > deadline:
            raise ReplyTimeout(f"zaber: still moving {plan.sweep_duration_s:.2f} s "
                               f"after the sweep started")
        time.sleep(POLL_PERIOD_S)
    if pos != plan.end_steps:
        raise RigError(f"zaber: sweep ended at {pos} microsteps, not {plan.end_steps}")
    a.wait_event("CLOSE", deadline=deadline)
    record.mark("sweep done")
    record.set_board_events(a.events)
    record.set_stage_samples(z.samples)


def run_capture(setup, ports: RigPorts, *, out: str | Path | None = None,
                plan: CapturePlan | None = None) -> CaptureRecord:
    """Run one focal-sweep capture on the rig and return its record.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    ports : RigPorts
        ``ports.zaber`` given: Zaber stage + Arduino shutter; else the Arduino does both.
    out : path, optional
        Capture record (JSON), written atomically: once marked ``"running"`` before any
        motion, and again at the end (complete, or incomplete with the reason).
    plan : CapturePlan, optional
        Default: :func:`plan_capture` of the setup for the chosen stage.

    Raises
    ------
    PlanError
        Before any port is opened (bad sweep for this rig), or when a port cannot be
        opened (:class:`~mitsweep.rig.errors.PortUnavailable`).
    RigError, KeyboardInterrupt
        During the capture, after the stage was stopped, the shutter released and the
        record written incomplete.
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
    dev = _open_devices(ports, plan, setup, log)   # PortUnavailable: nothing moved
    try:
        record.save()                              # "running": never lost
        try:
            _prepare(dev, plan, setup, ports, record)
            if dev.zaber is not None:
                _sweep_zaber(dev, plan, record)
            else:
                _sweep_arduino(dev, plan, record)
            record.finish(complete=True, status="complete")   # checks the measurement
        except BaseException as exc:
            logger.error("capture failed (%s): stopping the stage, releasing the shutter",
                         exc or type(exc).__name__)
            _safe_stop(dev, record)
            record.set_board_events(dev.arduino.events)
            if dev.zaber is not None:
                record.set_stage_samples(dev.zaber.samples)
            record.finish(complete=False, status=status_of(exc),
                          error=str(exc) or type(exc).__name__)
            record.save()
            raise
        record.save()
        return record
    finally:
        dev.close()


def capture(setup, *, port: str, zaber_port: str | None = None, out=None,
            checksums: bool = False) -> CaptureRecord:
    """Convenience wrapper of :func:`run_capture`."""
    return run_capture(setup, RigPorts(arduino=port, zaber=zaber_port, checksums=checksums),
                       out=out)
