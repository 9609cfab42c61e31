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
              model: str = "mitsweep synthetic", noise: tuple[float, float] | None = None,
              noise_profile=None, seed: int = 0) -> Path:
    """Write linear ``rgb`` (H, W, 3) in [0, 1] (times ``neutral`` per channel, the
    camera's raw response) as a 16-bit RGGB DNG with the given black and white levels.

    ``noise = (S, O)``: each photosite gets Gaussian noise of variance ``S x + O`` (x
    the normalised raw value, the DNG convention), drawn with ``seed``.
    ``noise_profile``: the values of the NoiseProfile tag (51041) to write (pairs
    (S, O) flattened), e.g. ``noise`` itself; None writes no tag."""
    import tifffile

    rgb = np.asarray(rgb, dtype=np.float64) * np.asarray(neutral, dtype=np.float64)
    cfa = mosaic_rggb(np.clip(rgb, 0.0, 1.0))
    if noise is not None:
        S, O = noise
        cfa = cfa + np.sqrt(S * cfa + O) * np.random.default_rng(seed).standard_normal(cfa.shape)
    raw = np.clip(np.round(black + cfa * (white - black)), 0, 65535).astype(np.uint16)
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
    if noise_profile is not None:
        values = tuple(float(v) for v in np.ravel(noise_profile))
        tags.append((51041, "d", len(values), values, True))   # NoiseProfile
    if pitch_mm is not None:  # EXIF focal-plane resolution in IFD0, pixels per mm
        tags += [(41486, "2I", 1, _rationals([1.0 / pitch_mm], 1000), True),
                 (41487, "2I", 1, _rationals([1.0 / pitch_mm], 1000), True),
                 (41488, "H", 1, 4, True)]
    tifffile.imwrite(path, raw, photometric=32803, extratags=tags, subfiletype=0,
                     metadata=None)
    return Path(path)


def synthetic_mirror_photo(setup, shape, center_offset_px, *, supersample: int = 3,
                           sweep_samples: int = 3, blur_px: float = 0.8, holder: bool = True,
                           arm: bool = True, vignetting: bool = True, seed: int = 0,
                           mirror: bool = True, roll_deg: float = 0.0) -> np.ndarray:
    """A linear RGB "photo" (H, W, 3) of the setup's mirror, its axis at
    ``center_offset_px = (drow, dcol)`` from the image centre.

    Built by ray casting, independently of :mod:`mitsweep.optics.calibration`: each of
    ``supersample²`` sub-pixel chief rays per pixel, at ``sweep_samples`` sensor
    distances evenly over the sweep (the magnification breathes as in a sweep), is
    intersected with the mirror (:func:`mitsweep.optics.chief_ray.intersect_mirror`);
    hits show a texture of the world-bound reflected direction, misses a textured
    background, a dark holder ring just outside the rim and an arm from it to the frame
    edge; then a Gaussian blur of ``blur_px`` (defocus) and cos⁴ vignetting.
    ``roll_deg``: the camera turned about its axis, so that the image turns by that much
    counter-clockwise as displayed.
    """
    from scipy.ndimage import gaussian_filter

    from mitsweep.optics.chief_ray import mirror_point_from_image
    from mitsweep.optics.pixels import pixel_to_sensor
    from mitsweep.optics.placement import placement_of
    from mitsweep.optics.reference import reference_geometry

    H, W = shape
    pitch = setup.sensor.pixel_pitch
    geo = reference_geometry(setup)
    i_lo, i_hi = sorted((geo.sweep.sensor_start, geo.sweep.sensor_end))
    distances = np.linspace(i_lo, i_hi, sweep_samples) if sweep_samples > 1 else \
        np.array([geo.sensor_distance])
    placement = placement_of(setup.mirror)
    rng = np.random.default_rng(seed)
    k = supersample
    sub = (np.arange(k) + 0.5) / k - 0.5
    rows = (np.arange(H)[:, None] + sub[None, :]).ravel()
    cols = (np.arange(W)[:, None] + sub[None, :]).ravel()
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    u, v = pixel_to_sensor(rr, cc, (H, W), pitch, center_offset_px=center_offset_px)
    if roll_deg:
        t = np.radians(roll_deg)  # what the unrolled camera sees at R(-t)(u, v)
        u, v = np.cos(t) * u + np.sin(t) * v, -np.sin(t) * u + np.cos(t) * v
    freq = rng.uniform(2.0, 9.0, size=(3, 2))
    phase = rng.uniform(0, 2 * np.pi, size=3)
    img = np.zeros(rr.shape + (3,))
    for i in distances:
        tan_u, tan_v = u / i, v / i  # direction of the chief ray (pinhole) at this distance
        bg = 0.25 + 0.15 * np.sin(40 * tan_u + 1.0) * np.cos(33 * tan_v) \
            + 0.1 * np.sin(150 * (tan_u + 0.3 * tan_v))
        layer = np.repeat(bg[..., None], 3, axis=-1) * np.array([0.9, 1.0, 1.1])
        r_ang = np.hypot(tan_u, tan_v)
        if mirror:
            ray = mirror_point_from_image(placement, u, v, i)
            hit = np.isfinite(ray.surface.rho) & (ray.cos_incidence > 0)
            w = ray.world_dir
            tex = [0.45 + 0.3 * np.sin(freq[c, 0] * np.arctan2(w[..., 1], w[..., 0])
                                       + freq[c, 1] * w[..., 2] + phase[c]) for c in range(3)]
            tex = np.nan_to_num(np.stack(tex, axis=-1))
            # the holder: a dark ring from the rim's angular radius to 12% beyond
            rim_ang = np.nanmax(np.where(hit, r_ang, np.nan)) if hit.any() else 0.0
            if holder:
                ring = (r_ang > 0.9 * rim_ang) & (r_ang < 1.12 * rim_ang) & ~hit
                layer[ring] = 0.04
            if arm:
                bar = (np.abs(tan_v) < 0.12 * rim_ang) & (tan_u > rim_ang) & ~hit
                layer[bar] = 0.06
            layer[hit] = tex[hit]
        img += layer
    img /= len(distances)
    img = img.reshape(H, k, W, k, 3).mean(axis=(1, 3))
    img = gaussian_filter(img, (blur_px, blur_px, 0)) if blur_px > 0 else img
    if vignetting:
        r0, c0 = (H - 1) / 2, (W - 1) / 2
        rad = np.hypot(*np.meshgrid(np.arange(H) - r0, np.arange(W) - c0, indexing="ij"))
        img *= (np.cos(np.arctan(rad / (1.2 * max(H, W)))) ** 4)[..., None]
    return img
