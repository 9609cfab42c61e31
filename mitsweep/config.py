"""Setup dataclasses and TOML loading.

A *setup* describes one catadioptric focal-sweep camera: the mirror, the lens, the
sensor, the sweep and, optionally, the rendered scene and the rig. Every section is a
frozen, keyword-only dataclass validated in ``__post_init__``; a bad value raises
:class:`SetupError` naming the key and the allowed range. TOML files are strict:
unknown sections and keys are rejected, so that a typo never passes silently.

All lengths are millimetres, angles are degrees at this edge (``*_deg``), time is
seconds (``*_s``).

Mirror kinds (all normalised to a conic of vertex radius ``radius`` and conic constant
``conic``, plus optional even-asphere coefficients):

- ``"conic"``: ``radius``, ``conic``, ``rim_radius``, ``vertex_distance``.
- ``"sphere"``: ``radius`` and either ``center_distance`` (lens centre to the sphere's
  centre, as in the paper) or ``vertex_distance``; ``conic`` must be absent or 0.
- ``"paraboloid"``: ``focal_length`` (R = 2 f, k = -1) and ``vertex_distance``.
- ``"asphere"``: like ``"conic"`` plus ``aspheric = [a4, a6, ...]``, the coefficients of
  ρ⁴, ρ⁶, ... added to the conic sag.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any
from collections.abc import Mapping

from .resources import require_regular_file

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

__all__ = [
    "SetupError",
    "Mirror",
    "Lens",
    "Sensor",
    "Sweep",
    "Scene",
    "Placement",
    "Rig",
    "Setup",
    "load_setup",
    "setup_from_dict",
    "toml_nesting",
    "setup_to_dict",
    "setup_to_toml",
    "DEFAULT_SETUP",
]

#: Largest sensor side, pixels: a 32768² RGB float32 image alone is 12 GiB.
MAX_RESOLUTION = 32768
#: Deepest nesting of arrays and inline tables a setup file may hold (a setup needs 2).
MAX_NESTING = 8
MIRROR_KINDS = ("conic", "sphere", "paraboloid", "asphere")
MOTION_PROFILES = ("linear", "trapezoidal", "tabulated")
SCENE_LIGHTING = ("emissive", "lit")
#: Length units of a user's Mitsuba scene (:attr:`Scene.unit`).
SCENE_UNITS = ("mm", "cm", "m")


class SetupError(ValueError):
    """A setup value is missing, unknown or outside its allowed range."""


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise SetupError(f"{key}: {message}")


def _is_number(value: Any) -> bool:
    """A real number (NumPy scalars too), not a bool (``True`` is an ``int`` in Python)
    and not a string."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _number(value: Any, key: str, *, allow_inf: bool = False) -> float:
    """``value`` as a float; strings, booleans and NaN are refused, naming ``key``."""
    _require(_is_number(value), key, f"expected a number, got {value!r}")
    x = float(value)
    if allow_inf:
        _require(not math.isnan(x), key, f"must be a number (inf allowed), got {value!r}")
    else:
        _require(math.isfinite(x), key, f"must be finite, got {value!r}")
    return x


def _finite(value: Any, key: str) -> float:
    return _number(value, key)


def _integer(value: Any, key: str, lo: int, hi: int | None = None) -> int:
    """``value`` as an int in ``[lo, hi]``; floats (even 2.0), strings and booleans are refused."""
    allowed = f"an integer in [{lo}, {hi}]" if hi is not None else f"an integer >= {lo}"
    ok = isinstance(value, numbers.Integral) and not isinstance(value, bool) \
        and lo <= int(value) and (hi is None or int(value) <= hi)
    _require(ok, key, f"must be {allowed}, got {value!r}")
    return int(value)


def _choice(value: Any, key: str, choices: tuple[str, ...]) -> str:
    _require(isinstance(value, str) and value in choices, key,
             f"must be one of {', '.join(choices)}, got {value!r}")
    return value


def _assign(obj: Any, **values: Any) -> None:
    """Store normalised values on a frozen dataclass from its ``__post_init__``."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


def _positive(value: Any, key: str) -> float:
    x = _finite(value, key)
    _require(x > 0, key, f"must be > 0, got {value!r}")
    return x


@dataclass(frozen=True, kw_only=True)
class Mirror:
    """A rotationally symmetric convex mirror, placed on the camera axis.

    Parameters
    ----------
    radius : float
        Vertex radius of curvature R, mm (> 0; the mirror is convex toward the camera).
    conic : float
        Conic constant k (0 sphere, -1 paraboloid, < -1 hyperboloid, (-1, 0) prolate,
        > 0 oblate ellipsoid).
    rim_radius : float
        Radial extent of the mirror, mm. Must lie inside the conic's domain
        ``(1 + k) ρ² < R²``.
    vertex_distance : float
        Distance from the lens centre to the mirror vertex along the camera axis, mm.
    tilt_deg : float
        Rotation of the mirror about its vertex in the x–z plane, degrees, in (-90, 90).
    aspheric : tuple of float
        Even-asphere coefficients of ρ⁴, ρ⁶, ... (mm^-3, mm^-5, ...).
    kind : str
        The kind the setup was written as (kept for provenance).
    """

    radius: float
    conic: float = 0.0
    rim_radius: float
    vertex_distance: float
    tilt_deg: float = 0.0
    aspheric: tuple[float, ...] = ()
    kind: str = field(default="conic", compare=False)

    def __post_init__(self) -> None:
        _choice(self.kind, "mirror.kind", MIRROR_KINDS)
        R = _positive(self.radius, "mirror.radius")
        k = _finite(self.conic, "mirror.conic")
        rim = _positive(self.rim_radius, "mirror.rim_radius")
        vd = _positive(self.vertex_distance, "mirror.vertex_distance")
        tilt = _finite(self.tilt_deg, "mirror.tilt_deg")
        _require(-90.0 < tilt < 90.0, "mirror.tilt_deg", f"must be in (-90, 90), got {tilt}")
        _require(isinstance(self.aspheric, (tuple, list)), "mirror.aspheric",
                 f"must be a list of numbers [a4, a6, ...], got {self.aspheric!r}")
        coeffs = tuple(_finite(a, f"mirror.aspheric[{i}]") for i, a in enumerate(self.aspheric))
        if 1.0 + k > 0:
            rho_lim = R / math.sqrt(1.0 + k)
            _require(rim <= rho_lim, "mirror.rim_radius",
                     f"must be <= {rho_lim:.6g} mm, where a conic of radius {R:g} and "
                     f"conic constant {k:g} ends (got {rim:g})")
        _assign(self, radius=R, conic=k, rim_radius=rim, vertex_distance=vd, tilt_deg=tilt,
                aspheric=coeffs)

    @property
    def tilt(self) -> float:
        """Tilt in radians."""
        return math.radians(self.tilt_deg)

    @property
    def is_sphere(self) -> bool:
        return self.conic == 0.0 and not any(self.aspheric)

    @property
    def is_symmetric(self) -> bool:
        """True when the camera axis is the mirror's axis of rotation."""
        return self.tilt_deg == 0.0


@dataclass(frozen=True, kw_only=True)
class Lens:
    """Thin lens: ``focal_length`` (mm, > 0) and ``f_number`` (> 0)."""

    focal_length: float = 50.0
    f_number: float = 2.8

    def __post_init__(self) -> None:
        _assign(self, focal_length=_positive(self.focal_length, "lens.focal_length"),
                f_number=_positive(self.f_number, "lens.f_number"))

    @property
    def aperture_radius(self) -> float:
        """Entrance-pupil radius, mm: f / (2 N)."""
        return self.focal_length / (2.0 * self.f_number)


@dataclass(frozen=True, kw_only=True)
class Sensor:
    """Image sensor: ``resolution = [width, height]`` in pixels (each at most
    :data:`MAX_RESOLUTION`), ``pixel_pitch`` in mm.

    ``center_offset_px = [drow, dcol]`` (optional, pixels) is where the mirror's axis
    meets the image relative to the image centre, as ``mitsweep calibrate`` measures it
    on a photograph: the axis is at pixel ``(H/2 - 1/2 + drow, W/2 - 1/2 + dcol)`` (see
    :mod:`mitsweep.optics.pixels`). Absent (None) means the image centre; each part must
    lie within the image's height (rows) and width (columns) of it.
    """

    resolution: tuple[int, int] = (512, 512)
    pixel_pitch: float = 0.018
    center_offset_px: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        res = self.resolution
        _require(isinstance(res, (tuple, list)) and len(res) == 2, "sensor.resolution",
                 f"must be [width, height], got {res!r}")
        w, h = (_integer(v, f"sensor.resolution {name}", 1, MAX_RESOLUTION)
                for name, v in zip(("width", "height"), res))
        _assign(self, resolution=(w, h),
                pixel_pitch=_positive(self.pixel_pitch, "sensor.pixel_pitch"))
        off = self.center_offset_px
        if off is not None:
            _require(isinstance(off, (tuple, list)) and len(off) == 2, "sensor.center_offset_px",
                     f"must be [drow, dcol] in pixels, got {off!r}")
            drow, dcol = (_finite(v, f"sensor.center_offset_px {name}")
                          for name, v in zip(("drow", "dcol"), off))
            for name, value, limit in (("drow", drow, h), ("dcol", dcol, w)):
                _require(abs(value) <= limit, f"sensor.center_offset_px {name}",
                         f"must be in [-{limit}, {limit}] px (within the image's "
                         f"{'height' if name == 'drow' else 'width'} of its centre), "
                         f"got {value:g}")
            _assign(self, center_offset_px=(drow, dcol))

    @property
    def width(self) -> int:
        return self.resolution[0]

    @property
    def height(self) -> int:
        return self.resolution[1]

    @property
    def size_mm(self) -> tuple[float, float]:
        return (self.width * self.pixel_pitch, self.height * self.pixel_pitch)

    def at_resolution(self, width: int, height: int) -> Sensor:
        """This sensor's frame sampled at ``width`` × ``height`` pixels.

        The pitch is scaled by ``s = max(W / width, H / height)`` (``W``, ``H`` this
        sensor's resolution), so the new frame covers at least this frame's area in both
        directions: whatever this frame shows (the mirror's whole image, for the bundled
        setups) stays in frame, only sampled more coarsely (``s`` > 1) or finely. A
        ``center_offset_px`` keeps its place in mm (its pixels divided by ``s``).

        Parameters
        ----------
        width, height : int
            The new resolution, pixels, each in [1, :data:`MAX_RESOLUTION`].

        Returns
        -------
        Sensor
            With ``resolution = (width, height)`` and ``pixel_pitch`` × ``s``.

        Raises
        ------
        SetupError
            For a resolution outside that range (naming ``sensor.resolution``).
        """
        w, h = (_integer(v, f"sensor.resolution {name}", 1, MAX_RESOLUTION)
                for name, v in zip(("width", "height"), (width, height)))
        scale = max(self.width / w, self.height / h)
        off = self.center_offset_px
        return dataclasses.replace(
            self, resolution=(w, h), pixel_pitch=self.pixel_pitch * scale,
            center_offset_px=None if off is None else (off[0] / scale, off[1] / scale))


@dataclass(frozen=True, kw_only=True)
class Sweep:
    """The wanted field of view and depth range, and the stage motion.

    ``focus_min``/``focus_max`` (mm, optional, both or neither) override the optimal
    sweep range computed from ``fov_deg`` and the depth range (paper Eq. 8–9), e.g. to
    reproduce Table 1's longer sweeps. ``velocity`` is the stage velocity in mm/s.

    The fields of the setup dataclasses are the TOML keys, one for one (the loader, the
    strict key check, :func:`setup_to_dict` and the banks' optics fingerprints all use
    them), so ``velocity`` keeps its documented key rather than the ``velocity_mm_s`` of
    computed quantities such as :attr:`mitsweep.optics.SweepRange.velocity_mm_s`.
    """

    fov_deg: float
    depth_min: float = 300.0
    depth_max: float = 10000.0
    velocity: float = 1.0
    profile: str = "linear"
    focus_min: float | None = None
    focus_max: float | None = None

    def __post_init__(self) -> None:
        fov = _finite(self.fov_deg, "sweep.fov_deg")
        _require(0.0 < fov < 360.0, "sweep.fov_deg", f"must be in (0, 360), got {fov}")
        dmin = _positive(self.depth_min, "sweep.depth_min")
        dmax = _number(self.depth_max, "sweep.depth_max", allow_inf=True)
        _require(dmax > 0, "sweep.depth_max", f"must be > 0 (inf allowed), got {self.depth_max!r}")
        _require(dmin <= dmax, "sweep.depth_min",
                 f"must be <= sweep.depth_max ({dmax:g}), got {dmin:g}")
        vel = _positive(self.velocity, "sweep.velocity")
        _choice(self.profile, "sweep.profile", MOTION_PROFILES)
        _require((self.focus_min is None) == (self.focus_max is None), "sweep.focus_min",
                 "give both focus_min and focus_max, or neither")
        if self.focus_min is not None:
            fmin = _positive(self.focus_min, "sweep.focus_min")
            fmax = _positive(self.focus_max, "sweep.focus_max")
            _require(fmin < fmax, "sweep.focus_min",
                     f"must be < sweep.focus_max ({fmax:g}), got {fmin:g}")
            _assign(self, focus_min=fmin, focus_max=fmax)
        _assign(self, fov_deg=fov, depth_min=dmin, depth_max=dmax, velocity=vel)

    @property
    def fov(self) -> float:
        return math.radians(self.fov_deg)


@dataclass(frozen=True, kw_only=True)
class Placement:
    """Where a user's scene sits in the mirror's frame (after its conversion to mm).

    ``rotate_deg = [rx, ry, rz]``: rotations about the frame's x, y, then z axes
    (degrees); then ``translate = [x, y, z]`` (mm).
    """

    translate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotate_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("translate", "rotate_deg"):
            v = getattr(self, name)
            _require(isinstance(v, (tuple, list)) and len(v) == 3, f"scene.placement.{name}",
                     f"must be [x, y, z], got {v!r}")
            _assign(self, **{name: tuple(_finite(x, f"scene.placement.{name}") for x in v)})


@dataclass(frozen=True, kw_only=True)
class Scene:
    """Synthetic surroundings for rendering (owned by ``mitsweep.render``).

    ``room_size = [x, y, z]`` mm: an axis-aligned room around the mirror whose walls,
    floor and ceiling lie between ~10 cm and 3 m from it; ``objects`` adds textured
    boards at those depths; ``texture_seed`` picks the texture layout.
    ``lighting``: ``"emissive"`` (textured self-luminous surfaces, one bounce off the
    mirror suffices, noise only from the lens) or ``"lit"`` (diffuse textured surfaces
    under a ceiling light, two bounces). ``mesh_sag_tol`` (mm) and
    ``mesh_normal_tol`` (rad) bound the mirror tessellation where a mesh is needed.

    A user's own Mitsuba scene replaces the room (:mod:`mitsweep.render.user_scene`):
    ``file`` is its XML file (relative to the setup file's folder when loaded from
    TOML), ``unit`` its length unit (``"mm"``, ``"cm"`` or ``"m"``; default mm) and
    ``placement = {translate = [x, y, z], rotate_deg = [rx, ry, rz]}`` where it sits in
    the mirror's frame: after the conversion to mm, rotated by ``rx``, ``ry`` then ``rz``
    degrees about the frame's x, y and z axes, then translated by ``translate`` mm.
    """

    room_size: tuple[float, float, float] = (4000.0, 4000.0, 2500.0)
    objects: int = 6
    texture_seed: int = 0
    max_depth: int = 0  # integrator depth; 0 = chosen from the scene
    lighting: str = "emissive"
    mesh_sag_tol: float = 1e-4
    mesh_normal_tol: float = 1e-4
    file: str | None = None
    unit: str | None = None
    placement: Placement | None = None

    def __post_init__(self) -> None:
        if self.file is not None:
            _require(isinstance(self.file, (str, Path)) and str(self.file) != "", "scene.file",
                     f"must be a path to a Mitsuba XML file, got {self.file!r}")
            _assign(self, file=str(self.file))
        if self.unit is not None:
            _choice(self.unit, "scene.unit", SCENE_UNITS)
        if self.placement is not None and not isinstance(self.placement, Placement):
            _require(isinstance(self.placement, Mapping), "scene.placement",
                     f"must be a table {{translate = [x, y, z], rotate_deg = [rx, ry, rz]}}, "
                     f"got {self.placement!r}")
            _reject_unknown(self.placement, {"translate", "rotate_deg"}, "scene.placement")
            _assign(self, placement=Placement(**self.placement))
        rs = self.room_size
        _require(isinstance(rs, (tuple, list)) and len(rs) == 3, "scene.room_size",
                 f"must be [x, y, z] in mm, got {rs!r}")
        _assign(self, room_size=tuple(_positive(v, "scene.room_size") for v in rs),
                objects=_integer(self.objects, "scene.objects", 0, 64),
                texture_seed=_integer(self.texture_seed, "scene.texture_seed", 0),
                max_depth=_integer(self.max_depth, "scene.max_depth", 0, 64))
        _choice(self.lighting, "scene.lighting", SCENE_LIGHTING)
        _assign(self, **{name: _positive(getattr(self, name), f"scene.{name}")
                         for name in ("mesh_sag_tol", "mesh_normal_tol")})


@dataclass(frozen=True, kw_only=True)
class Rig:
    """The capture rig (owned by ``mitsweep.rig``): stage limits, motion and camera.

    ``travel`` is the stage's usable travel (mm), ``max_velocity`` (mm/s) and
    ``acceleration`` (mm/s²) its limits; ``settle_distance`` (mm) is run at constant
    velocity after the ramp before the shutter opens (and before the ramp down after
    it closes). ``min_exposure_s``/``max_exposure_s`` bound the camera's bulb exposure.

    ``steps_per_mm`` converts stage millimetres to the controller's (micro)steps (the
    Arduino's stepper, or a Zaber stage's microsteps). ``soft_limit_min`` /
    ``soft_limit_max`` (mm, stage coordinates, default 0 .. ``travel``) bound every
    commanded position. ``sensor_distance_at_zero`` (mm) is the lens-to-sensor distance
    when the stage is at position 0, and ``sensor_direction`` (+1 or -1) the sign of
    d(sensor distance)/d(stage position); when ``sensor_distance_at_zero`` is absent
    (an uncalibrated rig) the sweep is centred within the soft limits. ``baudrate`` and
    ``reply_timeout_s`` (deadline on every reply) set the serial links.
    ``watchdog_s`` (0 < x <= 60) is how long the firmware waits without host traffic
    during a motion before it stops the stage.
    """

    travel: float = 25.0
    max_velocity: float = 5.0
    acceleration: float = 10.0
    settle_distance: float = 0.05
    min_exposure_s: float = 1.0 / 4000.0
    max_exposure_s: float = 30.0
    steps_per_mm: float = 400.0
    soft_limit_min: float = 0.0
    soft_limit_max: float | None = None
    sensor_distance_at_zero: float | None = None
    sensor_direction: int = 1
    baudrate: int = 115200
    reply_timeout_s: float = 1.0
    watchdog_s: float = 1.0

    def __post_init__(self) -> None:
        _assign(self, **{name: _positive(getattr(self, name), f"rig.{name}")
                         for name in ("travel", "max_velocity", "acceleration", "min_exposure_s",
                                      "max_exposure_s", "steps_per_mm", "reply_timeout_s",
                                      "watchdog_s")})
        _require(self.watchdog_s <= 60.0, "rig.watchdog_s",
                 f"must be in (0, 60] s, got {self.watchdog_s:g}")
        sd = _finite(self.settle_distance, "rig.settle_distance")
        _require(sd >= 0, "rig.settle_distance", f"must be >= 0, got {sd}")
        _assign(self, settle_distance=sd)
        _require(self.min_exposure_s < self.max_exposure_s, "rig.min_exposure_s",
                 "must be < rig.max_exposure_s")
        lo = _finite(self.soft_limit_min, "rig.soft_limit_min")
        hi = self.travel if self.soft_limit_max is None else _finite(self.soft_limit_max,
                                                                     "rig.soft_limit_max")
        _require(0.0 <= lo, "rig.soft_limit_min", f"must be >= 0 mm, got {lo:g}")
        _require(hi <= self.travel, "rig.soft_limit_max",
                 f"must be <= rig.travel ({self.travel:g} mm), got {hi:g}")
        _require(lo < hi, "rig.soft_limit_min",
                 f"must be < rig.soft_limit_max ({hi:g} mm), got {lo:g}")
        _assign(self, soft_limit_min=lo, soft_limit_max=hi)
        if self.sensor_distance_at_zero is not None:
            _assign(self, sensor_distance_at_zero=_positive(self.sensor_distance_at_zero,
                                                            "rig.sensor_distance_at_zero"))
        direction = self.sensor_direction
        _require(isinstance(direction, numbers.Integral) and not isinstance(direction, bool)
                 and direction in (1, -1), "rig.sensor_direction",
                 f"must be 1 or -1, got {direction!r}")
        _assign(self, sensor_direction=int(direction),
                baudrate=_integer(self.baudrate, "rig.baudrate", 300, 4_000_000))


@dataclass(frozen=True, kw_only=True)
class Setup:
    """One catadioptric focal-sweep camera and, optionally, its scene and rig."""

    mirror: Mirror
    lens: Lens = field(default_factory=Lens)
    sensor: Sensor = field(default_factory=Sensor)
    sweep: Sweep
    scene: Scene = field(default_factory=Scene)
    rig: Rig = field(default_factory=Rig)
    name: str = "setup"

    def __post_init__(self) -> None:
        _require(self.mirror.vertex_distance > self.lens.focal_length, "mirror.vertex_distance",
                 f"must be > lens.focal_length ({self.lens.focal_length:g} mm) so the "
                 f"camera can focus on the mirror, got {self.mirror.vertex_distance:g}")
        if self.sweep.focus_min is not None:
            _require(self.sweep.focus_min > self.lens.focal_length, "sweep.focus_min",
                     f"must be > lens.focal_length ({self.lens.focal_length:g} mm), "
                     f"got {self.sweep.focus_min:g}")


_SECTIONS: dict[str, type] = {
    "mirror": Mirror, "lens": Lens, "sensor": Sensor, "sweep": Sweep,
    "scene": Scene, "rig": Rig,
}


def _mirror_from_table(table: Mapping[str, Any]) -> Mirror:
    t = dict(table)
    kind = t.pop("kind", "conic")
    if kind == "sphere":
        allowed = {"radius", "center_distance", "vertex_distance", "rim_radius", "tilt_deg", "conic"}
        _reject_unknown(t, allowed, "mirror")
        _require("radius" in t, "mirror.radius", "missing (required for kind = 'sphere')")
        R = _positive(t["radius"], "mirror.radius")
        _require(_finite(t.get("conic", 0.0), "mirror.conic") == 0.0, "mirror.conic",
                 "must be 0 for kind = 'sphere' (use kind = 'conic')")
        has_c, has_v = "center_distance" in t, "vertex_distance" in t
        _require(has_c != has_v, "mirror.center_distance",
                 "give exactly one of center_distance and vertex_distance for a sphere")
        vd = (_positive(t["center_distance"], "mirror.center_distance") - R) if has_c \
            else t["vertex_distance"]
        return Mirror(kind=kind, radius=R, conic=0.0, rim_radius=t.get("rim_radius", R),
                      vertex_distance=vd, tilt_deg=t.get("tilt_deg", 0.0))
    if kind == "paraboloid":
        allowed = {"focal_length", "radius", "rim_radius", "vertex_distance", "tilt_deg", "conic"}
        _reject_unknown(t, allowed, "mirror")
        _require(("focal_length" in t) != ("radius" in t), "mirror.focal_length",
                 "give exactly one of focal_length and radius (= 2 focal_length) for a paraboloid")
        R = 2.0 * _positive(t["focal_length"], "mirror.focal_length") if "focal_length" in t \
            else t["radius"]
        _require(_finite(t.get("conic", -1.0), "mirror.conic") == -1.0, "mirror.conic",
                 "must be -1 for kind = 'paraboloid' (use kind = 'conic')")
        for key in ("rim_radius", "vertex_distance"):
            _require(key in t, f"mirror.{key}", "missing (required)")
        return Mirror(kind=kind, radius=R, conic=-1.0, rim_radius=t["rim_radius"],
                      vertex_distance=t["vertex_distance"], tilt_deg=t.get("tilt_deg", 0.0))
    if kind in ("conic", "asphere"):
        allowed = {"radius", "conic", "rim_radius", "vertex_distance", "tilt_deg"}
        if kind == "asphere":
            allowed.add("aspheric")
        _reject_unknown(t, allowed, "mirror")
        for key in ("radius", "rim_radius", "vertex_distance"):
            _require(key in t, f"mirror.{key}", "missing (required)")
        return Mirror(kind=kind, radius=t["radius"], conic=t.get("conic", 0.0),
                      rim_radius=t["rim_radius"], vertex_distance=t["vertex_distance"],
                      tilt_deg=t.get("tilt_deg", 0.0), aspheric=t.get("aspheric", ()))
    raise SetupError(f"mirror.kind: must be one of {', '.join(MIRROR_KINDS)}, got {kind!r}")


def _reject_unknown(table: Mapping[str, Any], allowed: set[str], section: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise SetupError(f"{section}.{unknown[0]}: unknown key; allowed keys: "
                         f"{', '.join(sorted(allowed))}")


def _section_from_table(cls: type, table: Mapping[str, Any], section: str) -> Any:
    if not isinstance(table, Mapping):
        raise SetupError(f"{section}: must be a table, got {table!r}")
    names = {f.name for f in fields(cls)}
    _reject_unknown(table, names, section)
    required = {f.name for f in fields(cls)
                if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING}
    missing = sorted(required - set(table))
    if missing:
        raise SetupError(f"{section}.{missing[0]}: missing (required)")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in table.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:  # wrong type reaching a comparison
        raise SetupError(f"{section}: {exc}") from None


def setup_from_dict(data: Mapping[str, Any], *, name: str = "setup") -> Setup:
    """Build a validated :class:`Setup` from a TOML-like nested mapping."""
    if not isinstance(data, Mapping):
        raise SetupError(f"setup: must be a table, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_SECTIONS) - {"name"})
    if unknown:
        raise SetupError(f"[{unknown[0]}]: unknown section; allowed sections: "
                         f"{', '.join(_SECTIONS)} (and a top-level name)")
    _require("mirror" in data, "mirror", "missing section [mirror]")
    _require("sweep" in data, "sweep", "missing section [sweep]")
    setup_name = data.get("name", name)
    _require(isinstance(setup_name, str), "name", f"must be a string, got {setup_name!r}")
    kwargs: dict[str, Any] = {"name": setup_name}
    mirror_table = data["mirror"]
    _require(isinstance(mirror_table, Mapping), "mirror", "must be a table")
    kwargs["mirror"] = _mirror_from_table(mirror_table)
    for section, cls in _SECTIONS.items():
        if section != "mirror" and section in data:
            kwargs[section] = _section_from_table(cls, data[section], section)
    return Setup(**kwargs)


def load_setup(path: str | Path) -> Setup:
    """Load and validate a setup TOML file.

    Raises
    ------
    SetupError
        If the file is missing, is not TOML, or holds an unknown, missing or
        out-of-range key. The message names the key and the allowed values.
    """
    p = require_regular_file(path, "setup file")
    try:
        text = p.read_bytes()
    except FileNotFoundError as exc:
        raise SetupError(f"{p}: no such setup file ({exc.strerror})") from None
    except OSError as exc:
        raise SetupError(f"{p}: cannot read ({exc.strerror})") from None
    try:
        source = text.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SetupError(f"{p}: not a valid TOML file ({exc})") from None
    depth, line = toml_nesting(source)
    if depth > MAX_NESTING:
        raise SetupError(f"{p}: line {line}: arrays or inline tables nested deeper than "
                         f"{MAX_NESTING} levels; a setup file needs at most 2")
    try:
        data = tomllib.loads(source)
    except tomllib.TOMLDecodeError as exc:
        raise SetupError(f"{p}: not a valid TOML file ({exc})") from None
    except RecursionError:  # the scan above should have caught it; tomllib recurses
        raise SetupError(f"{p}: arrays or inline tables nested deeper than {MAX_NESTING} "
                         f"levels") from None
    setup = setup_from_dict(data, name=p.stem)
    file = setup.scene.file
    if file is not None and not Path(file).is_absolute():
        # A setup's scene file is found beside the setup, wherever it is run from.
        scene = dataclasses.replace(setup.scene, file=str(p.parent / file))
        setup = dataclasses.replace(setup, scene=scene)
    return setup


def toml_nesting(source: str) -> tuple[int, int]:
    """Deepest nesting of ``[`` / ``{`` outside strings and comments, and its line.

    A linear scan that runs before :mod:`tomllib`, which parses nested arrays by
    recursion (a 5000-deep array is a RecursionError). It knows TOML's four string
    forms and comments well enough to skip them; table headers count as one or two
    levels. A malformed file gets whatever depth the scan sees: tomllib reports it.
    """
    depth = deepest = 0
    line = deepest_line = 1
    i, n = 0, len(source)
    while i < n:
        c = source[i]
        if c == "\n":
            line += 1
        elif c == "#":
            j = source.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'":
            triple = source.startswith(c * 3, i)
            close = c * 3 if triple else c
            j = i + len(close)
            while j < n:
                if c == '"' and source[j] == "\\":
                    j += 2
                    continue
                if source.startswith(close, j) or (not triple and source[j] == "\n"):
                    break
                j += 1
            end = j + len(close)
            while triple and end < n and source[end] == c:   # """a"""" ends in a quote
                end += 1
            line += source.count("\n", i, min(end, n))
            i = end
            continue
        elif c in "[{":
            depth += 1
            if depth > deepest:
                deepest, deepest_line = depth, line
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return deepest, deepest_line


def setup_to_dict(setup: Setup) -> dict[str, Any]:
    """The setup as a plain, JSON/TOML-serialisable nested dict (normalised to a conic)."""
    out: dict[str, Any] = {"name": setup.name}
    for section in _SECTIONS:
        value = dataclasses.asdict(getattr(setup, section))
        if section == "mirror":
            value["kind"] = "asphere" if any(value["aspheric"]) else "conic"
            if value["kind"] == "conic":
                del value["aspheric"]
        out[section] = {k: (list(v) if isinstance(v, tuple) else v)
                        for k, v in value.items() if v is not None}
    return out


def setup_to_toml(setup: Setup, *, header: str = "") -> str:
    """The setup as TOML text that :func:`load_setup` reads back to an equal setup.

    Written by ``tomli-w`` (the writer paired with the ``tomllib`` reader; infinite
    depths come out as TOML's ``inf``).

    Parameters
    ----------
    setup : Setup
        The setup to write.
    header : str, optional
        Written first as ``#`` comment lines, e.g. provenance.

    Returns
    -------
    str
        TOML text, ending in a newline.
    """
    import tomli_w

    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    body = tomli_w.dumps(setup_to_dict(setup))
    return "\n".join(lines) + ("\n" if lines else "") + body


#: The embedded default: the paper's spherical mirror (Sec. 3.1 and 5.2).
DEFAULT_SETUP = Setup(
    name="sphere",
    mirror=Mirror(kind="sphere", radius=25.0, conic=0.0, rim_radius=25.0, vertex_distance=327.0),
    lens=Lens(focal_length=50.0, f_number=2.8),
    sweep=Sweep(fov_deg=237.0, depth_min=300.0, depth_max=10000.0, velocity=1.0),
)

