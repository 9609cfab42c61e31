"""``mitsweep dataset``: render a synthetic focal-sweep dataset (resumable)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from .common import (UsageError, check_outputs, load_setup_arg, positive_float, positive_int,
                     print_json)

NAME = "dataset"
HELP = ("render a synthetic dataset: ground truth, focused, sweep and stopped images, depth "
        "AOV, IPSF bank, noisy versions and EDOF images, with a manifest (resumable)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file")
    p.add_argument("--out", required=True, help="dataset directory")
    p.add_argument("--scenes", type=positive_int, default=1, help="scene variations (default 1)")
    p.add_argument("--seed", type=int, default=0, help="base seed (default 0)")
    p.add_argument("--spp", type=positive_int, nargs=4, metavar=("PINHOLE", "FOCUSED", "SWEEP", "STOPPED"),
                   default=[16, 64, 128, 64], help="samples per pixel per mode (default 16 64 128 64)")
    p.add_argument("--lux", type=positive_float, nargs="*", default=[50.0, 2.0, 0.5],
                   help="light levels for the noisy images, lux (default 50 2 0.5)")
    p.add_argument("--executor", choices=["serial", "process"], default="serial")
    p.add_argument("--jobs", type=positive_int, default=2, help="processes for --executor process")
    p.add_argument("--wait", nargs="?", type=_seconds, const=math.inf, default=None,
                   metavar="SECONDS",
                   help="if another run holds the directory, wait for it (for ever, or at "
                        "most SECONDS) instead of refusing at once")
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")


def _seconds(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if not x >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 seconds, got {text}")
    return x


#: DatasetOptions fields → the options that set them, for messages.
_OPTION_OF = {"scenes": "--scenes", "seed": "--seed", "spp": "--spp",
              "light_levels_lux": "--lux"}


def check_dataset_outputs(inputs: list, out: Path, opts) -> None:
    """:func:`check_outputs` for a dataset directory: no input is the directory, nor one
    of the files a run with ``opts`` writes in it (manifest, lock, items)."""
    from ..io.lock import LOCK_FILE
    from ..pipeline import MANIFEST, item_names

    check_outputs(inputs, [out])
    written = None
    root = out.resolve()
    for inp in inputs:
        if inp is None:
            continue
        try:
            rel = Path(inp).resolve().relative_to(root).as_posix()
        except ValueError:
            continue  # not inside the directory
        written = written or {MANIFEST, LOCK_FILE, *item_names(opts)}
        if rel in written:
            check_outputs([inp], [out / rel])


def run(args) -> int:
    from ..pipeline import DatasetError, DatasetOptions, build_dataset

    if args.out.strip() == "":
        raise UsageError("--out: must name a directory")
    setup = load_setup_arg(args.setup)
    try:
        opts = DatasetOptions(scenes=args.scenes, seed=args.seed,
                              spp=dict(zip(("pinhole", "focused", "sweep", "stopped"), args.spp)),
                              light_levels_lux=tuple(args.lux))
    except DatasetError as exc:  # name the option, not the field
        field, _, rest = str(exc).partition(":")
        raise UsageError(f"{_OPTION_OF.get(field.split('[')[0], field)}:{rest}") from None
    out = Path(args.out)
    check_dataset_outputs([args.setup], out, opts)
    manifest = build_dataset(setup, out, opts, executor=args.executor, jobs=args.jobs,
                             wait=args.wait)
    if args.json:
        print_json(manifest)
    else:
        print(f"{len(manifest['items'])} items in {args.out}/ (manifest.json)")
    return 0
