"""``mitsweep deconvolve``: restore an EDOF image from a focal-sweep photo or render.

The photo is any camera file :func:`mitsweep.io.camera.read_camera_image` reads (RAW,
TIFF, PNG, JPEG, EXR). Without ``--bank`` the IPSF bank of the photo's own geometry (its
resolution and pixel pitch, the setup's optics, the capture record's measured motion) is
traced once and cached (:func:`mitsweep.tracer.cache.cached_bank`).

The mirror's axis on the photo: ``--center``, else the setup's calibrated
``sensor.center_offset_px`` (``mitsweep calibrate --write``), else the image centre. A
radial bank takes it as the pole of the polar deconvolution; a grid bank (tilted mirror)
is applied to a window of the photo centred on it to the nearest pixel (the kernels
vary over many pixels, so the half-pixel left is immaterial).
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .common import (UsageError, add_photo_arguments, check_outputs, load_setup_arg,
                     photo_options, positive_float, positive_int, print_json)

NAME = "deconvolve"
HELP = ("deconvolve a focal-sweep photo (RAW, TIFF, PNG, JPEG or EXR) into an EDOF image, "
        "with the IPSF bank of its geometry (traced and cached) or a given one")

logger = logging.getLogger(__name__)

#: What ``--operator`` accepts; before restoration methods existed ``--method`` took these.
OPERATORS = ("auto", "polar", "grid")
#: Output suffixes: linear EXR, or a 16-bit sRGB display image.
OUTPUT_SUFFIXES = (".exr", ".tif", ".tiff", ".png")


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


def _setup_motion(setup) -> dict | None:
    """The stage motion a setup implies, or None for a measured (tabulated) one."""
    if setup.sweep.profile == "tabulated":
        logger.info("sweep.profile = 'tabulated': the bank's motion is not compared")
        return None
    from ..optics.reference import reference_geometry

    return reference_geometry(setup).motion.as_dict()


def _image_optics(meta: dict, given, setup_path: str | None, src: Path, motion):
    """(optics sections of the image's setup or None, where they came from)."""
    from ..config import setup_to_dict
    from ..io.bank import optics_fingerprint, optics_sections

    setup = meta.get("setup")
    from_meta = None
    if isinstance(setup, dict) and "mirror" in setup:
        recorded = meta.get("motion")
        from_meta = optics_sections(setup, recorded if isinstance(recorded, dict) else None)
    if given is None:
        return from_meta, ("its metadata" if from_meta is not None else None)
    mdict = motion.as_dict() if motion is not None else _setup_motion(given)
    from_arg = optics_sections(setup_to_dict(given), mdict)
    if from_meta is not None:
        common = [k for k in from_meta if k in from_arg and k != "sensor"]
        if optics_fingerprint({k: from_meta[k] for k in common}) != \
                optics_fingerprint({k: from_arg[k] for k in common}):
            raise UsageError(f"--setup {setup_path} differs from the setup recorded in {src}'s "
                             f"metadata; drop --setup to use the recorded one")
        return from_meta, "its metadata"
    return from_arg, f"--setup {setup_path}"


def _record_motion(path: str, setup):
    """The measured motion of a capture record, checked against the setup's optics."""
    from ..config import setup_to_dict
    from ..optics.motion import MotionProfile
    from ..optics.reference import reference_geometry
    from ..rig.record import load_capture_record, measured_motion

    record = load_capture_record(path)
    times, distances = measured_motion(record)
    motion = MotionProfile.tabulated(times, distances)
    ours = setup_to_dict(setup)
    theirs = record.get("setup") or {}
    for section in ("mirror", "lens"):
        if section in theirs and theirs[section] != ours[section]:
            raise UsageError(f"--record {path}: the capture used another {section} than the "
                             f"setup's ({theirs[section]} vs {ours[section]})")
    ref = (record.get("reference") or {}).get("reference_sensor_distance_mm")
    mid = reference_geometry(setup, motion=motion).sensor_distance
    if ref is not None and abs(float(ref) - mid) > 1e-9 * mid:
        raise UsageError(f"--record {path}: its reference sensor distance {float(ref):.6g} mm "
                         f"is not its measured motion's mid-travel {mid:.6g} mm")
    return motion


def _resolve_center(args, setup, shape) -> tuple[tuple[float, float], str]:
    from ..optics.pixels import center_offset_of, optical_center_px

    H, W = shape
    if args.center is not None:
        row, col = args.center
        if not (0 <= row < H and 0 <= col < W):
            raise UsageError(f"--center {row:g} {col:g} lies outside the {W}x{H} image")
        return (float(row), float(col)), "--center"
    offset = center_offset_of(setup) if setup is not None else None
    if offset is not None:
        if tuple(setup.sensor.resolution) == (W, H):
            return optical_center_px(shape, offset), "the setup's sensor.center_offset_px"
        logger.warning("the setup's centre offset was calibrated on a %dx%d image, this one "
                       "is %dx%d: using the image centre (give --center)",
                       *setup.sensor.resolution, W, H)
    return optical_center_px(shape), "the image centre"


def _traced_bank(args, setup, shape, pitch, motion, depth):
    """The bank of the photo's geometry, from the cache (traced on a miss)."""
    from tqdm import tqdm

    from ..deconv.spatial import mirror_grid_shape
    from ..io.bank import bank_kernel_size
    from ..tracer.bank import BANK_RAYS
    from ..tracer.cache import cached_bank

    H, W = shape
    photo = replace(setup, sensor=replace(setup.sensor, resolution=(W, H), pixel_pitch=pitch,
                                          center_offset_px=None))
    kind = "radial" if photo.mirror.is_symmetric else "grid"
    # a tilted mirror's image covers part of the frame: a grid fine enough for it
    grid = mirror_grid_shape(photo) if kind == "grid" else (9, 9)
    n = 19 if kind == "radial" else grid[0] * grid[1]
    with tqdm(total=n, desc="IPSF bank", unit="ipsf", file=sys.stderr,
              disable=not sys.stderr.isatty()) as bar:
        got = cached_bank(photo, motion=motion, kind=kind,
                          depths=(depth if isinstance(depth, float) else 500.0,),
                          rays=args.rays or BANK_RAYS, kernel_size=bank_kernel_size(pitch),
                          grid=grid, progress=bar.update)
    return got, photo


def _window(image: np.ndarray, center: tuple[float, float]):
    """The photo shifted by whole pixels so that ``center`` is within half a pixel of the
    image centre (edge pixels repeated where it leaves the frame): ``(window, shift)``,
    window pixel (r, c) = photo pixel (r + dr, c + dc)."""
    from ..optics.pixels import optical_center_px

    r0, c0 = optical_center_px(image.shape)
    dr, dc = int(round(center[0] - r0)), int(round(center[1] - c0))
    H, W = image.shape[:2]
    pad = [(max(0, -dr), max(0, dr)), (max(0, -dc), max(0, dc))] + [(0, 0)] * (image.ndim - 2)
    padded = np.pad(image, pad, mode="edge")
    r, c = max(0, dr), max(0, dc)
    return padded[r:r + H, c:c + W], (dr, dc)


def _unwindow(photo: np.ndarray, window: np.ndarray, shift) -> np.ndarray:
    dr, dc = shift
    H, W = photo.shape[:2]
    out = photo.astype(window.dtype, copy=True)
    rs, cs = slice(max(0, dr), min(H, H + dr)), slice(max(0, dc), min(W, W + dc))
    out[rs, cs] = window[rs.start - dr:rs.stop - dr, cs.start - dc:cs.stop - dc]
    return out


def run(args) -> int:
    from .. import __version__
    from ..config import setup_from_dict
    from ..deconv import deconvolve, grid_bank_from_radial
    from ..deconv.kernels import bank_identity_problem, check_bank_matches
    from ..io import write_exr
    from ..io.bank import BankError, load_bank, optics_fingerprint
    from ..io.camera import CameraFileError, read_camera_image, write_display_image

    from ..deconv import METHODS

    depth = _depth_arg(args.depth)
    method, operator = args.method, args.operator
    if method not in METHODS and method not in OPERATORS:
        raise UsageError(f"--method {method!r}: choose a restoration method from "
                         f"{', '.join(METHODS)} (the operators {', '.join(OPERATORS)} are "
                         f"--operator's)")
    deprecated = None
    if method in OPERATORS:
        if operator is not None:
            raise UsageError(f"--method {method} is an operator: give the restoration method "
                             f"to --method and the operator to --operator")
        deprecated = method
        method, operator = "wiener", method
    operator = operator or "auto"
    src = Path(args.image)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such image file")
    out = Path(args.out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise UsageError(f"--out must be an {', '.join(OUTPUT_SUFFIXES)} file, got {out}")
    check_outputs([src, args.bank, args.setup, args.record], {"--out": out})
    # its warnings are logged once the photo is accepted: a refusal is the only line
    try:
        photo = read_camera_image(src, log_warnings=False, **photo_options(args))
    except CameraFileError as exc:
        if src.suffix.lower() == ".exr" and "missing channels" in str(exc):
            raise UsageError(f"{src}: needs a Y channel or R, G, B channels ({exc})") from None
        raise
    image = photo.data
    meta = photo.meta.get("exr_header") or {}
    given = load_setup_arg(args.setup) if args.setup is not None else None
    setup = given
    if setup is None and isinstance(meta.get("setup"), dict):
        setup = setup_from_dict(meta["setup"])
    if args.bank is None and setup is None:
        raise UsageError(f"{src}: no setup in its metadata; give --setup (the setup the photo "
                         f"was taken with) or --bank")
    if args.record is not None and setup is None:
        raise UsageError("--record needs the photo's setup: give --setup")
    motion = _record_motion(args.record, setup) if args.record is not None else None
    pitch = photo.pixel_pitch
    pitch_from = photo.meta.get("pixel_pitch_source")
    if pitch is None and _image_pixel_pitch(meta) is not None:
        pitch, pitch_from = _image_pixel_pitch(meta), "metadata"
    if pitch is None and setup is not None:
        pitch, pitch_from = float(setup.sensor.pixel_pitch), "setup"
    H, W = image.shape[:2]
    center, center_from = _resolve_center(args, setup, (H, W))

    def check_operator(kind: str) -> None:
        """Refuse what the operator cannot do with a bank of ``kind`` (before tracing)."""
        if operator == "polar" and kind != "radial":
            raise UsageError("--operator polar needs a radial bank (an untilted mirror)")
        max_grid = max(1, min(H, W) // 4)
        if operator == "grid" and kind == "radial" and args.grid > max_grid:
            raise UsageError(f"--grid {args.grid}: at most {max_grid} for a {W}x{H} image "
                             f"(grid cells of at least 4 px)")

    cache = None
    if args.bank is not None:
        bank = load_bank(args.bank)
        check_operator(bank.kind)
        if pitch is None:
            logger.warning("%s: no pixel pitch in the metadata; assuming the bank's %g mm",
                           src, bank.pixel_pitch)
        check_bank_matches(bank, image.shape, pixel_pitch=pitch)
        optics, optics_from = _image_optics(meta, given, args.setup, src, motion)
        problem = bank_identity_problem(bank, optics, image=f"{src}")
        if problem is not None and not args.force:
            hint = " (give --setup)" if optics is None and bank.optics is not None else ""
            raise BankError(f"{problem}{hint}; use --force to override")
        if problem is not None:
            logger.warning("--force: %s", problem)
        identity = {"checked_against": optics_from, "forced": problem is not None,
                    "problem": problem, "bank_optics_sha256":
                    None if bank.optics is None else optics_fingerprint(bank.optics)}
        bank_source = str(args.bank)
    else:
        if args.force:
            raise UsageError("--force applies to a given --bank only")
        check_operator("radial" if setup.mirror.is_symmetric else "grid")
        got, _ = _traced_bank(args, setup, (H, W), pitch, motion, depth)
        bank, cache = got.bank, {"path": got.path and str(got.path), "traced": got.traced}
        identity = {"checked_against": "traced for the photo's geometry", "forced": False,
                    "problem": None, "bank_optics_sha256": optics_fingerprint(bank.optics)}
        bank_source = str(got.path) if got.path is not None else "traced (not cached)"

    photo.log_warnings()  # the setup, bank and geometry took it: it will be restored
    explicit_center = args.center is not None or center_from != "the image centre"
    if deprecated is not None:
        logger.warning("--method %s is deprecated: --method now names the restoration method "
                       "(%s); use --operator %s", deprecated, "wiener", deprecated)

    t0 = time.perf_counter()
    kw = dict(nsr=args.nsr, prior=args.prior, depth_mm=depth) if method == "wiener" else \
        dict(nsr=args.nsr, depth_mm=depth)
    shift = None
    if bank.kind == "radial" and operator != "grid":
        used = "polar"
        restored = deconvolve(image, bank, method=method,
                              center=center if explicit_center else None, **kw)
    else:
        used = "grid"
        work = grid_bank_from_radial(bank, (args.grid, args.grid), (H, W)) \
            if bank.kind == "radial" else bank
        window, shift = _window(image, center)
        restored = _unwindow(image, deconvolve(window, work, method=method, **kw), shift)
    seconds = time.perf_counter() - t0

    provenance = {
        "command": "deconvolve", "version": __version__, "input": str(src),
        "input_kind": photo.kind, "input_bit_depth": photo.bit_depth,
        "input_warnings": list(photo.warnings),
        "bank": bank_source, "bank_kind": bank.kind, "bank_cache": cache,
        "method": method, "operator": used,
        "nsr": args.nsr if args.nsr is not None else "estimated", "prior": args.prior,
        "depth_mm": depth if depth is not None else 500.0,
        "center_rc": list(center) if explicit_center else None,
        "center_from": center_from, "window_shift_rc": list(shift) if shift else None,
        "pixel_pitch": float(bank.pixel_pitch), "pixel_pitch_from": pitch_from,
        "reference_sensor_distance": float(bank.reference_sensor_distance),
        "record": args.record,
        "motion": None if motion is None else motion.as_dict(),
        "bank_identity": identity,
        "input_metadata": meta,
    }
    if setup is not None:
        from ..config import setup_to_dict

        provenance["setup"] = setup_to_dict(setup)
    for key in ("setup", "sweep_range"):
        if key in meta:
            provenance[key] = meta[key]
    if out.suffix.lower() == ".exr":
        write_exr(out, restored.astype("float32"), metadata=provenance)
    else:
        write_display_image(out, restored, metadata=provenance)
    result = {"out": str(out), "method": method, "operator": used, "seconds": seconds,
              "shape": list(image.shape), "nsr": provenance["nsr"], "prior": args.prior,
              "bank": bank_source, "bank_traced": bool(cache and cache["traced"]),
              "center_rc": list(center), "center_from": center_from,
              "warnings": list(photo.warnings)}
    if args.json:
        print_json(result)
    else:
        how = "" if cache is None else (" (bank from the cache)" if not cache["traced"]
                                        else " (bank traced and cached)" if cache["path"]
                                        else " (bank traced, not cached)")
        sys.stdout.write(f"{out}: {method} deconvolution ({used}) of {W}x{H} in "
                         f"{seconds:.2f} s{how}\n")
    return 0
