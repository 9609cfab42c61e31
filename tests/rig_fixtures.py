"""The rig tests' shared setups: the paper's sphere on a fast-positioning rig, with the
Arduino's stepper (400 steps/mm) or a Zaber stage's microsteps, the bent motion
profile the profile tests sweep, complete captures against the simulated devices on
ptys and their checks, and a capture subprocess that cannot outlive its test.

A test module takes the fixtures by importing them
(``from rig_fixtures import sphere, sphere_zaber  # noqa: F401 - fixtures``).
"""

from __future__ import annotations

import contextlib
import functools
import subprocess
import time
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest
from conftest import SCENES

from mitsweep.config import Setup, load_setup
from mitsweep.optics import SweepRange, optimal_sweep_range
from mitsweep.optics.motion import MotionProfile
from mitsweep.rig import (CapturePlan, CaptureRecord, RigPorts, load_capture_record,
                          plan_capture, run_capture)
from mitsweep.rig.simulator import ArduinoModel, PtyDevice, ZaberModel
from mitsweep.rig.testing import fast_rig_setup

__all__ = ["ZABER_STEPS_PER_MM", "ZABER_MAX_POSITION", "TIMER_RESOLUTION_S", "arduino_capture",
           "assert_board_timed_exposure", "assert_safe", "bent_profile", "complete_exposure",
           "killed_on_exit", "soft_limit_steps", "sphere", "sphere_zaber", "sweep_of",
           "zaber_capture"]

#: 0.047625 µm microsteps (Zaber X-LSM family).
ZABER_STEPS_PER_MM = 1 / 0.047625e-3
#: The simulated Zaber stage's travel: 26 mm, in microsteps.
ZABER_MAX_POSITION = int(26 * ZABER_STEPS_PER_MM)
#: Timing resolution of a measured exposure: the simulated board stamps events from the
#: analytic motion at its 1 µs ``micros()``, and an exposure is two such stamps apart.
TIMER_RESOLUTION_S = 2e-6


@functools.lru_cache(maxsize=None)
def sweep_of(setup: Setup) -> SweepRange:
    """``optimal_sweep_range(setup)``, once per setup in this process (a pure function
    of the frozen setup that takes ~0.1-0.4 s of solving; the rig tests ask it often)."""
    return optimal_sweep_range(setup)


def bent_profile(sr, n: int = 64, bend: float = 0.3) -> MotionProfile:
    """A monotonic, non-uniform profile over the sweep range: ``u = t + bend t (1 - t)``
    (fast at the start, ``(1 + bend)`` times the mean velocity, slow at the end,
    ``(1 - bend)``), as ``n`` tabulated knots."""
    t = np.linspace(0.0, 1.0, n)
    u = t + bend * t * (1.0 - t)
    return MotionProfile.tabulated(t, sr.sensor_start + (sr.sensor_end - sr.sensor_start) * u)


@pytest.fixture(scope="module")
def sphere():
    """The sphere setup on a fast-positioning rig with the Arduino's stepper."""
    return fast_rig_setup(load_setup(SCENES / "sphere.toml"))


@pytest.fixture(scope="module")
def sphere_zaber():
    """The sphere setup on a fast-positioning rig with a Zaber stage's microsteps."""
    return fast_rig_setup(load_setup(SCENES / "sphere.toml"), steps_per_mm=ZABER_STEPS_PER_MM)


def soft_limit_steps(plan) -> tuple[int, int]:
    """The plan's soft limits (min, max) in the stage's steps."""
    return (round(plan.soft_limit_min * plan.steps_per_mm),
            round(plan.soft_limit_max * plan.steps_per_mm))


def assert_safe(model, lo_steps: int, hi_steps: int) -> None:
    """The simulated device's stage at rest within [lo_steps, hi_steps], its shutter
    (if it has one) closed."""
    now = time.monotonic()
    assert not model.moving(now), "stage still moving"
    assert lo_steps <= model.position(now) <= hi_steps
    assert not getattr(model, "shutter_open", False), "shutter left open"


def arduino_capture(setup: Setup, out: Path, plan: CapturePlan | None = None, *,
                    at_approach: bool = False, checksums: bool = False) -> ArduinoModel:
    """Capture ``plan`` (default: the setup's sweep) with the simulated Arduino driving
    stage and shutter, the record written to ``out``; check that it left the stage at
    rest on the plan's end step and the shutter closed. The board's model.

    ``at_approach``: the board starts homed at the approach step (the sweep starts at
    once), else unhomed, like a board after power-up.
    """
    plan = plan or plan_capture(setup)
    model = (ArduinoModel(homed=True, position=plan.approach_steps) if at_approach
             else ArduinoModel())
    with PtyDevice(model) as dev:
        run_capture(setup, RigPorts(arduino=dev.port, checksums=checksums), out=out,
                    plan=plan)
        now = time.monotonic()
        assert not dev.model.moving(now) and not dev.model.shutter_open
        assert dev.model.position(now) == plan.end_steps
    return dev.model


def zaber_capture(setup: Setup, out: Path,
                  plan: CapturePlan | None = None) -> tuple[CaptureRecord, ZaberModel]:
    """Capture ``plan`` (default: the setup's sweep) on a simulated Zaber stage with the
    simulated Arduino's shutter (checksums on), the record written to ``out``; check
    that the stage came to rest on the plan's end step. (The capture's record, the
    stage's model.)"""
    plan = plan or plan_capture(setup, stage="zaber")
    with PtyDevice(ArduinoModel()) as board, \
            PtyDevice(ZaberModel(max_position=ZABER_MAX_POSITION)) as stage:
        record = run_capture(setup, RigPorts(arduino=board.port, zaber=stage.port,
                                             checksums=True), out=out, plan=plan)
        now = time.monotonic()
        assert not stage.model.moving(now) and not board.model.shutter_open
        assert stage.model.position(now) == plan.end_steps
    return record, stage.model


def complete_exposure(out: Path, plan: CapturePlan) -> tuple[dict, dict]:
    """The capture record at ``out``, checked complete with the planned exposure
    measured to :data:`TIMER_RESOLUTION_S`: (the record, its measured exposure)."""
    data = load_capture_record(out)
    assert data["complete"] and data["status"] == "complete" and data["error"] is None
    exp = data["measured"]["exposure"]
    assert exp["measured_exposure_s"] == pytest.approx(plan.planned_exposure_s,
                                                       abs=TIMER_RESOLUTION_S)
    return data, exp


def assert_board_timed_exposure(board: ArduinoModel, exp: dict, plan: CapturePlan) -> None:
    """The Arduino timed the shutter: it opened exactly once, for the planned time, and
    the record's measured exposure ``exp`` puts it on the planned positions exactly."""
    history = list(board.shutter_history)
    assert [h[0] for h in history] == ["open", "close"]
    assert history[1][1] - history[0][1] == pytest.approx(plan.planned_exposure_s, abs=1e-9)
    assert exp["open_position_mm"] == pytest.approx(plan.open_position, abs=1e-12)
    assert exp["close_position_mm"] == pytest.approx(plan.close_position, abs=1e-12)


@contextlib.contextmanager
def killed_on_exit(proc: subprocess.Popen) -> Iterator[subprocess.Popen]:
    """``proc``, killed and reaped when the block ends, however it ends (a capture
    subprocess must not outlive a failed test and hold the simulated ports)."""
    try:
        yield proc
    finally:
        proc.kill()
        proc.wait()
