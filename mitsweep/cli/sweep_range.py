"""``mitsweep sweep-range``: the optimal focal-sweep range of a setup (paper Sec. 4)."""

from __future__ import annotations

import argparse
import math
import sys

from .common import UsageError, load_setup_arg, positive_float, print_json

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


def compute(args) -> tuple[object, dict]:
    from ..optics import optimal_sweep_range

    setup = load_setup_arg(args.setup)
    dmin = dmax = None
    if args.depth is not None:
        dmin, dmax = args.depth
        if not (dmin > 0) or math.isnan(dmax) or not (dmax > 0):
            raise UsageError(f"--depth: both must be > 0 mm, got {dmin:g} {dmax:g}")
        if dmin > dmax:
            raise UsageError(f"--depth: MIN ({dmin:g}) must be <= MAX ({dmax:g})")
    if args.fov is not None and not args.fov < 360:
        raise UsageError(f"--fov: must be in (0, 360) degrees, got {args.fov:g}")
    result = optimal_sweep_range(setup, fov_deg=args.fov, depth_min=dmin, depth_max=dmax)
    out = result.as_dict()
    out["setup"] = setup.name
    return setup, result, out


def run(args) -> int:
    setup, result, out = compute(args)
    if args.verify:
        from ..tracer.focus import traced_sweep_range  # provided by the tracer

        traced = traced_sweep_range(setup, fov_deg=args.fov, depth_min=result.depth_min_mm,
                                    depth_max=result.depth_max_mm)
        out["traced_focus_min_mm"] = traced.focus_min_mm
        out["traced_focus_max_mm"] = traced.focus_max_mm
        if not setup.mirror.is_symmetric:  # the whole 2-D field, beyond the tilt plane
            out["traced_field_focus_min_mm"] = traced.field_focus_min_mm
            out["traced_field_focus_max_mm"] = traced.field_focus_max_mm
    if args.plot:
        from ..plots import plot_focal_surfaces

        plot_focal_surfaces(setup, result, args.plot)
        out["plot"] = args.plot
    if args.json:
        print_json(out)
    else:
        r = result
        lines = [
            f"setup            {setup.name}",
            f"field of view    {r.fov_deg:.2f} deg (mirror reaches {r.max_fov_deg:.2f} deg); "
            f"mirror zone rho {r.rho_start_mm:.3f} .. {r.rho_end_mm:.3f} mm",
            f"depth range      {r.depth_min_mm:g} .. {r.depth_max_mm:g} mm",
            f"focus range      {r.focus_min_mm:.3f} .. {r.focus_max_mm:.3f} mm ({r.source})",
            f"sensor distance  {r.sensor_start_mm:.4f} -> {r.sensor_end_mm:.4f} mm "
            f"(reference {r.reference_sensor_distance:.4f} mm)",
            f"sensor travel    {r.translation_mm:.4f} mm",
            f"exposure         {r.exposure_s:.4f} s at {r.velocity_mm_s:g} mm/s",
        ]
        if "traced_focus_min_mm" in out:
            lines.append(f"traced focus     {out['traced_focus_min_mm']:.3f} .. "
                         f"{out['traced_focus_max_mm']:.3f} mm")
        if "traced_field_focus_min_mm" in out:
            lines.append(f"traced 2-D field {out['traced_field_focus_min_mm']:.3f} .. "
                         f"{out['traced_field_focus_max_mm']:.3f} mm (whole mirror, off the "
                         f"tilt plane too)")
        if args.plot:
            lines.append(f"plot             {args.plot}")
        sys.stdout.write("\n".join(lines) + "\n")
    return 0
