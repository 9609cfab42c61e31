"""``mitsweep calibrate``: find the mirror in a photo; centre, rim size, a setup for it.

Reads the photo (RAW, TIFF, PNG, JPEG or EXR, :mod:`mitsweep.io.camera`), predicts the
mirror's outline from the setup and fits it to sub-pixel precision
(:mod:`mitsweep.photo`). Reports the optical axis's pixel
(``center_px``), the rim radius measured and predicted, and the pixel pitch or
lens–mirror distance the difference implies; ``--write`` saves a setup for this camera
and photo (resolution, pitch, ``sensor.center_offset_px``) that every other command
accepts.

Exit status 2, one line: an unreadable photo, no mirror found, or a mirror found whose size
disagrees with the setup's prediction by more than 35% (the message says the pitch or
distance it implies). A thin wrapper over :func:`mitsweep.workflows.calibrate_camera`
(``--free``: :func:`mitsweep.workflows.find_mirror_circle`).
"""

from __future__ import annotations

import argparse

from ..workflows.calibrate import calibrate_camera, find_mirror_circle
from .common import UsageError, add_photo_arguments, photo_options, print_json

NAME = "calibrate"
HELP = ("find the mirror in a photo: its centre and rim radius (sub-pixel) against the "
        "setup's prediction; --write a setup for this camera")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("photo", help="photo of the mirror: RAW (DNG, CR2, NEF, ARW, ...), TIFF, "
                                 "PNG, JPEG or EXR")
    p.add_argument("--setup", help="setup TOML file (see scenes/); without it (or with "
                                   "--free) the outline is found as a circle from the "
                                   "photo alone")
    p.add_argument("--free", action="store_true",
                   help="find the mirror's outline without a setup (a circle of any centre "
                        "and radius) and print a [sensor] skeleton to start a setup from")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--write", metavar="CALIBRATED.toml",
                   help="write the setup for this camera and photo: resolution, pixel "
                        "pitch and sensor.center_offset_px")
    p.add_argument("--fit-roll", action="store_true",
                   help="also fit the camera's roll about its axis (tilted mirrors: a roll "
                        "left out moves the axis by ~0.5%% of the rim radius per degree; "
                        "fitted, the centre is less certain)")
    add_photo_arguments(p)


def run(args) -> int:
    if args.free or args.setup is None:
        return _run_free(args)
    result = calibrate_camera(args.photo, args.setup, write=args.write,
                              fit_roll=args.fit_roll, **photo_options(args))
    cal, out, p = result.value, result.summary, result.provenance
    if args.json:
        print_json(out)
        return 0
    H, W = cal.image_shape
    vd, pitch = cal.implied_vertex_distance, p["pixel_pitch"]
    lines = [
        f"photo            {args.photo} ({out['kind']}, {out['bit_depth']}-bit, {W}x{H} px, "
        f"pitch {pitch:g} mm from the {p['pixel_pitch_source']})",
        f"setup            {out['setup']}{' (tilted mirror)' if out['tilted'] else ''}",
        f"centre           row {cal.center_px[0]:.3f}, col {cal.center_px[1]:.3f} px "
        f"(offset from the image centre {cal.center_offset_px[0]:+.3f}, "
        f"{cal.center_offset_px[1]:+.3f} px)",
        f"rim radius       {cal.rim_radius_px:.3f} px measured, "
        f"{cal.predicted_radius_px:.3f} px predicted ({100 * (cal.radius_ratio - 1):+.2f}%)",
        f"implies          pixel pitch {cal.implied_pixel_pitch:.6g} mm (setup {pitch:g}), "
        f"or lens-mirror distance "
        f"{'n/a' if vd is None else f'{vd:.3f} mm'} (setup "
        f"{p['vertex_distance']:g})",
        f"fit              {cal.fit.points_used} of {cal.fit.points_total} rim points, "
        f"rms {cal.fit.residual_rms_px:.3f} px (centre standard error "
        f"{cal.fit.center_se_px:.3f} px)",
    ]
    if cal.fit.roll_deg is not None:
        lines.append(f"roll             {cal.fit.roll_deg:+.3f} deg about the axis")
    if args.write:
        lines.append(f"written          {args.write}")
    print("\n".join(lines))
    return 0


def _run_free(args) -> int:
    """``calibrate --free``: the outline as a circle from the photo alone."""
    if args.write or args.fit_roll:
        raise UsageError("--write and --fit-roll need --setup (--free finds a circle only)")
    out = find_mirror_circle(args.photo, **photo_options(args)).summary
    if args.json:
        print_json(out)
        return 0
    (H, W), (row, col), offset = out["image_shape"], out["center_px"], out["center_offset_px"]
    print("\n".join([
        f"photo            {args.photo} ({out['kind']}, {out['bit_depth']}-bit, {W}x{H} px)",
        f"centre           row {row:.3f}, col {col:.3f} px "
        f"(offset from the image centre {offset[0]:+.3f}, {offset[1]:+.3f} px)",
        f"radius           {out['radius_px']:.3f} px (a circle; no setup)",
        *(["outline          a sphere's limb, found where the photo shows no edge (from "
           "how the image changes across it)"] if out.get("limb") else []),
        f"fit              {out['points_used']} of {out['points_total']} outline points, rms "
        f"{out['residual_rms_px']:.3f} px (centre standard error "
        f"{out['center_standard_error_px']:.3f} px)",
        *_ellipse_lines(out.get("ellipse")),
        "setup skeleton:", *out["setup_skeleton"].splitlines()]))
    return 0


def _ellipse_lines(e: dict | None) -> list[str]:
    if not e:
        return []
    (a, b), (row, col) = e["semi_axes_px"], e["center_px"]
    verdict = "no circle: a tilted view?" if e["significant"] else "a circle within the fit"
    return [f"ellipse          semi-axes {a:.3f} x {b:.3f} px at {e['angle_deg']:.1f} deg, "
            f"centre row {row:.3f}, col {col:.3f} px, rms {e['residual_rms_px']:.3f} px "
            f"({verdict})"]
