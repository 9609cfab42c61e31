"""``mitsweep sweep-range``: the optimal focal-sweep range of a setup (paper Sec. 4)."""

from __future__ import annotations

import argparse
import logging
import math
import sys

from .common import UsageError, check_outputs, load_setup_arg, positive_float, print_json

logger = logging.getLogger(__name__)

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


def _traced_keys(traced) -> dict:
    return {"traced_field": traced.field,
            "traced_focus_min_mm": traced.focus_min,
            "traced_focus_max_mm": traced.focus_max,
            "traced_focus_min_at": traced.min_at,
            "traced_focus_max_at": traced.max_at,
            "traced_convergence": traced.convergence,
            "traced_points": traced.points}


def _where(at: dict) -> str:
    return (f"mirror ({at['x_mm']:.3f}, {at['y_mm']:.3f}) mm{' (rim)' if at['on_rim'] else ''}"
            f", depth {at['depth_mm']:g} mm, image ({at['image_uv_mm'][0]:.3f}, "
            f"{at['image_uv_mm'][1]:.3f}) mm")


def run(args) -> int:
    if args.field is not None and not args.verify:
        raise UsageError("--field: chooses the field of the traced range; give it with "
                         "--verify")
    if args.plot:
        check_outputs([args.setup], {"--plot": args.plot})
        from ..plots import check_figure_path

        check_figure_path(args.plot, "--plot")  # before --verify's traces, not after
    setup, result, out = compute(args)
    if args.verify:
        from ..config import SetupError
        from ..tracer.focus import traced_sweep_range

        field = args.field or "plane"
        trace = lambda f: traced_sweep_range(  # noqa: E731
            setup, fov_deg=args.fov, depth_min=result.depth_min,
            depth_max=result.depth_max, field=f)
        traced = trace(field)
        out.update(_traced_keys(traced))
        # traced_field_focus_*: the whole mirror (field "mirror"), as before for a tilted
        # mirror, whose tilt plane is not all of it; omitted where that field is undefined.
        whole = traced if field == "mirror" else None
        if whole is None and not setup.mirror.is_symmetric:
            try:
                whole = trace("mirror")
            except SetupError as exc:
                logger.info("no whole-mirror traced range: %s", exc)
        if whole is not None:
            out["traced_field_focus_min_mm"] = whole.focus_min
            out["traced_field_focus_max_mm"] = whole.focus_max
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
