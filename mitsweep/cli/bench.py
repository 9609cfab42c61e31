"""``mitsweep bench TARGET|all``: reproducible benchmarks printed side by side.

Each target is a module ``mitsweep.<pkg>.bench`` exposing ``run_bench(args) -> dict``;
the dict is printed as a table, or as JSON with ``--json``. Baselines run in the same
process as what they are compared with, so that ratios survive a noisy machine.

``bench all`` runs every target in turn in this process and prints one object: the
machine (:func:`mitsweep.backend.describe_machine`: CPU, cores, memory, load, GPUs,
LLVM, Dr.Jit, Mitsuba and NumPy versions, backend and variant), then for each target
its wall time, its peak resident memory and its own result; a target whose module is
not installed is reported as skipped with the reason, one that fails with its error
(exit status 1). A thin wrapper over :func:`mitsweep.workflows.run_benchmarks`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..workflows.bench import (  # noqa: F401  (names the tests and scripts import from the command)
    BENCH_TARGETS,
    TargetMissing,
    missing_module,
    peak_rss_mib,
    reset_peak_rss,
    run_benchmarks,
)
from .common import UsageError, print_json

NAME = "bench"
HELP = "benchmarks (run time against error, against baselines in the same run)"

#: Target name → its benchmark module (a command-line registry: the modules are loaded
#: by name, which only the CLI may do; see tests/test_architecture.py).
TARGETS = dict(BENCH_TARGETS)
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


def load_target(name: str):
    """The benchmark module of target ``name`` (:data:`TARGETS`).

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
        if missing_module(exc, modname):
            raise TargetMissing(f"{modname} is not available ({exc})") from exc
        raise


def run(args) -> int:
    try:
        got = run_benchmarks(args.target, quick=args.quick, load=load_target,
                             names=list(TARGETS))
    except TargetMissing as exc:
        raise UsageError(f"bench target {args.target!r}: {exc}") from exc
    if args.json:
        print_json(got.value)
    else:
        _print_table(got.value)
    return got.provenance["status"]
