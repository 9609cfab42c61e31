"""``mitsweep demo``: the main job on the embedded default setup (the paper's sphere).

The whole chain, written under ``--out``: optimal sweep range (paper Eq. 4–9) and its
traced check → renders (pinhole ground truth, focused, sweep, stopped) → IPSF bank →
deconvolution (clean and at 50 lux) → evaluation against the ground truth → images
(EXR and PNG), plots and a short report (``report.md``, ``report.json``).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import time
from pathlib import Path

from .common import UsageError, check_outputs, positive_int

NAME = "demo"
HELP = "run the whole pipeline on the embedded default setup (the paper's spherical mirror)"

logger = logging.getLogger(__name__)

#: Samples per pixel of the demo's renders (each mode's sampler:
#: ``mitsweep.render.api.MODE_SAMPLERS``), spent where the figures need them. The
#: stratified ground truth's two seeds agree to 42 dB at 64 spp (36 dB at the 256
#: independent samples it had). The focused image's error is its blur (20 dB): 64 spp
#: move it by 0.1 dB. The F11 image (28 dB) keeps about its old noise at 144
#: stratified spp. The sweep keeps 512 independent spp: the EDOF image's Wiener NSR is
#: estimated from the sweep's own noise (see README, "Validation on ground truth").
DEMO_SPP = {"pinhole": 64, "focused": 64, "sweep": 512, "stopped": 144}
#: Files the demo writes under --out besides the dataset and the images' PNGs.
_OUTPUTS = ("focal_surfaces.png", "evaluation.json", "psnr_per_radius.png", "report.json",
            "report.md")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--setup", help="setup TOML (default: the embedded paper sphere)")
    p.add_argument("--out", default="out/demo", help="output directory (default: out/demo)")
    p.add_argument("--spp-scale", type=float, default=1.0,
                   help="scale the samples per pixel of every render (default 1)")
    p.add_argument("--scenes", type=positive_int, default=1, help="scene variations (default 1)")
    p.add_argument("--no-verify", action="store_true", help="skip the traced sweep-range check")


def _step(msg: str) -> None:
    sys.stderr.write(f"[demo] {msg}\n")
    sys.stderr.flush()


def run(args) -> int:
    from ..config import DEFAULT_SETUP, load_setup
    from ..io import read_exr, write_text_atomic
    from ..io.exr import stack_channels
    from ..io.png import write_png
    from ..optics import optimal_sweep_range
    from ..pipeline import DatasetOptions, build_dataset, evaluate_dataset, item_names, white_level
    from ..plots import plot_focal_surfaces, plot_per_radius
    from ..workflows.dataset import check_dataset_outputs

    if not (0 < args.spp_scale < math.inf):
        raise UsageError(f"--spp-scale: must be a finite number > 0, got {args.spp_scale:g}")

    setup = load_setup(args.setup) if args.setup else DEFAULT_SETUP
    out = Path(args.out)
    spp = {k: max(1, int(round(v * args.spp_scale))) for k, v in DEMO_SPP.items()}
    opts = DatasetOptions(scenes=args.scenes, seed=0, spp=spp)
    check_outputs([args.setup], {"--out": [out / name for name in _OUTPUTS]
                                 + [out / f"{Path(n).stem}.png" for n in item_names(opts)
                                    if n.startswith("scene_000/")]})
    check_dataset_outputs([args.setup], out / "dataset", opts)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--out: cannot create {out} ({exc.strerror})") from None
    timings: dict[str, float] = {}
    t_all = time.perf_counter()

    t0 = time.perf_counter()
    sweep = optimal_sweep_range(setup)
    plot_focal_surfaces(setup, sweep, out / "focal_surfaces.png")
    timings["sweep_range_s"] = time.perf_counter() - t0
    _step(f"sweep range {sweep.focus_min:.2f}-{sweep.focus_max:.2f} mm, sensor travel "
          f"{sweep.translation:.3f} mm, exposure {sweep.exposure_s:.3f} s")
    report: dict = {"setup": setup.name, "sweep_range": sweep.as_dict()}

    if not args.no_verify:
        from ..tracer.focus import traced_sweep_range

        t0 = time.perf_counter()
        traced = traced_sweep_range(setup)
        timings["traced_sweep_range_s"] = time.perf_counter() - t0
        report["traced_sweep_range"] = {"focus_min_mm": traced.focus_min,
                                        "focus_max_mm": traced.focus_max}
        _step(f"traced sweep range {traced.focus_min:.2f}-{traced.focus_max:.2f} mm")

    _step(f"rendering and deconvolving into {out / 'dataset'} (spp {spp})")
    t0 = time.perf_counter()
    build_dataset(setup, out / "dataset", opts)
    timings["dataset_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    results = evaluate_dataset(out / "dataset")
    timings["evaluate_s"] = time.perf_counter() - t0
    write_text_atomic(out / "evaluation.json", json.dumps(results, indent=1, default=str) + "\n")
    plot_per_radius(results, out / "psnr_per_radius.png")

    scene = out / "dataset" / "scene_000"
    chans, _ = read_exr(scene / "pinhole.exr")
    level = white_level(stack_channels(chans), chans.get("mask.Y"))
    for path in sorted(scene.glob("*.exr")):
        img = stack_channels(read_exr(path)[0])
        write_png(out / f"{path.stem}.png", img, white=level)

    timings["total_s"] = time.perf_counter() - t_all
    report.update(evaluation=results["mean"], timings=timings, spp=spp)
    write_text_atomic(out / "report.json", json.dumps(report, indent=2, default=str) + "\n")
    write_text_atomic(out / "report.md", _report_md(setup, sweep, report, results))
    _step(f"done in {timings['total_s']:.0f} s")
    means = results["mean"]
    print(f"sweep range {sweep.focus_min:.2f}-{sweep.focus_max:.2f} mm; PSNR inside the "
          f"mirror: EDOF {means['edof']['psnr']:.2f} dB, focused {means['focused']['psnr']:.2f} "
          f"dB, stopped {means['stopped']['psnr']:.2f} dB; report: {out / 'report.md'}")
    return 0


def _report_md(setup, sweep, report, results) -> str:
    lines = [f"# mitsweep demo: {setup.name}", "",
             f"Sweep range (Eq. 8–9): {sweep.focus_min:.2f}–{sweep.focus_max:.2f} mm; "
             f"sensor {sweep.sensor_start:.4f} → {sweep.sensor_end:.4f} mm "
             f"(travel {sweep.translation:.4f} mm, exposure {sweep.exposure_s:.3f} s at "
             f"{sweep.velocity_mm_s:g} mm/s)."]
    if "traced_sweep_range" in report:
        t = report["traced_sweep_range"]
        lines.append(f"Traced check: {t['focus_min_mm']:.2f}–{t['focus_max_mm']:.2f} mm.")
    lines += ["", "| image | PSNR (dB) | SSIM |", "|---|---|---|"]
    for name, m in sorted(results["mean"].items()):
        lines.append(f"| {name} | {m['psnr']:.2f} | {m['ssim']:.4f} |")
    lines += ["", "Per radius (dB, bins from the optical axis outward):", ""]
    first = next(iter(results["scenes"].values()))
    names = [n for n in ("focused", "sweep", "edof", "stopped") if n in first]
    radii = first[names[0]]["per_radius"]["radius_px"]
    lines.append("| radius (px) | " + " | ".join(names) + " |")
    lines.append("|---" * (len(names) + 1) + "|")
    for k, r in enumerate(radii):
        lines.append(f"| {r:.0f} | " + " | ".join(f"{first[n]['per_radius']['psnr'][k]:.2f}"
                                                  for n in names) + " |")
    lines += ["", "Timings (s): " + ", ".join(f"{k} {v:.1f}" for k, v in report["timings"].items()),
              "", "Images: `pinhole.png` (ground truth), `focused.png`, `sweep.png`, `edof.png`, "
              "`stopped.png` and the `*_50lux` noisy versions; `focal_surfaces.png` (Fig. 6), "
              "`psnr_per_radius.png`.", ""]
    return "\n".join(lines)
