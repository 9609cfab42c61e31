"""Scores of a dataset: its EDOF, focused, stopped and noisy images against the ground
truth, inside the mirror's image (PSNR and SSIM overall, per radius, per depth band)."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..optics.pixels import optical_center_px
from .dataset import load_manifest
from .runner import DatasetError, sha256
from .tasks import read_rgb, white_level

__all__ = ["evaluate_dataset", "checked_items", "read_finite", "DEPTH_BANDS_MM"]

DEPTH_BANDS_MM = (0.0, 300.0, 1000.0, 3000.0, math.inf)
#: A scene's entry holding its render tasks' ``scene_source`` (procedural and XML scenes).
_SOURCE = "source"


def checked_items(root: Path, manifest: dict, *, checksums: bool = True) -> dict[str, Path]:
    """The items of a complete dataset, each file present and unchanged since written.

    Parameters
    ----------
    root : Path
        The dataset directory.
    manifest : dict
        Its manifest, validated (:func:`~mitsweep.pipeline.load_manifest`).
    checksums : bool
        Compare every file's SHA-256 with the manifest's (reads every file); ``False``
        compares sizes only.

    Returns
    -------
    dict of str to Path
        Item name (``scene_000/sweep.exr``) to its file, sorted by name.

    Raises
    ------
    DatasetError
        The dataset is incomplete, or a file is missing or changed (naming it).
    """
    if manifest.get("complete") is not True:
        raise DatasetError(f"{root}: incomplete dataset (rerun `mitsweep dataset` with the "
                           f"same options to finish it)")
    files = {}
    for name, item in sorted(manifest["items"].items()):
        p = root / name
        if not p.is_file():
            raise DatasetError(f"{p}: listed in the manifest but missing (rerun `mitsweep "
                               f"dataset` to redo it)")
        if p.stat().st_size != item["bytes"] or (checksums and sha256(p) != item["sha256"]):
            raise DatasetError(f"{p}: changed since it was written (size or SHA-256 differs "
                               f"from the manifest; rerun `mitsweep dataset` to redo it)")
        files[name] = p
    return files


def read_finite(path: Path) -> tuple[np.ndarray, dict, dict]:
    """An item's RGB image (H, W, 3), channels and metadata
    (:func:`mitsweep.pipeline.tasks.read_rgb`), every pixel finite.

    Parameters
    ----------
    path : Path
        An EXR item of a dataset.

    Returns
    -------
    (ndarray, dict, dict)
        The ``(H, W, 3)`` float32 image, its other channels by name (``mask.Y``,
        ``depth.Z``...), its metadata.

    Raises
    ------
    DatasetError
        Naming the file and the channel, if any pixel is NaN or inf.
    """
    img, chans, meta = read_rgb(path)
    for name, arr in {"image": img, **chans}.items():
        if not np.all(np.isfinite(arr)):
            raise DatasetError(f"{path}: holds NaN or inf pixels (channel {name}); cannot "
                               f"score it (rerun `mitsweep dataset` to redo it)")
    return img, chans, meta


def evaluate_dataset(directory: str | os.PathLike, *, n_radial_bins: int = 8) -> dict:
    """Score EDOF against focused and stopped images, on the ground truth.

    Returns per scene and averaged: PSNR (dB) and SSIM inside the mirror's image, per
    radial bin (pixels from the optical axis) and per depth band (mm), for ``edof``
    (Wiener), ``edof_<method>`` (every other restoration method the dataset holds),
    ``focused``, ``stopped``, ``sweep`` (not deconvolved) and the noisy variants
    (``_<lux>lux``), each under its item's name; a procedural or XML scene's entry
    also holds ``source``, its render tasks' ``scene_source`` (family and seed and
    parameters, or file and SHA-256).

    The manifest is validated (:func:`load_manifest`); the dataset must be complete,
    with every item's file present and unchanged, and every image finite.

    Parameters
    ----------
    directory : str or path-like
        A complete dataset (``mitsweep dataset``).
    n_radial_bins : int
        Radial bins, equal in width from the optical axis to the mirror's image edge
        (px).

    Returns
    -------
    dict
        ``dataset`` (the directory), ``scenes`` (per scene: ``white_level``,
        ``mirror_radius_px``, ``source`` where it has one, and per image ``psnr``,
        ``ssim``, ``per_radius``, ``per_depth_band``) and ``mean`` (per image name, the
        scenes' mean ``psnr`` and ``ssim``).

    Raises
    ------
    DatasetError
        An invalid manifest, an incomplete dataset, a missing, changed or non-finite
        file, a ground truth with no or an empty mirror mask, a shape mismatch.
    """
    from ..deconv import per_depth_band, per_radius, psnr, ssim

    root = Path(directory)
    manifest = load_manifest(root)
    files = checked_items(root, manifest)
    n_scenes = manifest["options"]["scenes"]
    results: dict[str, Any] = {"dataset": str(root), "scenes": {}}
    for i in range(n_scenes):
        d = root / f"scene_{i:03d}"
        gt, chans, _ = read_finite(d / "pinhole.exr")
        mask = chans.get("mask.Y")
        if mask is None:
            raise DatasetError(f"{d}/pinhole.exr: no mask.Y channel (mirror mask AOV)")
        m = mask > 0.5
        if not np.any(m):
            raise DatasetError(f"{d}/pinhole.exr: the mirror mask is empty (nothing to score)")
        depth = chans.get("depth.Z", np.full(mask.shape, np.nan, dtype=np.float32))
        depth = np.where(m & (depth > 0), depth, np.nan)
        level = white_level(gt, mask)
        ref = gt / level
        ys, xs = np.nonzero(m)
        cy, cx = optical_center_px(m.shape)
        r_max = float(np.max(np.hypot(ys - cy, xs - cx))) + 0.5
        edges = np.linspace(0.0, r_max, n_radial_bins + 1)
        scene_res: dict[str, Any] = {"white_level": level, "mirror_radius_px": r_max}
        source = manifest["items"][f"{d.name}/pinhole.exr"]["params"].get("scene_source")
        if source is not None:  # not the room: say which scene (family and seed, or file)
            scene_res[_SOURCE] = source
        for name, path in files.items():  # every image of the scene, every EDOF
            if not name.startswith(f"{d.name}/") or path.suffix != ".exr" \
                    or path.stem == "pinhole":
                continue
            img = read_finite(path)[0] / level
            if img.shape != ref.shape:
                raise DatasetError(f"{path}: shape {img.shape} differs from the ground "
                                   f"truth's {ref.shape}")
            # An image leaves the mirror's disc alone outside the mask: score inside only.
            entry = {"psnr": psnr(img, ref, mask=m), "ssim": ssim(img, ref, mask=m),
                     "per_radius": _listify(per_radius(img, ref, edges, mask=m)),
                     "per_depth_band": _listify(per_depth_band(img, ref, depth,
                                                               list(DEPTH_BANDS_MM), mask=m))}
            scene_res[path.stem] = entry
        results["scenes"][d.name] = scene_res
    names = sorted({k for s in results["scenes"].values() for k, v in s.items()
                    if isinstance(v, dict) and k != _SOURCE})
    scenes = list(results["scenes"].values())
    results["mean"] = {n: {m: float(np.nanmean([s[n][m] for s in scenes if n in s]))
                           for m in ("psnr", "ssim")}
                       for n in names}
    return results


def _listify(d: dict) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}
