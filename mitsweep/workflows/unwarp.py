"""Unwarp a catadioptric image into a cylindrical or equirectangular panorama
(``mitsweep unwarp``), computed from the mirror geometry (the chief ray of every pixel,
:func:`mitsweep.optics.panorama.panorama_map`)."""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..config import Setup
from ._base import InputError, WorkflowResult, resolve_setup
from ._paths import check_outputs

__all__ = ["unwarp_image", "OUTPUT_SUFFIXES"]

#: Output suffixes: linear EXR (with a mask layer), or a 16-bit sRGB display image.
OUTPUT_SUFFIXES = (".exr", ".tif", ".tiff", ".png")


def _number(meta: dict, key: str) -> float | None:
    value = meta.get(key)
    if isinstance(value, (int, float)) and not isinstance(value, bool) and \
            math.isfinite(value) and value > 0:
        return float(value)
    return None


def _unwarp_bytes(pmap, image: np.ndarray, out: Path) -> float:
    """Peak memory of making the panorama and writing it, bytes: :func:`unwarp`'s, then
    the panorama kept while the writer makes its copies (EXR: float32 image and mask
    twice; display files: :data:`~mitsweep.io.camera.DISPLAY_BYTES_PER_SAMPLE`)."""
    from ..io.camera import DISPLAY_BYTES_PER_SAMPLE
    from ..optics.panorama import panorama_bytes

    channels = 1 if image.ndim == 2 else int(image.shape[2])
    pixels = float(pmap.size[0]) * float(pmap.size[1])
    writer = pixels * (2 * 4 * (channels + 1) if out.suffix.lower() == ".exr"
                       else DISPLAY_BYTES_PER_SAMPLE * channels)
    return panorama_bytes(pmap.size, image.shape, channels, image.dtype.itemsize) + writer


def unwarp_image(image: str | os.PathLike, out: str | os.PathLike, *, projection: str,
                 setup: Setup | str | os.PathLike | None = None, up: str = "camera",
                 size: tuple[int, int] | None = None,
                 elevation: tuple[float, float] | None = None,
                 center: tuple[float, float] | None = None,
                 sensor_distance: float | None = None, pixel_pitch: float | None = None,
                 white_balance: str = "camera", transfer: str | None = None
                 ) -> WorkflowResult:
    """Unwarp a catadioptric image (an EDOF image or a photo) into a panorama and write it
    (``mitsweep unwarp``).

    Parameters
    ----------
    image : path-like
        EXR (an EDOF image from :func:`restore_photo`, or a render), RAW, TIFF, PNG, JPEG.
    out : path-like
        The panorama: ``.exr`` (linear, with a ``mask.Y`` layer and the provenance) or
        ``.tif``/``.tiff``/``.png`` (16-bit sRGB).
    projection : {"cylindrical", "equirectangular"}
        Rows linear in tan(elevation), or in elevation.
    setup : Setup, path-like or str, optional
        The image's setup (default: the one in its metadata).
    up : {"camera", "away"}
        Which way is world-up in the panorama (see ``mitsweep unwarp --help``).
    size : (int, int), optional
        Panorama size (W, H) in pixels, at least 2 x 2 (default: one column per pixel of
        the mirror image's outer circumference).
    elevation : (float, float), optional
        Elevations of the bottom and top, degrees (default: everything the image sees).
    center : (float, float), optional
        Pixel (row, col) of the camera axis (default: the image's recorded centre, else
        the setup's calibrated one, else the image centre).
    sensor_distance : float, optional
        Sensor distance of the image's pixel grid, mm (default: the recorded one, else
        the setup's reference distance).
    pixel_pitch, white_balance, transfer
        Passed to :func:`mitsweep.io.camera.read_camera_image`.

    Returns
    -------
    WorkflowResult
        ``value``: ``(panorama, valid)``: the panorama, ``(H, W[, C])``, and its boolean
        mask of pixels the image sees. ``provenance``: what the output file carries
        (input, projection, size, up, elevation_deg, center_rc, pixel_pitch,
        sensor_distance, valid_fraction, setup, the columns' and rows' mapping) plus
        ``seconds``. ``summary``: what ``mitsweep unwarp --json`` prints.

    Raises
    ------
    InputError
        A bad option (elevations, size, centre, sensor distance), no setup.
    mitsweep.resources.ResourceError
        A panorama too large for the memory available.

    Examples
    --------
    >>> from mitsweep.workflows import unwarp_image
    >>> r = unwarp_image("edof.exr", "pano.png", projection="cylindrical")  # doctest: +SKIP
    >>> r.value[0].shape[:2] == tuple(reversed(r.summary["size"]))          # doctest: +SKIP
    True
    """
    from ..config import setup_from_dict, setup_to_dict
    from ..io import write_exr
    from ..io.camera import read_camera_image, write_display_image
    from ..optics.panorama import panorama_map, unwarp
    from ..resources import check_allocation

    src, out = Path(image), Path(out)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such image file")
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise InputError(f"--out must be an {', '.join(OUTPUT_SUFFIXES)} file, got {out}")
    setup_path = None if isinstance(setup, Setup) else setup
    check_outputs([src, setup_path], {"--out": out})
    if elevation is not None and not elevation[0] < elevation[1]:
        raise InputError(f"--elevation {elevation[0]:g} {elevation[1]:g}: LOW must "
                         f"be below HIGH")
    if size is not None and min(size) < 2:
        raise InputError(f"--size {size[0]} {size[1]}: at least 2 x 2")
    # its warnings are logged once the photo is accepted: a refusal is the only line
    photo = read_camera_image(src, pixel_pitch=pixel_pitch, white_balance=white_balance,
                              transfer=transfer, log_warnings=False,
                              noise=False)   # no restoration is weighted here
    meta = photo.meta.get("exr_header") or {}
    if setup is not None:
        setup = resolve_setup(setup)
    elif isinstance(meta.get("setup"), dict):
        setup = setup_from_dict(meta["setup"])
    else:
        raise InputError(f"{src}: no setup in its metadata; give --setup")
    H, W = photo.shape
    pitch = photo.pixel_pitch or _number(meta, "pixel_pitch") or setup.sensor.pixel_pitch
    if sensor_distance is not None and sensor_distance <= setup.lens.focal_length:
        raise InputError(f"--sensor-distance {sensor_distance:g}: must exceed the lens "
                         f"focal length, {setup.lens.focal_length:g} mm (a camera focused "
                         f"at any depth has its sensor beyond it)")
    i = sensor_distance or _number(meta, "reference_sensor_distance")
    if center is None and isinstance(meta.get("center_rc"), list):
        rc = [float(x) for x in meta["center_rc"]]
        if len(rc) != 2:
            raise InputError(f"{src}: its metadata's center_rc must be (row, col), got "
                             f"{meta['center_rc']!r}")
        center = (rc[0], rc[1])
    if center is not None and not (0 <= center[0] < H and 0 <= center[1] < W):
        raise InputError(f"--center {center[0]:g} {center[1]:g} lies outside the {W}x{H} image")
    t0 = time.perf_counter()
    try:
        pmap = panorama_map(setup, (H, W), projection=projection, size=size,
                            elevation_deg=elevation, pixel_pitch=pitch, center_px=center,
                            sensor_distance=i, up=up)
    except ValueError as exc:  # the elevations seen at this distance make no range
        if sensor_distance is None or elevation is not None or \
                not str(exc).startswith("elevation range"):
            raise
        raise InputError(f"--sensor-distance {sensor_distance:g}: the {W}x{H} frame "
                         f"sees no range of elevations for a {projection} panorama at "
                         f"that distance; give the sensor distance the image was taken "
                         f"at") from None
    check_allocation(f"panorama {pmap.size[0]}x{pmap.size[1]} written to {out}",
                     _unwarp_bytes(pmap, photo.data, out))
    photo.log_warnings()
    pano, valid = unwarp(photo.data, pmap)
    seconds = time.perf_counter() - t0
    lo, hi = (math.degrees(e) for e in pmap.elevation_range)
    provenance = {
        "command": "unwarp", "version": __version__, "input": str(src),
        "projection": pmap.projection, "size": list(pmap.size), "up": pmap.up,
        "elevation_deg": [lo, hi], "center_rc": list(pmap.center_px),
        "pixel_pitch": pmap.pixel_pitch, "sensor_distance": pmap.sensor_distance,
        "valid_fraction": float(valid.mean()), "setup": setup_to_dict(setup),
        "columns": ("azimuth = 180 - 360 (col + 0.5) / W deg, from world +x toward +y"
                    + ("" if pmap.up == "camera" else ", with col -> W - 1 - col")),
        "rows": ("elevation" if pmap.projection == "equirectangular" else "tan(elevation)")
        + (" linear from top to bottom" if pmap.up == "camera"
           else " linear from bottom to top (up = away from the camera)"),
    }
    if out.suffix.lower() == ".exr":
        write_exr(out, pano.astype(np.float32), channels={"mask.Y": valid.astype(np.float32)},
                  metadata=provenance)
    else:
        write_display_image(out, pano, metadata=provenance)
    summary = {"out": str(out), "projection": pmap.projection, "size": list(pmap.size),
               "elevation_deg": [lo, hi], "center_rc": list(pmap.center_px),
               "valid_fraction": float(valid.mean()), "seconds": seconds}
    return WorkflowResult((pano, valid), dict(provenance, workflow="unwarp_image",
                                              seconds=seconds), summary)
