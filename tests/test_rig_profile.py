"""Motion profiles on the rig: the plan's step-rate table, its refusals before any
motion, the protocol exchanges, and captures against the simulators (real pty I/O)
whose measured motion follows the planned profile.

Timing resolution of the simulators: the Arduino model stamps events from the analytic
motion at the board's 1 µs ``micros()``; a sample's planned position is the table's at
the sample's time, so the measured position agrees within one step (the stepper stands
at the floor of its travel) plus the peak rate over two 1 µs stamps.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cli_contract import refused
from conftest import ROOT, run_cli
from rig_fixtures import (TIMER_RESOLUTION_S, ZABER_MAX_POSITION, arduino_capture,
                          assert_board_timed_exposure, assert_safe, bent_profile,
                          complete_exposure, sweep_of, zaber_capture)
from rig_fixtures import sphere, sphere_zaber  # noqa: F401 - fixtures
from test_rig_cli import setup_file
from test_rig_firmware import HostBoard
from test_rig_signals import ZABER_RIG, finish, received, signal_exit_status, wait_for
from test_rig_watchdog import MARGIN_S, WATCHDOG_RIG, WATCHDOG_S, read_lines

from mitsweep.config import SetupError, load_setup
from mitsweep.optics.motion import MotionProfile
from mitsweep.optics.motion_file import save_motion_file
from mitsweep.rig import (DeviceError, DeviceFault, PortLost, ProtocolError, ReplyTimeout, RigPorts,
                          load_capture_record, measured_motion, plan_capture, run_capture)
from mitsweep.rig.arduino import MAX_STEP_RATE, MAX_TABLE_SEGMENTS, ArduinoSweepController
from mitsweep.rig.errors import PlanError
from mitsweep.rig.sim.base import command
from mitsweep.rig.simulator import ArduinoModel, Fault, PtyDevice, ZaberModel
from mitsweep.rig.testing import expected_protocol
from mitsweep.rig.zaber import SPEED_UNIT, ZaberStage


@pytest.fixture(scope="module")
def profile(sphere):
    return bent_profile(sweep_of(sphere))


def setup_for(stage, sphere, sphere_zaber):
    return sphere if stage == "arduino" else sphere_zaber


# -- the plan ------------------------------------------------------------------------------
@pytest.mark.parametrize("stage", ["arduino", "zaber"])
def test_table_follows_profile_within_its_stated_tolerance(sphere, sphere_zaber, profile,
                                                           stage):
    setup = setup_for(stage, sphere, sphere_zaber)
    exposure = 0.7
    plan = plan_capture(setup, stage=stage, motion=profile, exposure_s=exposure)
    table, spm = plan.profile, plan.steps_per_mm
    assert len(table.steps) <= len(profile.times) - 1
    # the profile's stage travel from the open step, at dense times: brute force against
    # the table's reported deviation (exact for two piecewise-linear travels)
    t = np.linspace(0.0, exposure, 20001)
    x = ((profile.sensor_distance(t / exposure) - plan.sensor_distance_at_zero)
         / plan.sensor_direction)                       # stage position, mm
    ideal = plan.direction * (x * spm - plan.open_steps)
    # placed within half a step of the profile's start, as the linear sweep's window
    assert abs(table.offset_steps) <= 0.5 and table.offset_steps == pytest.approx(ideal[0])
    dense = float(np.max(np.abs(table.travel_at(t) - (ideal - ideal[0]))))
    assert dense <= table.max_deviation_steps + 1e-9
    # boundaries at the profile's own step crossings: within the bend of one knot, under
    # half a step here (~4-5 steps per interval at 400 steps/mm, the velocity changing
    # by < 1 % from one to the next); the durations add up to the exposure (Arduino:
    # whole µs; Zaber: each boundary within a speed quantum's time, no drift)
    assert table.max_deviation_steps <= 0.5
    if stage == "arduino":
        assert table.duration_s == pytest.approx(exposure, abs=1e-6)
        assert all(u == round(d * 1e6) for u, d in zip(table.driver, table.durations_s))
        assert max(k / d for k, d in zip(table.steps, table.durations_s)) <= MAX_STEP_RATE
    else:
        assert table.duration_s == pytest.approx(exposure, abs=1e-6)
        speeds = np.array(table.steps) / np.array(table.durations_s)
        assert np.allclose(speeds * SPEED_UNIT, table.driver, rtol=0, atol=1e-6)
    # no segment runs faster than the profile's peak (quantisation asks for no more)
    rates = np.array(table.steps) / np.array(table.durations_s)
    assert rates.max() <= table.max_velocity_mm_s * spm * (1 + 1e-3)
    assert plan.planned_exposure_s == pytest.approx(table.duration_s, abs=1e-6)
    # the shutter window is the profile's span; ramps and settle outside it
    assert plan.sensor_distance(plan.open_position) == pytest.approx(profile.start, abs=0.5 / spm)
    assert plan.sensor_distance(plan.close_position) == pytest.approx(profile.end, abs=1.0 / spm)
    assert plan.close_steps - plan.open_steps == plan.direction * table.total_steps
    xs = [plan.approach_steps, plan.open_steps, plan.close_steps, plan.end_steps]
    assert xs == sorted(xs, reverse=plan.direction < 0)
    margin = setup.rig.settle_distance * spm
    v_in, v_out = table.entry_rate, table.exit_rate
    a = plan.acceleration_mm_s2 * spm
    assert abs(plan.open_steps - plan.approach_steps) >= v_in ** 2 / (2 * a) + margin - 1e-9
    assert abs(plan.end_steps - plan.close_steps) >= v_out ** 2 / (2 * a) + margin - 1e-9
    # velocities: the profile's (1 + bend) and (1 - bend) times the mean at its ends
    mean = plan.translation / exposure
    assert table.max_velocity_mm_s == pytest.approx(1.3 * mean, rel=0.02)
    assert plan.velocity_mm_s == pytest.approx(mean, rel=1e-12)


def test_linear_profile_plans_the_linear_sweeps_shutter_window(sphere):
    sr = sweep_of(sphere)
    linear = plan_capture(sphere)
    plan = plan_capture(sphere, motion=MotionProfile.linear(sr.sensor_start, sr.sensor_end),
                        exposure_s=sr.exposure_s)
    assert len(plan.profile.steps) == 1
    assert (plan.open_steps, plan.close_steps) == (linear.open_steps, linear.close_steps)
    # the Arduino times the table in whole µs: half of one
    assert plan.planned_exposure_s == pytest.approx(sr.exposure_s, abs=0.5e-6)
    # the default exposure is the linear sweep's: travel at sweep.velocity
    default = plan_capture(sphere, motion=MotionProfile.linear(sr.sensor_start, sr.sensor_end))
    assert default.exposure_s == pytest.approx(sr.exposure_s, rel=1e-12)  # round-off


def test_profile_with_more_knots_than_the_board_holds_is_reknotted(sphere):
    sr = sweep_of(sphere)
    plan = plan_capture(sphere, motion=bent_profile(sr, n=300), exposure_s=0.7)
    table = plan.profile
    assert len(table.steps) == MAX_TABLE_SEGMENTS
    # chords over h = 1/64 of the exposure of the parabola u(t) deviate from it by at
    # most bend |Δ| h² / 4; the new knots lie on the 300-knot polyline, itself within
    # bend |Δ| (1/299)² / 4 of the parabola
    bound = 0.3 * sr.translation / 4 * (1 / 64 ** 2 + 1 / 299 ** 2)
    assert 0.9 * bound <= table.resample_deviation <= bound
    assert "re-knotted" in plan.summary()


def with_rig(setup, **rig):
    return dataclasses.replace(setup, rig=dataclasses.replace(setup.rig, **rig))


@pytest.mark.parametrize("case, match", [
    ("too fast", "more than rig.max_velocity"),
    ("too abrupt", "more than rig.acceleration"),
    ("crosses focal length", "focal length"),
    ("turns back", "must be monotonic"),
    ("starts at rest", "rests at"),
    ("too long", "outside the camera's range"),
])
def test_profile_the_stage_cannot_follow_is_refused(sphere, case, match):
    sr = sweep_of(sphere)
    s0, s1 = sr.sensor_start, sr.sensor_end
    exposure = 0.7
    setup = sphere
    if case == "too fast":           # 0.695 mm in 0.05 s: ~18 mm/s > 10 mm/s
        motion, exposure = bent_profile(sr), 0.05
    elif case == "too abrupt":       # velocity halves between two knots: ~0.7 mm/s in
        t = [0.0, 0.5, 1.0]          # ~0.35 s, 2 mm/s^2 > 1 mm/s^2
        motion = MotionProfile.tabulated(t, [s0, s0 + (s1 - s0) * 2 / 3, s1])
        setup = with_rig(sphere, acceleration=1.0)
    elif case == "crosses focal length":
        f = sphere.lens.focal_length
        motion = MotionProfile.linear(f + 0.3, f - 0.2)
    elif case == "turns back":
        motion = MotionProfile.tabulated([0, 0.4, 0.7, 1.0], [s0, s1, s0 + 0.5 * (s1 - s0), s1])
    elif case == "starts at rest":
        motion = MotionProfile.tabulated([0, 0.2, 1.0], [s0, s0, s1])
    else:                            # 60 s > rig.max_exposure_s = 30 s
        motion, exposure = bent_profile(sr), 60.0
    with pytest.raises(PlanError, match=match):
        plan_capture(setup, motion=motion, exposure_s=exposure)


def test_empty_profile_is_refused_when_made():
    with pytest.raises(SetupError, match="empty sweep"):
        MotionProfile.tabulated([0.0, 1.0], [58.0, 58.0])
    with pytest.raises(SetupError, match=">= 2"):
        MotionProfile.tabulated([], [])


def test_a_profile_whole_steps_cannot_follow_is_refused(sphere):
    """Coarse steps (9.3 steps/mm: 6.4 steps over the sweep) and knots whose bends lie
    within a step of each other: the best table of whole steps is 1.65 steps off (found
    by a random search over such profiles), more than the one step allowed."""
    sr = sweep_of(sphere)
    t = np.array([0.0, 0.3341, 0.3349, 0.3359, 0.5883, 0.5894, 0.7406, 0.7418, 0.7424,
                  1.0169])
    x = np.array([0.0, 0.482, 1.977, 2.684, 3.595, 4.796, 5.057, 6.264, 6.369, 6.436])
    coarse = with_rig(sphere, steps_per_mm=x[-1] / sr.translation, max_velocity=1000.0,
                      acceleration=1e7)
    motion = MotionProfile.tabulated(t, sr.sensor_start
                                     + (sr.sensor_end - sr.sensor_start) * x / x[-1])
    with pytest.raises(PlanError, match=r"deviates from it by 1\.6\d steps"):
        plan_capture(coarse, motion=motion, exposure_s=float(t[-1]))


@pytest.mark.parametrize("stage", ["arduino", "zaber"])
def test_a_dwell_inside_the_exposure_is_refused(sphere, sphere_zaber, stage):
    setup = with_rig(setup_for(stage, sphere, sphere_zaber), acceleration=1000.0)
    sr = sweep_of(setup)
    s0, s1 = sr.sensor_start, sr.sensor_end
    mid = s0 + 0.5 * (s1 - s0)
    dwell = MotionProfile.tabulated([0, 0.45, 0.55, 1.0], [s0, mid, mid, s1])
    with pytest.raises(PlanError, match="rests at"):
        plan_capture(setup, stage=stage, motion=dwell, exposure_s=0.7)


def test_a_slow_long_interval_before_a_fast_short_one_is_refused(sphere):
    """The velocity change must fit in the shorter interval: 9 -> 0.05 mm/s within the
    fast interval's 7.7 ms needs ~1160 mm/s², though spread over the mean of the two
    intervals (the slow one lasts 1.39 s) it would look like ~13 mm/s²."""
    sr = sweep_of(sphere)
    s0, s1 = sr.sensor_start, sr.sensor_end
    step = (s1 - s0) / 10
    t_slow, t_fast = abs(step) / 0.05, abs(step) / 9.0
    times = np.concatenate([[0.0], np.cumsum([t_fast] * 4 + [t_slow] + [t_fast] * 5)])
    motion = MotionProfile.tabulated(times, s0 + step * np.arange(11))
    with pytest.raises(PlanError, match="more than rig.acceleration"):
        plan_capture(with_rig(sphere, acceleration=200.0), motion=motion,
                     exposure_s=float(times[-1]))


# -- the protocol ----------------------------------------------------------------------
def test_arduino_table_upload_is_acknowledged_with_running_totals():
    exchanges = [(b"TABLE 2\n", b"OK TABLE 2\n"),
                 (b"SEG 0 40 100000\n", b"OK SEG 0 40 100000\n"),
                 (b"SEG 1 20 100000\n", b"OK SEG 1 60 200000\n"),
                 (b"TSWEEP 300 4000 100 160\n", b"OK TSWEEP\n")]
    with expected_protocol(lambda t: ArduinoSweepController(t, steps_per_mm=400),
                           exchanges) as board:
        board.load_table([40, 20], [100000, 100000])
        board.start_table_sweep(target=300, acceleration_mm_s2=10.0, open_at=100, close_at=160)


def test_arduino_table_with_a_wrong_total_fails_before_motion():
    # the board acknowledges segment 1 with totals that are not the host's: a line lost
    # or altered on the way (checksums off)
    exchanges = [(b"TABLE 2\n", b"OK TABLE 2\n"),
                 (b"SEG 0 40 100000\n", b"OK SEG 0 40 100000\n"),
                 (b"SEG 1 20 100000\n", b"OK SEG 1 61 200000\n")]
    with pytest.raises(ProtocolError, match="totals"):
        with expected_protocol(lambda t: ArduinoSweepController(t, steps_per_mm=400),
                               exchanges) as board:
            board.load_table([40, 20], [100000, 100000])


def test_a_protocol_2_board_runs_linear_sweeps_but_no_table():
    exchanges = [(b"ID\n", b"OK ID mitsweep-sweep 1.1 2\n")]
    with expected_protocol(lambda t: ArduinoSweepController(t, steps_per_mm=400),
                           exchanges) as board:
        assert board.identify() == "mitsweep-sweep 1.1 (protocol 2)"
        with pytest.raises(DeviceError, match="no step-rate tables"):
            board.load_table([40], [100000])     # nothing sent


class Protocol2Board(ArduinoModel):
    """Firmware 1.1: the watchdog, no tables."""

    @command("ID", nargs=0)
    def cmd_id(self, nums, now):
        return [self.encode_line("OK ID mitsweep-sweep 1.1 2")]


def test_profile_capture_on_a_protocol_2_board_fails_before_any_motion(sphere, profile,
                                                                        tmp_path):
    plan = plan_capture(sphere, motion=profile, exposure_s=0.7)
    out = tmp_path / "capture.json"
    with PtyDevice(Protocol2Board()) as dev:
        with pytest.raises(DeviceError, match="flash scripts/firmware"):
            run_capture(sphere, RigPorts(arduino=dev.port), out=out, plan=plan)
        words = [text.split()[0] for _, d, text in dev.model.log if d == "rx"]
    assert not {"HOME", "MOVE", "TABLE", "TSWEEP"} & set(words), words
    assert load_capture_record(out)["status"] == "error"


def test_zaber_stream_is_stored_then_started_by_one_command():
    ok = b"@01 0 OK IDLE -- 0\r\n"
    sent = [b"stream 1 setup disable", b"stream buffer 1 erase",
            b"stream 1 setup store 1 1", b"stream 1 set tanaccel 164",
            b"stream 1 set maxspeed 1638", b"stream 1 line abs 2000",
            b"stream 1 set maxspeed 3277", b"stream 1 line abs 4000",
            b"stream 1 setup disable", b"stream 1 setup live 1"]
    exchanges = [(b"/1 0 " + s + b"\n", ok) for s in sent]
    exchanges.append((b"/1 0 stream 1 call 1\n", b"@01 0 OK BUSY -- 0\r\n"))
    with expected_protocol(lambda t: ZaberStage(t, steps_per_mm=1000), exchanges) as z:
        z.load_stream([(2000, 1638), (4000, 3277)], accel=164)
        z.start_stream()


# -- captures against the simulators -------------------------------------------------
def test_arduino_capture_runs_the_profile_it_planned(sphere, profile, tmp_path):
    plan = plan_capture(sphere, motion=profile, exposure_s=0.7)
    out = tmp_path / "capture.json"
    board = arduino_capture(sphere, out, plan, checksums=True)
    data, exp = complete_exposure(out, plan)
    # shutter window: open once, on the planned steps, for the table's duration
    assert_board_timed_exposure(board, exp, plan)
    # measured motion (EV POS every 50 ms) against the plan, within the timing resolution
    cmp = data["measured"]["profile"]
    peak = max(k / d for k, d in zip(plan.profile.steps, plan.profile.durations_s))
    assert cmp["tolerance_steps"] == pytest.approx(1 + peak * TIMER_RESOLUTION_S)
    assert cmp["max_deviation_steps"] <= cmp["tolerance_steps"]
    assert len(cmp["time_s"]) >= 10
    # and against the optimised profile itself: the table's deviation on top
    t, s = measured_motion(out)
    ideal = profile.sensor_distance(t / plan.exposure_s)
    bound = (cmp["tolerance_steps"] + plan.profile.max_deviation_steps) / plan.steps_per_mm
    assert np.max(np.abs(s - ideal)) <= bound
    # a non-uniform profile, not a linear sweep: the measured velocity over the first and
    # the last 0.2 s (line fits) differs as the profile's does, ~1.55x
    def speed_ratio(s_mm):
        first, last = t <= 0.2, t >= t[-1] - 0.2
        return np.polyfit(t[first], s_mm[first], 1)[0] / np.polyfit(t[last], s_mm[last], 1)[0]

    assert speed_ratio(ideal) > 1.5     # measured 1.59
    # line fits over 0.2 s of samples within ~1 step (2.5 µm) of the plan: measured 0.64 %
    # (the simulator's motion is analytic: the same on every run)
    assert speed_ratio(s) == pytest.approx(speed_ratio(ideal), rel=0.03)
    texts = [c["text"].split("*")[0] for c in data["commands"]]
    assert texts.count("OK TSWEEP") == 1 and not any(x.startswith("SWEEP ") for x in texts)
    assert sum(x.startswith("SEG ") for x in texts) == len(plan.profile.steps)


def test_zaber_capture_runs_the_profile_as_a_stream(sphere_zaber, profile, tmp_path):
    plan = plan_capture(sphere_zaber, stage="zaber", motion=profile, exposure_s=0.7)
    out = tmp_path / "capture.json"
    zaber_capture(sphere_zaber, out, plan)
    data, _ = complete_exposure(out, plan)
    # positions from polls: each known to half its round trip, the clock mapping to half
    # the SHUTTER round trip, the shutter placed to the host's latency (the record's
    # tolerance); the stream's lines are the table's
    cmp = data["measured"]["profile"]
    assert cmp["max_deviation_steps"] <= cmp["tolerance_steps"]
    texts = [c["text"].split(":")[0] for c in data["commands"]]
    lines = [x for x in texts if " stream 1 line abs " in x]
    assert len(lines) == len(plan.profile.steps) + 2
    assert lines[-1].endswith(f" {plan.end_steps}")
    assert sum(" stream 1 call 1" in x for x in texts) == 1


# -- safety during a table sweep --------------------------------------------------------
@pytest.mark.parametrize("fault, error, status", [
    (Fault("no_reply", command="TSWEEP"), ReplyTimeout, "timeout"),
    (Fault("garbage", command="SEG"), ProtocolError, "error"),
    (Fault("fault_flag", at_fraction=0.5), DeviceFault, "fault"),
    (Fault("late_event", delay_s=5.0), ReplyTimeout, "timeout"),
    (Fault("unplug", at_fraction=0.5), PortLost, "port lost"),
], ids=lambda x: f"{x.kind}-{x.command}" if isinstance(x, Fault) else None)
def test_fault_during_table_sweep_leaves_the_rig_safe(sphere, profile, tmp_path, fault,
                                                      error, status):
    plan = plan_capture(sphere, motion=profile, exposure_s=0.7)
    out = tmp_path / "capture.json"
    lo, hi = 0, round(plan.soft_limit_max * plan.steps_per_mm)
    with PtyDevice(ArduinoModel([fault], homed=True, position=plan.approach_steps)) as dev:
        t0 = time.monotonic()
        with pytest.raises(error):
            run_capture(sphere, RigPorts(arduino=dev.port), out=out, plan=plan)
        assert time.monotonic() - t0 < plan.sweep_duration_s * 1.25 + 2.5
        assert_safe(dev.model, lo, hi)
        if fault.kind in ("fault_flag", "unplug"):    # stopped part-way through the table
            assert dev.model.position(time.monotonic()) != plan.end_steps
    data = load_capture_record(out)
    assert data["complete"] is False and data["status"] == status
    assert data["safety"] and data["safety"][0]["ok"] is (fault.kind != "unplug")


def test_zaber_fault_during_stream_stops_and_releases_the_shutter(sphere_zaber, profile,
                                                                  tmp_path):
    plan = plan_capture(sphere_zaber, stage="zaber", motion=profile, exposure_s=0.7)
    out = tmp_path / "capture.json"
    with PtyDevice(ArduinoModel()) as board, \
            PtyDevice(ZaberModel([Fault("fault_flag", at_fraction=0.5)],
                                 max_position=ZABER_MAX_POSITION)) as stage:
        with pytest.raises(DeviceFault):
            run_capture(sphere_zaber, RigPorts(arduino=board.port, zaber=stage.port),
                        out=out, plan=plan)
        now = time.monotonic()
        assert not stage.model.moving(now) and not board.model.shutter_open
        assert stage.model.position(now) != plan.end_steps
    data = load_capture_record(out)
    assert data["status"] == "fault" and all(a["ok"] for a in data["safety"])


# -- the command line ----------------------------------------------------------------
def motion_json(path: Path, times, distances, exposure_s=0.7) -> Path:
    """A motion-profile file written by hand (the format of mitsweep.optics.motion_file),
    so that bad tables can be written too."""
    path.write_text(json.dumps({"format": "mitsweep-motion-profile", "version": 1,
                                "times": list(times), "sensor_distances_mm": list(distances),
                                "exposure_s": exposure_s,
                                "provenance": {"generator": "test_rig_profile"}}))
    return path


@pytest.fixture
def rig_setup_file(tmp_path):
    return setup_file(tmp_path)


def test_cli_capture_with_motion_file_against_simulator(rig_setup_file, sphere, profile,
                                                        tmp_path):
    motion = save_motion_file(tmp_path / "profile.json", profile, exposure_s=0.7,
                              provenance={"generator": "test_rig_profile"})
    rc, stdout, err = run_cli("capture", rig_setup_file, "--motion", motion, "--dry-run",
                              timeout=120)
    assert rc == 0, err
    assert "motion profile     63 segments" in stdout
    out = tmp_path / "rec.json"
    with PtyDevice(ArduinoModel()) as dev:
        rc, stdout, err = run_cli("capture", rig_setup_file, "--port", dev.port, "--motion",
                                  motion, "--out", out, "--json", timeout=120)
    assert rc == 0, err
    summary = json.loads(stdout)
    assert summary["complete"]
    assert summary["measured_exposure_s"] == pytest.approx(0.7, abs=TIMER_RESOLUTION_S)
    assert summary["profile_max_deviation_steps"] <= summary["profile_tolerance_steps"]
    data = load_capture_record(out)
    assert data["motion"]["file"] == str(motion)
    assert data["motion"]["provenance"] == {"generator": "test_rig_profile"}
    assert data["plan"]["profile"]["segments"] == 63


@pytest.mark.parametrize("case, message", [
    ("too fast", "cannot follow"),
    ("too abrupt", "mm/s^2"),
    ("slow to fast", "at knot 2"),
    ("crosses focal length", "focal length"),
    ("empty", "empty table"),
    ("non-monotonic", "monotonic"),
])
def test_cli_bad_motion_exits_2_with_one_line_before_any_motion(rig_setup_file, sphere,
                                                                tmp_path, capsys, case,
                                                                message):
    """In this process (``cli_contract.refused``): exit 2, one line, no traceback."""
    sr = sweep_of(sphere)
    s0, s1 = sr.sensor_start, sr.sensor_end
    f = sphere.lens.focal_length
    t, d, exposure = [0.0, 0.5, 1.0], [s0, 0.5 * (s0 + s1), s1], 0.7
    if case == "too fast":                       # ~14 mm/s > rig.max_velocity = 10
        exposure = 0.05
    elif case == "too abrupt":                   # 9.4 -> 0.5 mm/s within 0.07 s:
        d = [s0, s0 + 0.95 * (s1 - s0), s1]      # 127 mm/s^2 > rig.acceleration = 100
        exposure = 0.14
    elif case == "slow to fast":
        # equal steps of sensor distance at 1, 0.06, 5, 5 mm/s: 0.06 -> 5 mm/s within the
        # fast interval's 35 ms is 141 mm/s^2 (the file's check once spread it over the
        # two intervals' mean, saw 3.4 mm/s^2 and passed it to the plan; now it applies
        # the plan's rule and refuses it first, naming the knot)
        step = (s1 - s0) / 4
        dt = np.abs(step) / np.array([1.0, 0.06, 5.0, 5.0])
        exposure = float(dt.sum())
        t = np.concatenate([[0.0], np.cumsum(dt) / exposure]).tolist()
        t[-1] = 1.0
        d = (s0 + step * np.arange(5)).tolist()
    elif case == "crosses focal length":
        d = [f + 0.3, f + 0.05, f - 0.2]
    elif case == "empty":
        t, d = [], []
    else:
        d = [s0, s1, 0.5 * (s0 + s1)]
    motion = motion_json(tmp_path / "profile.json", t, d, exposure)
    out = tmp_path / "rec.json"
    with PtyDevice(ArduinoModel()) as dev:
        err = refused(capsys, ["capture", rig_setup_file, "--port", dev.port, "--motion",
                               motion, "--out", out])
        assert not [line for _, di, line in dev.model.log if di == "rx"], "port was used"
    assert err.startswith("mitsweep: error:") and message in err, err
    assert not out.exists()


# -- signals and the watchdog during a table sweep (real subprocesses) ------------------
# a slow profile: the shutter stays open 3.5 s (0.695 mm, 0.2 mm/s on average): time to
# signal or kill the capture in the middle of the table
SLOW_EXPOSURE_S = 3.5


def start_profile_capture(setup_path, motion_path, out, board, stage=None):
    argv = [sys.executable, "-m", "mitsweep", "capture", str(setup_path), "--port",
            board.port, "--motion", str(motion_path), "--out", str(out)]
    if stage is not None:
        argv += ["--stage", f"zaber:{stage.port}"]
    return subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def sigkill_mid_table(setup_path, motion_path, out, board, shutter_is_open) -> float:
    """Start the profile capture, SIGKILL it once ``shutter_is_open()``; the kill's
    ``time.monotonic()``."""
    proc = start_profile_capture(setup_path, motion_path, out, board)
    try:
        wait_for(shutter_is_open, "the shutter open mid-table", proc)
        t_kill = time.monotonic()
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        proc.kill()
        proc.wait()
    return t_kill


def slow_profile_rig(tmp_path, rig_kind, extra_rig=""):
    """(setup path, motion path, plan) of the slow profile on a fast-positioning rig."""
    setup_path = setup_file(tmp_path, (ZABER_RIG if rig_kind == "zaber" else "") + extra_rig)
    setup = load_setup(setup_path)
    motion = bent_profile(sweep_of(setup))
    path = save_motion_file(tmp_path / "profile.json", motion, exposure_s=SLOW_EXPOSURE_S,
                            provenance={"generator": "test_rig_profile"})
    return setup_path, path, plan_capture(setup, stage=rig_kind, motion=motion,
                                          exposure_s=SLOW_EXPOSURE_S)


@pytest.mark.parametrize("rig_kind", ["arduino", "zaber"])
def test_sigterm_mid_table_sweep_stops_the_rig_and_records_interrupted(tmp_path, rig_kind):
    setup_path, motion_path, plan = slow_profile_rig(tmp_path, rig_kind)
    out = tmp_path / "rec.json"
    board = PtyDevice(ArduinoModel(homed=True, position=plan.approach_steps
                                   if rig_kind == "arduino" else 0))
    stage = None
    if rig_kind == "zaber":
        stage = PtyDevice(ZaberModel(homed=True, position=plan.approach_steps,
                                     max_position=ZABER_MAX_POSITION))
    motor = stage or board
    with contextlib.ExitStack() as devices:
        for dev in filter(None, (board, stage)):
            devices.enter_context(dev)
        proc = start_profile_capture(setup_path, motion_path, out, board, stage)
        try:
            wait_for(lambda: board.model.shutter_open and motor.model.moving(time.monotonic()),
                     "the shutter open mid-table", proc)
            assert received(motor.model, "TSWEEP" if stage is None else "/1 0 stream 1 call 1")
            proc.send_signal(signal.SIGTERM)
            rc, err = finish(proc)
        finally:
            proc.kill()
            proc.wait()
        now = time.monotonic()
        assert not board.model.shutter_open, "shutter left open"
        assert not motor.model.moving(now) and motor.model.stopped, "stage not stopped"
        assert motor.model.position(now) != plan.end_steps       # stopped mid-table
    assert rc == signal_exit_status("SIGTERM"), err
    data = load_capture_record(out)
    assert data["status"] == "interrupted" and data["signal"] == "SIGTERM"
    assert all(a["ok"] for a in data["safety"])


def test_sigkilled_host_mid_table_the_simulated_board_stops_within_watchdog(tmp_path):
    setup_path, motion_path, plan = slow_profile_rig(tmp_path, "arduino", WATCHDOG_RIG)
    with PtyDevice(ArduinoModel(homed=True, position=plan.approach_steps)) as board:
        t_kill = sigkill_mid_table(setup_path, motion_path, tmp_path / "rec.json", board,
                                   lambda: board.model.shutter_open)
        wait_for(lambda: not board.model.shutter_open
                 and not board.model.moving(time.monotonic()), "the board at rest",
                 timeout_s=10.0)
        assert board.model.faults_seen == ["WATCHDOG"]
        kind, t_release = board.model.shutter_history[-1]
        assert kind == "close" and t_release - t_kill <= WATCHDOG_S + MARGIN_S


def test_sigkilled_host_mid_table_the_firmware_stops_within_watchdog(
        host_firmware, tmp_path):
    setup_path, motion_path, plan = slow_profile_rig(tmp_path, "arduino", WATCHDOG_RIG)
    board = HostBoard(host_firmware, tmp_path / "pins.txt", start_steps=400)
    shutter = lambda: [v for _, v, _ in board.pin_changes(6)]  # noqa: E731 - PIN_SHUTTER
    try:
        t_kill = sigkill_mid_table(setup_path, motion_path, tmp_path / "rec.json", board,
                                   lambda: shutter() == [1])
        wait_for(lambda: shutter() == [1, 0], "the shutter's release", timeout_s=10.0)
        elapsed = board.pin_times(6)[-1][0] - t_kill
        faults = [ln for ln in read_lines(board.slave, 0.5) if ln.startswith("EV FAULT")]
        assert len(faults) == 1 and faults[0].endswith(" WATCHDOG"), faults
        os.write(board.slave, b"STATE\n")
        state = [ln for ln in read_lines(board.slave, 1.0) if ln.startswith("OK STATE")]
        _, _, _, pos, _, moving, shutter_open = state[0].split()
        assert (moving, shutter_open) == ("0", "0")
        # stopped inside the table, where it faulted
        assert int(pos) == int(faults[0].split()[3])
        assert min(plan.open_steps, plan.close_steps) < int(pos) < max(plan.open_steps,
                                                                        plan.close_steps)
    finally:
        board.close()
    assert elapsed <= WATCHDOG_S + MARGIN_S
