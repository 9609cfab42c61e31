"""Restoration study: every method of mitsweep.deconv.METHODS on datasets of the paper's
setups, noise-free and at 50, 2 and 0.5 lux; PSNR/SSIM of each EDOF against focused and
against F11 (stopped down).

Small by default (one scene, low spp) so that it runs on a laptop; pass --spp and
--scenes for the README's figures. Usage::

    .venv/bin/python scripts/restoration_study.py --out data/study [--setups sphere ...]

It runs ``mitsweep dataset`` then ``mitsweep evaluate --json`` for each setup (resumable:
a finished dataset is not rendered again) and prints one table per setup: rows are the
images (focused, F11, EDOF per method, each noise-free and per lux), columns PSNR and
SSIM overall and PSNR per radial bin.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted", "paraboloid_dslr")
LUX = ("50", "2", "0.5")


def _run(args: list[str]) -> str:
    cmd = [sys.executable, "-c", "import sys; from mitsweep.cli.main import main; "
           "sys.exit(main(sys.argv[1:]))", *args]
    print("$ mitsweep", " ".join(args), file=sys.stderr, flush=True)
    return subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, text=True).stdout


def _row(name: str, entry: dict) -> str:
    radial = entry.get("per_radius") or entry.get("radius") or {}
    if isinstance(radial, dict):
        radial = radial.get("psnr", [])
    per_r = " / ".join(f"{v:.1f}" for v in radial if v == v) if isinstance(radial, list) else ""
    return f"| {name} | {entry['psnr']:.2f} | {entry['ssim']:.3f} | {per_r} |"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--setups", nargs="+", default=list(SETUPS[:3]), choices=SETUPS)
    ap.add_argument("--scenes", type=int, default=1)
    ap.add_argument("--spp", nargs=4, default=["8", "32", "64", "32"])
    ap.add_argument("--methods", default="wiener,rl,tv,hyperlaplacian")
    args = ap.parse_args(argv)
    for setup in args.setups:
        out = args.out / setup
        _run(["dataset", str(ROOT / "scenes" / f"{setup}.toml"), "--out", str(out),
              "--scenes", str(args.scenes), "--spp", *args.spp, "--lux", *LUX,
              "--methods", args.methods])
        res = json.loads(_run(["evaluate", str(out), "--json"]))
        scene = next(iter(res["scenes"].values()))
        print(f"\n### {setup}\n\n| image | PSNR dB | SSIM | PSNR per radius |\n|---|---|---|---|")
        for name in sorted(res["mean"]):
            entry = dict(res["mean"][name], **{k: v for k, v in scene.get(name, {}).items()
                                               if k not in ("psnr", "ssim")})
            print(_row(name, entry))
        sys.stdout.flush()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
