"""Scenes around the mirror: a textured room, boards at 10 cm – 3 m, lighting.

World frame as in :mod:`mitsweep.optics` (mm): mirror vertex at the origin, its axis +z
toward the camera, the camera (lens centre) at ``(0, 0, vertex_distance)`` looking down
−z with image up = +y. The room is an axis-aligned box of ``scene.room_size`` centred
on the mirror in x and y, its floor 40 % of the height below the mirror and its
ceiling above the camera. ``scene.objects`` square boards, each with a resolution target
or a scikit-image picture, are placed at depths log-spaced from 100 mm to 1500 mm in
directions the mirror reflects toward the camera (within the setup's FOV about the
mirror axis), facing the mirror and never inside the camera's line of sight.

Lighting: ``emissive`` makes every surface a textured area emitter with a black BSDF,
so a camera ray needs one bounce off the mirror (integrator ``max_depth = 2``) and the
only noise is the lens and pixel sampling; ``lit`` uses diffuse textured surfaces under
a ceiling light (``max_depth = 3``: mirror, diffuse surface, light). Emissive scenes are
rendered by the ``mirrorview`` integrator (:mod:`mitsweep.render.integrator`: the
``path`` integrator's image, bit for bit, at a quarter of its cost), lit ones (and user
scenes) in ``*_ad_*`` variants by ``mirrorpath`` (:mod:`mitsweep.render.ad_integrator`:
``path``'s image with the same seed, and a sweep derivative through the mirror), else
by ``path``.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from ..config import Setup
from ..optics import placement_of
from . import ad_integrator
from .integrator import INTEGRATOR_NAME, integrator_dict, register_integrator
from .mirror import mirror_shape
from .textures import TEXTURE_NAMES, texture

__all__ = ["build_scene", "integrator_depth", "board_layout", "camera_transform", "FAR_CLIP"]

logger = logging.getLogger(__name__)

#: Far clip of every camera, mm (Mitsuba's default, 1e4 scene units, would cut at 10 m).
FAR_CLIP = 1.0e6
_WALL_TILE_MM = 1000.0
_BOARD_HALF_ANGLE_DEG = 14.0


def integrator_depth(setup: Setup) -> int:
    """Path depth the scene needs (``scene.max_depth`` when set).

    Emissive surroundings: camera → mirror → emitter is two path segments
    (``max_depth = 2``); lit diffuse surroundings add the light connection (3).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``scene.max_depth`` (> 0: given) and ``scene.lighting``.
    """
    if setup.scene.max_depth > 0:
        return setup.scene.max_depth
    return 2 if setup.scene.lighting == "emissive" else 3


def camera_transform(setup: Setup) -> Any:
    """Camera-to-world ``look_at`` for the lens centre (Mitsuba scalar transform).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The lens sits on the mirror's axis at ``mirror.vertex_distance`` (mm) from the
        vertex, looking at it, +y up.
    """
    import mitsuba as mi

    vd = setup.mirror.vertex_distance
    return mi.ScalarTransform4f().look_at(origin=[0.0, 0.0, vd], target=[0.0, 0.0, 0.0],
                                          up=[0.0, 1.0, 0.0])


def _bitmap(name: str, tiles: float = 1.0):
    import mitsuba as mi

    return {"type": "bitmap", "bitmap": mi.Bitmap(texture(name)), "filter_type": "bilinear",
            "wrap_mode": "repeat", "raw": True,
            "to_uv": mi.ScalarTransform4f().scale([tiles, tiles, 1.0])}


def _surface(setup, to_world, tex_name: str, tiles: float = 1.0) -> dict:
    tex = _bitmap(tex_name, tiles)
    if setup.scene.lighting == "emissive":
        return {"type": "rectangle", "to_world": to_world,
                "bsdf": {"type": "diffuse", "reflectance": 0.0},
                "emitter": {"type": "area", "radiance": tex}}
    return {"type": "rectangle", "to_world": to_world,
            "bsdf": {"type": "diffuse", "reflectance": tex}}


def _room(setup) -> dict:
    import mitsuba as mi

    T = mi.ScalarTransform4f
    X, Y, Z = setup.scene.room_size
    z_floor, z_ceil = -0.4 * Z, 0.6 * Z
    zc = 0.5 * (z_floor + z_ceil)
    walls = {
        # rectangle: [-1, 1]², normal +z; each faces the room's inside.
        "floor": (T().translate([0, 0, z_floor]).scale([X / 2, Y / 2, 1]), "gravel", X),
        "ceiling": (T().translate([0, 0, z_ceil]).rotate([1, 0, 0], 180)
                    .scale([X / 2, Y / 2, 1]), "text", X),
        "wall_px": (T().translate([X / 2, 0, zc]).rotate([0, 1, 0], -90)
                    .scale([Z / 2, Y / 2, 1]), "brick", Y),
        "wall_nx": (T().translate([-X / 2, 0, zc]).rotate([0, 1, 0], 90)
                    .scale([Z / 2, Y / 2, 1]), "siemens", Y),
        "wall_py": (T().translate([0, Y / 2, zc]).rotate([1, 0, 0], 90)
                    .scale([X / 2, Z / 2, 1]), "bars", X),
        "wall_ny": (T().translate([0, -Y / 2, zc]).rotate([1, 0, 0], -90)
                    .scale([X / 2, Z / 2, 1]), "grass", X),
    }
    out = {}
    for name, (tw, tex, extent) in walls.items():
        out[name] = _surface(setup, tw, tex, tiles=max(1.0, extent / _WALL_TILE_MM))
    if setup.scene.lighting == "lit":
        out["ceiling_light"] = {
            "type": "rectangle",
            "to_world": T().translate([0, 0, z_ceil - 1.0]).rotate([1, 0, 0], 180)
            .scale([X / 6, Y / 6, 1]),
            "emitter": {"type": "area", "radiance": 8.0}}
    return out


def board_layout(setup: Setup) -> list[dict]:
    """Centres, normals, half-sizes (mm) and textures of the scene's boards.

    Deterministic for ``scene.texture_seed``. Depths log-spaced over 100–1500 mm
    (clipped to the room); directions within the setup's FOV about the mirror axis and
    at least 30° from it; boards reaching into the cylinder the camera looks through
    (radius rim + 15 mm around the camera axis) are redrawn.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``scene`` (``objects``: how many boards, ``texture_seed``, ``room_size``),
        mirror and field of view (``sweep.fov_deg``).
    """
    sc = setup.scene
    n = sc.objects
    if n == 0:
        return []
    rng = np.random.default_rng(sc.texture_seed)
    m = setup.mirror
    axis = placement_of(m).axis
    X, Y, Z = sc.room_size
    reach = 0.9 * min(X / 2, Y / 2, 0.4 * Z, 0.6 * Z)
    depths = np.geomspace(100.0, min(1500.0, reach), n)
    half_fov = min(math.radians(setup.sweep.fov_deg) / 2, math.radians(150.0))
    lo = math.radians(30.0)
    hi = max(lo + math.radians(5.0), half_fov - math.radians(_BOARD_HALF_ANGLE_DEG))
    names = [t for t in TEXTURE_NAMES if t not in ("checker",)]
    # An orthonormal frame around the mirror axis.
    e1 = np.cross(axis, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    keep_out = m.rim_radius + 15.0
    boards = []
    for k, d in enumerate(depths):
        half = d * math.tan(math.radians(_BOARD_HALF_ANGLE_DEG))
        for _ in range(200):
            theta = rng.uniform(lo, hi)
            phi = rng.uniform(0.0, 2.0 * math.pi)
            w = (math.cos(theta) * axis
                 + math.sin(theta) * (math.cos(phi) * e1 + math.sin(phi) * e2))
            c = d * w
            # Board corners: in the plane normal to w.
            t1 = np.cross(w, [0.0, 0.0, 1.0])
            t1 = t1 / np.linalg.norm(t1) if np.linalg.norm(t1) > 1e-9 else np.array([1.0, 0, 0])
            t2 = np.cross(w, t1)
            pts = [c + half * (a * t1 + b * t2) for a in (-1, 0, 1) for b in (-1, 0, 1)]
            blocked = any(math.hypot(p[0], p[1]) < keep_out and p[2] > -m.radius for p in pts)
            inside = all(abs(p[0]) < X / 2 and abs(p[1]) < Y / 2 and -0.4 * Z < p[2] < 0.6 * Z
                         for p in pts)
            if not blocked and inside:
                break
        else:
            logger.warning("board %d at %.0f mm: no free place found; skipped", k, d)
            continue
        boards.append({"center": c, "normal": -w, "half_size": half,
                       "texture": names[(k + sc.texture_seed) % len(names)]})
    return boards


def _boards(setup) -> dict:
    import mitsuba as mi

    out = {}
    for k, b in enumerate(board_layout(setup)):
        c = b["center"]
        up = [0.0, 0.0, 1.0] if abs(b["normal"][2]) < 0.95 else [0.0, 1.0, 0.0]
        tw = (mi.ScalarTransform4f().look_at(origin=c.tolist(), target=(c + b["normal"]).tolist(),
                                             up=up)
              .scale([b["half_size"], b["half_size"], 1.0]))
        out[f"board_{k}"] = _surface(setup, tw, b["texture"])
    return out


def build_scene(setup: Setup, sensor: dict, *, surroundings: bool = True, extra: dict | None = None,
                mirror_mesh: bool = False, sag_tol: float | None = None,
                normal_tol: float | None = None, max_depth: int | None = None) -> tuple[dict, dict]:
    """The Mitsuba scene dict of a setup with ``sensor``, and a description.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    sensor : dict
        The camera (e.g. from :func:`mitsweep.render.api.camera_dict`).
    surroundings : bool
        Include the room and the boards (False: mirror only, e.g. for point sources).
    extra : dict, optional
        More scene objects (name -> dict or instantiated Mitsuba object, e.g. a user
        scene's, :func:`mitsweep.render.user_scene.user_scene`).
    mirror_mesh : bool
        Mesh the mirror even where the analytic sphere applies (accuracy studies).
    sag_tol, normal_tol : float, optional
        Mesh bounds (default: the setup's ``scene.mesh_sag_tol``/``mesh_normal_tol``).
    max_depth : int, optional
        Integrator depth (default :func:`integrator_depth`).

    The integrator is ``mirrorview`` where it is exact (emissive lighting, a finite
    depth, every extra object black; not in scalar variants), else ``mirrorpath`` in
    ``*_ad_*`` variants at a depth of 1 to 8 (so a sweep gradient of the scene passes
    through the mirror), else ``path``; the description's ``integrator`` says which.
    """
    sc = setup.scene
    shape, info = mirror_shape(setup, force_mesh=mirror_mesh, sag_tol=sag_tol,
                               normal_tol=normal_tol)
    depth = integrator_depth(setup) if max_depth is None else max_depth
    black = all(_is_black(obj) for obj in (extra or {}).values())
    integrator = _integrator(sc.lighting if black else "lit", depth)
    d = {"type": "scene", "integrator": integrator, "sensor": sensor, "mirror": shape}
    if surroundings:
        d.update(_room(setup))
        d.update(_boards(setup))
    if extra:
        d.update(extra)
    return d, {"mirror": info, "max_depth": depth, "lighting": sc.lighting,
               "surroundings": surroundings, "integrator": integrator["type"]}


def _is_black(obj) -> bool:
    """Whether a scene object reflects nothing: a black ``diffuse`` BSDF."""
    bsdf = obj.get("bsdf") if isinstance(obj, dict) else None
    return (isinstance(bsdf, dict) and bsdf.get("type") == "diffuse"
            and bsdf.get("reflectance") in (0, 0.0))


def _integrator(lighting: str, depth: int) -> dict:
    """``mirrorview`` where it is exact and fast (vectorised variants), ``mirrorpath``
    where a gradient can be asked (``*_ad_*`` variants), else ``path``."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None or variant.startswith("scalar"):
        # Python integrators run per sample in scalar variants: keep the C++ one there.
        return integrator_dict("lit", depth)
    d = integrator_dict(lighting, depth, differentiable="_ad_" in variant)
    if d["type"] == INTEGRATOR_NAME:
        register_integrator()
    elif d["type"] == ad_integrator.INTEGRATOR_NAME:
        ad_integrator.register_integrator()
    return d
