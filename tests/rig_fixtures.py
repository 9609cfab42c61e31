"""The rig tests' shared setups: the paper's sphere on a fast-positioning rig, with the
Arduino's stepper (400 steps/mm) or a Zaber stage's microsteps, and the bent motion
profile the profile tests sweep.

A test module takes the fixtures by importing them
(``from rig_fixtures import sphere, sphere_zaber  # noqa: F401 - fixtures``).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import SCENES

from mitsweep.config import load_setup
from mitsweep.optics.motion import MotionProfile
from mitsweep.rig.testing import fast_rig_setup

__all__ = ["ZABER_STEPS_PER_MM", "ZABER_MAX_POSITION", "assert_safe", "bent_profile",
           "soft_limit_steps", "sphere", "sphere_zaber"]

#: 0.047625 µm microsteps (Zaber X-LSM family).
ZABER_STEPS_PER_MM = 1 / 0.047625e-3
#: The simulated Zaber stage's travel: 26 mm, in microsteps.
ZABER_MAX_POSITION = int(26 * ZABER_STEPS_PER_MM)


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
    return (round(plan.soft_limit_min_mm * plan.steps_per_mm),
            round(plan.soft_limit_max_mm * plan.steps_per_mm))


def assert_safe(model, lo_steps: int, hi_steps: int) -> None:
    """The simulated device's stage at rest within [lo_steps, hi_steps], its shutter
    (if it has one) closed."""
    now = time.monotonic()
    assert not model.moving(now), "stage still moving"
    assert lo_steps <= model.position(now) <= hi_steps
    assert not getattr(model, "shutter_open", False), "shutter left open"
