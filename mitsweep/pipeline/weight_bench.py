"""A dataset's Wiener weights against the oracle, before and after the noise-model rule.

For every scene's noise-free sweep and noisy sweep of a complete dataset,
:func:`dataset_weight_bench` restores the image as the dataset does (Wiener, natural
prior, the bank's 500-mm kernels) with the oracle NSR
(:func:`mitsweep.deconv.budget.oracle_weight`), with the former rule (``before``: the
larger of the image's variance-based estimate and the noise model's NSR at exposure
0.5), with the noise-model rule (``after``: :func:`mitsweep.deconv.weights.model_nsr`
with the image's noise model and mirror mask, the whole frame's spectrum; the datasets'
rule before the calibrated one) and with the
same read over the mirror's image (``mirror``: ``spectrum="mirror"``), and reports each
one's PSNR loss against the oracle, in one process. With a ``calibration_scene``, that
scene's noise-free sweep and truth calibrate the bank's mismatch profile
(:func:`mitsweep.deconv.weights.calibrate_mismatch`) and the other scenes are also
restored with it (``calibrated``: ``model_nsr(..., mismatch=profile)``): held out, as a rig's
profile measured on renders would be used on its photos. Without one, the ``calibrated``
column uses the dataset's own profile, measured on its calibration scene (the datasets'
rule, :data:`mitsweep.pipeline.tasks.WEIGHT_RULE`).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .dataset import load_manifest
from .evaluation import checked_items, read_finite
from .tasks import (BANK, DECONV_PRIOR, MISMATCH, calibration_profile, is_scene_item,
                    read_mismatch, white_level)

__all__ = ["dataset_weight_bench"]

_SWEEP = re.compile(r"sweep(?:_(?P<lux>[0-9.e+-]+)lux)?")


def _lux(name: str) -> float:
    """The light level of a sweep item's name, lux (``sweep_2lux.exr``: 2; the
    noise-free ``sweep.exr``: inf)."""
    match = _SWEEP.fullmatch(Path(name).stem)
    if match is None:
        raise ValueError(f"{name}: not a sweep item")
    return float(match["lux"] or "inf")


def dataset_weight_bench(directory: str | Path, *, scenes: int | None = None,
                         calibration_scene: int | None = None) -> list[dict]:
    """The weights of each sweep image of a dataset against the oracle.

    Parameters
    ----------
    directory : str or Path
        A complete dataset (``mitsweep dataset``; its items are checked as for
        :func:`~mitsweep.pipeline.evaluate_dataset`).
    scenes : int, optional
        Only the first so many scenes (default: all; the calibration scene is not
        counted among them).
    calibration_scene : int, optional
        The scene (its index) whose noise-free sweep and truth give the mismatch
        profile of the ``calibrated`` weight; it is not itself restored. Default: the
        dataset's own profile (its calibration scene's, :data:`~.tasks.MISMATCH`, the
        datasets' rule), or no ``calibrated`` column for a dataset made before it.

    Returns
    -------
    list of dict
        Per sweep image (noise-free first, then by decreasing light level), the row of
        :func:`mitsweep.deconv.weight_bench.weight_rows` for the weights ``before``,
        ``after``, ``mirror`` (and ``calibrated``), with ``case``: the dataset's folder
        name, the scene, the image.
    """
    from ..deconv import SensorNoise, deconvolve, estimate_nsr
    from ..deconv.weight_bench import weight_rows
    from ..deconv.weights import model_nsr
    from ..io.bank import load_bank

    root = Path(directory)
    files = checked_items(root, load_manifest(root))
    bank = load_bank(files[BANK])
    scene_dirs = sorted({Path(n).parent.name for n in files if is_scene_item(n)})
    profile = read_mismatch(files[MISMATCH]) if MISMATCH in files else None
    if calibration_scene is not None:
        if not 0 <= calibration_scene < len(scene_dirs) or len(scene_dirs) < 2:
            raise ValueError(f"calibration_scene must be one of the dataset's scenes "
                             f"(0..{len(scene_dirs) - 1}) and leave another to restore; "
                             f"got {calibration_scene!r}")
        profile = _profile(files, bank, scene_dirs.pop(calibration_scene))
    rows = []
    for scene in scene_dirs[:scenes]:
        gt, chans, _ = read_finite(files[f"{scene}/pinhole.exr"])
        mask = chans["mask.Y"] > 0.5
        level = white_level(gt, chans["mask.Y"])
        truth = gt / level
        sweeps = sorted((n for n in files if n.startswith(f"{scene}/")
                         and _SWEEP.fullmatch(Path(n).stem)),
                        key=lambda n: -_lux(n))
        for name in sweeps:
            img, _, meta = read_finite(files[name])
            noise = SensorNoise.from_dict(meta["noise"]) if "noise" in meta else None
            before = estimate_nsr(img)
            if noise is not None:
                before = max(before, noise.nsr(0.5))
            after = model_nsr(img, bank, noise, mask=mask, level=level)
            mirror = model_nsr(img, bank, noise, mask=mask, level=level, spectrum="mirror")
            candidates = {"before": before, "after": after, "mirror": mirror}
            if profile is not None:
                candidates["calibrated"] = model_nsr(img, bank, noise, mask=mask,
                                                     level=level, mismatch=profile)
            x = (img / level).astype(np.float32)

            def restore(im, w):
                return deconvolve(im, bank, method="wiener", weight=w, prior=DECONV_PRIOR)

            r = weight_rows(x, truth, restore, candidates, mask=mask)
            rows.append({"case": f"{root.name} {scene} {Path(name).stem}", **r})
    return rows


def _profile(files: dict, bank, scene: str):
    """The bank's mismatch profile calibrated on ``scene``'s noise-free sweep and truth
    (:func:`mitsweep.pipeline.tasks.calibration_profile`, the dataset's restoration)."""
    return calibration_profile(files[f"{scene}/pinhole.exr"], files[f"{scene}/sweep.exr"],
                               bank)
