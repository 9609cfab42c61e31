"""Setup dataclasses and TOML loading.

A *setup* describes one catadioptric focal-sweep camera: the mirror, the lens, the
sensor, the sweep and, optionally, the rendered scene and the rig. Every section is a
frozen, keyword-only dataclass validated in ``__post_init__``; a bad value raises
:class:`SetupError` naming the key and the allowed range. TOML files are strict:
unknown sections and keys are rejected, so that a typo never passes silently.

Each key's constraint is declared once, in its field's metadata (:func:`setting`: the
check, the unit and a line of meaning); the same declaration validates the value, words
its error message and writes the table of setup keys in ``docs/reference/setups.md``
(:func:`setup_keys_table`). Constraints between keys (``depth_min <= depth_max``, the
rim inside the conic, ...) are checked in ``__post_init__`` after the fields.

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

A setup read from a table (:func:`setup_from_dict`, :func:`load_setup`) must also ask
for a field of view the mirror can reflect into the lens (:attr:`Mirror.max_fov_deg`).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any, ClassVar, TypeAlias

import numpy as np

from .deprecation import renamed_fields
from .resources import require_regular_file

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]  # the same module, by its 3.10 name

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
    "setup_keys_table",
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


# --- The constraints a key may declare ------------------------------------------------
#
# Each check is called as ``check(value, key, unit)`` and returns the value normalised
# (a float, an int, a tuple) or raises SetupError naming ``key``; ``allowed`` words the
# constraint for the docs table, and the error message says the same words.


def _in_unit(unit: str) -> str:
    return f" {unit}" if unit else ""


@dataclass(frozen=True)
class Number:
    """A real number (NumPy scalars too), not a bool (``True`` is an ``int`` in Python)
    nor a string; finite unless ``inf`` allows ±infinity (NaN is always refused).

    Parameters
    ----------
    inf : bool, optional
        Also accept ±infinity (default False).
    """

    inf: bool = False

    @property
    def allowed(self) -> str:
        return "a number (inf allowed)" if self.inf else "a number"

    def __call__(self, value: Any, key: str, unit: str = "") -> float:
        _require(isinstance(value, numbers.Real) and not isinstance(value, bool), key,
                 f"expected a number, got {value!r}")
        x = float(value)
        if self.inf:
            _require(not math.isnan(x), key, f"must be a number (inf allowed), got {value!r}")
        else:
            _require(math.isfinite(x), key, f"must be finite, got {value!r}")
        return x


@dataclass(frozen=True)
class Positive(Number):
    """A number > 0 and, when ``most`` is given, at most ``most``. A value <= 0 is
    refused as not positive; one above ``most`` naming the whole range ``(0, most]``.

    Parameters
    ----------
    inf : bool, optional
        Also accept +infinity (default False).
    most : float or None, optional
        The largest value allowed, in the key's unit (default None: no upper bound).
    """

    most: float | None = None

    @property
    def allowed(self) -> str:
        if self.most is not None:
            return f"in (0, {self.most:g}]"
        return "> 0, inf allowed" if self.inf else "> 0"

    def __call__(self, value: Any, key: str, unit: str = "") -> float:
        x = Number.__call__(self, value, key, unit)
        _require(x > 0, key, f"must be > 0{_in_unit(unit)}{' (inf allowed)' if self.inf else ''}, "
                             f"got {value!r}")
        if self.most is not None:
            _require(x <= self.most, key, f"must be {self.allowed}{_in_unit(unit)}, got {value!r}")
        return x


@dataclass(frozen=True)
class AtLeast:
    """A finite number >= ``least``.

    Parameters
    ----------
    least : float, optional
        The smallest value allowed, in the key's unit (default 0).
    """

    least: float = 0.0

    @property
    def allowed(self) -> str:
        return f">= {self.least:g}"

    def __call__(self, value: Any, key: str, unit: str = "") -> float:
        x = Number()(value, key, unit)
        _require(x >= self.least, key, f"must be {self.allowed}{_in_unit(unit)}, got {value!r}")
        return x


@dataclass(frozen=True)
class Between:
    """A finite number in the open interval ``(low, high)``.

    Parameters
    ----------
    low, high : float
        The interval's ends, excluded, in the key's unit.
    """

    low: float
    high: float

    @property
    def allowed(self) -> str:
        return f"in ({self.low:g}, {self.high:g})"

    def __call__(self, value: Any, key: str, unit: str = "") -> float:
        x = Number()(value, key, unit)
        _require(self.low < x < self.high, key,
                 f"must be {self.allowed}{_in_unit(unit)}, got {value!r}")
        return x


@dataclass(frozen=True)
class Integer:
    """An integer in ``[least, most]``; floats (even 2.0), strings and booleans are
    refused.

    Parameters
    ----------
    least : int, optional
        The smallest value allowed (default 0).
    most : int or None, optional
        The largest value allowed (default None: unbounded).
    """

    least: int = 0
    most: int | None = None

    @property
    def allowed(self) -> str:
        if self.most is None:
            return f"an integer >= {self.least}"
        return f"an integer in [{self.least}, {self.most}]"

    def __call__(self, value: Any, key: str, unit: str = "") -> int:
        ok = (isinstance(value, numbers.Integral) and not isinstance(value, bool)
              and self.least <= int(value) and (self.most is None or int(value) <= self.most))
        _require(ok, key, f"must be {self.allowed}{_in_unit(unit)}, got {value!r}")
        return int(value)


@dataclass(frozen=True)
class OneOf:
    """One of ``choices``: strings, or integers (then not a bool nor a float).

    Parameters
    ----------
    choices : tuple of str or tuple of int
        The values allowed, all of one type.
    """

    choices: tuple[Any, ...]

    @property
    def allowed(self) -> str:
        if all(isinstance(c, str) for c in self.choices):
            return f"one of {', '.join(self.choices)}"
        return " or ".join(str(c) for c in self.choices)

    def __call__(self, value: Any, key: str, unit: str = "") -> Any:
        words = isinstance(self.choices[0], str)
        same_type = (isinstance(value, str) if words
                     else isinstance(value, numbers.Integral) and not isinstance(value, bool))
        _require(same_type and value in self.choices, key,
                 f"must be {self.allowed}, got {value!r}")
        return value if words else int(value)


@dataclass(frozen=True)
class Vector:
    """A list of a fixed length, each item checked by ``item``; kept as a tuple.

    Parameters
    ----------
    item : Check
        The check of each item, in the key's unit.
    shape : str
        The list as the message words it, e.g. ``"[x, y, z]"``; its length is the count
        of its items.
    names : tuple of str, optional
        Item names: an item's errors are keyed ``"<key> <name>"`` (default: ``<key>``).
    """

    item: Check
    shape: str
    names: tuple[str, ...] = ()

    @property
    def length(self) -> int:
        return self.shape.count(",") + 1

    @property
    def allowed(self) -> str:
        return f"{self.shape}, each {self.item.allowed}"

    def __call__(self, value: Any, key: str, unit: str = "") -> tuple[Any, ...]:
        _require(isinstance(value, (tuple, list)) and len(value) == self.length, key,
                 f"must be {self.shape}{' in ' + unit if unit else ''}, got {value!r}")
        names = self.names or ("",) * self.length
        return tuple(self.item(v, f"{key} {name}" if name else key, unit)
                     for name, v in zip(names, value))


@dataclass(frozen=True)
class Numbers:
    """A list of any length of finite numbers, item ``i`` keyed ``"<key>[i]"``.

    Parameters
    ----------
    shape : str
        The list as the message words it, e.g. ``"[a4, a6, ...]"``.
    """

    shape: str

    @property
    def allowed(self) -> str:
        return f"a list of numbers {self.shape}"

    def __call__(self, value: Any, key: str, unit: str = "") -> tuple[float, ...]:
        _require(isinstance(value, (tuple, list)), key,
                 f"must be a list of numbers {self.shape}, got {value!r}")
        return tuple(Number()(a, f"{key}[{i}]") for i, a in enumerate(value))


@dataclass(frozen=True)
class FilePath:
    """A non-empty path (a string or a :class:`~pathlib.Path`), kept as a string.

    Parameters
    ----------
    what : str
        What the file is, for the message (``"a Mitsuba XML file"``).
    """

    what: str

    @property
    def allowed(self) -> str:
        return f"a path to {self.what}"

    def __call__(self, value: Any, key: str, unit: str = "") -> str:
        _require(isinstance(value, (str, Path)) and str(value) != "", key,
                 f"must be a path to {self.what}, got {value!r}")
        return str(value)


@dataclass(frozen=True)
class Table:
    """An inline table whose keys are the fields of the dataclass ``cls`` (an instance
    of it passes as it is).

    Parameters
    ----------
    cls : type
        A setup dataclass (e.g. :class:`Placement`) built from the table.
    shape : str
        The table as the message words it.
    """

    cls: type
    shape: str

    @property
    def allowed(self) -> str:
        return f"a table {self.shape}"

    def __call__(self, value: Any, key: str, unit: str = "") -> Any:
        if isinstance(value, self.cls):
            return value
        _require(isinstance(value, Mapping), key,
                 f"must be a table {self.shape}, got {value!r}")
        _reject_unknown(value, {f.name for f in fields(self.cls)}, key)
        return self.cls(**value)


@dataclass(frozen=True)
class OrNone:
    """``None`` (the key absent), or a value that passes ``check``.

    Parameters
    ----------
    check : Check
        The check of a value that is given.
    """

    check: Check

    @property
    def allowed(self) -> str:
        return self.check.allowed

    def __call__(self, value: Any, key: str, unit: str = "") -> Any:
        return None if value is None else self.check(value, key, unit)


#: A key's constraint: any of the checks above.
Check: TypeAlias = (Number | AtLeast | Between | Integer | OneOf | Vector | Numbers | FilePath
                    | Table | OrNone)


def setting(check: Check, meaning: str, *, unit: str = "",
            also: str = "") -> MappingProxyType[str, Any]:
    """The field metadata of one setup key: its constraint, declared once.

    Parameters
    ----------
    check : Check
        Validates and normalises the value (called with the value, the key and the unit):
        :class:`Number`, :class:`Positive`, :class:`AtLeast`, :class:`Between`,
        :class:`Integer`, :class:`OneOf`, :class:`Vector`, :class:`Numbers`,
        :class:`FilePath`, :class:`Table` or :class:`OrNone`.
    meaning : str
        What the key is, one line for the docs table.
    unit : str, optional
        The value's unit (``"mm"``, ``"deg"``, ``"s"``, ``"px"``, ...); empty when it has
        none. Error messages and the docs table say it.
    also : str, optional
        A constraint involving other keys, checked in ``__post_init__``, in words for the
        docs table (e.g. ``"<= sweep.depth_max"``).

    Returns
    -------
    types.MappingProxyType
        Read-only, for ``dataclasses.field(metadata=...)``: keys ``check``, ``meaning``,
        ``unit`` and ``also``.
    """
    return MappingProxyType({"check": check, "meaning": meaning, "unit": unit, "also": also})


def _check_fields(obj: Any) -> None:
    """Validate and normalise every declared field of a frozen dataclass in place.

    Frozen dataclasses store normalised values from ``__post_init__`` through
    ``object.__setattr__`` (the documented way), here in one place.
    """
    for f in fields(obj):
        spec = f.metadata
        if "check" in spec:
            value = spec["check"](getattr(obj, f.name), f"{obj.SECTION}.{f.name}", spec["unit"])
            object.__setattr__(obj, f.name, value)


_RESOLUTION_SIDE = Integer(1, MAX_RESOLUTION)


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

    SECTION: ClassVar[str] = "mirror"

    radius: float = field(metadata=setting(
        Positive(), "vertex radius of curvature R", unit="mm"))
    conic: float = field(default=0.0, metadata=setting(
        Number(), "conic constant k: 0 sphere, -1 paraboloid, < -1 hyperboloid"))
    rim_radius: float = field(metadata=setting(
        Positive(), "radial extent of the mirror", unit="mm",
        also="inside the conic: (1 + k) rim_radius² <= radius²"))
    vertex_distance: float = field(metadata=setting(
        Positive(), "lens centre to mirror vertex", unit="mm", also="> lens.focal_length"))
    tilt_deg: float = field(default=0.0, metadata=setting(
        Between(low=-90.0, high=90.0), "rotation about the vertex in the x–z plane",
        unit="deg"))
    aspheric: tuple[float, ...] = field(default=(), metadata=setting(
        Numbers("[a4, a6, ...]"), "coefficients of ρ⁴, ρ⁶, ... added to the sag "
        "(kind = \"asphere\")"))
    kind: str = field(default="conic", compare=False, metadata=setting(
        OneOf(MIRROR_KINDS), "how the mirror is written (see below)"))

    def __post_init__(self) -> None:
        _check_fields(self)
        R, k = self.radius, self.conic
        if 1.0 + k > 0:
            rho_lim = R / math.sqrt(1.0 + k)
            _require(self.rim_radius <= rho_lim, "mirror.rim_radius",
                     f"must be <= {rho_lim:.6g} mm, where a conic of radius {R:g} and "
                     f"conic constant {k:g} ends (got {self.rim_radius:g})")

    @property
    def tilt(self) -> float:
        """Tilt in radians."""
        return math.radians(self.tilt_deg)

    @property
    def is_sphere(self) -> bool:
        """True for a sphere: conic constant 0 and no asphere terms."""
        return self.conic == 0.0 and not any(self.aspheric)

    @property
    def is_symmetric(self) -> bool:
        """True when the camera axis is the mirror's axis of rotation."""
        return self.tilt_deg == 0.0

    @property
    def max_fov_deg(self) -> float:
        """The largest FOV this mirror reflects into the lens, degrees.

        Untilted: twice the largest angle a world-bound reflected chief ray makes with
        the axis, over the visible run of the mirror from its vertex while that angle
        grows. Tilted: the spread of those rays' directions within the tilt plane, over
        the visible run from the rim nearest the camera. This is the reach
        :func:`mitsweep.optics.sweep.mirror_zone` finds, computed here on the same grid
        from the mirror's profile in the tilt plane (the configuration may not import the
        optics), so that a setup refused here is refused there, and one accepted here
        accepted there: the two agree to ~1e-13° (to 3e-6° where a tilted mirror's rim is
        the conic's edge, tests/test_config_reach.py).
        """
        return math.degrees(_reach(self))


# --- The mirror's reach (the largest FOV), in the tilt plane ----------------------------
#
# In the plane y = 0 every quantity is an angle measured from +z toward +x. A mirror
# point at local x (signed) has the local normal angle atan2(x (1 + q p), q) (the
# profile's normal written through q = sqrt(R² - (1+k) x²), finite at a hemisphere's
# rim), the world normal angle θ = that + tilt; the direction r̂ toward the lens centre
# has the angle α; the camera sees the point where cos(θ - α) > 0, and the world-bound
# reflected chief ray w = -r̂ + 2 (n·r̂) n leaves at the angle 2θ - α.

#: Points of the grid the reach is sampled on: mitsweep.optics.sweep's, so the two agree.
_REACH_GRID = 4097


def _tilt_plane_rays(mirror: Mirror, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(cos_incidence, world_angle)`` of the chief rays at local tilt-plane points ``x``
    (mm, signed): n·r̂, and the angle of the world-bound reflected ray (radians)."""
    R, k, t = mirror.radius, mirror.conic, mirror.tilt
    x2 = x * x
    q = np.sqrt(np.maximum(R * R - (1.0 + k) * x2, 0.0))
    sag = x2 / (R + q)
    p = np.zeros_like(x)   # the asphere's s'/ρ
    for j, a in enumerate(mirror.aspheric):
        n = 2 * (j + 2)
        sag = sag + a * x2 ** (n // 2)
        p = p + n * a * x2 ** (n // 2 - 1)
    theta = np.arctan2(x * (1.0 + q * p), q) + t
    c, s = math.cos(t), math.sin(t)
    px, pz = c * x - s * sag, -s * x - c * sag           # world position (z = -sag locally)
    alpha = np.unwrap(np.arctan2(-px, mirror.vertex_distance - pz))
    return np.cos(theta - alpha), 2.0 * theta - alpha


def _visible_end(mirror: Mirror, x_lo: float, x_hi: float) -> float:
    """The end of the visible run that starts at ``x_lo``, searched toward ``x_hi``: the
    first sign change of n·r̂ on the grid, refined by bisection to 1e-12 mm."""
    xs = np.linspace(x_lo, x_hi, _REACH_GRID)
    vis = _tilt_plane_rays(mirror, xs)[0] > 0
    if not vis[0]:
        return x_lo
    if vis.all():
        return x_hi
    j = int(np.argmin(vis))
    a, b = float(xs[j - 1]), float(xs[j])
    for _ in range(200):
        m = 0.5 * (a + b)
        if abs(b - a) <= 2e-12 or m in (a, b):
            break
        fm = float(_tilt_plane_rays(mirror, np.array([m]))[0][0])
        if fm == 0.0:
            return m
        if fm > 0:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


def _reach(mirror: Mirror) -> float:
    """The mirror's reach, radians (see :attr:`Mirror.max_fov_deg`)."""
    rim = mirror.rim_radius
    if mirror.is_symmetric:
        xs = np.linspace(0.0, _visible_end(mirror, 0.0, rim), _REACH_GRID)
        phi = _tilt_plane_rays(mirror, xs)[1]
        ang = np.abs((phi + math.pi) % (2.0 * math.pi) - math.pi)   # angle to the axis
        grows = np.concatenate([[True], np.diff(ang) > 0])
        stop = int(np.argmin(grows)) if not grows.all() else len(xs)
        return 2.0 * float(ang[stop - 1])
    # Tilted: from the first visible point on the side nearest the camera.
    s = math.sin(mirror.tilt)
    near = -rim if s * rim >= -s * rim else rim          # larger world z at the rim
    xs_all = np.linspace(near, -near, _REACH_GRID)
    first = int(np.argmax(_tilt_plane_rays(mirror, xs_all)[0] > 0))  # the vertex is seen
    start = float(xs_all[first])
    xs = np.linspace(start, _visible_end(mirror, start, -near), _REACH_GRID)
    phi = _tilt_plane_rays(mirror, xs)[1]
    return float(np.max(phi) - np.min(phi))


@dataclass(frozen=True, kw_only=True)
class Lens:
    """Thin lens.

    Parameters
    ----------
    focal_length : float
        Focal length f, mm (> 0; default 50).
    f_number : float
        f-number N (> 0; default 2.8): the entrance pupil's diameter is f / N.
    """

    SECTION: ClassVar[str] = "lens"

    focal_length: float = field(default=50.0, metadata=setting(
        Positive(), "focal length f", unit="mm"))
    f_number: float = field(default=2.8, metadata=setting(
        Positive(), "f-number N (entrance pupil diameter f / N)"))

    def __post_init__(self) -> None:
        _check_fields(self)

    @property
    def aperture_radius(self) -> float:
        """Entrance-pupil radius, mm: f / (2 N)."""
        return self.focal_length / (2.0 * self.f_number)


@renamed_fields(size_mm="size")
@dataclass(frozen=True, kw_only=True)
class Sensor:
    """Image sensor.

    Parameters
    ----------
    resolution : tuple of int
        ``(width, height)``, pixels, each in [1, :data:`MAX_RESOLUTION`] (default 512²).
    pixel_pitch : float
        Pixel pitch, mm (> 0; default 0.018).
    center_offset_px : tuple of float or None
        ``(drow, dcol)``, pixels: where the mirror's axis meets the image relative to
        the image centre, as ``mitsweep calibrate`` measures it on a photograph: the axis
        is at pixel ``(H/2 - 1/2 + drow, W/2 - 1/2 + dcol)`` (see
        :mod:`mitsweep.optics.pixels`). None (the default) means the image centre; each
        part must lie within the image's height (rows) and width (columns) of it.
    """

    SECTION: ClassVar[str] = "sensor"

    resolution: tuple[int, int] = field(default=(512, 512), metadata=setting(
        Vector(_RESOLUTION_SIDE, "[width, height]", names=("width", "height")),
        "image size", unit="px"))
    pixel_pitch: float = field(default=0.018, metadata=setting(
        Positive(), "pixel pitch", unit="mm"))
    center_offset_px: tuple[float, float] | None = field(default=None, metadata=setting(
        OrNone(Vector(Number(), "[drow, dcol]", names=("drow", "dcol"))),
        "the mirror axis's image relative to the image centre (default: the centre)",
        unit="px", also="within the image's height and width of its centre"))

    def __post_init__(self) -> None:
        _check_fields(self)
        off = self.center_offset_px
        if off is not None:
            w, h = self.resolution
            for name, value, limit in (("drow", off[0], h), ("dcol", off[1], w)):
                _require(abs(value) <= limit, f"sensor.center_offset_px {name}",
                         f"must be in [-{limit}, {limit}] px (within the image's "
                         f"{'height' if name == 'drow' else 'width'} of its centre), "
                         f"got {value:g}")

    @property
    def width(self) -> int:
        """Image width, pixels."""
        return self.resolution[0]

    @property
    def height(self) -> int:
        """Image height, pixels."""
        return self.resolution[1]

    @property
    def size(self) -> tuple[float, float]:
        """Sensor size ``(width, height)``, mm: the resolution times the pixel pitch."""
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
        w, h = (_RESOLUTION_SIDE(v, f"sensor.resolution {name}", "px")
                for name, v in zip(("width", "height"), (width, height)))
        scale = max(self.width / w, self.height / h)
        off = self.center_offset_px
        return dataclasses.replace(
            self, resolution=(w, h), pixel_pitch=self.pixel_pitch * scale,
            center_offset_px=None if off is None else (off[0] / scale, off[1] / scale))


@dataclass(frozen=True, kw_only=True)
class Sweep:
    """The wanted field of view and depth range, and the stage motion.

    The fields of the setup dataclasses are the TOML keys, one for one (the loader, the
    strict key check, :func:`setup_to_dict` and the banks' optics fingerprints all use
    them), so ``velocity`` keeps its documented key rather than the ``velocity_mm_s`` of
    computed quantities such as :attr:`mitsweep.optics.SweepRange.velocity_mm_s`.

    Parameters
    ----------
    fov_deg : float
        Field of view, degrees, in (0, 360): the whole cone for an untilted mirror,
        the spread within the tilt plane for a tilted one.
    depth_min, depth_max : float
        Depth range, mm, from the mirror along the reflected ray (defaults 300 and
        10000; ``depth_max`` may be ``inf``; ``depth_min <= depth_max``).
    velocity : float
        Stage velocity, mm/s (> 0; default 1).
    profile : str
        Stage motion: ``"linear"`` (default), ``"trapezoidal"`` or ``"tabulated"``.
    focus_min, focus_max : float or None
        A given sweep range (focus distances, mm, both or neither), overriding the
        optimal one computed from ``fov_deg`` and the depth range (paper Eq. 8–9), e.g.
        to reproduce Table 1's longer sweeps.
    """

    SECTION: ClassVar[str] = "sweep"

    fov_deg: float = field(metadata=setting(
        Between(low=0.0, high=360.0), "field of view (in the tilt plane when tilted)",
        unit="deg", also="within the mirror's reach"))
    depth_min: float = field(default=300.0, metadata=setting(
        Positive(), "nearest depth, from the mirror along the reflected ray", unit="mm",
        also="<= sweep.depth_max"))
    depth_max: float = field(default=10000.0, metadata=setting(
        Positive(inf=True), "farthest depth", unit="mm"))
    velocity: float = field(default=1.0, metadata=setting(
        Positive(), "stage velocity", unit="mm/s"))
    profile: str = field(default="linear", metadata=setting(
        OneOf(MOTION_PROFILES), "stage motion"))
    focus_min: float | None = field(default=None, metadata=setting(
        OrNone(Positive()), "a given sweep range's nearest focus distance", unit="mm",
        also="< sweep.focus_max, > lens.focal_length; both or neither"))
    focus_max: float | None = field(default=None, metadata=setting(
        OrNone(Positive()), "a given sweep range's farthest focus distance", unit="mm"))

    def __post_init__(self) -> None:
        _check_fields(self)
        dmin, dmax = self.depth_min, self.depth_max
        _require(dmin <= dmax, "sweep.depth_min",
                 f"must be <= sweep.depth_max ({dmax:g}), got {dmin:g}")
        fmin, fmax = self.focus_min, self.focus_max
        _require((fmin is None) == (fmax is None), "sweep.focus_min",
                 "give both focus_min and focus_max, or neither")
        if fmin is not None and fmax is not None:
            _require(fmin < fmax, "sweep.focus_min",
                     f"must be < sweep.focus_max ({fmax:g}), got {fmin:g}")

    @property
    def fov(self) -> float:
        """Field of view in radians."""
        return math.radians(self.fov_deg)


@dataclass(frozen=True, kw_only=True)
class Placement:
    """Where a user's scene sits in the mirror's frame (after its conversion to mm).

    Parameters
    ----------
    translate : tuple of float
        ``[x, y, z]``, mm, applied after the rotations (default 0).
    rotate_deg : tuple of float
        ``[rx, ry, rz]``: rotations about the frame's x, y, then z axes, degrees
        (default 0).
    """

    SECTION: ClassVar[str] = "scene.placement"

    translate: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=setting(
        Vector(Number(), "[x, y, z]"), "shift after the rotations", unit="mm"))
    rotate_deg: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0), metadata=setting(
        Vector(Number(), "[rx, ry, rz]"), "rotations about x, y, then z", unit="deg"))

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True, kw_only=True)
class Scene:
    """Synthetic surroundings for rendering (owned by ``mitsweep.render``).

    A user's own Mitsuba scene replaces the room (:mod:`mitsweep.render.user_scene`)
    when ``file`` is given.

    Parameters
    ----------
    room_size : tuple of float
        ``[x, y, z]``, mm: an axis-aligned room around the mirror whose walls, floor and
        ceiling lie between ~10 cm and 3 m from it (each > 0).
    objects : int
        Textured boards added at those depths, in [0, 64] (default 6).
    texture_seed : int
        Picks the texture layout (>= 0).
    max_depth : int
        Integrator depth in [0, 64]; 0 (the default) chooses it from the scene.
    lighting : str
        ``"emissive"`` (textured self-luminous surfaces, one bounce off the mirror
        suffices, noise only from the lens) or ``"lit"`` (diffuse textured surfaces under
        a ceiling light, two bounces).
    mesh_sag_tol : float
        Largest sag error of the mirror tessellation where a mesh is needed, mm (> 0).
    mesh_normal_tol : float
        Largest normal error of that tessellation, radians (> 0).
    file : str or None
        A user's Mitsuba XML scene (relative to the setup file's folder when loaded
        from TOML).
    unit : str or None
        That scene's length unit: ``"mm"`` (the default), ``"cm"`` or ``"m"``.
    placement : Placement or None
        Where that scene sits in the mirror's frame (a table ``{translate = [x, y, z],
        rotate_deg = [rx, ry, rz]}`` in TOML): after the conversion to mm, rotated by
        ``rx``, ``ry`` then ``rz`` degrees about the frame's x, y and z axes, then
        translated by ``translate`` mm.
    """

    SECTION: ClassVar[str] = "scene"

    room_size: tuple[float, float, float] = field(
        default=(4000.0, 4000.0, 2500.0), metadata=setting(
            Vector(Positive(), "[x, y, z]"), "the synthetic room around the mirror", unit="mm"))
    objects: int = field(default=6, metadata=setting(
        Integer(0, 64), "textured boards in the room"))
    texture_seed: int = field(default=0, metadata=setting(Integer(0), "texture layout"))
    max_depth: int = field(default=0, metadata=setting(
        Integer(0, 64), "integrator depth; 0 = chosen from the scene"))
    lighting: str = field(default="emissive", metadata=setting(
        OneOf(SCENE_LIGHTING), "self-luminous surfaces, or lit by a ceiling light"))
    mesh_sag_tol: float = field(default=1e-4, metadata=setting(
        Positive(), "mirror tessellation: largest sag error", unit="mm"))
    mesh_normal_tol: float = field(default=1e-4, metadata=setting(
        Positive(), "mirror tessellation: largest normal error", unit="rad"))
    file: str | None = field(default=None, metadata=setting(
        OrNone(FilePath("a Mitsuba XML file")),
        "a user's Mitsuba scene, relative to the setup file"))
    unit: str | None = field(default=None, metadata=setting(
        OrNone(OneOf(SCENE_UNITS)), "that scene's length unit (default mm)"))
    placement: Placement | None = field(default=None, metadata=setting(
        OrNone(Table(Placement, "{translate = [x, y, z], rotate_deg = [rx, ry, rz]}")),
        "where that scene sits in the mirror's frame"))

    def __post_init__(self) -> None:
        _check_fields(self)


@dataclass(frozen=True, kw_only=True)
class Rig:
    """The capture rig (owned by ``mitsweep.rig``): stage limits, motion and camera.

    When ``sensor_distance_at_zero`` is absent (an uncalibrated rig) the sweep is
    centred within the soft limits.

    Parameters
    ----------
    travel : float
        The stage's usable travel, mm (> 0; default 25).
    max_velocity : float
        Stage velocity limit, mm/s (> 0).
    acceleration : float
        Stage acceleration limit, mm/s² (> 0).
    settle_distance : float
        Run at constant velocity after the ramp before the shutter opens (and before
        the ramp down after it closes), mm (>= 0).
    min_exposure_s, max_exposure_s : float
        Bounds of the camera's bulb exposure, s (> 0, min < max).
    steps_per_mm : float
        Controller (micro)steps per stage millimetre (the Arduino's stepper, or a Zaber
        stage's microsteps), > 0.
    soft_limit_min, soft_limit_max : float
        Bounds of every commanded position, mm in stage coordinates: ``0 <= min < max
        <= travel``; ``soft_limit_max`` None (the default) means ``travel``.
    sensor_distance_at_zero : float or None
        Lens-to-sensor distance when the stage is at position 0, mm (> 0); None for an
        uncalibrated rig.
    sensor_direction : int
        The sign of d(sensor distance)/d(stage position): 1 or -1.
    baudrate : int
        Serial links' baud rate, in [300, 4000000].
    reply_timeout_s : float
        Deadline on every reply, s (> 0).
    watchdog_s : float
        How long the firmware waits without host traffic during a motion before it
        stops the stage, s, in (0, 60].
    """

    SECTION: ClassVar[str] = "rig"

    travel: float = field(default=25.0, metadata=setting(
        Positive(), "the stage's usable travel", unit="mm"))
    max_velocity: float = field(default=5.0, metadata=setting(
        Positive(), "stage velocity limit", unit="mm/s"))
    acceleration: float = field(default=10.0, metadata=setting(
        Positive(), "stage acceleration limit", unit="mm/s²"))
    settle_distance: float = field(default=0.05, metadata=setting(
        AtLeast(least=0.0), "run at constant velocity around the exposure", unit="mm"))
    min_exposure_s: float = field(default=1.0 / 4000.0, metadata=setting(
        Positive(), "shortest bulb exposure", unit="s", also="< rig.max_exposure_s"))
    max_exposure_s: float = field(default=30.0, metadata=setting(
        Positive(), "longest bulb exposure", unit="s"))
    steps_per_mm: float = field(default=400.0, metadata=setting(
        Positive(), "controller (micro)steps per stage millimetre"))
    soft_limit_min: float = field(default=0.0, metadata=setting(
        AtLeast(least=0.0), "lowest commanded stage position", unit="mm",
        also="< rig.soft_limit_max"))
    soft_limit_max: float | None = field(default=None, metadata=setting(
        OrNone(Number()), "highest commanded stage position (default: rig.travel)",
        unit="mm", also="<= rig.travel"))
    sensor_distance_at_zero: float | None = field(default=None, metadata=setting(
        OrNone(Positive()), "lens-to-sensor distance at stage position 0 (absent: "
        "uncalibrated)", unit="mm"))
    sensor_direction: int = field(default=1, metadata=setting(
        OneOf((1, -1)), "sign of d(sensor distance)/d(stage position)"))
    baudrate: int = field(default=115200, metadata=setting(
        Integer(300, 4_000_000), "serial links' baud rate"))
    reply_timeout_s: float = field(default=1.0, metadata=setting(
        Positive(), "deadline on every reply", unit="s"))
    watchdog_s: float = field(default=1.0, metadata=setting(
        Positive(most=60.0), "firmware stops the stage after this long without host "
        "traffic", unit="s"))

    def __post_init__(self) -> None:
        _check_fields(self)
        _require(self.min_exposure_s < self.max_exposure_s, "rig.min_exposure_s",
                 "must be < rig.max_exposure_s")
        lo = self.soft_limit_min
        hi = self.travel if self.soft_limit_max is None else self.soft_limit_max
        _require(hi <= self.travel, "rig.soft_limit_max",
                 f"must be <= rig.travel ({self.travel:g} mm), got {hi:g}")
        _require(lo < hi, "rig.soft_limit_min",
                 f"must be < rig.soft_limit_max ({hi:g} mm), got {lo:g}")
        object.__setattr__(self, "soft_limit_max", hi)


@dataclass(frozen=True, kw_only=True)
class Setup:
    """One catadioptric focal-sweep camera and, optionally, its scene and rig.

    Parameters
    ----------
    mirror : Mirror
        The ``[mirror]`` table (required); ``mirror.vertex_distance`` must exceed
        ``lens.focal_length`` so the camera can focus on the mirror.
    lens : Lens
        The ``[lens]`` table (default :class:`Lens`\\ ()).
    sensor : Sensor
        The ``[sensor]`` table (default :class:`Sensor`\\ ()).
    sweep : Sweep
        The ``[sweep]`` table (required); ``sweep.focus_min``, when given, must exceed
        ``lens.focal_length``.
    scene : Scene
        The ``[scene]`` table (default :class:`Scene`\\ ()).
    rig : Rig
        The ``[rig]`` table (default :class:`Rig`\\ ()).
    name : str
        The setup's name (default ``"setup"``; a file's stem when loaded).
    """

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
        R = Positive()(t["radius"], "mirror.radius", "mm")
        _require(Number()(t.get("conic", 0.0), "mirror.conic") == 0.0, "mirror.conic",
                 "must be 0 for kind = 'sphere' (use kind = 'conic')")
        has_c, has_v = "center_distance" in t, "vertex_distance" in t
        _require(has_c != has_v, "mirror.center_distance",
                 "give exactly one of center_distance and vertex_distance for a sphere")
        vd = (Positive()(t["center_distance"], "mirror.center_distance", "mm") - R) if has_c \
            else t["vertex_distance"]
        return Mirror(kind=kind, radius=R, conic=0.0, rim_radius=t.get("rim_radius", R),
                      vertex_distance=vd, tilt_deg=t.get("tilt_deg", 0.0))
    if kind == "paraboloid":
        allowed = {"focal_length", "radius", "rim_radius", "vertex_distance", "tilt_deg", "conic"}
        _reject_unknown(t, allowed, "mirror")
        _require(("focal_length" in t) != ("radius" in t), "mirror.focal_length",
                 "give exactly one of focal_length and radius (= 2 focal_length) for a paraboloid")
        R = 2.0 * Positive()(t["focal_length"], "mirror.focal_length", "mm") if "focal_length" in t \
            else t["radius"]
        _require(Number()(t.get("conic", -1.0), "mirror.conic") == -1.0, "mirror.conic",
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


def _refuse_unreachable_fov(setup: Setup) -> None:
    """Refuse ``sweep.fov_deg`` beyond the mirror's reach, as
    :func:`mitsweep.optics.sweep.mirror_zone` words it (the same comparison, in
    radians, on the same reach)."""
    reach = _reach(setup.mirror)
    fov = setup.sweep.fov_deg
    if math.radians(fov) > reach:
        where = "from the camera" if setup.mirror.is_symmetric else "in its tilt plane"
        raise SetupError(f"sweep.fov_deg: {fov:g}° is beyond this mirror's reach {where}; "
                         f"the largest FOV it gives is {math.degrees(reach):.2f}°")


def setup_from_dict(data: Mapping[str, Any], *, name: str = "setup") -> Setup:
    """Build a validated :class:`Setup` from a TOML-like nested mapping.

    Besides each key's own constraint and those between keys, ``sweep.fov_deg`` must lie
    within the mirror's reach (:attr:`Mirror.max_fov_deg`): a field of view the mirror
    cannot reflect into the lens is refused here, not later by
    :func:`mitsweep.optics.optimal_sweep_range`. (A :class:`Setup` built directly, e.g.
    by :func:`dataclasses.replace`, is not checked for reach.)

    Parameters
    ----------
    data : mapping
        Sections ``mirror`` and ``sweep`` (required), ``lens``, ``sensor``, ``scene``,
        ``rig`` (optional), each a mapping of keys as in a setup TOML file, and an
        optional top-level ``name``.
    name : str, optional
        The setup's name when ``data`` has none.

    Returns
    -------
    Setup

    Raises
    ------
    SetupError
        For an unknown section or key, a missing one, a value of the wrong type or out
        of its range, or an FOV beyond the mirror's reach; the message names the key and
        what is allowed.
    """
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
    setup = Setup(**kwargs)
    _refuse_unreachable_fov(setup)
    return setup


def load_setup(path: str | Path) -> Setup:
    """Load and validate a setup TOML file (:func:`setup_from_dict` on its tables).

    Parameters
    ----------
    path : str or path-like
        The setup file. A relative ``[scene] file`` in it is resolved beside it.

    Returns
    -------
    Setup
        Named after the file's stem unless the file gives a ``name``.

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

    Parameters
    ----------
    source : str
        TOML text.

    Returns
    -------
    depth : int
        The deepest nesting (0 when nothing is nested).
    line : int
        The 1-based line where that depth is first reached.
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
    """The setup as a plain, JSON/TOML-serialisable nested dict (normalised to a conic).

    Parameters
    ----------
    setup : Setup
        The setup to write.

    Returns
    -------
    dict
        Its sections under their TOML names, keys as in a setup file (absent ones
        omitted); :func:`setup_from_dict` reads it back to an equal setup.
    """
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


def _toml_text(value: Any) -> str:
    """A default value as a setup file writes it."""
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, tuple):
        return "[" + ", ".join(_toml_text(v) for v in value) + "]"
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def _key_rows(cls: type, section: str) -> list[str]:
    rows = []
    for f in fields(cls):
        spec = f.metadata
        if f.default is not dataclasses.MISSING:
            default = "absent" if f.default is None else f"`{_toml_text(f.default)}`"
        else:
            default = "required"
        allowed = spec["check"].allowed + (f"; {spec['also']}" if spec["also"] else "")
        rows.append(f"| `{section}.{f.name}` | {default} | {spec['unit']} | {allowed} "
                    f"| {spec['meaning']} |")
        check = spec["check"]
        inner = check.check if isinstance(check, OrNone) else check
        if isinstance(inner, Table):
            rows += _key_rows(inner.cls, f"{section}.{f.name}")
    return rows


def setup_keys_table() -> str:
    """The keys of a setup file as a Markdown table, written from the fields' declared
    constraints (:func:`setting`): ``docs/reference/setups.md`` holds this text, and a
    test checks that it still does.

    Returns
    -------
    str
        One row per key (``section.key``, default, unit, what is allowed, meaning),
        sections in file order, ending in a newline.
    """
    rows = ["| key | default | unit | allowed | meaning |", "|---|---|---|---|---|"]
    for section, cls in _SECTIONS.items():
        rows += _key_rows(cls, section)
    return "\n".join(rows) + "\n"


#: The embedded default: the paper's spherical mirror (Sec. 3.1 and 5.2).
DEFAULT_SETUP = Setup(
    name="sphere",
    mirror=Mirror(kind="sphere", radius=25.0, conic=0.0, rim_radius=25.0, vertex_distance=327.0),
    lens=Lens(focal_length=50.0, f_number=2.8),
    sweep=Sweep(fov_deg=237.0, depth_min=300.0, depth_max=10000.0, velocity=1.0),
)

