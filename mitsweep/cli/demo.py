"""``mitsweep demo``: the main job on the embedded default setup (the paper's sphere).

The whole chain, written under ``--out``: optimal sweep range (paper Eq. 4–9) and its
traced check → renders (pinhole ground truth, focused, sweep, stopped) → IPSF bank →
deconvolution (clean and at 50 lux) → evaluation against the ground truth → images
(EXR and PNG), plots and a short report (``report.md``, ``report.json``). A thin wrapper
over :func:`mitsweep.workflows.run_demo`.
"""

from __future__ import annotations

import argparse
import sys

from ..workflows.demo import DEMO_SPP, run_demo  # noqa: F401  (DEMO_SPP: the demo's spp)
from .common import positive_int

NAME = "demo"
HELP = "run the whole pipeline on the embedded default setup (the paper's spherical mirror)"


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
    result = run_demo(args.out, setup=args.setup, spp_scale=args.spp_scale,
                      scenes=args.scenes, verify=not args.no_verify, step=_step)
    sweep, means = result.value["sweep_range"], result.summary["mean"]
    print(f"sweep range {sweep['focus_min_mm']:.2f}-{sweep['focus_max_mm']:.2f} mm; PSNR inside the "
          f"mirror: EDOF {means['edof']['psnr']:.2f} dB, focused {means['focused']['psnr']:.2f} "
          f"dB, stopped {means['stopped']['psnr']:.2f} dB; report: "
          f"{result.provenance['out']}/report.md")
    return 0
