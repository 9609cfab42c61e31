"""``mitsweep dataset``: render a synthetic focal-sweep dataset (resumable)."""

from __future__ import annotations

import argparse

from .common import UsageError, load_setup_arg, positive_float, positive_int, print_json

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
    p.add_argument("--json", action="store_true", help="print the manifest as JSON")


def run(args) -> int:
    from ..pipeline import DatasetOptions, build_dataset

    setup = load_setup_arg(args.setup)
    opts = DatasetOptions(scenes=args.scenes, seed=args.seed,
                          spp=dict(zip(("pinhole", "focused", "sweep", "stopped"), args.spp)),
                          light_levels_lux=tuple(args.lux))
    if args.out.strip() == "":
        raise UsageError("--out: must name a directory")
    manifest = build_dataset(setup, args.out, opts, executor=args.executor, jobs=args.jobs)
    if args.json:
        print_json(manifest)
    else:
        print(f"{len(manifest['items'])} items in {args.out}/ (manifest.json)")
    return 0
