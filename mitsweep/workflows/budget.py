"""Where each EDOF image's error comes from (``mitsweep budget``): information limit,
forward-model mismatch, Monte Carlo and sensor noise, the weight choice, per radius and
depth band (:func:`mitsweep.pipeline.budget.dataset_budget`)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from .. import __version__
from ._base import InputError, WorkflowResult, json_text
from ._paths import check_outputs

if TYPE_CHECKING:
    from ..io.bank import IPSFBank

__all__ = ["error_budget"]


def _rim_bank(dataset: str | os.PathLike) -> tuple[IPSFBank, str]:
    """The dataset's bank extended to the mirror's rim
    (:func:`mitsweep.tracer.bank.extend_to_rim`), and what was done to it: a radial bank
    traced out to the rim's image, a grid bank with its off-mirror nodes given the
    nearest traced kernel."""
    from ..config import setup_from_dict
    from ..io.bank import load_bank
    from ..pipeline import load_manifest
    from ..pipeline.tasks import BANK
    from ..tracer.bank import extend_to_rim

    bank = load_bank(Path(dataset) / BANK)
    setup = setup_from_dict(load_manifest(Path(dataset))["setup"])
    rim = extend_to_rim(setup, bank)
    meta = rim.metadata or {}
    if rim.kind == "radial":
        how = (f"radial bank traced to the mirror's rim ({meta.get('rim_points', 0)} "
               f"points beyond the FOV's {len(bank.points_uv)})")
    else:
        how = (f"grid bank, {len(meta.get('filled_nodes', []))} off-mirror nodes filled "
               f"with the nearest traced kernel")
    return rim, how


def error_budget(dataset: str | os.PathLike, *, items: Sequence[str] | None = None,
                 second_seed: int | None = None,
                 out: str | os.PathLike | None = None,
                 rim_bank: bool = False) -> WorkflowResult:
    """The error budget of a dataset's EDOF images (``mitsweep budget``).

    Parameters
    ----------
    dataset : path-like
        A dataset directory (:func:`mitsweep.workflows.build_dataset`).
    items : sequence of str, optional
        EDOF items (``scene_000/edof_2lux.exr``, or a stem such as ``edof_2lux`` for every
        scene); default: every Wiener EDOF image.
    second_seed : int, optional
        Render each scene's sweep again with this Monte Carlo seed (into ``out``) to
        measure the Monte Carlo term; needs ``out``.
    out : path-like, optional
        Write ``budget.json``, ``budget.txt`` and one ``budget_*.png`` per item here.
    rim_bank : bool
        Budget the restoration with the dataset's bank extended to the mirror's rim
        instead of its own (``mitsweep budget --rim-bank``,
        :func:`mitsweep.tracer.bank.extend_to_rim`): a radial bank traced out to the
        image of the rim (the same trace settings, the next seeds), a grid bank with its
        off-mirror nodes given the nearest traced kernel. Each
        EDOF image is restored again from its input with that bank and the dataset's
        weight rule (:func:`mitsweep.pipeline.budget.dataset_budget`'s ``bank``); the
        ``beyond_fov`` region stays the design FOV's. Default False: the dataset's bank.

    Returns
    -------
    WorkflowResult
        ``value``: :func:`mitsweep.pipeline.budget.dataset_budget`'s result (``budgets``:
        item → budget). ``summary``: its JSON form (what ``mitsweep budget --json``
        prints; with ``rim_bank``, ``bank`` says how the bank was extended).
        ``provenance``: ``dataset``, ``items``, ``second_seed``, ``out``, ``rim_bank``,
        ``bank`` (None, or how the bank was extended), ``text`` (the tables ``budget.txt``
        holds), ``version``.

    Raises
    ------
    InputError
        ``second_seed`` without ``out``, an ``out`` that is a file, outputs that would
        overwrite the dataset's files.

    Examples
    --------
    >>> from mitsweep.workflows import error_budget
    >>> print(error_budget("data").provenance["text"])  # doctest: +SKIP
    """
    from ..io import write_text_atomic
    from ..pipeline import dataset_inputs
    from ..pipeline.budget import budget_json, dataset_budget

    if second_seed is not None and not out:
        raise InputError("--second-seed needs --out DIR (the second renders are kept there)")
    out = Path(out) if out else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise InputError(f"--out {out}: not a directory")
        check_outputs(dataset_inputs(dataset), [out / "budget.json", out / "budget.txt"])
    bank, how = _rim_bank(dataset) if rim_bank else (None, None)
    result = dataset_budget(Path(dataset), items=None if items is None else list(items),
                            second_seed=second_seed,
                            work_dir=out / "renders" if out is not None else None,
                            bank=bank)
    text = "" if how is None else f"bank: {how}\n"
    text += "".join(f"{name} (restored from {b.info['restored_from']})\n{b.table()}\n"
                   for name, b in result["budgets"].items())
    data = budget_json(result)
    if how is not None:
        data["bank"] = how
    if out is not None:
        from ..plots import plot_error_budget

        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / "budget.json", json_text(data))   # the same text as --json
        write_text_atomic(out / "budget.txt", text)
        for name, b in data["budgets"].items():
            stem = name.removesuffix(".exr").replace("/", "_")
            plot_error_budget(b, out / f"budget_{stem}.png", title=name)
    provenance = {"workflow": "error_budget", "version": __version__,
                  "dataset": os.fspath(dataset), "items": None if items is None else list(items),
                  "second_seed": second_seed, "out": None if out is None else str(out),
                  "rim_bank": bool(rim_bank), "bank": how, "text": text}
    return WorkflowResult(result, provenance, data)
