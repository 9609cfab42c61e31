"""One reference geometry: renders, IPSFs and banks of a measured motion share one grid.

A measured (tabulated) sensor motion need not span the optimal sweep range: here it is
shifted by +0.15 mm and 20 % longer, and runs at an uneven speed. The reference sensor
distance of every image is then the measured span's mid-travel
(:func:`mitsweep.optics.reference.reference_geometry`), for the renderer and the tracer
alike; with the optimal range's midpoint as the tracer's reference (the old behaviour)
the IPSF would sit half a pixel away from the rendered blob at the field's edge.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.optics import image_point, mirror_point_from_image, placement_of
from mitsweep.optics.motion import MotionProfile
from mitsweep.optics.pixels import image_shape, sensor_to_pixel
from mitsweep.optics.reference import reference_geometry
from mitsweep.tracer import integrated_psf, ipsf_bank

from conftest import SCENES

#: Image point near the edge of the sphere's FOV zone (its image radius is 3.63 mm),
#: where a change of reference distance moves the point most (shift ∝ radius).
U, V = 3.3, 0.0
DEPTH = 500.0
#: Render and tracer centroids agree to this, in pixels. Measured on this point (8 seeds,
#: 4096 spp, a 2 px source): the rendered centroid scatters by 0.011 px (1 σ) per
#: render, the tracer's (400 000 rays) by < 0.005 px, and the finite source and the
#: renderer's own sampling leave a bias below 0.03 px; 0.1 px is that bias plus 6 σ.
TOLERANCE_PX = 0.1


def _measured_motion(geometry) -> MotionProfile:
    """A rig-like log: the optimal travel shifted by +0.15 mm, 20 % longer, uneven speed."""
    sr = geometry.sweep
    half = 0.5 * abs(sr.sensor_start - sr.sensor_end)
    mid = geometry.sensor_distance + 0.15
    start, end = mid + 1.2 * half, mid - 1.2 * half     # sensor_start > sensor_end here
    frac = np.array([0.0, 0.25, 0.6, 1.0])              # of the travel, at these times:
    return MotionProfile.tabulated([0.0, 0.3, 0.55, 1.0], start + (end - start) * frac)


@pytest.fixture(scope="module")
def case():
    setup = load_setup(SCENES / "sphere.toml")
    optimal = reference_geometry(setup)
    measured = reference_geometry(setup, motion=_measured_motion(optimal))
    return setup, optimal, measured


def _centroid(img: np.ndarray) -> np.ndarray:
    rows, cols = np.indices(img.shape)
    s = img.sum()
    return np.array([(rows * img).sum() / s, (cols * img).sum() / s])


def _tracer_centroid(setup, info) -> np.ndarray:
    """The traced IPSF's centroid in image pixels (row, col), through the pixel mapping."""
    return np.array(sensor_to_pixel(*info["centroid_uv_mm"], image_shape(setup),
                                    setup.sensor.pixel_pitch))


def test_measured_motion_moves_the_reference(case):
    setup, optimal, measured = case
    # the table's mid-travel is the optimum's plus 0.15 mm by construction: round-off
    assert measured.sensor_distance == pytest.approx(optimal.sensor_distance + 0.15, abs=1e-12)
    assert measured.motion.kind == "tabulated"
    assert measured.sweep == optimal.sweep      # the motion, not the sweep, sets i_ref


def test_render_and_tracer_share_the_grid_of_a_measured_motion(case):
    """Rendered sweep blob and traced IPSF of one point have one centroid, in pixels;
    the optimal range's midpoint as the tracer's reference would put them apart."""
    from mitsweep.render import render_point_source

    setup, optimal, measured = case
    motion = measured.motion
    img = render_point_source(setup, U, V, DEPTH, spp=4096, seed=1, mode="sweep",
                              window_px=31, motion=motion, radius_px=2.0)
    rendered = _centroid(img)
    kernel, info = integrated_psf(setup, U, V, DEPTH, motion=motion, rays=400_000,
                                  kernel_size=31)
    assert info["reference_sensor_distance_mm"] == measured.sensor_distance
    traced = _tracer_centroid(setup, info)
    assert np.abs(rendered - traced).max() < TOLERANCE_PX, (rendered, traced)

    # Sensitivity: the grid offset the two references imply for this point. The old
    # tracer put the source on the chief ray through (U, V) at the optimal midpoint;
    # on the measured reference grid that ray lands elsewhere.
    ray = mirror_point_from_image(placement_of(setup.mirror), np.array([U]), np.array([V]),
                                  optimal.sensor_distance)
    u_old, v_old = (float(x[0]) for x in image_point(ray, measured.sensor_distance))
    expected_px = np.hypot(u_old - U, v_old - V) / setup.sensor.pixel_pitch
    assert expected_px > 3 * TOLERANCE_PX, expected_px
    # ... and the old tracer's IPSF is indeed that far from the rendered blob.
    _, old_info = integrated_psf(setup, U, V, DEPTH, motion=motion, rays=400_000,
                                 kernel_size=31,
                                 reference_sensor_distance=optimal.sensor_distance)
    old = _tracer_centroid(setup, old_info)
    miss = float(np.hypot(*(old - rendered)))
    assert miss > 3 * TOLERANCE_PX
    assert miss == pytest.approx(expected_px, abs=TOLERANCE_PX)


def test_mode_cameras_use_the_measured_reference(case):
    from mitsweep.render.api import mode_camera

    setup, _, measured = case
    kw, desc = mode_camera(setup, "pinhole", measured)
    assert kw["sensor_distance"] == measured.sensor_distance
    assert desc["reference_sensor_distance_mm"] == measured.sensor_distance
    kw, desc = mode_camera(setup, "sweep", measured)
    assert kw["motion"] is measured.motion
    assert desc["motion"] == measured.motion.as_dict()
    kw, desc = mode_camera(setup, "focused", measured)
    assert desc["pitch_scale"] == pytest.approx(kw["sensor_distance"] / measured.sensor_distance)


def test_bank_traced_with_a_motion_records_its_reference(case):
    setup, optimal, measured = case
    bank = ipsf_bank(setup, kind="radial", n_radii=2, depths=(DEPTH,), rays=20_000,
                     motion=measured.motion, seed=3)
    assert bank.reference_sensor_distance == measured.sensor_distance
    # the measured motion's reference is 0.15 mm from the optimum's: 0.1 tells them apart
    assert bank.reference_sensor_distance != pytest.approx(optimal.sensor_distance, abs=0.1)
    assert bank.optics["motion"] == measured.motion.as_dict()
    # its kernels are the IPSFs of that motion, on that grid (same seed: same samples)
    k, _ = integrated_psf(setup, float(bank.points_uv[1, 0]), 0.0, DEPTH, rays=20_000,
                          motion=measured.motion, seed=4)
    np.testing.assert_array_equal(bank.kernels[0, 1], k)


def test_ipsf_cli_bank_from_a_motion_table_records_its_mid_travel(case, tmp_path, capsys):
    from mitsweep.cli.main import main

    _, _, measured = case
    text = (SCENES / "sphere.toml").read_text() + 'profile = "tabulated"\n'
    setup_file = tmp_path / "sphere_tab.toml"
    setup_file.write_text(text)
    table = tmp_path / "motion.csv"
    m = measured.motion
    table.write_text("".join(f"{t * 0.7:.17g},{p:.17g}\n" for t, p in zip(m.times, m.positions)))
    assert main(["ipsf", str(setup_file), "--bank", "radial", "--radii", "2", "--rays",
                 "20000", "--motion-table", str(table), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reference_sensor_distance_mm"] == pytest.approx(measured.sensor_distance,
                                                                abs=1e-12)


def test_mode_camera_refuses_a_bare_sweep_range(case):
    """The third argument is the whole reference geometry: a SweepRange alone (the old
    signature) would leave the motion, and so the reference, unresolved."""
    from mitsweep.render.api import mode_camera

    setup, optimal, _ = case
    with pytest.raises(TypeError, match="ReferenceGeometry"):
        mode_camera(setup, "pinhole", optimal.sweep)
