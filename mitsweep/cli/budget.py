"""``mitsweep budget``: where each EDOF image's error comes from (information limit,
forward-model mismatch, Monte Carlo and sensor noise, the weight choice), per radius and
depth band (:func:`mitsweep.pipeline.budget.dataset_budget`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import check_outputs, json_text, print_json

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
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--out", metavar="DIR",
                   help="write budget.json, budget.txt and one budget_*.png per item here")


def run(args) -> int:
    from ..io import write_text_atomic
    from ..pipeline import dataset_inputs
    from ..pipeline.budget import budget_json, dataset_budget
    from .common import UsageError

    if args.second_seed is not None and not args.out:
        raise UsageError("--second-seed needs --out DIR (the second renders are kept there)")
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.exists() and not out.is_dir():
            raise UsageError(f"--out {out}: not a directory")
        check_outputs(dataset_inputs(args.dataset), [out / "budget.json", out / "budget.txt"])
    result = dataset_budget(args.dataset, items=args.item, second_seed=args.second_seed,
                            work_dir=out / "renders" if out is not None else None)
    text = "".join(f"{name} (restored from {b.info['restored_from']})\n{b.table()}\n"
                   for name, b in result["budgets"].items())
    data = budget_json(result)
    if out is not None:
        from ..plots import plot_error_budget

        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / "budget.json", json_text(data))   # the same text as --json
        write_text_atomic(out / "budget.txt", text)
        for name, b in data["budgets"].items():
            stem = name.removesuffix(".exr").replace("/", "_")
            plot_error_budget(b, out / f"budget_{stem}.png", title=name)
    if args.json:
        print_json(data)
    else:
        sys.stdout.write(text)
    return 0
