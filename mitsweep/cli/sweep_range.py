"""``mitsweep sweep-range``: the optimal focal-sweep range of a setup (paper Sec. 4); a thin
wrapper over :func:`mitsweep.workflows.compute_sweep_range`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.sweep_range import compute_sweep_range
from .common import positive_float, print_json

NAME = "sweep-range"
HELP = ("optimal focal-sweep range, sensor travel and exposure for a setup "
        "(paper Eq. 4-9)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (see scenes/)")
    p.add_argument("--fov", type=positive_float, metavar="DEG",
                   help="field of view, degrees (default: the setup's sweep.fov_deg)")
    p.add_argument("--depth", type=float, nargs=2, metavar=("MIN", "MAX"),
                   help="depth range, mm from the mirror (MAX may be inf)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE", help="draw the focal surfaces (paper Fig. 6)")
    p.add_argument("--verify", action="store_true",
                   help="also trace the sweep range numerically (needs the tracer)")
    p.add_argument("--field", choices=("plane", "mirror", "fov"), default=None,
                   help="with --verify, the field the traced range covers. 'plane' "
                        "(default): the paper's FOV zone; untilted, the disc from the axis "
                        "out to where the reflected chief ray makes FOV/2 with the axis; "
                        "tilted, the tilt-plane segment from the rim nearest the camera "
                        "over which the reflected chief rays span the FOV. 'mirror': the "
                        "whole mirror out to its rim (rim included), which must all face "
                        "the lens. 'fov': the FOV in 2-D, the mirror points whose "
                        "reflected chief rays lie within FOV/2 of the FOV's central "
                        "direction (the axis when untilted, where it equals 'plane'; the "
                        "bisector of the tilt-plane fan when tilted)")


def _where(at: dict) -> str:
    return (f"mirror ({at['x_mm']:.3f}, {at['y_mm']:.3f}) mm{' (rim)' if at['on_rim'] else ''}"
            f", depth {at['depth_mm']:g} mm, image ({at['image_uv_mm'][0]:.3f}, "
            f"{at['image_uv_mm'][1]:.3f}) mm")


def run(args) -> int:
    got = compute_sweep_range(args.setup, fov_deg=args.fov, depth=args.depth,
                              verify=args.verify, field=args.field, plot=args.plot)
    out, setup_name = got.summary, got.summary["setup"]
    if args.json:
        print_json(out)
    else:
        r = got.value
        lines = [
            f"setup            {setup_name}",
            f"field of view    {r.fov_deg:.2f} deg (mirror reaches {r.max_fov_deg:.2f} deg); "
            f"mirror zone rho {r.rho_start:.3f} .. {r.rho_end:.3f} mm",
            f"depth range      {r.depth_min:g} .. {r.depth_max:g} mm",
            f"focus range      {r.focus_min:.3f} .. {r.focus_max:.3f} mm ({r.source})",
            f"sensor distance  {r.sensor_start:.4f} -> {r.sensor_end:.4f} mm "
            f"(reference {r.reference_sensor_distance:.4f} mm)",
            f"sensor travel    {r.translation:.4f} mm",
            f"exposure         {r.exposure_s:.4f} s at {r.velocity_mm_s:g} mm/s",
        ]
        if "traced_focus_min_mm" in out:
            lines += [
                f"traced focus     {out['traced_focus_min_mm']:.3f} .. "
                f"{out['traced_focus_max_mm']:.3f} mm (field {out['traced_field']}, "
                f"{out['traced_points']} traced points)",
                f"  nearest at     {_where(out['traced_focus_min_at'])}",
                f"  farthest at    {_where(out['traced_focus_max_at'])}"]
        if "traced_field_focus_min_mm" in out and out.get("traced_field") != "mirror":
            lines.append(f"traced mirror    {out['traced_field_focus_min_mm']:.3f} .. "
                         f"{out['traced_field_focus_max_mm']:.3f} mm (field mirror: the whole "
                         f"mirror out to its rim)")
        if args.plot:
            lines.append(f"plot             {args.plot}")
        sys.stdout.write("\n".join(lines) + "\n")
    return 0
