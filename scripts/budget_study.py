"""Error budgets of the demo's EDOF images and of the three bundled mirrors at 2 lux.

Runs, as a user would, ``mitsweep demo`` (the sphere, 512 px) and, per bundled setup
(sphere, paraboloid, tilted paraboloid), ``mitsweep dataset SETUP --scenes 1 --lux 2``;
then ``mitsweep budget`` on each (the demo's Wiener EDOF images; each dataset's
``edof_2lux``), with a second Monte Carlo seed for the ``monte_carlo`` term. Prints, per
budget, each term's MSE per radial bin and over the whole mirror, the terms adding up
to the measured error, and writes them all as JSON (``--json``)::

    .venv/bin/python scripts/budget_study.py OUT --json docs/reference/budget_study.json

About 5 minutes on two cores (4.9 min measured). A rerun reuses what ``OUT`` already holds (the demo, the
datasets, the second-seed renders), so ``--json`` alone rewrites the record quickly.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MITSWEEP = str(ROOT / ".venv" / "bin" / "mitsweep")
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
#: The Monte Carlo seed of the second render (the datasets render with seed 0 onwards).
SECOND_SEED = 1000


def _run(args: list[str]) -> str:
    print("$ mitsweep " + " ".join(args), file=sys.stderr, flush=True)
    return subprocess.run([MITSWEEP, *args], check=True, capture_output=True,
                          text=True).stdout


def _budget(dataset: Path, items: list[str], work: Path) -> dict:
    args = ["budget", str(dataset), "--json", "--second-seed", str(SECOND_SEED),
            "--out", str(work)]
    for item in items:
        args += ["--item", item]
    return json.loads(_run(args))["budgets"]


def _summary(budget: dict) -> dict:
    """What the record keeps of an ErrorBudget: the terms over the mirror and per radial
    bin, the measured MSE and PSNR, the weights."""
    total, radius = budget["total"], budget["per_radius"]
    last = budget["order"][-1]
    return {"order": budget["order"], "weights": budget["weights"],
            "total": {"pixels": total["pixels"], "terms": total["terms"],
                      "mse": total["mse_after"][last], "psnr": total["psnr_after"][last]},
            "per_radius": {"edges_px": radius["edges_px"], "pixels": radius["pixels"],
                           "terms": radius["terms"], "mse": radius["mse_after"][last],
                           "psnr": radius["psnr_after"][last]}}


def study(out: Path) -> dict:
    """Every budget of the study, run (or reused) under ``out``."""
    t0 = time.perf_counter()
    budgets = {}
    demo = out / "demo"
    if not (demo / "report.json").is_file():
        _run(["demo", "--out", str(demo)])
    for item, b in _budget(demo / "dataset", [], out / "demo_budget").items():
        budgets[f"demo (sphere) {item}"] = _summary(b)
    for name in SETUPS:
        d = out / name
        if not (d / "manifest.json").is_file() or not any(d.glob("scene_000/edof_2lux.exr")):
            _run(["dataset", str(ROOT / "scenes" / f"{name}.toml"), "--scenes", "1",
                  "--seed", "0", "--lux", "2", "--out", str(d)])
        for item, b in _budget(d, ["edof_2lux"], out / f"{name}_budget").items():
            budgets[f"{name} {item}"] = _summary(b)
    return {"command": "python scripts/budget_study.py OUT --json FILE",
            "second_seed": SECOND_SEED, "budgets": budgets,
            "seconds": time.perf_counter() - t0}


TERMS = ("information", "depth", "mismatch", "monte_carlo", "sensor", "weight")


def table(record: dict) -> str:
    """One Markdown table: per budget, the whole mirror then each radial bin; each term's
    MSE × 10⁴, their sum (the measured MSE) and its PSNR."""
    head = ["image", "region", "pixels", *TERMS, "total", "PSNR dB"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cells(terms: dict, mse: float, psnr: float | None) -> list[str]:
        vals = ["–" if terms.get(t) is None else f"{1e4 * terms[t]:.2f}" for t in TERMS]
        return [*vals, f"{1e4 * mse:.2f}", "–" if psnr is None else f"{psnr:.2f}"]
    for name, b in record["budgets"].items():
        t = b["total"]
        lines.append("| " + " | ".join([name, "all", str(t["pixels"]),
                                        *cells(t["terms"], t["mse"], t["psnr"])]) + " |")
        r = b["per_radius"]
        e = r["edges_px"]
        for i, n in enumerate(r["pixels"]):
            if not n:
                continue
            terms = {k: v[i] for k, v in r["terms"].items()}
            lines.append("| " + " | ".join(["", f"r {e[i]:.0f}–{e[i + 1]:.0f} px", str(n),
                                            *cells(terms, r["mse"][i], r["psnr"][i])]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("out", type=Path, help="working directory (demo, datasets, renders)")
    p.add_argument("--json", type=Path, help="write the record here")
    a = p.parse_args(argv)
    record = study(a.out)
    if a.json:
        a.json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    print(table(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
