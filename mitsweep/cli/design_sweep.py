"""``mitsweep design-sweep``: an optimised sensor-motion profile for a setup and light level.

The objective, the constraints and the certificate are stated in :mod:`mitsweep.design`.
The profile is written as a motion-profile file (:mod:`mitsweep.optics.motion_file`) that
``ipsf``, ``render``, ``dataset`` and ``capture`` run with ``--motion``. A thin wrapper
over :func:`mitsweep.workflows.design_motion_profile`.
"""

from __future__ import annotations

import argparse
import math
import sys

from ..workflows.design_sweep import design_motion_profile
from .common import depth_mm, illuminance_lux, number_type, positive_int, print_json

NAME = "design-sweep"
HELP = ("design the sensor's time profile over the sweep (not only its range) that "
        "minimises the predicted Wiener restoration error, and write it as a motion file")


_distance = number_type(float, lambda x: math.isfinite(x) and x > 0,
                        "a sensor distance in mm", "a finite sensor distance > 0 mm",
                        "sensor_distance")
_nsr = number_type(float, lambda x: math.isfinite(x) and x > 0, "an NSR",
                   "a finite NSR > 0", "nsr")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (see scenes/)")
    p.add_argument("--lux", type=illuminance_lux, default=50.0,
                   help="scene illuminance of the noise model, lux (50); the sensor is the "
                        "dataset's (paper Fig. 10 sweep settings: F2.8, 0.6 s, ISO 100, "
                        "6.4 um pixels)")
    p.add_argument("--objective", choices=("worst", "mean"), default="worst",
                   help="minimise the worst (default) or the mean predicted MSE over field "
                        "points x depths")
    p.add_argument("--planes", type=positive_int, default=64,
                   help="bins N of sensor distance over the span (64; at least 8)")
    p.add_argument("--span-mm", type=_distance, nargs=2, metavar=("A", "B"),
                   help="sweep from sensor distance A to B, mm (default: the optimal range); "
                        "the exposure stays the setup's over the optimal range")
    p.add_argument("--out", required=True, metavar="PROFILE.json",
                   help="motion-profile file to write")
    p.add_argument("--radii", type=positive_int, default=9,
                   help="field radii from the centre to the FOV's edge (9; untilted mirrors)")
    p.add_argument("--grid", type=positive_int, nargs=2, default=None, metavar=("ROWS", "COLS"),
                   help="tilted mirrors: grid of field points over the sensor (default 5 5); "
                        "with --restoration deployed, the grid bank restoring the images "
                        "(default the datasets', 11 11 for the tilted paraboloid), its nodes "
                        "and cell centres the field points")
    p.add_argument("--depth", type=depth_mm, nargs="+", metavar="MM",
                   help="depths, mm (default: the setup's depth range's ends and the V_avg "
                        "depths 500, 1000, 5000, 10000 within it)")
    p.add_argument("--rays", type=positive_int, default=1 << 16,
                   help="rays per field point and depth of the plane banks (65536)")
    p.add_argument("--kernel-size", type=positive_int, default=31,
                   help="kernel size K, odd (31)")
    p.add_argument("--seed", type=int, default=0, help="sample-stream seed (0)")
    p.add_argument("--brute-force-steps", type=int, default=16, metavar="M",
                   help="lattice resolution of the brute-force check on 6 bins (16; 0 skips "
                        "it)")
    p.add_argument("--restoration", choices=("matched", "deployed"), default="matched",
                   help="the restoration whose error is minimised: matched (each depth with "
                        "its own IPSF and the sensor's NSR; certified bound) or deployed (as "
                        "datasets restore: every depth with the --deploy-depth kernels)")
    p.add_argument("--deploy-depth", type=depth_mm, metavar="MM",
                   help="deployed: the depth whose kernels restore every depth, mm (500)")
    p.add_argument("--deploy-nsr", type=_nsr, metavar="X",
                   help="deployed: the restoration's NSR (default the sensor's at --lux)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="w(i) of both profiles and the predicted error per radius")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    result = design_motion_profile(
        args.setup, args.out, lux=args.lux, objective=args.objective, planes=args.planes,
        span=args.span_mm, radii=args.radii, grid=args.grid, depths=args.depth,
        rays=args.rays, kernel_size=args.kernel_size, seed=args.seed,
        brute_force_steps=args.brute_force_steps, plot=args.plot, progress=True,
        restoration=args.restoration, deploy_depth=args.deploy_depth, deploy_nsr=args.deploy_nsr)
    report = result.summary
    setup_name = result.provenance["setup"]
    if args.json:
        print_json(report)
        return 0
    c = report["certificate"]
    w_lin, w_opt = report["linear_worst_at"], report["optimized_worst_at"]
    lines = [
        f"setup              {setup_name} at {args.lux:g} lux, objective {args.objective}, "
        f"{args.planes} planes, {args.restoration} restoration",
        f"span               {report['span_mm'][0]:.4f} -> {report['span_mm'][1]:.4f} mm, "
        f"exposure {report['exposure_s']:.4f} s",
        f"worst MSE          linear {report['linear_worst_mse']:.4g} "
        f"(r {w_lin['radius_mm']:.2f} mm, l {w_lin['depth_mm']:g} mm) -> optimised "
        f"{report['optimized_worst_mse']:.4g} (r {w_opt['radius_mm']:.2f} mm, "
        f"l {w_opt['depth_mm']:g} mm)",
        f"image mean MSE     linear {report['linear_image_mean_mse']:.4g} -> optimised "
        f"{report['optimized_image_mean_mse']:.4g} (points weighted by their image area)",
        f"V_avg              linear {report['linear_v_avg']:.4g} -> optimised "
        f"{report['optimized_v_avg']:.4g}",
        f"velocity           {report['velocity_mm_s'][0]:.3g} .. {report['velocity_mm_s'][1]:.3g}"
        f" mm/s, |acceleration| <= {report['max_acceleration_mm_s2']:.3g} mm/s^2",
        f"certificate        optimum in [{c['lower_bound']:.4g}, {c['objective_value']:.4g}] "
        f"(gap {100 * c['relative_gap']:.3g} %)" if c["lower_bound"] is not None
        else f"certificate        none: {c['says']}",
    ]
    b = c.get("brute_force")
    if b:
        lines.append(f"brute force        {b['bins']} bins, {b['feasible_points']} feasible "
                     f"lattice points: best {b['lattice_best']:.4g}, optimiser "
                     f"{b['local_value']:.4g} ({'agrees' if b['agrees'] else 'DISAGREES'})")
    lines.append(f"seconds            {report['seconds']['total']:.1f}")
    lines.append(f"wrote              {args.out}")
    sys.stdout.write("\n".join(lines) + "\n")
    return 0
