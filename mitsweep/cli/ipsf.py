"""``mitsweep ipsf``: one traced PSF/IPSF, or a bank of IPSFs, with the Dr.Jit tracer."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from .common import (number_type, UsageError, check_outputs, depth_mm, load_setup_arg, positive_float,
                     positive_int, print_json)
from .motion import add_motion_argument, motion_from_args

NAME = "ipsf"
HELP = ("trace the integrated PSF of a point source over the focal sweep (or a PSF at one "
        "sensor distance, or a radial/grid IPSF bank) with the Dr.Jit tracer")


_finite = number_type(float, math.isfinite, "a number", "a finite number", "finite")


def _radius(text: str) -> float:
    x = _finite(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0 mm, got {text}")
    return x


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (see scenes/)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--point", type=_finite, nargs=2, metavar=("U", "V"),
                       help="image point, upright mm at the reference (mid-sweep) sensor "
                            "distance (default: the image centre)")
    where.add_argument("--radius", type=_radius, metavar="MM",
                       help="image point at this radius (mm) and --angle")
    p.add_argument("--angle", type=_finite, default=0.0, metavar="DEG",
                   help="polar angle of --radius, degrees counter-clockwise from +u (0)")
    p.add_argument("--bank", choices=["radial", "grid"],
                   help="compute a bank instead of one IPSF (radial: untilted mirrors)")
    p.add_argument("--radii", type=positive_int, default=19, help="radial bank size (19)")
    p.add_argument("--grid", type=positive_int, nargs=2, default=(9, 9),
                   metavar=("ROWS", "COLS"), help="grid bank shape (9 9)")
    p.add_argument("--depth", type=depth_mm, nargs="+", default=[500.0], metavar="MM",
                   help="depth(s) l of the source from the mirror, mm (500; inf allowed); "
                        "several for one point: one IPSF per depth, each -o / --plot file "
                        "named per depth (FILE_l500mm.exr, FILE_linf.exr)")
    p.add_argument("--sensor-distance", type=positive_float, metavar="MM",
                   help="a PSF at this one sensor distance instead of the sweep's IPSF")
    p.add_argument("--method", choices=["exact", "continuous", "planes"], default="exact",
                   help="exact: each ray's whole sweep deposited as its segment (default); "
                        "continuous: stratified sweep times per ray; planes: the paper's "
                        "N-plane sum")
    p.add_argument("--planes", type=positive_int, default=16,
                   help="focal planes of --method planes (16, at most 64)")
    p.add_argument("--time-samples", type=positive_int, default=4,
                   help="stratified times per ray of --method continuous (4, at most 64)")
    p.add_argument("--motion-table", metavar="CSV",
                   help="measured stage motion (two columns: time, sensor distance mm) for "
                        "sweep.profile = 'tabulated'")
    add_motion_argument(p)
    p.add_argument("--rays", type=positive_int, default=1_000_000,
                   help="rays per IPSF (1000000)")
    p.add_argument("--kernel-size", type=positive_int, default=31,
                   help="kernel size K, odd, smaller than the sensor's smaller side (31)")
    p.add_argument("--seed", type=int, default=0, help="sample-stream seed (0)")
    p.add_argument("--float64", action="store_true", help="trace in float64 (reference)")
    p.add_argument("-o", "--output", metavar="FILE",
                   help="write .npz (bank format) or .exr (layered, with metadata)")
    p.add_argument("--plot", metavar="FILE.png",
                   help="thumbnails and radial/tangential cross-sections (paper Fig. 3-5)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _geometry(setup, table_path, designed=None):
    """The reference geometry of the run: the setup's sweep and motion (measured, from
    ``--motion-table``, for ``sweep.profile = 'tabulated'``; or a motion-profile file,
    ``--motion``) and its reference distance."""
    from ..config import SetupError
    from ..optics import optimal_sweep_range
    from ..optics.motion import MotionProfile, motion_for
    from ..optics.reference import reference_geometry

    if designed is not None:  # a motion-profile file: its span sets the reference grid
        return reference_geometry(setup, sweep=optimal_sweep_range(setup), motion=designed)
    table = None
    if table_path is not None:
        import numpy as np

        try:
            data = np.loadtxt(table_path, delimiter=",", ndmin=2)
        except ValueError as exc:
            raise UsageError(f"--motion-table {table_path}: expected two numeric columns "
                             f"(time, sensor distance mm) separated by commas ({exc})") from None
        if data.shape[1] != 2:
            raise UsageError(f"--motion-table {table_path}: expected 2 columns, got "
                             f"{data.shape[1]}")
        table = (data[:, 0], data[:, 1])
        try:  # the profile's own checks: finite, >= 2 rows, increasing times
            MotionProfile.tabulated(*table)
        except SetupError as exc:
            raise UsageError(f"--motion-table {table_path}: {exc}") from None
        if setup.sweep.profile != "tabulated":
            raise UsageError(f"--motion-table {table_path} needs sweep.profile = 'tabulated' "
                             f"in the setup")
    sweep = optimal_sweep_range(setup)
    return reference_geometry(setup, sweep=sweep, motion=motion_for(setup, sweep, table=table))


def depth_tag(depth: float) -> str:
    """The file-name tag of a depth: ``l500mm``, ``l1e06mm``, ``linf``."""
    if math.isinf(depth):
        return "linf"
    return "l" + f"{depth:.10g}".replace("+", "") + "mm"


def per_depth_path(path: str, depth: float) -> str:
    """``path`` with the depth's tag before its suffix: ``k.exr`` → ``k_l500mm.exr``."""
    p = Path(path)
    return str(p.with_name(f"{p.stem}_{depth_tag(depth)}{p.suffix}"))


def _outputs(args) -> dict[str, list[str | None]]:
    """Every file the run writes, by option: with several depths for one point, one of
    each per depth (a bank holds its depths in one file)."""
    if args.bank or len(args.depth) == 1:
        return {"--output": [args.output], "--plot": [args.plot]}
    return {opt: [per_depth_path(f, d) for d in args.depth] if f else []
            for opt, f in (("--output", args.output), ("--plot", args.plot))}


def _check_output(path: str | None, allowed: tuple[str, ...], what: str) -> None:
    if path is not None and Path(path).suffix.lower() not in allowed:
        raise UsageError(f"{path}: {what} output must end in {' or '.join(allowed)}")


def run(args) -> int:
    import numpy as np

    from .. import __version__
    from ..config import setup_to_dict
    from ..io import write_exr
    from ..io.bank import IPSFBank, optics_sections, save_bank
    from ..tracer import integrated_psf, ipsf_bank, psf
    from ..tracer.source import source_from_image

    if not args.bank and len(set(args.depth)) != len(args.depth):
        given = " ".join(f"{d:g}" for d in args.depth)
        raise UsageError(f"--depth {given}: give each depth once (one IPSF per depth)")
    check_outputs([args.setup, args.motion_table, args.motion], _outputs(args))
    if args.plot:  # before the traces, not after
        from ..plots import check_figure_path

        check_figure_path(args.plot, "--plot")
    setup = load_setup_arg(args.setup)
    W, H = setup.sensor.resolution
    if args.kernel_size % 2 == 0 or not 3 <= args.kernel_size < min(W, H):
        raise UsageError(f"--kernel-size: must be odd, >= 3 and smaller than the {W}x{H} "
                         f"sensor, got {args.kernel_size}")
    if args.bank == "grid" and (args.grid[0] > H or args.grid[1] > W):
        raise UsageError(f"--grid {args.grid[0]} {args.grid[1]}: at most {H} {W} for the "
                         f"{W}x{H} sensor (one point per pixel)")
    if args.bank == "radial" and args.radii > max(W, H):
        raise UsageError(f"--radii {args.radii}: at most {max(W, H)} for the {W}x{H} sensor")
    if args.seed < 0:
        raise UsageError(f"--seed: must be >= 0, got {args.seed}")
    if args.motion is not None and args.motion_table is not None:
        raise UsageError("--motion and --motion-table both give the stage motion: give one")
    geometry = _geometry(setup, args.motion_table, motion_from_args(args, setup))
    sweep, motion, i_ref = geometry.sweep, geometry.motion, geometry.sensor_distance
    common = dict(rays=args.rays, kernel_size=args.kernel_size, seed=args.seed)
    out: dict = {"setup": setup.name, "version": __version__}

    if args.bank:
        if args.point is not None or args.radius is not None or args.sensor_distance:
            raise UsageError("--bank computes its own points: drop --point, --radius and "
                             "--sensor-distance")
        _check_output(args.output, (".npz", ".exr"), "a bank")
        from tqdm import tqdm

        n_pts = args.radii if args.bank == "radial" else args.grid[0] * args.grid[1]
        with tqdm(total=n_pts * len(args.depth), desc="IPSF bank", unit="ipsf",
                  file=sys.stderr, disable=not sys.stderr.isatty()) as bar:
            bank = ipsf_bank(setup, kind=args.bank, n_radii=args.radii, grid=tuple(args.grid),
                             depths=args.depth, sweep=sweep, motion=motion, method=args.method,
                             time_samples=args.time_samples, n_planes=args.planes,
                             progress=bar.update, **common)
        out.update(kind=bank.kind, shape=list(bank.kernels.shape),
                   reference_sensor_distance_mm=bank.reference_sensor_distance,
                   depths_mm=bank.depths_mm.tolist(), points_uv_mm=bank.points_uv.tolist(),
                   max_vignetted=float(np.max(bank.vignetted)),
                   max_outside_kernel=float(np.max(bank.metadata["outside_kernel"])),
                   seconds=bank.metadata["seconds"])
        if args.output:
            if args.output.lower().endswith(".npz"):
                save_bank(args.output, bank)
            else:
                chans = {f"d{j}.p{i}.Y": bank.kernels[j, i]
                         for j in range(bank.kernels.shape[0])
                         for i in range(bank.kernels.shape[1])}
                meta = dict(bank.metadata, kind=bank.kind, points_uv=bank.points_uv.tolist(),
                            depths_mm=bank.depths_mm.tolist(), pixel_pitch=bank.pixel_pitch,
                            reference_sensor_distance=bank.reference_sensor_distance,
                            vignetted=bank.vignetted.tolist(),
                            radii_mm=None if bank.radii_mm is None else bank.radii_mm.tolist(),
                            grid_shape=bank.grid_shape, optics=bank.optics)
                write_exr(args.output, channels=chans, metadata=meta)
            out["output"] = args.output
        if args.plot:
            from ..plots import plot_bank
            from ..tracer.metrics import cross_sections

            sections = {}
            for name, i in (("centre", 0), ("periphery", bank.kernels.shape[1] - 1)):
                u, v = bank.points_uv[i]
                angle = math.atan2(v, u) if (u or v) else 0.0
                sections[name] = [cross_sections(k, angle) for k in bank.kernels[:, i]]
            plot_bank(bank, args.plot, sections=sections)
            out["plot"] = args.plot
        return _report(args, out)

    _check_output(args.output, (".npz", ".exr"), "an IPSF")
    if args.radius is not None:
        a = math.radians(args.angle)
        u, v = args.radius * math.cos(a), args.radius * math.sin(a)
    elif args.point is not None:
        u, v = args.point
    else:
        u = v = 0.0
    where = (f"--radius {args.radius:g} --angle {args.angle:g}" if args.radius is not None
             else f"--point {u:g} {v:g}")
    for depth in args.depth:  # before any trace
        try:  # the image point must see the mirror: say which flag put it elsewhere
            source_from_image(setup, u, v, depth, reference_sensor_distance=i_ref)
        except ValueError as exc:
            raise UsageError(f"{where}: {exc}") from None
    several = len(args.depth) > 1
    entries = []
    for depth in args.depth:
        if args.sensor_distance is not None:
            kernel, info = psf(setup, u, v, depth, args.sensor_distance, double=args.float64,
                               reference_sensor_distance=i_ref, **common)
        else:
            kernel, info = integrated_psf(setup, u, v, depth, sweep=sweep, motion=motion,
                                          method=args.method, time_samples=args.time_samples,
                                          n_planes=args.planes, double=args.float64, **common)
        entry = dict(info)
        if args.output:
            path = per_depth_path(args.output, depth) if several else args.output
            setup_dict = setup_to_dict(setup)
            meta = {"setup": setup_dict, "sweep_range": sweep.as_dict(), **info}
            if path.lower().endswith(".exr"):
                write_exr(path, kernel, metadata=meta)
            else:
                bank = IPSFBank(kernels=kernel[None, None], points_uv=np.array([[u, v]]),
                                depths_mm=np.array([depth]),
                                pixel_pitch=setup.sensor.pixel_pitch,
                                reference_sensor_distance=info["reference_sensor_distance_mm"],
                                kind="grid", grid_shape=(1, 1),
                                vignetted=np.array([[info["vignetted_fraction"]]]),
                                metadata=meta,
                                optics=optics_sections(setup_dict, motion.as_dict()))
                save_bank(path, bank)
            entry["output"] = path
        if args.plot:
            from ..plots import plot_ipsf
            from ..tracer.metrics import cross_sections

            path = per_depth_path(args.plot, depth) if several else args.plot
            title = "PSF" if args.sensor_distance else "IPSF"
            plot_ipsf(kernel, path, pitch_mm=setup.sensor.pixel_pitch,
                      sections=cross_sections(kernel, math.atan2(v, u) if (u or v) else 0.0),
                      title=f"{title} at ({u:.2f}, {v:.2f}) mm, l = {depth:g} mm")
            entry["plot"] = path
        entries.append(entry)
    if several:  # one entry per depth, in the order given
        out.update(image_uv_mm=[float(u), float(v)], depths_mm=list(args.depth),
                   ipsfs=entries)
    else:
        out.update(entries[0])
    return _report(args, out)


def _report(args, out: dict) -> int:
    if args.json:
        print_json(out)
        return 0
    _print_table({k: v for k, v in out.items() if k != "ipsfs"})
    for entry in out.get("ipsfs", []):
        sys.stdout.write(f"-- depth {entry['depth_mm']:g} mm\n")
        _print_table(entry)
    return 0


def _print_table(out: dict) -> None:
    skip = {"motion", "box_mm", "ellipse_mm", "mirror_point_mm", "points_uv_mm", "version"}
    for key, value in out.items():
        if key in skip:
            continue
        if isinstance(value, float):
            value = f"{value:.6g}"
        elif isinstance(value, (tuple, list)) and value and isinstance(value[0], float):
            value = "(" + ", ".join(f"{x:.6g}" for x in value) + ")"
        sys.stdout.write(f"{key:<30s} {value}\n")
