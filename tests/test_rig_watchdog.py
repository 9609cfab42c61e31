"""The board's watchdog (protocol 2): a host that is SIGKILLed mid-sweep cannot stop
anything, so the board must. A real ``mitsweep capture`` subprocess is killed with the
shutter open, against the Python simulator and against the sketch's own code built for
the host; the board must end at rest with the shutter released within the configured
``rig.watchdog_s`` (+ a margin), and say why (``EV FAULT ... WATCHDOG``). Also: the
driver's heartbeats keep a move longer than the watchdog alive.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import time

import pytest
from conftest import ROOT
from test_rig_cli import setup_file
from test_rig_firmware import HostBoard
from test_rig_signals import SWEEP_VELOCITY, Rig, wait_for

from mitsweep.rig.arduino import ArduinoSweepController
from mitsweep.rig.simulator import ArduinoModel, PtyDevice
from mitsweep.rig.transport import LineTransport, open_port

WATCHDOG_S = 1.0
WATCHDOG_RIG = f"watchdog_s = {WATCHDOG_S}\n"
# The expiry comes at most WATCHDOG_S after the kill (the last line preceded it); the
# board acts on it within a loop turn (1 ms in the simulator, ~20 µs plus scheduling in
# the host build, whose process shares a loaded 2-core machine). The time is the
# board's own record of when it released the shutter (the simulator's model time, the
# host build's pin trace on CLOCK_MONOTONIC), so a test process that is itself starved
# does not count; the kill time is taken *before* the kill, so the bound is an upper one.
MARGIN_S = 0.3
# How long the test waits to see the board at rest at all.
GIVE_UP_S = 10.0


def kill_mid_sweep(proc, shutter_open) -> float:
    """SIGKILL the capture once the shutter is open mid-sweep; returns a time just
    before the kill."""
    wait_for(shutter_open, "the shutter to open mid-sweep", proc)
    t_kill = time.monotonic()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    return t_kill


@pytest.mark.parametrize("rig_kind", ["arduino", "zaber"])
def test_sigkilled_host_simulator_board_stops_within_watchdog(tmp_path, rig_kind):
    with Rig(rig_kind, tmp_path) as rig:
        rig.setup.write_text(rig.setup.read_text() + WATCHDOG_RIG)
        proc = rig.start_capture()
        try:
            t_kill = kill_mid_sweep(proc, rig.shutter_open_mid_sweep)
        finally:
            proc.kill()
            proc.wait()
        board = rig.board.model

        def safe() -> bool:
            shutter_done = not board.shutter_open and not board.exposure_pending
            # in zaber mode the board guards the exposure only: the stage's own move
            # runs to its target (no watchdog on a Zaber stage)
            return shutter_done and (rig.stage or not board.moving(time.monotonic()))

        wait_for(safe, "the board at rest", timeout_s=GIVE_UP_S)
        assert board.faults_seen == ["WATCHDOG"]
        assert board.stopped
        kind, t_release = board.shutter_history[-1]
        assert kind == "close"
        elapsed = t_release - t_kill
        if rig_kind == "zaber":
            wait_for(lambda: not rig.motor.moving(time.monotonic()), "the Zaber move",
                     timeout_s=10.0)
            pos = rig.motor.position(time.monotonic())
            assert 0 <= pos <= rig.motor.settings["limit.max"]
    assert elapsed <= WATCHDOG_S + MARGIN_S


def test_sigkilled_host_firmware_stops_within_watchdog(host_firmware, tmp_path):
    setup = setup_file(tmp_path, WATCHDOG_RIG, SWEEP_VELOCITY)
    board = HostBoard(host_firmware, tmp_path / "pins.txt", start_steps=400)
    out = tmp_path / "rec.json"
    shutter = lambda: [v for _, v, _ in board.pin_changes(6)]  # noqa: E731 - PIN_SHUTTER
    try:
        proc = subprocess.Popen([sys.executable, "-m", "mitsweep", "capture", str(setup),
                                 "--port", board.port, "--out", str(out)], cwd=ROOT,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            t_kill = kill_mid_sweep(proc, lambda: shutter() == [1])
        finally:
            proc.kill()
            proc.wait()
        wait_for(lambda: shutter() == [1, 0], "the shutter's release", timeout_s=GIVE_UP_S)
        elapsed = board.pin_times(6)[-1][0] - t_kill
        # what the board said after the host died, then its own account of its state
        lines = read_lines(board.slave, 0.5)
        faults = [ln for ln in lines if ln.startswith("EV FAULT")]
        assert len(faults) == 1 and faults[0].endswith(" WATCHDOG"), lines
        os.write(board.slave, b"STATE\n")
        state = [ln for ln in read_lines(board.slave, 1.0) if ln.startswith("OK STATE")]
        assert len(state) == 1, state
        _, _, _, pos, homed, moving, shutter_open = state[0].split()
        assert (moving, shutter_open) == ("0", "0")
        assert int(pos) == int(faults[0].split()[3])   # stopped where it faulted
    finally:
        board.close()
    assert elapsed <= WATCHDOG_S + MARGIN_S


def read_lines(fd: int, quiet_s: float) -> list[str]:
    """Lines readable on ``fd`` until it has been quiet for ``quiet_s``."""
    data = b""
    while select.select([fd], [], [], quiet_s)[0]:
        data += os.read(fd, 4096)
    return [ln for ln in data.decode("ascii", "replace").split("\n") if ln]


@pytest.fixture(params=["simulator", "firmware"])
def board(request, tmp_path):
    """A homed board at step 0 with soft limits 0..10000, driven by the Python driver."""
    if request.param == "simulator":
        dev = PtyDevice(ArduinoModel(position=300)).__enter__()
        port, close = dev.port, dev.close
    else:
        host = HostBoard(request.getfixturevalue("host_firmware"), tmp_path / "pins.txt",
                         start_steps=300)
        port, close = host.port, host.close
    t = LineTransport(open_port(port), name=request.param, timeout_s=1.0)
    try:
        a = ArduinoSweepController(t, steps_per_mm=400)
        assert a.wait_ready(3.0)
        a.set_soft_limits(0, 25)
        a.home(velocity_mm_s=10, timeout_s=5)
        yield a
    finally:
        t.close()
        close()


def test_heartbeats_keep_a_move_longer_than_the_watchdog_alive(board):
    """A 2 s move under a 0.3 s watchdog ends DONE (not FAULT): the driver's PINGs, sent
    every quarter of the timeout while it waits, feed the board's watchdog."""
    board.set_watchdog(0.3)
    t0 = time.monotonic()
    # 800 steps at 400 steps/s
    board.move_to(2.0, velocity_mm_s=1.0, acceleration_mm_s2=100.0, timeout_s=5.0)
    # 2 s of travel plus ramps: longer than six watchdog periods
    assert time.monotonic() - t0 > 6 * 0.3
    pings = [e for e in board.transport.log.entries if e.direction == "tx"
             and e.text == "PING"]
    # one per quarter period would be ~27; one per period (6 over 1.8 s) is the least
    # that keeps the board from faulting, so that is the bar
    assert len(pings) >= 6
    assert not [e for e in board.events if e.name == "FAULT"]
