"""``mitsweep figures``: every figure of the paper, for its three setups, in one command."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import UsageError, check_outputs, load_setup_arg, number_type

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


def resolve_setup(text: str) -> Path:
    """A ``--setup`` value → its TOML file: a paper setup's name (the bundled file,
    :func:`mitsweep.resources.bundled_setup`) or a path."""
    from ..pipeline.figures import PAPER_SETUPS
    from ..resources import bundled_setup

    if text in PAPER_SETUPS:
        return bundled_setup(text)
    p = Path(text)
    if p.suffix == ".toml" and p.is_file():
        return p
    raise UsageError(f"--setup {text!r}: not a paper setup ({', '.join(PAPER_SETUPS)}) nor "
                     f"an existing .toml file")


def run(args) -> int:
    from ..pipeline.figures import FULL, PAPER_SETUPS, QUICK, data_dir, figure_files, make_figures

    if args.out.strip() == "":
        raise UsageError("--out: must name a directory")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    paths = [resolve_setup(s) for s in (args.setup or PAPER_SETUPS)]
    setups = [load_setup_arg(str(p)) for p in paths]
    names = [s.name for s in setups]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise UsageError(f"--setup: {', '.join(dup)} given twice (each setup's name is its "
                         f"files' suffix)")
    quality = QUICK if args.quick else FULL
    files = [out / name for s in setups for name in figure_files(s)] + [out / "figures.json"]
    check_outputs([str(p) for p in paths], {"--out": files})
    if not args.force:
        existing = [f for f in files if f.exists()]
        existing += [d for d in (data_dir(out, s, quality) for s in setups) if d.exists()]
        if existing:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise UsageError(f"{existing[0]} exists{more}: refusing to overwrite an earlier "
                             f"run's figures; pass --force, or choose another --out")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out: cannot create {out} ({exc.strerror})") from None

    def step(msg: str) -> None:
        sys.stderr.write(f"[figures] {msg}\n")
        sys.stderr.flush()

    report = make_figures(setups, out, quality=quality, seed=args.seed, step=step)
    n = sum(len(v["files"]) for v in report["setups"].values())
    print(f"{n} files for {', '.join(names)} ({quality.name} quality) in {out}, "
          f"{report['total_s']:.0f} s; provenance: {out / 'figures.json'}")
    return 0
