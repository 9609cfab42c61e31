"""``mitsweep unwarp``: the panorama of a catadioptric image, exact from the mirror geometry;
a thin wrapper over :func:`mitsweep.workflows.unwarp_image`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.unwarp import unwarp_image
from .common import (add_photo_arguments, number_type, positive_float, positive_int,
                     print_json)

NAME = "unwarp"
HELP = ("unwarp a catadioptric image (an EDOF image or a photo) into a cylindrical or "
        "equirectangular panorama, computed from the mirror geometry (the chief ray of "
        "every pixel)")


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


def run(args) -> int:
    result = unwarp_image(
        args.image, args.out, projection=args.projection, setup=args.setup, up=args.up,
        size=args.size, elevation=args.elevation, center=args.center,
        sensor_distance=args.sensor_distance, pixel_pitch=args.pixel_pitch,
        white_balance=args.white_balance, transfer=args.transfer)
    s = result.summary
    if args.json:
        print_json(s)
    else:
        lo, hi = s["elevation_deg"]
        sys.stdout.write(f"{s['out']}: {s['projection']} panorama {s['size'][0]}x{s['size'][1]}, "
                         f"elevation {lo:.1f} to {hi:.1f} deg, {100 * s['valid_fraction']:.1f}% "
                         f"seen, in {s['seconds']:.2f} s\n")
    return 0
