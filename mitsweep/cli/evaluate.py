"""``mitsweep evaluate``: PSNR/SSIM of EDOF (every restoration method the dataset holds),
focused and stopped images on ground truth."""

from __future__ import annotations

import argparse
import sys

from .common import check_outputs, json_text, print_json

NAME = "evaluate"
HELP = "score a dataset: PSNR and SSIM inside the mirror's image, per radius and depth band"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", help="dataset directory (from `mitsweep dataset`)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE", help="per-radius PSNR curves (PNG)")
    p.add_argument("--out", metavar="FILE", help="also write the JSON to FILE")


def run(args) -> int:
    from ..io import write_text_atomic
    from ..io.atomic import check_writable
    from ..pipeline import dataset_inputs, evaluate_dataset

    # Before the (long) evaluation: the outputs overwrite none of the dataset's files,
    # and can be written.
    check_outputs(dataset_inputs(args.dataset), {"--plot": args.plot, "--out": args.out})
    for path in (args.plot, args.out):
        if path:
            check_writable(path)
    if args.plot:
        from ..plots import check_figure_path

        check_figure_path(args.plot, "--plot")
    results = evaluate_dataset(args.dataset)
    if args.plot:
        from ..plots import plot_per_radius

        plot_per_radius(results, args.plot)
    if args.out:
        write_text_atomic(args.out, json_text(results))      # the same text as --json
    if args.json:
        print_json(results)
    else:
        # Every image the manifest holds: one EDOF per restoration method and light level.
        width = max([22, *(len(name) for name in results["mean"])])
        sys.stdout.write(f"{'image':<{width}s} {'PSNR dB':>8s} {'SSIM':>7s}\n")
        for name, m in sorted(results["mean"].items()):
            sys.stdout.write(f"{name:<{width}s} {m['psnr']:8.2f} {m['ssim']:7.4f}\n")
    return 0
