"""``mitsweep figures``: every figure of the paper, for its three setups, in one command; a
thin wrapper over :func:`mitsweep.workflows.make_paper_figures`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.paper import make_paper_figures
from .common import number_type

NAME = "figures"
HELP = ("regenerate the paper's figures (Figs. 3-6, 8-10 and Table 1) for its three setups, "
        "as PNG and PDF")


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..pipeline.figures import PAPER_SETUPS

    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--setup", action="append", metavar="SETUP",
                   help=f"a paper setup ({', '.join(PAPER_SETUPS)}: the bundled "
                        f"scenes/<name>.toml) or a setup TOML file; repeat for several "
                        f"(default: the three)")
    p.add_argument("--quick", action="store_true",
                   help="small renders and few rays: every file in minutes (the full run "
                        "is the gallery's quality)")
    p.add_argument("--force", action="store_true",
                   help="overwrite the figures of an earlier run in DIR (its renders under "
                        "DIR/data are reused)")
    from ..pipeline.options import MAX_SEED

    # checked as the command line is read: a bad seed must fail before the first figure
    seed = number_type(int, lambda x: 0 <= x <= MAX_SEED, "an integer",
                       f"in [0, {MAX_SEED}]", "seed")
    p.add_argument("--seed", type=seed, default=0,
                   help=f"seed of traces and renders, 0 to {MAX_SEED} (0)")


def _step(msg: str) -> None:
    sys.stderr.write(f"[figures] {msg}\n")
    sys.stderr.flush()


def run(args) -> int:
    result = make_paper_figures(args.out, setups=args.setup, quick=args.quick,
                                force=args.force, seed=args.seed, step=_step)
    report, p = result.value, result.provenance
    n = sum(len(v["files"]) for v in report["setups"].values())
    print(f"{n} files for {', '.join(p['setups'])} ({p['quality']} quality) in {p['out']}, "
          f"{report['total_s']:.0f} s; provenance: {p['out']}/figures.json")
    return 0
