"""Restoration study: every restoration method on datasets of the paper's three setups
(sphere, paraboloid, tilted paraboloid), noise-free and at 50, 2 and 0.5 lux, at the
demo's pixel pitch and at the paper camera's 6.4 µm; PSNR and SSIM of each EDOF image
overall and per radius, against the focused F2.8 image and the stopped-down F11 one.

One command makes the datasets (``mitsweep dataset``, resumable: a finished item is not
made again, so a second run with more methods only restores), scores them
(``mitsweep evaluate --json``) and writes the tables, as markdown (``study.md``, also
printed) and JSON (``study.json``)::

    .venv/bin/python scripts/restoration_study.py --out data/study
    .venv/bin/python scripts/restoration_study.py --out data/study --pitches demo \\
        --spp 8 8 32 8 --setups sphere          # a quick look
    .venv/bin/python scripts/restoration_study.py --out data/study \\
        --fine-setups sphere paraboloid         # the tilted case only at the demo pitch

Each image is also scored inside the design FOV (r up to the radial bank's last radius):
the mirror's image reaches the rim beyond it, where no kernel was traced.

A pitch other than ``demo`` renders the setup on a sensor of the same size with pixels
of that pitch (mm): the resolution grows by the pitch ratio (sphere 512 px at 18 µm:
1440 px at 6.4 µm), so the blur in pixels is the paper camera's. Richardson–Lucy is left
out at fine pitches unless ``--fine-methods`` names it (at 1.5k² its 60 iterations take
minutes per channel).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The paper's three setups (Sec. 3.1 and 5.2), as scene files.
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
LUX = ("50", "2", "0.5")
#: The paper camera's pixel pitch, mm (a DSLR of its era).
PAPER_PITCH_MM = 0.0064


def _run(args: list[str]) -> str:
    cmd = [sys.executable, "-c", "import sys; from mitsweep.cli.main import main; "
           "sys.exit(main(sys.argv[1:]))", *args]
    print("$ mitsweep", " ".join(args), file=sys.stderr, flush=True)
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"mitsweep {args[0]} failed (exit {proc.returncode})")
    return proc.stdout


def setup_file(setup: str, pitch: str, out: Path) -> Path:
    """The scene file of ``setup`` at ``pitch`` ("demo": as it is; else mm): the same
    sensor size with that pitch, written under ``out/setups``."""
    src = ROOT / "scenes" / f"{setup}.toml"
    if pitch == "demo":
        return src
    from mitsweep.config import load_setup, setup_to_toml

    s = load_setup(src)
    p = float(pitch)
    ratio = s.sensor.pixel_pitch / p
    res = [int(math.ceil(n * ratio / 16.0) * 16) for n in s.sensor.resolution]
    s = dataclasses.replace(s, name=f"{s.name}_{p * 1000:g}um",
                            sensor=dataclasses.replace(s.sensor, pixel_pitch=p,
                                                       resolution=tuple(res)))
    path = out / "setups" / f"{setup}_{p * 1000:g}um.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    text = setup_to_toml(s, header=f"{src.name} at a {p * 1000:g} µm pitch (same sensor "
                                   f"size): scripts/restoration_study.py")
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    return path


def fov_scores(directory: Path) -> tuple[float | None, dict]:
    """PSNR of every image of scene 0 inside the part of the mirror's image that the
    radial bank covers (r <= its last radius: the design FOV; the mask reaches the
    mirror's rim beyond it, where the sweep was not designed and no kernel was traced).
    ``(None, {})`` for a grid bank."""
    import numpy as np

    from mitsweep.deconv import psnr
    from mitsweep.deconv.kernels import radii_px
    from mitsweep.io.bank import load_bank
    from mitsweep.optics.pixels import optical_center_px
    from mitsweep.pipeline.tasks import read_rgb, white_level

    bank = load_bank(directory / "bank.npz")
    if bank.kind != "radial":
        return None, {}
    scene = directory / "scene_000"
    gt, chans, _ = read_rgb(scene / "pinhole.exr")
    mask = chans["mask.Y"] > 0.5
    level = white_level(gt, chans["mask.Y"])
    r_fov = float(radii_px(bank).max())
    cy, cx = optical_center_px(mask.shape)
    yy, xx = np.mgrid[:mask.shape[0], :mask.shape[1]]
    inside = mask & (np.hypot(yy - cy, xx - cx) <= r_fov)
    out = {}
    for path in sorted(scene.glob("*.exr")):
        if path.stem != "pinhole":
            out[path.stem] = psnr(read_rgb(path)[0] / level, gt / level, mask=inside)
    return r_fov, out


def _images(methods: list[str]) -> list[tuple[str, str, str]]:
    """(row label, light, item stem) of every image the tables show."""
    rows = []
    for light in ["none", *LUX]:
        suffix = "" if light == "none" else f"_{light}lux"
        if light == "none":
            rows.append(("focused F2.8", light, "focused"))
        rows.append(("F11", light, f"stopped{suffix}"))
        rows.append(("sweep (raw)", light, f"sweep{suffix}"))
        for m in methods:
            rows.append((f"EDOF {m}", light, ("edof" if m == "wiener" else f"edof_{m}") + suffix))
    return rows


def _entry(scene: dict, stem: str) -> dict | None:
    e = scene.get(stem)
    if not isinstance(e, dict):
        return None
    pr = e.get("per_radius", {})
    return {"psnr": e["psnr"], "ssim": e["ssim"], "per_radius_psnr": pr.get("psnr"),
            "per_radius_ssim": pr.get("ssim"), "radius_px": pr.get("radius_px")}


def tables(results: dict, methods_of: dict, fov: dict) -> tuple[str, dict]:
    """Markdown and JSON of the study from ``{key: evaluate's JSON}`` and
    ``{key: fov_scores}``."""
    md, js = [], {}
    summary = ["| setup | pitch | light | focused | F11 | best EDOF (method) | EDOF − F11 | "
               "EDOF − focused |", "|---|---|---|---|---|---|---|---|"]
    for key, res in results.items():
        setup, pitch = key
        scene = next(iter(res["scenes"].values()))
        r_fov, in_fov = fov.get(key, (None, {}))
        rows = {}
        for label, light, stem in _images(methods_of[key]):
            e = _entry(scene, stem)
            if e is not None:
                rows[stem] = dict(e, label=label, light=light, psnr_fov=in_fov.get(stem))
        radius = next((r["radius_px"] for r in rows.values() if r["radius_px"]), [])
        js[f"{setup}@{pitch}"] = {"setup": setup, "pitch": pitch, "images": rows,
                                  "mirror_radius_px": scene.get("mirror_radius_px"),
                                  "fov_radius_px": r_fov}
        head = " / ".join(f"{r:.0f}" for r in radius)
        fov_head = f"PSNR r ≤ {r_fov:.0f} px (FOV)" if r_fov else "PSNR in FOV"
        md += [f"\n### {setup}, pitch {pitch}\n",
               f"| image | light | PSNR dB | SSIM | {fov_head} | PSNR per radius ({head} px) |",
               "|---|---|---|---|---|---|"]
        for stem, r in rows.items():
            per = " / ".join("–" if v is None or v != v else f"{v:.1f}"
                             for v in (r["per_radius_psnr"] or []))
            f = "–" if r["psnr_fov"] is None else f"{r['psnr_fov']:.2f}"
            md.append(f"| {r['label']} | {r['light']} | {r['psnr']:.2f} | {r['ssim']:.3f} "
                      f"| {f} | {per} |")
        focused = rows.get("focused")
        for light in ["none", *LUX]:
            suffix = "" if light == "none" else f"_{light}lux"
            f11 = rows.get(f"stopped{suffix}")
            edofs = [(r["psnr"], r["label"].split()[-1]) for s, r in rows.items()
                     if s.startswith("edof") and r["light"] == light]
            if f11 is None or not edofs or focused is None:
                continue
            best, name = max(edofs)
            # the focused image has no noisy versions: it is compared without noise only
            foc = (f"{focused['psnr']:.2f}", f"{best - focused['psnr']:+.2f}") \
                if light == "none" else ("–", "–")
            summary.append(f"| {setup} | {pitch} | {light} | {foc[0]} | {f11['psnr']:.2f} | "
                           f"{best:.2f} ({name}) | {best - f11['psnr']:+.2f} | {foc[1]} |")
    text = "\n".join(["## Summary (PSNR dB inside the mirror's image)\n", *summary, *md])
    return text + "\n", js


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="study directory")
    ap.add_argument("--setups", nargs="+", default=list(SETUPS), choices=SETUPS)
    ap.add_argument("--pitches", nargs="+", default=["demo", str(PAPER_PITCH_MM)],
                    help="'demo' (the scene file's) and/or pitches in mm (default: demo "
                         f"{PAPER_PITCH_MM})")
    ap.add_argument("--fine-setups", nargs="+", choices=SETUPS,
                    help="setups at pitches other than demo (default: --setups)")
    ap.add_argument("--scenes", type=int, default=1)
    ap.add_argument("--spp", nargs=4, default=["16", "16", "64", "16"],
                    metavar=("PINHOLE", "FOCUSED", "SWEEP", "STOPPED"))
    ap.add_argument("--methods", default="wiener,rl,tv,hyperlaplacian",
                    help="methods at the demo pitch")
    ap.add_argument("--fine-methods", default="wiener,tv,hyperlaplacian",
                    help="methods at other pitches")
    ap.add_argument("--tables-only", action="store_true",
                    help="make no dataset: the tables from each dataset's evaluation.json "
                         "of an earlier run")
    ap.add_argument("--jobs", type=int, default=1,
                    help="local processes per dataset (default 1: this process)")
    args = ap.parse_args(argv)
    for p in args.pitches:
        if p != "demo":
            try:
                ok = float(p) > 0
            except ValueError:
                ok = False
            if not ok:
                ap.error(f"--pitches: 'demo' or a pitch in mm > 0, got {p!r}")
    results, methods_of, seconds, fov = {}, {}, {}, {}
    for pitch in args.pitches:
        for setup in args.setups if pitch == "demo" else (args.fine_setups or args.setups):
            key = (setup, pitch)
            methods = args.methods if pitch == "demo" else args.fine_methods
            methods_of[key] = methods.split(",")
            out = args.out / (setup if pitch == "demo" else f"{setup}_{float(pitch) * 1000:g}um")
            t0 = time.perf_counter()
            cmd = ["dataset", str(setup_file(setup, pitch, args.out)), "--out", str(out),
                   "--scenes", str(args.scenes), "--spp", *args.spp, "--lux", *LUX,
                   "--methods", methods]
            if args.jobs > 1:
                cmd += ["--executor", "process", "--jobs", str(args.jobs)]
            if args.tables_only:
                results[key] = json.loads((out / "evaluation.json").read_text(encoding="utf-8"))
            else:
                _run(cmd)
                results[key] = json.loads(_run(["evaluate", str(out), "--json",
                                                "--out", str(out / "evaluation.json")]))
            fov[key] = fov_scores(out)
            seconds[f"{setup}@{pitch}"] = time.perf_counter() - t0
    text, js = tables(results, methods_of, fov)
    meta = {"spp": dict(zip(("pinhole", "focused", "sweep", "stopped"), map(int, args.spp))),
            "scenes": args.scenes, "seconds": seconds}
    (args.out / "study.md").write_text(text, encoding="utf-8")
    (args.out / "study.json").write_text(json.dumps({"options": meta, "results": js},
                                                    indent=1), encoding="utf-8")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
