"""What a dataset holds: :class:`DatasetOptions`, validated for the command line and
for a manifest read back alike."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, fields
from typing import Any

from ..deprecation import renamed_fields
from ..render.api import MODES  # the camera modes; render imports Mitsuba only when rendering
from .runner import DatasetError

__all__ = ["DatasetOptions", "options_from_dict", "MAX_SCENES", "MAX_LIGHT_LEVELS",
           "MAX_BANK_DEPTHS", "MAX_SEED", "FAMILIES", "SCENE_UNITS", "FILE_KEYS"]

#: Most scene variations a dataset may hold (``DatasetOptions.scenes``); a manifest that
#: claims more is refused before any work starts.
MAX_SCENES = 10_000
#: Most light levels and bank depths a dataset may hold.
MAX_LIGHT_LEVELS = 32
MAX_BANK_DEPTHS = 64
#: Mitsuba's sampler seeds are 32-bit: scene i renders with seed + i.
MAX_SEED = 2**32 - 1
#: Where a dataset's scenes come from: ``room`` the built-in textured room (texture
#: layout ``scene.texture_seed + i``), ``procedural`` the procedural family
#: (:mod:`mitsweep.render.procedural`, scene seed ``seed + i``), ``xml`` the user's
#: Mitsuba XML files (``scene_files``, one scene each).
FAMILIES = ("room", "procedural", "xml")
SCENE_UNITS = ("mm", "cm", "m")
#: Fields renamed since datasets were first written, by the key a manifest keeps for
#: each (files keep their keys: every manifest written before still reads, and the same
#: options write the same bytes).
FILE_KEYS = {"bank_depths": "bank_depths_mm"}
_HEX = frozenset("0123456789abcdef")


def _is_int(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _is_real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _is_sha256(v: Any) -> bool:
    return isinstance(v, str) and len(v) == 64 and set(v) <= _HEX


def _digests(value: Any, key: str) -> dict[str, str]:
    """A scene's content digests (:func:`mitsweep.io.scene_files.scene_digests`):
    ``{name: SHA-256}``, at least one, names non-empty strings; sorted."""
    _require(isinstance(value, dict) and bool(value), key,
             f"must be an object of file names to SHA-256, got {value!r}")
    for name, sha in value.items():
        _require(isinstance(name, str) and name != "", key, f"file names must be non-empty "
                                                            f"strings, got {name!r}")
        _require(_is_sha256(sha), f"{key}[{name!r}]",
                 f"must be 64 lowercase hex digits, got {sha!r}")
    return dict(sorted(value.items()))


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise DatasetError(f"{key}: {message}")


def _positive_reals(values: Any, key: str, lo_count: int, hi_count: int) -> tuple[float, ...]:
    _require(isinstance(values, (list, tuple)) and lo_count <= len(values) <= hi_count, key,
             f"must be a list of {lo_count} to {hi_count} numbers, got {values!r}")
    for v in values:
        _require(_is_real(v) and math.isfinite(v) and v > 0, key,
                 f"every value must be a finite number > 0, got {v!r}")
    return tuple(float(v) for v in values)


def _methods(values: Any) -> tuple[str, ...]:
    from ..deconv import METHODS  # read now: the restoration methods known at run time

    allowed = ", ".join(METHODS)
    _require(isinstance(values, (list, tuple)) and len(values) >= 1, "methods",
             f"must be a list of 1 or more of {allowed}, got {values!r}")
    for m in values:
        _require(isinstance(m, str) and m in METHODS, "methods",
                 f"unknown restoration method {m!r}; allowed: {allowed}")
    _require(len(set(values)) == len(values), "methods",
             f"each method at most once, got {list(values)}")
    return tuple(values)


@renamed_fields(bank_depths_mm="bank_depths")
@dataclass(frozen=True, kw_only=True)
class DatasetOptions:
    """What a dataset holds. Seeds: scene i renders with ``seed + i`` (texture layout
    ``scene.texture_seed + i``); noise of scene i at level j uses ``(seed, i, j)``.

    Every field is validated here, for the command line and for a manifest read back
    alike (:func:`options_from_dict`): ``scenes`` in [1, ``MAX_SCENES``], ``seed`` >= 0
    with ``seed + scenes - 1`` <= ``MAX_SEED``, ``spp`` a positive integer per mode,
    light levels (at most ``MAX_LIGHT_LEVELS``, distinct as file names) and bank depths
    (1 to ``MAX_BANK_DEPTHS``) finite and > 0, ``methods`` names of
    :data:`mitsweep.deconv.METHODS` (each makes its own EDOF images: ``wiener`` the
    ``edof*`` items, another method ``m`` the ``edof_m*`` items).

    Scenes: ``family`` one of :data:`FAMILIES`. ``procedural`` takes ``family_params``
    (the family's parameters, plain JSON, stored resolved:
    :func:`mitsweep.render.procedural.resolve_params`). ``xml`` takes ``scene_files``,
    one ``{"path": absolute path, "sha256": of its bytes}`` per scene (``scenes`` is
    their number), with ``"files"``, the SHA-256 of every file it loads
    (:func:`mitsweep.io.scene_files.scene_digests`), when it loads more than itself, and
    ``scene_unit`` (one of :data:`SCENE_UNITS`, or None for the setup's).
    A room dataset's options read and write as before these fields existed.

    Attributes
    ----------
    scenes : int
        Scene variations, in [1, :data:`MAX_SCENES`].
    seed : int
        Monte Carlo and scene seed of scene 0 (scene i: ``seed + i``), >= 0.
    spp : dict
        Samples per pixel of each render mode (``pinhole``, ``focused``, ``sweep``,
        ``stopped``), positive integers.
    light_levels_lux : tuple of float
        Light levels of the noisy images, lux (at most :data:`MAX_LIGHT_LEVELS`; none:
        no noisy images).
    bank_depths : tuple of float
        Depths of the IPSF bank's sources from the mirror, mm (1 to
        :data:`MAX_BANK_DEPTHS`). Formerly ``bank_depths_mm`` (still accepted and
        readable, with a warning; the manifest's key keeps that name).
    bank_rays : int or None
        Rays per IPSF of the bank (None: the tracer's default).
    grid : (int, int)
        Grid bank shape (rows, cols), each in [1, 256], for a tilted mirror.
    stopped_f_number : float
        F-number of the ``stopped`` images.
    diffraction : bool
        Convolve the thin-lens images (focused, sweep, stopped) with the lens's
        pixel-integrated Airy PSF at 550 nm; the ground truth stays ideal.
    methods : tuple of str
        Restoration methods, each at most once (default Wiener only).
    family : {"room", "procedural", "xml"}
        Where the scenes come from (:data:`FAMILIES`).
    family_params : dict
        The procedural family's parameters (procedural only).
    scene_files : tuple of dict
        One entry per scene (xml only), as :func:`~mitsweep.pipeline.scene_files_from`
        makes them.
    scene_unit : {"mm", "cm", "m"} or None
        The XML scenes' length unit (xml only; None: the setup's).
    motion : dict or None
        A tabulated stage motion to run instead of the setup's sweep:
        ``{"times": [...], "positions_mm": [...]}`` (times in any unit, rescaled over the
        exposure; sensor distances, mm).
    """

    scenes: int = 1
    seed: int = 0
    spp: dict = field(default_factory=lambda: {"pinhole": 16, "focused": 64, "sweep": 128,
                                               "stopped": 64})
    light_levels_lux: tuple[float, ...] = (50.0, 2.0, 0.5)
    bank_depths: tuple[float, ...] = (500.0,)
    bank_rays: int | None = None
    grid: tuple[int, int] = (9, 9)
    stopped_f_number: float = 11.0
    diffraction: bool = True
    methods: tuple[str, ...] = ("wiener",)
    family: str = "room"
    family_params: dict = field(default_factory=dict)
    scene_files: tuple[dict, ...] = ()
    scene_unit: str | None = None
    motion: dict | None = None

    def __post_init__(self) -> None:
        _require(_is_int(self.scenes) and 1 <= self.scenes <= MAX_SCENES, "scenes",
                 f"must be an integer in [1, {MAX_SCENES}], got {self.scenes!r}")
        _require(_is_int(self.seed) and 0 <= self.seed <= MAX_SEED - (self.scenes - 1), "seed",
                 f"must be an integer in [0, {MAX_SEED - (self.scenes - 1)}] (scene i uses "
                 f"seed + i, a 32-bit seed), got {self.seed!r}")
        _require(isinstance(self.spp, dict) and set(self.spp) == set(MODES), "spp",
                 f"must give samples per pixel for exactly {', '.join(MODES)}, got "
                 f"{self.spp!r}")
        for mode in MODES:
            v = self.spp[mode]
            _require(_is_int(v) and v > 0, f"spp[{mode!r}]",
                     f"must be a positive integer, got {v!r}")
        lux = _positive_reals(self.light_levels_lux, "light_levels_lux", 0, MAX_LIGHT_LEVELS)
        names = [f"{x:g}" for x in lux]
        _require(len(set(names)) == len(names), "light_levels_lux",
                 f"levels must differ (as file names: {', '.join(names)})")
        depths = _positive_reals(self.bank_depths, "bank_depths", 1, MAX_BANK_DEPTHS)
        _require(self.bank_rays is None or (_is_int(self.bank_rays) and self.bank_rays > 0),
                 "bank_rays", f"must be a positive integer or null, got {self.bank_rays!r}")
        _require(isinstance(self.grid, (list, tuple)) and len(self.grid) == 2
                 and all(_is_int(g) and 1 <= g <= 256 for g in self.grid), "grid",
                 f"must be two integers in [1, 256], got {self.grid!r}")
        _require(_is_real(self.stopped_f_number) and math.isfinite(self.stopped_f_number)
                 and self.stopped_f_number > 0, "stopped_f_number",
                 f"must be a finite number > 0, got {self.stopped_f_number!r}")
        _require(isinstance(self.diffraction, bool), "diffraction",
                 f"must be true or false, got {self.diffraction!r}")
        methods = _methods(self.methods)
        self._check_scenes()
        self._check_motion()
        object.__setattr__(self, "spp", {m: int(self.spp[m]) for m in MODES})
        object.__setattr__(self, "light_levels_lux", lux)
        object.__setattr__(self, "bank_depths", depths)
        object.__setattr__(self, "grid", tuple(int(g) for g in self.grid))
        object.__setattr__(self, "methods", methods)

    def _check_scenes(self) -> None:
        _require(isinstance(self.family, str) and self.family in FAMILIES, "family",
                 f"must be one of {', '.join(FAMILIES)}, got {self.family!r}")
        _require(isinstance(self.family_params, dict), "family_params",
                 f"must be an object, got {type(self.family_params).__name__}")
        _require(isinstance(self.scene_files, (list, tuple)), "scene_files",
                 f"must be a list, got {type(self.scene_files).__name__}")
        _require(self.scene_unit is None or self.scene_unit in SCENE_UNITS, "scene_unit",
                 f"must be one of {', '.join(SCENE_UNITS)} or null, got {self.scene_unit!r}")
        if self.family != "procedural":
            _require(not self.family_params, "family_params",
                     f"apply to the procedural family only (family {self.family!r})")
        else:
            from ..render.procedural import resolve_params  # pure NumPy, no Mitsuba

            try:
                params = resolve_params(**self.family_params)
            except ValueError as exc:
                raise DatasetError(f"family_params.{exc}") from None
            object.__setattr__(self, "family_params", params)
        if self.family != "xml":
            _require(not self.scene_files, "scene_files",
                     f"apply to family 'xml' only (family {self.family!r})")
            _require(self.scene_unit is None, "scene_unit",
                     f"applies to family 'xml' only (family {self.family!r})")
            object.__setattr__(self, "scene_files", ())
            return
        _require(len(self.scene_files) == self.scenes, "scene_files",
                 f"one file per scene: {self.scenes} scenes, {len(self.scene_files)} files")
        files = []
        for k, f in enumerate(self.scene_files):
            key = f"scene_files[{k}]"
            _require(isinstance(f, dict) and {"path", "sha256"} <= set(f)
                     <= {"path", "sha256", "files"}, key,
                     f"must be an object with path, sha256 and optionally files, got {f!r}")
            _require(isinstance(f["path"], str) and f["path"].endswith(".xml"), f"{key}.path",
                     f"must be the path of an .xml file, got {f['path']!r}")
            _require(_is_sha256(f["sha256"]), f"{key}.sha256",
                     f"must be 64 lowercase hex digits, got {f['sha256']!r}")
            entry = {"path": f["path"], "sha256": f["sha256"]}
            if "files" in f:
                entry["files"] = _digests(f["files"], f"{key}.files")
            files.append(entry)
        object.__setattr__(self, "scene_files", tuple(files))

    def _check_motion(self) -> None:
        """``motion``: None (the setup's sweep) or a tabulated profile,
        ``{"times": [...], "positions_mm": [...]}`` (e.g. a motion-profile file's)."""
        if self.motion is None:
            return
        from ..optics.motion import MotionProfile

        m = self.motion
        _require(isinstance(m, dict) and set(m) == {"times", "positions_mm"}, "motion",
                 f"must be null or an object with exactly times and positions_mm, got {m!r}")
        try:
            prof = MotionProfile.tabulated(m["times"], m["positions_mm"])
        except (TypeError, ValueError) as exc:
            raise DatasetError(f"motion: {exc}") from None
        object.__setattr__(self, "motion", {"times": prof.times.tolist(),
                                            "positions_mm": prof.positions.tolist()})

    def as_dict(self) -> dict:
        """The options as a manifest records them (JSON values; the file's keys,
        :data:`FILE_KEYS`); :func:`options_from_dict` reads them back."""
        d = {"scenes": self.scenes, "seed": self.seed, "spp": dict(self.spp),
             "light_levels_lux": list(self.light_levels_lux),
             FILE_KEYS["bank_depths"]: list(self.bank_depths), "bank_rays": self.bank_rays,
             "grid": list(self.grid), "stopped_f_number": self.stopped_f_number,
             "diffraction": self.diffraction, "methods": list(self.methods)}
        # The scene fields only where they say something: a room dataset's manifest is
        # byte for byte what it was before they existed.
        if self.family != "room":
            d["family"] = self.family
        if self.family == "procedural":
            d["family_params"] = dict(self.family_params)
        if self.family == "xml":
            d["scene_files"] = [dict(f) for f in self.scene_files]
            d["scene_unit"] = self.scene_unit
        if self.motion is not None:
            d["motion"] = {k: list(v) for k, v in self.motion.items()}
        return d


#: Keys a manifest's options may omit (datasets written before they existed), with the
#: value those datasets were made with.
_ADDED_LATER: dict[str, Any] = {"methods": ["wiener"], "family": "room", "family_params": {},
                "scene_files": [], "scene_unit": None, "motion": None}


def options_from_dict(d: Any) -> DatasetOptions:
    """:class:`DatasetOptions` from a manifest's ``options``.

    Parameters
    ----------
    d : object
        The ``options`` object as parsed from JSON: the keys of
        :meth:`DatasetOptions.as_dict` (:data:`FILE_KEYS` where a field was renamed),
        all required but those added later (which older datasets omit), no others.

    Returns
    -------
    DatasetOptions

    Raises
    ------
    DatasetError
        Not an object, unknown or missing keys, or a bad value, naming the field by its
        key in the file.
    """
    names = [FILE_KEYS.get(f.name, f.name) for f in fields(DatasetOptions)]
    _require(isinstance(d, dict), "options", f"must be an object, got {type(d).__name__}")
    unknown = sorted(set(d) - set(names))
    missing = [k for k in names if k not in d and k not in _ADDED_LATER]
    _require(not unknown, "options", f"unknown keys {unknown}")
    _require(not missing, "options", f"missing keys {missing}")
    field_of = {key: name for name, key in FILE_KEYS.items()}
    try:
        return DatasetOptions(**{field_of.get(k, k): v for k, v in {**_ADDED_LATER, **d}.items()})
    except DatasetError as exc:
        name, sep, rest = str(exc).partition(":")
        head = name.split("[")[0].split(".")[0]   # spp['sweep'], scene_files[0].path...
        key = FILE_KEYS.get(head, head) + name[len(head):]
        raise DatasetError(f"options.{key}{sep}{rest}") from None
