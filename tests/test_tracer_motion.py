"""MotionProfile: sensor distance over the normalised exposure time."""

import numpy as np
import pytest

from mitsweep.config import SetupError, load_setup
from mitsweep.optics import optimal_sweep_range
from mitsweep.optics.motion import MotionProfile, motion_for
import dataclasses


@pytest.mark.parametrize("start,end", [(52.0, 51.3), (51.3, 52.0)])
def test_linear_profile_ends_and_constant_velocity(start, end):
    m = MotionProfile.linear(start, end)
    t = np.linspace(0, 1, 11)
    i = m.sensor_distance(t)
    assert i[0] == start and i[-1] == end
    np.testing.assert_allclose(np.diff(i), (end - start) / 10, rtol=1e-12)
    assert m.midpoint == pytest.approx(0.5 * (start + end))


@pytest.mark.parametrize("a", [0.05, 0.2, 0.5])
def test_trapezoidal_profile_is_continuous_and_reaches_ends(a):
    m = MotionProfile.trapezoidal(52.0, 51.0, a)
    t = np.linspace(0, 1, 200001)
    i = m.sensor_distance(t)
    assert i[0] == pytest.approx(52.0, abs=1e-12) and i[-1] == pytest.approx(51.0, abs=1e-12)
    # Continuity: steps bounded by peak velocity * dt (|Δ|/(1-a) per unit time).
    assert np.max(np.abs(np.diff(i))) <= 1.0 / (1 - a) * (t[1] - t[0]) * (1 + 1e-9)
    # Velocity integrates to the travel (trapezoid rule, second order in dt).
    v = m.velocity(t)
    assert np.trapezoid(v, t) == pytest.approx(-1.0, rel=1e-6)
    assert v[0] == 0 and v[-1] == 0


@pytest.mark.parametrize("n", [1, 4, 32])
def test_trapezoidal_segments_within_chord_bound(n):
    a = 0.3
    m = MotionProfile.trapezoidal(52.0, 51.0, a)
    kt, kp = m.segments(n)
    t = np.linspace(0, 1, 100001)
    err = np.max(np.abs(np.interp(t, kt, kp) - m.sensor_distance(t)))
    bound = 1.0 * a / (8 * n * n * (1 - a))  # Notes of MotionProfile.segments
    assert err <= bound * (1 + 1e-9)


def test_tabulated_profile_interpolates_and_rescales_time():
    m = MotionProfile.tabulated([10.0, 11.0, 13.0], [52.0, 51.8, 51.0])
    # Times 10, 11, 13 s -> normalised 0, 1/3, 1.
    assert m.sensor_distance(1 / 3) == pytest.approx(51.8)
    assert m.sensor_distance(2 / 3) == pytest.approx(51.4)
    assert m.sensor_distance(1.0) == pytest.approx(51.0)
    kt, kp = m.segments()
    np.testing.assert_allclose(kt, [0, 1 / 3, 1])


@pytest.mark.parametrize("build,match", [
    (lambda: MotionProfile.linear(52.0, 52.0), "empty sweep"),
    (lambda: MotionProfile.linear(-1.0, 52.0), "> 0 mm"),
    (lambda: MotionProfile.trapezoidal(52.0, 51.0, 0.7), "accel_fraction"),
    (lambda: MotionProfile.tabulated([0, 0], [52, 51]), "strictly increasing"),
    (lambda: MotionProfile.tabulated([0, 1], [52, 52]), "empty sweep"),
    (lambda: MotionProfile("bouncy", 52.0, 51.0), "must be one of"),
])
def test_bad_motion_gets_clear_error(build, match):
    with pytest.raises(SetupError, match=match):
        build()


@pytest.mark.parametrize("profile", ["linear", "trapezoidal"])
def test_motion_for_setup_spans_the_sweep_range(profile):
    setup = load_setup("scenes/sphere.toml")
    setup = dataclasses.replace(setup, sweep=dataclasses.replace(setup.sweep, profile=profile))
    sr = optimal_sweep_range(setup)
    m = motion_for(setup, sr)
    assert m.kind == profile
    assert m.sensor_distance(0.0) == pytest.approx(sr.sensor_start)
    assert m.sensor_distance(1.0) == pytest.approx(sr.sensor_end)
    assert m.midpoint == pytest.approx(sr.reference_sensor_distance)


def test_motion_for_tabulated_needs_a_table():
    setup = load_setup("scenes/sphere.toml")
    setup = dataclasses.replace(setup, sweep=dataclasses.replace(setup.sweep, profile="tabulated"))
    with pytest.raises(SetupError, match="tabulated"):
        motion_for(setup)
