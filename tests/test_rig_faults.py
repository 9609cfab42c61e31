"""Injected faults: each ends with the stage stopped, the shutter closed, a clear error
and a record marked incomplete (real pty I/O against the simulators)."""

from __future__ import annotations

import _thread
import os
import signal
import threading
import time

import pytest
from rig_fixtures import ZABER_MAX_POSITION, assert_safe, soft_limit_steps
from rig_fixtures import sphere, sphere_zaber  # noqa: F401 - fixtures

from mitsweep.rig import (CaptureInterrupted, DeviceFault, PortLost, ProtocolError,
                          ReplyTimeout, RigPorts, load_capture_record, plan_capture,
                          run_capture)
from mitsweep.rig.simulator import ArduinoModel, Fault, PtyDevice, ZaberModel


def assert_incomplete(out, status):
    data = load_capture_record(out)
    assert data["complete"] is False
    assert data["status"] == status
    assert data["error"]
    assert data["safety"], "the safety path must be recorded"
    return data


@pytest.mark.parametrize("fault, error, status, stop_ok", [
    (Fault("no_reply", command="SWEEP"), ReplyTimeout, "timeout", True),
    (Fault("garbage", command="SWEEP"), ProtocolError, "error", True),
    (Fault("fault_flag", at_fraction=0.5), DeviceFault, "fault", True),
    (Fault("late_event", delay_s=5.0), ReplyTimeout, "timeout", True),
    (Fault("unplug", at_fraction=0.5), PortLost, "port lost", False),
    (Fault("brownout", at_fraction=0.5), DeviceFault, "fault", True),
], ids=lambda x: x.kind if isinstance(x, Fault) else None)
def test_arduino_fault_stops_and_records_incomplete(sphere, tmp_path, fault, error, status,
                                                    stop_ok):
    plan = plan_capture(sphere)
    out = tmp_path / "capture.json"
    lo, hi = soft_limit_steps(plan)
    with PtyDevice(ArduinoModel([fault], homed=True, position=plan.approach_steps)) as dev:
        t0 = time.monotonic()
        with pytest.raises(error):
            run_capture(sphere, RigPorts(arduino=dev.port), out=out)
        # no hanging: the deadline is the sweep's duration plus a bounded slack
        assert time.monotonic() - t0 < plan.sweep_duration_s * 1.25 + 2.5
        assert_safe(dev.model, lo, hi)
    data = assert_incomplete(out, status)
    assert data["safety"][0]["ok"] is stop_ok
    if fault.kind in ("fault_flag", "unplug", "brownout"):
        # stopped part-way: the sweep did not reach its end
        assert dev.model.position(time.monotonic()) != plan.end_steps
    if fault.kind == "brownout":
        assert "restarted mid-session" in data["error"]
        assert not dev.model.homed


@pytest.mark.parametrize("fault, error, status", [
    (Fault("fault_flag", at_fraction=0.5), DeviceFault, "fault"),
    (Fault("no_reply", command="move"), ReplyTimeout, "timeout"),
    (Fault("garbage", command="move"), ProtocolError, "error"),
    (Fault("unplug", at_fraction=0.5), PortLost, "port lost"),
], ids=lambda x: x.kind if isinstance(x, Fault) else None)
def test_zaber_fault_releases_shutter_and_records_incomplete(sphere_zaber, tmp_path, fault,
                                                             error, status):
    plan = plan_capture(sphere_zaber, stage="zaber")
    out = tmp_path / "capture.json"
    lo, hi = soft_limit_steps(plan)
    zaber = ZaberModel([fault], homed=True, position=plan.approach_steps,
                       max_position=ZABER_MAX_POSITION)
    with PtyDevice(ArduinoModel(homed=True)) as board, PtyDevice(zaber) as stage:
        with pytest.raises(error):
            run_capture(sphere_zaber, RigPorts(arduino=board.port, zaber=stage.port), out=out)
        assert not board.model.shutter_open
        data = assert_incomplete(out, status)
        actions = [(a["device"], a["ok"]) for a in data["safety"]]
        # the shutter is released first, then the stage is stopped
        assert actions[0] == ("arduino", True)
        assert actions[1] == ("zaber", fault.kind != "unplug")
        if fault.kind == "unplug":
            # the link is gone but the stage finishes the commanded move on its own
            # supply: it ends inside the limits the driver set on the device itself
            time.sleep(plan.sweep_duration_s)
        assert_safe(stage.model, lo, hi)


def _is_sweep(line: bytes) -> bool:
    """Whether a line the host sent the simulated board is a ``SWEEP`` command."""
    return line.split()[:1] == [b"SWEEP"]


class _InterruptingBoard(ArduinoModel):
    """Presses Ctrl-C (SIGINT to the main thread) 0.2 s into the sweep.

    The timer is kept so the test can cancel it: a capture that fails before it fires
    must fail its test, not interrupt the whole pytest session later."""

    timer = None

    def handle(self, line, now):
        if _is_sweep(line):
            self.timer = threading.Timer(0.2, _thread.interrupt_main)
            self.timer.start()
        return super().handle(line, now)


def test_ctrl_c_during_sweep_stops_and_records_interrupted(sphere, tmp_path):
    plan = plan_capture(sphere)
    out = tmp_path / "capture.json"
    board = _InterruptingBoard(homed=True, position=plan.approach_steps)
    with PtyDevice(board) as dev:
        try:
            with pytest.raises(KeyboardInterrupt):
                run_capture(sphere, RigPorts(arduino=dev.port), out=out)
        finally:
            if board.timer is not None:
                board.timer.cancel()
        assert_safe(dev.model, 0, round(plan.soft_limit_max * plan.steps_per_mm))
        assert dev.model.stopped
    data = assert_incomplete(out, "interrupted")
    assert data["safety"][0]["ok"]
    # the record holds the partial sweep: the start of it was seen
    assert any(e["name"] == "START" for e in data["events"])


def test_record_marked_running_before_motion(sphere, tmp_path):
    """A process killed mid-capture still leaves a record saying it is incomplete."""
    plan = plan_capture(sphere)
    out = tmp_path / "capture.json"
    seen = {}

    class Spy(ArduinoModel):
        def handle(self, line, now):
            if _is_sweep(line):
                seen.update(load_capture_record(out))
            return super().handle(line, now)

    with PtyDevice(Spy(homed=True, position=plan.approach_steps)) as dev:
        run_capture(sphere, RigPorts(arduino=dev.port), out=out)
    assert seen["status"] == "running" and seen["complete"] is False
    assert load_capture_record(out)["complete"] is True


class _TerminatedBoard(ArduinoModel):
    """Sends SIGTERM to this process (``kill PID``) 0.2 s into the sweep (the timer kept
    so that a capture failing before it fires can cancel it, see _InterruptingBoard)."""

    timer = None

    def handle(self, line, now):
        if _is_sweep(line):
            self.timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGTERM))
            self.timer.start()
        return super().handle(line, now)


def test_sigterm_during_sweep_runs_the_safety_path_and_restores_handlers(sphere, tmp_path):
    """The API on the main thread: SIGTERM raises CaptureInterrupted after the safety
    path, the record names the signal, and the caller's handler is back afterwards."""
    plan = plan_capture(sphere)
    out = tmp_path / "capture.json"
    seen = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(signum))
    try:
        board = _TerminatedBoard(homed=True, position=plan.approach_steps)
        with PtyDevice(board) as dev:
            try:
                with pytest.raises(CaptureInterrupted) as info:
                    run_capture(sphere, RigPorts(arduino=dev.port), out=out)
            finally:
                if board.timer is not None:
                    board.timer.cancel()
            assert_safe(dev.model, 0, round(plan.soft_limit_max * plan.steps_per_mm))
            assert dev.model.stopped
        assert info.value.signal_name == "SIGTERM"
        assert info.value.capture_record.signal == "SIGTERM"
        os.kill(os.getpid(), signal.SIGTERM)   # the caller's handler again, not ours
        time.sleep(0.05)
        assert seen == [signal.SIGTERM]
    finally:
        signal.signal(signal.SIGTERM, previous)
    data = assert_incomplete(out, "interrupted")
    assert data["signal"] == "SIGTERM" and data["safety"][0]["ok"]
