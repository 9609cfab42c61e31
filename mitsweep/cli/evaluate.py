"""``mitsweep evaluate``: PSNR/SSIM of EDOF (every restoration method the dataset holds),
focused and stopped images on ground truth; a thin wrapper over
:func:`mitsweep.workflows.evaluate_dataset`."""

from __future__ import annotations

import argparse
import sys

from ..workflows.dataset import evaluate_dataset
from .common import print_json

NAME = "evaluate"
HELP = "score a dataset: PSNR and SSIM inside the mirror's image, per radius and depth band"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", help="dataset directory (from `mitsweep dataset`)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE", help="per-radius PSNR curves (PNG)")
    p.add_argument("--out", metavar="FILE", help="also write the JSON to FILE")


def run(args) -> int:
    results = evaluate_dataset(args.dataset, plot=args.plot, out=args.out).value
    if args.json:
        print_json(results)
    else:
        # Every image the manifest holds: one EDOF per restoration method and light level.
        width = max([22, *(len(name) for name in results["mean"])])
        sys.stdout.write(f"{'image':<{width}s} {'PSNR dB':>8s} {'SSIM':>7s}\n")
        for name, m in sorted(results["mean"].items()):
            sys.stdout.write(f"{name:<{width}s} {m['psnr']:8.2f} {m['ssim']:7.4f}\n")
    return 0
