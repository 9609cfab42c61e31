"""Camera files in (RAW, TIFF, PNG, JPEG, EXR) as linear images; display images out.

:func:`read_camera_image` turns a photograph into what the rest of mitsweep works on: a
float32 array (H, W, 3) or (H, W), *linear* in scene radiance, scaled so that the
format's white level is 1.0, with the pixel pitch when the file states it.

Formats (chosen by the file's suffix) and what "linear" means for each:

========  ============================================================================
kind      decoding
========  ============================================================================
``raw``   DNG, CR2, NEF, ARW, ... through rawpy (LibRaw): black level subtracted,
          white level applied (LibRaw's automatic maximum adjustment off), gamma (1, 1),
          no auto-brightening, linear sRGB primaries, the white balance stated in
          :data:`WHITE_BALANCES` (default the camera's as-shot balance). 1.0 is the
          white level in the least-amplified channel (dcraw's convention).
``tiff``  8/16/32-bit through tifffile. The transfer function is decided by
          :func:`tiff_transfer` (the rule below); integer samples are divided by
          ``2**bits - 1``, float samples are taken as they are.
``png``   8-bit through Pillow, 16-bit through libpng (imagecodecs: Pillow reduces
          16-bit colour PNGs to 8 bits); sRGB-encoded unless the file says otherwise.
``jpeg``  through Pillow; sRGB-encoded unless its ICC profile says otherwise.
``exr``   through :mod:`mitsweep.io.exr`: already linear.
========  ============================================================================

**Transfer rule** (TIFF, PNG, JPEG), first match wins:

1. the ``transfer`` argument (``"linear"`` or ``"srgb"``), when given;
2. floating-point samples are linear;
3. mitsweep's own display files state it (``"transfer"`` in a TIFF's JSON
   ``ImageDescription`` or a PNG's ``mitsweep`` text chunk);
4. an embedded ICC profile: a gray/red tone curve that is the identity or a pure
   gamma of 1.0 is linear; another pure gamma γ decodes as ``x**γ``; any other curve
   (the sRGB curve, parametric curves) as sRGB. A PNG ``gAMA`` chunk without an
   ``sRGB`` chunk is read the same way;
5. otherwise integer samples are sRGB-encoded (what image software writes by default).

Only the transfer function is undone; colour primaries are not converted.

Pixel pitch (mm) comes from the file's EXIF ``FocalPlaneXResolution`` and
``FocalPlaneResolutionUnit`` (RAW, TIFF, JPEG) or a mitsweep EXR's setup, else from the
``pixel_pitch`` argument, else it is None.

Memory: the width and height a file's header declares are checked against the memory
available and ``$MITSWEEP_MAX_MEMORY_GB`` (:func:`mitsweep.resources.check_allocation`)
before any pixel is decoded; Pillow's own decompression-bomb limit is replaced by that
check while a file is opened.

:func:`write_display_image` writes a linear image as a 16-bit sRGB TIFF or PNG for
viewing (the linear result belongs in EXR, :func:`mitsweep.io.exr.write_exr`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import struct
import threading
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from .atomic import atomic_path
from .exr import _json_default
from .exr import _openexr_chatter as _library_chatter  # collects C libraries' stderr
from .png import linear_to_srgb
from ..resources import ResourceError, require_regular_file

__all__ = ["CameraFileError", "CameraImage", "RAW_SUFFIXES", "CAMERA_SUFFIXES",
           "WHITE_BALANCES", "TRANSFERS", "read_camera_image", "write_display_image",
           "srgb_to_linear", "tiff_transfer", "dng_noise_profile", "NOISE_PROFILE_TAG"]

logger = logging.getLogger(__name__)

#: File suffixes read through rawpy/LibRaw.
RAW_SUFFIXES = (".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2",
                ".raf", ".orf", ".rw2", ".rwl", ".pef", ".srw", ".3fr", ".iiq", ".erf",
                ".mrw", ".dcr", ".kdc", ".mos", ".x3f", ".raw")
_KIND_OF_SUFFIX = {**{s: "raw" for s in RAW_SUFFIXES}, ".tif": "tiff", ".tiff": "tiff",
                   ".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg", ".exr": "exr"}
#: Every suffix :func:`read_camera_image` accepts.
CAMERA_SUFFIXES = tuple(_KIND_OF_SUFFIX)
#: White balance of RAW decoding: the camera's as-shot multipliers, LibRaw's daylight
#: multipliers for the camera, a grey-world estimate from the image, or none (unit
#: multipliers: the sensor's raw channel response).
WHITE_BALANCES = ("camera", "daylight", "auto", "none")
#: Transfer functions the ``transfer`` argument may force.
TRANSFERS = ("linear", "srgb")

#: Share of pixels at the white level above which a clipping warning is given.
CLIPPED_WARN_FRACTION = 1e-3
#: Relative difference between the file's pitch and the argument's that is reported.
PITCH_MISMATCH_WARN = 0.01

_EIGHT_BIT_WARNING = ("8-bit input: 256 sRGB-encoded levels limit the restoration "
                      "(deconvolution amplifies quantisation noise); use a RAW file or a "
                      "16-bit TIFF where possible")
_JPEG_WARNING = ("JPEG input: lossy compression adds block artefacts that deconvolution "
                 "amplifies")


class CameraFileError(ValueError):
    """A camera file cannot be read, or holds something that is not an image."""


@dataclass(frozen=True)
class CameraImage:
    """A photograph decoded to linear values.

    Attributes
    ----------
    data : (H, W, 3) or (H, W) float32 ndarray
        Linear values; the format's white level is 1.0.
    pixel_pitch : float or None
        Pixel pitch, mm: from the file's metadata, else the caller's, else None.
    kind : {"raw", "tiff", "png", "jpeg", "exr"}
    bit_depth : int
        Bits per sample as stored (8, 16, 32; RAW: the bits the white level needs).
    meta : dict
        ``path``, ``transfer``, ``white_level``, ``black_level``, ``white_balance`` (RAW),
        ``exif`` (essentials found), ``exr_header`` (EXR), ``pixel_pitch_source``;
        ``noise`` for a RAW whose file states its noise (a DNG's NoiseProfile,
        :func:`dng_noise_profile`): ``profile`` (the (S, O) pairs), ``sigma`` (per
        channel of ``data``, carried through LibRaw's development) and ``source``.
    warnings : list of str
        What limits the result (8-bit input, JPEG, clipping, a pitch mismatch); each is
        also logged (:meth:`log_warnings`).
    """

    data: np.ndarray
    pixel_pitch: float | None
    kind: str
    bit_depth: int
    meta: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return int(self.data.shape[0]), int(self.data.shape[1])

    def log_warnings(self) -> None:
        """Log each of :attr:`warnings` (level WARNING), prefixed with the file's path."""
        for w in self.warnings:
            logger.warning("%s: %s", self.meta.get("path", "camera file"), w)


def srgb_to_linear(x: ArrayLike) -> np.ndarray:
    """The sRGB transfer function inverted (IEC 61966-2-1), float32, on [0, 1].

    Parameters
    ----------
    x : array_like
        sRGB-encoded values, 1 = full white; computed in float32, not clipped.

    Returns
    -------
    ndarray
        Linear values, float32, of ``x``'s shape.
    """
    x = np.asarray(x, dtype=np.float32)
    return np.where(x <= 0.04045, x / np.float32(12.92),
                    ((x + np.float32(0.055)) / np.float32(1.055)) ** np.float32(2.4)
                    ).astype(np.float32)


# --------------------------------------------------------------------------- reading


def read_camera_image(path: str | Path, *, pixel_pitch: float | None = None,
                      white_balance: str = "camera", transfer: str | None = None,
                      log_warnings: bool = True, noise: bool = True) -> CameraImage:
    """Read a camera file as a linear float32 image.

    Parameters
    ----------
    path : path
        A RAW (see :data:`RAW_SUFFIXES`), TIFF, PNG, JPEG or EXR file, by suffix.
    pixel_pitch : float, optional
        Pitch (mm) to use when the file does not state one.
    white_balance : {"camera", "daylight", "auto", "none"}
        RAW only: see :data:`WHITE_BALANCES`.
    transfer : {"linear", "srgb"}, optional
        Force the transfer function of a TIFF, PNG or JPEG (default: the module's rule).
    log_warnings : bool
        Log the image's warnings now (default). A command that may still refuse the
        photo passes False and calls :meth:`CameraImage.log_warnings` once it accepts
        it, so that a refusal is the only line the user sees.
    noise : bool
        RAW only: develop the file's noise into ``meta["noise"]`` (its NoiseProfile, or
        the noise line estimated from its photosites,
        :func:`mitsweep.io.raw_noise.estimate_raw_noise`), which takes a second LibRaw
        development (on a 24 MP DNG it more than triples the read time). A reader that
        does not weigh a restoration (calibration, unwarping) passes False.

    Returns
    -------
    CameraImage

    Raises
    ------
    CameraFileError
        Unknown suffix, missing, unreadable or truncated file, an image that is not
        (H, W[, 3|4]), or a bad argument; the message is one line naming the file.
    mitsweep.resources.ResourceError
        The size the file's header declares would not fit the memory
        (``$MITSWEEP_MAX_MEMORY_GB``); checked before any pixel is decoded.
    """
    p = Path(path)
    kind = _KIND_OF_SUFFIX.get(p.suffix.lower())
    if kind is None:
        raise CameraFileError(f"{p}: unknown camera file type {p.suffix or '(no suffix)'!r}; "
                              f"allowed: RAW ({', '.join(RAW_SUFFIXES[:6])}, ...), .tif, "
                              f".tiff, .png, .jpg, .jpeg, .exr")
    if white_balance not in WHITE_BALANCES:
        raise CameraFileError(f"white balance must be one of {', '.join(WHITE_BALANCES)}, "
                              f"got {white_balance!r}")
    if transfer is not None and transfer not in TRANSFERS:
        raise CameraFileError(f"transfer must be one of {', '.join(TRANSFERS)}, "
                              f"got {transfer!r}")
    if pixel_pitch is not None and not (math.isfinite(pixel_pitch) and pixel_pitch > 0):
        raise CameraFileError(f"pixel pitch must be a finite number > 0 mm, got {pixel_pitch!r}")
    require_regular_file(p, "photo")
    if not p.is_file():
        raise CameraFileError(f"{p}: no such file")
    reader = {"raw": _read_raw, "tiff": _read_tiff, "png": _read_png, "jpeg": _read_jpeg,
              "exr": _read_exr}[kind]
    warnings: list[str] = []
    extra = {"noise": bool(noise)} if kind == "raw" else {}
    data, bit_depth, meta, file_pitch = reader(p, warnings=warnings,
                                               white_balance=white_balance, transfer=transfer,
                                               **extra)
    data = _as_image(np.asarray(data), p, warnings)
    if not np.all(np.isfinite(data)):
        raise CameraFileError(f"{p}: holds NaN or infinite values")
    meta["path"] = str(p)
    pitch, source = file_pitch, "file" if file_pitch is not None else None
    if pitch is None and pixel_pitch is not None:
        pitch, source = float(pixel_pitch), "argument"
    elif pitch is not None and pixel_pitch is not None \
            and abs(pitch - pixel_pitch) > PITCH_MISMATCH_WARN * pixel_pitch:
        warnings.append(f"the file states a pixel pitch of {pitch:.6g} mm, not the "
                        f"{pixel_pitch:.6g} mm given; using the file's")
    meta["pixel_pitch_source"] = source
    image = CameraImage(data=data, pixel_pitch=pitch, kind=kind, bit_depth=int(bit_depth),
                        meta=meta, warnings=warnings)
    if log_warnings:
        image.log_warnings()
    return image


def _as_image(a: np.ndarray, p: Path, warnings: list[str]) -> np.ndarray:
    """(H, W) or (H, W, 3) float32: a single channel squeezed, alpha dropped."""
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 3 and a.shape[2] in (2, 4):
        warnings.append("alpha channel ignored")
        a = a[..., 0] if a.shape[2] == 2 else a[..., :3]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3) or min(a.shape[:2]) < 1:
        raise CameraFileError(f"{p}: expected an (H, W) or (H, W, 3) image, got shape "
                              f"{a.shape}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _clip_warning(a: np.ndarray, white: float, warnings: list[str]) -> None:
    if a.size == 0:  # refused by _as_image; no mean of nothing (NumPy would warn)
        return
    frac = float(np.mean(np.max(a, axis=-1) >= white)) if a.ndim == 3 else \
        float(np.mean(a >= white))
    if frac > CLIPPED_WARN_FRACTION:
        warnings.append(f"{100 * frac:.2g}% of pixels are at the white level (clipped): "
                        f"deconvolution cannot restore them")


def _raw_error(p: Path, exc: BaseException, said: list[str]) -> CameraFileError:
    cause = exc.args[0] if exc.args else type(exc).__name__
    if isinstance(cause, bytes):
        cause = cause.decode("utf-8", "replace")
    told = "; ".join(s.split(": ", 1)[-1] for s in said)
    return CameraFileError(f"{p}: not a readable RAW file ({cause}"
                           f"{'; ' + told if told else ''})")


def _read_raw(p: Path, *, warnings, white_balance, transfer, noise=True):
    import rawpy

    if transfer not in (None, "linear"):
        raise CameraFileError(f"{p}: a RAW file is linear; transfer {transfer!r} does not apply")
    wb_choices: dict[str, dict[str, Any]] = {
        "camera": dict(use_camera_wb=True), "daylight": dict(use_camera_wb=False),
        "auto": dict(use_auto_wb=True), "none": dict(user_wb=[1.0, 1.0, 1.0, 1.0])}
    wb_args = wb_choices[white_balance]
    develop_noise = noise
    profile = dng_noise_profile(p) if develop_noise else None
    noise = None
    try:
        with _library_chatter() as said:
            with rawpy.imread(str(p)) as raw:
                sizes = raw.sizes
                # LibRaw's raw buffer (2 bytes a photosite) and its 4-channel 16-bit image,
                # the 16-bit RGB it returns; then the float32 RGB and its work
                _check_decode(p, "RAW", int(sizes.width), int(sizes.height), 3,
                              2 * float(sizes.raw_width) * float(sizes.raw_height)
                              / max(1.0, float(sizes.width) * float(sizes.height)) + 8 + 6)
                rgb = raw.postprocess(gamma=(1, 1), no_auto_bright=True, output_bps=16,
                                      output_color=rawpy.ColorSpace.sRGB, user_flip=0,
                                      adjust_maximum_thr=0.0, **wb_args)
                white = int(raw.white_level)
                black = [int(b) for b in raw.black_level_per_channel]
                multipliers = {"camera": list(raw.camera_whitebalance),
                               "daylight": list(raw.daylight_whitebalance),
                               "none": [1.0, 1.0, 1.0, 1.0]}.get(white_balance)
                pattern = raw.color_desc.decode("ascii", "replace")
                source = "DNG NoiseProfile, developed by LibRaw (simulated)"
                if profile is None and develop_noise:
                    profile, source = _estimated_profile(p, raw, black, white)
                if profile is not None:
                    noise = _profile_through_libraw(raw, profile, rgb, black, white,
                                                    dict(gamma=(1, 1), no_auto_bright=True,
                                                         output_bps=16, user_flip=0,
                                                         output_color=rawpy.ColorSpace.sRGB,
                                                         adjust_maximum_thr=0.0, **wb_args))
                    noise["source"] = source
    except (CameraFileError, ResourceError):
        raise
    except (rawpy.LibRawError, OSError, ValueError) as exc:
        raise _raw_error(p, exc, said) from None
    if said:
        logger.debug("%s: LibRaw said: %s", p, " | ".join(said))
    if white <= max(black, default=0):
        raise CameraFileError(f"{p}: white level {white} is not above the black level "
                              f"{max(black)}")
    data = _scaled(rgb, 65535.0)
    del rgb
    _clip_warning(data, 1.0, warnings)
    exif, pitch = {}, None
    try:  # DNG, NEF, CR2, ARW, PEF are TIFF inside: their EXIF is readable there
        import tifffile

        with _library_chatter():
            with tifffile.TiffFile(str(p)) as tf:
                exif = _tiff_exif(tf.pages[0])
        pitch = _pitch_from_exif(exif, warnings)
    except Exception as exc:  # noqa: BLE001 - EXIF is optional; the image was read
        logger.debug("%s: no EXIF through tifffile (%s)", p, exc)
    meta = {"transfer": "linear", "white_level": white, "black_level": black,
            "white_balance": {"mode": white_balance, "multipliers": multipliers},
            "color_space": "linear sRGB primaries", "cfa_colors": pattern, "exif": exif}
    if noise is not None:
        meta["noise"] = noise
    return data, max(1, math.ceil(math.log2(white + 1))), meta, pitch


#: The DNG tag NoiseProfile: per CFA plane (or one for all), the pair (S, O) of the
#: noise variance ``S x + O`` of a raw value ``x`` normalised to [0, 1] between the
#: black and the white level (DNG 1.3+, written by phones and by Adobe's converter).
NOISE_PROFILE_TAG = 51041


def dng_noise_profile(path: str | os.PathLike) -> list[tuple[float, float]] | None:
    """The (S, O) pairs of a DNG's NoiseProfile tag (:data:`NOISE_PROFILE_TAG`), looked
    for in every IFD and sub-IFD; None where the file has none (or is no TIFF).

    Parameters
    ----------
    path : path-like
        The camera file.

    Returns
    -------
    list of (float, float) or None
        One pair per CFA plane, or one pair for all planes; each S ≥ 0, O ≥ 0 (a
        profile with a negative or non-finite value is ignored, with a log line).
    """
    try:
        import tifffile

        with _library_chatter():
            with tifffile.TiffFile(os.fspath(path)) as tf:
                pages = list(tf.pages)
                for page in list(pages):
                    pages += list(getattr(page, "pages", None) or [])
                for page in pages:
                    tags = getattr(page, "tags", None)   # a TiffFrame has none
                    tag = None if tags is None else tags.get(NOISE_PROFILE_TAG)
                    if tag is not None:
                        values = np.asarray(tag.value, dtype=np.float64).ravel()
                        break
                else:
                    return None
    except Exception as exc:  # noqa: BLE001 - optional metadata; the image is read apart
        logger.debug("%s: no NoiseProfile through tifffile (%s)", path, exc)
        return None
    if len(values) < 2 or len(values) % 2 or not np.all(np.isfinite(values)) \
            or np.any(values < 0):
        logger.info("%s: NoiseProfile %s is not (S, O) pairs >= 0: not used", path,
                    values.tolist())
        return None
    return [(float(a), float(b)) for a, b in values.reshape(-1, 2)]


def _estimated_profile(p: Path, raw, black, white) -> tuple[list | None, str]:
    """A RAW's noise line estimated from its own photosites
    (:func:`mitsweep.io.raw_noise.estimate_raw_noise`) where the file states none, and
    where it came from; ``(None, "")`` where the estimate is refused (its bins scatter
    off a noise line by more than :data:`mitsweep.io.raw_noise.MAX_SCATTER`: texture,
    not noise, in the flattest blocks)."""
    from .raw_noise import MAX_SCATTER, estimate_raw_noise

    est = estimate_raw_noise(raw.raw_image_visible, raw.raw_colors_visible, black, white)
    if est is None or not est["rms_rel"] <= MAX_SCATTER:
        logger.info("%s: no NoiseProfile, and the photosites' noise could not be told from "
                    "texture (%s): the noise is estimated from the image", p,
                    "too few flat blocks" if est is None
                    else f"bins {est['rms_rel']:.2f} RMS off the line")
        return None, ""
    (S, O), = est["profile"]
    return est["profile"], (f"estimated from the RAW's photosites (S {S:.3g}, O {O:.3g}; "
                            f"bins {est['rms_rel']:.2f} RMS off the line), developed by "
                            f"LibRaw (simulated)")


def _profile_through_libraw(raw, profile, clean, black, white, args) -> dict:
    """The file's noise profile carried through LibRaw's own pipeline (black level,
    white balance, demosaicking, colour matrix) by simulation: the raw photosites get
    noise of the profile's variance (fixed seed), are developed again with the same
    settings, and the difference from the clean development is the noise of the image
    :func:`read_camera_image` returns. Returns ``{"profile", "sigma", "source"}`` with
    ``sigma`` per output channel in the image's units (white level 1), measured over
    the pixels clipped in neither development."""
    visible = raw.raw_image_visible
    colours = np.asarray(raw.raw_colors_visible)
    pairs = np.asarray(profile if len(profile) > 1 else profile * 4, dtype=np.float64)
    plane = np.where(colours == 3, 1, colours)        # the second green is plane 1
    plane = np.minimum(plane, len(pairs) - 1)
    blk = np.asarray(black, dtype=np.float64)[np.minimum(colours, len(black) - 1)]
    span = float(white) - blk
    orig = visible.copy()
    x = np.clip((orig - blk) / span, 0.0, 1.0)
    sd = np.sqrt(pairs[plane, 0] * x + pairs[plane, 1]) * span
    rng = np.random.default_rng(0)
    visible[...] = np.clip(np.round(orig + sd * rng.standard_normal(orig.shape)), 0,
                           np.iinfo(visible.dtype).max).astype(visible.dtype)
    try:
        noisy = raw.postprocess(**args)
    finally:
        visible[...] = orig
    ok = (clean < 65535).all(axis=-1) & (noisy < 65535).all(axis=-1)
    # one channel at a time, in float32 (differences of 16-bit values are exact there):
    # a 24 MP photo's float64 difference of all three would be 0.6 GB
    sigma = [float(np.std(noisy[..., c][ok].astype(np.float32) - clean[..., c][ok],
                          dtype=np.float64) / 65535.0) if ok.any() else 0.0
             for c in range(clean.shape[-1])]
    return {"profile": [list(p) for p in profile], "sigma": sigma,
            "source": "DNG NoiseProfile, developed by LibRaw (simulated)"}


#: EXIF and TIFF tags kept in ``meta["exif"]`` (tifffile's names).
_EXIF_KEYS = ("Make", "Model", "UniqueCameraModel", "DateTimeOriginal", "DateTime",
              "ExposureTime", "FNumber", "ISOSpeedRatings", "PhotographicSensitivity",
              "FocalLength", "LensModel", "FocalPlaneXResolution", "FocalPlaneYResolution",
              "FocalPlaneResolutionUnit")
#: FocalPlaneResolutionUnit → mm per unit (EXIF: 2 inch, 3 cm, 4 mm, 5 µm).
_FOCAL_PLANE_UNIT_MM = {1: 25.4, 2: 25.4, 3: 10.0, 4: 1.0, 5: 1e-3}


def _plain(value):
    """An EXIF value as JSON-friendly Python: rationals as floats, enums as ints."""
    if isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, int) for v in value):
        return value[0] / value[1] if value[1] else None
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace").rstrip("\x00")
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):
        return value.item()
    if isinstance(value, (int, float, str)):
        return int(value) if isinstance(value, int) else value
    try:
        return float(value)  # PIL's IFDRational
    except (TypeError, ValueError):
        return str(value)


def _tiff_exif(page) -> dict:
    tags = {t.name: t.value for t in page.tags}
    exif = tags.get("ExifTag")
    if isinstance(exif, dict):
        tags = {**exif, **tags}
    return {k: _plain(tags[k]) for k in _EXIF_KEYS if k in tags}


def _pitch_from_exif(exif: Mapping[str, Any], warnings: list[str] | None = None
                     ) -> float | None:
    """Pixel pitch, mm, from FocalPlaneXResolution (pixels per unit) and its unit; None
    when either is missing or not what EXIF allows (a unit code 1-5, a number > 0). A unit
    that is not a code is reported in ``warnings``."""
    res = exif.get("FocalPlaneXResolution")
    code = exif.get("FocalPlaneResolutionUnit") or 2  # absent or 0: inches (the default)
    ok_code = isinstance(code, (int, float)) and not isinstance(code, bool) \
        and float(code).is_integer()
    unit = _FOCAL_PLANE_UNIT_MM.get(int(code)) if ok_code else None
    if unit is None:
        if warnings is not None and res is not None:
            warnings.append(f"EXIF FocalPlaneResolutionUnit {code!r} is not a unit code "
                            f"(1-5): the file's pixel pitch is not used")
        return None
    if not isinstance(res, (int, float)) or isinstance(res, bool) or not res > 0:
        return None
    pitch = unit / float(res)
    return pitch if 1e-4 < pitch < 1.0 else None  # 0.1 µm .. 1 mm: else not a pitch


def _scaled(a: np.ndarray, white: float) -> np.ndarray:
    """``a / white`` as float32, made in place (one float32 array, no float64 copy)."""
    data = a.astype(np.float32)
    data /= np.float32(white)
    return data


def _decode_transfer(a: np.ndarray, rule: str, gamma: float | None) -> np.ndarray:
    """Undo the transfer function of float32 ``a`` in place, in blocks of rows (the
    temporaries of the curve stay a few MiB whatever the image's size)."""
    if rule == "linear":
        return a
    rows = max(1, _TRANSFER_BLOCK_SAMPLES // max(1, a[:1].size))
    for r in range(0, a.shape[0], rows):
        block = a[r:r + rows]
        if rule == "gamma":
            np.power(np.clip(block, 0.0, None, out=block), np.float32(gamma), out=block)
        else:
            block[...] = srgb_to_linear(np.clip(block, 0.0, 1.0, out=block))
    return a


def icc_transfer(icc: bytes | None) -> tuple[str, float | None] | None:
    """``("linear"|"gamma"|"srgb", γ)`` from an ICC profile's gray or red tone curve.

    Parameters
    ----------
    icc : bytes or None
        The profile as embedded in the file (a TIFF's tag 34675, a PNG's iCCP chunk).
        Any bytes: a damaged profile never raises, it reads as None or as the curve
        its bytes spell.

    Returns
    -------
    (rule, gamma) or None
        ``("linear", None)`` for an identity curve (no entry, or γ 1 within 1e-3),
        ``("gamma", γ)`` for a one-entry power curve, ``("srgb", None)`` for a table or
        a parametric curve; None without a profile, a ``kTRC``/``rTRC`` tag, or when
        the profile is cut short.
    """
    if not icc or len(icc) < 132:
        return None
    try:
        (count,) = struct.unpack(">I", icc[128:132])
        table = {}
        for k in range(min(count, 256)):
            sig, off, size = struct.unpack(">4sII", icc[132 + 12 * k:144 + 12 * k])
            table[sig] = icc[off:off + size]
        curve = table.get(b"kTRC") or table.get(b"rTRC")
        if curve is None or curve[:4] != b"curv":
            return ("srgb", None) if curve is not None else None
        (n,) = struct.unpack(">I", curve[8:12])
        if n == 0:
            return ("linear", None)
        if n == 1:
            (g,) = struct.unpack(">H", curve[12:14])
            g = g / 256.0
            return ("linear", None) if abs(g - 1.0) < 1e-3 else ("gamma", g)
        return ("srgb", None)
    except struct.error:
        return None


def tiff_transfer(page: Any, forced: str | None = None) -> tuple[str, float | None, str]:
    """The transfer function of a TIFF page by the module's rule.

    Parameters
    ----------
    page : tifffile.TiffPage
        The page read: its sample format, ``ImageDescription`` and ICC profile (tag
        34675) decide, in that order.
    forced : {"linear", "srgb"}, optional
        The transfer the caller imposes; it wins over the page (default: the rule).

    Returns
    -------
    (rule, gamma, reason) : (str, float or None, str)
        ``rule`` is ``"linear"``, ``"srgb"`` or ``"gamma"`` (decode as ``x**gamma``);
        ``reason`` says which step of the rule decided.
    """
    if forced is not None:
        return forced, None, "forced by the caller"
    if page.sampleformat == 3:
        return "linear", None, "floating-point samples"
    described = _described_transfer(page.description)
    if described is not None:
        return described, None, "stated in the ImageDescription"
    icc = page.tags.get(34675)
    found = icc_transfer(bytes(icc.value) if icc is not None else None)
    if found is not None:
        return found[0], found[1], "ICC profile"
    return "srgb", None, "integer samples without a profile (default)"


def _described_transfer(text) -> str | None:
    try:
        value = json.loads(text or "").get("transfer")
    except (ValueError, AttributeError):
        return None
    return value if value in TRANSFERS else None


def _read_tiff(p: Path, *, warnings, white_balance, transfer):
    import tifffile

    try:
        with _library_chatter() as said:
            with tifffile.TiffFile(str(p)) as tf:
                # the first page is always a whole TiffPage (only later ones may be frames)
                page = cast("tifffile.TiffPage", tf.pages[0])
                if page.photometric == 32803:
                    raise CameraFileError(f"{p}: a raw CFA (Bayer) TIFF; give it a .dng "
                                          f"suffix to read it through LibRaw")
                if int(page.photometric) not in (0, 1, 2):
                    raise CameraFileError(
                        f"{p}: TIFF photometric {page.photometric!r} is not supported; "
                        f"allowed: grey (min-is-black) or RGB")
                shape, axes = tuple(int(n) for n in page.shape), page.axes
                h, w = (shape[axes.index(k)] if k in axes else 1 for k in "YX")
                samples = int(page.samplesperpixel)
                _check_decode(p, "TIFF", w, h, samples,
                              samples * np.dtype(page.dtype).itemsize)
                a = page.asarray()
                bits = int(page.bitspersample)
                rule, gamma, reason = tiff_transfer(page, transfer)
                exif = _tiff_exif(page)
                inverted = int(page.photometric) == 0
    except (CameraFileError, ResourceError):
        raise
    except Exception as exc:  # tifffile raises TiffFileError, ValueError, OSError, ...
        cause = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CameraFileError(f"{p}: not a readable TIFF file ({cause})") from None
    if said:
        logger.debug("%s: tifffile said: %s", p, " | ".join(said))
    if "S" in axes and axes.index("S") < axes.index("Y"):  # planar: (S, H, W)
        a = np.moveaxis(a, axes.index("S"), -1)
    a = np.squeeze(a) if a.ndim > 3 else a
    if np.issubdtype(a.dtype, np.integer):
        white = float(np.iinfo(a.dtype).max) if bits >= 8 * a.dtype.itemsize \
            else float(2 ** bits - 1)
        data = _scaled(a, white)
        if inverted:
            np.subtract(np.float32(1.0), data, out=data)
        _clip_warning(data, 1.0, warnings)
    elif np.issubdtype(a.dtype, np.floating):
        data, white = a.astype(np.float32), 1.0
    else:
        raise CameraFileError(f"{p}: TIFF samples of type {a.dtype} are not supported")
    if bits <= 8:
        warnings.append(_EIGHT_BIT_WARNING)
    data = _decode_transfer(data, rule, gamma)
    meta = {"transfer": rule if rule != "gamma" else f"gamma {gamma:g}",
            "transfer_reason": reason, "white_level": white, "black_level": 0, "exif": exif}
    return data, bits, meta, _pitch_from_exif(exif, warnings)


#: Bytes of work per decoded sample beyond what the decoder returns: the float32 image,
#: one float32 copy (alpha dropped, planes made contiguous), the boolean masks of the
#: clipping and finiteness checks, and the transfer decoding's bounded row blocks.
#: Measured peaks (tests/test_memory_gate.py) stay below this estimate.
_WORK_BYTES_PER_SAMPLE = 10
#: Rows per block of the transfer decoding: its temporaries stay a few MiB.
_TRANSFER_BLOCK_SAMPLES = 1 << 20


def _check_decode(p: Path, what: str, width: int, height: int, channels: int,
                  decoded_bytes: float) -> None:
    """Refuse a photo, from the size its header declares and before any pixel is decoded,
    when decoding it would not fit the memory (:func:`mitsweep.resources.check_allocation`).

    ``decoded_bytes`` is what the decoder itself holds per pixel (its own buffer and the
    array it returns); the float32 image and its work come on top.
    """
    from ..resources import check_allocation

    if width < 1 or height < 1:
        raise CameraFileError(f"{p}: the {what} header declares a {width}x{height} image; "
                              f"expected at least 1x1 pixels")
    pixels = float(width) * float(height)
    check_allocation(f"{p}: decoding the {width}x{height} {what} image",
                     pixels * (decoded_bytes + channels * _WORK_BYTES_PER_SAMPLE))


#: Pillow's decompression-bomb limit is one module global; mitsweep replaces it, while it
#: opens a file, with its own gate (:func:`_check_decode`, from the memory cap), so that
#: a huge declared size is one refusal naming the file, never Pillow's warning or error.
_PILLOW_LIMIT_LOCK = threading.Lock()


@contextlib.contextmanager
def _pillow_image(p: Path, label: str):
    """``PIL.Image.open`` of ``p`` (lazy: the header and the chunks before the pixels)
    with Pillow's own pixel limit lifted for this call, its errors as one
    :class:`CameraFileError` naming the file."""
    from PIL import Image

    with _PILLOW_LIMIT_LOCK:
        saved, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            im = Image.open(p)
        except Exception as exc:  # noqa: BLE001 - Pillow raises many types on bad files
            raise _pillow_error(p, label, exc) from None
        finally:
            Image.MAX_IMAGE_PIXELS = saved
    with im:
        yield im


def _pillow_error(p: Path, label: str, exc: BaseException) -> CameraFileError:
    cause = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    if type(exc).__name__ == "UnidentifiedImageError":
        cause = "not recognised as an image"
    return CameraFileError(f"{p}: not a readable {label} file ({cause})")


def _pillow_exif(p: Path, im) -> dict:
    """The :data:`_EXIF_KEYS` of an open Pillow image (empty when it has none)."""
    try:
        from PIL import ExifTags

        raw_exif = im.getexif()
        merged = {**dict(raw_exif.get_ifd(0x8769)), **dict(raw_exif)}
        named = {ExifTags.TAGS.get(k, str(k)): v for k, v in merged.items()}
        return {k: _plain(named[k]) for k in _EXIF_KEYS if k in named}
    except Exception as exc:  # noqa: BLE001 - EXIF is optional
        logger.debug("%s: EXIF not read (%s)", p, exc)
        return {}


#: Bytes per pixel Pillow holds for a mode (its own buffer: 1 or 4 bytes a pixel, 4 for
#: the 32-bit modes), before :func:`numpy.asarray` copies it.
_PILLOW_PIXEL_BYTES = {"1": 1, "L": 1, "P": 1, "I;16": 2, "I;16B": 2, "I;16L": 2}


def _read_pillow(p: Path, label: str):
    with _pillow_image(p, label) as im:
        w, h = im.size
        mode = im.mode
        # Pillow's buffer, a converted copy (palette → RGB(A), I;16B → I;16) and NumPy's
        # copy of it: at most three 4-byte pixels
        _check_decode(p, label, w, h, len(im.getbands()) if mode != "P" else 4,
                      3 * _PILLOW_PIXEL_BYTES.get(mode, 4))
        try:
            im.load()
            info = dict(im.info)
            exif = _pillow_exif(p, im)
            if mode in ("P", "PA", "1", "CMYK", "YCbCr", "LAB", "HSV"):
                conv = im.convert("RGBA" if mode == "PA" or "transparency" in info else "RGB")
            elif mode == "I;16B":
                conv = im.convert("I;16")
            else:
                conv = im
            a = np.asarray(conv)
        except Exception as exc:  # noqa: BLE001 - Pillow's decoders raise many types
            raise _pillow_error(p, label, exc) from None
    return a, mode, info, exif


def _read_jpeg(p: Path, *, warnings, white_balance, transfer):
    a, mode, info, exif = _read_pillow(p, "JPEG")
    rule, gamma, reason = _pillow_transfer(info, transfer, default_reason="JPEG (sRGB)")
    data = _scaled(a, 255.0)
    _clip_warning(data, 1.0, warnings)
    warnings.append(_EIGHT_BIT_WARNING)
    warnings.append(_JPEG_WARNING)
    meta = {"transfer": rule if rule != "gamma" else f"gamma {gamma:g}",
            "transfer_reason": reason, "white_level": 255, "black_level": 0,
            "source_mode": mode, "exif": exif}
    return _decode_transfer(data, rule, gamma), 8, meta, _pitch_from_exif(exif, warnings)


def _pillow_transfer(info: Mapping, forced: str | None, *, default_reason: str):
    if forced is not None:
        return forced, None, "forced by the caller"
    described = _described_transfer(info.get("mitsweep"))
    if described is not None:
        return described, None, "stated in the mitsweep text chunk"
    found = icc_transfer(info.get("icc_profile"))
    if found is not None:
        return found[0], found[1], "ICC profile"
    if "gamma" in info and "srgb" not in info:  # PNG gAMA: stored value is 1/γ
        g = 1.0 / float(info["gamma"]) if float(info["gamma"]) > 0 else 1.0
        return ("linear", None, "gAMA chunk") if abs(g - 1.0) < 1e-3 else \
            ("gamma", g, "gAMA chunk")
    return "srgb", None, default_reason


def _read_png(p: Path, *, warnings, white_balance, transfer):
    header = _png_header(p)
    if header is not None and header["bit_depth"] == 16:
        a, mode, info, exif = _read_png16(p, header)
    else:
        a, mode, info, exif = _read_pillow(p, "PNG")
    rule, gamma, reason = _pillow_transfer(info, transfer, default_reason="PNG (sRGB)")
    if a.dtype == np.uint8:
        bits, white = 8, 255.0
        warnings.append(_EIGHT_BIT_WARNING)
    elif a.dtype in (np.uint16, np.dtype(">u2")) or mode.startswith("I;16"):
        bits, white = 16, 65535.0
    elif mode == "I":  # Pillow's 32-bit integer mode holds 16-bit grey PNGs too
        bits, white = 16, 65535.0
    else:
        bits, white = 8 * a.dtype.itemsize, float(np.iinfo(a.dtype).max)
    data = _scaled(a, white)
    _clip_warning(data, 1.0, warnings)
    meta = {"transfer": rule if rule != "gamma" else f"gamma {gamma:g}",
            "transfer_reason": reason, "white_level": white, "black_level": 0,
            "source_mode": mode, "exif": exif}
    return _decode_transfer(data, rule, gamma), bits, meta, _pitch_from_exif(exif, warnings)


def _read_exr(p: Path, *, warnings, white_balance, transfer):
    from .exr import ExrError, read_exr, stack_channels

    if transfer not in (None, "linear"):
        raise CameraFileError(f"{p}: an EXR file is linear; transfer {transfer!r} does not apply")
    try:
        chans, header = read_exr(p)
    except ExrError as exc:
        raise CameraFileError(str(exc)) from None
    try:
        data = stack_channels(chans)
    except ValueError as exc:
        raise CameraFileError(f"{p}: {exc}") from None
    bits = 16 if data.dtype == np.float16 else 32
    pitch = None
    setup = header.get("setup")
    if isinstance(setup, dict):
        value = (setup.get("sensor") or {}).get("pixel_pitch")
        pitch = float(value) if isinstance(value, (int, float)) and value > 0 else None
    meta = {"transfer": "linear", "white_level": 1.0, "black_level": 0.0,
            "exr_header": header, "exif": {}}
    return data, bits, meta, pitch


# ------------------------------------------------------------- 16-bit PNG, both ways
#
# Pillow keeps no 16-bit colour mode: it reduces 16-bit RGB(A) PNGs to 8 bits (and so does
# imageio, whose PNG reader is Pillow). 16-bit PNGs are therefore decoded by libpng through
# imagecodecs (the codec library of tifffile's author, with binary wheels), which returns
# every 16-bit colour type as uint16; Pillow still reads their chunks (gAMA, sRGB, iCCP,
# text, eXIf) without decoding the pixels, so that both kinds of PNG share one metadata
# reader. Only the IHDR is parsed here: its width and height gate the decoding.

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_CHANNELS = {0: 1, 2: 3, 3: 1, 4: 2, 6: 4}  # by colour type (PNG spec, Table 11.1)


def _png_header(p: Path) -> dict | None:
    """The IHDR of a PNG file (None when the file does not start with one)."""
    with open(p, "rb") as f:
        head = f.read(33)
    if len(head) < 33 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        return None
    w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", head[16:29])
    return {"width": w, "height": h, "bit_depth": depth, "color_type": ctype,
            "interlace": interlace}


def _read_png16(p: Path, header: dict) -> tuple[np.ndarray, str, dict, dict]:
    """A 16-bit PNG as uint16 (H, W[, C]) through libpng, with Pillow's chunk metadata."""
    import imagecodecs

    channels = _PNG_CHANNELS.get(header["color_type"], 4)
    # libpng's row buffers and the uint16 array it fills; inflation stops at the rows
    # the header declares, so a stream that inflates further costs nothing more
    _check_decode(p, "PNG", header["width"], header["height"], channels, 4 * channels)
    with _pillow_image(p, "PNG") as im:  # chunks only: Pillow would reduce the pixels
        info = dict(im.info)
        # Pillow's getexif() of a PNG decodes the pixels to look for a late eXIf chunk:
        # only an eXIf before the image data is read
        exif = _pillow_exif(p, im) if "exif" in info else {}
    try:
        with _library_chatter() as said:  # libpng prints its warnings on descriptor 2
            a = imagecodecs.png_decode(p.read_bytes())
    except Exception as exc:  # noqa: BLE001 - PngError, and whatever libpng's wrapper raises
        cause = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CameraFileError(f"{p}: not a readable PNG file ({cause})") from None
    if said:
        logger.debug("%s: libpng said: %s", p, " | ".join(said))
    mode = {1: "I;16", 2: "LA;16", 3: "RGB;16", 4: "RGBA;16"}.get(a.shape[-1] if a.ndim == 3
                                                               else 1, "I;16")
    return a, mode, info, exif


def png16_bytes(img16: np.ndarray, text: Mapping[str, str]) -> bytes:
    """A 16-bit grey or RGB PNG (filter Up on every row, sRGB chunk, tEXt chunks).

    Parameters
    ----------
    img16 : (H, W) or (H, W, 3) ndarray of uint16
        The samples, written as they are (no transfer applied).
    text : mapping of str to str
        ``tEXt`` chunks, keyword to text (Latin-1; a character outside it is replaced).

    Returns
    -------
    bytes
        The whole file.
    """
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + \
            struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    h, w = img16.shape[:2]
    channels = 1 if img16.ndim == 2 else img16.shape[2]
    color_type = {1: 0, 3: 2}[channels]
    rows = np.ascontiguousarray(img16, dtype=">u2").view(np.uint8).reshape(h, -1)
    up = rows.copy()
    up[1:] -= rows[:-1]  # uint8 arithmetic wraps modulo 256, as the filter wants
    filtered = np.concatenate([np.full((h, 1), 2, np.uint8), up], axis=1)
    out = [_PNG_SIGNATURE,
           chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, color_type, 0, 0, 0)),
           chunk(b"sRGB", b"\x00")]
    out += [chunk(b"tEXt", k.encode("latin-1") + b"\x00" + v.encode("latin-1", "replace"))
            for k, v in text.items()]
    out += [chunk(b"IDAT", zlib.compress(filtered.tobytes(), 6)), chunk(b"IEND", b"")]
    return b"".join(out)


# --------------------------------------------------------------------------- writing

DISPLAY_SUFFIXES = (".tif", ".tiff", ".png")
#: Bytes a sample that :func:`write_display_image` holds beyond the image: the 16-bit
#: samples, the percentile's copy of the image (float32: 4), and the PNG writer's
#: big-endian, filtered and compressed copies (or tifffile's). Measured peaks
#: (tests/test_memory_gate.py) stay below it.
DISPLAY_BYTES_PER_SAMPLE = 20


def write_display_image(path: str | Path, image: np.ndarray, *, white: float | None = None,
                        metadata: Mapping[str, Any] | None = None) -> Path:
    """Write a linear image as a 16-bit sRGB TIFF or PNG for display (atomic).

    Parameters
    ----------
    path : path
        ``.tif``/``.tiff`` (zlib-compressed TIFF) or ``.png``.
    image : (H, W) or (H, W, 3) ndarray
        Linear values; negative values (deconvolution ringing) show as black.
    white : float, optional
        The linear value shown as full white (default: the 99.5th percentile, as
        :func:`mitsweep.io.png.write_png`).
    metadata : mapping, optional
        Provenance, stored as JSON with the transfer (``"srgb"``) and the white used:
        in the TIFF's ImageDescription, or a PNG ``tEXt`` chunk named ``mitsweep``, so
        that :func:`read_camera_image` decodes the file back to these linear values
        (divided by ``white``).

    Returns
    -------
    Path

    Notes
    -----
    Peak memory: about :data:`DISPLAY_BYTES_PER_SAMPLE` bytes a sample beyond ``image``.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in DISPLAY_SUFFIXES:
        raise ValueError(f"{p}: display images are .tif, .tiff or .png, got "
                         f"{p.suffix or '(no suffix)'!r}; linear results go to .exr")
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise ValueError(f"image must be (H, W) or (H, W, 3), got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image holds NaN or inf values; refusing to write them")
    if white is None:
        white = float(np.percentile(img, 99.5)) if img.size else 1.0
    if not (math.isfinite(white) and white > 0):
        white = 1.0
    # encoded in blocks of rows: the float64 curve's temporaries stay a few MiB
    img16 = np.empty(img.shape, np.uint16)
    rows = max(1, _TRANSFER_BLOCK_SAMPLES // max(1, img[:1].size))
    for r in range(0, img.shape[0], rows):
        block = np.asarray(img[r:r + rows], dtype=np.float64) / white
        img16[r:r + rows] = np.round(linear_to_srgb(block) * 65535.0)
    desc = json.dumps({"transfer": "srgb", "white": white, **dict(metadata or {})},
                      default=_json_default)
    with atomic_path(p, suffix=suffix) as tmp:
        if suffix == ".png":
            tmp.write_bytes(png16_bytes(img16, {"mitsweep": desc}))
        else:
            import tifffile

            tifffile.imwrite(tmp, img16, photometric="rgb" if img16.ndim == 3 else
                             "minisblack", description=desc, metadata=None,
                             compression="zlib")
    return p
