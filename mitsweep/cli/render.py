"""``mitsweep render``: render a setup's scene through the mirror with Mitsuba 3."""

from __future__ import annotations

import argparse
import math
import sys

from ..config import MAX_RESOLUTION
from .common import (UsageError, check_outputs, load_setup_arg, positive_float, positive_int,
                     print_json)
from .motion import add_motion_argument, motion_from_args

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


def _check_out(path: str, suffix: str) -> None:
    from ..io.atomic import check_writable

    if not path.lower().endswith(suffix):
        raise UsageError(f"{path}: the output must end in {suffix}")
    try:
        check_writable(path)
    except OSError as exc:
        raise UsageError(str(exc)) from None


def run(args) -> int:
    from ..render import render_image, render_to_exr

    if args.scene is not None and not args.scene.strip():
        raise UsageError("--scene: an empty path; give a Mitsuba XML scene file")
    setup = load_setup_arg(args.setup)
    check_outputs([args.setup, args.scene or setup.scene.file, args.motion],
                  {"--out": args.out, "--preview": args.preview})
    _check_out(args.out, ".exr")
    if args.preview:
        _check_out(args.preview, ".png")
    if args.f_number is not None and args.mode != "stopped":
        raise UsageError("--f-number applies to --mode stopped only (the other modes use "
                         "the setup's lens.f_number)")
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if args.scene_unit is not None and args.scene is None and setup.scene.file is None:
        raise UsageError("--scene-unit applies to a scene file (--scene, or [scene] file in "
                         "the setup)")
    if args.resolution is not None and max(args.resolution) > MAX_RESOLUTION:
        raise UsageError(f"--resolution: each side must be at most {MAX_RESOLUTION} px, "
                         f"got {args.resolution[0]} {args.resolution[1]}")
    motion = motion_from_args(args, setup)
    result = render_image(setup, args.mode, spp=args.spp, seed=args.seed, motion=motion,
                          aovs=tuple(dict.fromkeys(args.aov)), f_number=args.f_number,
                          mirror_only=not args.full_frame, progress=sys.stderr.isatty(),
                          sampler=args.sampler, scene=args.scene, scene_unit=args.scene_unit,
                          resolution=args.resolution)
    render_to_exr(args.out, result)
    if args.preview:
        from ..io.png import write_png

        write_png(args.preview, result.image, max_width=args.preview_size)
    m = result.metadata
    summary = {"out": args.out, "mode": args.mode, "spp": args.spp, "seed": args.seed,
               "sampler": m["sampler"],
               "render_s": m["render_s"], "aovs": sorted(result.aovs),
               "reference_sensor_distance_mm": m["reference_sensor_distance_mm"],
               "mean": float(result.image.mean())}
    if args.preview:
        summary["preview"] = args.preview
    if "resolution" in m:
        summary["resolution"] = m["resolution"]
    if args.motion:
        summary["motion"] = args.motion
    if "user_scene" in m:
        summary["scene"] = {k: m["user_scene"][k] for k in ("source", "sha256", "unit", "replaced")}
    if args.json:
        print_json(summary)
    else:
        r = m.get("resolution")
        size = "" if r is None else ("{}x{} px at {:.4g} mm pitch, ".format(
            *r["resolution_px"], r["pixel_pitch_mm"]))
        sys.stdout.write(f"{args.out}: {args.mode}, {size}{args.spp} spp, seed {args.seed}, "
                         f"{m['render_s']:.2f} s\n")
    return 0 if math.isfinite(summary["mean"]) else 1
