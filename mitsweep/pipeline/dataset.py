"""A dataset directory: its manifest's schema, and :func:`build_dataset`."""

from __future__ import annotations

import concurrent.futures as cf
import json
import math
import os
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any

from ..config import Setup, setup_to_dict
from ..resources import FileTypeError, require_regular_file
from ..io.scene_files import SceneFileError, scene_digests
from .options import MAX_SCENES, DatasetOptions, _is_int, _is_real, _require, options_from_dict
from .runner import (DEFAULT_RETRIES, LOG_DIR, MANIFEST, SHARD_DIR, DatasetError, Shard,
                     run_tasks)
from .tasks import CALIBRATION_DIR, MISMATCH, item_names, plan

__all__ = ["build_dataset", "load_manifest", "read_manifest", "validate_manifest",
           "dataset_inputs", "scene_files_from", "FORMAT"]

FORMAT = "mitsweep-dataset/1"


def read_manifest(path: str | Path) -> dict:
    """Read and validate a manifest file (the directory's, or a shard's).

    Parameters
    ----------
    path : str or Path
        The ``manifest.json`` of a dataset directory, or of one of its shards
        (``shards/K-of-N/manifest.json``: validated against the dataset directory).

    Returns
    -------
    dict
        The manifest, validated (:func:`validate_manifest`).

    Raises
    ------
    DatasetError
        Not JSON, or an invalid manifest (naming the file and the field).
    OSError
        The file cannot be read.
    """
    p = Path(path)
    try:
        manifest = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{p}: corrupt manifest ({exc})") from None
    directory = p.parent if p.parent.parent.name != SHARD_DIR else p.parent.parent.parent
    try:
        validate_manifest(manifest, directory)
    except DatasetError as exc:
        raise DatasetError(f"{p}: invalid manifest: {exc}") from None
    return manifest


def load_manifest(directory: str | Path) -> dict:
    """Read and validate ``directory/manifest.json`` (see :func:`validate_manifest`).

    Parameters
    ----------
    directory : str or Path
        A dataset directory.

    Returns
    -------
    dict
        The manifest (:func:`read_manifest`).

    Raises
    ------
    DatasetError
        No manifest there (not a mitsweep dataset), or an invalid one.
    """
    p = Path(directory) / MANIFEST
    if not p.is_file():
        raise DatasetError(f"{directory}: no {MANIFEST} (not a mitsweep dataset)")
    return read_manifest(p)


def validate_manifest(manifest: Any, directory: str | Path) -> DatasetOptions:
    """Check a manifest's schema before anything trusts it; return its options.

    The top level is an object with ``format`` (``mitsweep-dataset/1``), ``setup`` (an
    object), ``options`` (validated as :class:`DatasetOptions`, the limits of the
    command line) and ``items``: an object whose keys are items of a dataset with those
    options (relative paths such as ``scene_000/sweep.exr``, never absolute, never with
    ``..``, never resolving outside ``directory`` through a symlink) and whose values
    hold ``params`` (object), ``sha256`` (64 hex digits), ``bytes`` (integer >= 0) and,
    in datasets written before the per-task logs, ``seconds`` (number >= 0).
    ``complete``, when present, is ``true`` and then every item of the dataset is
    listed.

    Parameters
    ----------
    manifest : object
        The manifest as parsed from JSON (any type: anything but an object is refused).
    directory : str or Path
        The dataset directory its items are relative to.

    Returns
    -------
    DatasetOptions
        The options it records.

    Raises
    ------
    DatasetError
        Naming the first field that breaks the schema.
    """
    _require(isinstance(manifest, dict), "top level",
             f"must be a JSON object, got {type(manifest).__name__}")
    _require(manifest.get("format") == FORMAT, "format",
             f"must be {FORMAT!r}, got {manifest.get('format')!r}")
    _require(isinstance(manifest.get("setup"), dict), "setup",
             f"must be an object, got {type(manifest.get('setup')).__name__}")
    opts = options_from_dict(manifest.get("options"))
    items = manifest.get("items")
    _require(isinstance(items, dict), "items", f"must be an object, got {type(items).__name__}")
    root = Path(directory).resolve()
    expected = set(item_names(opts))
    for name, item in items.items():
        key = f"items[{name!r}]"
        posix = PurePosixPath(name)
        _require(name != "" and not posix.is_absolute() and "\\" not in name
                 and not PureWindowsPath(name).drive, key, "must be a relative path")
        _require(".." not in posix.parts, key, "must stay inside the dataset directory")
        _require(name in expected, key, f"is not an item of a dataset with these options "
                                        f"({opts.scenes} scenes)")
        _require((root / name).resolve().is_relative_to(root), key,
                 "resolves outside the dataset directory (symlink)")
        _require(isinstance(item, dict), key, f"must be an object, got {type(item).__name__}")
        _require(isinstance(item.get("params"), dict), f"{key}.params", "must be an object")
        sha = item.get("sha256")
        _require(isinstance(sha, str) and len(sha) == 64
                 and all(c in "0123456789abcdef" for c in sha), f"{key}.sha256",
                 f"must be 64 lowercase hex digits, got {sha!r}")
        _require(_is_int(item.get("bytes")) and item["bytes"] >= 0, f"{key}.bytes",
                 f"must be an integer >= 0, got {item.get('bytes')!r}")
        if "seconds" in item:
            _require(_is_real(item["seconds"]) and math.isfinite(item["seconds"])
                     and item["seconds"] >= 0, f"{key}.seconds",
                     f"must be a finite number >= 0, got {item['seconds']!r}")
    if "complete" in manifest:
        _require(manifest["complete"] is True, "complete",
                 f"must be true when present, got {manifest['complete']!r}")
        if not any(isinstance(item, dict) and isinstance(item.get("params"), dict)
                   and item["params"].get("mismatch") == MISMATCH for item in items.values()):
            # made before the calibration scene (its restorations read no profile)
            expected = {n for n in expected if not n.startswith(f"{CALIBRATION_DIR}/")}
        missing = sorted(expected - set(items))
        if missing:
            more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
            raise DatasetError(f"items: a complete dataset lists every item; missing "
                               f"{missing[0]}{more}")
    return opts


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out: dict[str, str | None] = {}
    for pkg in ("mitsweep", "mitsuba", "drjit", "numpy", "scipy", "scikit-image", "OpenEXR"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


def dataset_inputs(directory: str | os.PathLike) -> list[Path]:
    """Every file of a dataset that evaluating it reads: the manifest and the items (for
    :func:`~mitsweep.cli.common.check_outputs`).

    Parameters
    ----------
    directory : str or path-like
        A dataset directory (its manifest is read and validated).

    Returns
    -------
    list of Path
        ``directory/manifest.json``, then each item's file in the manifest's order.
    """
    root = Path(directory)
    manifest = load_manifest(root)
    return [root / MANIFEST] + [root / name for name in manifest["items"]]


def scene_files_from(directory: str | os.PathLike, setup: Setup | None = None, *,
                     unit: str | None = None) -> tuple[dict, ...]:
    """The scenes of ``mitsweep dataset --scenes-from``: every ``*.xml`` file of
    ``directory`` (not its subfolders), sorted by name, as ``{"path", "sha256"}``, plus
    ``"files"``, the SHA-256 of every file the scene loads, when it loads others
    (:attr:`DatasetOptions.scene_files`). Every ``*.xml`` entry must be a regular file
    (a named pipe or a folder so named is refused, not read).

    With ``setup``, each file is loaded first as the render will load it and its view
    of the mirror probed (:func:`mitsweep.render.user_scene.check_user_scene`, in
    ``unit``): a file that is not Mitsuba XML, references a missing file, uses an
    unknown plugin, has no emitter, puts geometry between the lens and the mirror or
    nothing in the mirror's view is refused before any work starts, naming the file.

    Parameters
    ----------
    directory : str or path-like
        The folder of scenes (at most :data:`~mitsweep.pipeline.options.MAX_SCENES`
        ``*.xml`` files).
    setup : Setup, optional
        Probe each scene with this setup; None only checks and digests the files.
    unit : {"mm", "cm", "m"}, optional
        The scenes' length unit (default: the setup's ``scene.unit``, else mm).

    Returns
    -------
    tuple of dict
        One :attr:`DatasetOptions.scene_files` entry per scene, sorted by name.

    Raises
    ------
    DatasetError
        Not a folder, no scene in it, or too many.
    mitsweep.resources.FileTypeError
        A ``*.xml`` entry that is not a regular file.
    mitsweep.render.user_scene.UserSceneError
        A scene the probe or the digests refuse. All three are ValueErrors: one line at
        the command line.
    """
    root = Path(directory)
    if not root.is_dir():
        raise DatasetError(f"{directory}: not a directory (--scenes-from takes a folder of "
                           f"Mitsuba XML scenes)")
    # every *.xml is a scene: a named pipe, device or folder so named is refused, not
    # skipped (nor read: it would block)
    paths = sorted(require_regular_file(p, "--scenes-from scene") for p in root.glob("*.xml"))
    if not paths:
        raise DatasetError(f"{directory}: no *.xml scene files")
    _require(len(paths) <= MAX_SCENES, "scenes-from",
             f"{directory} holds {len(paths)} scenes; at most {MAX_SCENES}")
    if setup is not None:
        from ..render.user_scene import check_user_scene

        for p in paths:
            check_user_scene(setup, p, unit=unit)
    return tuple(_scene_file(p) for p in paths)


def _scene_file(path: Path) -> dict:
    """A :attr:`DatasetOptions.scene_files` entry: path, SHA-256 and, for a scene that
    loads other files, ``files``: the SHA-256 of each (:func:`scene_digests`)."""
    from ..render.user_scene import UserSceneError

    try:
        files = scene_digests(path)
    except (FileTypeError, SceneFileError) as exc:
        raise UserSceneError(str(exc)) from None
    top = path.resolve()
    entry: dict[str, Any] = {"path": str(top), "sha256": files[top.name]}
    if len(files) > 1:
        entry["files"] = files
    return entry


def written_paths(opts: DatasetOptions, shard: Shard | None = None) -> set[str]:
    """Paths (relative to the dataset directory) a run with ``opts`` may write.

    Parameters
    ----------
    opts : DatasetOptions
        The run's options (they name its items).
    shard : Shard, optional
        The shard the run makes; its manifest and lock are then written too.

    Returns
    -------
    set of str
        POSIX paths: the manifest, the lock file, every item and its task log, and the
        shard's manifest and lock.
    """
    from ..io.lock import LOCK_FILE

    names = item_names(opts)
    out = {MANIFEST, LOCK_FILE, *names, *(f"{LOG_DIR}/{n}.log" for n in names)}
    if shard is not None:
        out |= {f"{SHARD_DIR}/{shard.dirname}/{MANIFEST}",
                f"{SHARD_DIR}/{shard.dirname}/{LOCK_FILE}"}
    return out


def _without_scene_path(setup_dict: dict) -> dict:
    """A manifest's setup with its ``[scene] file`` path left out (set or not stays)."""
    scene = setup_dict.get("scene")
    if not isinstance(scene, dict) or scene.get("file") is None:
        return setup_dict
    return {**setup_dict, "scene": {**scene, "file": True}}


def build_dataset(setup: Setup, out_dir: str | Path, options: DatasetOptions | None = None, *,
                  executor: str | cf.Executor = "serial", jobs: int = 2,
                  scheduler: str | None = None, shard: Shard | str | None = None,
                  retries: int = DEFAULT_RETRIES, progress: bool = True,
                  wait: float | None = None) -> dict:
    """Render, trace, add noise and deconvolve a synthetic dataset (resumable).

    Parameters
    ----------
    setup : Setup
    out_dir : path
        Created if needed. A directory holding a manifest for another setup is refused
        (the setup's ``[scene] file`` compares by the content of every file it loads,
        not by its path: a changed one redoes the renders and what was made from them).
        Its folders must be its own: a symlinked one is refused, never written
        through.
    options : DatasetOptions
    executor : {"serial", "process", "dask"} or concurrent.futures.Executor
        Run the tasks in this process; in ``jobs`` local processes; on Dask (a
        ``LocalCluster`` of ``jobs`` single-threaded worker processes, or the cluster of
        ``scheduler``); or on any executor (``Client.get_executor()``, ...), which is
        left running. Workers set up the backend themselves
        (:func:`~mitsweep.pipeline.executors.init_worker`).
    jobs : int
        Processes or Dask workers of the embedded pool or cluster.
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running Dask scheduler (implies ``"dask"``).
    shard : Shard or "K/N", optional
        Make only shard K of N (a deterministic subset: the scenes ``i`` with
        ``i mod N = K - 1``, and the bank); the shard that completes the dataset
        merges the manifests (:mod:`mitsweep.pipeline.runner`).
    retries : int
        Submissions of a task again after its worker was lost.
    progress : bool
        A tqdm bar on stderr.
    wait : float or None
        The directory (or shard) is locked for the run
        (:class:`~mitsweep.io.lock.DirectoryLock`): another run on it is refused at
        once (``None``) or after waiting this many seconds for it (``math.inf``: for
        ever).

    Returns
    -------
    dict
        The manifest (also written to ``out_dir/manifest.json``): ``complete`` only once
        every item's file matches the SHA-256 recorded when it was written. The same
        setup and options give the same bytes in every item and in the manifest,
        whichever executor or shards made them.
    """
    from .executors import open_executor

    if wait is not None and not (wait >= 0):
        raise DatasetError(f"wait: must be >= 0 seconds, got {wait!r}")
    if isinstance(shard, str):
        shard = Shard.parse(shard)
    opts = options or DatasetOptions()
    sd = setup_to_dict(setup)
    header = {"format": FORMAT, "setup": sd, "options": opts.as_dict(),
              "versions": _versions()}

    def same_setup(manifest: dict, path: Path) -> None:
        # the setup's own scene file by content, not by the spelling of its path: its
        # digests are in the render items' parameters (tasks.setup_scene_digests)
        if _without_scene_path(manifest["setup"]) != _without_scene_path(sd):
            raise DatasetError(f"{Path(out_dir)}: holds a dataset of another setup "
                               f"({manifest['setup'].get('name')!r}); use a new directory")

    with open_executor(executor, jobs=jobs, scheduler=scheduler) as (pool, lost):
        return run_tasks(out_dir, plan(opts, setup), setup, header, read_manifest=read_manifest,
                         check_header=same_setup, executor=pool, lost=lost, shard=shard,
                         wait=wait, progress=progress, retries=retries, desc="dataset")
