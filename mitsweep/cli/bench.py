"""``mitsweep bench TARGET``: reproducible benchmarks printed side by side.

Each target is a module ``mitsweep.<pkg>.bench`` exposing
``add_arguments(parser)`` (optional) and ``run_bench(args) -> dict``; the dict is
printed as a table, or as JSON with ``--json``. Baselines run in the same process so
that ratios survive a noisy machine.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from .common import print_json

NAME = "bench"
HELP = "benchmarks (run time against error, against baselines in the same run)"

TARGETS = {
    "tracer": "mitsweep.tracer.bench",
    "render": "mitsweep.render.bench",
    "deconv": "mitsweep.deconv.bench",
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("target", choices=sorted(TARGETS), help="what to benchmark")
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


def run(args) -> int:
    mod = importlib.import_module(TARGETS[args.target])
    result = mod.run_bench(args)
    if args.json:
        print_json(result)
    else:
        _print_table(result)
    return 0
