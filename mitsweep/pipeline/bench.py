"""``mitsweep bench dataset``: dataset throughput by executor, in one run.

One tiny dataset (48 px frame, a few samples per pixel, a small bank: every task for
real, seconds each) is made serially, on a Dask LocalCluster of 1 and of 2 workers and
on a pool of 2 processes, each into a fresh directory. Per executor: the start-up time
of its workers, the run time, items per second, the speed-up over serial and the
per-task overhead, ``(run time × workers − Σ task seconds) / items``, the worker time
each task costs beyond its own work (scheduling, transfers, checksums, the manifest);
and whether its files are byte-identical to the serial run's. (A process pool starts
its processes at its first task, so their start-up is in its run time; a Dask cluster
is up, its workers initialised, before the run starts.) The serial run's task
logs give the per-item costs, from which ``projection`` gives scenes and items per
hour on N machines of W workers: ``N W 3600 / (scene seconds + items per scene ×
overhead)``, with the bank (traced once per dataset) left out.

The baselines run in the same process, one after the other, so ratios survive a busy
machine; the load average is reported with them.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

__all__ = ["run_bench", "add_arguments"]

#: (name, executor, workers) in the order they run.
CONFIGS = (("serial", "serial", 1), ("dask_1", "dask", 1), ("dask_2", "dask", 2),
           ("process_2", "process", 2))
#: Machines × workers of the projection.
PROJECTION_MACHINES = (1, 8, 64)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the benchmark's own options to the ``mitsweep bench`` parser.

    Parameters
    ----------
    p : argparse.ArgumentParser
        The parser of ``mitsweep bench``; gains ``--scenes``.
    """
    p.add_argument("--scenes", type=int, default=None,
                   help="scenes of the benchmark dataset (default 4; 2 with --quick)")


def _setup_and_options(scenes: int):
    from ..config import DEFAULT_SETUP, Sensor
    from .options import DatasetOptions

    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(48, 48), pixel_pitch=0.18))
    opts = DatasetOptions(scenes=scenes, spp={"pinhole": 2, "focused": 2, "sweep": 4,
                                              "stopped": 2},
                          bank_rays=1 << 12, light_levels_lux=(50.0,))
    return setup, opts


def _kind(name: str) -> str:
    """The cost class of an item: bank, render_MODE, noise or deconvolve."""
    stem = Path(name).stem
    if name == "bank.npz":
        return "bank"
    if stem.startswith("edof"):
        return "deconvolve"
    if stem.endswith("lux"):
        return "noise"
    return f"render_{stem}"


def _files(root: Path) -> dict:
    from .runner import LOG_DIR, sha256

    return {p.relative_to(root).as_posix(): sha256(p) for p in sorted(root.rglob("*"))
            if p.is_file() and LOG_DIR not in p.relative_to(root).parts}


def _task_log(root: Path, name: str) -> dict:
    """The task log of an item the run has just made (every item of a finished run has
    one)."""
    from .runner import read_task_log

    record = read_task_log(root, name)
    if record is None:
        raise RuntimeError(f"{root}: no task log for {name} after the run")
    return record


def run_bench(args: argparse.Namespace) -> dict:
    """Build the benchmark dataset with each executor of :data:`CONFIGS` and compare them.

    Parameters
    ----------
    args : argparse.Namespace
        The ``mitsweep bench`` options: ``scenes`` (the dataset's scenes; None: 4, or 2
        with ``quick``) and ``quick`` (a smaller run for a smoke test). Either may be
        absent (the defaults then).

    Returns
    -------
    dict
        ``dataset`` (scenes, items, resolution in px, spp, bank rays),
        ``load_average_1min``, ``executors`` (per configuration: ``workers``,
        ``startup_s``, ``run_s``, ``items_per_s``, ``task_s_total``,
        ``overhead_per_task_s``, ``speedup_vs_serial``, ``identical_to_serial``),
        ``per_item_s`` (mean seconds per item kind, serial run) and ``projection``
        (scenes and items per hour on N machines of W workers, with its formula).
    """
    from . import build_dataset, item_names
    from .executors import open_executor

    scenes = getattr(args, "scenes", None) or (2 if getattr(args, "quick", False) else 4)
    setup, opts = _setup_and_options(scenes)
    names = item_names(opts)
    result: dict = {"dataset": {"scenes": scenes, "items": len(names),
                                "resolution": list(setup.sensor.resolution),
                                "spp": dict(opts.spp), "bank_rays": opts.bank_rays},
                    "load_average_1min": os.getloadavg()[0], "executors": {}}
    with tempfile.TemporaryDirectory(prefix="mitsweep-bench-") as tmp:
        reference = None
        for name, kind, workers in CONFIGS:
            root = Path(tmp) / name
            t0 = time.perf_counter()
            with open_executor(kind, jobs=workers) as (pool, _):
                t1 = time.perf_counter()
                build_dataset(setup, root, opts, executor=pool or "serial", progress=False)
                t2 = time.perf_counter()
            logs = {n: _task_log(root, n) for n in names}
            task_s = sum(r["seconds"] for r in logs.values())
            run_s = t2 - t1
            files = _files(root)
            reference = reference or files
            entry = {"workers": workers, "startup_s": t1 - t0, "run_s": run_s,
                     "items_per_s": len(names) / run_s, "task_s_total": task_s,
                     "overhead_per_task_s": (run_s * workers - task_s) / len(names),
                     "identical_to_serial": files == reference}
            if name == "serial":
                costs: dict[str, list] = {}
                for n, r in logs.items():
                    costs.setdefault(_kind(n), []).append(r["seconds"])
                result["per_item_s"] = {k: sum(v) / len(v) for k, v in sorted(costs.items())}
                scene_s = (task_s - logs["bank.npz"]["seconds"]) / scenes
            result["executors"][name] = entry
    serial_run = result["executors"]["serial"]["run_s"]
    for entry in result["executors"].values():
        entry["speedup_vs_serial"] = serial_run / entry["run_s"]
    per_scene = (len(names) - 1) / scenes
    overhead = max(0.0, result["executors"]["dask_2"]["overhead_per_task_s"])
    cost = scene_s + per_scene * overhead
    result["projection"] = {
        "scene_s": scene_s, "items_per_scene": per_scene, "overhead_per_task_s": overhead,
        "formula": "scenes/hour = machines * workers * 3600 / (scene_s + items_per_scene "
                   "* overhead_per_task_s)",
        **{f"machines_{m}_workers_{w}": {"scenes_per_hour": m * w * 3600 / cost,
                                          "items_per_hour": m * w * 3600 / cost * per_scene}
           for m in PROJECTION_MACHINES for w in (2, 16)}}
    return result
