"""A user's own Mitsuba scene seen through the mirror.

:func:`load_user_scene` reads a Mitsuba XML file or scene dict (the form
:func:`mitsuba.load_dict` takes) with Mitsuba's own parser (``mitsuba.parser``: the
file's ``<default>`` values, ``<include>``\\ s and references resolve as in
:func:`mitsuba.load_file`; relative file names against the file's folder), drops what
mitsweep supplies itself (sensors with their films and samplers, integrators: each
replacement is logged), and moves every kept object into the mirror's frame in mm:

.. math::

    M = T(\\mathrm{translate})\\; R_z R_y R_x\\; S(s),

with ``s`` the millimetres per scene unit (:data:`MM_PER_UNIT`) and the optional
placement (:class:`mitsweep.config.Placement`). ``M`` is prepended to the ``to_world``
of every top-level shape (a sphere's ``center``/``radius`` and a cylinder's ends
compose with it; instancing, ``shapegroup``/``instance``, is refused); point-like emitters
(``point``, ``spot``, ``projector``) move with ``M`` and their intensity is multiplied by ``s²``;
direction-only emitters (``directional``, ``envmap``, ``constant``) turn with the
rotation only. Media densities are divided by ``s`` (they are per unit length) and grid
volumes move with ``M``. Area emitters' radiance, BSDFs and textures do not depend on
the unit. So a pixel's value is the radiance the user's scene has in its own unit
system: the same scene written in metres and in millimetres renders the same image
(``tests/test_render_user_scene.py``).

:func:`check_view` then probes the loaded scene along the pixels' chief rays and
refuses, as a :class:`UserSceneError` (a user error: one line, exit 2 at the CLI), a
scene whose geometry lies between the lens and the mirror, one with nothing in the
mirror's view, and one without any emitter.

Before Mitsuba's parser sees a file, :func:`mitsweep.io.scene_files.scene_files` reads
it for every file it would open (includes, textures, meshes, ...) and refuses a named
pipe, device, socket or directory among them, on which the parser would block.
"""

from __future__ import annotations

import codecs
import contextlib
import hashlib
import json
import logging
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Mapping

import numpy as np

from ..config import Placement, Setup
from ..resources import FileTypeError, require_regular_file
from ..io.scene_files import SceneFileError, scene_files

__all__ = ["UserScene", "UserSceneError", "MM_PER_UNIT", "load_user_scene", "user_scene",
           "scene_transform", "check_view", "check_user_scene"]

logger = logging.getLogger(__name__)

#: Millimetres per scene unit.
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
#: Names mitsweep gives its own scene objects; a user's object so named is renamed.
RESERVED_NAMES = ("mirror", "sensor", "integrator", "type")
#: Emitters that sit at a point: intensity (per steradian) falls off as 1/distance².
_POINT_EMITTERS = {"point": "intensity", "spot": "intensity", "projector": "scale"}
#: Emitters that only have directions.
_DIRECTION_EMITTERS = ("directional", "envmap", "constant")
#: Probe of :func:`check_view`: chief rays on a grid of this many pixels per side.
_PROBE_GRID = 33


class UserSceneError(ValueError):
    """A user's scene cannot be rendered; the message names the scene and the problem."""


@dataclass(frozen=True)
class UserScene:
    """A user's scene, in mm in the mirror's frame, ready for a scene dict.

    Attributes
    ----------
    objects : dict of str to mitsuba.Object
        Instantiated shapes (with their BSDFs, textures, media and area emitters) and
        the emitters not attached to a shape, keyed by a name for
        :func:`mitsuba.load_dict` (the object's id where it has one).
    provenance : dict
        ``source`` (the file's absolute path, or ``"dict"``), ``sha256`` (of the file's
        bytes, or of the dict's canonical JSON), ``unit``, ``mm_per_unit``,
        ``placement``, ``replaced`` (what the scene had that mitsweep replaces),
        ``shapes`` and ``emitters`` (the kept names).
    max_depth : int or None
        The user's integrator's ``max_depth``, if it had one.
    has_media : bool
        Whether the scene holds participating media (it then needs ``volpath``).
    """

    objects: dict
    provenance: dict = field(default_factory=dict)
    max_depth: int | None = None
    has_media: bool = False

    @property
    def label(self) -> str:
        return self.provenance.get("source", "scene")


def scene_transform(unit: str = "mm", placement: Placement | None = None) -> np.ndarray:
    """The (4, 4) matrix from a user's scene coordinates to the mirror frame (mm).

    ``S(s)`` for the unit, then the placement's rotations about x, y and z (degrees),
    then its translation (mm); see the module docstring.

    Parameters
    ----------
    unit : {"mm", "cm", "m"}, optional
        The scene's length unit (default mm).
    placement : mitsweep.config.Placement, optional
        Rotations ``rotate_deg`` (degrees about x, y, z, in that order) and
        ``translate`` (mm) of the scene in the mirror frame (default None: none).
    """
    if unit not in MM_PER_UNIT:
        raise UserSceneError(f"scene unit: must be one of {', '.join(MM_PER_UNIT)}, "
                             f"got {unit!r}")
    m = np.diag([MM_PER_UNIT[unit]] * 3 + [1.0])
    if placement is None:
        return m
    for axis, deg in zip(range(3), placement.rotate_deg):
        c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
        i, j = [k for k in range(3) if k != axis]
        r = np.eye(4)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        m = r @ m
    t = np.eye(4)
    t[:3, 3] = placement.translate
    return t @ m


def _one_line(exc: Exception, name: str, path: str | None = None) -> str:
    """``name: problem`` from Mitsuba's message: source locations and repeats dropped,
    on one line."""
    text = re.sub(r"\[[\w.]+(?::\d+)?\]\s*", "", str(exc))
    if path:
        text = re.sub(rf"(At |Error while loading )?{re.escape(path)}\s*", "", text)
    out = []
    for part in (p.strip().rstrip(":;").strip() for p in text.splitlines()):
        if part and part not in out:  # nested errors repeat their context
            out.append(part)
    text = "; ".join(out) or type(exc).__name__
    return f"{name} {text}" if text.startswith("(line") else f"{name}: {text}"


@contextlib.contextmanager
def _resolver(folder: Path | None):
    """Resolve the scene's relative file names against ``folder`` while loading."""
    import mitsuba as mi

    if folder is None:
        yield
        return
    # Any: Mitsuba's stubs lack its module-level file_resolver and set_file_resolver
    file_resolver: Any = mi.file_resolver
    set_file_resolver: Any = mi.set_file_resolver
    old = mi.FileResolver(file_resolver())
    file_resolver().prepend(str(folder))
    try:
        yield
    finally:
        set_file_resolver(old)


def _canonical(value: Any) -> Any:
    """A JSON-able stand-in for a scene dict value (for the dict's SHA-256)."""
    if isinstance(value, Mapping):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    matrix = getattr(value, "matrix", None)
    if matrix is not None:
        return {"matrix": np.array(matrix, dtype=np.float64).tolist()}
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):
        return repr(value)
    if arr.dtype == object:
        return repr(value)
    if arr.size <= 16:      # colours, vectors: readable values
        return np.asarray(arr, dtype=np.float64).tolist()
    # a bitmap or a tensor: its bytes' digest (a list of millions of floats took minutes)
    arr = np.ascontiguousarray(arr)
    return {"shape": list(arr.shape), "dtype": str(arr.dtype),
            "sha256": hashlib.sha256(arr.tobytes()).hexdigest()}


def _source(scene) -> tuple[str, str, Path | None]:
    """(label, sha256, folder) of a scene path or dict."""
    if isinstance(scene, Mapping):
        if scene.get("type") != "scene":
            raise UserSceneError(f"scene dict: needs \"type\": \"scene\" (as mitsuba.load_dict "
                                 f"takes), got type {scene.get('type')!r}")
        blob = json.dumps(_canonical(scene), sort_keys=True).encode()
        return "dict", hashlib.sha256(blob).hexdigest(), None
    if not isinstance(scene, (str, Path)):
        raise UserSceneError(f"scene: expected a path to a Mitsuba XML file or a scene dict, "
                             f"got {type(scene).__name__}")
    if not str(scene).strip():  # Path("") is the working directory
        raise UserSceneError("scene: an empty path; give a Mitsuba XML scene file")
    path = Path(scene).expanduser().resolve()
    try:
        data = require_regular_file(path, "scene file").read_bytes()
    except FileNotFoundError:
        raise UserSceneError(f"{scene}: no such scene file") from None
    except OSError as exc:
        raise UserSceneError(f"{scene}: cannot read ({exc.strerror})") from None
    except FileTypeError as exc:
        raise UserSceneError(str(exc)) from None
    head = data.removeprefix(codecs.BOM_UTF8).lstrip()[:200]  # Mitsuba reads a BOM
    if not head.startswith(b"<"):
        raise UserSceneError(f"{scene}: not a Mitsuba XML scene (it does not start with an "
                             f"XML tag)")
    try:  # Mitsuba's parser blocks for ever on a named pipe: it never gets one
        scene_files(path)
    except (FileTypeError, SceneFileError) as exc:
        raise UserSceneError(str(exc)) from None
    return str(path), hashlib.sha256(data).hexdigest(), path.parent


def _move_shape(props, m: np.ndarray) -> None:
    """Prepend ``m`` to the ``to_world`` of ``props`` (composed in float64)."""
    import mitsuba as mi

    if "to_world" in props:
        old = props["to_world"]
        m = m @ np.array(old.matrix, dtype=np.float64)
        props["to_world"] = type(old)(m.tolist())
    else:
        props["to_world"] = mi.ScalarTransform4d(m.tolist())


def _scaled(props, key: str, factor: float, what: str) -> None:
    """Multiply a float or colour property by ``factor`` (a texture cannot be); an
    absent one is Mitsuba's default, 1."""
    if key not in props:
        props[key] = float(factor)
        return
    kind = str(props.type(key)).rsplit(".", 1)[-1]
    if kind == "Float":
        props[key] = float(props[key]) * factor
    elif kind == "Color":
        import mitsuba as mi

        c = props[key]
        props[key] = mi.ScalarColor3d(c[0] * factor, c[1] * factor, c[2] * factor)
    else:
        raise UserSceneError(f"{what}: its {key} is a {kind.lower()}, which cannot be "
                             f"converted to mm; give it as a float or rgb value")


def _move_emitter(props, m: np.ndarray, s: float, what: str) -> None:
    import mitsuba as mi

    plugin = props.plugin_name()
    rot = m.copy()
    rot[:3, 3] = 0.0
    rot[:3, :3] /= s  # rotation only
    if plugin in _POINT_EMITTERS:
        if "position" in props:
            p = np.asarray(props["position"], dtype=np.float64)
            props["position"] = mi.ScalarPoint3d(*(m[:3, :3] @ p + m[:3, 3]))
        else:
            _move_shape(props, m)
        if s != 1.0:  # irradiance I / r² stays what it is in the scene's own unit
            _scaled(props, _POINT_EMITTERS[plugin], s * s, what)
    elif plugin in _DIRECTION_EMITTERS:
        if "direction" in props:
            d = np.asarray(props["direction"], dtype=np.float64)
            props["direction"] = mi.ScalarVector3d(*(rot[:3, :3] @ d))
        elif "to_world" in props or np.any(rot != np.eye(4)):
            _move_shape(props, rot)
    else:
        logger.warning("%s: emitter plugin %r is moved by its to_world only", what, plugin)
        _move_shape(props, m)


def _node_ids(props) -> list[tuple[str, int]]:
    """(property name, node index) of a node's child references."""
    out = []
    for key in props.keys():
        if str(props.type(key)).endswith("ResolvedReference"):
            out.append((key, int(str(props[key]).split("[")[1].rstrip("]"))))
    return out


def _describe(node) -> str:
    ident = node.props.id()
    kind = str(node.type).rsplit(".", 1)[-1].lower()
    return f"{kind} {node.props.plugin_name()!r}" + (f" (id {ident!r})" if ident else "")


def _prepare(state, label: str, m: np.ndarray, s: float) -> tuple[list[str], int | None]:
    """Drop sensors and integrators, move the rest (see the module): (replaced, depth)."""
    import mitsuba as mi

    T = mi.ObjectType
    root = state.root.props
    replaced, depth = [], None
    children = dict(_node_ids(root))
    for key in list(root.keys()):
        kind = str(root.type(key)).rsplit(".", 1)[-1]
        if kind == "Object":  # an object instantiated before (a dict value)
            obj = root[key]
            if not np.allclose(m, np.eye(4)) and isinstance(obj, (mi.Shape, mi.Emitter)):
                raise UserSceneError(f"{label}: {key!r} is an instantiated Mitsuba object, "
                                     f"which cannot be moved to mm; give it as a dict")
            continue
        if kind != "ResolvedReference":
            continue
        node = state.nodes[children[key]]
        what = f"{label}: {_describe(node)}"
        if node.type in (T.Sensor, T.Integrator, T.Film, T.Sampler):
            if node.type == T.Integrator and "max_depth" in node.props:
                depth = int(node.props["max_depth"])
            replaced.append(_describe(node))
            logger.info("%s: replaced by mitsweep's %s", what,
                        "camera" if node.type != T.Integrator else "integrator")
            del root[key]
        elif node.type == T.Shape and node.props.plugin_name() in ("shapegroup", "instance"):
            # An instance's shape group cannot be handed to a second scene as an object.
            raise UserSceneError(f"{what}: instancing (shapegroup/instance) is not supported "
                                 f"in a user scene; write the instanced shapes out")
        elif node.type == T.Shape:
            _move_shape(node.props, m)
        elif node.type == T.Emitter:
            _move_emitter(node.props, m, s, what)
    if s != 1.0 or not np.allclose(m, np.eye(4)):
        for node in state.nodes:
            if node.type == T.Medium and node.props.plugin_name() in ("homogeneous",
                                                                      "heterogeneous"):
                # Densities are per unit length.
                node.props["scale"] = float(node.props["scale"]) / s if "scale" in node.props \
                    else 1.0 / s
                for _, idx in _node_ids(node.props):
                    child = state.nodes[idx]
                    if child.type == T.Volume and child.props.plugin_name() == "gridvolume":
                        _move_shape(child.props, m)
    return replaced, depth


def load_user_scene(setup: Setup, scene: str | Path | Mapping[str, Any], *,
                    unit: str | None = None, placement: Placement | None = None) -> UserScene:
    """A user's Mitsuba scene in mm in the mirror's frame (see the module docstring).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``[scene]`` gives the default ``unit`` and ``placement``.
    scene : str, Path or dict
        A Mitsuba XML file, or a scene dict (``{"type": "scene", ...}``, as
        :func:`mitsuba.load_dict` takes; instantiated objects in it are kept as they
        are, so only in a scene in mm without placement).
    unit : {"mm", "cm", "m"}, optional
        The scene's length unit (default: the setup's ``scene.unit``, else mm).
    placement : mitsweep.config.Placement, optional
        Default: the setup's ``scene.placement`` (none: the scene's origin at the
        mirror vertex, its axes the mirror frame's).

    Raises
    ------
    UserSceneError
        Not Mitsuba XML, a missing referenced file, an unknown plugin, or anything else
        Mitsuba refuses: one line naming the scene and the problem.
    """
    import mitsuba as mi

    from .sensor import register

    variant = register()
    unit = unit or setup.scene.unit or "mm"
    placement = placement if placement is not None else setup.scene.placement
    m = scene_transform(unit, placement)
    s = MM_PER_UNIT[unit]
    label, sha, folder = _source(scene)
    name = label if label == "dict" else str(scene)
    p = mi.parser
    cfg = p.ParserConfig(variant)
    cfg.merge_meshes = False  # keep the user's shapes (and their ids) apart
    try:
        with _resolver(folder):
            state = p.parse_dict(cfg, dict(scene)) if isinstance(scene, Mapping) \
                else p.parse_file(cfg, label)
            p.transform_upgrade(cfg, state)
            p.transform_resolve(cfg, state)
            replaced, depth = _prepare(state, name, m, s)
            loaded = p.instantiate(cfg, state)
    except UserSceneError:
        raise
    except Exception as exc:  # Mitsuba raises RuntimeError/ValueError/TypeError
        raise UserSceneError(_one_line(exc, name, None if folder is None else label)) from None
    if not isinstance(loaded, mi.Scene):
        raise UserSceneError(f"{name}: not a scene (its root is a {type(loaded).__name__})")
    objects: dict = {}

    def key_of(obj, fallback: str) -> str:
        k = obj.id() or fallback
        if k in RESERVED_NAMES or k in objects or k.startswith("_"):
            k = f"user_{k.lstrip('_')}"
        while k in objects:
            k += "_"
        return k

    shapes, emitters = [], []
    for k, shape in enumerate(loaded.shapes()):
        key = key_of(shape, f"shape_{k}")
        objects[key] = shape
        shapes.append(key)
    for k, emitter in enumerate(loaded.emitters()):
        if mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface):
            continue  # an area emitter: it comes with its shape
        key = key_of(emitter, f"emitter_{k}")
        objects[key] = emitter
        emitters.append(key)
    prov = {"source": label, "sha256": sha, "unit": unit, "mm_per_unit": s,
            "placement": None if placement is None else
            {"translate": list(placement.translate), "rotate_deg": list(placement.rotate_deg)},
            "replaced": replaced, "shapes": shapes, "emitters": emitters}
    logger.info("%s: %d shapes and %d emitters kept (unit %s)", name, len(shapes),
                len(emitters), unit)
    media = any(n.type == mi.ObjectType.Medium for n in state.nodes)
    return UserScene(objects, prov, depth, media)


def user_scene(setup: Setup, scene: str | Path | Mapping[str, Any], *,
               unit: str | None = None, placement: Placement | None = None) -> dict:
    """The objects of a user's scene to add to a scene dict (mm, mirror frame).

    ``load_user_scene(...).objects``: a dict of name to instantiated Mitsuba object
    (shapes, emitters) for :func:`mitsuba.load_dict`, beside the mirror
    (:func:`mitsweep.render.mirror.mirror_shape`) and a camera
    (:func:`mitsweep.render.api.camera_dict`).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``[scene]`` gives the default ``unit`` and ``placement``.
    scene : str, Path or dict
        A Mitsuba XML file, or a scene dict (as :func:`mitsuba.load_dict` takes).
    unit : {"mm", "cm", "m"}, optional
        The scene's length unit (default: the setup's ``scene.unit``, else mm).
    placement : mitsweep.config.Placement, optional
        Where the scene sits in the mirror's frame (default: the setup's
        ``scene.placement``).
    """
    return load_user_scene(setup, scene, unit=unit, placement=placement).objects


def check_user_scene(setup: Setup, scene: str | Path | Mapping[str, Any], *,
                     unit: str | None = None, placement: Placement | None = None) -> dict:
    """Load a user's scene as :func:`~mitsweep.render.api.render_image` does and probe
    its view of the setup's mirror, without rendering (e.g. every scene of a dataset
    before any work starts).

    :func:`load_user_scene`, then :func:`check_view` of the scene with the setup's
    mirror at the reference sensor distance
    (:func:`mitsweep.optics.reference.reference_geometry`) and the setup's lens aperture
    (the ``focused`` and ``sweep`` modes'; the others' smaller apertures see less).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``[scene]`` gives the default ``unit`` and ``placement``.
    scene : str, Path or dict
        A Mitsuba XML file, or a scene dict (as :func:`mitsuba.load_dict` takes).
    unit : {"mm", "cm", "m"}, optional
        The scene's length unit (default: the setup's ``scene.unit``, else mm).
    placement : mitsweep.config.Placement, optional
        Where the scene sits in the mirror's frame (default: the setup's
        ``scene.placement``).

    Raises
    ------
    UserSceneError
        Whatever either refuses, naming the scene. Returns :func:`check_view`'s dict.
    """
    import mitsuba as mi

    from ..optics.reference import reference_geometry
    from .mirror import mirror_shape

    user = load_user_scene(setup, scene, unit=unit, placement=placement)
    shape, _ = mirror_shape(setup)
    loaded = mi.load_dict({"type": "scene", "mirror": shape, **user.objects})
    return check_view(loaded, setup, reference_geometry(setup).sensor_distance,
                      label=user.label)


def check_view(scene: Any, setup: Setup, sensor_distance: float, *, label: str = "scene",
               aperture_radius: float | None = None) -> dict:
    """Probe a loaded scene through the mirror; raise where the render would be wrong.

    Chief rays of a grid of :data:`_PROBE_GRID`² image points that see the mirror
    (:func:`mitsweep.optics.mirror_point_from_image` at ``sensor_distance``) are cast
    from the lens centre and from four points on the aperture rim (``aperture_radius``,
    default the setup's lens) to their mirror point, then reflected into the scene.

    Parameters
    ----------
    scene : mitsuba.Scene
        The loaded scene, with the mirror in it.
    setup : mitsweep.config.Setup
        The mirror, lens and sensor.
    sensor_distance : float
        Sensor distance of the probe's image points, mm.
    label : str, optional
        How the scene is named in messages.
    aperture_radius : float, optional
        Radius of the aperture the probe's rays start from, mm (default: the setup's lens).

    Raises
    ------
    UserSceneError
        No emitter; a shape between the lens and the mirror (a segment's first hit
        is not the mirror), naming the shape and the share of segments it blocks;
        nothing in the mirror's view (no reflected ray meets a shape and there is no
        environment emitter).

    Returns
    -------
    dict
        ``probe_rays``, ``in_view_fraction`` (reflected rays that meet a shape).
    """
    import mitsuba as mi

    from ..optics import mirror_point_from_image, placement_of
    from ..optics.pixels import image_shape, pixel_to_sensor

    if not len(scene.emitters()):
        raise UserSceneError(f"{label}: no emitter (area light, point light or environment): "
                             f"the image would be black")
    mirror = [s for s in scene.shapes() if s.id() == "mirror"]
    if len(mirror) != 1:
        raise UserSceneError(f"{label}: the scene needs exactly one shape named 'mirror'")
    mirror_ptr = mi.ShapePtr(mirror[0])
    H, W = image_shape(setup)
    n = min(_PROBE_GRID, H, W)
    rows, cols = np.meshgrid(np.linspace(0, H - 1, n), np.linspace(0, W - 1, n), indexing="ij")
    u, v = pixel_to_sensor(rows.ravel(), cols.ravel(), (H, W), setup.sensor.pixel_pitch)
    ray = mirror_point_from_image(placement_of(setup.mirror), u, v, sensor_distance)
    ok = np.isfinite(ray.surface.rho)
    if not ok.any():
        raise UserSceneError(f"{label}: no pixel sees the mirror")
    pts = ray.surface.position[ok]
    out_dir = ray.world_dir[ok]
    a = setup.lens.aperture_radius if aperture_radius is None else aperture_radius
    lens = np.array([0.0, 0.0, setup.mirror.vertex_distance])
    origins = [lens] + [lens + a * np.array(o) for o in
                        ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0))] * (a > 0)
    names = {s.id() for s in scene.shapes()}
    blocked: dict[str, int] = {}
    total = 0
    for o in origins:
        d = pts - o
        dist = np.linalg.norm(d, axis=-1)
        d /= dist[:, None]
        r = mi.Ray3f(mi.Point3f(*(np.broadcast_to(o, pts.shape).T.astype(np.float32))),
                     mi.Vector3f(*d.T.astype(np.float32)))
        si = scene.ray_intersect(r)
        hit_mirror = np.array(si.shape == mirror_ptr, dtype=bool)
        t = np.array(si.t, dtype=np.float64)
        early = np.array(si.is_valid(), dtype=bool) & (~hit_mirror | (t < dist - 1e-3 * dist))
        total += len(dist)
        if early.any():
            ids = _shape_ids(scene, si, early)
            for k in ids:
                blocked[k] = blocked.get(k, 0) + 1
    if blocked:
        worst = max(blocked, key=lambda k: blocked[k])
        share = sum(blocked.values()) / total
        raise UserSceneError(f"{label}: shape {worst!r} lies between the lens and the mirror "
                             f"(it hides {100 * share:.3g} % of the probed lens-to-mirror rays); move "
                             f"the scene (scene.placement) or leave the camera's line of sight free")
    r = mi.Ray3f(mi.Point3f(*(pts + 1e-3 * out_dir).T.astype(np.float32)),
                 mi.Vector3f(*out_dir.T.astype(np.float32)))
    si = scene.ray_intersect(r)
    seen = np.array(si.is_valid(), dtype=bool) & ~np.array(si.shape == mirror_ptr, dtype=bool)
    if not seen.any() and scene.environment() is None:
        raise UserSceneError(f"{label}: nothing in the mirror's view (no reflected ray meets a "
                             f"shape of the {len(names) - 1} and there is no environment "
                             f"emitter); check scene.unit and scene.placement")
    return {"probe_rays": int(total), "in_view_fraction": float(seen.mean())}


def _shape_ids(scene, si, where) -> list[str]:
    """The ids of the shapes ``si`` hit at the lanes ``where``."""
    import mitsuba as mi

    out = []
    idx = np.flatnonzero(where)
    shapes = scene.shapes()
    ptrs = [mi.ShapePtr(s) for s in shapes]
    for s, ptr in zip(shapes, ptrs):
        hit = np.array(si.shape == ptr, dtype=bool)[idx]
        out += [s.id()] * int(hit.sum())
    return out
