"""``mitsweep budget``: where each EDOF image's error comes from (information limit,
forward-model mismatch, Monte Carlo and sensor noise, the weight choice), per radius and
depth band; a thin wrapper over :func:`mitsweep.workflows.error_budget`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.budget import error_budget
from .common import print_json

NAME = "budget"
HELP = ("error budget of a dataset's EDOF images: information limit, model mismatch, "
        "Monte Carlo and sensor noise, weight choice, per radius and depth band")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", help="dataset directory (from `mitsweep dataset`)")
    p.add_argument("--item", action="append", metavar="NAME",
                   help="EDOF item to budget (repeatable): scene_000/edof_2lux.exr, or a "
                        "stem such as edof_2lux for every scene (default: every Wiener "
                        "EDOF image)")
    p.add_argument("--second-seed", type=int, metavar="SEED",
                   help="render each scene's sweep again with this Monte Carlo seed (into "
                        "--out) to measure the Monte Carlo term")
    p.add_argument("--rim-bank", action="store_true",
                   help="restore with the dataset's bank extended to the mirror's rim (radial: "
                        "traced out to the rim's image; grid: off-mirror nodes filled) instead "
                        "of its own")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", metavar="DIR",
                   help="write budget.json, budget.txt and one budget_*.png per item here")


def run(args) -> int:
    result = error_budget(args.dataset, items=args.item, second_seed=args.second_seed,
                          out=args.out, rim_bank=args.rim_bank)
    if args.json:
        print_json(result.summary)
    else:
        sys.stdout.write(result.provenance["text"])
    return 0
