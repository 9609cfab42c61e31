"""Designed against linear sweeps on the paper's three setups: predicted, then measured.

Predicted: for sphere, paraboloid and paraboloid_tilted at 50, 2 and 0.5 lux,
:func:`mitsweep.design.design_sweep` (worst-case objective; the plane bank traced once
per setup, it does not depend on the light level), and both profiles re-scored on a
held-out plane bank (another seed, twice the rays), which shows whether the optimiser
fitted the Monte Carlo noise of its own bank.

Measured (``--measured SETUP LUX``, or ``--all`` for the nine cases): for each setup,
the linear profile over the optimal range and one designed per light level are written as
motion-profile files, and each runs through the dataset pipeline
(``mitsweep dataset SETUP --motion PROFILE.json``, then ``mitsweep evaluate``): the same
scenes, render seeds and spp, the same light levels in the same order (so the same noise
draw), the same exposure (the noise model's 0.6 s; the profiles share the setup's sweep
exposure), and each profile's own IPSF bank with the dataset's NSR rule. The two
datasets' ground truths are checked to be the same pixels. Per case: EDOF PSNR of both
profiles per scene, the paired differences (mean, standard error, range), per-radius PSNR
and the design's predictions beside them (``measured.md``, ``measured.json``). The
datasets and profiles stay under OUT_DIR: a rerun reuses the finished items and the
designs of the same setup file, planes and rays.

Usage::

    python scripts/design_study.py OUT_DIR [--planes 64] [--rays 65536]
    python scripts/design_study.py OUT_DIR --measured paraboloid 0.5 [--scenes 3]
    python scripts/design_study.py OUT_DIR --all [--scenes 3] [--family room|procedural]
        [--spp P F S ST] [--resolution N]
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
LUX = (50.0, 2.0, 0.5)


def predicted(out: Path, *, planes: int, rays: int, grid: tuple[int, int] | None,
              radii: int) -> list[dict]:
    from mitsweep.config import load_setup
    from mitsweep.deconv import paper_fig10_settings
    from mitsweep.design import design_sweep, plane_bank, wiener_model
    from mitsweep.optics.motion_file import save_motion_file
    from mitsweep.pipeline import NOISE_PIXEL_MM

    rows = []
    for name in SETUPS:
        setup = load_setup(ROOT / "scenes" / f"{name}.toml")
        bank = held = None
        for lux in LUX:
            noise = paper_fig10_settings(NOISE_PIXEL_MM, lux)["sweep"]
            t0 = time.perf_counter()
            d = design_sweep(setup, noise=noise, n_planes=planes, rays=rays, grid=grid,
                             n_radii=radii, bank=bank)
            bank = d.bank
            if held is None:  # held-out bank: another seed, twice the rays
                held = plane_bank(setup, bank.points_uv, bank.depths, bank.edges,
                                  reference_sensor_distance=bank.reference_sensor_distance,
                                  rays=2 * rays, seed=1000)
            n_px = float(np.sqrt(np.prod(setup.sensor.resolution)))
            hm = wiener_model(held.kernels, noise, n_px=n_px)
            h_lin, h_opt = hm.mse(d.tau_linear), hm.mse(d.tau)
            r = d.report
            c = r["certificate"]
            b = c["brute_force"] or {}
            rows.append({
                "setup": name, "lux": lux,
                "linear_worst_mse": r["linear_worst_mse"],
                "optimized_worst_mse": r["optimized_worst_mse"],
                "linear_mean_mse": r["linear_mean_mse"],
                "optimized_mean_mse": r["optimized_mean_mse"],
                "linear_v_avg": r["linear_v_avg"], "optimized_v_avg": r["optimized_v_avg"],
                "linear_worst_at": r["linear_worst_at"],
                "optimized_worst_at": r["optimized_worst_at"],
                "lower_bound": c["lower_bound"], "relative_gap": c["relative_gap"],
                "without_acceleration": c["without_acceleration_value"],
                "starts": c["starts"],
                "brute_force": {k: b.get(k) for k in ("feasible_points", "lattice_best",
                                                      "local_value", "agrees",
                                                      "same_optimum")},
                "heldout_linear_worst_mse": float(h_lin.max()),
                "heldout_optimized_worst_mse": float(h_opt.max()),
                "heldout_linear_mean_mse": float(h_lin.mean()),
                "heldout_optimized_mean_mse": float(h_opt.mean()),
                "velocity_mm_s": r["velocity_mm_s"],
                "seconds": time.perf_counter() - t0, "points": len(bank.points_uv),
                "depths_mm": r["depths_mm"],
            })
            save_motion_file(out / f"{name}_{lux:g}lux.json", d.profile,
                             exposure_s=d.exposure_s,
                             provenance={"generator": "scripts/design_study.py",
                                         "setup": name, "lux": lux, "planes": planes,
                                         "rays": rays})
            logging.info("%s %g lux: worst %.4g -> %.4g (%.1f s)", name, lux,
                         r["linear_worst_mse"], r["optimized_worst_mse"], rows[-1]["seconds"])
            (out / "predicted.json").write_text(json.dumps(rows, indent=1))
    return rows


def table(rows: list[dict]) -> str:
    db = lambda m: 10 * np.log10(1 / m)  # noqa: E731
    head = ("| setup | lux | worst MSE lin → opt (dB) | mean MSE lin → opt (dB) | V_avg lin → "
            "opt | worst at (r mm, l mm) lin / opt | held-out worst lin → opt (dB) | "
            "bound gap | brute force |")
    lines = [head, "|" + "---|" * 9]
    for r in rows:
        wl, wo = r["linear_worst_at"], r["optimized_worst_at"]
        bf = r["brute_force"]
        lines.append(
            f"| {r['setup']} | {r['lux']:g} | {db(r['linear_worst_mse']):.2f} → "
            f"{db(r['optimized_worst_mse']):.2f} | {db(r['linear_mean_mse']):.2f} → "
            f"{db(r['optimized_mean_mse']):.2f} | {r['linear_v_avg']:.3g} → "
            f"{r['optimized_v_avg']:.3g} | ({wl['radius_mm']:.2f}, {wl['depth_mm']:g}) / "
            f"({wo['radius_mm']:.2f}, {wo['depth_mm']:g}) | "
            f"{db(r['heldout_linear_worst_mse']):.2f} → "
            f"{db(r['heldout_optimized_worst_mse']):.2f} | {100 * r['relative_gap']:.0f} % | "
            f"{'agrees' if bf['agrees'] else 'DISAGREES'}"
            f"{', same optimum' if bf['same_optimum'] else ''} |")
    return "\n".join(lines) + "\n"


def setup_file(name: str, out: Path, resolution: int | None) -> Path:
    """The scene file of setup ``name``: as it is, or (``resolution``) an N × N sensor of
    the same size (the pitch scaled), written under ``out/setups``."""
    src = ROOT / "scenes" / f"{name}.toml"
    if resolution is None:
        return src
    import dataclasses

    from mitsweep.config import load_setup, setup_to_toml

    s = load_setup(src)
    n = int(resolution)
    pitch = s.sensor.pixel_pitch * s.sensor.resolution[0] / n
    s = dataclasses.replace(s, name=f"{s.name}_{n}px",
                            sensor=dataclasses.replace(s.sensor, pixel_pitch=pitch,
                                                       resolution=(n, n)))
    path = out / "setups" / f"{name}_{n}px.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(setup_to_toml(s, header=f"{src.name} at {n}x{n} px (same sensor size): "
                                            f"scripts/design_study.py"), encoding="utf-8")
    return path


def _mitsweep(args: list[str]) -> str:
    """Run ``mitsweep ARGS`` in a child process (nice as this one); its stdout."""
    cmd = [sys.executable, "-c", "import sys; from mitsweep.cli.main import main; "
           "sys.exit(main(sys.argv[1:]))", *args]
    logging.info("$ mitsweep %s", " ".join(args))
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"mitsweep {args[0]} failed (exit {proc.returncode})")
    return proc.stdout


def designed_profiles(setup_path: Path, name: str, luxes: list[float], out: Path, *,
                      planes: int, rays: int, tables_only: bool = False,
                      restoration: str = "matched", objective: str = "worst",
                      deploy_nsr: dict | None = None, grid: tuple[int, int] | None = None,
                      radii: int = 9) -> dict:
    """The linear profile and one designed per light level (worst-case objective, as
    ``mitsweep design-sweep`` by default), as motion-profile files under ``out``, and the
    designs' reports. A profile whose file and report exist from an earlier run with the
    same setup file, planes and rays is read, not designed again (``tables_only``: must
    be). ``restoration="deployed"``: the design's objective is the deployed pipeline's
    (:func:`mitsweep.design.design_sweep`'s ``restoration``), with ``deploy_nsr[lux]``,
    the NSR the linear dataset's restorations used at that light level; ``objective``
    the mean or the worst case."""
    from mitsweep.config import load_setup
    from mitsweep.deconv import paper_fig10_settings
    from mitsweep.design import design_sweep
    from mitsweep.optics import optimal_sweep_range
    from mitsweep.optics.motion import MotionProfile
    from mitsweep.optics.motion_file import save_motion_file
    from mitsweep.pipeline import NOISE_PIXEL_MM

    setup = load_setup(setup_path)
    sweep = optimal_sweep_range(setup)
    key = {"setup_file": setup_path.read_text(encoding="utf-8"), "planes": planes, "rays": rays}
    if restoration != "matched" or objective != "worst":
        key.update(restoration=restoration, objective=objective)
    if objective == "mean":   # the mean over the image (points weighted by their area)
        key.update(mean="image area")
    if grid is not None or radii != 9:   # not design_sweep's default field points
        key.update(grid=None if grid is None else list(grid), radii=radii)
    if restoration == "deployed" and not setup.mirror.is_symmetric:
        key.update(field="grid bank nodes and cell centres, blended filters")
    out.mkdir(parents=True, exist_ok=True)
    linear = out / f"{name}_linear.json"
    save_motion_file(linear, MotionProfile.linear(sweep.sensor_start, sweep.sensor_end),
                     exposure_s=float(sweep.exposure_s),
                     provenance={"generator": "scripts/design_study.py", "setup": name,
                                 "profile": "linear over the optimal range"})
    res = {"linear": linear, "designs": {}}
    bank = None
    for lux in luxes:
        path, rep = out / f"{name}_{lux:g}lux.json", out / f"{name}_{lux:g}lux_design.json"
        if path.is_file() and rep.is_file():
            old = json.loads(rep.read_text(encoding="utf-8"))
            if {k: v for k, v in old.get("key", {}).items() if k != "deploy_nsr"} == key and (
                    restoration != "deployed"
                    or (old["key"].get("deploy_nsr") or {}).get("nsr")
                    == (deploy_nsr or {}).get(lux)):
                logging.info("%s %g lux: profile from the earlier run (%s)", name, lux, path)
                res["designs"][lux] = (path, old["report"])
                continue
        if tables_only:
            raise SystemExit(f"{rep}: no design of this setup, planes and rays (run without "
                             f"--tables-only first)")
        noise = paper_fig10_settings(NOISE_PIXEL_MM, lux)["sweep"]
        if restoration == "deployed":
            nsr = (deploy_nsr or {}).get(lux)
            d = design_sweep(setup, noise=noise, n_planes=planes, rays=rays, bank=bank,
                             restoration="deployed", objective=objective, deploy_nsr=nsr,
                             grid=None if grid is None else tuple(grid), n_radii=radii)
        else:
            d = design_sweep(setup, noise=noise, n_planes=planes, rays=rays, bank=bank,
                             objective=objective, grid=None if grid is None else tuple(grid),
                             n_radii=radii)
        bank = d.bank
        save_motion_file(path, d.profile, exposure_s=d.exposure_s,
                         provenance={"generator": "scripts/design_study.py", "setup": name,
                                     "lux": lux, "planes": planes, "rays": rays})
        report = dict(d.report, points_uv_mm=d.points_uv.tolist())
        rep.write_text(json.dumps({"key": {**key, "deploy_nsr": report.get("deploy")},
                                   "report": report}), encoding="utf-8")
        logging.info("%s %g lux: designed, predicted worst %.2f -> %.2f dB", name, lux,
                     report["linear_worst_psnr_db"], report["optimized_worst_psnr_db"])
        res["designs"][lux] = (path, report)
    return res


def _predicted_per_bin(report: dict, edges_px: np.ndarray, pitch_mm: float) -> dict:
    """The design's predicted MSE per field point, mean over its depths, gathered into
    the evaluation's radial bins (pixels from the optical axis): PSNR per bin, None for a
    bin without a design point (beyond the FOV's edge)."""
    r_px = np.hypot(*np.asarray(report["points_uv_mm"]).T) / pitch_mm
    out = {}
    for which in ("linear", "optimized"):
        mse = np.asarray(report["per_point"][f"{which}_mse"]).mean(axis=0)
        b = np.clip(np.digitize(r_px, edges_px) - 1, 0, len(edges_px) - 2)
        out[which] = [float(10 * np.log10(1 / mse[b == k].mean())) if np.any(b == k) else None
                      for k in range(len(edges_px) - 1)]
    return out


def _same_ground_truth(a: Path, b: Path, scenes: int) -> bool:
    """Whether two datasets' ground truths (RGB, depth and mask) are the same pixels
    (their files differ in the motion recorded in the metadata)."""
    from mitsweep.pipeline.tasks import read_rgb

    for i in range(scenes):
        ca, cb = (read_rgb(d / f"scene_{i:03d}" / "pinhole.exr")[1] for d in (a, b))
        if ca.keys() != cb.keys() or any(not np.array_equal(ca[k], cb[k]) for k in ca):
            return False
    return True


def measured_cases(out: Path, cases: list[tuple[str, float]], *, scenes: int, seed: int,
                   family: str, spp: list[str] | None, resolution: int | None, planes: int,
                   rays: int, tables_only: bool = False, restoration: str = "matched",
                   objective: str = "worst", grid: tuple[int, int] | None = None,
                   radii: int = 9) -> list[dict]:
    """Datasets rendered with the linear and each designed profile, deconvolved with their
    own banks and scored (``mitsweep dataset --motion`` and ``mitsweep evaluate``); one
    row per (setup, lux) case.

    Both profiles of a setup run through the same dataset options: the same scenes and
    render seeds, and the same light levels in the same order (the noise draw of scene
    ``i`` at the ``j``-th level is seeded ``[seed, i, j]``), so each pair of EDOF images
    differs by the profile alone. Their ground truths must be the same images (same
    span, so the same reference grid): checked pixel for pixel. ``tables_only``: no
    design or dataset is made; the rows from an earlier run's designs and evaluations."""
    levels = list(LUX) + sorted({lux for _, lux in cases} - set(LUX))
    rows = []
    for name in dict.fromkeys(n for n, _ in cases):
        luxes = [lux for n, lux in cases if n == name]
        sfile = setup_file(name, out, resolution)
        common = [str(sfile), "--scenes", str(scenes), "--seed", str(seed), "--family",
                  family, "--lux", *(f"{x:g}" for x in levels)]
        if spp:
            common += ["--spp", *spp]
        evals, dirs, seconds = {}, {}, {}
        deploy_nsr = None
        if restoration == "deployed":
            # the deployed NSR is the linear dataset's (its restorations' weight rule),
            # so the linear profile's dataset comes first
            from mitsweep.optics import optimal_sweep_range
            from mitsweep.optics.motion import MotionProfile
            from mitsweep.optics.motion_file import save_motion_file
            from mitsweep.config import load_setup as _load

            sw = optimal_sweep_range(_load(sfile))
            lin_file = out / "profiles" / f"{name}_linear.json"
            lin_file.parent.mkdir(parents=True, exist_ok=True)
            save_motion_file(lin_file, MotionProfile.linear(sw.sensor_start, sw.sensor_end),
                             exposure_s=float(sw.exposure_s),
                             provenance={"generator": "scripts/design_study.py", "setup": name,
                                         "profile": "linear over the optimal range"})
            d = out / "datasets" / name / "linear"
            if not tables_only:
                _mitsweep(["dataset", *common, "--out", str(d), "--motion", str(lin_file)])
            deploy_nsr = {lux: float(np.mean(_used_nsr(d, lux, scenes))) for lux in luxes}
        t0 = time.perf_counter()
        prof = designed_profiles(sfile, name, luxes, out / "profiles", planes=planes,
                                 rays=rays, tables_only=tables_only, restoration=restoration,
                                 objective=objective, deploy_nsr=deploy_nsr, grid=grid,
                                 radii=radii)
        t_design = time.perf_counter() - t0
        for tag, mfile in [("linear", prof["linear"]),
                           *((f"opt_{lux:g}lux", prof["designs"][lux][0]) for lux in luxes)]:
            d = out / "datasets" / name / tag
            t1 = time.perf_counter()
            if tables_only:
                evals[tag] = json.loads((d / "evaluation.json").read_text(encoding="utf-8"))
            else:
                _mitsweep(["dataset", *common, "--out", str(d), "--motion", str(mfile)])
                evals[tag] = json.loads(_mitsweep(["evaluate", str(d), "--json", "--out",
                                                   str(d / "evaluation.json")]))
            dirs[tag] = d
            seconds[tag] = None if tables_only else time.perf_counter() - t1
        from mitsweep.config import load_setup

        pitch = load_setup(sfile).sensor.pixel_pitch
        for lux in luxes:
            tag = f"opt_{lux:g}lux"
            if not _same_ground_truth(dirs["linear"], dirs[tag], scenes):
                raise SystemExit(f"{name}: the ground truths of {tag} and linear differ "
                                 f"(the profiles' reference grids do not agree)")
            rows.append(case_row(name, lux, evals["linear"], evals[tag],
                                 prof["designs"][lux][1], pitch,
                                 seconds={"design_s": None if tables_only else t_design,
                                          "linear_dataset_s": seconds["linear"],
                                          "optimized_dataset_s": seconds[tag]}))
            logging.info("%s %g lux: EDOF %.2f -> %.2f dB (paired %+.2f +- %.2f)", name, lux,
                         rows[-1]["linear"]["psnr_mean"], rows[-1]["optimized"]["psnr_mean"],
                         rows[-1]["paired_db"]["mean"], rows[-1]["paired_db"]["se"])
        (out / "measured.json").write_text(json.dumps(
            {"options": {"scenes": scenes, "seed": seed, "family": family,
                         "restoration": restoration, "objective": objective,
                         "spp": spp or "dataset default", "resolution": resolution,
                         "planes": planes, "rays": rays, "light_levels": levels},
             "cases": rows}, indent=1), encoding="utf-8")
    return rows


def case_row(name: str, lux: float, ev_lin: dict, ev_opt: dict, report: dict,
             pitch_mm: float, *, seconds: dict) -> dict:
    """One case: EDOF and noisy-sweep PSNR per scene of both profiles, paired differences
    (mean, standard error, range), per-radius PSNR (mean over scenes), and the design's
    predictions beside them."""
    key, raw = f"edof_{lux:g}lux", f"sweep_{lux:g}lux"
    scenes = sorted(ev_lin["scenes"])
    row: dict = {"setup": name, "lux": lux, "scenes": len(scenes)}
    for which, ev in (("linear", ev_lin), ("optimized", ev_opt)):
        s = [ev["scenes"][k] for k in scenes]
        ps = np.array([x[key]["psnr"] for x in s])
        pr = np.array([x[key]["per_radius"]["psnr"] for x in s])
        row[which] = {"psnr": ps.tolist(), "psnr_mean": float(ps.mean()),
                      "ssim_mean": float(np.mean([x[key]["ssim"] for x in s])),
                      "sweep_psnr_mean": float(np.mean([x[raw]["psnr"] for x in s])),
                      "noiseless_edof_psnr_mean": float(np.mean([x["edof"]["psnr"] for x in s])),
                      "per_depth_band_psnr": np.nanmean(
                          [np.asarray(x[key]["per_depth_band"]["psnr"], dtype=float)
                           for x in s], axis=0).tolist(),
                      "per_radius_psnr": pr.mean(axis=0).tolist(),
                      "per_radius_psnr_scenes": pr.tolist()}
    d = np.array(row["optimized"]["psnr"]) - np.array(row["linear"]["psnr"])
    se = float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1 else float("nan")
    row["paired_db"] = {"per_scene": d.tolist(), "mean": float(d.mean()), "se": se,
                        "min": float(d.min()), "max": float(d.max())}
    pr_d = (np.array(row["optimized"]["per_radius_psnr_scenes"])
            - np.array(row["linear"]["per_radius_psnr_scenes"]))
    row["per_radius_paired_db"] = pr_d.mean(axis=0).tolist()
    row["per_radius_paired_se"] = (pr_d.std(axis=0, ddof=1) / np.sqrt(len(scenes))).tolist() \
        if len(scenes) > 1 else [float("nan")] * pr_d.shape[1]
    s0 = ev_lin["scenes"][scenes[0]]
    # evaluate's stdout writes the open band's end as null, its --out file as Infinity
    row["depth_band_edges_mm"] = [float("inf") if x is None else float(x)
                                  for x in s0[key]["per_depth_band"]["edges_mm"]]
    row["depth_band_pixels"] = s0[key]["per_depth_band"]["pixels"]
    edges = np.asarray(s0[key]["per_radius"]["edges_px"], dtype=float)
    row["radius_px_edges"] = edges.tolist()
    worst_lin = int(np.argmin(row["linear"]["per_radius_psnr"]))
    row["worst_bin"] = {"bin": worst_lin, "linear": row["linear"]["per_radius_psnr"][worst_lin],
                        "optimized": row["optimized"]["per_radius_psnr"][worst_lin],
                        "optimized_worst": float(np.min(row["optimized"]["per_radius_psnr"]))}
    row["predicted"] = {k: report[k] for k in ("linear_worst_psnr_db", "optimized_worst_psnr_db",
                                               "linear_mean_psnr_db", "optimized_mean_psnr_db",
                                               "linear_image_mean_psnr_db",
                                               "optimized_image_mean_psnr_db")
                        if k in report}
    row["predicted"]["per_radius_psnr"] = _predicted_per_bin(report, edges, pitch_mm)
    row["predicted"]["tau_range"] = [float(min(report["tau"])), float(max(report["tau"]))]
    row["predicted"]["planes"] = report["planes"]
    row["seconds"] = seconds
    return row


def _used_nsr(dataset: Path, lux: float, scenes: int) -> list[float]:
    """The NSR each scene's EDOF image at ``lux`` was deconvolved with (its metadata)."""
    from mitsweep.io import read_exr

    return [float(read_exr(dataset / f"scene_{i:03d}" / f"edof_{lux:g}lux.exr")[1]["nsr"])
            for i in range(scenes)]


def deployed_prediction(setup, report: dict, noise, *, nsr_used: float,
                        kernel_depth_mm: float = 500.0) -> dict:
    """The design's Wiener model with the deconvolution the dataset runs, for the linear
    and the designed τ: per field point one kernel, the IPSF at ``kernel_depth_mm`` (the
    dataset's bank depth), applied to the image of every depth, with the NSR the dataset
    used. The MSE of a filter ``G`` on an image blurred by ``H_l`` is

    ``Σ_f w_f (|1 − G H_l|² S(f) + |G|² σ²)``, ``S = σ²/R`` (the 1/f² prior),
    ``G = conj(H_b) / (|H_b|² + R nsr_used/nsr)``;

    with ``H_b = H_l`` and the model's NSR it is the design's MSE (checked here to 0.1 %,
    on the plane bank traced again with the design's seeds). Returns worst and mean PSNR (dB)
    of: ``matched`` (the design's), ``one_kernel`` (the 500-mm kernel, the model's NSR)
    and ``deployed`` (that kernel and the used NSR)."""
    from mitsweep.design import plane_bank, wiener_model
    from mitsweep.optics import optimal_sweep_range
    from mitsweep.optics.motion import MotionProfile
    from mitsweep.optics.reference import reference_geometry

    depths = np.asarray(report["depths_mm"], dtype=float)
    if kernel_depth_mm not in depths:
        raise ValueError(f"the design has no depth {kernel_depth_mm:g} mm")
    edges = np.asarray(report["edges_mm"], dtype=float)
    sweep = optimal_sweep_range(setup)
    geom = reference_geometry(setup, sweep=sweep,
                              motion=MotionProfile.linear(edges[0], edges[-1]))
    pb = report["plane_bank"]
    bank = plane_bank(setup, report["points_uv_mm"], depths, edges,
                      reference_sensor_distance=geom.sensor_distance, rays=pb["rays"],
                      kernel_size=pb["kernel_size"], seed=pb["seed"],
                      sub_planes=pb["sub_planes"])
    n_px = float(np.sqrt(np.prod(setup.sensor.resolution)))
    model = wiener_model(bank.kernels, noise, n_fft=report["n_fft"], n_px=n_px)
    D, P = len(depths), len(report["points_uv_mm"])
    b = int(np.flatnonzero(depths == kernel_depth_mm)[0])
    sigma2, w, R = model.noise_var, model.weight, model.reg
    S = sigma2 / R
    scale = nsr_used / float(noise.nsr(0.5))
    taus = {"linear": np.full(len(edges) - 1, 1.0 / (len(edges) - 1)),
            "optimized": np.asarray(report["tau"], dtype=float)}
    out: dict = {"nsr_model": float(noise.nsr(0.5)), "nsr_used": nsr_used,
                 "kernel_depth_mm": kernel_depth_mm}
    db = lambda m: float(10 * np.log10(1 / m))  # noqa: E731
    for which, tau in taus.items():
        kr, ki = model._transfer(tau)
        H = (kr + 1j * ki).reshape(D, P, -1)
        mse = {}
        for kind, hb, r in (("matched", H, R), ("one_kernel", H[b][None], R),
                            ("deployed", H[b][None], R * scale)):
            G = np.conj(hb) / (np.abs(hb) ** 2 + r)
            mse[kind] = ((np.abs(1 - G * H) ** 2 * S + np.abs(G) ** 2 * sigma2) * w).sum(-1)
        ref = np.asarray(report["per_point"][f"{which}_mse"])
        # same seeds and tracer revision: the plane bank is traced again bit for bit
        # (tests/test_design_determinism.py), so only the order of NumPy's sums differs;
        # a design reused from another tracer revision differs at ~1e-4 and is refused
        if not np.allclose(mse["matched"], ref, rtol=1e-6, atol=0):
            raise SystemExit(f"{setup.name}: the plane bank traced again does not give the "
                             f"design's MSE (max rel. diff "
                             f"{np.max(np.abs(mse['matched'] / ref - 1)):.2g})")
        out[which] = {kind: {"worst_db": db(m.max()), "mean_db": db(m.mean()),
                             "per_depth_mean_db": [db(x) for x in m.mean(axis=1)]}
                      for kind, m in mse.items()}
    out["depths_mm"] = depths.tolist()
    return out


def diagnose(out: Path, rows: list[dict], *, resolution: int | None) -> None:
    """Add to each row the design's model with the dataset's deconvolution
    (:func:`deployed_prediction`)."""
    from mitsweep.config import load_setup
    from mitsweep.deconv import paper_fig10_settings
    from mitsweep.pipeline import NOISE_PIXEL_MM

    for r in rows:
        name, lux = r["setup"], r["lux"]
        setup = load_setup(setup_file(name, out, resolution))
        report = json.loads((out / "profiles" / f"{name}_{lux:g}lux_design.json")
                            .read_text(encoding="utf-8"))["report"]
        noise = paper_fig10_settings(NOISE_PIXEL_MM, lux)["sweep"]
        used = {w: _used_nsr(out / "datasets" / name / t, lux, r["scenes"])
                for w, t in (("linear", "linear"), ("optimized", f"opt_{lux:g}lux"))}
        nsr = float(np.mean(used["linear"] + used["optimized"]))
        r["diagnosis"] = deployed_prediction(setup, report, noise, nsr_used=nsr)
        r["diagnosis"]["nsr_used_per_scene"] = used
        d = r["diagnosis"]
        logging.info("%s %g lux: predicted mean gain matched %+.2f, one kernel %+.2f, "
                     "deployed %+.2f dB", name, lux,
                     *(d["optimized"][k]["mean_db"] - d["linear"][k]["mean_db"]
                       for k in ("matched", "one_kernel", "deployed")))


def diagnosis_table(rows: list[dict]) -> str:
    """Markdown: predicted gains (opt − lin, dB) of the design's model, with one kernel
    per point (the dataset's 500-mm bank), and with the NSR the dataset used; measured."""
    lines = ["| setup | lux | NSR model / used | worst gain: matched, one kernel, deployed "
             "(dB) | mean gain: matched, one kernel, deployed (dB) | measured paired Δ (dB) |",
             "|" + "---|" * 6]
    for r in rows:
        d = r.get("diagnosis")
        if d is None:
            continue
        g = {k: [d["optimized"][m][k] - d["linear"][m][k]
                 for m in ("matched", "one_kernel", "deployed")] for k in ("worst_db", "mean_db")}
        lines.append(f"| {r['setup']} | {r['lux']:g} | {d['nsr_model']:.3g} / "
                     f"{d['nsr_used']:.3g} | "
                     + ", ".join(f"{x:+.2f}" for x in g["worst_db"]) + " | "
                     + ", ".join(f"{x:+.2f}" for x in g["mean_db"]) + " | "
                     f"{r['paired_db']['mean']:+.2f} ± {r['paired_db']['se']:.2f} |")
    return "\n".join(lines) + "\n"


def measured_table(rows: list[dict]) -> str:
    """Markdown: per case the predicted gains, the measured EDOF PSNR of both profiles
    (mean over scenes), the paired difference and the worst radial bin; then the
    per-radius differences, measured against predicted."""
    f = lambda x: "–" if x is None else f"{x:+.2f}"  # noqa: E731
    lines = ["| setup | lux | predicted worst / mean gain (dB) | EDOF PSNR lin → opt (dB) | "
             "paired Δ ± SE (dB) [min, max] | worst radial bin lin → opt (dB) | "
             "noisy sweep lin → opt (dB) | noiseless EDOF lin → opt (dB) |", "|" + "---|" * 8]
    # the mean the designs minimised: over the image where the reports have it
    mean = "image_mean" if rows and "linear_image_mean_psnr_db" in rows[0]["predicted"] \
        else "mean"
    for r in rows:
        p, w, dd = r["predicted"], r["worst_bin"], r["paired_db"]
        lines.append(
            f"| {r['setup']} | {r['lux']:g} | "
            f"{f(p['optimized_worst_psnr_db'] - p['linear_worst_psnr_db'])} / "
            f"{f(p[f'optimized_{mean}_psnr_db'] - p[f'linear_{mean}_psnr_db'])} | "
            f"{r['linear']['psnr_mean']:.2f} → {r['optimized']['psnr_mean']:.2f} | "
            f"{dd['mean']:+.2f} ± {dd['se']:.2f} [{dd['min']:+.2f}, {dd['max']:+.2f}] | "
            f"{w['linear']:.2f} → {w['optimized']:.2f} (bin {w['bin'] + 1}) | "
            f"{r['linear']['sweep_psnr_mean']:.2f} → {r['optimized']['sweep_psnr_mean']:.2f} | "
            f"{r['linear']['noiseless_edof_psnr_mean']:.2f} → "
            f"{r['optimized']['noiseless_edof_psnr_mean']:.2f} |")
    n = len(rows[0]["per_radius_paired_db"]) if rows else 0
    lines += ["", "Per radial bin (1 = centre): measured Δ opt − lin, mean over scenes "
              "(predicted Δ, mean over depths; – where no design point lies in the bin):", "",
              "| setup | lux | " + " | ".join(f"bin {k + 1}" for k in range(n)) + " |",
              "|" + "---|" * (n + 2)]
    for r in rows:
        pp = r["predicted"]["per_radius_psnr"]
        cells = []
        for k in range(n):
            pl, po = pp["linear"][k], pp["optimized"][k]
            pred = "–" if pl is None else f"{po - pl:+.2f}"
            cells.append(f"{r['per_radius_paired_db'][k]:+.2f} ({pred})")
        lines.append(f"| {r['setup']} | {r['lux']:g} | " + " | ".join(cells) + " |")
    if rows:
        e = rows[0]["depth_band_edges_mm"]
        bands = [f"{e[k]:g}–{e[k + 1]:g} mm" for k in range(len(e) - 1)]
        lines += ["", "Per depth band: EDOF PSNR lin → opt (dB), mean over scenes:", "",
                  "| setup | lux | " + " | ".join(bands) + " |", "|" + "---|" * (len(e) + 1)]
        for r in rows:
            cells = [f"{a:.2f} → {b:.2f}" for a, b in zip(r["linear"]["per_depth_band_psnr"],
                                                         r["optimized"]["per_depth_band_psnr"])]
            lines.append(f"| {r['setup']} | {r['lux']:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--planes", type=int, default=64)
    p.add_argument("--rays", type=int, default=1 << 16)
    p.add_argument("--grid", type=int, nargs=2, default=None)
    p.add_argument("--radii", type=int, default=9)
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--measured", nargs=2, metavar=("SETUP", "LUX"),
                      help="measure one case: datasets with the linear and the designed "
                           "profile")
    mode.add_argument("--all", action="store_true",
                      help="measure the nine cases (3 setups x 50, 2, 0.5 lux)")
    p.add_argument("--setups", nargs="+", choices=SETUPS, default=list(SETUPS),
                   help="with --all: these setups only")
    p.add_argument("--scenes", type=int, default=3, help="scenes per case (default 3)")
    p.add_argument("--family", choices=("room", "procedural"), default="room")
    p.add_argument("--spp", nargs=4, metavar=("PINHOLE", "FOCUSED", "SWEEP", "STOPPED"),
                   help="samples per pixel (default: the dataset's, 16 64 128 64)")
    p.add_argument("--resolution", type=int,
                   help="render an N x N sensor of the same size (default: the setup's)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--restoration", choices=("matched", "deployed"), default="matched",
                   help="the design's objective: each depth restored with its own IPSF "
                        "(matched, default) or as the dataset restores (deployed: the "
                        "500-mm kernels and the linear dataset's NSR; falls back to "
                        "linear where no profile beats it)")
    p.add_argument("--objective", choices=("worst", "mean"), default="worst")
    p.add_argument("--diagnose", action="store_true",
                   help="with --measured or --all: also the design's model with the "
                        "dataset's deconvolution (one 500-mm kernel per point, the NSR it "
                        "used); traces each design's plane bank again")
    p.add_argument("--tables-only", action="store_true",
                   help="with --measured or --all: design and render nothing, the tables "
                        "from an earlier run's designs and evaluations in OUT_DIR")
    a = p.parse_args(argv)
    if a.measured:
        if a.measured[0] not in SETUPS:
            p.error(f"--measured: setup must be one of {', '.join(SETUPS)}, got "
                    f"{a.measured[0]!r}")
        try:
            ok = float(a.measured[1]) > 0
        except ValueError:
            ok = False
        if not ok:
            p.error(f"--measured: LUX must be a number > 0, got {a.measured[1]!r}")
    if a.scenes < 1:
        p.error(f"--scenes: need at least 1, got {a.scenes}")
    if a.resolution is not None and a.resolution < 16:
        p.error(f"--resolution: need at least 16 px, got {a.resolution}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.measured or a.all:
        cases = [(a.measured[0], float(a.measured[1]))] if a.measured else \
            [(n, lux) for n in a.setups for lux in LUX]
        rows = measured_cases(out, cases, scenes=a.scenes, seed=a.seed, family=a.family,
                              spp=a.spp, resolution=a.resolution, planes=a.planes,
                              rays=a.rays, tables_only=a.tables_only,
                              restoration=a.restoration, objective=a.objective,
                              grid=None if a.grid is None else tuple(a.grid), radii=a.radii)
        text = measured_table(rows)
        if a.diagnose:
            diagnose(out, rows, resolution=a.resolution)
            text += ("\nThe design's model with the dataset's deconvolution (predicted gain "
                     "opt − lin):\n\n" + diagnosis_table(rows))
            js = json.loads((out / "measured.json").read_text(encoding="utf-8"))
            js["cases"] = rows
            (out / "measured.json").write_text(json.dumps(js, indent=1), encoding="utf-8")
        (out / "measured.md").write_text(text, encoding="utf-8")
        print(text)
        return 0
    rows = predicted(out, planes=a.planes, rays=a.rays,
                     grid=None if a.grid is None else tuple(a.grid), radii=a.radii)
    text = table(rows)
    (out / "predicted.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
