"""Checks against a real rig, run only when its port is given (pymeasure style):

    MITSWEEP_RIG_PORT=/dev/ttyACM0 pytest -m hardware tests/test_rig_hardware.py
    MITSWEEP_ZABER_PORT=/dev/ttyUSB0 ...                  (optional Zaber stage)

They identify the devices and read their state; they never move the stage or fire the
shutter (a capture is ``mitsweep capture``, run by a person watching the rig).
"""

from __future__ import annotations

import os

import pytest

from mitsweep.rig.arduino import ArduinoSweepController
from mitsweep.rig.transport import LineTransport, open_port
from mitsweep.rig.zaber import ZaberStage

ARDUINO_PORT = os.environ.get("MITSWEEP_RIG_PORT")
ZABER_PORT = os.environ.get("MITSWEEP_ZABER_PORT")

pytestmark = pytest.mark.hardware


@pytest.mark.skipif(not ARDUINO_PORT, reason="set MITSWEEP_RIG_PORT to the Arduino's port")
def test_arduino_identifies_and_reports_state():
    t = LineTransport(open_port(ARDUINO_PORT), name="arduino", timeout_s=1.0)
    try:
        board = ArduinoSweepController(t, steps_per_mm=400)
        board.wait_ready(3.0)
        assert board.identify().startswith("mitsweep-sweep")
        state = board.state()
        assert not state.moving
    finally:
        t.close()


@pytest.mark.skipif(not ZABER_PORT, reason="set MITSWEEP_ZABER_PORT to the Zaber stage's port")
def test_zaber_identifies_and_reports_state():
    t = LineTransport(open_port(ZABER_PORT), name="zaber", timeout_s=1.0)
    try:
        stage = ZaberStage(t, steps_per_mm=1 / 0.047625e-3)
        assert stage.identify().startswith("zaber device id")
        assert stage.state().fault is None
    finally:
        t.close()
