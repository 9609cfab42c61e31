"""The main job on the embedded default setup, the paper's sphere (``mitsweep demo``).

The whole chain, written under ``out``: optimal sweep range (paper Eq. 4–9) and its
traced check → renders (pinhole ground truth, focused, sweep, stopped) → IPSF bank →
deconvolution (clean and at 50 lux) → evaluation against the ground truth → images
(EXR and PNG), plots and a short report (``report.md``, ``report.json``).
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from collections.abc import Callable

from .. import __version__
from ._base import InputError, WorkflowResult, resolve_setup
from ._paths import check_outputs

__all__ = ["run_demo", "DEMO_SPP"]

#: Samples per pixel of the demo's renders (each mode's sampler:
#: ``mitsweep.render.api.MODE_SAMPLERS``), spent where the figures need them. The
#: stratified ground truth's two seeds agree to 42 dB at 64 spp (36 dB at the 256
#: independent samples it had). The focused image's error is its blur (20 dB): 64 spp
#: move it by 0.1 dB. The F11 image (28 dB) keeps about its old noise at 144
#: stratified spp. The sweep keeps 512 independent spp: the EDOF image's Wiener NSR is
#: estimated from the sweep's own noise (docs/reference/datasets.md, "Measured on the paper's three setups").
DEMO_SPP = {"pinhole": 64, "focused": 64, "sweep": 512, "stopped": 144}
#: Files the demo writes under --out besides the dataset and the images' PNGs.
_OUTPUTS = ("focal_surfaces.png", "evaluation.json", "psnr_per_radius.png", "report.json",
            "report.md")


def run_demo(out: str | os.PathLike = "out/demo", *, setup: str | os.PathLike | None = None,
             spp_scale: float = 1.0, scenes: int = 1, verify: bool = True,
             step: Callable[[str], object] | None = None) -> WorkflowResult:
    """Run the whole pipeline on the paper's spherical mirror (``mitsweep demo``).

    Parameters
    ----------
    out : path-like
        Output directory (the dataset under ``out/dataset``, images, plots, reports).
    setup : path-like or str, optional
        A setup TOML file or bundled name (default: the embedded paper sphere).
    spp_scale : float
        Scale of every render's samples per pixel (:data:`DEMO_SPP`), finite, > 0.
    scenes : int
        Scene variations.
    verify : bool
        Also trace the sweep range (the check of paper Eq. 8–9).
    step : callable, optional
        Called with one line per stage (the command prints them on stderr).

    Returns
    -------
    WorkflowResult
        ``value``: the report (``report.json``: setup, sweep_range, traced_sweep_range,
        evaluation, timings, spp). ``summary``: the evaluation's scores
        (:func:`mitsweep.workflows.evaluate_dataset`'s). ``provenance``: ``setup``, ``out``,
        ``spp``, ``scenes``, ``verify``, ``timings``, ``version``.

    Raises
    ------
    InputError
        A bad ``spp_scale``, an output directory that cannot be made, outputs that would
        overwrite the setup.

    Examples
    --------
    >>> from mitsweep.workflows import run_demo
    >>> r = run_demo("out/demo", spp_scale=0.25)       # doctest: +SKIP
    >>> r.summary["mean"]["edof"]["psnr"] > r.summary["mean"]["focused"]["psnr"]  # doctest: +SKIP
    True
    """
    from ..config import DEFAULT_SETUP
    from ..io import read_exr, write_text_atomic
    from ..io.exr import stack_channels
    from ..io.png import write_png
    from ..optics import optimal_sweep_range
    from ..pipeline import (
        DatasetOptions,
        build_dataset,
        evaluate_dataset,
        item_names,
        white_level,
    )
    from ..plots import plot_focal_surfaces, plot_per_radius
    from .dataset import check_dataset_outputs

    step = step or (lambda message: None)
    setup_path = setup
    if not (0 < spp_scale < math.inf):
        raise InputError(f"--spp-scale: must be a finite number > 0, got {spp_scale:g}")

    resolved = resolve_setup(setup_path) if setup_path else DEFAULT_SETUP
    out = Path(out)
    spp = {k: max(1, int(round(v * spp_scale))) for k, v in DEMO_SPP.items()}
    opts = DatasetOptions(scenes=scenes, seed=0, spp=spp)
    check_outputs([setup_path], {"--out": [out / name for name in _OUTPUTS]
                                 + [out / f"{Path(n).stem}.png" for n in item_names(opts)
                                    if n.startswith("scene_000/")]})
    check_dataset_outputs([setup_path], out / "dataset", opts)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create {out} ({exc.strerror})") from None
    timings: dict[str, float] = {}
    t_all = time.perf_counter()

    t0 = time.perf_counter()
    sweep = optimal_sweep_range(resolved)
    plot_focal_surfaces(resolved, sweep, out / "focal_surfaces.png")
    timings["sweep_range_s"] = time.perf_counter() - t0
    step(f"sweep range {sweep.focus_min:.2f}-{sweep.focus_max:.2f} mm, sensor travel "
          f"{sweep.translation:.3f} mm, exposure {sweep.exposure_s:.3f} s")
    report: dict = {"setup": resolved.name, "sweep_range": sweep.as_dict()}

    if verify:
        from ..tracer.focus import traced_sweep_range

        t0 = time.perf_counter()
        traced = traced_sweep_range(resolved)
        timings["traced_sweep_range_s"] = time.perf_counter() - t0
        report["traced_sweep_range"] = {"focus_min_mm": traced.focus_min,
                                        "focus_max_mm": traced.focus_max}
        step(f"traced sweep range {traced.focus_min:.2f}-{traced.focus_max:.2f} mm")

    step(f"rendering and deconvolving into {out / 'dataset'} (spp {spp})")
    t0 = time.perf_counter()
    build_dataset(resolved, out / "dataset", opts)
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
    write_text_atomic(out / "report.md", _report_md(resolved, sweep, report, results))
    step(f"done in {timings['total_s']:.0f} s")
    provenance = {"workflow": "run_demo", "version": __version__, "setup": resolved.name,
                  "out": str(out), "spp": spp, "scenes": scenes, "verify": verify,
                  "timings": timings}
    return WorkflowResult(report, provenance, results)


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
