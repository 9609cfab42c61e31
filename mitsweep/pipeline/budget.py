"""Error budgets of a dataset's EDOF images (:func:`dataset_budget`).

Each EDOF item is decomposed by :func:`mitsweep.deconv.budget.error_budget` with what
the dataset holds: the pinhole ground truth (with its depth and mask AOVs), the
noise-free sweep render, the noisy sweep the item was restored from (its metadata says
which), the item itself (the chosen weight's restoration, the weight from its metadata)
and the bank. A dataset renders each scene with one Monte Carlo seed; with
``second_seed`` the sweep is rendered again with that seed (the same task and
parameters otherwise, into ``work_dir``), which adds the ``monte_carlo`` term.
"""

from __future__ import annotations

import logging
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .dataset import load_manifest
from .evaluation import DEPTH_BANDS_MM, checked_items, read_finite
from .runner import DatasetError
from ..io.bank import IPSFBank
from .tasks import BANK, CALIBRATION_DIR, DECONV_PRIOR, calibration_profile, white_level

__all__ = ["dataset_budget", "budget_items", "budget_json"]

logger = logging.getLogger(__name__)

#: An EDOF item's stem: ``edof``, ``edof_50lux``, ``edof_tv``, ``edof_tv_2lux``.
_EDOF = re.compile(r"edof(?:_(?P<method>[a-z]+))?(?:_(?P<lux>[0-9.e+-]+)lux)?")
#: Methods whose restorations have a scalar weight the budget can search.
_WEIGHTED = ("wiener", "tv", "hyperlaplacian")


def _edof_method(name: str) -> str:
    """The restoration method an EDOF item's name says (``edof_tv_2lux.exr``: ``tv``;
    ``wiener`` when it names none)."""
    match = _EDOF.fullmatch(Path(name).stem)
    if match is None:
        raise DatasetError(f"{name}: not an EDOF item")
    return match["method"] or "wiener"


def budget_items(manifest: dict, items: list[str] | None = None) -> list[str]:
    """The EDOF items (``scene_000/edof_2lux.exr``) a budget covers.

    Parameters
    ----------
    manifest : dict
        The dataset's manifest (:func:`~mitsweep.pipeline.load_manifest`).
    items : list of str, optional
        Items as named, with or without ``.exr``; a bare stem such as ``edof_2lux``
        names it in every scene. Default: every Wiener EDOF item.

    Returns
    -------
    list of str
        The items' names in the manifest, each once.

    Raises
    ------
    DatasetError
        An unknown name, or (by default) a dataset with no Wiener EDOF item.
    """
    edofs = sorted(n for n in manifest["items"]
                   if n.endswith(".exr") and _EDOF.fullmatch(Path(n).stem))
    if items is None:
        chosen = [n for n in edofs if _edof_method(n) in ("wiener",)]
        if not chosen:
            raise DatasetError("the dataset holds no Wiener EDOF image to budget")
        return chosen
    out: list[str] = []
    for name in items:
        n = name if name.endswith(".exr") else f"{name}.exr"
        hits = [e for e in edofs if e == n or Path(e).name == n]
        if not hits:
            raise DatasetError(f"{name}: no such EDOF item in the dataset (items: "
                               f"{', '.join(sorted({Path(e).stem for e in edofs}))})")
        out += [h for h in hits if h not in out]
    return out


def _second_render(root: Path, manifest: dict, scene: str, seed: int, work_dir: Path) -> Path:
    """The scene's noise-free sweep rendered again with Monte Carlo seed ``seed``."""
    from ..config import setup_from_dict
    from .tasks import render

    params = dict(manifest["items"][f"{scene}/sweep.exr"]["params"])
    if int(seed) == int(params["seed"]):
        raise DatasetError(f"second seed {seed} is the seed the dataset rendered "
                           f"{scene} with: give another")
    params["seed"] = int(seed)
    out = Path(work_dir) / scene / f"sweep_seed{int(seed)}.exr"
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        render(setup_from_dict(manifest["setup"]), out, **params)
    return out


def dataset_budget(directory: str | Path, *, items: list[str] | None = None,
                   second_seed: int | None = None, work_dir: str | Path | None = None,
                   n_radial_bins: int = 8, edge_width_px: int = 2,
                   bank: IPSFBank | None = None) -> dict:
    """Error budgets of a dataset's EDOF images (see :mod:`mitsweep.deconv.budget`).

    Parameters
    ----------
    directory : path
        A complete dataset (``mitsweep dataset``); its items are checked as for
        :func:`~mitsweep.pipeline.evaluate_dataset`.
    items : list of str, optional
        EDOF items (:func:`budget_items`); default every Wiener EDOF image.
    second_seed : int, optional
        Render each budgeted scene's sweep again with this seed (Mitsuba; the bank's
        setup and the render's parameters from the manifest) for the ``monte_carlo``
        term; ``work_dir`` keeps those renders (required then; a rerun reuses them).
    n_radial_bins, edge_width_px
        As in :func:`~mitsweep.deconv.budget.error_budget` (the evaluation's bins).
    bank : IPSFBank, optional
        Restore every step with this bank instead of the dataset's (one traced to the
        mirror's rim, :func:`mitsweep.pipeline.rim.rim_bank`, or with its off-mirror
        grid nodes filled, :func:`mitsweep.deconv.kernels.fill_invalid_nodes`): the
        EDOF image is then restored again from its input with it, with the dataset's
        weight rule (Wiener: :func:`mitsweep.deconv.weights.model_nsr`; the calibrated
        rule's profile calibrated again for this bank on the calibration scene), so the
        budget says what that bank would have given.

    Returns
    -------
    dict
        ``{"dataset", "second_seed", "budgets": {item: ErrorBudget}}``, each budget's
        ``info`` naming its ``item``, ``scene``, ``restored_from`` (the image restored)
        and ``white_level``. :func:`budget_json` makes it plain JSON.
    """
    from ..deconv import SensorNoise
    from ..deconv.budget import error_budget
    from ..io.bank import load_bank

    root = Path(directory)
    manifest = load_manifest(root)
    files = checked_items(root, manifest)
    names = budget_items(manifest, items)
    if second_seed is not None and work_dir is None:
        raise DatasetError("a second seed needs a directory for its renders (work_dir)")
    other_bank = bank is not None
    bank = load_bank(files[BANK]) if bank is None else bank
    out: dict[str, Any] = {"dataset": str(root), "second_seed": second_seed, "budgets": {}}
    profile = None   # the calibrated weight's profile for another bank, made when needed
    for name in names:
        scene = Path(name).parent.name
        method = _edof_method(name)
        if method not in _WEIGHTED:
            raise DatasetError(f"{name}: method {method!r} has no scalar weight to budget "
                               f"(allowed: {', '.join(_WEIGHTED)})")
        gt, chans, _ = read_finite(files[f"{scene}/pinhole.exr"])
        mask = chans.get("mask.Y")
        if mask is None:
            raise DatasetError(f"{files[f'{scene}/pinhole.exr']}: no mask.Y channel "
                               f"(mirror mask AOV)")
        level = white_level(gt, mask)
        item, _, meta = read_finite(files[name])
        source = meta.get("deconvolved_from")
        if f"{scene}/{source}" not in files:
            raise DatasetError(f"{files[name]}: its metadata names no input of the dataset "
                               f"(deconvolved_from={source!r})")
        observed, _, src_meta = read_finite(files[f"{scene}/{source}"])
        clean = read_finite(files[f"{scene}/sweep.exr"])[0]
        second = None
        if second_seed is not None and work_dir is not None:  # work_dir: checked above
            second = read_finite(_second_render(root, manifest, scene, second_seed,
                                                 Path(work_dir)))[0] / level
        noise = src_meta.get("noise")
        # as the dataset restored it (pipeline.tasks.restore): Wiener with its prior and
        # the NSR its metadata records; the priors with the image's noise model
        kw: dict[str, Any] = {"prior": DECONV_PRIOR} if method == "wiener" \
            else {"noise": SensorNoise.from_dict(noise) if noise else None}
        depth = chans.get("depth.Z")
        if depth is not None:
            depth = np.where(depth > 0, depth, np.nan)
        logger.info("budget of %s", name)
        restored: np.ndarray | None = item / level
        weight = meta.get("nsr") if method == "wiener" else None
        if other_bank:
            from ..deconv.weights import model_nsr

            # as tasks.restore would have made it with this bank (its weight rule; a
            # calibrated one calibrated again, on the calibration scene, for this bank)
            rule: dict[str, Any] = {
                "spectrum": "mirror" if meta.get("nsr_rule") == "mirror" else "frame"}
            if meta.get("nsr_rule") == "calibrated" and method == "wiener":
                if profile is None:
                    profile = calibration_profile(files[f"{CALIBRATION_DIR}/pinhole.exr"],
                                                  files[f"{CALIBRATION_DIR}/sweep.exr"], bank)
                rule["mismatch"] = profile
            weight = model_nsr(observed, bank, SensorNoise.from_dict(noise) if noise else None,
                               mask=mask > 0.5, level=level,
                               **rule) if method == "wiener" else None
            restored = None
        b = error_budget(gt / level, observed / level, bank, clean_observed=clean / level,
                         second_seed=second, restored=restored, depth=depth,
                         mask=mask > 0.5, method=method,
                         weight=weight,
                         depth_bands=DEPTH_BANDS_MM, n_radial_bins=n_radial_bins,
                         edge_width_px=edge_width_px, **kw)
        out["budgets"][name] = replace(b, info={**b.info, "item": name, "scene": scene,
                                                "restored_from": source,
                                                "white_level": level})
    return out


def budget_json(result: dict) -> dict:
    """:func:`dataset_budget`'s result as plain JSON values.

    Parameters
    ----------
    result : dict
        What :func:`dataset_budget` returned.

    Returns
    -------
    dict
        The same keys, each budget replaced by its
        :meth:`~mitsweep.deconv.budget.ErrorBudget.as_dict`.
    """
    return {**{k: v for k, v in result.items() if k != "budgets"},
            "budgets": {n: b.as_dict() for n, b in result["budgets"].items()}}
