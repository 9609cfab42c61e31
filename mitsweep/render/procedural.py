"""A procedural scene family: seeded random objects, materials and lights around the mirror.

:func:`procedural_scene` ``(setup, seed, **params)`` makes the Mitsuba objects (mm, in the
mirror's frame, :mod:`mitsweep.optics`) of one scene of the family; the same setup, seed
and parameters give the same scene, so a dataset records only those
(:mod:`mitsweep.pipeline.tasks`). The parameters are plain JSON (numbers and strings);
:data:`DEFAULT_PARAMS` lists them and :func:`resolve_params` checks them.

Geometry
    ``objects`` shapes drawn from ``shapes`` (spheres, cubes turned at random,
    rectangles and disks facing the mirror with a random tilt, open cylinders along a
    coordinate axis). Each is placed where a pixel looks: a point drawn uniformly over
    the mirror's image (chief rays through image points, :func:`~mitsweep.optics.
    mirror_point_from_image`), at a depth ``l`` drawn log-uniformly over
    ``[depth_min_mm, depth_max_mm]`` widened to the setup's own depth range, along the
    point's world-bound reflected chief ray; its bounding sphere subtends an angular
    radius drawn log-uniformly over ``[size_min_deg, size_max_deg]`` from the mirror, so
    near and far objects have like image sizes. With probability ``cluster`` an object
    is put within twice the angular radius of an earlier one, at its own depth: one
    occludes the other. No bounding sphere overlaps another, and none enters the
    column the camera looks at the mirror through (the rim radius plus the lens
    aperture and 15 mm around the camera axis, from behind the mirror to the lens).
Materials
    A palette of ``palette`` materials per scene, each object one of them: a kind of
    ``materials`` (``diffuse``, ``plastic``, ``roughplastic``, ``roughconductor``:
    diffuse and glossy); with probability ``textured`` its colour is a texture of
    :mod:`mitsweep.render.textures` (scikit-image's bundled images, or a Siemens star,
    bar chart or checkerboard tinted with a random colour) tiled 1–4 times, else a
    uniform random colour. Surfaces reflect on both sides. The palette bounds the
    render's cost: every distinct BSDF is a callable the integrator's kernel traces
    and compiles for each render, a fixed cost that does not depend on the samples
    (measured at 128 px, loaded machine: 48 materials 20 s, 8 materials 9 s, 1
    material 2 s per render, at 16 as at 128 spp).
Lighting
    An environment map made from a bundled image (``envmap``: ``"random"``, a name of
    :data:`~mitsweep.render.textures.TEXTURE_NAMES`, or ``"none"``; mirrored into a
    seamless 2:1 latitude–longitude map, randomly turned about the vertical, times
    ``env_scale``) and ``lights`` rectangular area lights of radiance
    ``light_radiance`` (a random warm-to-cool tint) at 0.3–2 m in the mirror's view,
    facing away from it: they light the fronts of the objects beyond them, and the
    mirror sees their gray backs (a lamp seen from behind), not hot spots.

The objects reflect light (not the ``emissive`` room's black emitters), so the scene
needs Mitsuba's ``path`` integrator with ``max_depth`` segments: camera → mirror →
surface → light is 3; the default 4 adds one glossy inter-reflection.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from ..config import Setup
from ..optics import chief_ray, image_distance, image_point, mirror_point_from_image, placement_of
from .textures import TEXTURE_NAMES, texture

__all__ = ["procedural_scene", "procedural_layout", "resolve_params", "DEFAULT_PARAMS",
           "SHAPES", "MATERIALS", "FAMILY"]

logger = logging.getLogger(__name__)

FAMILY = "procedural"
SHAPES = ("sphere", "cube", "rectangle", "cylinder", "disk")
MATERIALS = ("diffuse", "plastic", "roughplastic", "roughconductor")
#: Conductors of Mitsuba's tabulated index-of-refraction list.
_METALS = ("Au", "Cu", "Al", "Ag", "Cr")
#: Gray procedural patterns: tinted with a random colour.
_PATTERNS = ("siemens", "bars", "checker")
#: Bundled images a random environment map is made of (not retina, mostly black).
_ENV_IMAGES = ("astronaut", "camera", "coffee", "chelsea", "brick", "grass", "gravel",
               "text", "rocket")
#: Most objects and lights of a scene (parameter limits).
MAX_OBJECTS = 256
MAX_LIGHTS = 16
#: Longest side of a texture or environment map handed to Mitsuba (px); larger bundled
#: images (retina is 1411²) are subsampled, which bounds a scene's memory.
_MAX_TEXTURE_PX = 512
_ENV_WIDTH_PX = 1024
#: Candidate image points drawn per scene to place objects on.
_CANDIDATES = 4096
_ATTEMPTS = 64
_KEEP_OUT_MARGIN_MM = 15.0
_LIGHT_DEPTH_MM = (300.0, 2000.0)
#: Reflectance of an area light's back (its housing).
_HOUSING = 0.5
_LIGHT_SIZE_DEG = (4.0, 10.0)

#: The parameters of the family and their defaults (every value plain JSON).
DEFAULT_PARAMS = {
    "objects": 48,
    "shapes": ",".join(SHAPES),
    "materials": ",".join(MATERIALS),
    "palette": 8,
    "textured": 0.75,
    "depth_min_mm": 100.0,
    "depth_max_mm": 20000.0,
    "size_min_deg": 5.0,
    "size_max_deg": 30.0,
    "cluster": 0.5,
    "envmap": "random",
    "env_scale": 1.0,
    "lights": 2,
    "light_radiance": 20.0,
    "max_depth": 4,
}


def _choices(value, key: str, allowed: tuple[str, ...]) -> str:
    names = [s.strip() for s in value.split(",")] if isinstance(value, str) else None
    if not names or not all(names):
        raise ValueError(f"{key}: must be a comma-separated list of {', '.join(allowed)}, "
                         f"got {value!r}")
    for n in names:
        if n not in allowed:
            raise ValueError(f"{key}: unknown {n!r}; allowed: {', '.join(allowed)}")
    return ",".join(dict.fromkeys(names))


def resolve_params(**params: Any) -> dict:
    """The family's parameters: :data:`DEFAULT_PARAMS` updated by ``params``, checked.

    Raises ValueError naming the parameter and what it allows. The result is plain
    JSON and ``resolve_params(**resolve_params(**p)) == resolve_params(**p)``.

    Parameters
    ----------
    **params
        Any of :data:`DEFAULT_PARAMS`: ``objects`` (1 to :data:`MAX_OBJECTS`),
        ``shapes`` and ``materials`` (comma-separated names of :data:`SHAPES` and
        :data:`MATERIALS`), ``palette`` (materials drawn per scene), ``textured`` and
        ``cluster`` (probabilities in [0, 1]), ``depth_min_mm`` and ``depth_max_mm``
        (mm, > 0, min <= max), ``size_min_deg`` and ``size_max_deg`` (angular radius,
        degrees, in (0, 40]), ``envmap`` (``random``, ``none`` or a texture name),
        ``env_scale`` and ``light_radiance`` (>= 0), ``lights`` (0 to
        :data:`MAX_LIGHTS`), ``max_depth`` (3 to 16); an unknown name is refused.
    """
    unknown = sorted(set(params) - set(DEFAULT_PARAMS))
    if unknown:
        raise ValueError(f"{unknown[0]}: not a parameter of the procedural family; known: "
                         f"{', '.join(DEFAULT_PARAMS)}")
    p = {**DEFAULT_PARAMS, **params}

    def integer(key, lo, hi):
        v = p[key]
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and lo <= v <= hi):
            raise ValueError(f"{key}: must be an integer in [{lo}, {hi}], got {v!r}")
        p[key] = int(v)

    def real(key, lo, hi, *, open_lo=False):
        v = p[key]
        ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
        ok = ok and math.isfinite(v) and (v > lo if open_lo else v >= lo) and v <= hi
        if not ok:
            bound = "(" if open_lo else "["
            raise ValueError(f"{key}: must be a number in {bound}{lo:g}, {hi:g}], got {v!r}")
        p[key] = float(v)

    integer("objects", 1, MAX_OBJECTS)
    integer("lights", 0, MAX_LIGHTS)
    integer("max_depth", 3, 16)
    integer("palette", 1, MAX_OBJECTS)
    p["shapes"] = _choices(p["shapes"], "shapes", SHAPES)
    p["materials"] = _choices(p["materials"], "materials", MATERIALS)
    for key in ("textured", "cluster"):
        real(key, 0.0, 1.0)
    real("depth_min_mm", 0.0, 1e7, open_lo=True)
    real("depth_max_mm", p["depth_min_mm"], 1e7)
    real("size_min_deg", 0.0, 40.0, open_lo=True)
    real("size_max_deg", p["size_min_deg"], 40.0)
    real("env_scale", 0.0, 1e6)
    real("light_radiance", 0.0, 1e6)
    envs = ("random", "none") + TEXTURE_NAMES
    if p["envmap"] not in envs:
        raise ValueError(f"envmap: must be one of {', '.join(envs)}, got {p['envmap']!r}")
    return p


def depth_range(setup: Setup, params: dict) -> tuple[float, float]:
    """Depths (mm) objects are drawn over: the parameters' range widened to the setup's
    ``sweep.depth_min``–``depth_max`` (an infinite ``depth_max`` adds nothing).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``sweep.depth_min`` and ``sweep.depth_max`` (mm).
    params : dict
        Resolved parameters (:func:`resolve_params`): ``depth_min_mm`` and
        ``depth_max_mm`` are read.
    """
    lo = min(params["depth_min_mm"], setup.sweep.depth_min)
    far = setup.sweep.depth_max
    hi = max(params["depth_max_mm"], far if math.isfinite(far) else 0.0)
    return lo, hi


def _candidates(setup, rng) -> dict:
    """Chief rays through image points drawn uniformly over the mirror's image (and
    the sensor): the places pixels look at, as mirror points and world directions."""
    placement = placement_of(setup.mirror)
    phi = np.linspace(0.0, 2 * math.pi, 361)
    r = setup.mirror.rim_radius
    rim = chief_ray(placement, placement.surface(r * np.cos(phi), r * np.sin(phi)))
    # Image coordinates on a sensor 1 mm behind the lens: tangents of the view angles.
    u, v = image_point(rim, 1.0)
    i_nominal = image_distance(setup.lens.focal_length, setup.mirror.vertex_distance)
    half_w, half_h = (0.5 * s / i_nominal for s in setup.sensor.size)
    u0, u1 = max(u.min(), -half_w), min(u.max(), half_w)
    v0, v1 = max(v.min(), -half_h), min(v.max(), half_h)
    uu = rng.uniform(u0, u1, _CANDIDATES)
    vv = rng.uniform(v0, v1, _CANDIDATES)
    ray = mirror_point_from_image(placement, uu, vv, 1.0)
    ok = np.isfinite(ray.surface.rho) & ray.visible
    if not np.any(ok):
        raise ValueError("procedural scene: no chief ray of the image reaches the mirror")
    return {"origin": ray.surface.position[ok], "direction": ray.world_dir[ok]}


def _keep_out_distance(setup, c: np.ndarray) -> float:
    """Distance (mm) from ``c`` to the camera's column (axis segment, behind the
    mirror to the lens) minus the column's radius."""
    m = setup.mirror
    z0, z1 = -m.radius if math.isfinite(m.radius) else -m.rim_radius, m.vertex_distance
    z = min(max(c[2], z0), z1)
    radius = m.rim_radius + setup.lens.aperture_radius + _KEEP_OUT_MARGIN_MM
    return float(math.hypot(c[0], c[1], c[2] - z) - radius)


def _log_uniform(rng, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _frame(rng) -> list:
    """A random rotation as (axis, angle_deg)."""
    axis = rng.normal(size=3)
    return [(axis / np.linalg.norm(axis)).tolist(), float(rng.uniform(0.0, 360.0))]


def _material(rng, params: dict) -> dict:
    kind = str(rng.choice(params["materials"].split(",")))
    colour: dict
    if rng.uniform() < params["textured"]:
        name = str(rng.choice(TEXTURE_NAMES))
        colour = {"texture": name, "tiles": float(rng.integers(1, 5)),
                  "tint": rng.uniform(0.3, 1.0, 3).tolist() if name in _PATTERNS else None}
    else:
        colour = {"rgb": rng.uniform(0.05, 0.9, 3).tolist()}
    out: dict[str, Any] = {"kind": kind, "colour": colour}
    if kind in ("roughplastic", "roughconductor"):
        out["alpha"] = float(rng.uniform(0.05, 0.35))
    if kind == "roughconductor":
        out["metal"] = str(rng.choice(_METALS))
    return out


def procedural_layout(setup: Setup, seed: int, **params: Any) -> tuple[dict, dict]:
    """The scene of ``seed`` as plain data (mm, mirror frame), and its parameters.

    Returns ``(layout, params)``: ``layout["objects"]`` is a list of records (``shape``,
    ``center``, ``radius`` of the bounding sphere, ``depth`` along the chief ray it was
    placed on, ``direction`` of that ray, the shape's own size and orientation and its
    ``material``), ``layout["lights"]`` the area lights, ``layout["envmap"]`` the
    environment (or None), ``layout["depth_range"]`` the depths drawn over;
    ``params`` are the resolved parameters (:func:`resolve_params`). No Mitsuba.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its mirror, lens and sensor say where pixels look; its depth range widens the
        depths drawn over.
    seed : int
        The scene (>= 0); the same setup, seed and parameters give the same layout.
    **params
        Any of :data:`DEFAULT_PARAMS` (:func:`resolve_params`).
    """
    if not (isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0):
        raise ValueError(f"seed: must be an integer >= 0, got {seed!r}")
    params = resolve_params(**params)
    rng = np.random.default_rng([int(seed), 0x5CE2E])
    cand = _candidates(setup, rng)
    n_cand = len(cand["direction"])
    lo, hi = depth_range(setup, params)
    shapes = params["shapes"].split(",")
    size_lo, size_hi = (math.radians(params[k]) for k in ("size_min_deg", "size_max_deg"))
    placed: list[dict] = []

    def free(c, r) -> bool:
        if _keep_out_distance(setup, c) < r:
            return False
        if np.linalg.norm(c) < r + 1.5 * setup.mirror.rim_radius:
            return False
        return all(np.linalg.norm(c - np.asarray(o["center"])) >= r + o["radius"]
                   for o in placed)

    def place(depth_lo, depth_hi, ang_lo, ang_hi, near=None):
        for _ in range(_ATTEMPTS):
            if near is not None:
                dirs = cand["direction"]
                cos = dirs @ np.asarray(near["direction"])
                close = np.nonzero(cos > math.cos(2.0 * near["angular_radius"]))[0]
                k = int(rng.choice(close)) if len(close) else int(rng.integers(n_cand))
            else:
                k = int(rng.integers(n_cand))
            depth = _log_uniform(rng, depth_lo, depth_hi)
            alpha = _log_uniform(rng, ang_lo, ang_hi)
            w = cand["direction"][k]
            c = cand["origin"][k] + depth * w
            r = depth * math.sin(alpha)
            if free(c, r):
                return {"center": c.tolist(), "radius": r, "depth": depth,
                        "direction": w.tolist(), "angular_radius": alpha}
        return None

    palette = [_material(rng, params) for _ in range(params["palette"])]
    objects: list[dict[str, Any]] = []
    for j in range(params["objects"]):
        near = None
        if objects and rng.uniform() < params["cluster"]:
            near = objects[int(rng.integers(len(objects)))]
        spot = place(lo, hi, size_lo, size_hi, near)
        if spot is None:
            logger.debug("procedural scene %d: object %d found no free place; left out",
                         seed, j)
            continue
        shape = str(rng.choice(shapes))
        m = int(rng.integers(len(palette)))
        obj = {"shape": shape, **spot, "material_index": m, "material": palette[m]}
        r = spot["radius"]
        if shape == "cube":
            obj["half_size"] = r / math.sqrt(3.0)
            obj["rotation"] = _frame(rng)
        elif shape in ("rectangle", "disk"):
            aspect = _log_uniform(rng, 0.5, 2.0) if shape == "rectangle" else 1.0
            a = r / math.sqrt(1.0 + aspect ** -2)
            obj["half_size"] = [a, a / aspect] if shape == "rectangle" else [r, r]
            # Facing the mirror point it was placed from, tilted up to ~50°.
            tilt = rng.normal(size=3) * 0.6
            n = -np.asarray(spot["direction"]) + tilt
            obj["normal"] = (n / np.linalg.norm(n)).tolist()
        elif shape == "cylinder":
            # Along a coordinate axis: Mitsuba's cylinder warns about the float32
            # round-off of any other rotation at these sizes (mm).
            h = r * float(rng.uniform(0.3, 0.9))
            axis = np.eye(3)[int(rng.integers(3))]
            c = np.asarray(spot["center"])
            obj["p0"], obj["p1"] = (c - h * axis).tolist(), (c + h * axis).tolist()
            obj["cylinder_radius"] = math.sqrt(r * r - h * h)
        placed.append(obj)
        objects.append(obj)
    lights = []
    for j in range(params["lights"]):
        spot = place(*_LIGHT_DEPTH_MM, *(math.radians(a) for a in _LIGHT_SIZE_DEG))
        if spot is None:
            logger.debug("procedural scene %d: light %d found no free place; left out",
                         seed, j)
            continue
        warm = float(rng.uniform())
        tint = [1.0, 0.85 + 0.15 * warm, 0.7 + 0.3 * (1.0 - warm)]
        # Facing away from the mirror: it lights the fronts of the objects beyond it,
        # and the mirror sees its gray back (a lamp's housing), not a hot spot that
        # would outweigh the whole image in any squared-error score.
        light = {**spot, "half_size": spot["radius"] / math.sqrt(2.0),
                 "normal": list(spot["direction"]),
                 "radiance": [params["light_radiance"] * t for t in tint]}
        placed.append(light)
        lights.append(light)
    env = None
    if params["envmap"] != "none":
        name = (str(rng.choice(_ENV_IMAGES)) if params["envmap"] == "random"
                else params["envmap"])
        env = {"texture": name, "rotation_deg": float(rng.uniform(0.0, 360.0)),
               "scale": params["env_scale"]}
    layout = {"objects": objects, "lights": lights, "envmap": env,
              "depth_range": [lo, hi]}
    return layout, params


def procedural_scene(setup: Setup, seed: int, **params: Any) -> tuple[dict, dict]:
    """The Mitsuba objects of procedural scene ``seed`` (name → dict), and its parameters.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its mirror, lens and sensor say where pixels look; its depth range widens the
        depths drawn over.
    seed : int
        The scene (>= 0); the same setup, seed and parameters give the same scene.
    **params
        Any of :data:`DEFAULT_PARAMS` (plain JSON).

    Returns
    -------
    objects : dict
        Shapes, BSDFs, emitters and the environment map, mm, in the mirror's frame:
        ready for ``{"type": "scene", **objects}`` (plus mirror, camera and an integrator
        of ``params["max_depth"]``, e.g. :func:`mitsweep.render.scene.build_scene` with
        ``surroundings=False, extra=objects``).
    params : dict
        The resolved parameters (:func:`resolve_params`):
        ``procedural_scene(setup, seed, **params)`` makes the same scene again.
    """
    layout, params = procedural_layout(setup, seed, **params)
    return scene_objects(layout), params


def _bitmap_texture(colour: dict, textures: dict):
    """A colour's texture: an ``rgb`` dict, or a bitmap texture instantiated once per
    image, tint and tiling (a scene dict holding instantiated textures, not raw
    bitmaps, stays cheap to fingerprint: :mod:`mitsweep.render.user_scene` hashes a
    dict's values, and millions of texels took minutes)."""
    import mitsuba as mi

    if "rgb" in colour:
        return {"type": "rgb", "value": list(colour["rgb"])}
    key = (colour["texture"], tuple(colour["tint"] or ()), colour["tiles"])
    if key not in textures:
        img = _subsampled(texture(colour["texture"]), _MAX_TEXTURE_PX)
        if colour["tint"]:
            img = img * np.asarray(colour["tint"], dtype=np.float32)
        t = colour["tiles"]
        textures[key] = mi.load_dict({
            "type": "bitmap", "bitmap": mi.Bitmap(np.ascontiguousarray(img, dtype=np.float32)),
            "filter_type": "bilinear", "wrap_mode": "repeat", "raw": True,
            "to_uv": mi.ScalarTransform4f().scale([t, t, 1.0])})
    return textures[key]


def _subsampled(img: np.ndarray, max_px: int) -> np.ndarray:
    step = max(1, math.ceil(max(img.shape[:2]) / max_px))
    return img[::step, ::step]


def _bsdf(material: dict, textures: dict) -> dict:
    colour = _bitmap_texture(material["colour"], textures)
    kind = material["kind"]
    if kind == "diffuse":
        d = {"type": "diffuse", "reflectance": colour}
    elif kind == "plastic":
        d = {"type": "plastic", "diffuse_reflectance": colour}
    elif kind == "roughplastic":
        d = {"type": "roughplastic", "diffuse_reflectance": colour, "alpha": material["alpha"]}
    else:
        d = {"type": "roughconductor", "material": material["metal"],
             "alpha": material["alpha"], "specular_reflectance": colour}
    # Two-sided for every shape: open ones (rectangles, disks, cylinders) need it, and
    # closed ones never show their inside, so one instance serves every shape.
    return {"type": "twosided", "bsdf": d}


def _axis_cylinder(p0, p1, radius: float):
    """``to_world`` of Mitsuba's unit cylinder (z in [0, 1]) from ``p0`` to ``p1`` along
    a coordinate axis: an exact permutation matrix, so Mitsuba's shear and scale
    checks (absolute 1e-6 on the decomposed matrix) see no round-off."""
    import mitsuba as mi

    p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
    a = int(np.argmax(np.abs(p1 - p0)))
    m = np.eye(4)
    # Columns: images of local x, y, z (a cyclic permutation, a proper rotation).
    m[:3, :3] = np.eye(3)[:, [(a + 1) % 3, (a + 2) % 3, a]] @ np.diag(
        [radius, radius, float(p1[a] - p0[a])])
    m[:3, 3] = p0
    return mi.ScalarTransform4f(m.tolist())


def _facing(center, normal, half_size):
    """``to_world`` of a rectangle or disk (local normal +z) at ``center`` facing
    ``normal`` with half-sizes ``(a, b)``."""
    import mitsuba as mi

    c = np.asarray(center)
    n = np.asarray(normal)
    up = [0.0, 0.0, 1.0] if abs(n[2]) < 0.95 else [0.0, 1.0, 0.0]
    return (mi.ScalarTransform4f().look_at(origin=c.tolist(), target=(c + n).tolist(), up=up)
            .scale([half_size[0], half_size[1], 1.0]))


def scene_objects(layout: dict) -> dict:
    """Mitsuba dicts of a :func:`procedural_layout` (name → dict).

    Parameters
    ----------
    layout : dict
        The layout (:func:`procedural_layout`'s first value): its objects, lights and
        environment map, mm, in the mirror's frame.
    """
    import mitsuba as mi

    from .sensor import register

    register()  # the variant (and mitsweep's plugins)

    T = mi.ScalarTransform4f
    textures: dict = {}
    bsdfs: dict = {}
    out = {}
    for k, o in enumerate(layout["objects"]):
        shape = o["shape"]
        if shape == "sphere":
            d = {"type": "sphere", "center": o["center"], "radius": o["radius"]}
        elif shape == "cube":
            axis, angle = o["rotation"]
            d = {"type": "cube", "to_world": T().translate(o["center"]).rotate(axis, angle)
                 .scale(o["half_size"])}
        elif shape in ("rectangle", "disk"):
            d = {"type": shape, "to_world": _facing(o["center"], o["normal"], o["half_size"])}
        else:
            d = {"type": "cylinder", "to_world": _axis_cylinder(o["p0"], o["p1"],
                                                                o["cylinder_radius"])}
        m = o["material_index"]
        if m not in bsdfs:
            bsdfs[m] = mi.load_dict(_bsdf(o["material"], textures))
        d["bsdf"] = bsdfs[m]
        out[f"object_{k:03d}_{shape}"] = d
    housing = mi.load_dict({"type": "twosided",
                            "bsdf": {"type": "diffuse", "reflectance": _HOUSING}})
    for k, light in enumerate(layout["lights"]):
        hs = light["half_size"]
        out[f"light_{k:02d}"] = {
            "type": "rectangle", "to_world": _facing(light["center"], light["normal"], (hs, hs)),
            "bsdf": housing,
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": light["radiance"]}}}
    env = layout["envmap"]
    if env is not None:
        out["environment"] = mi.load_dict({
            "type": "envmap", "bitmap": mi.Bitmap(_equirect(env["texture"])),
            "scale": env["scale"], "to_world": T().rotate([0.0, 1.0, 0.0], env["rotation_deg"])})
    return out


def _equirect(name: str) -> np.ndarray:
    """A seamless 2:1 latitude–longitude map from a bundled image: the image beside its
    mirror image (the seam at ±180° matches), rows resampled to half the width."""
    img = texture(name)
    pano = np.concatenate([img, img[:, ::-1]], axis=1)
    cols = np.linspace(0, pano.shape[1] - 1, _ENV_WIDTH_PX).round().astype(int)
    rows = np.linspace(0, pano.shape[0] - 1, _ENV_WIDTH_PX // 2).round().astype(int)
    return np.ascontiguousarray(pano[rows][:, cols], dtype=np.float32)
