"""``mitsweep bench TARGET|all``: reproducible benchmarks printed side by side.

Each target is a module ``mitsweep.<pkg>.bench`` exposing ``run_bench(args) -> dict``;
the dict is printed as a table, or as JSON with ``--json``. Baselines run in the same
process as what they are compared with, so that ratios survive a noisy machine.

``bench all`` runs every target in turn in this process and prints one object: the
machine (:func:`mitsweep.backend.describe_machine`: CPU, cores, memory, load, GPUs,
LLVM, Dr.Jit, Mitsuba and NumPy versions, backend and variant), then for each target
its wall time, its peak resident memory and its own result; a target whose module is
not installed is reported as skipped with the reason, one that fails with its error
(exit status 1).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import resource
import sys
import time

from .common import UsageError, print_json

NAME = "bench"
HELP = "benchmarks (run time against error, against baselines in the same run)"

logger = logging.getLogger(__name__)

TARGETS = {
    "tracer": "mitsweep.tracer.bench",
    "render": "mitsweep.render.bench",
    "deconv": "mitsweep.deconv.bench",
    "dataset": "mitsweep.pipeline.bench",
    "calibrate": "mitsweep.photo.bench",
}
ALL = "all"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("target", choices=sorted(TARGETS) + [ALL],
                   help="what to benchmark (all: every target, one report)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quick", action="store_true", help="smaller problem sizes (smoke run)")


def _print_table(result: dict, prefix: str = "") -> None:
    for key, value in result.items():
        if isinstance(value, dict):
            _print_table(value, prefix + key + ".")
        elif isinstance(value, float):
            sys.stdout.write(f"{prefix + key:<40s} {value:.6g}\n")
        else:
            sys.stdout.write(f"{prefix + key:<40s} {value}\n")


class TargetMissing(Exception):
    """The benchmark module of a target is not part of this installation."""


def load_target(name: str):
    """The benchmark module of target ``name``.

    Raises
    ------
    TargetMissing
        When that module (or the package it belongs to) does not exist; an import
        error from inside an existing module is raised as it is.
    """
    modname = TARGETS[name]
    try:
        return importlib.import_module(modname)
    except ModuleNotFoundError as exc:
        # only the target's own module path counts as missing: a dependency that the
        # module imports and cannot find is a real error
        if exc.name is not None and (modname == exc.name or modname.startswith(exc.name + ".")):
            raise TargetMissing(f"{modname} is not available ({exc})") from exc
        raise


# -- peak memory ----------------------------------------------------------------------

def _read_status_kib(field: str) -> float | None:
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return float(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def reset_peak_rss() -> bool:
    """Reset this process's peak resident set (Linux: ``/proc/self/clear_refs``, 5) to
    its current size, so the next peak read belongs to what runs next; False where the
    kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_rss_mib() -> float:
    """Peak resident memory of this process, MiB: ``VmHWM`` (which
    :func:`reset_peak_rss` resets), else ``getrusage``'s ``ru_maxrss`` (process life)."""
    hwm = _read_status_kib("VmHWM")
    if hwm is not None:
        return hwm / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_all(args) -> tuple[dict, int]:
    """Every target in this process; (report, exit status: 1 if a target failed)."""
    from ..backend import describe_machine

    report = {"machine": describe_machine(), "quick": bool(args.quick), "targets": {}}
    status = 0
    t_all = time.perf_counter()
    for name in TARGETS:
        entry: dict = {}
        try:
            mod = load_target(name)
        except TargetMissing as exc:
            entry["skipped"] = str(exc)
            logger.warning("bench %s skipped: %s", name, exc)
            report["targets"][name] = entry
            continue
        resettable = reset_peak_rss()
        rss0 = peak_rss_mib()
        t0 = time.perf_counter()
        logger.info("bench %s ...", name)
        try:
            entry["result"] = mod.run_bench(args)
        except Exception as exc:  # one broken target must not hide the others' figures
            logger.debug("bench %s failed", name, exc_info=True)
            entry["error"] = f"{type(exc).__name__}: {exc}"
            status = 1
        entry["seconds"] = time.perf_counter() - t0
        entry["peak_rss_mib"] = peak_rss_mib()
        entry["peak_rss_growth_mib"] = entry["peak_rss_mib"] - rss0
        entry["peak_rss_scope"] = "this target" if resettable else "process so far"
        report["targets"][name] = entry
    report["seconds"] = time.perf_counter() - t_all
    # the resets also reset ru_maxrss: the process's peak is the largest target's
    report["peak_rss_mib"] = max([peak_rss_mib()] + [e["peak_rss_mib"] for e in
                                                     report["targets"].values()
                                                     if "peak_rss_mib" in e])
    report["machine"]["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    return report, status


def run(args) -> int:
    if args.target == ALL:
        result, status = run_all(args)
    else:
        try:
            mod = load_target(args.target)
        except TargetMissing as exc:
            raise UsageError(f"bench target {args.target!r}: {exc}") from exc
        result, status = mod.run_bench(args), 0
    if args.json:
        print_json(result)
    else:
        _print_table(result)
    return status
