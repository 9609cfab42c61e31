"""Pixels ↔ sensor millimetres: the image convention, written once.

Sensor-plane coordinates ``(u, v)`` are millimetres from the optical axis, ``u`` to the
right and ``v`` up in the upright image; pixel indices ``(row, col)`` count from the
top-left pixel (0, 0), with integer indices at pixel centres. The optical axis meets the
sensor at the image centre, pixel ``(H/2 − 1/2, W/2 − 1/2)``:

.. math::

    u = (c + \\tfrac12 - \\tfrac W2)\\,p, \\qquad v = (\\tfrac H2 - r - \\tfrac12)\\,p

for pixel pitch ``p`` (mm). Arrays broadcast; ``shape`` is an image's ``(H, W)`` (note that a
setup's ``sensor.resolution`` is ``(W, H)``: use :func:`image_shape`).

A real camera's mirror axis rarely meets the sensor exactly at its centre. Every
function here takes an optional ``center_offset_px = (drow, dcol)``, the axis's offset
from the image centre in pixels (a setup's ``sensor.center_offset_px``, measured by
``mitsweep calibrate``; :func:`center_offset_of` reads it): the axis is then at
``(H/2 − 1/2 + drow, W/2 − 1/2 + dcol)`` and ``(u, v)`` stay millimetres from it.
``None`` (the default) is the image centre.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Setup
from ..deprecation import renamed_keywords

__all__ = ["image_shape", "center_offset_of", "optical_center_px", "pixel_to_sensor",
           "sensor_to_pixel"]


def image_shape(setup: Setup) -> tuple[int, int]:
    """``(H, W)`` of a setup's images (its ``sensor.resolution`` is ``(W, H)``).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``sensor.resolution``, ``(W, H)`` pixels.
    """
    W, H = setup.sensor.resolution
    return int(H), int(W)


def center_offset_of(setup: Setup) -> tuple[float, float] | None:
    """A setup's ``sensor.center_offset_px`` (``(drow, dcol)`` px), or None: the centre.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``sensor`` section (one without ``center_offset_px`` gives None).
    """
    return getattr(setup.sensor, "center_offset_px", None)


def optical_center_px(shape: tuple[int, ...],
                      center_offset_px: tuple[float, float] | None = None) -> tuple[float, float]:
    """``(row, col)`` of the optical axis on an image of ``shape = (H, W[, …])``,
    moved by ``center_offset_px = (drow, dcol)`` pixels when given.

    Parameters
    ----------
    shape : tuple of int
        The image's shape, (H, W) or (H, W, C).
    center_offset_px : tuple of float, optional
        ``(drow, dcol)``: how far the optical axis sits from the image centre, pixels
        (a calibrated camera's ``[sensor] center_offset_px``).
    """
    H, W = shape[0], shape[1]
    drow, dcol = (0.0, 0.0) if center_offset_px is None else center_offset_px
    return H / 2.0 - 0.5 + float(drow), W / 2.0 - 0.5 + float(dcol)


@renamed_keywords(pitch="pixel_pitch")
def sensor_to_pixel(u: ArrayLike, v: ArrayLike, shape: tuple[int, ...], pixel_pitch: float, *,
                    center_offset_px: tuple[float, float] | None = None
                   ) -> tuple[float, float] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(row, col)`` (fractional) of sensor point ``(u, v)`` mm, pixel pitch
    ``pixel_pitch`` mm.

    Parameters
    ----------
    u, v : array_like
        Upright sensor coordinates, mm (u right, v up).
    shape : tuple of int
        The image's shape, (H, W[, C]).
    pixel_pitch : float
        Pixel pitch, mm (formerly ``pitch``, still accepted with a warning).
    center_offset_px : tuple of float, optional
        The optical axis's offset from the image centre, ``(drow, dcol)`` pixels.
    """
    r0, c0 = optical_center_px(shape, center_offset_px)
    u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
    return _pair(r0 - v / pixel_pitch, c0 + u / pixel_pitch)


@renamed_keywords(pitch="pixel_pitch")
def pixel_to_sensor(row: ArrayLike, col: ArrayLike, shape: tuple[int, ...], pixel_pitch: float, *,
                    center_offset_px: tuple[float, float] | None = None
                   ) -> tuple[float, float] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Sensor point ``(u, v)`` mm of pixel ``(row, col)`` (centres at integers).

    Parameters
    ----------
    row, col : array_like
        Pixel coordinates (fractional allowed; pixel centres at integers).
    shape : tuple of int
        The image's shape, (H, W[, C]).
    pixel_pitch : float
        Pixel pitch, mm (formerly ``pitch``, still accepted with a warning).
    center_offset_px : tuple of float, optional
        The optical axis's offset from the image centre, ``(drow, dcol)`` pixels.
    """
    r0, c0 = optical_center_px(shape, center_offset_px)
    row, col = np.asarray(row, dtype=float), np.asarray(col, dtype=float)
    return _pair((col - c0) * pixel_pitch, (r0 - row) * pixel_pitch)


def _pair(a: np.ndarray, b: np.ndarray
         ) -> tuple[float, float] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two floats for scalar inputs, else two arrays broadcast to one shape."""
    if a.ndim == 0 and b.ndim == 0:
        return float(a), float(b)
    a, b = np.broadcast_arrays(a, b)
    return a.copy(), b.copy()
