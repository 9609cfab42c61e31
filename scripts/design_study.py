"""Designed against linear sweeps on the paper's three setups: predicted, then measured.

Predicted: for sphere, paraboloid and paraboloid_tilted at 50, 2 and 0.5 lux,
:func:`mitsweep.design.design_sweep` (worst-case objective; the plane bank traced once
per setup, it does not depend on the light level), and both profiles re-scored on a
held-out plane bank (another seed, twice the rays), which shows whether the optimiser
fitted the Monte Carlo noise of its own bank.

Measured (``--measured SETUP LUX``): the dataset's steps for one scene, done here with
the setup's motion replaced by each profile (the pipeline has no motion option yet): the
pinhole ground truth, a sweep render per profile (same spp and seed), the lens's
diffraction, the same sensor noise draw, an IPSF bank traced for each profile
(:func:`mitsweep.tracer.ipsf_bank` with ``motion=``), Wiener deconvolution with the
dataset's NSR rule, PSNR overall and per radius inside the mirror against the ground
truth (as :func:`mitsweep.pipeline.evaluation.evaluate_dataset` scores).

Usage::

    python scripts/design_study.py OUT_DIR [--planes 64] [--rays 65536]
    python scripts/design_study.py OUT_DIR --measured paraboloid 0.5 [--spp 128]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
LUX = (50.0, 2.0, 0.5)


def predicted(out: Path, *, planes: int, rays: int, grid: tuple[int, int],
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
                held = plane_bank(setup, bank.points_uv, bank.depths_mm, bank.edges_mm,
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


def measured(out: Path, name: str, lux: float, *, spp: int, seed: int, planes: int,
             rays: int) -> dict:
    from mitsweep.config import load_setup
    from mitsweep.deconv import (deconvolve, estimate_nsr, paper_fig10_settings, per_radius,
                                 psnr)
    from mitsweep.design import design_sweep
    from mitsweep.io.bank import bank_kernel_size
    from mitsweep.optics import optimal_sweep_range
    from mitsweep.optics.diffraction import add_diffraction
    from mitsweep.optics.motion import MotionProfile
    from mitsweep.optics.pixels import optical_center_px
    from mitsweep.pipeline import NOISE_PIXEL_MM
    from mitsweep.pipeline.tasks import DECONV_PRIOR, white_level
    from mitsweep.render import render_image
    from mitsweep.tracer import ipsf_bank

    setup = load_setup(ROOT / "scenes" / f"{name}.toml")
    noise = paper_fig10_settings(NOISE_PIXEL_MM, lux)["sweep"]
    sweep = optimal_sweep_range(setup)
    t0 = time.perf_counter()
    design = design_sweep(setup, noise=noise, n_planes=planes, rays=rays)
    profiles = {"linear": MotionProfile.linear(sweep.sensor_start, sweep.sensor_end),
                "optimized": design.profile}
    gt_r = render_image(setup, "pinhole", spp=16, seed=seed, aovs=("depth", "mask"),
                        motion=profiles["linear"])
    gt, mask = gt_r.image, gt_r.aovs["mask"]
    level = white_level(gt, mask)
    ref = gt / level
    m = mask > 0.5
    ys, xs = np.nonzero(m)
    cy, cx = optical_center_px(m.shape)
    edges = np.linspace(0.0, float(np.max(np.hypot(ys - cy, xs - cx))) + 0.5, 9)
    kind = "radial" if setup.mirror.is_symmetric else "grid"
    res: dict = {"setup": name, "lux": lux, "spp": spp, "seed": seed,
                 "design": {k: design.report[k] for k in ("linear_worst_mse",
                                                          "optimized_worst_mse",
                                                          "linear_mean_mse",
                                                          "optimized_mean_mse")}}
    for pname, prof in profiles.items():
        r = render_image(setup, "sweep", spp=spp, seed=seed, motion=prof)
        img = add_diffraction(r.image, setup.lens.f_number, setup.sensor.pixel_pitch)
        noisy = noise.apply(np.maximum(img / level, 0.0).astype(np.float32),
                            np.random.default_rng([seed, 7]))
        bank = ipsf_bank(setup, kind=kind, depths=(500.0,), motion=prof,
                         kernel_size=bank_kernel_size(setup.sensor.pixel_pitch))
        nsr = max(estimate_nsr(noisy), noise.nsr(0.5))
        edof = deconvolve(noisy, bank, method="wiener", nsr=nsr, prior=DECONV_PRIOR)
        res[pname] = {"psnr_sweep": psnr(noisy, ref, mask=m), "psnr_edof": psnr(edof, ref, mask=m),
                      "per_radius_psnr_edof": per_radius(edof, ref, edges, mask=m)["psnr"].tolist(),
                      "nsr": nsr}
        logging.info("%s: EDOF PSNR %.2f dB", pname, res[pname]["psnr_edof"])
    res["radius_px_edges"] = edges.tolist()
    res["seconds"] = time.perf_counter() - t0
    (out / f"measured_{name}_{lux:g}lux.json").write_text(json.dumps(res, indent=1))
    return res


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out")
    p.add_argument("--planes", type=int, default=64)
    p.add_argument("--rays", type=int, default=1 << 16)
    p.add_argument("--grid", type=int, nargs=2, default=(5, 5))
    p.add_argument("--radii", type=int, default=9)
    p.add_argument("--measured", nargs=2, metavar=("SETUP", "LUX"))
    p.add_argument("--spp", type=int, default=128)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", stream=sys.stderr)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    if a.measured:
        res = measured(out, a.measured[0], float(a.measured[1]), spp=a.spp, seed=a.seed,
                       planes=a.planes, rays=a.rays)
        print(json.dumps(res, indent=1))
        return 0
    rows = predicted(out, planes=a.planes, rays=a.rays, grid=tuple(a.grid), radii=a.radii)
    text = table(rows)
    (out / "predicted.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
