"""The simulator package: one command table per model, and the by-hand server."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest
import serial

from mitsweep.rig.sim import ArduinoModel, Fault, PtyDevice, ZaberModel


def test_both_models_dispatch_through_their_command_table():
    board, stage = ArduinoModel(homed=True), ZaberModel(homed=True)
    assert {w for (w,) in board.commands} >= {"ID", "STATE", "SWEEP", "SHUTTER", "STOP"}
    assert ("move", "abs") in stage.commands and ("get",) in stage.commands
    # an arity the table does not declare is refused by the dispatcher, not the method
    assert board.handle(b"STATE 1", 0.0) == [b"ERR SYNTAX STATE takes 0 arguments\n"]
    assert board.handle(b"NOPE", 0.0) == [b"ERR SYNTAX unknown command NOPE\n"]
    assert stage.handle(b"/1 1 get pos", 0.0) == [b"@01 1 OK IDLE -- 0\r\n"]
    assert stage.handle(b"/1 1 move abs", 0.0) == [b"@01 1 RJ IDLE -- BADCOMMAND\r\n"]
    assert stage.handle(b"/1 1 estop", 0.0) == [b"@01 1 OK IDLE -- 0\r\n"]


def test_zaber_model_runs_in_the_drivers_units():
    """maxspeed/accel data values become microsteps/s and /s² by zaber.SPEED_UNIT and
    ACCEL_UNIT: a move of 1e5 microsteps at maxspeed 163840 (1e5 microsteps/s) and accel
    16384 (1e5 microsteps/s²) takes 1 + 1 = 2 s (D/v + v/a)."""
    stage = ZaberModel(homed=True)
    stage.handle(b"/1 1 set maxspeed 163840", 0.0)
    stage.handle(b"/1 1 set accel 16384", 0.0)
    stage.handle(b"/1 1 move abs 100000", 0.0)
    assert stage.move.duration == pytest.approx(2.0, rel=1e-12)


@pytest.mark.parametrize("device, query, reply", [
    ("zaber", b"/1 1 get pos\n", b"@01 1 OK IDLE -- 0\r\n"),
    ("arduino", b"PING\n", b"OK PING "),
])
def test_python_m_simulator_serves_a_device(device, query, reply):
    proc = subprocess.Popen([sys.executable, "-m", "mitsweep.rig.simulator", device,
                             "--homed"], stdout=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/"), port
        with serial.Serial(port, 115200, timeout=3.0) as ser:
            if device == "arduino":       # opening the port resets the board: READY first
                assert ser.readline().startswith(b"READY ")
            ser.write(query)
            assert ser.readline().startswith(reply)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            assert proc.wait(timeout=5) == 0
        finally:
            if proc.poll() is None:
                proc.kill()


class _HostOpensAsReadyFallsDue(ArduinoModel):
    """Opens the host's end of the port (pyserial: a flush, which resets the board) at the
    moment the model thread has decided to emit a READY line but not yet written it."""

    port: str = ""
    host: serial.Serial | None = None

    def due(self, now):
        out = super().due(now)
        if self.host is None and any(d.startswith(b"READY ") for d in out):
            self.host = serial.Serial(self.port, 115200, timeout=0)
        return out


def test_opening_the_port_yields_one_ready_line_whenever_the_host_opens_it():
    """The race CI hit once: the host opened (and flushed) the port just as the power-on
    READY fell due, the model thread wrote that READY after the flush, then saw the flush
    and reset, printing a second READY in the middle of the session. Whenever the host
    opens the port it must see exactly one READY line, the reset's."""
    model = _HostOpensAsReadyFallsDue(homed=True, boot_time_s=0.05)
    dev = PtyDevice(model)
    model.port = dev.port
    with dev:
        time.sleep(0.2)                       # past the power-on READY's due time
        if model.host is None:                # no READY at power-on: the host opens now
            model.host = serial.Serial(dev.port, 115200, timeout=0)
        ser = model.host
        try:
            deadline, data = time.monotonic() + 0.5, b""
            while time.monotonic() < deadline:
                data += ser.read(4096)
                time.sleep(0.01)
        finally:
            ser.close()
    ready = [ln for ln in data.splitlines() if ln.startswith(b"READY ")]
    assert len(ready) == 1, data


def test_zaber_model_refuses_an_arduino_only_fault():
    with pytest.raises(ValueError, match="'brownout' is an Arduino fault"):
        ZaberModel([Fault("brownout")])
