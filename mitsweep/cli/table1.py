"""``mitsweep table1``: the paper's Table 1 (V_avg and kurtosis per sweep range); a thin
wrapper over :func:`mitsweep.workflows.reproduce_table1`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.paper import reproduce_table1
from .common import positive_int, print_json

NAME = "table1"
HELP = ("reproduce the paper's Table 1: depth variance V_avg (Eq. 3) and IPSF kurtosis at "
        "the image centre and periphery for several sweep ranges, and a conventional camera")


def _range(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN:MAX focus distances in mm, "
                                         f"got {text!r}") from None
    if not (0 < lo < hi):
        raise argparse.ArgumentTypeError(f"need 0 < MIN < MAX, got {text!r}")
    return lo, hi


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file of an untilted mirror (e.g. scenes/sphere.toml)")
    p.add_argument("--ranges", type=_range, nargs="+", metavar="MIN:MAX",
                   help="sweep ranges as focus distances, mm (default: the paper's three, "
                        "scaled to the setup's optimal range, and the optimal range)")
    p.add_argument("--rays", type=positive_int, default=1_000_000, help="rays per IPSF (1e6)")
    p.add_argument("--radii", type=positive_int, default=19, help="field points (19)")
    p.add_argument("--kernel-size", type=positive_int, default=63, help="kernel size (63)")
    p.add_argument("--seed", type=int, default=0, help="sample-stream seed (0)")
    p.add_argument("--plot", metavar="FILE.png", help="bar charts of the table")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    result = reproduce_table1(args.setup, ranges=args.ranges, radii=args.radii,
                              rays=args.rays, kernel_size=args.kernel_size, seed=args.seed,
                              plot=args.plot, progress=True).value
    if args.json:
        print_json(result)
        return 0
    w = sys.stdout.write
    w(f"Table 1 — {result['setup']}: V_avg (Eq. 3, eps = {result['epsilon']:g}, W = 1/|f|) "
      f"and kurtosis (Gaussian = 3), depths {', '.join(f'{d / 1000:g}' for d in result['depths_mm'])} m\n")
    w(f"{'sweep range [mm]':<18s} {'V_avg':>10s}   {'centre tan':>10s} {'centre rad':>10s}"
      f"   {'periph tan':>10s} {'periph rad':>10s}\n")
    for r in result["rows"]:
        k = r["kurtosis"]
        w(f"{r['focus_min_mm']:6.1f} - {r['focus_max_mm']:6.1f}    {r['v_avg']:10.3g}   "
          f"{k['center']['tangential']:10.2f} {k['center']['radial']:10.2f}   "
          f"{k['periphery']['tangential']:10.2f} {k['periphery']['radial']:10.2f}\n")
    c = result["conventional"]
    w(f"{'conventional':<18s} {c['v_avg']:10.3g}   (no mirror, no sweep, focused at "
      f"{c['focus_distance_mm']:.0f} mm)\n")
    return 0
