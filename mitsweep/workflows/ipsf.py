"""Trace one PSF/IPSF, or a bank of IPSFs, with the Dr.Jit tracer (``mitsweep ipsf``)."""

from __future__ import annotations

import math
import os
from pathlib import Path
from collections.abc import Sequence

import numpy as np

from .. import __version__
from ..config import Setup, SetupError, setup_to_dict
from ._base import (InputError, Progress, WorkflowResult, progress_callback,
                    read_motion_file, resolve_setup)
from ._paths import check_outputs

__all__ = ["trace_ipsf", "trace_ipsf_bank", "depth_tag", "per_depth_path"]

def depth_tag(depth: float) -> str:
    """The file-name tag of a depth: ``l500mm``, ``l1e06mm``, ``linf``.

    Parameters
    ----------
    depth : float
        Depth of the source from the mirror, mm (inf allowed).

    Returns
    -------
    str
    """
    if math.isinf(depth):
        return "linf"
    return "l" + f"{depth:.10g}".replace("+", "") + "mm"


def per_depth_path(path: str | os.PathLike, depth: float) -> str:
    """``path`` with the depth's tag before its suffix: ``k.exr`` → ``k_l500mm.exr``.

    Parameters
    ----------
    path : str or path-like
        The output named for all depths.
    depth : float
        The depth, mm (:func:`depth_tag`).

    Returns
    -------
    str
    """
    p = Path(path)
    return str(p.with_name(f"{p.stem}_{depth_tag(depth)}{p.suffix}"))


def _check_suffix(path, allowed: tuple[str, ...], what: str) -> None:
    if path is not None and Path(path).suffix.lower() not in allowed:
        raise InputError(f"{path}: {what} output must end in {' or '.join(allowed)}")


def _motion_table(setup: Setup, table_path):
    from ..optics.motion import MotionProfile

    try:
        data = np.loadtxt(table_path, delimiter=",", ndmin=2)
    except ValueError as exc:
        raise InputError(f"--motion-table {table_path}: expected two numeric columns "
                         f"(time, sensor distance mm) separated by commas ({exc})") from None
    if data.shape[1] != 2:
        raise InputError(f"--motion-table {table_path}: expected 2 columns, got "
                         f"{data.shape[1]}")
    table = (data[:, 0], data[:, 1])
    try:  # the profile's own checks: finite, >= 2 rows, increasing times
        MotionProfile.tabulated(*table)
    except SetupError as exc:
        raise InputError(f"--motion-table {table_path}: {exc}") from None
    if setup.sweep.profile != "tabulated":
        raise InputError(f"--motion-table {table_path} needs sweep.profile = 'tabulated' "
                         f"in the setup")
    return table


def _prepare(setup, *, inputs, outputs, plot, kernel_size) -> Setup:
    """The checks of both traces before any work: outputs, the plot's path, the setup and
    the kernel size."""
    check_outputs(inputs, outputs)
    if plot:  # before the traces, not after
        from ..plots import check_figure_path

        check_figure_path(plot, "--plot")
    setup = resolve_setup(setup)
    W, H = setup.sensor.resolution
    if kernel_size % 2 == 0 or not 3 <= kernel_size < min(W, H):
        raise InputError(f"--kernel-size: must be odd, >= 3 and smaller than the {W}x{H} "
                         f"sensor, got {kernel_size}")
    return setup


def _geometry(setup, seed, motion, motion_table):
    """The run's reference geometry: the setup's sweep and motion (measured, from
    ``motion_table``, for ``sweep.profile = 'tabulated'``; or a motion-profile file) and
    its reference distance."""
    from ..optics import optimal_sweep_range
    from ..optics.motion import motion_for
    from ..optics.reference import reference_geometry

    if seed < 0:
        raise InputError(f"--seed: must be >= 0, got {seed}")
    if motion is not None and motion_table is not None:
        raise InputError("--motion and --motion-table both give the stage motion: give one")
    if motion is not None:  # a motion-profile file: its span sets the reference grid
        designed = read_motion_file(motion, setup).profile
        return reference_geometry(setup, sweep=optimal_sweep_range(setup), motion=designed)
    table = _motion_table(setup, motion_table) if motion_table is not None else None
    sweep = optimal_sweep_range(setup)
    return reference_geometry(setup, sweep=sweep, motion=motion_for(setup, sweep, table=table))


_TRACE_PARAMETERS = """method : {"exact", "continuous", "planes"}
        exact: each ray's whole sweep deposited as its segment; continuous: stratified
        sweep times per ray; planes: the paper's N-plane sum.
    planes : int
        Focal planes of ``method="planes"`` (at most 64).
    time_samples : int
        Stratified times per ray of ``method="continuous"`` (at most 64).
    motion : path-like, optional
        A motion-profile file (``mitsweep design-sweep``) to run instead of the setup's
        sweep; the reference grid is mid-travel of its span.
    motion_table : path-like, optional
        Measured stage motion (CSV: time, sensor distance mm) for
        ``sweep.profile = 'tabulated'``.
    rays : int
        Rays per IPSF.
    kernel_size : int
        Kernel size K, odd, smaller than the sensor's smaller side.
    seed : int
        Sample-stream seed (>= 0).
    output : path-like, optional
        ``.npz`` (bank format) or ``.exr`` (layered, with metadata).
    plot : path-like, optional
        A PNG of thumbnails and radial/tangential cross-sections (paper Fig. 3-5)."""


def trace_ipsf_bank(setup: Setup | str | os.PathLike, *, kind: str = "radial",
                    radii: int = 19, grid: tuple[int, int] = (9, 9),
                    depths: Sequence[float] = (500.0,), method: str = "exact",
                    planes: int = 16, time_samples: int = 4, motion: str | os.PathLike | None = None,
                    motion_table: str | os.PathLike | None = None, rays: int = 1_000_000,
                    kernel_size: int = 31, seed: int = 0, output: str | os.PathLike | None = None,
                    plot: str | os.PathLike | None = None, progress: Progress = None) -> WorkflowResult:
    """Trace a radial or grid bank of IPSFs of a setup (``mitsweep ipsf --bank``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    kind : {"radial", "grid"}
        Radial (untilted mirrors: ``radii`` points along +u) or a ``grid`` of points.
    radii : int
        Radial bank size (at most the sensor's larger side).
    grid : (int, int)
        Grid bank shape (rows, cols), at most the sensor's (one point per pixel).
    depths : sequence of float
        Depths l of the sources from the mirror, mm (inf allowed).
    {trace_parameters}
    progress : None, True or callable
        Progress per traced IPSF (:func:`mitsweep.workflows.progress_callback`).

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.io.bank.IPSFBank`. ``provenance``: ``setup`` (its
        dict), ``sweep_range``, ``motion``, ``reference_sensor_distance_mm``, ``rays``,
        ``seed``, ``method``, ``seconds``, ``version``. ``summary``: what
        ``mitsweep ipsf --bank --json`` prints (shape, depths, points, vignetting).

    Raises
    ------
    InputError
        A bad kernel size, grid or radii for the sensor, a bad seed, two motions, an
        output of the wrong kind.
    mitsweep.config.SetupError
        An unreadable setup or motion file.

    Examples
    --------
    >>> from mitsweep.workflows import trace_ipsf_bank
    >>> bank = trace_ipsf_bank("sphere", radii=3, rays=20_000).value  # doctest: +SKIP
    >>> bank.kernels.shape                                            # doctest: +SKIP
    (1, 3, 31, 31)
    """
    from ..io import write_exr
    from ..io.bank import save_bank
    from ..tracer import ipsf_bank
    from ..tracer.settings import TraceSettings

    setup = _prepare(setup, inputs=[_path(setup), motion_table, motion],
                     outputs={"--output": [output], "--plot": [plot]}, plot=plot,
                     kernel_size=kernel_size)
    W, H = setup.sensor.resolution
    if kind == "grid" and (grid[0] > H or grid[1] > W):
        raise InputError(f"--grid {grid[0]} {grid[1]}: at most {H} {W} for the "
                         f"{W}x{H} sensor (one point per pixel)")
    if kind == "radial" and radii > max(W, H):
        raise InputError(f"--radii {radii}: at most {max(W, H)} for the {W}x{H} sensor")
    geometry = _geometry(setup, seed, motion, motion_table)
    _check_suffix(output, (".npz", ".exr"), "a bank")
    n_pts = radii if kind == "radial" else grid[0] * grid[1]
    with progress_callback(progress, n_pts * len(depths), "IPSF bank", "ipsf") as step:
        settings = TraceSettings(rays=rays, kernel_size=kernel_size, seed=seed, method=method,
                                 time_samples=time_samples, n_planes=planes)
        bank = ipsf_bank(setup, kind=kind, n_radii=radii, grid=(grid[0], grid[1]), depths=depths,
                         sweep=geometry.sweep, motion=geometry.motion, settings=settings,
                         progress=step)
    assert bank.vignetted is not None  # ipsf_bank records it for every bank it traces
    out: dict = {"setup": setup.name, "version": __version__, "kind": bank.kind,
                 "shape": list(bank.kernels.shape),
                 "reference_sensor_distance_mm": bank.reference_sensor_distance,
                 "depths_mm": bank.depths.tolist(), "points_uv_mm": bank.points_uv.tolist(),
                 "max_vignetted": float(np.max(bank.vignetted)),
                 "max_outside_kernel": float(np.max(bank.metadata["outside_kernel"])),
                 "seconds": bank.metadata["seconds"]}
    if output:
        path = os.fspath(output)
        if path.lower().endswith(".npz"):
            save_bank(path, bank)
        else:
            chans = {f"d{j}.p{i}.Y": bank.kernels[j, i]
                     for j in range(bank.kernels.shape[0])
                     for i in range(bank.kernels.shape[1])}
            meta = dict(bank.metadata, kind=bank.kind, points_uv=bank.points_uv.tolist(),
                        depths_mm=bank.depths.tolist(), pixel_pitch=bank.pixel_pitch,
                        reference_sensor_distance=bank.reference_sensor_distance,
                        vignetted=bank.vignetted.tolist(),
                        radii_mm=None if bank.radii is None else bank.radii.tolist(),
                        grid_shape=bank.grid_shape, optics=bank.optics)
            write_exr(path, channels=chans, metadata=meta)
        out["output"] = path
    if plot:
        from ..plots import plot_bank
        from ..tracer.metrics import cross_sections

        sections = {}
        for name, i in (("centre", 0), ("periphery", bank.kernels.shape[1] - 1)):
            u, v = bank.points_uv[i]
            angle = math.atan2(v, u) if (u or v) else 0.0
            sections[name] = [cross_sections(k, angle) for k in bank.kernels[:, i]]
        plot_bank(bank, os.fspath(plot), sections=sections)
        out["plot"] = os.fspath(plot)
    provenance = {"workflow": "trace_ipsf_bank", "version": __version__,
                  "setup": setup_to_dict(setup), "sweep_range": geometry.sweep.as_dict(),
                  "motion": geometry.motion.as_dict(),
                  "reference_sensor_distance_mm": bank.reference_sensor_distance,
                  "rays": rays, "seed": seed, "method": method,
                  "seconds": bank.metadata["seconds"]}
    return WorkflowResult(bank, provenance, out)


def _path(setup):
    """The setup argument's file, if it is one (an input no output may overwrite)."""
    return None if isinstance(setup, Setup) else setup


def trace_ipsf(setup: Setup | str | os.PathLike, *, point: tuple[float, float] | None = None,
               radius: float | None = None, angle_deg: float = 0.0,
               depths: Sequence[float] = (500.0,), sensor_distance: float | None = None,
               method: str = "exact", planes: int = 16, time_samples: int = 4,
               motion: str | os.PathLike | None = None, motion_table: str | os.PathLike | None = None,
               rays: int = 1_000_000, kernel_size: int = 31, seed: int = 0,
               float64: bool = False, output: str | os.PathLike | None = None,
               plot: str | os.PathLike | None = None) -> WorkflowResult:
    """Trace the IPSF (or the PSF at one sensor distance) of one image point at one or
    more depths (``mitsweep ipsf``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    point : (float, float), optional
        Image point (u, v), upright mm at the reference (mid-sweep) sensor distance
        (default: the image centre).
    radius, angle_deg : float, optional
        Or the image point at this radius (mm) and polar angle (degrees counter-clockwise
        from +u).
    depths : sequence of float
        Depths l of the source from the mirror, mm (inf allowed), each once; with several,
        each output and plot file is named per depth (:func:`per_depth_path`).
    sensor_distance : float, optional
        A PSF at this one sensor distance instead of the sweep's IPSF.
    {trace_parameters}
    float64 : bool
        Trace in float64 (reference).

    Returns
    -------
    WorkflowResult
        ``value``: the kernel, ``(K, K)`` float ndarray (unit sum), or with several
        depths a list of them in the order given. ``provenance``: ``setup``,
        ``sweep_range``, ``motion``, ``image_uv_mm``, ``depths_mm``, ``version`` and the
        tracer's record of each kernel (``traces``: rays, vignetting, reference distance,
        seconds...). ``summary``: what ``mitsweep ipsf --json`` prints.

    Raises
    ------
    InputError
        A repeated depth, a bad kernel size or seed, two motions, an output of the wrong
        kind, an image point that does not see the mirror.
    mitsweep.config.SetupError
        An unreadable setup or motion file.

    Examples
    --------
    >>> from mitsweep.workflows import trace_ipsf
    >>> kernel = trace_ipsf("sphere", radius=1.0, rays=20_000).value  # doctest: +SKIP
    >>> round(float(kernel.sum()), 6)                                  # doctest: +SKIP
    1.0
    """
    from ..io import write_exr
    from ..io.bank import IPSFBank, optics_sections, save_bank
    from ..tracer import integrated_psf, psf
    from ..tracer.settings import TraceSettings
    from ..tracer.source import source_from_image

    depths = list(depths)
    several = len(depths) > 1
    if len(set(depths)) != len(depths):
        given = " ".join(f"{d:g}" for d in depths)
        raise InputError(f"--depth {given}: give each depth once (one IPSF per depth)")
    outputs = {opt: ([per_depth_path(f, d) for d in depths] if f else []) if several else [f]
               for opt, f in (("--output", output), ("--plot", plot))}
    setup = _prepare(setup, inputs=[_path(setup), motion_table, motion], outputs=outputs,
                     plot=plot, kernel_size=kernel_size)
    geometry = _geometry(setup, seed, motion, motion_table)
    sweep, profile, i_ref = geometry.sweep, geometry.motion, geometry.sensor_distance
    _check_suffix(output, (".npz", ".exr"), "an IPSF")
    if radius is not None:
        a = math.radians(angle_deg)
        u, v = radius * math.cos(a), radius * math.sin(a)
    elif point is not None:
        u, v = point
    else:
        u = v = 0.0
    where = (f"--radius {radius:g} --angle {angle_deg:g}" if radius is not None
             else f"--point {u:g} {v:g}")
    for depth in depths:  # before any trace
        try:  # the image point must see the mirror: say which option put it elsewhere
            source_from_image(setup, u, v, depth, reference_sensor_distance=i_ref)
        except ValueError as exc:
            raise InputError(f"{where}: {exc}") from None
    entries, kernels = [], []
    setup_dict = setup_to_dict(setup)
    for depth in depths:
        if sensor_distance is not None:
            kernel, info = psf(setup, u, v, depth, sensor_distance, double=float64,
                               reference_sensor_distance=i_ref, rays=rays,
                               kernel_size=kernel_size, seed=seed)
        else:
            settings = TraceSettings(rays=rays, kernel_size=kernel_size, seed=seed,
                                     method=method, time_samples=time_samples,
                                     n_planes=planes)
            kernel, info = integrated_psf(setup, u, v, depth, sweep=sweep, motion=profile,
                                          settings=settings, double=float64)
        entry = dict(info)
        if output:
            path = per_depth_path(output, depth) if several else os.fspath(output)
            meta = {"setup": setup_dict, "sweep_range": sweep.as_dict(), **info}
            if path.lower().endswith(".exr"):
                write_exr(path, kernel, metadata=meta)
            else:
                bank = IPSFBank(kernels=kernel[None, None], points_uv=np.array([[u, v]]),
                                depths=np.array([depth]),
                                pixel_pitch=setup.sensor.pixel_pitch,
                                reference_sensor_distance=info["reference_sensor_distance_mm"],
                                kind="grid", grid_shape=(1, 1),
                                vignetted=np.array([[info["vignetted_fraction"]]]),
                                metadata=meta,
                                optics=optics_sections(setup_dict, profile.as_dict()))
                save_bank(path, bank)
            entry["output"] = path
        if plot:
            from ..plots import plot_ipsf
            from ..tracer.metrics import cross_sections

            path = per_depth_path(plot, depth) if several else os.fspath(plot)
            title = "PSF" if sensor_distance else "IPSF"
            plot_ipsf(kernel, path, pixel_pitch=setup.sensor.pixel_pitch,
                      sections=cross_sections(kernel, math.atan2(v, u) if (u or v) else 0.0),
                      title=f"{title} at ({u:.2f}, {v:.2f}) mm, l = {depth:g} mm")
            entry["plot"] = path
        entries.append(entry)
        kernels.append(kernel)
    out: dict = {"setup": setup.name, "version": __version__}
    if several:  # one entry per depth, in the order given
        out.update(image_uv_mm=[float(u), float(v)], depths_mm=list(depths), ipsfs=entries)
    else:
        out.update(entries[0])
    provenance = {"workflow": "trace_ipsf", "version": __version__, "setup": setup_dict,
                  "sweep_range": sweep.as_dict(), "motion": profile.as_dict(),
                  "image_uv_mm": [float(u), float(v)], "depths_mm": list(depths),
                  "sensor_distance_mm": sensor_distance, "traces": entries}
    return WorkflowResult(kernels if several else kernels[0], provenance, out)


for _f in (trace_ipsf, trace_ipsf_bank):  # the parameters both share, written once
    _f.__doc__ = (_f.__doc__ or "").replace("{trace_parameters}", _TRACE_PARAMETERS)
