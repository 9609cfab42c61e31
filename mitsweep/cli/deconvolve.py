"""``mitsweep deconvolve``: restore an EDOF image from a focal-sweep photo or render.

A thin wrapper over :func:`mitsweep.workflows.restore_photo` (which documents where the
bank, the pixel pitch and the mirror's centre come from).
"""

from __future__ import annotations

import argparse
import sys

from ..workflows.restore import OPERATORS, restore_photo
from .common import add_photo_arguments, positive_float, positive_int, print_json

NAME = "deconvolve"
HELP = ("deconvolve a focal-sweep photo (RAW, TIFF, PNG, JPEG or EXR) into an EDOF image, "
        "with the IPSF bank of its geometry (traced and cached) or a given one")


def _nsr(text: str) -> float:
    from ..deconv.wiener import MAX_NSR

    x = positive_float(text)
    if not x <= MAX_NSR:
        raise argparse.ArgumentTypeError(f"must be in (0, {MAX_NSR:g}], got {text}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..deconv import METHODS

    p.add_argument("image", help="focal-sweep photo: RAW (DNG, CR2, NEF, ARW, ...), TIFF, "
                                 "PNG, JPEG, or EXR (Y or R,G,B channels, linear)")
    p.add_argument("--setup", metavar="SETUP.toml",
                   help="the setup the photo was taken with (a calibrated one from "
                        "`mitsweep calibrate --write` carries the mirror's centre); "
                        "default: the setup in the image's metadata")
    p.add_argument("--record", metavar="CAPTURE.json",
                   help="the capture record of the photo: its measured stage motion "
                        "shapes the traced bank")
    p.add_argument("--bank", metavar="BANK.npz",
                   help="IPSF bank (NPZ); default: traced for the photo's geometry and "
                        "cached (MITSWEEP_CACHE_DIR, else the XDG cache)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="restored image: .exr (linear, with provenance) or .tif/.tiff/.png "
                        "(16-bit sRGB, for display)")
    p.add_argument("--method", default="wiener", metavar="METHOD",
                   help=f"restoration method: {', '.join(METHODS)} (default wiener)")
    p.add_argument("--operator", choices=OPERATORS, default=None,
                   help="auto (default): polar for radial banks, spatially varying for grid "
                        "banks; grid on a radial bank rotates its kernels onto a grid")
    p.add_argument("--nsr", type=_nsr, metavar="X",
                   help="Wiener noise-to-signal power ratio, (0, 1e6] (default: estimated from "
                        "the image)")
    p.add_argument("--mismatch", metavar="PROFILE.json",
                   help="the bank's mismatch profile (a dataset's calibration/mismatch.json, "
                        "made with the same --bank): the weight is then the calibrated "
                        "rule's, from the photo's noise and the profile (not with --nsr)")
    p.add_argument("--prior", choices=["natural", "constant"], default="natural",
                   help="Wiener regulariser: natural-image 1/f^2 spectrum (default) or a flat "
                        "one (constant NSR)")
    p.add_argument("--depth", metavar="MM|mean", default=None,
                   help="bank depth to deconvolve with, mm, or 'mean' (default 500 mm, "
                        "as in the paper); a traced bank is traced at this depth")
    p.add_argument("--grid", type=positive_int, default=16, metavar="N",
                   help="grid size N x N when --operator grid converts a radial bank "
                        "(default 16; at most a quarter of the image's smaller side)")
    p.add_argument("--center", type=float, nargs=2, metavar=("ROW", "COL"),
                   help="pixel position of the mirror axis (default: the setup's calibrated "
                        "centre, else the image centre, H/2-0.5, W/2-0.5)")
    add_photo_arguments(p)
    p.add_argument("--rays", type=positive_int, default=None, metavar="N",
                   help="rays per IPSF when tracing the bank (default 1000000)")
    p.add_argument("--bank-extent", choices=["fov", "rim"], default="fov",
                   help="how far a traced bank reaches: the design FOV (default) or the "
                        "whole mirror image out to its rim (traced, cached under its own key)")
    p.add_argument("--force", action="store_true",
                   help="use a bank traced for other optics (or unchecked ones) anyway; the "
                        "override is logged and recorded in the output's provenance")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    result = restore_photo(
        args.image, setup=args.setup, bank=args.bank, record=args.record, out=args.out,
        method=args.method, operator=args.operator, nsr=args.nsr, prior=args.prior,
        depth=args.depth, grid=args.grid, center=args.center, pixel_pitch=args.pixel_pitch,
        white_balance=args.white_balance, transfer=args.transfer, rays=args.rays,
        force=args.force, bank_extent=args.bank_extent, mismatch=args.mismatch,
        progress=True)
    s = result.summary
    if args.json:
        print_json(s)
        return 0
    cache = result.provenance["bank_cache"]
    how = "" if cache is None else (" (bank from the cache)" if not cache["traced"]
                                    else " (bank traced and cached)" if cache["path"]
                                    else " (bank traced, not cached)")
    H, W = s["shape"][:2]
    sys.stdout.write(f"{s['out']}: {s['method']} deconvolution ({s['operator']}) of {W}x{H} "
                     f"in {s['seconds']:.2f} s{how}\n")
    return 0
