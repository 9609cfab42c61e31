"""The pixel ↔ sensor-mm mapping and the reference geometry, each written once."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitsweep.config import DEFAULT_SETUP
from mitsweep.optics import optimal_sweep_range
from mitsweep.optics.motion import MotionProfile, motion_for
from mitsweep.optics.pixels import (image_shape, optical_center_px, pixel_to_sensor,
                                    sensor_to_pixel)
from mitsweep.optics.reference import reference_geometry


@pytest.mark.parametrize("shape,centre", [((512, 512), (255.5, 255.5)), ((3, 4), (1.0, 1.5)),
                                          ((1, 1), (0.0, 0.0))])
def test_optical_centre_is_the_image_centre(shape, centre):
    assert optical_center_px(shape) == centre


def test_corner_pixels_and_orientation():
    # 4 x 6 image, pitch 0.5 mm: the top-left pixel centre is up and to the left
    u, v = pixel_to_sensor(0, 0, (4, 6), 0.5)
    assert (u, v) == (-1.25, 0.75)
    # +u is to the right (columns grow), +v up (rows shrink)
    row, col = sensor_to_pixel(0.5, 0.5, (4, 6), 0.5)
    assert (row, col) == (0.5, 3.5)


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4), st.integers(1, 8192), st.integers(1, 8192),
       st.floats(1e-4, 1.0))
def test_maps_are_inverse(row, col, H, W, pitch):
    u, v = pixel_to_sensor(row, col, (H, W), pitch)
    r2, c2 = sensor_to_pixel(u, v, (H, W), pitch)
    # round trip in float64: relative rounding of the larger of |row| and the centre
    tol = 1e-9 * (1 + abs(row) + abs(col) + H + W)
    assert abs(r2 - row) <= tol and abs(c2 - col) <= tol


def test_arrays_broadcast():
    rows, cols = np.mgrid[0:3, 0:5]
    u, v = pixel_to_sensor(rows, cols, (3, 5), 0.1)
    assert u.shape == (3, 5) and np.allclose(u[:, 2], 0) and np.allclose(v[1], 0)


def test_scalar_and_array_arguments_broadcast():
    """A row of points at one v (a grid's axis) maps to one array each way."""
    u = np.array([-0.25, 0.0, 0.25])
    rows, cols = sensor_to_pixel(u, 0.0, (4, 6), 0.5)
    assert rows.shape == cols.shape == (3,)
    np.testing.assert_array_equal(rows, [1.5, 1.5, 1.5])
    np.testing.assert_array_equal(cols, [2.0, 2.5, 3.0])
    us, vs = pixel_to_sensor(1.5, cols, (4, 6), 0.5)
    np.testing.assert_array_equal(us, u)
    np.testing.assert_array_equal(vs, [0.0, 0.0, 0.0])


def test_image_shape_is_rows_then_columns():
    from dataclasses import replace

    from mitsweep.config import Sensor

    s = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(640, 480), pixel_pitch=0.02))
    assert image_shape(s) == (480, 640)


def test_reference_is_mid_travel_of_the_default_motion():
    sr = optimal_sweep_range(DEFAULT_SETUP)
    ref = reference_geometry(DEFAULT_SETUP)
    # the same mid-travel, computed twice: round-off
    assert ref.sensor_distance == pytest.approx(sr.reference_sensor_distance, abs=1e-12)
    assert ref.motion.span == pytest.approx((sr.sensor_start, sr.sensor_end)) or \
        ref.motion.span == pytest.approx((sr.sensor_end, sr.sensor_start))


def test_a_measured_motion_sets_the_reference():
    sr = optimal_sweep_range(DEFAULT_SETUP)
    lo, hi = sorted((sr.sensor_start, sr.sensor_end))
    # a rig log that overshot by 0.1 mm at the far end and started 0.05 mm late
    table = MotionProfile.tabulated([0.0, 0.3, 1.0], [lo + 0.05, 0.5 * (lo + hi), hi + 0.1])
    ref = reference_geometry(DEFAULT_SETUP, motion=table)
    assert ref.sensor_distance == pytest.approx(0.5 * (lo + 0.05 + hi + 0.1), abs=1e-12)  # ulps
    assert ref.sweep == sr and ref.motion is table


def test_reference_refuses_what_is_not_a_motion():
    with pytest.raises(TypeError, match="MotionProfile"):
        reference_geometry(DEFAULT_SETUP, motion=optimal_sweep_range(DEFAULT_SETUP))
    with pytest.raises(TypeError, match="SweepRange"):
        reference_geometry(DEFAULT_SETUP, sweep=motion_for(DEFAULT_SETUP))
