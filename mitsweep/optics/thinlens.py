"""The thin lens, 1/f = 1/i + 1/o (paper Eq. 1). All distances in mm."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["image_distance", "object_distance", "magnification"]


def image_distance(focal_length: float, object_distance: ArrayLike) -> float | NDArray[np.float64]:
    """Lens-to-sensor distance i that focuses an object at distance o (o > f).

    ``i = f o / (o − f)``; ``o = inf`` gives ``i = f``.

    Parameters
    ----------
    focal_length : float
        Focal length f, mm.
    object_distance : array_like
        Object distance o, mm (``inf`` allowed).

    Raises
    ------
    ValueError
        If any object distance is at or inside the focal length (no real image).
    """
    o = np.asarray(object_distance, dtype=float)
    if np.any(~(o > focal_length)):
        bad = float(np.min(o))
        raise ValueError(f"focus distance {bad:g} mm is at or inside the lens focal length "
                         f"({focal_length:g} mm): no real image; it must be > {focal_length:g} mm")
    with np.errstate(invalid="ignore"):
        i = np.where(np.isinf(o), focal_length, focal_length * o / (o - focal_length))
    return i if i.ndim else float(i)


def object_distance(focal_length: float, image_distance: ArrayLike) -> float | NDArray[np.float64]:
    """Object distance o in focus for a sensor at distance i (i > f): ``o = f i / (i − f)``.

    Parameters
    ----------
    focal_length : float
        Focal length f, mm.
    image_distance : array_like
        Lens-to-sensor distance i, mm (> f).
    """
    i = np.asarray(image_distance, dtype=float)
    if np.any(~(i > focal_length)):
        bad = float(np.min(i))
        raise ValueError(f"sensor distance {bad:g} mm is at or inside the lens focal length "
                         f"({focal_length:g} mm); it must be > {focal_length:g} mm")
    o = focal_length * i / (i - focal_length)
    return o if o.ndim else float(o)


def magnification(focal_length: float, object_distance: ArrayLike) -> float | NDArray[np.float64]:
    """Lateral magnification i/o of an object at distance o.

    Parameters
    ----------
    focal_length : float
        Focal length f, mm.
    object_distance : array_like
        Object distance o, mm (> f).
    """
    return image_distance(focal_length, object_distance) / np.asarray(object_distance, dtype=float)
