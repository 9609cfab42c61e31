"""``mitsweep ipsf``: one traced PSF/IPSF, or a bank of IPSFs, with the Dr.Jit tracer.

A thin wrapper over :func:`mitsweep.workflows.trace_ipsf` and
:func:`mitsweep.workflows.trace_ipsf_bank`.
"""

from __future__ import annotations

import argparse
import math
import sys

from ..workflows.ipsf import trace_ipsf, trace_ipsf_bank
from .common import (UsageError, depth_mm, number_type, positive_float, positive_int,
                     print_json)
from .motion import add_motion_argument

NAME = "ipsf"
HELP = ("trace the integrated PSF of a point source over the focal sweep (or a PSF at one "
        "sensor distance, or a radial/grid IPSF bank) with the Dr.Jit tracer")


_finite = number_type(float, math.isfinite, "a number", "a finite number", "finite")


def _radius(text: str) -> float:
    x = _finite(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 mm, got {text}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (see scenes/)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--point", type=_finite, nargs=2, metavar=("U", "V"),
                       help="image point, upright mm at the reference (mid-sweep) sensor "
                            "distance (default: the image centre)")
    where.add_argument("--radius", type=_radius, metavar="MM",
                       help="image point at this radius (mm) and --angle")
    p.add_argument("--angle", type=_finite, default=0.0, metavar="DEG",
                   help="polar angle of --radius, degrees counter-clockwise from +u (0)")
    p.add_argument("--bank", choices=["radial", "grid"],
                   help="compute a bank instead of one IPSF (radial: untilted mirrors)")
    p.add_argument("--radii", type=positive_int, default=19, help="radial bank size (19)")
    p.add_argument("--grid", type=positive_int, nargs=2, default=(9, 9),
                   metavar=("ROWS", "COLS"), help="grid bank shape (9 9)")
    p.add_argument("--depth", type=depth_mm, nargs="+", default=[500.0], metavar="MM",
                   help="depth(s) l of the source from the mirror, mm (500; inf allowed); "
                        "several for one point: one IPSF per depth, each -o / --plot file "
                        "named per depth (FILE_l500mm.exr, FILE_linf.exr)")
    p.add_argument("--sensor-distance", type=positive_float, metavar="MM",
                   help="a PSF at this one sensor distance instead of the sweep's IPSF")
    p.add_argument("--method", choices=["exact", "continuous", "planes"], default="exact",
                   help="exact: each ray's whole sweep deposited as its segment (default); "
                        "continuous: stratified sweep times per ray; planes: the paper's "
                        "N-plane sum")
    p.add_argument("--planes", type=positive_int, default=16,
                   help="focal planes of --method planes (16, at most 64)")
    p.add_argument("--time-samples", type=positive_int, default=4,
                   help="stratified times per ray of --method continuous (4, at most 64)")
    p.add_argument("--motion-table", metavar="CSV",
                   help="measured stage motion (two columns: time, sensor distance mm) for "
                        "sweep.profile = 'tabulated'")
    add_motion_argument(p)
    p.add_argument("--rays", type=positive_int, default=1_000_000,
                   help="rays per IPSF (1000000)")
    p.add_argument("--kernel-size", type=positive_int, default=31,
                   help="kernel size K, odd, smaller than the sensor's smaller side (31)")
    p.add_argument("--seed", type=int, default=0, help="sample-stream seed (0)")
    p.add_argument("--float64", action="store_true", help="trace in float64 (reference)")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="write .npz (bank format) or .exr (layered, with metadata)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="thumbnails and radial/tangential cross-sections (paper Fig. 3-5)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    common = dict(depths=args.depth, method=args.method, planes=args.planes,
                  time_samples=args.time_samples, motion=args.motion,
                  motion_table=args.motion_table, rays=args.rays,
                  kernel_size=args.kernel_size, seed=args.seed, output=args.output,
                  plot=args.plot)
    if args.bank:
        if args.point is not None or args.radius is not None or args.sensor_distance:
            raise UsageError("--bank computes its own points: drop --point, --radius and "
                             "--sensor-distance")
        result = trace_ipsf_bank(args.setup, kind=args.bank, radii=args.radii,
                                 grid=tuple(args.grid), progress=True, **common)
    else:
        result = trace_ipsf(args.setup, point=args.point, radius=args.radius,
                            angle_deg=args.angle, sensor_distance=args.sensor_distance,
                            float64=args.float64, **common)
    return _report(args, result.summary)


def _report(args, out: dict) -> int:
    if args.json:
        print_json(out)
        return 0
    _print_table({k: v for k, v in out.items() if k != "ipsfs"})
    for entry in out.get("ipsfs", []):
        sys.stdout.write(f"-- depth {entry['depth_mm']:g} mm\n")
        _print_table(entry)
    return 0


def _print_table(out: dict) -> None:
    skip = {"motion", "box_mm", "ellipse_mm", "mirror_point_mm", "points_uv_mm", "version"}
    for key, value in out.items():
        if key in skip:
            continue
        if isinstance(value, float):
            value = f"{value:.6g}"
        elif isinstance(value, (tuple, list)) and value and isinstance(value[0], float):
            value = "(" + ", ".join(f"{x:.6g}" for x in value) + ")"
        sys.stdout.write(f"{key:<30s} {value}\n")
