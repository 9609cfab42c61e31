"""``mitsweep render``: render a setup's scene through the mirror with Mitsuba 3; a thin
wrapper over :func:`mitsweep.workflows.render_exr`."""

from __future__ import annotations

import argparse
import math
import sys

from ..workflows.render import render_exr
from .common import positive_float, positive_int, print_json
from .motion import add_motion_argument

NAME = "render"
HELP = ("render a setup's scene, or your own Mitsuba scene, through the mirror (pinhole "
        "ground truth, focused, focal sweep, stopped-down) to an EXR with provenance")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (see scenes/)")
    p.add_argument("--mode", required=True, choices=["pinhole", "focused", "sweep", "stopped"],
                   help="pinhole: all-in-focus ground truth; focused: normal camera focused "
                        "at the mirror centre; sweep: the sensor moves over the optimal "
                        "range; stopped: focused at a smaller aperture (--f-number)")
    p.add_argument("--resolution", type=positive_int, nargs=2, metavar=("W", "H"),
                   help="render W x H pixels over the setup's frame: the pixel pitch is "
                        "scaled so the mirror's image stays in frame (default: the "
                        "setup's sensor.resolution)")
    p.add_argument("--spp", type=positive_int, default=64, help="samples per pixel (64)")
    p.add_argument("--seed", type=int, default=0, help="random seed (0)")
    p.add_argument("--out", required=True, metavar="FILE.exr", help="output EXR (atomic)")
    p.add_argument("--aov", action="append", choices=["depth", "mask"], default=[],
                   help="extra layer: depth (l, mm, along the reflected chief ray) or mask "
                        "(pixels that see the mirror); repeatable")
    p.add_argument("--f-number", type=positive_float, metavar="N",
                   help="f-number of --mode stopped (default 11)")
    p.add_argument("--sampler", choices=["multijitter", "independent"],
                   help="how a pixel's samples are drawn (default: the mode's; multijitter "
                        "is stratified, independent for the sweep)")
    p.add_argument("--full-frame", action="store_true",
                   help="also render pixels outside the mirror's image (default: skip them)")
    p.add_argument("--preview", metavar="FILE.png", help="also write a tone-mapped PNG")
    p.add_argument("--preview-size", type=positive_int, metavar="PX",
                   help="shrink the preview by an integer factor to at most PX wide")
    p.add_argument("--scene", metavar="SCENE.xml",
                   help="render this Mitsuba scene instead of the built-in room (its "
                        "sensors and integrators are replaced; default: the setup's "
                        "[scene] file, if any)")
    p.add_argument("--scene-unit", choices=["mm", "cm", "m"],
                   help="length unit of the scene file (default: the setup's [scene] unit, "
                        "else mm)")
    add_motion_argument(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary")


def run(args) -> int:
    got = render_exr(args.setup, args.out, mode=args.mode, spp=args.spp, seed=args.seed,
                     resolution=args.resolution, aovs=args.aov, f_number=args.f_number,
                     sampler=args.sampler, full_frame=args.full_frame, preview=args.preview,
                     preview_size=args.preview_size, scene=args.scene,
                     scene_unit=args.scene_unit, motion=args.motion,
                     progress=sys.stderr.isatty())
    summary, m = got.summary, got.provenance
    if args.json:
        print_json(summary)
    else:
        r = m.get("resolution")
        size = "" if r is None else ("{}x{} px at {:.4g} mm pitch, ".format(
            *r["resolution_px"], r["pixel_pitch_mm"]))
        sys.stdout.write(f"{args.out}: {args.mode}, {size}{args.spp} spp, seed {args.seed}, "
                         f"{m['render_s']:.2f} s\n")
    return 0 if math.isfinite(summary["mean"]) else 1
