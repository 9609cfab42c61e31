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
distance it implies).
"""

from __future__ import annotations

import argparse
import hashlib
import logging

from .common import (add_photo_arguments, check_outputs, load_setup_arg, photo_options,
                     print_json)

logger = logging.getLogger(__name__)

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


def _sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def run(args) -> int:
    from .. import __version__
    from ..photo import calibrate_photo
    from ..config import setup_to_toml
    from ..io import write_text_atomic
    from ..io.camera import read_camera_image

    if args.free or args.setup is None:
        return _run_free(args)
    check_outputs([args.photo, args.setup], {"--write": args.write})
    setup = load_setup_arg(args.setup)
    photo = read_camera_image(args.photo, log_warnings=False, **photo_options(args))
    pitch = photo.pixel_pitch or setup.sensor.pixel_pitch
    pitch_source = photo.meta.get("pixel_pitch_source") or "setup"
    cal = calibrate_photo(photo.data, setup, pixel_pitch=pitch, fit_roll=args.fit_roll)
    photo.log_warnings()  # the photo's quality matters once a mirror is found in it
    out = cal.as_dict()
    out.update(photo=str(args.photo), setup=setup.name, kind=photo.kind,
               bit_depth=photo.bit_depth, pixel_pitch_source=pitch_source,
               tilted=not setup.mirror.is_symmetric,
               warnings=list(photo.warnings) + list(cal.warnings))
    if args.write:
        calibrated = cal.calibrated_setup(setup)
        header = (f"Written by mitsweep calibrate {__version__} from {args.photo} "
                  f"(sha256 {_sha256(args.photo)})\nand the setup {args.setup}: centre "
                  f"(row, col) = ({cal.center_px[0]:.3f}, {cal.center_px[1]:.3f}) px, rim "
                  f"radius {cal.rim_radius_px:.3f} px\n(setup predicts "
                  f"{cal.predicted_radius_px:.3f} px), {cal.fit.points_used} of "
                  f"{cal.fit.points_total} rim points, rms {cal.fit.residual_rms_px:.3f} px.")
        write_text_atomic(args.write, setup_to_toml(calibrated, header=header))
        out["written"] = args.write
    if args.json:
        print_json(out)
        return 0
    H, W = cal.image_shape
    vd = cal.implied_vertex_distance
    lines = [
        f"photo            {args.photo} ({photo.kind}, {photo.bit_depth}-bit, {W}x{H} px, "
        f"pitch {pitch:g} mm from the {pitch_source})",
        f"setup            {setup.name}{' (tilted mirror)' if out['tilted'] else ''}",
        f"centre           row {cal.center_px[0]:.3f}, col {cal.center_px[1]:.3f} px "
        f"(offset from the image centre {cal.center_offset_px[0]:+.3f}, "
        f"{cal.center_offset_px[1]:+.3f} px)",
        f"rim radius       {cal.rim_radius_px:.3f} px measured, "
        f"{cal.predicted_radius_px:.3f} px predicted ({100 * (cal.radius_ratio - 1):+.2f}%)",
        f"implies          pixel pitch {cal.implied_pixel_pitch:.6g} mm (setup {pitch:g}), "
        f"or lens-mirror distance "
        f"{'n/a' if vd is None else f'{vd:.3f} mm'} (setup "
        f"{setup.mirror.vertex_distance:g})",
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
    from ..io.camera import read_camera_image
    from ..optics.pixels import optical_center_px
    from ..photo.free import find_circle
    from .common import UsageError

    if args.write or args.fit_roll:
        raise UsageError("--write and --fit-roll need --setup (--free finds a circle only)")
    check_outputs([args.photo], [])
    photo = read_camera_image(args.photo, log_warnings=False, **photo_options(args))
    fit, radius = find_circle(photo.data)
    photo.log_warnings()
    H, W = photo.shape
    r0, c0 = optical_center_px((H, W))
    offset = (fit.center_px[0] - r0, fit.center_px[1] - c0)
    pitch = photo.pixel_pitch
    skeleton = ["[sensor]", f"resolution = [{W}, {H}]"]
    skeleton.append(f"pixel_pitch = {pitch:.6g}" if pitch else
                    "# pixel_pitch = ?  (mm; the file does not say)")
    skeleton.append(f"center_offset_px = [{offset[0]:.3f}, {offset[1]:.3f}]")
    out = {"photo": str(args.photo), "kind": photo.kind, "bit_depth": photo.bit_depth,
           "image_shape": [H, W], "center_px": list(fit.center_px), "radius_px": radius,
           "center_offset_px": list(offset), "pixel_pitch_mm": pitch,
           "points_used": fit.points_used, "points_total": fit.points_total,
           "residual_rms_px": fit.residual_rms_px,
           "center_standard_error_px": fit.center_se_px,
           "setup_skeleton": "\n".join(skeleton) + "\n",
           "warnings": list(photo.warnings)}
    if args.json:
        print_json(out)
        return 0
    print("\n".join([
        f"photo            {args.photo} ({photo.kind}, {photo.bit_depth}-bit, {W}x{H} px)",
        f"centre           row {fit.center_px[0]:.3f}, col {fit.center_px[1]:.3f} px "
        f"(offset from the image centre {offset[0]:+.3f}, {offset[1]:+.3f} px)",
        f"radius           {radius:.3f} px (a circle; no setup)",
        f"fit              {fit.points_used} of {fit.points_total} outline points, rms "
        f"{fit.residual_rms_px:.3f} px (centre standard error {fit.center_se_px:.3f} px)",
        "setup skeleton:", *skeleton]))
    return 0
