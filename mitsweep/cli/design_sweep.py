"""``mitsweep design-sweep``: an optimised sensor-motion profile for a setup and light level.

The objective, the constraints and the certificate are stated in :mod:`mitsweep.design`.
The profile is written as a motion-profile file (:mod:`mitsweep.optics.motion_file`) that
``ipsf``, ``render``, ``dataset`` and ``capture`` run with ``--motion``.
"""

from __future__ import annotations

import argparse
import math
import sys

from .common import (UsageError, check_outputs, depth_mm, illuminance_lux, load_setup_arg,
                     number_type, positive_int, print_json)

NAME = "design-sweep"
HELP = ("design the sensor's time profile over the sweep (not only its range) that "
        "minimises the predicted Wiener restoration error, and write it as a motion file")


_distance = number_type(float, lambda x: math.isfinite(x) and x > 0,
                        "a sensor distance in mm", "a finite sensor distance > 0 mm",
                        "sensor_distance")



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
    p.add_argument("--grid", type=positive_int, nargs=2, default=(5, 5), metavar=("ROWS", "COLS"),
                   help="grid of field points over the sensor (5 5; tilted mirrors)")
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
    p.add_argument("--plot", metavar="FILE.png",
                   help="w(i) of both profiles and the predicted error per radius")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _check_args(args, setup) -> None:
    from ..design.objective import DEFAULT_FFT_SIZE

    K = args.kernel_size
    W, H = setup.sensor.resolution
    # the objective's DFT grid holds the kernels: checked here, before any tracing
    k_max = min(DEFAULT_FFT_SIZE - (1 - DEFAULT_FFT_SIZE % 2), min(W, H) - 1)
    if K % 2 == 0 or not 3 <= K <= k_max:
        raise UsageError(f"--kernel-size: must be odd, in [3, {k_max}] (the design's "
                         f"{DEFAULT_FFT_SIZE}-point DFT grid and the {W}x{H} sensor), "
                         f"got {K}")
    from ..design.sweep import MIN_PLANES

    if not MIN_PLANES <= args.planes <= 1024:
        raise UsageError(f"--planes: must be in [{MIN_PLANES}, 1024], got {args.planes}")
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if not 0 <= args.brute_force_steps <= 32:
        raise UsageError(f"--brute-force-steps: must be in [0, 32], got "
                         f"{args.brute_force_steps}")
    if not args.out.lower().endswith(".json"):
        raise UsageError(f"--out {args.out}: a motion-profile file must end in .json")
    if args.span_mm is not None:
        a, b = args.span_mm
        f = setup.lens.focal_length
        if a == b:
            raise UsageError(f"--span-mm {a:g} {b:g}: the two ends must differ")
        if min(a, b) <= f:
            raise UsageError(f"--span-mm {a:g} {b:g}: crosses the lens focal length "
                             f"({f:g} mm): both ends must be > {f:g} mm")


def plot_design(design, path: str) -> None:
    """Time density w(i) of both profiles, and the predicted MSE per field point."""
    import numpy as np

    from ..plots import new_figure, save_figure

    fig, (a0, a1) = new_figure(1, 2, figsize=(10.0, 4.0))
    e = design.edges_mm
    mid = 0.5 * (e[:-1] + e[1:])
    width = np.abs(np.diff(e))
    T = design.exposure_s
    a0.step(mid, design.tau_linear * T / width, where="mid", label="linear (uniform)")
    a0.step(mid, design.tau * T / width, where="mid", label="optimised")
    a0.set_xlabel("sensor distance i (mm)")
    a0.set_ylabel("time density w(i) (s/mm)")
    a0.set_title("time spent per mm of sensor travel")
    a0.legend()
    r = np.hypot(design.points_uv[:, 0], design.points_uv[:, 1])
    order = np.argsort(r)
    for name, mse in (("linear", design.mse_linear), ("optimised", design.mse)):
        a1.plot(r[order], mse.max(axis=0)[order], marker="o", label=f"{name}, worst depth")
        a1.plot(r[order], mse.mean(axis=0)[order], ls="--", label=f"{name}, mean over depths")
    a1.set_xlabel("image radius (mm)")
    a1.set_ylabel("predicted Wiener MSE")
    a1.set_yscale("log")
    a1.set_title(f"objective: {design.report['objective']}")
    a1.legend(fontsize="small")
    save_figure(fig, path)


def run(args) -> int:
    from .. import __version__
    from ..deconv import paper_fig10_settings
    from ..design import design_sweep
    from ..io.atomic import check_writable
    from ..optics.motion_file import check_motion_file, load_motion_file, save_motion_file
    from ..pipeline import NOISE_PIXEL_MM
    from ..tracer.kernel import TRACE_REVISION

    check_outputs([args.setup], {"--out": args.out, "--plot": args.plot})
    check_writable(args.out)
    if args.plot:
        from ..plots import check_figure_path

        check_figure_path(args.plot, "--plot")
    setup = load_setup_arg(args.setup)
    _check_args(args, setup)
    noise = paper_fig10_settings(NOISE_PIXEL_MM, args.lux)["sweep"]
    from tqdm import tqdm

    with tqdm(desc="plane banks", unit="point", file=sys.stderr,
              disable=not sys.stderr.isatty()) as bar:
        design = design_sweep(setup, noise=noise, objective=args.objective,
                              n_planes=args.planes,
                              span_mm=None if args.span_mm is None else tuple(args.span_mm),
                              n_radii=args.radii, grid=tuple(args.grid), depths=args.depth,
                              rays=args.rays, kernel_size=args.kernel_size, seed=args.seed,
                              brute_force_steps=args.brute_force_steps, progress=bar.update)
    # the plane banks are traced: their tracer revision says which results are comparable
    report = dict(design.report, lux=args.lux, version=__version__,
                  trace_revision=TRACE_REVISION)
    provenance = {"generator": "mitsweep design-sweep", "version": __version__,
                  "trace_revision": TRACE_REVISION,
                  "setup_file": str(args.setup), "setup": setup.name, "lux": args.lux,
                  "objective": args.objective, "planes": args.planes,
                  "span_mm": report["span_mm"], "seed": args.seed, "rays": args.rays,
                  "noise": report["noise"],
                  "predicted": {k: report[k] for k in (
                      "linear_worst_mse", "optimized_worst_mse", "linear_mean_mse",
                      "optimized_mean_mse", "linear_v_avg", "optimized_v_avg")},
                  "certificate": {k: report["certificate"][k] for k in (
                      "objective_value", "lower_bound", "relative_gap")}}
    save_motion_file(args.out, design.profile, exposure_s=design.exposure_s,
                     provenance=provenance)
    # what was written must be what the stage can run: read it back as every user will
    check_motion_file(load_motion_file(args.out), setup)
    report["out"] = args.out
    if args.plot:
        plot_design(design, args.plot)
        report["plot"] = args.plot
    if args.json:
        print_json(report)
        return 0
    c = report["certificate"]
    w_lin, w_opt = report["linear_worst_at"], report["optimized_worst_at"]
    lines = [
        f"setup              {setup.name} at {args.lux:g} lux, objective {args.objective}, "
        f"{args.planes} planes",
        f"span               {report['span_mm'][0]:.4f} -> {report['span_mm'][1]:.4f} mm, "
        f"exposure {report['exposure_s']:.4f} s",
        f"worst MSE          linear {report['linear_worst_mse']:.4g} "
        f"(r {w_lin['radius_mm']:.2f} mm, l {w_lin['depth_mm']:g} mm) -> optimised "
        f"{report['optimized_worst_mse']:.4g} (r {w_opt['radius_mm']:.2f} mm, "
        f"l {w_opt['depth_mm']:g} mm)",
        f"mean MSE           linear {report['linear_mean_mse']:.4g} -> optimised "
        f"{report['optimized_mean_mse']:.4g}",
        f"V_avg              linear {report['linear_v_avg']:.4g} -> optimised "
        f"{report['optimized_v_avg']:.4g}",
        f"velocity           {report['velocity_mm_s'][0]:.3g} .. {report['velocity_mm_s'][1]:.3g}"
        f" mm/s, |acceleration| <= {report['max_acceleration_mm_s2']:.3g} mm/s^2",
        f"certificate        optimum in [{c['lower_bound']:.4g}, {c['objective_value']:.4g}] "
        f"(gap {100 * c['relative_gap']:.3g} %)",
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
