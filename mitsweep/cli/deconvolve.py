"""``mitsweep deconvolve``: restore an EDOF image from a focal-sweep capture or render."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from .common import (UsageError, check_outputs, load_setup_arg, positive_float, positive_int,
                     print_json)

NAME = "deconvolve"
HELP = ("deconvolve a focal-sweep image (EXR) with an IPSF bank: polar for radial banks, "
        "spatially varying for grid banks")

logger = logging.getLogger(__name__)


def _nsr(text: str) -> float:
    from ..deconv.wiener import MAX_NSR

    x = positive_float(text)
    if not x <= MAX_NSR:
        raise argparse.ArgumentTypeError(f"must be in (0, {MAX_NSR:g}], got {text}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("image", help="focal-sweep image, EXR (Y or R,G,B channels, linear)")
    p.add_argument("--bank", required=True, metavar="BANK.npz", help="IPSF bank (NPZ)")
    p.add_argument("--out", required=True, metavar="OUT.exr", help="restored image (EXR)")
    p.add_argument("--nsr", type=_nsr, metavar="X",
                   help="Wiener noise-to-signal power ratio, (0, 1e6] (default: estimated from "
                        "the image)")
    p.add_argument("--prior", choices=["natural", "constant"], default="natural",
                   help="regulariser: natural-image 1/f^2 spectrum (default) or a flat one "
                        "(constant NSR)")
    p.add_argument("--depth", metavar="MM|mean", default=None,
                   help="bank depth to deconvolve with, mm, or 'mean' (default 500 mm, "
                        "as in the paper)")
    p.add_argument("--method", choices=["auto", "polar", "grid"], default="auto",
                   help="auto: polar for radial banks, spatially varying for grid banks; "
                        "grid on a radial bank rotates its kernels onto a grid")
    p.add_argument("--grid", type=positive_int, default=16, metavar="N",
                   help="grid size N x N when --method grid converts a radial bank "
                        "(default 16; at most a quarter of the image's smaller side)")
    p.add_argument("--center", type=float, nargs=2, metavar=("ROW", "COL"),
                   help="pixel position of the mirror axis for polar deconvolution of a real "
                        "capture (default the image centre, H/2-0.5, W/2-0.5)")
    p.add_argument("--pixel-pitch", type=positive_float, metavar="MM",
                   help="the image's pixel pitch, mm, when its metadata does not say")
    p.add_argument("--setup", metavar="SETUP.toml",
                   help="the setup the image was captured with, when its metadata holds none "
                        "(a real capture): the bank must have been traced for its optics")
    p.add_argument("--force", action="store_true",
                   help="use a bank traced for other optics (or unchecked ones) anyway; the "
                        "override is logged and recorded in the output's provenance")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _image_pixel_pitch(meta: dict) -> float | None:
    for getter in (lambda m: m["pixel_pitch"],
                   lambda m: m["setup"]["sensor"]["pixel_pitch"]):
        try:
            return float(getter(meta))
        except (KeyError, TypeError, ValueError):
            continue
    return None


def _depth_arg(text: str | None):
    if text is None or text == "mean":
        return text
    try:
        d = float(text)
    except ValueError:
        raise UsageError(f"--depth: expected a depth in mm or 'mean', got {text!r}") from None
    if not d > 0:
        raise UsageError(f"--depth: must be > 0 mm, got {text}")
    return d


def _image_optics(meta: dict, setup_path: str | None, src: Path):
    """(optics sections of the image's setup or None, where they came from)."""
    from ..config import setup_to_dict
    from ..io.bank import optics_fingerprint, optics_sections

    setup = meta.get("setup")
    from_meta = None
    if isinstance(setup, dict) and "mirror" in setup:
        motion = meta.get("motion")
        from_meta = optics_sections(setup, motion if isinstance(motion, dict) else None)
    if setup_path is None:
        return from_meta, ("its metadata" if from_meta is not None else None)
    given = load_setup_arg(setup_path)
    from_arg = optics_sections(setup_to_dict(given), _setup_motion(given))
    if from_meta is not None:
        common = [k for k in from_meta if k in from_arg]
        if optics_fingerprint({k: from_meta[k] for k in common}) != \
                optics_fingerprint({k: from_arg[k] for k in common}):
            raise UsageError(f"--setup {setup_path} differs from the setup recorded in {src}'s "
                             f"metadata; drop --setup to use the recorded one")
        return from_meta, "its metadata"
    return from_arg, f"--setup {setup_path}"


def _setup_motion(setup) -> dict | None:
    """The stage motion a setup implies, or None for a measured (tabulated) one."""
    if setup.sweep.profile == "tabulated":
        logger.info("sweep.profile = 'tabulated': the bank's motion is not compared")
        return None
    from ..optics.reference import reference_geometry

    return reference_geometry(setup).motion.as_dict()


def run(args) -> int:
    from .. import __version__
    from ..deconv import deconvolve, grid_bank_from_radial
    from ..deconv.kernels import bank_identity_problem, check_bank_matches
    from ..deconv.polar import polar_deconvolve
    from ..deconv.spatial import spatially_varying_deconvolve
    from ..io import read_exr, write_exr
    from ..io.bank import BankError, load_bank, optics_fingerprint
    from ..io.exr import stack_channels

    depth = _depth_arg(args.depth)
    src = Path(args.image)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such image file")
    out = Path(args.out)
    if out.suffix.lower() != ".exr":
        raise UsageError(f"--out must be an .exr file, got {out}")
    check_outputs([src, args.bank, args.setup], [out])
    bank = load_bank(args.bank)
    chans, meta = read_exr(src)
    try:
        image = stack_channels(chans)
    except ValueError as exc:
        raise UsageError(f"{src}: needs a Y channel or R, G, B channels ({exc})") from None
    pitch = args.pixel_pitch if args.pixel_pitch is not None else _image_pixel_pitch(meta)
    if pitch is None:
        logger.warning("%s: no pixel pitch in the metadata; assuming the bank's %g mm",
                    src, bank.pixel_pitch)
    check_bank_matches(bank, image.shape, pixel_pitch=pitch)
    optics, optics_from = _image_optics(meta, args.setup, src)
    problem = bank_identity_problem(bank, optics, image=f"{src}")
    if problem is not None and not args.force:
        hint = " (give --setup)" if optics is None and bank.optics is not None else ""
        raise BankError(f"{problem}{hint}; use --force to override")
    if problem is not None:
        logger.warning("--force: %s", problem)
    identity = {"checked_against": optics_from, "forced": problem is not None,
                "problem": problem, "bank_optics_sha256":
                None if bank.optics is None else optics_fingerprint(bank.optics)}

    center = None
    if args.center is not None:
        row, col = args.center
        if not (0 <= row < image.shape[0] and 0 <= col < image.shape[1]):
            raise UsageError(f"--center {row:g} {col:g} lies outside the "
                             f"{image.shape[1]}x{image.shape[0]} image")
        if args.method == "grid" or (args.method == "auto" and bank.kind == "grid"):
            raise UsageError("--center applies to polar deconvolution (radial banks) only")
        center = (row, col)
    use_grid = args.method == "grid" and bank.kind == "radial" and center is None
    max_grid = max(1, min(image.shape[:2]) // 4)
    if use_grid and args.grid > max_grid:
        raise UsageError(f"--grid {args.grid}: at most {max_grid} for a {image.shape[1]}x"
                         f"{image.shape[0]} image (grid cells of at least 4 px)")
    t0 = time.perf_counter()
    kw = dict(nsr=args.nsr, prior=args.prior, depth_mm=depth)
    if args.method == "polar" or center is not None:
        restored = polar_deconvolve(image, bank, center=center, **kw)
    elif args.method == "grid" and bank.kind == "radial":
        grid = grid_bank_from_radial(bank, (args.grid, args.grid), image.shape[:2])
        restored = spatially_varying_deconvolve(image, grid, **kw)
    else:
        restored = deconvolve(image, bank, **kw)
    seconds = time.perf_counter() - t0
    method = args.method if args.method != "auto" else (
        "polar" if bank.kind == "radial" else "grid")

    provenance = {
        "command": "deconvolve", "version": __version__, "input": str(src),
        "bank": str(args.bank), "bank_kind": bank.kind, "method": method,
        "nsr": args.nsr if args.nsr is not None else "estimated", "prior": args.prior,
        "depth_mm": depth if depth is not None else 500.0,
        "center_rc": list(center) if center is not None else None,
        "pixel_pitch": float(bank.pixel_pitch),
        "reference_sensor_distance": float(bank.reference_sensor_distance),
        "bank_identity": identity,
        "input_metadata": meta,
    }
    for key in ("setup", "sweep_range"):
        if key in meta:
            provenance[key] = meta[key]
    write_exr(out, restored.astype("float32"), metadata=provenance)
    result = {"out": str(out), "method": method, "seconds": seconds,
              "shape": list(image.shape), "nsr": provenance["nsr"], "prior": args.prior}
    if args.json:
        print_json(result)
    else:
        sys.stdout.write(f"{out}: {method} deconvolution of {image.shape[1]}x{image.shape[0]} "
                         f"in {seconds:.2f} s\n")
    return 0
