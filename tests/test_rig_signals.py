"""Signals and unconfirmed safety steps during ``mitsweep capture``, in real subprocesses
against the pty simulators: SIGINT, SIGTERM and SIGHUP at each stage of a capture (the
approach move, mid-sweep with the shutter open, and a second signal while the safety
path runs), on both rigs (the Arduino alone; a Zaber stage with the Arduino's shutter).

Each ends with the stage at rest, the shutter released, the record incomplete with the
signal's name, and the exit status of ``mitsweep.cli.capture``'s table: 128 + the
signal's number when every safety step was confirmed, 3 when one was not.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import sys
import time

import pytest
from conftest import ROOT
from rig_fixtures import ZABER_MAX_POSITION, ZABER_STEPS_PER_MM, killed_on_exit
from test_rig_cli import setup_file

from mitsweep.config import load_setup
from mitsweep.rig import load_capture_record, plan_capture
from mitsweep.rig.simulator import ArduinoModel, Fault, PtyDevice, ZaberModel
from mitsweep.rig.transport import SAFETY_ATTEMPTS

ZABER_RIG = f"steps_per_mm = {ZABER_STEPS_PER_MM!r}\n"
# Slow enough that the shutter stays open ~3.5 s (0.695 mm at 0.2 mm/s): time to signal.
SWEEP_VELOCITY = 0.2
SIGNALS = ["SIGINT", "SIGTERM", "SIGHUP"]
# The capture process must react to a condition within this (process start-up included,
# on a loaded 2-core machine).
WAIT_S = 60.0
# A second signal's delay: the simulator holds the STOP reply back this long, so the
# second signal surely lands inside the safety path (its reply deadline is 3 s).
SLOW_STOP_S = 1.0


def wait_for(condition, what: str, proc=None, timeout_s: float = WAIT_S) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"capture exited ({proc.returncode}) before {what}: {err[-2000:]}")
        if time.monotonic() > deadline:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.005)


def received(model, prefix: str) -> bool:
    return any(d == "rx" and text.startswith(prefix) for _, d, text in list(model.log))


class Rig:
    """The simulated devices of one rig configuration and the capture's command line."""

    def __init__(self, kind: str, tmp_path, board_faults=(), zaber_faults=(), *,
                 at_approach: bool = True) -> None:
        """``at_approach``: the stage starts at the approach position (the sweep starts
        at once), else at 0 (a ~1.2 s approach move first)."""
        self.kind = kind
        extra = ZABER_RIG if kind == "zaber" else ""
        self.setup = setup_file(tmp_path, extra, SWEEP_VELOCITY)
        self.out = tmp_path / "rec.json"
        plan = plan_capture(load_setup(self.setup), stage=kind)
        start = plan.approach_steps if at_approach else 0
        board_start = start if kind == "arduino" else 0
        self.board = PtyDevice(ArduinoModel(list(board_faults), homed=True,
                                            position=board_start))
        self.stage = None
        if kind == "zaber":
            self.stage = PtyDevice(ZaberModel(list(zaber_faults), homed=True, position=start,
                                              max_position=ZABER_MAX_POSITION))

    @property
    def motor(self):
        """The model that moves the stage."""
        return (self.stage or self.board).model

    def __enter__(self) -> "Rig":
        self.board.start()
        if self.stage:
            self.stage.start()
        return self

    def __exit__(self, *exc) -> None:
        self.board.close()
        if self.stage:
            self.stage.close()

    def start_capture(self) -> subprocess.Popen:
        argv = [sys.executable, "-m", "mitsweep", "capture", str(self.setup),
                "--port", self.board.port, "--out", str(self.out)]
        if self.stage:
            argv += ["--stage", f"zaber:{self.stage.port}"]
        return subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)

    def capture(self) -> contextlib.AbstractContextManager[subprocess.Popen]:
        """:meth:`start_capture` as a context manager: the process, killed when the
        block ends (:func:`rig_fixtures.killed_on_exit`)."""
        return killed_on_exit(self.start_capture())

    def signal_when(self, condition, what: str, sig: str) -> tuple[int, str]:
        """Run the capture, send it ``sig`` once ``condition()`` holds (``what`` names it
        in a failure), and return its (exit status, stderr)."""
        with self.capture() as proc:
            wait_for(condition, what, proc)
            proc.send_signal(getattr(signal, sig))
            return finish(proc)

    def in_approach_move(self) -> bool:
        word = "/1 1 move abs" if self.stage else "MOVE"
        return received(self.motor, word) and self.motor.moving(time.monotonic())

    def shutter_open_mid_sweep(self) -> bool:
        return self.board.model.shutter_open and self.motor.moving(time.monotonic())

    def assert_safe(self) -> None:
        now = time.monotonic()
        assert not self.board.model.shutter_open, "shutter left open"
        assert not self.motor.moving(now), "stage still moving"
        assert self.motor.stopped, "stage not stopped by the safety path"


def finish(proc: subprocess.Popen) -> tuple[int, str]:
    _, err = proc.communicate(timeout=WAIT_S)
    return proc.returncode, err


def signal_exit_status(name: str) -> int:
    return 128 + getattr(signal, name)


def matrix(cases, fast):
    """``cases`` as params; those not in ``fast`` marked slow. The default run keeps
    each signal, each rig and each point of the capture at least once; CI's full run
    (``-m "slow or not slow"``) runs them all."""
    return [pytest.param(*c, id="-".join(c),
                         marks=() if c in fast else pytest.mark.slow) for c in cases]


@pytest.mark.parametrize("when, sig, rig_kind", matrix(
    [(w, s, r) for w in ("approach", "sweep") for s in SIGNALS for r in ("arduino", "zaber")],
    fast={("sweep", "SIGINT", "arduino"), ("sweep", "SIGTERM", "zaber"),
          ("sweep", "SIGHUP", "arduino"), ("approach", "SIGTERM", "arduino"),
          ("approach", "SIGHUP", "zaber")}))
def test_signal_stops_the_rig_and_records_interrupted(tmp_path, rig_kind, sig, when):
    with Rig(rig_kind, tmp_path, at_approach=when != "approach") as rig:
        if when == "approach":
            rc, err = rig.signal_when(rig.in_approach_move, "the approach move", sig)
        else:
            rc, err = rig.signal_when(rig.shutter_open_mid_sweep,
                                      "the shutter to open mid-sweep", sig)
        rig.assert_safe()
        if when == "approach":
            assert rig.board.model.shutter_history == [], "shutter opened before the sweep"
    assert rc == signal_exit_status(sig), err
    data = load_capture_record(rig.out)
    assert (data["complete"], data["status"], data["signal"]) == (False, "interrupted", sig)
    assert data["safety"] and all(step["ok"] for step in data["safety"])
    assert f"capture incomplete (interrupted by {sig})" in err
    assert "NOT confirmed" not in err
    if rig_kind == "zaber":
        assert "shutter released: confirmed; stage stopped: confirmed" in err
    else:
        assert "shutter released and stage stopped: confirmed" in err


@pytest.mark.parametrize("first, second, rig_kind", matrix(
    [(SIGNALS[i], SIGNALS[(i + 1) % 3], r) for i in range(3) for r in ("arduino", "zaber")],
    fast={("SIGTERM", "SIGHUP", "arduino"), ("SIGHUP", "SIGINT", "zaber")}))
def test_second_signal_does_not_cut_the_safety_path_short(tmp_path, rig_kind, first,
                                                          second):
    slow_stop = Fault("slow_reply", command="STOP", delay_s=SLOW_STOP_S)
    with Rig(rig_kind, tmp_path, board_faults=[slow_stop]) as rig, rig.capture() as proc:
        wait_for(rig.shutter_open_mid_sweep, "the shutter to open mid-sweep", proc)
        proc.send_signal(getattr(signal, first))
        wait_for(lambda: received(rig.board.model, "STOP"), "the safety path's STOP", proc)
        proc.send_signal(getattr(signal, second))
        rc, err = finish(proc)
        rig.assert_safe()
    assert rc == signal_exit_status(first), err
    data = load_capture_record(rig.out)
    assert (data["status"], data["signal"]) == ("interrupted", first)
    assert data["signals_during_safety"] == [second]
    # every step ran and was confirmed: the Zaber stop came after the second signal
    assert [s["device"] for s in data["safety"]] == (["arduino", "zaber"]
                                                     if rig_kind == "zaber" else ["arduino"])
    assert all(step["ok"] for step in data["safety"])
    assert f"{second} received during the safety path" in err


@pytest.mark.parametrize("rig_kind, board_faults, zaber_faults, expected", [
    ("arduino", [Fault("unplug", at_fraction=0.2)], [],
     "shutter released and stage stopped: NOT confirmed (port lost)"),
    ("zaber", [], [Fault("unplug", at_fraction=0.2)],
     "shutter released: confirmed; stage stopped: NOT confirmed (port lost)"),
], ids=["arduino-unplug", "zaber-unplug"])
def test_unconfirmed_safety_step_exits_3_and_says_which(tmp_path, rig_kind, board_faults,
                                                        zaber_faults, expected):
    """The false reassurance is gone: after an unplug stderr says what was not confirmed."""
    with Rig(rig_kind, tmp_path, board_faults, zaber_faults) as rig, rig.capture() as proc:
        rc, err = finish(proc)
    assert rc == 3, err
    assert "capture incomplete (port lost)" in err
    assert expected in err and "the rig may be unsafe" in err
    data = load_capture_record(rig.out)
    assert data["status"] == "port lost"
    assert [s["ok"] for s in data["safety"]] == ([True, False] if rig_kind == "zaber"
                                                  else [False])


def sigterm_mid_sweep(rig) -> tuple[int, str]:
    """Start a capture, SIGTERM it once the shutter is open, and return (status, stderr)."""
    return rig.signal_when(rig.shutter_open_mid_sweep, "the shutter to open mid-sweep",
                           "SIGTERM")


def test_signal_with_one_lost_stop_retries_and_confirms(tmp_path):
    """The first STOP is swallowed: the safety path sends it again (a stop is idempotent)
    and the second is confirmed, so the exit status is the signal's."""
    with Rig("arduino", tmp_path, board_faults=[Fault("no_reply", command="STOP")]) as rig:
        rc, err = sigterm_mid_sweep(rig)
        # the watchdog may have stopped the board while the first STOP went unanswered
        assert not rig.board.model.shutter_open
        assert not rig.board.model.moving(time.monotonic())
        assert sum(1 for _, d, text in list(rig.board.model.log)
                   if d == "rx" and text == "STOP") == 2
    assert rc == signal_exit_status("SIGTERM"), err
    data = load_capture_record(rig.out)
    assert all(step["ok"] for step in data["safety"])


def test_signal_with_unanswered_stop_exits_3(tmp_path):
    """An interrupted capture whose STOP goes unanswered every time is 'maybe unsafe'
    (3), not the signal's status: the board stopped, but nothing confirmed it."""
    lost = [Fault("no_reply", command="STOP")] * SAFETY_ATTEMPTS
    with Rig("arduino", tmp_path, board_faults=lost) as rig:
        rc, err = sigterm_mid_sweep(rig)
        # the board never acted on that STOP; its watchdog stopped it when the host went
        # silent (the safety path waits for the reply without sending heartbeats)
        wait_for(lambda: not rig.board.model.moving(time.monotonic()), "the watchdog",
                 timeout_s=5.0)
        assert rig.board.model.faults_seen == ["WATCHDOG"]
        assert not rig.board.model.shutter_open
    assert rc == 3, err
    assert "capture incomplete (interrupted by SIGTERM)" in err
    assert "shutter released and stage stopped: NOT confirmed (no reply)" in err
    data = load_capture_record(rig.out)
    assert (data["status"], data["signal"]) == ("interrupted", "SIGTERM")
    assert data["safety"][0]["ok"] is False
