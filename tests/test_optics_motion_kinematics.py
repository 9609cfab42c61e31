"""Trapezoidal kinematics (mitsweep.optics.kinematics) against closed forms and against a
numerical integration of its own velocity profile, over trapezoidal and triangular
moves."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitsweep.optics.kinematics import Trapezoid

# distances from 1 µm to 100 mm (or steps), speeds and accelerations over six decades:
# both shapes occur (v²/a from 1e-6 to 1e6 against D from 1e-3 to 1e2)
MOVES = st.builds(Trapezoid,
                  distance=st.floats(1e-3, 1e2),
                  velocity=st.floats(1e-2, 1e2),
                  acceleration=st.floats(1e-2, 1e4))


@given(MOVES)
@settings(max_examples=300, deadline=None)
def test_closed_forms(move):
    D, v, a = move.distance, move.velocity, move.acceleration
    # at v² = a D both shapes are one move (no cruise): the shape is asserted only off
    # that boundary, the closed forms everywhere (they agree on it). Relative tolerance:
    # the 1e-12 band where the move counts as reaching v, plus a few ulps
    if v * v <= a * D:
        if v * v < a * D * (1 - 1e-9):
            assert not move.is_triangular
        assert move.peak_velocity == pytest.approx(v, rel=1e-11)
        assert move.duration == pytest.approx(D / v + v / a, rel=1e-11)
        assert move.ramp_distance == pytest.approx(v * v / (2 * a), rel=1e-11)
        assert move.accel_fraction == pytest.approx((v / a) / (D / v + v / a), rel=1e-11)
    else:
        if v * v > a * D * (1 + 1e-9):
            assert move.is_triangular
            assert move.cruise_time == 0.0
        assert move.peak_velocity == pytest.approx(math.sqrt(a * D), rel=1e-11)
        assert move.duration == pytest.approx(2 * math.sqrt(D / a), rel=1e-11)
        assert move.ramp_distance == pytest.approx(D / 2, rel=1e-11)
        assert move.accel_fraction == pytest.approx(0.5, rel=1e-11)
    assert move.ramp_time == pytest.approx(move.peak_velocity / a, rel=1e-12)
    assert move.position_at(0.0) == 0.0
    assert move.position_at(move.duration) == pytest.approx(D, rel=1e-12)
    assert move.position_at(-1.0) == 0.0 and move.position_at(move.duration + 1.0) == D


@given(MOVES)
@settings(max_examples=100, deadline=None)
def test_position_is_the_integral_of_the_velocity(move):
    """Trapezoid-rule integral of velocity_at on 20001 points: exact on each linear piece,
    off only in the (at most 4) intervals holding a kink, by at most a_max dt² per kink."""
    n = 20001
    t = np.linspace(0.0, move.duration, n)
    vel = move.velocity_at(t)
    dt = t[1] - t[0]
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    pos = move.position_at(t)
    tol = 4 * move.acceleration * dt * dt + 1e-12 * move.distance
    np.testing.assert_allclose(pos, integral, rtol=0, atol=tol)
    assert np.all(np.diff(pos) >= 0), "the move never goes backwards"
    assert vel.max() <= move.peak_velocity * (1 + 1e-12)


@given(MOVES, st.floats(0.0, 1.0))
@settings(max_examples=300, deadline=None)
def test_time_at_inverts_position_at(move, fraction):
    d = fraction * move.distance
    t = move.time_at(d)
    assert 0.0 <= t <= move.duration * (1 + 1e-12)
    # inverting a square root near the ends loses half the digits: compare positions
    assert move.position_at(t) == pytest.approx(d, rel=1e-9, abs=1e-12 * move.distance)


@given(st.floats(1e-2, 1e2), st.floats(1e-2, 1e4), st.floats(0.0, 1e2))
def test_reaching_gives_a_full_ramp(v, a, cruise):
    move = Trapezoid.reaching(v, a, cruise_distance=cruise)
    assert move.peak_velocity == v
    # closed forms: a few ulps; the cruise is a difference (D - v²/a) / v, which loses
    # the digits of v²/a when the cruise is short, hence rel 1e-9 and abs 1e-12 v / a
    assert move.ramp_time == pytest.approx(v / a, rel=1e-12)
    assert move.ramp_distance == pytest.approx(v * v / (2 * a), rel=1e-12)
    assert move.cruise_time == pytest.approx(cruise / v, rel=1e-9, abs=1e-12 * v / a)


def test_zero_length_move():
    move = Trapezoid(0.0, 1.0, 1.0)
    assert move.duration == 0.0 and move.position_at(1.0) == 0.0 and move.time_at(1.0) == 0.0
    assert move.accel_fraction == 0.5


@pytest.mark.parametrize("field, value", [("distance", -1.0), ("velocity", 0.0),
                                          ("acceleration", -2.0), ("velocity", math.inf),
                                          ("distance", math.nan)])
def test_bad_parameters_refused(field, value):
    args = {"distance": 1.0, "velocity": 1.0, "acceleration": 1.0, field: value}
    with pytest.raises(ValueError, match=f"{field} must be finite"):
        Trapezoid(**args)


@given(st.floats(1e-3, 1e2), st.floats(1e-2, 1e2), st.floats(1e-3, 0.5))
def test_with_accel_fraction_round_trips(distance, duration, fraction):
    move = Trapezoid.with_accel_fraction(distance, duration, fraction)
    # round-off: measured <= 5.6e-16 over 2e5 random moves (f = 0.5 and 0.5 - 1e-9 too)
    assert move.duration == pytest.approx(duration, rel=1e-12)
    assert move.accel_fraction == pytest.approx(fraction, rel=1e-12)
    assert move.distance == distance


def test_arrays_in_arrays_out():
    move = Trapezoid(10.0, 2.0, 4.0)
    t = np.linspace(-1.0, move.duration + 1.0, 7)
    np.testing.assert_array_equal(move.position_at(t), [move.position_at(x) for x in t])
    np.testing.assert_array_equal(move.velocity_at(t), [move.velocity_at(x) for x in t])
    d = np.linspace(0.0, 10.0, 5)
    np.testing.assert_allclose(move.position_at(move.time_at(d)), d, rtol=1e-12)  # ulps
    assert isinstance(move.position_at(1.0), float)
