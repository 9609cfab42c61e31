"""Synthetic camera files for the tests: a DNG that LibRaw reads, written with tifffile.

The DNG holds a Bayer (RGGB) mosaic of a linear image whose camera is linear sRGB: its
``ColorMatrix1`` is the XYZ → linear-sRGB matrix (D65), so LibRaw's sRGB output equals
the input up to the white balance; ``AsShotNeutral`` is the camera's response to grey.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["XYZ_TO_SRGB", "mosaic_rggb", "write_dng"]

#: XYZ (D65) → linear sRGB, IEC 61966-2-1.
XYZ_TO_SRGB = np.array([[3.2404542, -1.5371385, -0.4985314],
                        [-0.9692660, 1.8760108, 0.0415560],
                        [0.0556434, -0.2040259, 1.0572252]])


def mosaic_rggb(rgb: np.ndarray) -> np.ndarray:
    """The RGGB Bayer samples (H, W) of a linear (H, W, 3) image."""
    cfa = np.empty(rgb.shape[:2], dtype=np.float64)
    cfa[0::2, 0::2] = rgb[0::2, 0::2, 0]
    cfa[0::2, 1::2] = rgb[0::2, 1::2, 1]
    cfa[1::2, 0::2] = rgb[1::2, 0::2, 1]
    cfa[1::2, 1::2] = rgb[1::2, 1::2, 2]
    return cfa


def _rationals(values, denominator: int = 1_000_000) -> tuple[int, ...]:
    out: list[int] = []
    for v in np.ravel(values):
        out += [int(round(float(v) * denominator)), denominator]
    return tuple(out)


def write_dng(path, rgb: np.ndarray, *, black: int = 512, white: int = 15000,
              neutral=(1.0, 1.0, 1.0), pitch_mm: float | None = None,
              model: str = "mitsweep synthetic") -> Path:
    """Write linear ``rgb`` (H, W, 3) in [0, 1] (times ``neutral`` per channel, the
    camera's raw response) as a 16-bit RGGB DNG with the given black and white levels."""
    import tifffile

    rgb = np.asarray(rgb, dtype=np.float64) * np.asarray(neutral, dtype=np.float64)
    cfa = mosaic_rggb(np.clip(rgb, 0.0, 1.0))
    raw = np.round(black + cfa * (white - black)).astype(np.uint16)
    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),          # DNGVersion
        (50708, "s", 0, model, True),                 # UniqueCameraModel
        (33421, "H", 2, (2, 2), True),                # CFARepeatPatternDim
        (33422, "B", 4, (0, 1, 1, 2), True),          # CFAPattern: R G / G B
        (50710, "B", 3, (0, 1, 2), True),             # CFAPlaneColor
        (50711, "H", 1, 1, True),                     # CFALayout: rectangular
        (50714, "H", 1, black, True),                 # BlackLevel
        (50717, "H", 1, white, True),                 # WhiteLevel
        (50721, "2i", 9, _rationals(XYZ_TO_SRGB), True),  # ColorMatrix1 (XYZ → camera)
        (50778, "H", 1, 21, True),                    # CalibrationIlluminant1: D65
        (50728, "2I", 3, _rationals(neutral), True),  # AsShotNeutral
    ]
    if pitch_mm is not None:  # EXIF focal-plane resolution in IFD0, pixels per mm
        tags += [(41486, "2I", 1, _rationals([1.0 / pitch_mm], 1000), True),
                 (41487, "2I", 1, _rationals([1.0 / pitch_mm], 1000), True),
                 (41488, "H", 1, 4, True)]
    tifffile.imwrite(path, raw, photometric=32803, extratags=tags, subfiletype=0,
                     metadata=None)
    return Path(path)
