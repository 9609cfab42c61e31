"""Unwarping: the panorama maps are exact both ways, put the world where it is, and wrap.

References are independent of the forward map being tested: the test images are "seen"
through the *inverse* map's path (pixel → chief ray → ray–mirror intersection →
reflected direction, :func:`mitsweep.optics.panorama.image_to_direction`), while the
panorama is resampled through the forward map (Newton's method on the mirror surface).
"""

import functools
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from conftest import SCENES
from mitsweep.cli.main import main
from mitsweep.config import load_setup
from mitsweep.io import read_exr, write_exr
from mitsweep.optics import pixel_to_sensor
from mitsweep.optics.panorama import (PROJECTIONS, angles_to_directions, image_to_direction,
                                      panorama_map, unwarp)

N = 160  # image side, px: the scenes' 512 px sensors at 3.2x the pitch (fast tests)


def small(setup, n=N):
    W, _ = setup.sensor.resolution
    return replace(setup, sensor=replace(setup.sensor, resolution=(n, n),
                                         pixel_pitch=setup.sensor.pixel_pitch * W / n))


@pytest.fixture(scope="module", params=["sphere", "paraboloid_tilted"])
def setup(request, scenes_dir_module):
    return small(load_setup(scenes_dir_module / f"{request.param}.toml"))


@pytest.fixture(scope="module")
def scenes_dir_module():
    from conftest import SCENES

    return SCENES


def sensor_points(pmap, rows, cols):
    """Sensor points (u, v) mm of image pixels (rows, cols) of the map's camera image."""
    return pixel_to_sensor(rows, cols, pmap.image_shape, pmap.pixel_pitch,
                           center_offset_px=pmap.center_offset_px)


def seen(pmap, world):
    """The image a pinhole camera records of the world radiance ``world(directions)``:
    each pixel's direction by ray–mirror intersection; 0 off the mirror."""
    H, W = pmap.image_shape
    rows, cols = np.mgrid[0:H, 0:W]
    u, v = sensor_points(pmap, rows, cols)
    d, ok = image_to_direction(pmap.placement, u, v, pmap.sensor_distance)
    img = np.zeros((H, W))
    img[ok] = world(d[ok])
    return img, ok


def pixel_step_rad(pmap):
    """(H, W): the angle between the directions of neighbouring image pixels (the
    larger of the row and column neighbours), inf off the mirror."""
    H, W = pmap.image_shape
    rows, cols = np.mgrid[0:H + 1, 0:W + 1]
    u, v = sensor_points(pmap, rows, cols)
    d, ok = image_to_direction(pmap.placement, u, v, pmap.sensor_distance)
    step = np.maximum(np.linalg.norm(d[1:, :-1] - d[:-1, :-1], axis=-1),
                      np.linalg.norm(d[:-1, 1:] - d[:-1, :-1], axis=-1))
    return np.where(np.isfinite(step), step, np.inf)


def interior(pmap, ok_image, prow, pcol, margin=8, max_step_deg=None):
    """Panorama pixels whose image point is at least ``margin`` px inside the mirror's
    image (the cubic spline's prefilter rings off the rim's edge as 0.268^n at n px:
    below 3e-5 of the edge's step at 8 px) and, given ``max_step_deg``, where the
    image samples the world at most that finely (near a grazing rim one image pixel
    spans degrees: there the image itself undersamples the world)."""
    inner = ndimage.binary_erosion(ok_image, iterations=margin)
    if max_step_deg is not None:
        fine = ndimage.minimum_filter(pixel_step_rad(pmap) <= np.radians(max_step_deg),
                                      size=2 * margin + 1)
        inner &= fine
    row, col, ok = pmap.to_image(prow, pcol)
    r = np.clip(np.round(np.nan_to_num(row)).astype(int), 0, pmap.image_shape[0] - 1)
    c = np.clip(np.round(np.nan_to_num(col)).astype(int), 0, pmap.image_shape[1] - 1)
    return ok & inner[r, c]


@pytest.mark.parametrize("projection", PROJECTIONS)
@pytest.mark.parametrize("offset", [(0.0, 0.0), (7.3, -11.6)])
def test_forward_then_inverse_maps_agree_within_005_px(setup, projection, offset):
    H = W = N
    center = (H / 2 - 0.5 + offset[0], W / 2 - 0.5 + offset[1])
    pmap = panorama_map(setup, (H, W), projection=projection, center_px=center)
    rng = np.random.default_rng(1)
    Wp, Hp = pmap.size
    pr, pc = rng.uniform(-0.5, Hp - 0.5, 4000), rng.uniform(-0.5, Wp - 0.5, 4000)
    row, col, ok = pmap.to_image(pr, pc)
    # measured >= 0.97 (sphere), >= 0.55 (tilted paraboloid) of the panorama seen
    assert ok.mean() > 0.3, "most of the panorama should be seen"
    pr2, pc2, ok2 = pmap.from_image(row[ok], col[ok])
    assert ok2.all()
    dc = (pc2 - pc[ok] + Wp / 2) % Wp - Wp / 2   # columns wrap
    # the promise is 0.05 px; both maps invert to round-off: measured <= 7.2e-8 px (both
    # setups and projections, both centres, seeds 1-3), so 1e-6 px is the bar
    assert np.max(np.abs(pr2 - pr[ok])) < 1e-6 and np.max(np.abs(dc)) < 1e-6
    # and the other way: image pixels on the mirror -> panorama -> image
    ir, ic = rng.uniform(-0.5, H - 0.5, 4000), rng.uniform(-0.5, W - 0.5, 4000)
    qr, qc, okq = pmap.from_image(ir, ic)
    back_r, back_c, okb = pmap.to_image(qr[okq], qc[okq])
    assert okq.mean() > 0.2 and okb.all()    # the mirror's share of the frame: >= 0.47
    # measured <= 1.4e-9 px (as above)
    assert np.max(np.hypot(back_r - ir[okq], back_c - ic[okq])) < 1e-6


@functools.cache
def small_setup(name):
    return small(load_setup(SCENES / f"{name}.toml"))


def thinned(cases, fast):
    """``cases`` (tuples starting with a setup name) as params; the tilted paraboloid's
    cases not in ``fast`` marked slow (1.3-5 s each: its panoramas resample through the
    off-axis forward map). The default run keeps every case on the sphere (~0.3 s each)
    and the tilted mirror where it differs most: the wrap-around, in one projection (each
    projection's formula is checked on both mirrors by the forward/inverse test). CI's
    full run (``-m "slow or not slow"``) runs them all."""
    return [pytest.param(*c, id="-".join(map(str, c)),
                         marks=() if c[0] == "sphere" or c in fast else pytest.mark.slow)
            for c in cases]


@pytest.mark.parametrize("name, azimuth_deg, projection", thinned(
    [(n, a, p) for n in ("sphere", "paraboloid_tilted") for a in (40.0, 180.0)  # 180: wrap
     for p in PROJECTIONS],
    fast={("paraboloid_tilted", 180.0, "equirectangular")}))
def test_marker_at_a_world_direction_lands_where_the_geometry_says(name, projection,
                                                                   azimuth_deg):
    setup = small_setup(name)
    pmap = panorama_map(setup, (N, N), projection=projection)
    Wp, Hp = pmap.size
    # an elevation the mirror shows at this azimuth: midway down the column's seen rows
    col = (180.0 - azimuth_deg) / 360.0 * Wp - 0.5
    _, _, shown = pmap.to_image(np.arange(Hp), np.full(Hp, col))
    rows = np.flatnonzero(shown)
    mid = pmap.directions(rows[len(rows) // 2], col)
    target = angles_to_directions(np.radians(azimuth_deg), np.arcsin(mid[2]))
    sigma = np.radians(3.0)

    def marker(d):
        return np.exp(-np.sum((d - target) ** 2, axis=-1) / (2 * sigma ** 2))

    img, ok_img = seen(pmap, marker)
    assert img.max() > 0.9   # the image shows the marker's centre
    pano, valid = unwarp(img, pmap)
    prow, pcol = np.mgrid[0:Hp, 0:Wp]
    expected = np.where(valid, marker(pmap.directions(prow, pcol)), 0.0)
    # where the marker sits in the panorama, by the panorama's own formula
    tr, tc = pmap.panorama_coords(target)
    peak = np.unravel_index(np.argmax(pano), pano.shape)
    dcol = (peak[1] - tc + Wp / 2) % Wp - Wp / 2
    assert abs(peak[0] - tr) <= 1.0 and abs(dcol) <= 1.0, (peak, (tr, tc))
    # centroids, in columns unrolled about the target (the marker may straddle the wrap)
    unrolled = (pcol - tc + Wp / 2) % Wp - Wp / 2
    near = (np.hypot(prow - tr, unrolled) < 12 * sigma * Wp / (2 * np.pi)) & valid

    def centroid(a):
        w = np.where(near, a, 0.0)
        return np.sum(w * prow) / w.sum(), np.sum(w * unrolled) / w.sum()

    got, want = centroid(pano), centroid(expected)
    # cubic resampling of a blob ~8 px wide in the image: centroid errors ~0.01 px
    assert np.hypot(got[0] - want[0], got[1] - want[1]) < 0.05, (got, want)
    assert np.max(np.abs(pano - expected)[near]) < 0.03


@pytest.mark.parametrize("name, projection", thinned(
    [(n, p) for n in ("sphere", "paraboloid_tilted") for p in PROJECTIONS],
    fast={("paraboloid_tilted", "equirectangular")}))
def test_panorama_has_no_nan_and_no_seam_at_the_wrap(name, projection):
    setup = small_setup(name)
    pmap = panorama_map(setup, (N, N), projection=projection)

    def world(d):  # smooth over the sphere of directions, azimuth-dependent
        return 0.5 + 0.3 * d[..., 0] + 0.2 * d[..., 1] * d[..., 2]

    img, ok_img = seen(pmap, world)
    pano, valid = unwarp(img.astype(np.float32), pmap)
    assert pano.dtype == np.float32 and np.all(np.isfinite(pano))
    assert np.all(pano[~valid] == 0)
    Wp, Hp = pmap.size
    prow, pcol = np.mgrid[0:Hp, 0:Wp]
    inner = interior(pmap, ok_img, prow, pcol, max_step_deg=3.0)
    assert inner.mean() > 0.2
    err = np.abs(pano - world(pmap.directions(prow, pcol)))[inner]
    # a cubic spline on a world sampled at <= 3 deg per pixel (the world's change per
    # pixel <= 0.03): measured <= 2e-6 (tilted paraboloid), 2e-8 (sphere)
    assert err.max() < 1e-4
    both = inner[:, 0] & inner[:, -1]
    assert both.sum() > 5
    seam = np.abs(pano[both, 0] - pano[both, -1]).max()
    steps = np.abs(np.diff(pano, axis=1))[inner[:, 1:] & inner[:, :-1]]
    assert seam <= steps.max()


def test_directions_outside_the_frame_are_marked_not_seen(scenes_dir_module):
    """A mirror whose image leaves the frame: those panorama pixels are 0 and not valid."""
    setup = small(load_setup(scenes_dir_module / "sphere.toml"))
    pmap = panorama_map(setup, (N, N), projection="equirectangular",
                        center_px=(N / 2 - 0.5, N - 20.0))
    pano, valid = unwarp(np.ones((N, N)), pmap)
    assert 0.2 < valid.mean() < 0.95          # measured 0.70: part seen, part not
    assert np.all(np.isfinite(pano)) and np.all(pano[~valid] == 0)
    # a constant resamples to itself: measured 8.9e-16 off (round-off)
    np.testing.assert_allclose(pano[valid], 1.0, atol=1e-9)


def test_unwarp_command_writes_the_panorama_with_its_mask_and_provenance(
        tmp_path, capsys, scenes_dir_module):
    from mitsweep.config import setup_to_dict

    setup = small(load_setup(scenes_dir_module / "sphere.toml"))
    img = np.random.default_rng(0).random((N, N, 3)).astype(np.float32)
    write_exr(tmp_path / "edof.exr", img, metadata={"setup": setup_to_dict(setup)})
    out = tmp_path / "pano.exr"
    assert main(["unwarp", str(tmp_path / "edof.exr"), "--projection", "cylindrical",
                 "--size", "360", "90", "--out", str(out), "--json"]) == 0
    chans, meta = read_exr(out)
    assert set(chans) == {"R", "G", "B", "mask.Y"} and chans["R"].shape == (90, 360)
    assert meta["projection"] == "cylindrical" and meta["size"] == [360, 90]
    assert 0 < meta["valid_fraction"] <= 1 and meta["elevation_deg"][1] <= 75.0
    assert main(["unwarp", str(tmp_path / "edof.exr"), "--projection", "equirectangular",
                 "--out", str(tmp_path / "pano.png")]) == 0
    assert (tmp_path / "pano.png").stat().st_size > 0


@pytest.mark.parametrize("args,message", [
    (["--projection", "cylindrical", "--elevation", "-10", "90"], "cylindrical"),
    (["--projection", "equirectangular", "--elevation", "20", "10"], "below"),
    (["--projection", "equirectangular", "--out", "{d}/p.jpg"], ".exr"),
    (["--projection", "equirectangular", "--center", "1e6", "3"], "outside"),
])
def test_unwarp_bad_input_gets_one_line_and_status_2(tmp_path, capsys, scenes_dir_module,
                                                     args, message):
    setup_path = scenes_dir_module / "sphere.toml"
    write_exr(tmp_path / "img.exr", np.ones((N, N), np.float32))
    argv = ["unwarp", str(tmp_path / "img.exr"), "--setup", str(setup_path),
            "--out", str(tmp_path / "p.exr")]
    argv += [a.format(d=tmp_path) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mitsweep: error:") and message in err and "\n" not in err


# ------------------------------------------------------------------ which way is up

def test_up_camera_puts_the_camera_side_on_top_and_away_turns_it(setup):
    """The room's camera is above the mirror looking down (world +z toward the camera):
    with ``up="camera"`` the top row looks toward +z and the bottom row toward -z (the
    floor); ``up="away"`` (a camera below the mirror looking up) turns the panorama by
    180 degrees, so it is world-up for that rig and still not mirror-reversed (the
    azimuth runs the other way)."""
    cam = panorama_map(setup, (N, N), projection="equirectangular")
    away = panorama_map(setup, (N, N), projection="equirectangular", up="away")
    Wp, Hp = cam.size
    cols = np.arange(Wp)
    assert np.all(cam.directions(np.zeros(Wp), cols)[..., 2]
                  > cam.directions(np.full(Wp, Hp - 1), cols)[..., 2])
    assert np.all(away.directions(np.zeros(Wp), cols)[..., 2]
                  < away.directions(np.full(Wp, Hp - 1), cols)[..., 2])
    prow, pcol = np.mgrid[0:Hp, 0:Wp]
    np.testing.assert_allclose(away.directions(prow, pcol),
                               cam.directions(Hp - 1 - prow, Wp - 1 - pcol), atol=1e-12)
    # turned, not mirrored: going right along a row turns the azimuth the same way
    # relative to that panorama's up direction (the handedness of (right, up, out))
    def handedness(pm, top_z):
        mid = Hp // 2
        d0, d1 = pm.directions(mid, 10), pm.directions(mid, 11)
        up = np.array([0.0, 0.0, top_z])
        return float(np.dot(np.cross(d1 - d0, up), d0))
    assert np.sign(handedness(cam, 1.0)) == np.sign(handedness(away, -1.0))


def test_up_away_maps_agree_both_ways(setup):
    pmap = panorama_map(setup, (N, N), projection="cylindrical", up="away")
    rows, cols = np.mgrid[20:140:7, 20:140:7].astype(float)
    prow, pcol, ok = pmap.from_image(rows, cols)
    assert ok.mean() > 0.5
    r2, c2, ok2 = pmap.to_image(prow[ok], pcol[ok])
    assert ok2.all()
    np.testing.assert_allclose(r2, rows[ok], atol=0.01)
    np.testing.assert_allclose(c2, cols[ok], atol=0.01)


def test_unwarp_command_up_away_is_the_default_turned(tmp_path, capsys, scenes_dir_module):
    setup_path = scenes_dir_module / "sphere.toml"
    pmap = panorama_map(small(load_setup(setup_path)), (N, N), projection="equirectangular")
    img, _ = seen(pmap, lambda d: 0.5 + 0.3 * d[..., 0] + 0.2 * d[..., 2])
    src = tmp_path / "img.exr"
    write_exr(src, np.repeat(img[..., None], 3, axis=-1).astype(np.float32))
    from mitsweep.config import setup_to_toml

    st = tmp_path / "s.toml"
    st.write_text(setup_to_toml(small(load_setup(setup_path))))
    outs = {}
    for up in ("camera", "away"):
        out = tmp_path / f"{up}.exr"
        assert main(["unwarp", str(src), "--setup", str(st), "--projection",
                     "equirectangular", "--up", up, "--out", str(out)]) == 0
        outs[up] = read_exr(out)
    cam, away = outs["camera"][0], outs["away"][0]
    assert set(cam) == set(away) and "mask.Y" in cam
    for name in cam:
        np.testing.assert_array_equal(away[name], cam[name][::-1, ::-1])
    assert outs["away"][1]["up"] == "away"
