"""``mitsweep evaluate``: PSNR/SSIM of EDOF, focused and stopped images on ground truth."""

from __future__ import annotations

import argparse
import sys

from .common import check_outputs, print_json

NAME = "evaluate"
HELP = "score a dataset: PSNR and SSIM inside the mirror's image, per radius and depth band"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", help="dataset directory (from `mitsweep dataset`)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", metavar="FILE", help="per-radius PSNR curves (PNG)")
    p.add_argument("--out", metavar="FILE", help="also write the JSON to FILE")


def plot_per_radius(results: dict, path, pixel_pitch: float | None = None) -> None:
    from ..plots import new_figure, save_figure

    scenes = results["scenes"]
    first = next(iter(scenes.values()))
    fig, ax = new_figure(figsize=(7, 4.5))
    styles = {"edof": ("tab:red", "-"), "focused": ("tab:blue", "-"), "stopped": ("tab:green", "-"),
              "sweep": ("0.5", ":")}
    for name, entry in sorted(first.items()):
        if not isinstance(entry, dict):
            continue
        base = name.split("_")[0]
        color, ls = styles.get(base, ("k", "-"))
        if "lux" in name:
            ls = "--"
        r = entry["per_radius"]
        ax.plot(r["radius_px"], r["psnr"], ls, color=color, marker="o", ms=3, label=name)
    ax.set_xlabel("distance from the optical axis (pixels)")
    ax.set_ylabel("PSNR (dB) against the pinhole ground truth")
    ax.set_title("per-radius PSNR inside the mirror's image")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    save_figure(fig, path)


def run(args) -> int:
    import json

    from ..io import write_text_atomic
    from ..io.atomic import check_writable
    from ..pipeline import dataset_inputs, evaluate_dataset

    # Before the (long) evaluation: the outputs overwrite none of the dataset's files,
    # and can be written.
    check_outputs(dataset_inputs(args.dataset), [args.plot, args.out])
    for path in (args.plot, args.out):
        if path:
            check_writable(path)
    results = evaluate_dataset(args.dataset)
    if args.plot:
        plot_per_radius(results, args.plot)
    if args.out:
        write_text_atomic(args.out, json.dumps(results, indent=1, default=str) + "\n")
    if args.json:
        print_json(results)
    else:
        sys.stdout.write(f"{'image':<22s} {'PSNR dB':>8s} {'SSIM':>7s}\n")
        for name, m in sorted(results["mean"].items()):
            sys.stdout.write(f"{name:<22s} {m['psnr']:8.2f} {m['ssim']:7.4f}\n")
    return 0
