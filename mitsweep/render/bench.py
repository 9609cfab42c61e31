"""``mitsweep bench render``: timings side by side in one process, and error vs time.

Sections of the result:

- ``focalsweep_s``, ``thinlens_s``, ``ratio``: the plugin collapsed to one sensor
  distance against Mitsuba's built-in ``thinlens`` at equal spp on the same scene
  (best of 3 interleaved runs, render only, scene already loaded); ``sweep_s``: the
  plugin with the sensor moving.
- ``error_vs_time``: RMSE against a reference (continuous sweep at 16× the largest
  budget, another seed) of the continuous sweep and of the paper-style sum of N fixed
  sensor positions at the same total spp, with their render times.
- ``savings``: item 5 of the issue — rendering only the mirror's window, the integrator
  depth chosen from the scene, the analytic sphere instead of a mesh, AOVs on demand.
- ``ground_truth``: what the demo's renders cost before and after (issue 14): for each
  spp, the old way (Mitsuba's ``path`` integrator, independent samples) and the new
  (``mirrorview``, the mode's sampler, :data:`~mitsweep.render.api.MODE_SAMPLERS`), the
  second render's wall and CPU seconds (``time.process_time``; the first compiled the
  kernels of that spp; both ways run in this process, so a loaded machine slows both
  alike) and the two-seed agreement: PSNR between renders
  of seeds 1 and 2 inside the mirror's image, normalised by the first one's 99th
  percentile there, as the demo's evaluation does.
- ``mesh_accuracy``: the sphere meshed at several bounds against the analytic sphere:
  triangles, measured errors, render time and the L1 difference of a focused
  point-source image (same seed, so the Monte Carlo noise largely cancels).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import numpy as np

__all__ = ["run_bench"]

_SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _setup(name: str, n: int):
    from ..config import load_setup

    s = load_setup(_SCENES / f"{name}.toml")
    W = s.sensor.resolution[0]
    sensor = dataclasses.replace(s.sensor, resolution=(n, n),
                                 pixel_pitch=s.sensor.pixel_pitch * W / n)
    return dataclasses.replace(s, sensor=sensor)


def _timed(scene, seed, spp=None):
    import drjit as dr
    import mitsuba as mi

    dr.sync_thread()
    t0 = time.perf_counter()
    img = mi.render(scene, seed=seed) if spp is None else mi.render(scene, seed=seed, spp=spp)
    arr = np.array(img)
    dr.sync_thread()
    return time.perf_counter() - t0, arr


def _best(fn, repeats=3):
    best, out = math.inf, None
    for _ in range(repeats):
        t, out = fn()
        best = min(best, t)
    return best, out


def _plugin_vs_thinlens(setup, spp):
    import mitsuba as mi

    from .api import camera_dict, mode_camera
    from .scene import build_scene, camera_transform
    from ..optics import object_distance

    W, H = setup.sensor.resolution
    p = setup.sensor.pixel_pitch
    kw, _ = mode_camera(setup, "focused", None, None)
    i = kw["sensor_distance"]
    ours = mi.load_dict(build_scene(setup, camera_dict(
        setup, spp=spp, sensor_distance=i, aperture_radius=kw["aperture_radius"]))[0])
    tl = {"type": "thinlens", "fov": math.degrees(2 * math.atan(W * p / 2 / i)),
          "fov_axis": "x", "aperture_radius": kw["aperture_radius"],
          "focus_distance": object_distance(setup.lens.focal_length, i),
          "to_world": camera_transform(setup), "far_clip": 1e6,
          "film": {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
                   "pixel_format": "rgb", "sample_border": False},
          "sampler": {"type": "independent", "sample_count": spp}}
    theirs = mi.load_dict(build_scene(setup, tl)[0])
    kws, _ = mode_camera(setup, "sweep", None, None)
    sweep = mi.load_dict(build_scene(setup, camera_dict(setup, spp=spp, **kws))[0])
    for sc in (ours, theirs, sweep):   # compile once
        _timed(sc, 0)
    times = {"ours": math.inf, "theirs": math.inf, "sweep": math.inf}
    for _ in range(3):
        for key, sc in (("ours", ours), ("theirs", theirs), ("sweep", sweep)):
            times[key] = min(times[key], _timed(sc, 1)[0])
    t_o, a = _timed(ours, 7)
    t_t, b = _timed(theirs, 7)
    return {"focalsweep_s": times["ours"], "thinlens_s": times["theirs"],
            "ratio": times["ours"] / times["theirs"], "sweep_s": times["sweep"],
            "same_seed_max_abs_diff": float(np.max(np.abs(a - b))),
            "resolution": [W, H], "spp": spp}


def _error_vs_time(setup, budgets, n_planes):
    import mitsuba as mi

    from .api import camera_dict, mode_camera
    from .scene import build_scene

    kws, _ = mode_camera(setup, "sweep", None, None)
    motion = kws["motion"]
    sweep = mi.load_dict(build_scene(setup, camera_dict(setup, spp=4, **kws))[0])
    ref_spp = 16 * max(budgets)
    _, ref = _timed(sweep, 12345, ref_spp)
    fixed = mi.load_dict(build_scene(setup, camera_dict(
        setup, spp=4, sensor_distance=motion.start,
        aperture_radius=setup.lens.aperture_radius))[0])
    params = mi.traverse(fixed)
    dists = motion.sensor_distance((np.arange(n_planes) + 0.5) / n_planes)
    _timed(fixed, 0, 4)
    rows = []
    norm = float(np.sqrt(np.mean(ref ** 2)))
    for spp in budgets:
        per = max(1, spp // n_planes)
        _timed(sweep, 0, spp)       # compile both kernels at these sample counts
        _timed(fixed, 0, per)
        t_c, img_c = _timed(sweep, 1, spp)
        acc, t_p = 0.0, 0.0
        for k, i in enumerate(dists):
            params["sensor.sensor_distance"] = mi.Float([float(i)])
            params.update()
            t, img = _timed(fixed, 100 + k, per)
            acc, t_p = acc + img, t_p + t
        img_p = acc / n_planes
        rows.append({"spp": spp,
                     "continuous_s": t_c,
                     "continuous_rel_rmse": float(np.sqrt(np.mean((img_c - ref) ** 2)) / norm),
                     "planes_s": t_p, "planes": n_planes, "planes_spp_each": per,
                     "planes_rel_rmse": float(np.sqrt(np.mean((img_p - ref) ** 2)) / norm)})
    return {"reference_spp": ref_spp, "rows": rows}


def _savings(setup, spp):
    from .api import render_image

    out = {}
    render_image(setup, "pinhole", spp=1)  # compile, build the scene caches
    full = _best(lambda: _run(setup, spp, mirror_only=False))
    crop = _best(lambda: _run(setup, spp, mirror_only=True))
    out["mirror_window"] = {"full_s": full[0], "window_s": crop[0], "ratio": crop[0] / full[0]}
    d_auto = _best(lambda: _run(setup, spp, max_depth=None))
    d_inf = _best(lambda: _run(setup, spp, max_depth=-1))
    out["integrator_depth"] = {
        "auto_depth": 2 if setup.scene.lighting == "emissive" else 3,
        "auto_s": d_auto[0], "unlimited_s": d_inf[0], "ratio": d_auto[0] / d_inf[0],
        "max_abs_diff": float(np.max(np.abs(d_auto[1] - d_inf[1])))}
    aov = _best(lambda: _aov_time(setup))
    out["aovs_on_demand"] = {"render_s": d_auto[0], "aov_pass_s": aov[0],
                             "note": "the AOV pass runs only when AOVs are asked for"}
    return out


def _run(setup, spp, **kw):
    from .api import render_image

    r = render_image(setup, "sweep", spp=spp, seed=3, **kw)
    return r.metadata["render_s"], r.image


def _aov_time(setup):
    from .api import render_image

    r = render_image(setup, "pinhole", spp=1, seed=3, aovs=("depth", "mask"))
    return r.metadata["aov_s"], None


def _mesh_accuracy(setup, tols, spp):
    from .api import render_point_source
    from .mirror import cached_mesh_file

    from ..optics.pixels import image_shape, pixel_to_sensor

    H, W = image_shape(setup)
    col, row = int(W * 0.66), int(H * 0.4)
    u, v = pixel_to_sensor(row, col, (H, W), setup.sensor.pixel_pitch)
    kw = dict(spp=spp, seed=4, mode="focused", window_px=31, radius_px=0.3)
    t0 = time.perf_counter()
    ref = render_point_source(setup, u, v, 500.0, **kw)
    t_ref = time.perf_counter() - t0
    rows = [{"mesh": "analytic sphere", "triangles": 0, "render_s": t_ref, "psf_l1": 0.0}]
    for tol in tols:
        _, stats = cached_mesh_file(setup.mirror, sag_tol=tol, normal_tol=tol)
        t0 = time.perf_counter()
        img = render_point_source(setup, u, v, 500.0, mesh_tol=tol, **kw)
        t = time.perf_counter() - t0
        rows.append({"mesh": f"tol {tol:g}", "triangles": stats["triangles"],
                     "sag_error_mm": stats["sag_error_mm"],
                     "normal_error_rad": stats["normal_error_rad"], "render_s": t,
                     "psf_l1": float(np.abs(img - ref).sum())})
    return rows


def _window_render(setup, mode, spp, seed, *, integrator=None, sampler=None):
    """One render of the mirror's window as :func:`render_image` makes it, optionally
    with another integrator: (image, wall s, CPU s)."""
    from .api import MODE_SAMPLERS, camera_dict, mirror_image_bbox, mode_camera, render_passes
    from .scene import build_scene

    kw, desc = mode_camera(setup, mode, None, None)
    crop = mirror_image_bbox(setup, desc["reference_sensor_distance_mm"], margin_px=8)
    cam = camera_dict(setup, spp=spp, crop=crop, sampler=sampler or MODE_SAMPLERS[mode], **kw)
    d, _ = build_scene(setup, cam)
    if integrator is not None:
        d["integrator"] = integrator
    c0 = time.process_time()
    img, _, wall = render_passes(d, spp, seed, progress=False)
    return img, wall, time.process_time() - c0


def _ground_truth(setup, budgets, modes=("pinhole",)):
    """Old (path, independent) against new (mirrorview, the mode's sampler) renders."""
    from .api import mirror_image_bbox, reference_sensor_distance, render_image

    i_ref = reference_sensor_distance(setup)
    x, y, w, h = mirror_image_bbox(setup, i_ref, margin_px=8)
    mask = render_image(setup, "pinhole", spp=1, aovs=("mask",)).aovs["mask"][y:y + h, x:x + w]
    inside = mask > 0.5
    old = {"type": "path", "max_depth": 2, "hide_emitters": False}
    rows = []
    for mode in modes:
        for spp in budgets:
            for name, kw in (("old", dict(integrator=old, sampler="independent")),
                             ("new", {})):
                a, _, _ = _window_render(setup, mode, spp, 1, **kw)   # compiles this spp
                b, wall, cpu = _window_render(setup, mode, spp, 2, **kw)
                level = float(np.percentile(a[inside], 99.0))
                # PSNR as mitsweep.deconv.psnr (render may not import deconv).
                mse = float(np.mean(((a - b)[inside] / level) ** 2))
                rows.append({"mode": mode, "spp": spp, "method": name, "render_s": wall,
                             "cpu_s": cpu, "two_seed_psnr_db": 10.0 * math.log10(1.0 / mse)})
    return rows


def run_bench(args: argparse.Namespace) -> dict:
    """All render benchmarks; ``args.quick`` shrinks sizes for a smoke run.

    Parameters
    ----------
    args : argparse.Namespace
        The command line's options; read: ``quick`` (bool, absent: False): 64 px and
        8 spp instead of 256 px and 32 spp, and fewer sample counts and mesh bounds.
    """
    from .sensor import register

    variant = register()
    quick = bool(getattr(args, "quick", False))
    n = 64 if quick else 256
    spp = 8 if quick else 32
    sphere = _setup("sphere", n)
    out = {"variant": variant}
    out.update(_plugin_vs_thinlens(sphere, spp))
    out["error_vs_time"] = _error_vs_time(_setup("sphere", 48 if quick else 128),
                                          [8, 32] if quick else [16, 64, 256], 8)
    out["savings"] = _savings(_setup("paraboloid", n), spp)
    out["ground_truth"] = _ground_truth(
        _setup("sphere", 128 if quick else 512), [4, 16] if quick else [16, 64, 256],
        ("pinhole",) if quick else ("pinhole", "focused", "sweep", "stopped"))
    out["mesh_accuracy"] = _mesh_accuracy(
        _setup("sphere", 512), [1e-2, 1e-3] if quick else [1e-2, 1e-3, 1e-4],
        2048 if quick else 16384)
    return out
