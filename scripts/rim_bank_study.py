"""Banks to the rim (issue 27, item 3): a dataset's error budget with its own bank and
with one that covers the whole mirror image, per radius, side by side.

Radial banks (the paraboloid): the dataset's bank extended to the image of the mirror's
rim; grid banks (the tilted paraboloid): the off-mirror nodes filled with the nearest
traced kernel (both :func:`mitsweep.tracer.bank.extend_to_rim`, what
``ipsf_bank(..., extent="rim")`` traces). Both are restored with the dataset's weight
rule; the budget's ``beyond_fov`` region is the design FOV's (radial). ``mitsweep budget
DATASET --rim-bank`` gives the rim bank's budget alone.

    .venv/bin/python scripts/rim_bank_study.py DATASET [--item edof_2lux] [--json]
"""

from __future__ import annotations

import argparse
import json
import math
import sys


def _row(label: str, b: dict, last: str) -> str:
    pr = b["per_radius"]
    cells = " ".join(f"{p:6.2f}" if p is not None else f"{'-':>6s}"
                     for p in pr["psnr_after"][last])
    bf = b["regions"].get("beyond_fov")
    bfs = f"{bf['psnr_after'][last]:6.2f}" if bf and bf["pixels"] else f"{'-':>6s}"
    return f"{label:<8s} {b['total']['psnr_after'][last]:6.2f} {bfs} | {cells}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset")
    ap.add_argument("--item", default="edof_2lux")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    from mitsweep.config import setup_from_dict
    from mitsweep.io.bank import load_bank
    from mitsweep.pipeline import load_manifest
    from mitsweep.pipeline.budget import budget_json, dataset_budget
    from mitsweep.tracer.bank import extend_to_rim

    manifest = load_manifest(a.dataset)
    setup = setup_from_dict(manifest["setup"])
    bank = load_bank(f"{a.dataset}/bank.npz")
    other = extend_to_rim(setup, bank)
    how = ("radial bank traced to the mirror's rim" if bank.kind == "radial" else
           "grid bank, off-mirror nodes filled")
    runs = {}
    for label, b in (("before", None), ("rim", other)):
        res = budget_json(dataset_budget(a.dataset, items=[a.item], bank=b))
        runs[label] = next(iter(res["budgets"].values()))
    if a.json:
        print(json.dumps(runs, indent=1))
        return 0
    b0 = runs["before"]
    last = b0["order"][-1]
    edges = b0["per_radius"]["edges_px"]
    print(f"{a.dataset} {a.item}: {how}; PSNR dB after the last step "
          f"(the restoration), all / beyond the design FOV "
          f"(r > {b0['info'].get('fov_radius_px', math.nan):.1f} px) / per radius bin")
    print(f"{'bank':<8s} {'all':>6s} {'>FOV':>6s} | " + " ".join(
        f"{edges[i]:.0f}-{edges[i + 1]:.0f}".rjust(6) for i in range(len(edges) - 1)))
    for label in runs:
        print(_row(label, runs[label], last))
    print(f"weights: before {b0['weights']}\n         rim    {runs['rim']['weights']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
