"""Full captures against the simulated devices on ptys (real serial I/O, real time).

Timing resolution of the simulator: event timestamps are computed from the analytic
motion and quantised to the board's 1 µs ``micros()``; the measured exposure is the
difference of two such stamps, so it must equal the planned one within 2 µs
(:data:`rig_fixtures.TIMER_RESOLUTION_S`).
"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
from rig_fixtures import (TIMER_RESOLUTION_S, ZABER_MAX_POSITION, arduino_capture,
                          assert_board_timed_exposure, complete_exposure, soft_limit_steps,
                          zaber_capture)
from rig_fixtures import sphere, sphere_zaber  # noqa: F401 - fixtures

from mitsweep.rig import (DeviceFault, HostTooSlow, RigPorts, load_capture_record, measured_motion,
                          plan_capture, run_capture)
from mitsweep.rig.capture import SHUTTER_ATTEMPTS
from mitsweep.rig.simulator import ArduinoModel, Fault, PtyDevice, ZaberModel


@pytest.mark.parametrize("checksums", [False, True])
def test_arduino_capture_measures_planned_exposure(sphere, tmp_path, checksums):
    plan = plan_capture(sphere)
    out = tmp_path / "capture.json"
    board = arduino_capture(sphere, out, plan, checksums=checksums)
    data, exp = complete_exposure(out, plan)
    assert data["homed"], "an unhomed stage must be homed before the sweep"
    # the shutter was open exactly once, for the planned time, between the planned steps
    assert_board_timed_exposure(board, exp, plan)
    # every line exchanged is in the record, sent and received
    texts = [c["text"].split("*")[0] for c in data["commands"]]
    assert "ID" in texts and any(t.startswith("SWEEP ") for t in texts)
    assert any(t.startswith("HOME ") for t in texts)
    assert texts.count("OK SWEEP") == 1
    if checksums:
        assert all("*" in c["text"] for c in data["commands"]
                   if c["dir"] == "rx" and not c["text"].startswith("READY"))


def test_arduino_capture_motion_profile_is_constant_velocity(sphere, tmp_path):
    out = tmp_path / "capture.json"
    plan = plan_capture(sphere)
    arduino_capture(sphere, out, plan, at_approach=True)
    t, s = measured_motion(out)
    assert t[0] == 0.0 and t[-1] == pytest.approx(plan.planned_exposure_s, abs=TIMER_RESOLUTION_S)
    assert len(t) >= 10    # EV POS every 50 ms over ~0.7 s
    # at constant velocity the sensor distance is linear in time: residuals of a line fit
    # are below one step (the stepper's position is integer steps)
    fit = np.polyfit(t, s, 1)
    assert np.max(np.abs(np.polyval(fit, t) - s)) <= 1.0 / plan.steps_per_mm
    assert abs(fit[0]) == pytest.approx(plan.velocity_actual_mm_s, rel=2e-3)
    data = json.loads(out.read_text())
    assert not data["homed"]   # position known: no homing


def test_measured_motion_feeds_tabulated_profile(sphere, tmp_path):
    from mitsweep.optics import motion

    out = tmp_path / "capture.json"
    plan = plan_capture(sphere)
    arduino_capture(sphere, out, plan, at_approach=True)
    profile = motion.MotionProfile.tabulated(*measured_motion(out))
    assert profile.start == pytest.approx(plan.sensor_start, abs=0.5 / plan.steps_per_mm)
    assert profile.end == pytest.approx(plan.sensor_end, abs=1.0 / plan.steps_per_mm)


def test_zaber_capture_with_arduino_shutter(sphere_zaber, tmp_path):
    plan = plan_capture(sphere_zaber, stage="zaber")
    out = tmp_path / "capture.json"
    record, stage = zaber_capture(sphere_zaber, out, plan)
    assert stage.settings["limit.max"] == soft_limit_steps(plan)[1]
    data, exp = complete_exposure(out, plan)
    # positions come from polls interpolated at the shutter times: the record's timing
    # uncertainty (the SHUTTER round trip's half for the clock mapping, plus half the
    # round trip of the polls used); and the host-timed shutter opens late or early by
    # at most the host's latency from sending the move to the SHUTTER reply (a few ms
    # when idle, more under load): allow both at the velocity. A complete record's
    # latency keeps the whole exposure at constant velocity (within the settle distance)
    placement_s = data["clock_map"]["placement_uncertainty_s"]
    assert 0 < placement_s <= plan.settle_distance / plan.velocity_actual_mm_s
    tol = plan.velocity_actual_mm_s * (exp["timing_uncertainty_s"] + placement_s)
    assert exp["open_position_mm"] == pytest.approx(plan.open_position, abs=tol)
    assert exp["close_position_mm"] == pytest.approx(plan.close_position, abs=tol)
    assert record.devices["zaber"].startswith("zaber device id")


#: Injected host latency at the SHUTTER exchange: four times the settle time of the fast
#: rig's sweep (0.05 mm at 1 mm/s = 0.05 s), so no scheduling luck makes it fit.
SLOW_SHUTTER_REPLY_S = 0.2


@pytest.mark.parametrize("slow_attempts", [1, SHUTTER_ATTEMPTS])
def test_zaber_capture_host_too_slow_to_time_the_shutter(sphere_zaber, tmp_path,
                                                         slow_attempts):
    """The board answers SHUTTER late (it acts at once: as if the host read the reply
    late), so the host cannot bound when the shutter opened relative to the move better
    than the settle distance allows. Each such attempt is abandoned with the shutter
    released; a later fast attempt completes, and none fast fails the capture safely."""
    setup = sphere_zaber
    plan = plan_capture(setup, stage="zaber")
    allowed_s = plan.settle_distance / plan.velocity_actual_mm_s
    assert SLOW_SHUTTER_REPLY_S > 2 * allowed_s
    out = tmp_path / "capture.json"
    slow = [Fault("slow_reply", command="SHUTTER", delay_s=SLOW_SHUTTER_REPLY_S)] * slow_attempts
    with PtyDevice(ArduinoModel(slow)) as board, \
            PtyDevice(ZaberModel(max_position=ZABER_MAX_POSITION)) as stage:
        ports = RigPorts(arduino=board.port, zaber=stage.port)
        if slow_attempts == SHUTTER_ATTEMPTS:
            with pytest.raises(HostTooSlow, match="host too slow to time the shutter"):
                run_capture(setup, ports, out=out)
        else:
            run_capture(setup, ports, out=out)
        now = time.monotonic()
        assert not stage.model.moving(now) and not board.model.shutter_open
        # every abandoned attempt's exposure was cut short by the host
        opens = [t for what, t in board.model.shutter_history if what == "open"]
        assert len(opens) == SHUTTER_ATTEMPTS if slow_attempts == SHUTTER_ATTEMPTS \
            else slow_attempts + 1
    data = load_capture_record(out)
    abandoned = [m for m in data["marks"] if "host too slow" in m["what"]]
    assert len(abandoned) == slow_attempts
    if slow_attempts == SHUTTER_ATTEMPTS:
        assert data["complete"] is False and data["status"] == "host too slow"
        assert "host too slow" in data["error"] and "rig.settle_distance" in data["error"]
        assert data["safety"] and all(a["ok"] for a in data["safety"])
        assert data["measured"] is None, "an abandoned exposure must not be measured"
    else:
        complete_exposure(out, plan)
        assert data["clock_map"]["placement_uncertainty_s"] <= allowed_s


def test_complete_record_holds_the_reference_geometry_of_its_measured_motion(sphere, tmp_path):
    """The record's reference sensor distance is the measured span's midpoint (the rule of
    optics.reference), over the measured samples; an incomplete record has none."""
    out = tmp_path / "capture.json"
    plan = plan_capture(sphere)
    arduino_capture(sphere, out, plan, at_approach=True)
    data = load_capture_record(out)
    ref = data["reference"]
    _, s = measured_motion(data)
    assert ref["reference_sensor_distance_mm"] == pytest.approx(0.5 * (s.min() + s.max()),
                                                                abs=1e-12)
    assert ref["motion"]["kind"] == "tabulated"
    assert ref["motion"]["positions_mm"] == pytest.approx(s.tolist(), abs=0)
    # within a step of the plan's midpoint: the measured motion is the planned one
    assert ref["reference_sensor_distance_mm"] == pytest.approx(
        0.5 * (plan.sensor_start + plan.sensor_end), abs=1.0 / plan.steps_per_mm)
    assert ref["sweep"]["sensor_start_mm"] == pytest.approx(plan.sensor_start, abs=1e-12)

    out2 = tmp_path / "interrupted.json"
    with PtyDevice(ArduinoModel([Fault("fault_flag", at_fraction=0.5)], homed=True,
                                position=plan.approach_steps)) as dev:
        with pytest.raises(DeviceFault):
            run_capture(sphere, RigPorts(arduino=dev.port), out=out2)
    assert load_capture_record(out2)["reference"] is None
