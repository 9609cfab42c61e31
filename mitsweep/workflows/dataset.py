"""Render a synthetic focal-sweep dataset, and score one (``mitsweep dataset``,
``mitsweep evaluate``).

These are the commands' workflows: options by name, checked with messages that name the
command's options, outputs checked before any work. The engine underneath is
:func:`mitsweep.pipeline.build_dataset` (which takes a
:class:`~mitsweep.pipeline.DatasetOptions`) and :func:`mitsweep.pipeline.evaluate_dataset`.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from collections.abc import Mapping, Sequence

from .. import __version__
from ..config import Setup, setup_to_dict
from ..pipeline import DatasetError, DatasetOptions, Shard, dataset_inputs, item_names
from ..pipeline import build_dataset as _build
from ..pipeline import evaluate_dataset as _evaluate
from ..pipeline.options import FILE_KEYS
from ._base import (InputError, WorkflowResult, json_text, read_motion_file, resolve_setup)
from ._paths import check_outputs

__all__ = ["build_dataset", "evaluate_dataset", "scene_options", "check_dataset_outputs"]

#: DatasetOptions fields → the options that set them, for messages.
_OPTION_OF = {"scenes": "--scenes", "seed": "--seed", "spp": "--spp",
              "light_levels_lux": "--lux", "methods": "--methods", "bank_rays": "--bank-rays",
              "family": "--family", "family_params": "--family-param",
              "scene_files": "--scenes-from", "scene_unit": "--scene-unit",
              "motion": "--motion"}


def scene_options(setup: Setup, *, scenes: int | None = None, family: str | None = None,
                  family_params: Mapping[str, object] | Sequence = (),
                  scenes_from: str | os.PathLike | None = None,
                  scene_unit: str | None = None) -> dict:
    """The :class:`~mitsweep.pipeline.DatasetOptions` fields of the scene options: the
    built-in room or the procedural family (``scenes`` of them), or every ``*.xml``
    Mitsuba scene of the folder ``scenes_from``.

    Parameters
    ----------
    setup : Setup
        The dataset's setup (each XML scene is probed with it).
    scenes : int, optional
        Scene variations of the room or the procedural family (default 1).
    family : {"room", "procedural"}, optional
        The family (default the room).
    family_params : mapping or sequence of (name, value) pairs
        The procedural family's parameters.
    scenes_from : path-like, optional
        A folder of Mitsuba XML scenes, one scene per ``*.xml`` file
        (:func:`mitsweep.pipeline.scene_files_from`).
    scene_unit : {"mm", "cm", "m"}, optional
        Those scenes' length unit (default: the setup's).

    Returns
    -------
    dict
        ``scenes``, ``family`` and either ``family_params`` or ``scene_files`` and
        ``scene_unit``: keyword arguments of :class:`~mitsweep.pipeline.DatasetOptions`.

    Raises
    ------
    InputError
        Options that do not go together (``scene_unit`` without ``scenes_from``, family
        parameters of the room, a family or a count with ``scenes_from``).
    """
    from ..pipeline.dataset import scene_files_from

    if scenes_from is None:
        if scene_unit is not None:
            raise InputError("--scene-unit: applies to --scenes-from scenes only")
        family = family or "room"
        if family_params and family != "procedural":
            raise InputError(f"--family-param: applies to --family procedural only, got "
                             f"--family {family}")
        return {"scenes": scenes or 1, "family": family, "family_params": dict(family_params)}
    for given, option in ((family, "--family"), (scenes, "--scenes"),
                          (family_params, "--family-param")):
        if given:
            raise InputError(f"{option}: not with --scenes-from (each *.xml file of "
                             f"{scenes_from} is one scene)")
    files = scene_files_from(scenes_from, setup, unit=scene_unit)
    return {"scenes": len(files), "family": "xml", "scene_files": files,
            "scene_unit": scene_unit}


def check_dataset_outputs(inputs: list, out: Path, opts: DatasetOptions,
                          shard: Shard | str | None = None) -> None:
    """:func:`check_outputs` for a dataset directory: no input is the directory, nor one
    of the files a run with ``opts`` writes in it (manifest, lock, items, logs).

    Parameters
    ----------
    inputs : list of path-like or None
        Every file the run reads (None entries are skipped).
    out : Path
        The dataset directory.
    opts : DatasetOptions
        The run's options (they name the files it writes).
    shard : Shard or "K/N", optional
        The shard the run makes (its manifest and lock are written too).

    Raises
    ------
    InputError
        An input that is the directory or one of the files the run writes.
    """
    from ..pipeline.dataset import written_paths

    check_outputs(inputs, {"--out": out})
    written = None
    root = out.resolve()
    for inp in inputs:
        if inp is None:
            continue
        try:
            rel = Path(inp).resolve().relative_to(root).as_posix()
        except ValueError:
            continue  # not inside the directory
        written = written or written_paths(
            opts, Shard.parse(shard) if isinstance(shard, str) else shard)
        if rel in written:
            check_outputs([inp], [out / rel])


def build_dataset(setup: Setup | str | os.PathLike, out: str | os.PathLike, *,
                  scenes: int | None = None, family: str | None = None,
                  family_params: Mapping[str, object] | Sequence = (),
                  scenes_from: str | os.PathLike | None = None, scene_unit: str | None = None,
                  seed: int = 0,
                  spp: Sequence[int] = (16, 64, 128, 64),
                  lux: Sequence[float] = (50.0, 2.0, 0.5),
                  methods: Sequence[str] = ("wiener",), bank_rays: int | None = None,
                  motion: str | os.PathLike | None = None, executor: str | None = None, jobs: int = 2,
                  scheduler: str | None = None, shard: Shard | str | None = None,
                  retries: int = 2,
                  wait: float | None = None) -> WorkflowResult:
    """Render, trace, add noise and deconvolve a synthetic dataset, resumably
    (``mitsweep dataset``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    out : path-like
        The dataset directory.
    scenes, family, family_params, scenes_from, scene_unit
        The scenes (:func:`scene_options`): ``scenes`` variations of the built-in room
        (default) or of the procedural family (with its parameters), or every ``*.xml``
        scene of ``scenes_from`` in ``scene_unit`` (mm, cm or m).
    seed : int
        Base seed.
    spp : (int, int, int, int)
        Samples per pixel of the pinhole, focused, sweep and stopped renders.
    lux : sequence of float
        Light levels of the noisy images, lux.
    methods : sequence of str
        Restoration methods of the EDOF images.
    bank_rays : int, optional
        Rays traced per IPSF of the bank (default: the tracer's).
    motion : path-like, optional
        A motion-profile file to render and trace instead of the setup's sweep.
    executor, jobs, scheduler, shard, retries, wait
        Where and how the tasks run (:func:`mitsweep.pipeline.build_dataset`).

    Returns
    -------
    WorkflowResult
        ``value`` and ``summary``: the manifest (a dict; ``manifest.json`` holds it).
        ``provenance``: ``setup``, ``out``, ``options`` (the DatasetOptions as a dict),
        ``items_expected`` (of the whole dataset, all shards), ``executor``, ``shard``,
        ``seconds``, ``version``.

    Raises
    ------
    InputError
        An option out of range (named as the command's option), options that do not go
        together, an output that would overwrite an input.
    mitsweep.pipeline.DatasetError
        The directory holds another dataset, or is locked by another run.

    Examples
    --------
    >>> from mitsweep.workflows import build_dataset
    >>> manifest = build_dataset("sphere", "data", spp=(4, 4, 4, 4)).value  # doctest: +SKIP
    >>> manifest["complete"]                                              # doctest: +SKIP
    True
    """
    from dataclasses import asdict


    if os.fspath(out).strip() == "":
        raise InputError("--out: must name a directory")
    setup_path = None if isinstance(setup, Setup) else setup
    setup = resolve_setup(setup)
    fields = scene_options(setup, scenes=scenes, family=family, family_params=family_params,
                           scenes_from=scenes_from, scene_unit=scene_unit)
    if motion is not None:
        profile = read_motion_file(motion, setup).profile
        fields["motion"] = {"times": profile.times.tolist(),
                            "positions_mm": profile.positions.tolist()}
    try:
        opts = DatasetOptions(seed=seed,
                              spp=dict(zip(("pinhole", "focused", "sweep", "stopped"), spp)),
                              light_levels_lux=tuple(lux), methods=tuple(methods),
                              bank_rays=bank_rays, **fields)
    except DatasetError as exc:  # name the option, not the field
        field, _, rest = str(exc).partition(":")
        head = field.split("[")[0].split(".")[0]
        detail = field.partition(".")[2]
        rest = f" {detail}:{rest}" if detail else rest
        raise InputError(f"{_OPTION_OF.get(head, field)}:{rest}") from None
    out = Path(out)
    if scheduler and executor not in (None, "dask"):
        raise InputError(f"--scheduler: needs --executor dask (or no --executor), got "
                         f"--executor {executor}")
    check_dataset_outputs([setup_path, motion, *(f["path"] for f in opts.scene_files)],
                          out, opts, shard)
    t0 = time.perf_counter()
    manifest = _build(setup, out, opts, executor=executor or "serial", jobs=jobs,
                      scheduler=scheduler, shard=shard, retries=retries, wait=wait)
    provenance = {"workflow": "build_dataset", "version": __version__,
                  "setup": setup_to_dict(setup), "out": str(out),
                  "options": {FILE_KEYS.get(k, k): v for k, v in asdict(opts).items()},
                  "executor": executor or "serial",
                  "shard": None if shard is None else str(shard),
                  "items_expected": len(item_names(opts)),
                  "seconds": time.perf_counter() - t0}
    return WorkflowResult(manifest, provenance, manifest)


def evaluate_dataset(dataset: str | os.PathLike, *, plot: str | os.PathLike | None = None,
                     out: str | os.PathLike | None = None) -> WorkflowResult:
    """PSNR and SSIM of a dataset's EDOF (every restoration method it holds), focused and
    stopped images on ground truth, inside the mirror's image, per radius and depth band
    (``mitsweep evaluate``).

    Parameters
    ----------
    dataset : path-like
        A dataset directory (:func:`build_dataset`).
    plot : path-like, optional
        A PNG of the per-radius PSNR curves.
    out : path-like, optional
        A JSON file of the scores (the text ``mitsweep evaluate --json`` prints).

    Returns
    -------
    WorkflowResult
        ``value`` and ``summary``: the scores of :func:`mitsweep.pipeline.evaluate_dataset`
        (``mean``: image name → ``{"psnr", "ssim"}``, per item, per radius...).
        ``provenance``: ``dataset``, ``plot``, ``out``, ``seconds``, ``version``.

    Raises
    ------
    InputError
        An output that would overwrite one of the dataset's files.
    mitsweep.pipeline.DatasetError
        Not a complete dataset.

    Examples
    --------
    >>> from mitsweep.workflows import evaluate_dataset
    >>> evaluate_dataset("data").value["mean"]["edof"]["psnr"]  # doctest: +SKIP
    27.3
    """
    from ..io import write_text_atomic
    from ..io.atomic import check_writable

    # Before the (long) evaluation: the outputs overwrite none of the dataset's files,
    # and can be written.
    check_outputs(dataset_inputs(dataset), {"--plot": plot, "--out": out})
    for path in (plot, out):
        if path:
            check_writable(os.fspath(path))
    if plot:
        from ..plots import check_figure_path

        check_figure_path(os.fspath(plot), "--plot")
    t0 = time.perf_counter()
    results = _evaluate(dataset)
    if plot:
        from ..plots import plot_per_radius

        plot_per_radius(results, os.fspath(plot))
    if out:
        write_text_atomic(os.fspath(out), json_text(results))      # the same text as --json
    provenance = {"workflow": "evaluate_dataset", "version": __version__,
                  "dataset": os.fspath(dataset), "plot": plot and os.fspath(plot),
                  "out": out and os.fspath(out), "seconds": time.perf_counter() - t0}
    return WorkflowResult(results, provenance, results)
