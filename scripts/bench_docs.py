#!/usr/bin/env python3
"""Write docs/benchmarks.md from ``mitsweep bench all --json``: the page is generated,
never copied by hand.

    .venv/bin/python scripts/bench_docs.py                 # runs `mitsweep bench all --json` (minutes)
    .venv/bin/python scripts/bench_docs.py --quick         # its smoke sizes
    .venv/bin/python scripts/bench_docs.py --from run.json # a saved run's JSON

It keeps the run's JSON beside the page (docs/benchmarks.json), so
``tests/test_bench_docs.py`` checks that the page is exactly what this script makes of
that JSON. Every table of the page comes from one function below, from the JSON alone.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "benchmarks.md"
DATA = ROOT / "docs" / "benchmarks.json"


def _f(x, digits=3) -> str:
    """A number with `digits` significant figures (– for a missing one)."""
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}"
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits:
        return f"{x:,.0f}"
    return f"{x:.{digits}g}"


def _m(rate) -> str:
    """Rays per second in millions."""
    return "–" if rate is None else f"{rate / 1e6:.1f} M"


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table: the header, its rule, one line per row (every row as wide)."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in rows:
        assert len(row) == len(header), (header, row)
        out.append("| " + " | ".join(str(c) for c in row) + " |")
    return out + [""]


def machine_section(run: dict) -> list[str]:
    m = run["machine"]
    la, lb = m.get("load_average") or [None], m.get("load_average_end") or [None]
    rows = [["CPU", f"{m.get('cpu')} ({m.get('cores_usable')} usable cores of {m.get('cores_logical')})"],
            ["memory", f"{_f(m.get('memory_gib'))} GiB"],
            ["GPUs", ", ".join(map(str, m.get("gpus") or [])) or "none"],
            ["backend, variant", f"{m.get('backend')}, `{m.get('variant')}`"],
            ["LLVM, vector width", f"{m.get('llvm')}, {m.get('llvm_vector_width')} (native {m.get('llvm_native_vector_width')})"],
            ["versions", f"mitsweep {m.get('mitsweep')}, Dr.Jit {m.get('drjit')}, Mitsuba {m.get('mitsuba')}, "
                         f"NumPy {m.get('numpy')}, SciPy {m.get('scipy')}, Python {m.get('python')}"],
            ["load average (1 min) at start / end", f"{_f(la[0])} / {_f(lb[0])}"],
            ["problem sizes", "`--quick` (smoke sizes)" if run.get("quick") else "full"],
            ["whole run", f"{_f(run.get('seconds'))} s, peak memory {_f(run.get('peak_rss_mib'))} MiB"]]
    return ["## The machine", "", *table(["", ""], rows)]


def targets_section(run: dict) -> list[str]:
    rows = [[name, _f(t.get("seconds")), f"{_f(t.get('peak_rss_mib'))} (+{_f(t.get('peak_rss_growth_mib'))})",
             "failed: " + str(t["error"]) if t.get("error") else "ok"]
            for name, t in run["targets"].items()]
    return ["## Targets", "", *table(["target", "wall s", "peak memory MiB (growth)", "status"], rows)]


def tracer_section(r: dict) -> list[str]:
    peer = r.get("peer", "peer")
    rows = [["mitsweep, 1 sweep time per ray", _m(r.get("rays_per_s")), _f(r.get("ratio")), _f(r.get("ratio_cpu"))],
            [f"mitsweep, {r.get('default_time_samples')} sweep times per ray",
             _m(r.get("rays_per_s_default_time_samples")), _f(r.get("ratio_default_time_samples")), "–"],
            ["mitsweep, exact sweep deposit", _m(r.get("rays_per_s_exact")), _f(r.get("ratio_exact")), "–"],
            [f"{peer}, reflection only", _m(r.get("peer_rays_per_s")), "1", "1"]]
    out = ["## Tracer (`mitsweep bench tracer`)", "",
           f"Useful rays per second at the {r.get('setup')}'s periphery (u = "
           f"{_f((r.get('image_point_mm') or [None])[0])} mm, l = {_f(r.get('depth_mm'))} mm), "
           f"{_f(r.get('rays'))} rays, {r.get('threads')} threads; {peer} in the same process "
           f"(it takes the wrong root for {_f(100 * r.get('peer_wrong_root_fraction', 0))} % of "
           "these grazing rays, counted as if it did not).", "",
           *table(["", "useful rays/s", f"× {peer}", f"× {peer} in CPU time"], rows)]
    strategies = r.get("deposit_strategies") or []
    if strategies:
        out += ["Deposit strategies, side by side:", "",
                *table(["strategy", "method", "rays/s", "× peer"],
                       [[s.get("strategy"), s.get("method"), _m(s.get("rays_per_s")), _f(s.get("ratio"))]
                        for s in strategies])]
    bank = r.get("bank_error_per_second")
    if bank:
        out += [f"Rays and seconds for a bank ({bank.get('n_radii')} radii × "
                f"{len(bank.get('depths_mm') or [])} depths) whose worst kernel is within the "
                f"target L1 of a {_f(bank.get('reference_rays'))}-ray reference:", "",
                *table(["method", "rays per kernel", "bank s", "worst L1", "error floor L1"],
                       [[row.get("label"), _f(row.get("rays_per_kernel")), _f(row.get("seconds")),
                         _f(row.get("worst_l1")), _f(row.get("floor_l1"))] for row in bank.get("rows", [])])]
    return out


def render_section(r: dict) -> list[str]:
    res = r.get("resolution") or ["?", "?"]
    out = ["## Renderer (`mitsweep bench render`)", "",
           f"{res[0]}×{res[1]} px, {r.get('spp')} spp, variant `{r.get('variant')}`:", "",
           *table(["camera", "seconds"],
                  [["`focalsweep` (mitsweep), fixed distance", _f(r.get("focalsweep_s"))],
                   ["`thinlens` (Mitsuba)", _f(r.get("thinlens_s"))],
                   ["`focalsweep`, moving sensor", _f(r.get("sweep_s"))],
                   ["ratio focalsweep / thinlens", _f(r.get("ratio"))]]),
           f"Same seed, sweep collapsed to one distance against `thinlens`: max |Δ| "
           f"{_f(r.get('same_seed_max_abs_diff'))}.", ""]
    gt = r.get("ground_truth") or []
    if gt:
        out += ["The ground truth's sampler, old (independent) against new (stratified):", "",
                *table(["mode", "spp", "method", "render s", "CPU s", "two-seed PSNR dB"],
                       [[g.get("mode"), _f(g.get("spp")), g.get("method"), _f(g.get("render_s")),
                         _f(g.get("cpu_s")), _f(g.get("two_seed_psnr_db"))] for g in gt])]
    mesh = r.get("mesh_accuracy") or []
    if mesh:
        out += ["Mirror meshes against the analytic sphere:", "",
                *table(["mesh", "triangles", "sag error mm", "PSF L1", "render s"],
                       [[m.get("mesh"), _f(m.get("triangles")), _f(m.get("sag_error_mm")),
                         _f(m.get("psf_l1")), _f(m.get("render_s"))] for m in mesh])]
    evt = (r.get("error_vs_time") or {}).get("rows") or []
    if evt:
        out += ["The continuous sweep against fixed planes, the same total spp:", "",
                *table(["spp", "continuous rel. RMSE", "continuous s", "planes", "planes rel. RMSE", "planes s"],
                       [[_f(e.get("spp")), _f(e.get("continuous_rel_rmse")), _f(e.get("continuous_s")),
                         _f(e.get("planes")), _f(e.get("planes_rel_rmse")), _f(e.get("planes_s"))] for e in evt])]
    return out


def deconv_section(r: dict) -> list[str]:
    names = [("polar", "polar Wiener, model NSR"), ("wiener", "`wiener`, discrepancy-principle NSR"),
             ("tv", "`tv`"), ("hyperlaplacian", "`hyperlaplacian`"), ("rl", "`rl`"),
             ("spatial", "spatially varying Wiener"), ("wiener_single", "one IPSF, mitsweep Wiener"),
             ("skimage_wiener", "one IPSF, scikit-image `wiener`")]
    rows = [["blurred input", "–", "–", _f(r.get("blurred_psnr_db"), 4)]]
    for key, label in names:
        m = r.get(key)
        if m:
            rows.append([label, _f(m.get("seconds")), _f(m.get("cpu_seconds")), _f(m.get("psnr_db"), 4)])
    return ["## Deconvolution (`mitsweep bench deconv`)", "",
            f"{r.get('image')}, kernel {r.get('kernel_px')} px; best prior method: "
            f"`{r.get('best_prior_method')}`.", "",
            *table(["method", "wall s", "CPU s", "PSNR dB"], rows)]


def dataset_section(r: dict) -> list[str]:
    d = r.get("dataset") or {}
    res = d.get("resolution") or ["?", "?"]
    rows = [[name, _f(e.get("workers")), _f(e.get("run_s")), _f(e.get("items_per_s")),
             _f(e.get("overhead_per_task_s")), _f(e.get("startup_s")), _f(e.get("identical_to_serial"))]
            for name, e in (r.get("executors") or {}).items()]
    return ["## Datasets (`mitsweep bench dataset`)", "",
            f"{d.get('scenes')} scenes at {res[0]} px, {d.get('items')} items:", "",
            *table(["executor", "workers", "run s", "items/s", "per-task overhead s", "start-up s",
                    "identical to serial"], rows)]


def calibrate_section(r: dict) -> list[str]:
    p = r.get("photo") or {}
    rows = [[name, _f(e.get("seconds")), _f(e.get("centre_error_px")), _f(e.get("radius_error_px"))]
            for name, e in ((k, r.get(k)) for k in ("setup", "free", "skimage")) if e]
    return ["## Calibration (`mitsweep bench calibrate`)", "",
            f"A synthetic {_f(p.get('megapixels'))} MP photo (rim radius {_f(p.get('radius_px'))} px); "
            "`skimage` is scikit-image's Canny + RANSAC circle, handed the annulus to look in:", "",
            *table(["path", "seconds", "centre error px", "radius error px"], rows)]


SECTIONS = {"tracer": tracer_section, "render": render_section, "deconv": deconv_section,
            "dataset": dataset_section, "calibrate": calibrate_section}


def page(run: dict) -> str:
    """The whole page, from one run of ``mitsweep bench all --json``."""
    out = ["# Benchmarks", "",
           "<!-- Generated by scripts/bench_docs.py from docs/benchmarks.json (the output of",
           "     `mitsweep bench all --json`): do not edit; rerun the script. -->", "",
           "`mitsweep bench tracer|render|deconv|dataset|calibrate [--json] [--quick]` prints each "
           "figure with its baseline, run side by side in one process; `mitsweep bench all` runs "
           "every target in one process with the machine's description and each target's wall "
           "time and peak memory. This page is written by `scripts/bench_docs.py` from one such "
           "run, so its figures are that run's, on the machine described below. Compare ratios "
           "between machines, not seconds: a load average above the core count makes wall times "
           "meaningless.", "",
           "<!-- skip: the full benchmark takes many minutes; tests/test_cli_bench.py runs its --quick form -->",
           "```bash",
           ".venv/bin/python scripts/bench_docs.py             # runs `mitsweep bench all --json`, rewrites this page",
           ".venv/bin/python scripts/bench_docs.py --from run.json   # from a saved run",
           "```", ""]
    out += machine_section(run)
    out += targets_section(run)
    for name, section in SECTIONS.items():
        target = run["targets"].get(name) or {}
        if target.get("result"):
            out += section(target["result"])
    return "\n".join(out).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--from", dest="source", type=Path, help="a saved `bench all --json` output")
    ap.add_argument("--quick", action="store_true", help="run the benchmark's smoke sizes")
    ap.add_argument("--page", type=Path, default=PAGE)
    ap.add_argument("--data", type=Path, default=DATA)
    args = ap.parse_args(argv)
    if args.source:
        text = args.source.read_text()
    else:
        cmd = [str(ROOT / ".venv" / "bin" / "mitsweep"), "bench", "all", "--json"] + (["--quick"] if args.quick else [])
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode not in (0, 1):   # 1: a target failed, reported in the JSON
            sys.stderr.write(proc.stderr[-3000:])
            return proc.returncode
        text = proc.stdout
    run = json.loads(text)
    args.data.write_text(json.dumps(run, indent=1, sort_keys=True) + "\n")
    args.page.write_text(page(run))
    print(f"{args.page}: {len(run['targets'])} targets")
    return 0


if __name__ == "__main__":
    sys.exit(main())
