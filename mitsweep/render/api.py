"""Rendering API: the four camera modes on one reference pixel grid, AOVs, EXR output.

Reference geometry (docs/design.md, :mod:`mitsweep.optics.reference`): the reference
sensor distance ``i_ref`` is mid-travel of the sensor motion that is run (the default
motion over the optimal sweep range, or a given, e.g. measured, one); every mode's pixel
(col, row) has the chief ray of the pinhole camera at ``i_ref`` with the setup's pixel
pitch, so all images line up pixel for pixel with the ground truth and with the
tracer's IPSF banks, which resolve ``i_ref`` the same way.

Modes
-----
``pinhole``
    All-in-focus ground truth: aperture 0, sensor at ``i_ref``.
``focused``
    A normal camera focused at the mirror centre: focus distance ``D_0`` = axial
    distance of the focal image of the mirror's vertex (ρ = 0) for a depth of 500 mm,
    the paper's IPSF reference depth (mean of D_m and D_s, equal on an untilted
    mirror's axis); sensor at ``i_f = f D_0 / (D_0 − f)``, aperture ``f / (2 N)`` with
    the setup's f-number. Expressed on the reference grid by scaling the pitch to
    ``p i_f / i_ref``: a pixel's chief ray direction ``(u, v, i)/|…|`` is then the
    pinhole's. This equals resampling the real camera's image by the magnification
    ratio ``i_ref / i_f`` (≈ 1 ± 0.5 %).
``stopped``
    As ``focused`` at a smaller aperture (``f_number``, default 11, paper Fig. 10).
``sweep``
    The sensor moves over ``[sensor_start, sensor_end]`` with the setup's motion profile
    during the exposure, pixels at fixed physical positions (pitch unchanged): the image
    breathes by ``i(t)/i_ref`` exactly as in the rig, and the IPSF bank accounts for it.
"""

from __future__ import annotations

import logging
import math
import time as _time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any
from collections.abc import Iterable, Mapping

import numpy as np

from ..config import Setup
from ..deprecation import renamed_keywords
from ..optics import (SweepRange, chief_ray, focal_image_axial_distances, image_distance,
                      image_point, mirror_point_from_image, placement_of)
from ..optics.motion import MotionProfile
from ..optics.pixels import image_shape, pixel_to_sensor, sensor_to_pixel
from ..optics.reference import ReferenceGeometry, reference_geometry
from ..resources import check_allocation

__all__ = ["MODES", "SAMPLERS", "MODE_SAMPLERS", "RenderResult", "render_image", "render_to_exr",
           "render_point_source",
           "camera_dict", "mode_camera", "reference_sensor_distance",
           "focus_distance_mirror_centre", "mirror_image_bbox", "AOV_NAMES",
           "FOCUS_REFERENCE_DEPTH_MM"]

logger = logging.getLogger(__name__)

MODES = ("pinhole", "focused", "sweep", "stopped")
AOV_NAMES = ("depth", "mask")
#: Samplers of :func:`render_image`: ``multijitter`` stratifies each sample dimension
#: pair (pixel position, aperture, time) on a jittered grid, with the pairs' strata
#: permuted; ``independent`` draws every sample independently.
SAMPLERS = ("multijitter", "independent")
#: Each mode's sampler unless one is given. Stratified for the ground truth and the
#: fixed cameras (the pinhole's two seeds agree to 42 dB at 64 spp instead of 30 dB).
#: Independent for the sweep: the EDOF image's Wiener NSR is estimated from the sweep
#: image's own noise, and with stratified noise that estimate fell 2.4× and the EDOF
#: image lost 0.4 dB at 512 spp and 1.0 dB at 216 spp (the demo; docs/reference/render.md).
MODE_SAMPLERS = {"pinhole": "multijitter", "focused": "multijitter", "sweep": "independent",
                 "stopped": "multijitter"}
#: Depth (mm) whose focal image at the mirror centre the ``focused`` camera focuses on.
FOCUS_REFERENCE_DEPTH_MM = 500.0
DEFAULT_STOPPED_F_NUMBER = 11.0
#: Largest wavefront (pixels × samples per pass): bounds memory on the LLVM backend.
MAX_LANES = 1 << 24


@dataclass
class RenderResult:
    """A rendered image on the reference grid.

    Attributes
    ----------
    image : (H, W, 3) ndarray of float32
        Linear RGB radiance.
    aovs : dict of str to (H, W) ndarray of float32
        ``depth``: depth l (mm) along the world-bound reflected chief ray of the pixel
        centre (0 where the pixel does not see the mirror or the ray escapes);
        ``mask``: 1 where the pixel centre's chief ray hits the mirror.
    metadata : dict
        Provenance: setup, mode, spp, seed, sweep, camera, version, timings.
    """

    image: np.ndarray
    aovs: dict = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)


def reference_sensor_distance(setup: Setup, sweep: SweepRange | None = None, *,
                              motion: MotionProfile | None = None) -> float:
    """Reference sensor distance ``i_ref`` (mm): mid-travel of the motion run.

    A thin wrapper of :func:`mitsweep.optics.reference.reference_geometry`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sweep.
    sweep : mitsweep.optics.sweep.SweepRange, optional
        The sweep (default: the setup's optimal or given range).
    motion : mitsweep.optics.motion.MotionProfile, optional
        The motion actually run (default: the setup's profile over the sweep).
    """
    return reference_geometry(setup, sweep=sweep, motion=motion).sensor_distance


def focus_distance_mirror_centre(setup: Setup, depth: float = FOCUS_REFERENCE_DEPTH_MM) -> float:
    """Object distance (mm) of the focal image of the mirror vertex for ``depth`` mm.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror and lens.
    depth : float, optional
        Object depth l along the reflected chief ray of the vertex, mm.
    """
    d_m, d_s = focal_image_axial_distances(setup, np.array(0.0), depth)
    return float(0.5 * (np.asarray(d_m) + np.asarray(d_s)))


def camera_dict(setup: Setup, *, sensor_distance: float | None = None,
                motion: MotionProfile | None = None, aperture_radius: float = 0.0,
                pixel_pitch: float | None = None, spp: int = 16,
                crop: tuple[int, int, int, int] | None = None, exposure_s: float = 1.0,
                sampler: str = "independent") -> dict[str, Any]:
    """A ``focalsweep`` sensor dict at the lens centre, looking at the mirror.

    Give ``sensor_distance`` (fixed) or ``motion`` (a sweep over ``exposure_s``).
    ``crop = (x, y, w, h)`` renders a window of the film (pixels). ``sampler`` is one
    of :data:`SAMPLERS`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The camera, lens and mirror.
    sensor_distance : float, optional
        A fixed sensor distance, mm.
    motion : mitsweep.optics.motion.MotionProfile, optional
        A sensor motion during the exposure (the sweep).
    aperture_radius : float, optional
        Lens aperture radius, mm (0: a pinhole).
    pixel_pitch : float, optional
        Pixel pitch, mm (default: the setup's).
    spp : int, optional
        Samples per pixel.
    crop : tuple of int, optional
        ``(x, y, w, h)``: a window of the film to render, pixels.
    exposure_s : float, optional
        Exposure over which ``motion`` runs, s.
    sampler : str, optional
        One of :data:`SAMPLERS`.
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler: must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    from .scene import FAR_CLIP, camera_transform

    W, H = setup.sensor.resolution
    film = {"type": "hdrfilm", "width": W, "height": H, "rfilter": {"type": "box"},
            "pixel_format": "rgb", "sample_border": False}
    if crop is not None:
        x, y, w, h = (int(c) for c in crop)
        film.update(crop_offset_x=x, crop_offset_y=y, crop_width=w, crop_height=h)
    d = {"type": "focalsweep", "focal_length": setup.lens.focal_length,
         "aperture_radius": float(aperture_radius),
         "pixel_pitch": float(pixel_pitch or setup.sensor.pixel_pitch),
         "to_world": camera_transform(setup), "far_clip": FAR_CLIP,
         "film": film, "sampler": {"type": sampler, "sample_count": int(spp)}}
    if (sensor_distance is None) == (motion is None):
        raise ValueError("camera_dict: give sensor_distance or motion")
    if sensor_distance is not None:
        d["sensor_distance"] = float(sensor_distance)
    elif motion is not None:
        d.update(sensor_start=motion.start, sensor_end=motion.end, profile=motion.kind,
                 shutter_open=0.0, shutter_close=float(exposure_s))
        if motion.kind == "trapezoidal":
            d["accel_fraction"] = motion.accel_fraction
        elif motion.kind == "tabulated":
            d["times"] = " ".join(f"{t:.17g}" for t in motion.times)
            d["positions"] = " ".join(f"{p:.17g}" for p in motion.positions)
    return d


def mode_camera(setup: Setup, mode: str, geometry: ReferenceGeometry | None = None,
                f_number: float | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
    """Camera of a mode on the reference grid: (kwargs of :func:`camera_dict`, description).

    ``geometry`` is the setup's :class:`~mitsweep.optics.reference.ReferenceGeometry`
    (default: resolved from the setup alone). The description holds the reference sensor
    distance, the sweep and motion, and for ``focused``/``stopped`` the focus distance,
    sensor distance, f-number and the pitch scale ``i_f / i_ref`` that puts the image on
    the reference grid.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens, sensor and sweep.
    mode : str
        One of :data:`MODES`.
    geometry : mitsweep.optics.reference.ReferenceGeometry, optional
        The reference grid (default: resolved from the setup).
    f_number : float, optional
        The ``stopped`` mode's f-number (default 11).
    """
    if mode not in MODES:
        raise ValueError(f"mode: must be one of {', '.join(MODES)}, got {mode!r}")
    if geometry is None:
        geometry = reference_geometry(setup)
    elif not isinstance(geometry, ReferenceGeometry):
        raise TypeError(f"geometry: expected a ReferenceGeometry (from mitsweep.optics."
                        f"reference.reference_geometry), got {type(geometry).__name__}")
    sr, motion, i_ref = geometry.sweep, geometry.motion, geometry.sensor_distance
    f = setup.lens.focal_length
    pitch = setup.sensor.pixel_pitch
    desc = geometry.as_dict()
    if mode == "pinhole":
        return dict(sensor_distance=i_ref, aperture_radius=0.0, pixel_pitch=pitch), desc
    if mode == "sweep":
        desc["aperture_radius_mm"] = setup.lens.aperture_radius
        return dict(motion=motion, aperture_radius=setup.lens.aperture_radius,
                    pixel_pitch=pitch, exposure_s=max(sr.exposure_s, 1e-6)), desc
    n = setup.lens.f_number if mode == "focused" else (f_number or DEFAULT_STOPPED_F_NUMBER)
    if not n > 0:
        raise ValueError(f"f_number: must be > 0, got {n}")
    focus = focus_distance_mirror_centre(setup)
    i_f = image_distance(f, focus)
    desc.update(focus_distance_mm=focus, focus_reference_depth_mm=FOCUS_REFERENCE_DEPTH_MM,
                sensor_distance_mm=i_f, f_number=n, aperture_radius_mm=f / (2 * n),
                pitch_scale=i_f / i_ref)
    return dict(sensor_distance=i_f, aperture_radius=f / (2 * n),
                pixel_pitch=pitch * i_f / i_ref), desc


def mirror_image_bbox(setup: Setup, sensor_distance: float,
                      margin_px: int = 8) -> tuple[int, int, int, int]:
    """Pixel window (x, y, w, h) holding the mirror's image (rim and centre + margin).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sensor.
    sensor_distance : float
        Sensor distance of the pixel grid, mm.
    margin_px : int, optional
        Pixels added on every side.
    """
    placement = placement_of(setup.mirror)
    phi = np.linspace(0.0, 2 * math.pi, 721)
    rims = []
    for frac in (1.0, 0.75, 0.5, 0.25, 0.0):
        r = setup.mirror.rim_radius * frac
        surf = placement.surface(r * np.cos(phi), r * np.sin(phi))
        u, v = image_point(chief_ray(placement, surf), sensor_distance)
        rims.append((u, v))
    u = np.concatenate([a for a, _ in rims])
    v = np.concatenate([b for _, b in rims])
    H, W = image_shape(setup)
    rows, cols = sensor_to_pixel(u, v, (H, W), setup.sensor.pixel_pitch)
    x0 = int(max(0, math.floor(np.min(cols)) - margin_px))
    x1 = int(min(W, math.ceil(np.max(cols)) + margin_px + 1))
    y0 = int(max(0, math.floor(np.min(rows)) - margin_px))
    y1 = int(min(H, math.ceil(np.max(rows)) + margin_px + 1))
    if x1 <= x0 or y1 <= y0:
        return (0, 0, W, H)
    return (x0, y0, x1 - x0, y1 - y0)


#: Bytes per lane of a render wavefront (ray, sampler state, interaction, spectra) on
#: the LLVM backend: an estimate with headroom, for the memory check only.
_LANE_BYTES = 256
#: Bytes per pixel of the depth and mask AOVs: NumPy grids and directions (float64) and
#: the Dr.Jit rays and interactions of two intersections (float32).
_AOV_PIXEL_BYTES = 320


def render_memory_bytes(resolution: tuple[int, int], film: tuple[int, int], spp: int, *,
                        aovs: bool = False) -> float:
    """Estimated peak memory (bytes) of :func:`render_image`.

    The full RGB float32 image (W·H·3·4), Mitsuba's film on the rendered window (RGB,
    alpha and weight, float32) and its developed copy, the NumPy accumulators of the
    passes (two float64 RGB images), the wavefront of one pass (at most 2^24 lanes of
    :data:`_LANE_BYTES`) and, with AOVs, :data:`_AOV_PIXEL_BYTES` per pixel.

    Parameters
    ----------
    resolution : (int, int)
        The full image, (W, H) px.
    film : (int, int)
        The rendered window (Mitsuba's film, the crop), (w, h) px.
    spp : int
        Samples per pixel: with the window, the width of a pass's wavefront.
    aovs : bool, optional
        Whether the depth and mask layers are computed too (default False).
    """
    W, H = (float(x) for x in resolution)
    w, h = (float(x) for x in film)
    lanes = min(float(spp) * w * h, float(MAX_LANES))
    total = W * H * 3 * 4 + w * h * (5 * 4 + 3 * 4 + 2 * 3 * 8) + lanes * _LANE_BYTES
    if aovs:
        total += W * H * _AOV_PIXEL_BYTES
    return total


def _pass_seeds(seed: int, n: int) -> list[int]:
    return [int((seed * 1_000_003 + k) % (1 << 32)) for k in range(n)]


def multijitter_count(n: int) -> int:
    """The sample count Mitsuba's ``multijitter`` sampler makes of ``n``: a
    ``floor(sqrt(n))`` × ``ceil(n / floor(sqrt(n)))`` grid (it rounds up to that).

    Parameters
    ----------
    n : int
        Samples per pixel asked of the sampler, >= 1.

    Returns
    -------
    int
        Samples per pixel it takes, >= ``n``.
    """
    f = math.isqrt(n)
    return f * -(-n // f)


def pass_counts(spp: int, per_pass: int, sampler: str = "independent") -> list[int]:
    """Samples per pixel of each render pass: they sum to ``spp``, none exceeds
    ``per_pass``, and each is a count ``sampler`` takes as it is (``multijitter``
    rounds any other count up, which would render more samples than counted).

    ``independent``: full passes and the rest. ``multijitter``: equal passes where a
    few more passes than the least allow it (512 at most 73 per pass: eight of 64),
    else each pass the largest exact count that fits. Each distinct count is a kernel
    of its own (Dr.Jit compiles the count in), so equal passes also compile less.

    Parameters
    ----------
    spp : int
        Samples per pixel of the whole render (>= 1).
    per_pass : int
        Most samples per pixel one pass may take (>= 1; the memory bound).
    sampler : {"independent", "multijitter"}, optional
        Mitsuba's sampler of the render (default ``independent``).
    """
    n = math.ceil(spp / per_pass)
    if sampler == "independent":
        return [per_pass] * (n - 1) + [spp - per_pass * (n - 1)]
    for k in range(n, 2 * n + 1):
        if spp % k == 0 and multijitter_count(spp // k) == spp // k:
            return [spp // k] * k
    counts, left = [], spp
    while left > 0:
        c = min(left, per_pass)
        while multijitter_count(c) != c:
            c -= 1
        counts.append(c)
        left -= c
    return counts


def _load_passes(scene_dict, spp):
    """Load ``scene_dict`` for ``spp`` samples in passes (memory bound): (scene, counts)."""
    import mitsuba as mi

    film = scene_dict["sensor"]["film"]
    w = film.get("crop_width", film["width"])
    h = film.get("crop_height", film["height"])
    sampler = scene_dict["sensor"]["sampler"]["type"]
    counts = pass_counts(spp, max(1, min(spp, MAX_LANES // max(1, w * h))), sampler)
    scene_dict["sensor"]["sampler"]["sample_count"] = counts[0]
    return mi.load_dict(scene_dict), counts


def _render_loaded(scene, counts, seed, *, progress=True, desc="render"):
    """Mean image (h, w, C) of a loaded scene over passes of ``counts`` samples, and
    the seconds spent rendering."""
    import mitsuba as mi

    spp = sum(counts)
    acc = None
    bar = None
    if progress and len(counts) > 1:
        from tqdm import tqdm

        bar = tqdm(total=spp, desc=desc, unit="spp", leave=False)
    t0 = _time.perf_counter()
    for s, c in zip(_pass_seeds(seed, len(counts)), counts):
        img = np.array(mi.render(scene, seed=s, spp=c), dtype=np.float64)
        acc = img * c if acc is None else acc + img * c
        if bar is not None:
            bar.update(c)
    if bar is not None:
        bar.close()
    return (acc / spp).astype(np.float32), _time.perf_counter() - t0


def render_passes(scene_dict, spp, seed, *, progress=True, desc="render", check=None):
    """Render ``spp`` samples in passes (memory bound, progress).

    Parameters
    ----------
    scene_dict : dict
        The Mitsuba scene description (``mi.load_dict``'s), its sampler included.
    spp : int
        Samples per pixel in all, split into passes by :func:`pass_counts`.
    seed : int
        The render's seed; pass k renders with seed ``(seed * 1000003 + k) mod 2**32``.
    progress : bool, optional
        Show a progress bar on stderr (default True).
    desc : str, optional
        The progress bar's label (default ``"render"``).
    check : callable, optional
        ``check(scene)`` runs on the loaded scene before any pass; it raises to stop.

    Returns
    -------
    image : (h, w, C) ndarray of float32
        The mean over all samples.
    scene : mitsuba.Scene
        The loaded scene.
    seconds : float
        Wall time of the passes only, not of the scene load.
    """
    scene, counts = _load_passes(scene_dict, spp)
    if check is not None:
        check(scene)
    img, t = _render_loaded(scene, counts, seed, progress=progress, desc=desc)
    return img, scene, t


def _aovs(scene, setup, i_ref: float, wanted) -> dict:
    """Depth l and mirror mask on the reference grid, one chief ray per pixel centre."""
    import drjit as dr
    import mitsuba as mi

    H, W = image_shape(setup)
    rows, cols = np.indices((H, W))
    u, v = pixel_to_sensor(rows, cols, (H, W), setup.sensor.pixel_pitch)
    vd = setup.mirror.vertex_distance
    d = np.stack([u, v, -np.full_like(u, i_ref)], axis=-1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    ray = mi.Ray3f(mi.Point3f(0.0, 0.0, vd), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))
    si = scene.ray_intersect(ray)
    mirror = [s for s in scene.shapes() if s.id() == "mirror"]
    on_mirror = si.is_valid() & (si.shape == mi.ShapePtr(mirror[0]))
    out = {}
    if "mask" in wanted:
        out["mask"] = np.array(mi.Float(on_mirror), dtype=np.float32).reshape(H, W)
    if "depth" in wanted:
        n = si.sh_frame.n
        w = ray.d - 2.0 * dr.dot(ray.d, n) * n
        si2 = scene.ray_intersect(si.spawn_ray(w), on_mirror)
        l = dr.select(on_mirror & si2.is_valid(), si2.t, 0.0)
        out["depth"] = np.array(l, dtype=np.float32).reshape(H, W)
    return out


def render_image(setup: Setup, mode: str, *, spp: int, seed: int = 0, aovs: Iterable[str] = (),
                 sweep: SweepRange | None = None, motion: MotionProfile | None = None,
                 f_number: float | None = None, mirror_only: bool = True,
                 progress: bool = False, max_depth: int | None = None,
                 sampler: str | None = None,
                 scene: str | Path | Mapping[str, Any] | None = None,
                 scene_unit: str | None = None,
                 resolution: tuple[int, int] | None = None) -> RenderResult:
    """Render the setup's scene, or a user's Mitsuba scene, through the mirror in one of
    :data:`MODES`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    mode : {"pinhole", "focused", "sweep", "stopped"}
        See the module docstring (all on the reference grid).
    spp : int
        Samples per pixel (> 0); rendered in passes of at most 2^24 samples.
    seed : int
        Base seed; pass k uses ``(seed · 1000003 + k) mod 2^32``.
    aovs : iterable of {"depth", "mask"}
        Extra layers, computed only when asked.
    sweep : SweepRange, optional
        Default: the setup's optimal range.
    motion : MotionProfile, optional
        The sensor motion of the ``sweep`` mode, e.g. a measured one (default: the
        setup's profile over ``sweep``); its mid-travel is the reference distance of
        every mode (:func:`mitsweep.optics.reference.reference_geometry`).
    f_number : float, optional
        The ``stopped`` mode's f-number (default 11).
    mirror_only : bool
        Render only the window holding the mirror's image (the rest is 0).
    progress : bool
        A tqdm bar on stderr over the passes.
    max_depth : int, optional
        Override the integrator depth chosen from the scene.
    sampler : {"multijitter", "independent"}, optional
        How the samples of a pixel are drawn (:data:`SAMPLERS`; default the mode's,
        :data:`MODE_SAMPLERS`). ``multijitter`` is stratified: on the demo's sphere the
        ground truth's two seeds agree to 42 dB at 64 spp, where independent samples
        agree to 30 dB (``mitsweep bench render``).
    scene : str, Path or dict, optional
        A user's Mitsuba scene instead of the built-in room: an XML file or a scene dict
        (``{"type": "scene", ...}`` as :func:`mitsuba.load_dict` takes). Default: the
        setup's ``scene.file`` if it has one, else the built-in room. Its sensors, films
        and integrators are replaced (each logged), the rest is moved to mm in the
        mirror's frame (:mod:`mitsweep.render.user_scene`), and a scene that hides the
        mirror or leaves nothing in its view raises
        :class:`~mitsweep.render.user_scene.UserSceneError` before rendering.
    scene_unit : {"mm", "cm", "m"}, optional
        The user scene's length unit (default: the setup's ``scene.unit``, else mm).
    resolution : (int, int), optional
        Render at ``(width, height)`` pixels instead of the setup's resolution, over the
        same frame: the pixel pitch is scaled
        (:meth:`mitsweep.config.Sensor.at_resolution`), so the mirror's image stays in
        frame; ``metadata["setup"]`` holds the scaled sensor and
        ``metadata["resolution"]`` the setup's resolution and pitch, the new ones and
        the scale.

    Returns
    -------
    RenderResult
        With a user scene, ``metadata["user_scene"]`` holds its source (file path and
        SHA-256, or ``"dict"`` and the SHA-256 of its canonical JSON), unit, placement,
        what was replaced and the kept objects; the integrator depth is
        ``scene.max_depth`` if set, else the user's integrator's ``max_depth`` + 1 (the
        mirror's bounce), else unlimited (-1); the integrator is ``mirrorpath`` at a
        depth of 1 to 8 in ``*_ad_*`` variants (``path``'s image; see
        :func:`~mitsweep.render.scene.build_scene`), else ``path``, or ``volpath`` where
        the scene has participating media.
    """
    from .. import __version__
    from ..config import setup_to_dict
    from .scene import build_scene
    from .sensor import register

    if not (isinstance(spp, (int, np.integer)) and spp > 0):
        raise ValueError(f"spp: must be a positive integer, got {spp!r}")
    unknown = sorted(set(aovs) - set(AOV_NAMES))
    if unknown:
        raise ValueError(f"aovs: unknown {unknown[0]!r}; allowed: {', '.join(AOV_NAMES)}")
    rescaled = None
    if resolution is not None:
        given = setup.sensor
        setup = replace(setup, sensor=given.at_resolution(*resolution))
        rescaled = {"setup_resolution_px": list(given.resolution),
                    "setup_pixel_pitch_mm": given.pixel_pitch,
                    "resolution_px": list(setup.sensor.resolution),
                    "pixel_pitch_mm": setup.sensor.pixel_pitch,
                    "pitch_scale": setup.sensor.pixel_pitch / given.pixel_pitch}
    geometry = reference_geometry(setup, sweep=sweep, motion=motion)
    kwargs, desc = mode_camera(setup, mode, geometry, f_number)
    sampler = MODE_SAMPLERS[mode] if sampler is None else sampler
    i_ref = desc["reference_sensor_distance_mm"]
    W, H = setup.sensor.resolution
    crop = mirror_image_bbox(setup, i_ref, margin_px=8) if mirror_only else (0, 0, W, H)
    check_allocation(f"render of {W}x{H} px ({crop[2]}x{crop[3]} px film, {spp} spp)",
                     render_memory_bytes((W, H), crop[2:], spp, aovs=bool(aovs)))
    variant = register()
    cam = camera_dict(setup, spp=spp, crop=crop, sampler=sampler, **kwargs)
    source = scene if scene is not None else setup.scene.file
    if source is None and scene_unit is not None:
        raise ValueError("scene_unit: applies to a user scene only (give scene=...)")
    user = None
    if source is None:
        scene_dict, info = build_scene(setup, cam, max_depth=max_depth)
    else:
        from .user_scene import check_view, load_user_scene

        user = load_user_scene(setup, source, unit=scene_unit)
        depth = max_depth if max_depth is not None else user_scene_depth(setup, user.max_depth)
        scene_dict, info = build_scene(setup, cam, surroundings=False, extra=user.objects,
                                       max_depth=depth)
        info["lighting"] = "user scene"
        if user.has_media:  # path ignores participating media
            scene_dict["integrator"]["type"] = info["integrator"] = "volpath"
    def check(loaded):
        if user is not None:  # refuse a hidden mirror or an empty view before rendering
            user.provenance["view"] = check_view(loaded, setup, i_ref, label=user.label,
                                                 aperture_radius=kwargs["aperture_radius"])
    t0 = _time.perf_counter()
    img, scene, t_render = render_passes(scene_dict, spp, seed, progress=progress,
                                          desc=f"{mode}", check=check)
    t_total = _time.perf_counter() - t0
    full = np.zeros((H, W, 3), dtype=np.float32)
    x, y, w, h = crop
    full[y:y + h, x:x + w] = img[..., :3]
    t1 = _time.perf_counter()
    layers = _aovs(scene, setup, i_ref, set(aovs)) if aovs else {}
    t_aov = _time.perf_counter() - t1
    meta = {"setup": setup_to_dict(setup), "mode": mode, "spp": int(spp), "seed": int(seed),
            "sampler": sampler,
            "version": __version__, "variant": variant, "crop": list(crop),
            "render_s": t_render, "load_and_render_s": t_total, "aov_s": t_aov, **desc, **{"scene": info}}
    if user is not None:
        meta["user_scene"] = user.provenance
    if rescaled is not None:
        meta["resolution"] = rescaled
    return RenderResult(full, layers, meta)


def user_scene_depth(setup: Setup, user_depth: int | None) -> int:
    """Integrator depth of a user scene: ``scene.max_depth`` if set, else the user's
    integrator's ``max_depth`` plus the mirror's bounce, else unlimited (-1).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``scene.max_depth`` (> 0: given; else not set) comes first.
    user_depth : int or None
        The ``max_depth`` of the scene file's own integrator (None, or <= 0: none or
        unlimited).
    """
    if setup.scene.max_depth > 0:
        return setup.scene.max_depth
    if user_depth is not None and user_depth > 0:
        return user_depth + 1
    return -1


def render_to_exr(path: str | Path, result: RenderResult) -> Path:
    """Write a :class:`RenderResult` as EXR (atomic): RGB plus ``depth.Z`` and ``mask.Y``.

    Parameters
    ----------
    path : str or Path
        The EXR file to write.
    result : RenderResult
        A render (:func:`render_image`), its AOVs and metadata.
    """
    from ..io import write_exr

    channels = {}
    if "depth" in result.aovs:
        channels["depth.Z"] = result.aovs["depth"]
    if "mask" in result.aovs:
        channels["mask.Y"] = result.aovs["mask"]
    return write_exr(path, result.image, channels=channels, metadata=result.metadata)


def _world_per_pixel(setup, u, v, depth, i_ref) -> float:
    """World distance (mm) at ``depth`` between chief rays one pixel apart (smaller axis)."""
    placement = placement_of(setup.mirror)
    p = setup.sensor.pixel_pitch
    pts = []
    for du, dv in ((0, 0), (p, 0), (0, p)):
        ray = mirror_point_from_image(placement, u + du, v + dv, i_ref)
        pts.append(ray.surface.position + depth * ray.world_dir)
    return float(min(np.linalg.norm(pts[1] - pts[0]), np.linalg.norm(pts[2] - pts[0])))


@renamed_keywords(window="window_px")
def render_point_source(setup: Setup, u: float, v: float, depth: float, *, spp: int,
                        seed: int = 0, mode: str = "sweep", window_px: int = 64,
                        sweep: SweepRange | None = None,
                        motion: MotionProfile | None = None,
                        sensor_distance: float | None = None,
                        f_number: float | None = None, radius_px: float = 0.1,
                        mesh_tol: float | None = None) -> np.ndarray:
    """Image (H, W) of a tiny emitter seen through the mirror, normalised to unit sum.

    The emitter is a sphere at depth ``depth`` (mm) along the world-bound chief ray of
    the upright image point ``(u, v)`` (mm) at the reference distance; its radius is
    ``radius_px`` (default a tenth) of the world size of a pixel there, so its own image
    is sub-pixel. Only a ``window_px`` × ``window_px`` pixel crop around the point's reference
    pixel is rendered. ``sweep`` and ``motion`` as in :func:`render_image` (they set the
    reference distance, so a tabulated ``motion`` places the source where the tracer's
    :func:`~mitsweep.tracer.integrated_psf` with that motion does).

    ``sensor_distance`` (with mode ``"fixed"``) renders a fixed sensor at that distance
    with the setup's pitch and aperture (the N-plane reference). ``mesh_tol`` (mm and
    rad) forces a mirror mesh with that sag and normal bound (accuracy studies).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens, sensor and sweep.
    u, v : float
        Upright image point at the reference distance, mm.
    depth : float
        Depth l of the emitter along the chief ray, mm.
    spp : int
        Samples per pixel.
    seed : int, optional
        Random seed.
    mode : str, optional
        One of :data:`MODES`.
    window_px : int, optional
        Side of the rendered crop, px (default 64; formerly ``window``, still accepted
        with a DeprecationWarning).
    sweep : mitsweep.optics.sweep.SweepRange, optional
        The sweep (default: the setup's).
    motion : mitsweep.optics.motion.MotionProfile, optional
        The sensor's motion (default: the setup's profile).
    sensor_distance : float, optional
        A fixed sensor distance, mm (instead of the mode's).
    f_number : float, optional
        The ``stopped`` mode's f-number.
    radius_px : float, optional
        The emitter's radius as a fraction of a pixel's world size.
    mesh_tol : float, optional
        Sag tolerance of the mirror mesh, mm (default: the setup's).
    """
    from .scene import build_scene
    from .sensor import register

    register()
    geometry = reference_geometry(setup, sweep=sweep, motion=motion)
    i_ref = geometry.sensor_distance
    placement = placement_of(setup.mirror)
    ray = mirror_point_from_image(placement, u, v, i_ref)
    if not np.all(np.isfinite(ray.surface.position)):
        raise ValueError(f"image point ({u:g}, {v:g}) mm: its chief ray misses the mirror")
    centre = ray.surface.position + depth * ray.world_dir
    radius = radius_px * _world_per_pixel(setup, u, v, depth, i_ref)
    kwargs: dict[str, Any]
    if mode == "fixed":
        if sensor_distance is None:
            raise ValueError("mode 'fixed' needs sensor_distance")
        kwargs = dict(sensor_distance=sensor_distance,
                      aperture_radius=setup.lens.aperture_radius,
                      pixel_pitch=setup.sensor.pixel_pitch)
    else:
        kwargs, _ = mode_camera(setup, mode, geometry, f_number)
    H, W = image_shape(setup)
    row, col = sensor_to_pixel(u, v, (H, W), setup.sensor.pixel_pitch)
    x0 = int(np.clip(round(float(col)) - window_px // 2, 0, max(0, W - window_px)))
    y0 = int(np.clip(round(float(row)) - window_px // 2, 0, max(0, H - window_px)))
    crop = (x0, y0, min(window_px, W), min(window_px, H))
    cam = camera_dict(setup, spp=spp, crop=crop, **kwargs)
    source = {"type": "sphere", "center": centre.tolist(), "radius": radius,
              "bsdf": {"type": "diffuse", "reflectance": 0.0},
              "emitter": {"type": "area", "radiance": 1.0}}
    mesh: dict[str, Any] = {} if mesh_tol is None else dict(mirror_mesh=True, sag_tol=mesh_tol,
                                            normal_tol=mesh_tol)
    scene_dict, _ = build_scene(setup, cam, surroundings=False, extra={"source": source},
                                max_depth=2, **mesh)
    img, _, _ = render_passes(scene_dict, spp, seed, progress=False)
    out = np.zeros((H, W), dtype=np.float64)
    x, y, w, h = crop
    out[y:y + h, x:x + w] = img[..., :3].mean(axis=-1)
    s = out.sum()
    if not s > 0:
        raise ValueError(f"point source at depth {depth:g} mm: no sample reached it "
                         f"(raise spp or window_px)")
    return out / s
