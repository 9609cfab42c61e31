"""The ``focalsweep`` sensor's motion, read from the plugin's properties (no Mitsuba).

What the plugin module (:mod:`mitsweep.render.focalsweep`, one class per Mitsuba
variant) and the variant-free modules share: the plugin's name, the kinds of motion and
their differentiable parameters, the error raised for a gradient that would be lost,
and :func:`motion_from_properties`, which validates the motion and turns it into plain
NumPy tables (the plugin converts them to the variant's array type).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..optics.motion import MotionProfile
from .plugin_names import FOCALSWEEP as PLUGIN_NAME

__all__ = ["PLUGIN_NAME", "MOTION_TABLE_SIZE", "DIFFERENTIABLE", "NotDifferentiableError",
           "SensorMotion", "motion_from_properties", "motion_table"]

#: The trapezoidal motion's normalised shape is resampled on this many uniform intervals
#: of t and interpolated linearly in the kernel: error ``v h² / (8 a)`` on its ramps
#: (h = 1/65536). Tabulated motions are evaluated exactly (linear between their knots).
MOTION_TABLE_SIZE = 65536

#: Differentiable parameters (``mi.traverse`` keys) for each kind of motion.
DIFFERENTIABLE = {"fixed": ("sensor_distance",), "linear": ("sensor_start", "sensor_end"),
                  "trapezoidal": ("sensor_start", "sensor_end"), "tabulated": ("positions",)}


class NotDifferentiableError(ValueError):
    """A gradient was asked of a ``focalsweep`` parameter that is not differentiable, or
    of an integrator that would return zero for it."""


@dataclass(frozen=True)
class SensorMotion:
    """A validated sensor motion: ``kind`` (a key of :data:`DIFFERENTIABLE`), its
    ``start`` and ``end`` distances (mm), and for ``trapezoidal`` the normalised
    ``shape`` g on :data:`MOTION_TABLE_SIZE` uniform intervals (``i = start + (end −
    start) g(t)``), for ``tabulated`` the normalised ``times`` and the ``positions``.

    Attributes
    ----------
    kind : {"fixed", "linear", "trapezoidal", "tabulated"}
        The kind of motion.
    start, end : float
        Sensor distance at shutter open and close, mm (equal for ``fixed``).
    shape : (MOTION_TABLE_SIZE + 1,) ndarray or None
        ``trapezoidal`` only: g(t) at ``t = k / MOTION_TABLE_SIZE``, from 0 to 1.
    times : (n,) ndarray or None
        ``tabulated`` only: the knots' normalised times, rising from 0 to 1.
    positions : (n,) ndarray or None
        ``tabulated`` only: the sensor distance at each knot, mm.
    """

    kind: str
    start: float
    end: float
    shape: np.ndarray | None = None
    times: np.ndarray | None = None
    positions: np.ndarray | None = None

    @property
    def span(self) -> tuple[float, float]:
        """Least and greatest sensor distance, mm."""
        if self.positions is not None:  # tabulated
            return float(self.positions.min()), float(self.positions.max())
        return min(self.start, self.end), max(self.start, self.end)


def _floats(value: Any, name: str) -> np.ndarray:
    """A 1-D float array from a TensorXf/array or a whitespace/comma separated string."""
    if isinstance(value, str):
        parts = [p for p in re.split(r"[\s,]+", value.strip()) if p]
        try:
            return np.array([float(p) for p in parts], dtype=float)
        except ValueError:
            raise ValueError(f"focalsweep: {name} must be a list of numbers, got {value!r}") \
                from None
    return np.asarray(value, dtype=float).ravel()


def motion_table(motion: MotionProfile, n: int = MOTION_TABLE_SIZE) -> np.ndarray:
    """Sensor distances (mm) of a :class:`~mitsweep.optics.motion.MotionProfile` at
    ``n + 1`` uniform normalised times ``k / n`` (the kernel interpolates linearly).

    Parameters
    ----------
    motion : MotionProfile
        The stage's motion over the exposure.
    n : int, optional
        Intervals of the table (default :data:`MOTION_TABLE_SIZE`).
    """
    return np.asarray(motion.sensor_distance(np.linspace(0.0, 1.0, n + 1)), dtype=float)


def motion_from_properties(props: Any) -> SensorMotion:
    """The motion a ``focalsweep`` plugin's properties (``mi.Properties`` or a mapping
    with ``in`` and ``get``) describe; ValueError naming the fault otherwise.

    Parameters
    ----------
    props : mi.Properties or mapping
        The plugin's properties: ``sensor_distance`` (mm), or ``sensor_start`` and
        ``sensor_end`` (mm) with ``profile`` (``linear``, the default; ``trapezoidal``
        with ``accel_fraction``, default 0.1; ``tabulated`` with ``times`` and
        ``positions``, lists of numbers or strings of them).
    """
    has_fixed = ("sensor_distance" in props)
    has_range = ("sensor_start" in props) or ("sensor_end" in props)
    if has_fixed == has_range:
        raise ValueError("focalsweep: give either sensor_distance (fixed) or "
                         "sensor_start and sensor_end (a sweep)")
    if has_fixed:
        i = float(props.get("sensor_distance"))
        return SensorMotion("fixed", i, i)
    if not (("sensor_start" in props) and ("sensor_end" in props)):
        raise ValueError("focalsweep: a sweep needs both sensor_start and sensor_end")
    s, e = float(props.get("sensor_start")), float(props.get("sensor_end"))
    kind = props.get("profile", "linear")
    if kind == "linear":
        return SensorMotion("fixed", s, s) if s == e else SensorMotion("linear", s, e)
    if kind == "trapezoidal":
        mp = MotionProfile.trapezoidal(s, e, float(props.get("accel_fraction", 0.1)))
        # i(t) = s + (e − s) g(t): g depends on accel_fraction alone, so the sweep's
        # ends stay differentiable through the affine map.
        return SensorMotion("trapezoidal", s, e, shape=(motion_table(mp) - s) / (e - s))
    if kind == "tabulated":
        if not (("times" in props) and ("positions" in props)):
            raise ValueError("focalsweep: profile 'tabulated' needs times and positions")
        mp = MotionProfile.tabulated(_floats(props.get("times"), "times"),
                                     _floats(props.get("positions"), "positions"))
        if not (np.isclose(mp.start, s) and np.isclose(mp.end, e)):
            raise ValueError(f"focalsweep: tabulated positions run {mp.start:g} -> "
                             f"{mp.end:g} mm but sensor_start/end are {s:g}, {e:g}")
        return SensorMotion("tabulated", mp.start, mp.end,
                            times=np.asarray(mp.times, dtype=float),
                            positions=np.asarray(mp.positions, dtype=float))
    raise ValueError(f"focalsweep: profile must be linear, trapezoidal or tabulated, "
                     f"got {kind!r}")
