"""Capture plan: sweep range -> stage move, and every refusal before any motion."""

from __future__ import annotations

import dataclasses

import pytest
from rig_fixtures import sweep_of

from mitsweep.config import SetupError, load_setup
from mitsweep.rig.arduino import MAX_STEP_RATE
from mitsweep.rig.errors import PlanError
from mitsweep.rig.plan import plan_capture


def with_rig(setup, **rig):
    return dataclasses.replace(setup, rig=dataclasses.replace(setup.rig, **rig))


def with_velocity(setup, v):
    return dataclasses.replace(setup, sweep=dataclasses.replace(setup.sweep, velocity=v))


@pytest.fixture(scope="module")
def sphere(scenes_dir_module):
    return load_setup(scenes_dir_module / "sphere.toml")


@pytest.fixture(scope="module")
def scenes_dir_module():
    from pathlib import Path

    return Path(__file__).resolve().parents[1] / "scenes"


@pytest.mark.parametrize("scene", ["sphere", "paraboloid", "paraboloid_tilted"])
@pytest.mark.parametrize("stage, spm", [("arduino", 400.0), ("zaber", 20997.4)])
def test_plan_covers_sweep_range_at_constant_velocity(scenes_dir_module, scene, stage, spm):
    setup = with_rig(load_setup(scenes_dir_module / f"{scene}.toml"), steps_per_mm=spm)
    sr = sweep_of(setup)
    plan = plan_capture(setup, stage=stage, sweep_range=sr)
    # the shutter window maps onto the optical sweep, to within half a step
    half_step = 0.5 / spm
    assert plan.sensor_distance(plan.open_position) == pytest.approx(sr.sensor_start, abs=half_step)
    assert plan.sensor_distance(plan.close_position) == pytest.approx(sr.sensor_end,
                                                                abs=2 * half_step)
    # ramp + settle separate the shutter window from both ends of the move
    ramp = plan.velocity_actual_mm_s ** 2 / (2 * plan.acceleration_mm_s2)
    margin = ramp + setup.rig.settle_distance
    assert abs(plan.open_position - plan.approach_position) >= margin - 1e-12
    assert abs(plan.end_position - plan.close_position) >= margin - 1e-12
    # ordered along the direction of motion, inside the soft limits
    xs = [plan.approach_position, plan.open_position, plan.close_position, plan.end_position]
    assert xs == sorted(xs, reverse=plan.direction < 0)
    assert all(setup.rig.soft_limit_min <= x <= setup.rig.soft_limit_max for x in xs)
    # the run velocity is the requested one up to the controller's velocity quantum
    # (1 step/s; or 1 Zaber speed unit = 1/1.6384 microstep/s)
    v_quantum = (1.0 if stage == "arduino" else 1 / 1.6384) / spm
    assert plan.velocity_actual_mm_s == pytest.approx(sr.velocity_mm_s, abs=v_quantum / 2)
    # planned exposure = travel / run velocity up to the quantisation of the shutter
    # window (one step at the run velocity; or the Arduino's 1 µs timer in zaber mode)
    quantum = 1.0 / (spm * plan.velocity_actual_mm_s) if stage == "arduino" else 1e-6
    assert plan.planned_exposure_s == pytest.approx(
        sr.translation / plan.velocity_actual_mm_s, abs=quantum)


@pytest.mark.parametrize("direction", [1, -1])
def test_calibrated_mapping_puts_sweep_where_the_rig_says(sphere, direction):
    sr = sweep_of(sphere)
    s0 = sr.sensor_start - direction * 10.0   # stage 10 mm maps to the sweep start
    plan = plan_capture(with_rig(sphere, sensor_distance_at_zero=s0, sensor_direction=direction))
    assert plan.mapping == "calibrated"
    assert plan.open_position == pytest.approx(10.0, abs=0.5 / 400)
    assert plan.direction == (-1 if direction == 1 else 1)   # sensor distance decreases


def test_sweep_longer_than_travel_is_refused(sphere):
    with pytest.raises(PlanError, match="more than the soft limits allow"):
        plan_capture(with_rig(sphere, travel=0.7, soft_limit_max=0.7))


def test_calibrated_sweep_outside_soft_limits_is_refused(sphere):
    sr = sweep_of(sphere)
    with pytest.raises(PlanError, match="outside the soft limits"):
        plan_capture(with_rig(sphere, sensor_distance_at_zero=sr.sensor_start - 24.95))


def test_velocity_above_stage_limit_is_refused(sphere):
    with pytest.raises(PlanError, match="more than the stage can hold"):
        plan_capture(with_velocity(sphere, 6.0))   # rig.max_velocity = 5


def test_velocity_above_firmware_step_rate_is_refused(sphere):
    setup = with_rig(with_velocity(sphere, 2.0), steps_per_mm=MAX_STEP_RATE)  # 8000 steps/s
    with pytest.raises(PlanError, match="steps/s"):
        plan_capture(setup)


def test_velocity_not_representable_is_refused(sphere):
    # 0.0013 mm/s at 400 steps/mm is 0.52 steps/s: rounds to 1 step/s, 92 % off
    with pytest.raises(PlanError, match="cannot be held"):
        plan_capture(with_rig(with_velocity(sphere, 0.0013), max_exposure_s=3600))


@pytest.mark.parametrize("velocity, rig, match", [
    (0.01, {}, "outside the camera's range"),                       # 69.5 s > 30 s
    (1.0, {"min_exposure_s": 1.0, "max_exposure_s": 5.0}, "outside the camera's range"),
])
def test_exposure_outside_camera_range_is_refused(sphere, velocity, rig, match):
    with pytest.raises(PlanError, match=match):
        plan_capture(with_rig(with_velocity(sphere, velocity), **rig))


def test_unknown_stage_kind_is_refused(sphere):
    with pytest.raises(PlanError, match="arduino, zaber"):
        plan_capture(sphere, stage="thorlabs")


@pytest.mark.parametrize("rig, key", [
    ({"soft_limit_max": 30.0}, "rig.soft_limit_max"),
    ({"soft_limit_min": 5.0, "soft_limit_max": 4.0}, "rig.soft_limit_min"),
    ({"sensor_direction": 0}, "rig.sensor_direction"),
    ({"steps_per_mm": -1.0}, "rig.steps_per_mm"),
    ({"baudrate": 9600.5}, "rig.baudrate"),
])
def test_rig_config_validation_names_the_key(sphere, rig, key):
    with pytest.raises(SetupError, match=key):
        dataclasses.replace(sphere.rig, **rig)


@pytest.mark.parametrize("stage, steps_per_mm", [("arduino", 400.0),
                                                 ("zaber", 1 / 0.047625e-3)])
def test_plan_holds_mm_and_each_driver_converts_to_its_units(sphere, stage, steps_per_mm):
    """The plan's rates are mm/s and mm/s² only; the driver's quantised units, derived
    from them, are the ones the controller was planned for (round trip exact)."""
    from mitsweep.rig import zaber
    from mitsweep.rig.arduino import step_accel, step_rate
    from mitsweep.rig.testing import fast_rig_setup

    setup = fast_rig_setup(sphere, steps_per_mm=steps_per_mm)
    plan = plan_capture(setup, stage=stage)
    names = {f.name for f in dataclasses.fields(plan)}
    assert not names & {"step_rate", "accel_rate"}
    units = plan.as_dict()["driver_units"]
    v, a = plan.velocity_actual_mm_s, plan.acceleration_mm_s2
    if stage == "arduino":
        assert units == {"step_rate_steps_s": step_rate(v, steps_per_mm),
                         "accel_steps_s2": step_accel(a, steps_per_mm)}
        assert units["step_rate_steps_s"] / steps_per_mm == pytest.approx(v, rel=1e-15)
        assert "steps/s" in plan.summary()
    else:
        assert zaber.speed_mm_s(units["maxspeed"], steps_per_mm) == pytest.approx(v, rel=1e-15)
        assert zaber.accel_mm_s2(units["accel"], steps_per_mm) == pytest.approx(a, rel=1e-15)
        assert "maxspeed" in plan.summary()
