"""Restore an EDOF image from a focal-sweep photo or render (``mitsweep deconvolve``).

The photo is any camera file :func:`mitsweep.io.camera.read_camera_image` reads (RAW,
TIFF, PNG, JPEG, EXR). Without a bank the IPSF bank of the photo's own geometry (its
resolution and pixel pitch, the setup's optics, the capture record's measured motion) is
traced once and cached (:func:`mitsweep.tracer.cache.cached_bank`).

The mirror's axis on the photo: ``center``, else the setup's calibrated
``sensor.center_offset_px`` (``mitsweep calibrate --write``), else the image centre. A
radial bank takes it as the pole of the polar deconvolution; a grid bank (tilted mirror)
is applied to a window of the photo centred on it to the nearest pixel (the kernels
vary over many pixels, so the half-pixel left is immaterial).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .. import __version__
from ..config import Setup, setup_from_dict, setup_to_dict
from ._base import (InputError, Progress, WorkflowResult, progress_callback, resolve_setup)
from ._paths import check_outputs

if TYPE_CHECKING:
    from ..io.bank import IPSFBank
    from ..tracer.cache import CachedBank

__all__ = ["restore_photo", "OPERATORS", "OUTPUT_SUFFIXES", "split_method"]

logger = logging.getLogger(__name__)

#: What ``operator`` accepts; before restoration methods existed ``method`` took these.
OPERATORS = ("auto", "polar", "grid")
#: Output suffixes: linear EXR, or a 16-bit sRGB display image.
OUTPUT_SUFFIXES = (".exr", ".tif", ".tiff", ".png")


def split_method(method: str, operator: str | None) -> tuple[str, str, str | None]:
    """``(method, operator, deprecated)`` from a method that may be an old operator name
    (``method="polar"`` meant ``operator="polar"`` with Wiener): ``deprecated`` is that
    old name, else None.

    Raises
    ------
    InputError
        An unknown method, or an operator given both ways.
    """
    from ..deconv import METHODS

    if method not in METHODS and method not in OPERATORS:
        raise InputError(f"--method {method!r}: choose a restoration method from "
                         f"{', '.join(METHODS)} (the operators {', '.join(OPERATORS)} are "
                         f"--operator's)")
    if method in OPERATORS:
        if operator is not None:
            raise InputError(f"--method {method} is an operator: give the restoration method "
                             f"to --method and the operator to --operator")
        return "wiener", method, method
    return method, operator or "auto", None


def _image_pixel_pitch(meta: dict) -> float | None:
    for getter in (lambda m: m["pixel_pitch"],
                   lambda m: m["setup"]["sensor"]["pixel_pitch"]):
        try:
            return float(getter(meta))
        except (KeyError, TypeError, ValueError):
            continue
    return None


def _resolve_pitch(photo, meta: dict, setup: Setup | None) -> tuple[float | None, str | None]:
    """The photo's pixel pitch (mm) and where it came from: the file's (or the caller's,
    ``photo.meta["pixel_pitch_source"]``), the image metadata's (``"metadata"``), the
    setup's (``"setup"``), else None."""
    pitch, pitch_from = photo.pixel_pitch, photo.meta.get("pixel_pitch_source")
    if pitch is None and _image_pixel_pitch(meta) is not None:
        pitch, pitch_from = _image_pixel_pitch(meta), "metadata"
    if pitch is None and setup is not None:
        pitch, pitch_from = float(setup.sensor.pixel_pitch), "setup"
    return pitch, pitch_from


def _setup_motion(setup: Setup) -> dict | None:
    """The stage motion a setup implies, or None for a measured (tabulated) one."""
    if setup.sweep.profile == "tabulated":
        logger.info("sweep.profile = 'tabulated': the bank's motion is not compared")
        return None
    from ..optics.reference import reference_geometry

    return reference_geometry(setup).motion.as_dict()


def _image_optics(meta: dict, given, setup_path, src: Path, motion):
    """(optics sections of the image's setup or None, where they came from)."""
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
            raise InputError(f"--setup {setup_path} differs from the setup recorded in {src}'s "
                             f"metadata; drop --setup to use the recorded one")
        return from_meta, "its metadata"
    return from_arg, f"--setup {setup_path}"


def _record_motion(path, setup: Setup):
    """The measured motion of a capture record, checked against the setup's optics."""
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
            raise InputError(f"--record {path}: the capture used another {section} than the "
                             f"setup's ({theirs[section]} vs {ours[section]})")
    ref = (record.get("reference") or {}).get("reference_sensor_distance_mm")
    mid = reference_geometry(setup, motion=motion).sensor_distance
    if ref is not None and abs(float(ref) - mid) > 1e-9 * mid:
        raise InputError(f"--record {path}: its reference sensor distance {float(ref):.6g} mm "
                         f"is not its measured motion's mid-travel {mid:.6g} mm")
    return motion


def _resolve_center(center, setup, shape) -> tuple[tuple[float, float], str]:
    from ..optics.pixels import center_offset_of, optical_center_px

    H, W = shape
    if center is not None:
        row, col = center
        if not (0 <= row < H and 0 <= col < W):
            raise InputError(f"--center {row:g} {col:g} lies outside the {W}x{H} image")
        return (float(row), float(col)), "--center"
    offset = center_offset_of(setup) if setup is not None else None
    if offset is not None:
        if tuple(setup.sensor.resolution) == (W, H):
            return optical_center_px(shape, offset), "the setup's sensor.center_offset_px"
        logger.warning("the setup's centre offset was calibrated on a %dx%d image, this one "
                       "is %dx%d: using the image centre (give --center)",
                       *setup.sensor.resolution, W, H)
    return optical_center_px(shape), "the image centre"


def _traced_bank(setup, shape, pitch, motion, depth, rays, progress, cache_dir,
                 extent="fov"):
    """The bank of the photo's geometry, from the cache (traced on a miss), to the FOV or
    to the mirror's rim (``extent``)."""
    if extent not in ("fov", "rim"):
        raise InputError(f"--bank-extent: must be fov or rim, got {extent!r}")
    from ..deconv.spatial import mirror_grid_shape
    from ..io.bank import bank_kernel_size
    from ..tracer.bank import BANK_RAYS
    from ..tracer.cache import cached_bank
    from ..tracer.settings import TraceSettings

    H, W = shape
    photo = replace(setup, sensor=replace(setup.sensor, resolution=(W, H), pixel_pitch=pitch,
                                          center_offset_px=None))
    kind = "radial" if photo.mirror.is_symmetric else "grid"
    # a tilted mirror's image covers part of the frame: a grid fine enough for it
    grid = mirror_grid_shape(photo) if kind == "grid" else (9, 9)
    n = 19 if kind == "radial" else grid[0] * grid[1]
    with progress_callback(progress, n, "IPSF bank", "ipsf") as step:
        return cached_bank(photo, motion=motion, kind=kind,
                           depths=(depth if isinstance(depth, float) else 500.0,),
                           settings=TraceSettings(rays=rays or BANK_RAYS,
                                                  kernel_size=bank_kernel_size(pitch)),
                           grid=grid, cache_dir=cache_dir, progress=step, extent=extent)


def _file_noise(meta: dict) -> tuple[float | None, str]:
    """The noise σ the photo's file states (a DNG's NoiseProfile developed as the image
    was, :func:`mitsweep.io.camera.read_camera_image`), the RMS over its channels, and
    where it came from; ``(None, "estimated from the image")`` where the file states
    none."""
    noise = meta.get("noise") or {}
    if not noise.get("sigma"):
        return None, "estimated from the image"
    sigma = np.asarray(noise["sigma"], dtype=np.float64)
    return float(np.sqrt(np.mean(np.square(sigma)))), str(noise["source"])


def _photo_bank(got: CachedBank) -> tuple[IPSFBank, dict, dict, str]:
    """``(bank, cache record, identity record, source)`` of a bank traced for the photo
    (:func:`_traced_bank`'s :class:`~mitsweep.tracer.cache.CachedBank`)."""
    from ..io.bank import optics_fingerprint

    kernels = got.bank
    assert kernels.optics is not None  # a traced bank records the optics it was traced for
    identity = {"checked_against": "traced for the photo's geometry", "forced": False,
                "problem": None, "bank_optics_sha256": optics_fingerprint(kernels.optics)}
    source = str(got.path) if got.path is not None else "traced (not cached)"
    return kernels, {"path": got.path and str(got.path), "traced": got.traced}, identity, \
        source


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


def _given_photo_bank(bank, operator, grid, shape, pitch, src) -> IPSFBank:
    """A given bank, loaded and checked against the operator and the photo's ``shape``
    and pixel ``pitch`` (None: the bank's is assumed, with a warning)."""
    from ..deconv.kernels import check_bank_matches
    from ..io.bank import load_bank

    kernels = load_bank(os.fspath(bank))
    _check_operator(operator, kernels.kind, grid, shape[:2])
    if pitch is None:
        logger.warning("%s: no pixel pitch in the metadata; assuming the bank's %g mm",
                       src, kernels.pixel_pitch)
    check_bank_matches(kernels, shape, pixel_pitch=pitch)
    return kernels


def _given_bank_identity(bank, optics_from: tuple, src: Path, force: bool) -> dict:
    """The identity record of a given bank checked against the photo's optics
    (``optics_from``: :func:`_image_optics`' optics and where they came from); a bank of
    other optics is refused unless ``force``."""
    from ..deconv.kernels import bank_identity_problem
    from ..io.bank import BankError, optics_fingerprint

    optics, checked_against = optics_from
    problem = bank_identity_problem(bank, optics, image=f"{src}")
    if problem is not None and not force:
        hint = " (give --setup)" if optics is None and bank.optics is not None else ""
        raise BankError(f"{problem}{hint}; use --force to override")
    if problem is not None:
        logger.warning("--force: %s", problem)
    return {"checked_against": checked_against, "forced": problem is not None,
            "problem": problem, "bank_optics_sha256":
            None if bank.optics is None else optics_fingerprint(bank.optics)}


def _restore(pixels: np.ndarray, bank, *, method: str, operator: str | None, grid: int,
             center: tuple[float, float], explicit_center: bool, **kw):
    """``(restored, operator used, window shift or None)``: the polar operator on a
    radial bank (unless ``operator`` is ``"grid"``), else the product-convolution on a
    window centred on ``center`` (a radial bank rotated onto a ``grid`` x ``grid``
    grid)."""
    from ..deconv import deconvolve, grid_bank_from_radial

    if bank.kind == "radial" and operator != "grid":
        restored = deconvolve(pixels, bank, method=method,
                              center=center if explicit_center else None, **kw)
        return restored, "polar", None
    work = grid_bank_from_radial(bank, (grid, grid), pixels.shape[:2]) \
        if bank.kind == "radial" else bank
    window, shift = _window(pixels, center)
    return _unwindow(pixels, deconvolve(window, work, method=method, **kw), shift), "grid", \
        shift


def _calibrated_nsr(pixels: np.ndarray, bank, mismatch, sigma: float | None,
                    center: tuple[float, float], setup: Setup | None) -> float:
    """The calibrated rule's NSR for a photo (``restore_photo``'s ``mismatch``)."""
    from ..deconv.weights import MismatchProfile, blind_noise_variance, model_nsr

    try:
        profile = MismatchProfile.read(mismatch)
    except (OSError, ValueError) as exc:
        raise InputError(str(exc)) from None
    mask = _mirror_mask(pixels.shape[:2], center, setup, bank)
    if sigma is None:
        sigma = float(np.sqrt(blind_noise_variance(pixels)))
    return model_nsr(pixels, bank, sigma, mask=mask, mismatch=profile)


def _mirror_mask(shape: tuple[int, int], center: tuple[float, float], setup: Setup | None,
                 bank) -> np.ndarray:
    """The mirror's image in a photo: the setup's predicted outline around ``center``,
    else the radial bank's extent (a disc); refused where neither is known or the
    image holds all of it (nothing outside to tell)."""
    from skimage.draw import polygon

    from ..deconv.kernels import radii_px
    from ..deconv.metrics import disk_mask

    if setup is not None:
        from ..optics.outline import predicted_outline

        points = predicted_outline(setup).offsets_px(bank.pixel_pitch)[0]
        mask = np.zeros(shape, bool)
        rr, cc = polygon(points[:, 0] + center[0], points[:, 1] + center[1], shape)
        mask[rr, cc] = True
    elif bank.kind == "radial":
        mask = disk_mask(shape, float(np.max(radii_px(bank))), center=center)
    else:
        raise InputError("--mismatch reads the weight over the mirror's image: give --setup "
                         "(its outline) with a grid bank")
    if not mask.any() or mask.all():
        raise InputError(f"--mismatch: the mirror's image ({int(mask.sum())} of "
                         f"{mask.size} pixels at centre {center[0]:.1f}, {center[1]:.1f}) "
                         f"must lie partly inside the photo, with pixels outside it")
    return mask


def _check_depth(depth):
    if depth is None or depth == "mean":
        return depth
    text = depth if isinstance(depth, str) else f"{depth:g}"
    try:
        d = float(depth)
    except ValueError:
        raise InputError(f"--depth: expected a depth in mm or 'mean', got {text!r}") from None
    if not d > 0:
        raise InputError(f"--depth: must be > 0 mm, got {text}")
    return d


def _check_operator(operator: str | None, kind: str, grid: int,
                    shape: tuple[int, int]) -> None:
    """Refuse what the operator cannot do with a bank of ``kind`` on an image of ``shape``
    (before tracing)."""
    H, W = shape
    if operator == "polar" and kind != "radial":
        raise InputError("--operator polar needs a radial bank (an untilted mirror)")
    max_grid = max(1, min(H, W) // 4)
    if operator == "grid" and kind == "radial" and grid > max_grid:
        raise InputError(f"--grid {grid}: at most {max_grid} for a {W}x{H} image "
                         f"(grid cells of at least 4 px)")


def restore_photo(image: str | os.PathLike, *, setup: Setup | str | os.PathLike | None = None,
                  bank: str | os.PathLike | None = None,
                  record: str | os.PathLike | None = None,
                  out: str | os.PathLike | None = None, method: str = "wiener",
                  operator: str | None = None, nsr: float | None = None,
                  prior: str = "natural", depth: float | str | None = None, grid: int = 16,
                  center: tuple[float, float] | None = None,
                  pixel_pitch: float | None = None, white_balance: str = "camera",
                  transfer: str | None = None, rays: int | None = None, force: bool = False,
                  cache_dir: str | os.PathLike | None = None, bank_extent: str = "fov",
                  mismatch: str | os.PathLike | None = None,
                  progress: Progress = None) -> WorkflowResult:
    """Restore the EDOF image of a focal-sweep photo (what ``mitsweep deconvolve`` runs).

    Parameters
    ----------
    image : path-like
        The photo: RAW (DNG, CR2, NEF, ARW, ...), TIFF, PNG, JPEG, or EXR (Y or R, G, B
        channels, linear).
    setup : Setup, path-like or str, optional
        The setup the photo was taken with (a file, a bundled name, or a Setup); default:
        the setup recorded in the image's metadata. A calibrated setup
        (``mitsweep calibrate --write``) carries the mirror's centre.
    bank : path-like, optional
        An IPSF bank (NPZ); default: traced for the photo's geometry and cached
        (``MITSWEEP_CACHE_DIR``, else the XDG cache). A given bank's optics are checked
        against the photo's (its identity, :func:`mitsweep.deconv.kernels.bank_identity_problem`).
    record : path-like, optional
        The capture record of the photo: its measured stage motion shapes the traced bank.
    out : path-like, optional
        Where to write the restored image: ``.exr`` (linear, with the provenance as
        metadata) or ``.tif``/``.tiff``/``.png`` (16-bit sRGB, for display). None: not
        written.
    method : str
        Restoration method, one of :data:`mitsweep.deconv.METHODS` (``"wiener"``).
    operator : {"auto", "polar", "grid"}, optional
        auto (default): polar for radial banks, spatially varying for grid banks; grid on
        a radial bank rotates its kernels onto a ``grid`` x ``grid`` grid.
    nsr : float, optional
        Wiener noise-to-signal power ratio (for the priors, their first Wiener step's);
        default: estimated from the image, or the calibrated rule's with ``mismatch``.
    prior : {"natural", "constant"}
        Wiener regulariser: a natural-image 1/f² spectrum, or a flat one.
    depth : float or "mean", optional
        Bank depth to deconvolve with, mm (default 500 mm, as in the paper).
    grid : int
        Grid size when the grid operator converts a radial bank (at most a quarter of
        the image's smaller side).
    center : (float, float), optional
        Pixel position (row, col) of the mirror axis; default: the setup's calibrated
        centre, else the image centre.
    pixel_pitch, white_balance, transfer
        Passed to :func:`mitsweep.io.camera.read_camera_image`.
    rays : int, optional
        Rays per IPSF when tracing the bank (default :data:`mitsweep.tracer.bank.BANK_RAYS`).
    force : bool
        Use a given bank whose optics differ from the photo's (logged and recorded).
    cache_dir : path-like, optional
        Where a traced bank is cached (default: ``MITSWEEP_CACHE_DIR``, else the XDG
        cache; :func:`mitsweep.tracer.cache.cached_bank`).
    bank_extent : {"fov", "rim"}
        How far a traced bank reaches (:func:`mitsweep.tracer.ipsf_bank`'s ``extent``):
        the design FOV (default), or the whole mirror image out to its rim, where the
        sweep does not bring the scene into focus but the blur is still traced (a grid
        bank's nodes off the mirror take the nearest traced kernel). Cached under its
        own key. Not for a given ``bank``.
    mismatch : path-like, optional
        The bank's mismatch profile (JSON: a dataset's ``calibration/mismatch.json``,
        made with the same bank, or
        :meth:`mitsweep.deconv.weights.MismatchProfile.write`'s): the NSR is then the
        calibrated rule's (:func:`mitsweep.deconv.weights.model_nsr` with
        ``mismatch=``), with the noise σ the file states or, where it states none, the
        image's own (:func:`~mitsweep.deconv.weights.blind_noise_variance`), read over
        the mirror's image (the setup's predicted outline around the centre, else the
        radial bank's extent). Not with ``nsr``.
    progress : None, True or callable
        Progress of a bank trace (:func:`mitsweep.workflows.progress_callback`).

    Returns
    -------
    WorkflowResult
        ``value``: the restored image, float32 ``(H, W[, C])``. ``provenance``: the
        metadata an output file carries: ``input`` (path, ``input_kind``,
        ``input_bit_depth``, ``input_warnings``), ``setup``, ``bank`` (its path, or where
        it was cached), ``bank_kind``, ``bank_cache`` (``{"path", "traced"}`` for a traced
        bank), ``bank_identity`` (``checked_against``, ``forced``, ``problem``,
        ``bank_optics_sha256``), ``method``, ``operator`` (the one used), ``nsr``,
        ``prior``, ``depth_mm``, ``center_rc``/``center_from``, ``window_shift_rc``,
        ``pixel_pitch``/``pixel_pitch_from`` (the file's, ``"metadata"`` or ``"setup"``),
        ``reference_sensor_distance``, ``record``, ``motion``, ``input_metadata``,
        ``seconds`` (the deconvolution's wall time). ``summary``: what
        ``mitsweep deconvolve --json`` prints.

    Raises
    ------
    InputError
        A bad option, an unknown method, a centre outside the image, a bank the operator
        cannot use, a bank of other optics (without ``force``), no setup where one is
        needed.
    mitsweep.io.bank.BankError
        The bank's identity differs from the photo's optics (without ``force``).
    mitsweep.config.SetupError, mitsweep.io.camera.CameraFileError, OSError
        An unreadable setup or photo.

    Examples
    --------
    >>> from mitsweep.workflows import restore_photo
    >>> result = restore_photo("sweep.exr", out="restored.exr")  # doctest: +SKIP
    >>> result.provenance["center_from"]                         # doctest: +SKIP
    'the image centre'
    """
    from ..io import write_exr
    from ..io.camera import CameraFileError, read_camera_image, write_display_image

    depth = _check_depth(depth)
    method, operator, deprecated = split_method(method, operator)
    if mismatch is not None and nsr is not None:
        raise InputError("--mismatch and --nsr both set the weight: give one")
    src = Path(image)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such image file")
    if out is not None:
        out = Path(out)
        if out.suffix.lower() not in OUTPUT_SUFFIXES:
            raise InputError(f"--out must be an {', '.join(OUTPUT_SUFFIXES)} file, got {out}")
    setup_path = None if setup is None or isinstance(setup, Setup) else setup
    check_outputs([src, bank, setup_path, record, mismatch], {"--out": out})
    # its warnings are logged once the photo is accepted: a refusal is the only line
    try:
        photo = read_camera_image(src, log_warnings=False, pixel_pitch=pixel_pitch,
                                  white_balance=white_balance, transfer=transfer)
    except CameraFileError as exc:
        if src.suffix.lower() == ".exr" and "missing channels" in str(exc):
            raise InputError(f"{src}: needs a Y channel or R, G, B channels ({exc})") from None
        raise
    pixels = photo.data
    meta = photo.meta.get("exr_header") or {}
    given = resolve_setup(setup) if setup is not None else None
    photo_setup = given
    if photo_setup is None and isinstance(meta.get("setup"), dict):
        photo_setup = setup_from_dict(meta["setup"])
    if bank is None and photo_setup is None:
        raise InputError(f"{src}: no setup in its metadata; give --setup (the setup the photo "
                         f"was taken with) or --bank")
    motion = None
    if record is not None:
        if photo_setup is None:
            raise InputError("--record needs the photo's setup: give --setup")
        motion = _record_motion(record, photo_setup)
    pitch, pitch_from = _resolve_pitch(photo, meta, photo_setup)
    H, W = pixels.shape[:2]
    center_given = center is not None
    center, center_from = _resolve_center(center, photo_setup, (H, W))

    cache = None
    if bank is not None:
        if bank_extent != "fov":
            raise InputError("--bank-extent applies to a traced bank only: a given --bank "
                             "reaches as far as it was traced")
        bank_source = str(bank)
        kernels = _given_photo_bank(bank, operator, grid, pixels.shape, pitch, src)
        identity = _given_bank_identity(kernels, _image_optics(meta, given, setup_path, src,
                                                            motion), src, force)
    else:
        if force:
            raise InputError("--force applies to a given --bank only")
        assert photo_setup is not None  # refused above: no bank and no setup
        _check_operator(operator, "radial" if photo_setup.mirror.is_symmetric else "grid",
                        grid, (H, W))
        kernels, cache, identity, bank_source = _photo_bank(
            _traced_bank(photo_setup, (H, W), pitch, motion, depth, rays, progress,
                         cache_dir, bank_extent))

    photo.log_warnings()  # the setup, bank and geometry took it: it will be restored
    explicit_center = center_given or center_from != "the image centre"
    if deprecated is not None:
        logger.warning("--method %s is deprecated: --method now names the restoration method "
                       "(%s); use --operator %s", deprecated, "wiener", deprecated)

    noise, noise_from = _file_noise(photo.meta)
    nsr_rule = "given" if nsr is not None else "estimated"
    if mismatch is not None:
        nsr = _calibrated_nsr(pixels, kernels, mismatch, noise, center, photo_setup)
        nsr_rule = "calibrated"
    t0 = time.perf_counter()
    kw = dict(nsr=nsr, prior=prior, depth=depth) if method == "wiener" else \
        dict(nsr=nsr, depth=depth)
    if noise is not None:
        kw["noise"] = noise
    restored, used, shift = _restore(pixels, kernels, method=method, operator=operator,
                                     grid=grid, center=center,
                                     explicit_center=explicit_center, **kw)
    seconds = time.perf_counter() - t0

    provenance = {
        "command": "deconvolve", "version": __version__, "input": str(src),
        "input_kind": photo.kind, "input_bit_depth": photo.bit_depth,
        "input_warnings": list(photo.warnings),
        "bank": bank_source, "bank_kind": kernels.kind, "bank_cache": cache,
        "bank_extent": (kernels.metadata or {}).get("extent", "fov"),
        "method": method, "operator": used,
        "nsr": nsr if nsr is not None else "estimated", "nsr_rule": nsr_rule,
        "mismatch": None if mismatch is None else os.fspath(mismatch), "prior": prior,
        "noise_sigma": noise, "noise_from": noise_from,
        "depth_mm": depth if depth is not None else 500.0,
        "center_rc": list(center) if explicit_center else None,
        "center_from": center_from, "window_shift_rc": list(shift) if shift else None,
        "pixel_pitch": float(kernels.pixel_pitch), "pixel_pitch_from": pitch_from,
        "reference_sensor_distance": float(kernels.reference_sensor_distance),
        "record": None if record is None else os.fspath(record),
        "motion": None if motion is None else motion.as_dict(),
        "bank_identity": identity,
        "input_metadata": meta,
    }
    if photo_setup is not None:
        provenance["setup"] = setup_to_dict(photo_setup)
    for key in ("setup", "sweep_range"):
        if key in meta:
            provenance[key] = meta[key]
    if out is not None and out.suffix.lower() == ".exr":
        write_exr(out, restored.astype("float32"), metadata=provenance)
    elif out is not None:
        write_display_image(out, restored, metadata=provenance)
    summary = {"out": None if out is None else str(out), "method": method, "operator": used,
               "seconds": seconds, "shape": list(pixels.shape),
               "nsr": provenance["nsr"], "prior": prior, "bank": bank_source,
               "bank_traced": bool(cache and cache["traced"]), "center_rc": list(center),
               "center_from": center_from, "warnings": list(photo.warnings)}
    return WorkflowResult(restored.astype(np.float32, copy=False),
                          dict(provenance, workflow="restore_photo", seconds=seconds), summary)
