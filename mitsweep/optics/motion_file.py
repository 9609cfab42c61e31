"""The motion-profile file: a sensor motion ``i(t)`` that every part of mitsweep can run.

``mitsweep design-sweep`` writes one; ``mitsweep ipsf``, ``render``, ``dataset`` and
``capture`` read it with ``--motion PROFILE.json``. The tracer and the renderer run its
:attr:`MotionFile.profile` (a :meth:`MotionProfile.tabulated`), so banks and renders made
with it share one reference geometry (mid-travel of its span, docs/design.md); the rig
turns it into stage commands within its limits.

Format (JSON, version 1)
------------------------
One object, keys in any order, unknown keys refused::

    {
      "format": "mitsweep-motion-profile",
      "version": 1,
      "times": [0.0, 0.013, ..., 1.0],
      "sensor_distances_mm": [366.41, 366.42, ..., 366.91],
      "exposure_s": 0.5,
      "provenance": {"generator": "mitsweep design-sweep", ...}
    }

- ``times``: normalised exposure time, 0 = shutter opens, 1 = shutter closes; strictly
  increasing, first exactly 0, last exactly 1; at least 2 knots.
- ``sensor_distances_mm``: lens-to-sensor distance at each knot, mm, finite and > 0,
  **strictly monotonic** (the sensor moves one way and never stops: a stage that
  reverses or dwells inside the exposure is not a focal sweep). ``i(t)`` is linear
  between knots: the stage velocity is constant on each interval.
- ``exposure_s``: the exposure the profile was designed for, s, or ``null`` (a shape
  only: the tracer and the renderer need none; the rig needs one).
- ``provenance``: a JSON object (what made the file: setup, objective, version, ...).

Kinematics (:func:`stage_kinematics`)
-------------------------------------
With exposure ``T``, interval ``j`` (``Δt_j`` normalised, ``Δi_j`` mm) is run at
``v_j = Δi_j / (Δt_j T)`` mm/s. A piecewise-linear ``i(t)`` changes velocity at its
knots; the stage must make each change within the shorter of the two intervals beside
the knot, so the acceleration it needs there is ``a_j = (v_{j+1} − v_j) / (min(Δt_j,
Δt_{j+1}) T)`` mm/s². (Spreading the change over the time between the intervals'
midpoints, the mean of the two, let a long slow interval jump to a short fast one: 0.06
to 9.8 mm/s within 1.1 ms, which a 100 mm/s² stage needs 98 ms and 0.48 mm to do.) The
rig's plan applies the same rule (:func:`mitsweep.rig.profile.check_followable`).
:func:`check_motion_file` holds ``|v_j|`` to ``rig.max_velocity`` and ``|a_j|`` to
``rig.acceleration``.

Layering: :mod:`mitsweep.optics` may not import :mod:`mitsweep.io` (docs/design.md), so
:func:`save_motion_file` writes through its own temporary-and-rename (the same scheme
as :mod:`mitsweep.io.atomic`, whose :func:`~mitsweep.io.atomic.check_writable` the
command line calls before any work).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import Setup, SetupError
from ..resources import require_regular_file
from .motion import MotionProfile

__all__ = ["MotionFile", "FORMAT", "VERSION", "save_motion_file", "load_motion_file",
           "motion_file_text", "parse_motion_file", "check_motion_file", "stage_kinematics"]

FORMAT = "mitsweep-motion-profile"
VERSION = 1
_KEYS = {"format", "version", "times", "sensor_distances_mm", "exposure_s", "provenance"}
_REQUIRED = ("format", "version", "times", "sensor_distances_mm")
#: Chords per ramp when a trapezoidal profile is tabulated (``MotionProfile.segments``):
#: its distance then deviates from the parabola by < |Δi| a / (8·256² (1 − a)) mm.
_RAMP_CHORDS = 256
#: Relative slack on the stage limits: a profile designed exactly at the limit
#: (the optimiser's active constraints) must pass after a JSON round trip.
_LIMIT_RTOL = 1e-6


@dataclass(frozen=True)
class MotionFile:
    """A motion-profile file, read and validated.

    Attributes
    ----------
    profile : MotionProfile
        ``tabulated``, times normalised to [0, 1], positions in mm.
    exposure_s : float or None
        The exposure it was designed for, s.
    provenance : dict
        What made it (JSON object).
    source : str or None
        The file it was read from (messages name it).
    """

    profile: MotionProfile
    exposure_s: float | None
    provenance: dict = field(default_factory=dict)
    source: str | None = None

    def as_dict(self) -> dict:
        """The file's JSON object."""
        return {"format": FORMAT, "version": VERSION,
                "times": self.profile.times.tolist(),
                "sensor_distances_mm": self.profile.positions.tolist(),
                "exposure_s": self.exposure_s, "provenance": self.provenance}


def _fail(source: str | None, message: str) -> SetupError:
    return SetupError(f"motion file {source}: {message}" if source else f"motion file: {message}")


#: Smallest step between knot times (normalised exposure time): closer knots would give
#: velocities beyond any stage's (a 1e-300 step overflows them to inf).
MIN_TIME_STEP = 1e-9


def _check_table(times: np.ndarray, positions: np.ndarray, source: str | None) -> None:
    """The format's rules on the knots (module docstring)."""
    if times.size == 0 or positions.size == 0:
        raise _fail(source, "empty table: give at least 2 (time, sensor distance) knots")
    if times.shape != positions.shape:
        raise _fail(source, f"{times.size} times but {positions.size} sensor distances: "
                            f"give one distance per time")
    if times.size < 2:
        raise _fail(source, f"{times.size} knot: give at least 2 (time, sensor distance) knots")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(positions))):
        raise _fail(source, "times and sensor distances must be finite numbers (no NaN or inf)")
    if times[0] != 0.0 or times[-1] != 1.0:
        raise _fail(source, f"times are normalised exposure time: the first must be 0 and the "
                            f"last 1, got {times[0]:g} .. {times[-1]:g}")
    if np.any(np.diff(times) <= 0):
        k = int(np.argmax(np.diff(times) <= 0))
        raise _fail(source, f"times must be strictly increasing (knot {k + 1}: "
                            f"{times[k + 1]:g} after {times[k]:g})")
    if np.min(np.diff(times)) < MIN_TIME_STEP:
        k = int(np.argmin(np.diff(times)))
        raise _fail(source, f"times {times[k]:g} and {times[k + 1]:g} (knots {k} and {k + 1}) "
                            f"are closer than {MIN_TIME_STEP:g} of the exposure: the stage's "
                            f"velocity between them is not a number a sweep can have")
    if np.any(positions <= 0):
        raise _fail(source, f"sensor distances must be > 0 mm, got min {positions.min():g}")
    steps = np.diff(positions)
    if not (np.all(steps > 0) or np.all(steps < 0)):
        k = int(np.argmax(steps * np.sign(steps[0]) <= 0)) if steps[0] != 0 else 0
        raise _fail(source, f"sensor distances must be strictly monotonic (the stage never "
                            f"stops or reverses during the exposure); knot {k + 1} "
                            f"({positions[k + 1]:g} mm) after {positions[k]:g} mm")


def _check_exposure(exposure_s, source: str | None) -> float | None:
    if exposure_s is None:
        return None
    if isinstance(exposure_s, bool) or not isinstance(exposure_s, (int, float)):
        raise _fail(source, f"exposure_s must be a number of seconds or null, got {exposure_s!r}")
    x = float(exposure_s)
    if not (math.isfinite(x) and x > 0):
        raise _fail(source, f"exposure_s must be a finite number of seconds > 0, got {exposure_s!r}")
    return x


def motion_file_text(profile: MotionProfile, *, exposure_s: float | None,
                     provenance: dict) -> str:
    """The JSON text of a motion file for ``profile`` (any kind: it is tabulated).

    A linear profile is written as its 2 knots, a tabulated one as its knots, a
    trapezoidal one as 256 chords per ramp (:meth:`MotionProfile.segments`).

    Parameters
    ----------
    profile : MotionProfile
        The motion, any kind (it is written tabulated).
    exposure_s : float or None
        The exposure it was designed for, s (finite, > 0), or None for a shape only.
    provenance : dict
        What made it, JSON-serialisable with finite numbers.

    Raises
    ------
    SetupError
        If the profile breaks the format's rules (not strictly monotonic) or
        ``exposure_s`` / ``provenance`` are not valid.
    """
    if not isinstance(profile, MotionProfile):
        raise TypeError(f"profile: expected a MotionProfile, got {type(profile).__name__}")
    times, positions = profile.segments(_RAMP_CHORDS)
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float)
    times = (times - times[0]) / (times[-1] - times[0])
    times[0], times[-1] = 0.0, 1.0
    _check_table(times, positions, None)
    exposure = _check_exposure(exposure_s, None)
    if not isinstance(provenance, dict):
        raise _fail(None, f"provenance must be a dict, got {type(provenance).__name__}")
    doc = {"format": FORMAT, "version": VERSION, "times": times.tolist(),
           "sensor_distances_mm": positions.tolist(), "exposure_s": exposure,
           "provenance": provenance}
    try:
        return json.dumps(doc, indent=1, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise _fail(None, f"provenance must be JSON-serialisable with finite numbers ({exc})") \
            from None


def _reject_constant(name: str):
    raise ValueError(f"{name} is not a number: times and sensor distances must be finite")


def parse_motion_file(text: str, *, source: str | None = None) -> MotionFile:
    """Validate the JSON text of a motion file (format in the module docstring).

    Parameters
    ----------
    text : str
        The file's JSON text.
    source : str, optional
        Where it came from (a path), named by the messages and kept as
        :attr:`MotionFile.source`.

    Raises
    ------
    SetupError
        One line naming ``source`` and what is wrong: not JSON, another format or
        version, a missing or unknown key, an empty or short table, NaN or inf, times
        not normalised or not increasing, distances not monotonic.
    """
    try:
        doc = json.loads(text, parse_constant=_reject_constant)
    except ValueError as exc:
        raise _fail(source, f"not valid JSON ({str(exc).splitlines()[0]})") from None
    except RecursionError:
        raise _fail(source, "not a motion file: JSON nested deeper than Python's parser "
                            "goes") from None
    if not isinstance(doc, dict):
        raise _fail(source, f"expected a JSON object, got {type(doc).__name__}")
    if doc.get("format") != FORMAT:
        raise _fail(source, f"format must be {FORMAT!r}, got {doc.get('format')!r}")
    if doc.get("version") != VERSION or isinstance(doc.get("version"), bool):
        raise _fail(source, f"version {doc.get('version')!r} is not supported (this mitsweep "
                            f"reads version {VERSION})")
    missing = [k for k in _REQUIRED if k not in doc]
    if missing:
        raise _fail(source, f"missing key(s) {', '.join(missing)}")
    unknown = sorted(set(doc) - _KEYS)
    if unknown:
        raise _fail(source, f"unknown key(s) {', '.join(unknown)}; allowed: "
                            f"{', '.join(sorted(_KEYS))}")
    arrays = []
    for key in ("times", "sensor_distances_mm"):
        value = doc[key]
        if not isinstance(value, list) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
            raise _fail(source, f"{key} must be a list of numbers")
        try:
            arrays.append(np.asarray(value, dtype=float))
        except OverflowError:
            raise _fail(source, f"{key}: a number too large for a float (at most "
                                f"{np.finfo(float).max:.3g})") from None
    times, positions = arrays
    _check_table(times, positions, source)
    exposure = _check_exposure(doc.get("exposure_s"), source)
    provenance = doc.get("provenance", {})
    if provenance is None:
        provenance = {}
    if not isinstance(provenance, dict):
        raise _fail(source, f"provenance must be a JSON object, got {type(provenance).__name__}")
    return MotionFile(profile=MotionProfile.tabulated(times, positions), exposure_s=exposure,
                      provenance=provenance, source=source)


def load_motion_file(path: str | os.PathLike) -> MotionFile:
    """Read and validate a motion-profile file.

    Parameters
    ----------
    path : str or os.PathLike
        The JSON file (UTF-8), a regular file.

    Raises
    ------
    SetupError
        The file breaks the format (:func:`parse_motion_file`).
    OSError
        The file cannot be read.
    """
    p = require_regular_file(path, "motion-profile file")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise _fail(str(p), "not a text (UTF-8 JSON) file") from None
    return parse_motion_file(text, source=str(p))


def save_motion_file(path: str | os.PathLike, profile: MotionProfile, *,
                     exposure_s: float | None, provenance: dict) -> Path:
    """Write ``profile`` as a motion-profile file, atomically.

    The text is written to a temporary file beside ``path``, flushed and renamed over
    it: an interrupted write never leaves a partial file or removes an earlier one.
    Whether ``path`` may be replaced is the caller's decision (the command line refuses
    an output that names one of its inputs, :func:`mitsweep.cli.common.check_outputs`).

    Parameters
    ----------
    path : str or os.PathLike
        The file to write; its folder must exist.
    profile : MotionProfile
        The motion, any kind (it is written tabulated).
    exposure_s : float or None
        The exposure it was designed for, s (finite, > 0), or None for a shape only.
    provenance : dict
        What made it, JSON-serialisable with finite numbers.

    Returns
    -------
    Path
        ``path``.
    """
    text = motion_file_text(profile, exposure_s=exposure_s, provenance=provenance)
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".json", dir=parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, p)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
    return p


def stage_kinematics(profile: MotionProfile, exposure_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Stage velocity on each interval and acceleration at each inner knot.

    Parameters
    ----------
    profile : MotionProfile
        Any kind (tabulated from its segments).
    exposure_s : float
        Exposure T, s.

    Returns
    -------
    velocity_mm_s : (n − 1,) ndarray
        ``v_j = Δi_j / (Δt_j T)``, signed.
    acceleration_mm_s2 : (n − 2,) ndarray
        ``a_j = (v_{j+1} − v_j) / (min(Δt_j, Δt_{j+1}) T)`` (module docstring).
    """
    T = float(exposure_s)
    if not (math.isfinite(T) and T > 0):
        raise ValueError(f"exposure_s: must be a finite number > 0 s, got {exposure_s!r}")
    t, p = profile.segments(_RAMP_CHORDS)
    dt = np.diff(np.asarray(t, dtype=float)) * T
    v = np.diff(np.asarray(p, dtype=float)) / dt
    a = np.diff(v) / np.minimum(dt[:-1], dt[1:])
    return v, a


def check_motion_file(mf: MotionFile, setup: Setup, *, exposure_s: float | None = None
                     ) -> MotionFile:
    """Refuse a motion file this setup cannot run, before anything moves or is traced.

    Checks that every sensor distance is beyond the lens focal length (a span that
    crosses it has no image), that the span fits in ``rig.travel``, and, when an
    exposure is known (``exposure_s``, else the file's), that it lies within
    ``rig.min_exposure_s .. rig.max_exposure_s`` and that the stage can follow the
    profile: ``|v_j| <= rig.max_velocity`` and ``|a_j| <= rig.acceleration``
    (:func:`stage_kinematics`).

    Parameters
    ----------
    mf : MotionFile
        The motion file, as read.
    setup : mitsweep.config.Setup
        Its lens focal length and rig limits (``travel``, ``max_velocity``,
        ``acceleration``, ``min_exposure_s``, ``max_exposure_s``).
    exposure_s : float, optional
        The exposure it will run at, s (default: the file's own; with neither, the
        exposure and stage-following checks are skipped).

    Returns
    -------
    MotionFile
        ``mf``, unchanged.

    Raises
    ------
    SetupError
        One line naming the file, the limit and the value.
    """
    src = mf.source
    lo, hi = mf.profile.span
    f = setup.lens.focal_length
    if lo <= f:
        raise _fail(src, f"sensor distances {lo:g} .. {hi:g} mm reach the lens focal length "
                         f"({f:g} mm): every distance must be > {f:g} mm")
    rig = setup.rig
    if hi - lo > rig.travel:
        raise _fail(src, f"sensor travel {hi - lo:g} mm exceeds rig.travel ({rig.travel:g} mm)")
    T = mf.exposure_s if exposure_s is None else float(exposure_s)
    if T is None:
        return mf
    if not rig.min_exposure_s <= T <= rig.max_exposure_s:
        raise _fail(src, f"exposure {T:g} s is outside the camera's rig.min_exposure_s .. "
                         f"rig.max_exposure_s ({rig.min_exposure_s:g} .. "
                         f"{rig.max_exposure_s:g} s)")
    v, a = stage_kinematics(mf.profile, T)
    vmax = float(np.max(np.abs(v)))
    if vmax > rig.max_velocity * (1 + _LIMIT_RTOL):
        j = int(np.argmax(np.abs(v)))
        raise _fail(src, f"the stage cannot follow it: {vmax:.4g} mm/s on interval {j} "
                         f"(t = {mf.profile.times[j]:.4g} .. {mf.profile.times[j + 1]:.4g}) "
                         f"exceeds rig.max_velocity ({rig.max_velocity:g} mm/s) at "
                         f"exposure {T:g} s")
    if a.size:
        amax = float(np.max(np.abs(a)))
        if amax > rig.acceleration * (1 + _LIMIT_RTOL):
            j = int(np.argmax(np.abs(a)))
            raise _fail(src, f"the stage cannot follow it: {amax:.4g} mm/s^2 at knot {j + 1} "
                             f"(t = {mf.profile.times[j + 1]:.4g}) exceeds rig.acceleration "
                             f"({rig.acceleration:g} mm/s^2) at exposure {T:g} s")
    return mf
