"""``mitsweep unwarp``: the panorama of a catadioptric image, exact from the mirror geometry."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from .common import (number_type, UsageError, add_photo_arguments, check_outputs, load_setup_arg,
                     photo_options, positive_float, positive_int, print_json)

NAME = "unwarp"
HELP = ("unwarp a catadioptric image (an EDOF image or a photo) into a cylindrical or "
        "equirectangular panorama, computed from the mirror geometry (the chief ray of "
        "every pixel)")

OUTPUT_SUFFIXES = (".exr", ".tif", ".tiff", ".png")


_elevation = number_type(float, lambda x: -90.0 <= x <= 90.0, "degrees",
                         "in [-90, 90] degrees", "elevation")


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..optics.panorama import CYLINDRICAL_TOP_DEG, PROJECTIONS, UP_CHOICES

    p.add_argument("image", help="image: EXR (an EDOF image from `mitsweep deconvolve`, or "
                                 "a render), RAW, TIFF, PNG or JPEG")
    p.add_argument("--setup", metavar="SETUP.toml",
                   help="the setup of the image (default: the one in its metadata)")
    p.add_argument("--projection", choices=PROJECTIONS, required=True,
                   help="cylindrical: rows linear in tan(elevation); equirectangular: "
                        "rows linear in elevation")
    p.add_argument("--up", choices=UP_CHOICES, default="camera",
                   help="which way is world-up in the panorama: toward the camera (default: "
                        "a camera above the mirror, looking down at it) or away from it (a "
                        "camera below the mirror, looking up: the panorama turned by 180 "
                        "degrees, still unmirrored)")
    p.add_argument("--size", type=positive_int, nargs=2, metavar=("W", "H"),
                   help="panorama size in pixels (default: one column per pixel of the "
                        "mirror image's outer circumference, rows at the same angular step)")
    p.add_argument("--elevation", type=_elevation, nargs=2, metavar=("LOW", "HIGH"),
                   help="elevations of the panorama's bottom and top, degrees above the "
                        "plane through the mirror vertex normal to the camera axis "
                        "(default: everything the image sees; cylindrical: at most "
                        f"{CYLINDRICAL_TOP_DEG:g})")
    p.add_argument("--center", type=float, nargs=2, metavar=("ROW", "COL"),
                   help="pixel position of the camera axis (default: the image's recorded "
                        "centre, else the setup's calibrated one, else the image centre)")
    add_photo_arguments(p)
    p.add_argument("--sensor-distance", type=positive_float, metavar="MM",
                   help="sensor distance of the image's pixel grid, mm (default: the one "
                        "recorded in the image, else the setup's reference distance)")
    p.add_argument("--out", required=True, metavar="PANO",
                   help="panorama: .exr (linear, with a mask.Y layer and provenance) or "
                        ".tif/.tiff/.png (16-bit sRGB)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


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


def run(args) -> int:
    from .. import __version__
    from ..config import setup_from_dict, setup_to_dict
    from ..io import write_exr
    from ..io.camera import read_camera_image, write_display_image
    from ..optics.panorama import panorama_map, unwarp
    from ..resources import check_allocation

    src, out = Path(args.image), Path(args.out)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such image file")
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise UsageError(f"--out must be an {', '.join(OUTPUT_SUFFIXES)} file, got {out}")
    check_outputs([src, args.setup], {"--out": out})
    if args.elevation is not None and not args.elevation[0] < args.elevation[1]:
        raise UsageError(f"--elevation {args.elevation[0]:g} {args.elevation[1]:g}: LOW must "
                         f"be below HIGH")
    if args.size is not None and min(args.size) < 2:
        raise UsageError(f"--size {args.size[0]} {args.size[1]}: at least 2 x 2")
    # its warnings are logged once the photo is accepted: a refusal is the only line
    photo = read_camera_image(src, **photo_options(args), log_warnings=False)
    meta = photo.meta.get("exr_header") or {}
    if args.setup is not None:
        setup = load_setup_arg(args.setup)
    elif isinstance(meta.get("setup"), dict):
        setup = setup_from_dict(meta["setup"])
    else:
        raise UsageError(f"{src}: no setup in its metadata; give --setup")
    H, W = photo.shape
    pitch = photo.pixel_pitch or _number(meta, "pixel_pitch") or setup.sensor.pixel_pitch
    if args.sensor_distance is not None and args.sensor_distance <= setup.lens.focal_length:
        raise UsageError(f"--sensor-distance {args.sensor_distance:g}: must exceed the lens "
                         f"focal length, {setup.lens.focal_length:g} mm (a camera focused "
                         f"at any depth has its sensor beyond it)")
    i = args.sensor_distance or _number(meta, "reference_sensor_distance")
    center = args.center
    if center is None and isinstance(meta.get("center_rc"), list):
        center = tuple(float(x) for x in meta["center_rc"])
    if center is not None and not (0 <= center[0] < H and 0 <= center[1] < W):
        raise UsageError(f"--center {center[0]:g} {center[1]:g} lies outside the {W}x{H} image")
    t0 = time.perf_counter()
    try:
        pmap = panorama_map(setup, (H, W), projection=args.projection, size=args.size,
                            elevation_deg=args.elevation, pixel_pitch=pitch, center_px=center,
                            sensor_distance=i, up=args.up)
    except ValueError as exc:  # the elevations seen at this distance make no range
        if args.sensor_distance is None or args.elevation is not None or \
                not str(exc).startswith("elevation range"):
            raise
        raise UsageError(f"--sensor-distance {args.sensor_distance:g}: the {W}x{H} frame "
                         f"sees no range of elevations for a {args.projection} panorama at "
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
    result = {"out": str(out), "projection": pmap.projection, "size": list(pmap.size),
              "elevation_deg": [lo, hi], "center_rc": list(pmap.center_px),
              "valid_fraction": float(valid.mean()), "seconds": seconds}
    if args.json:
        print_json(result)
    else:
        sys.stdout.write(f"{out}: {pmap.projection} panorama {pmap.size[0]}x{pmap.size[1]}, "
                         f"elevation {lo:.1f} to {hi:.1f} deg, {100 * valid.mean():.1f}% seen, "
                         f"in {seconds:.2f} s\n")
    return 0
