"""Design an optimised sensor-motion profile for a setup and a light level, and write it
as a motion-profile file (``mitsweep design-sweep``).

The objective, the constraints and the certificate are stated in :mod:`mitsweep.design`
(:func:`mitsweep.design.design_sweep` is the optimiser; this is the command's workflow
around it: checks, noise model, the file and its provenance, the plot). The file
(:mod:`mitsweep.optics.motion_file`) is what ``ipsf``, ``render``, ``dataset`` and
``capture`` run with ``--motion``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

from .. import __version__
from ..config import Setup
from ..deprecation import renamed_keywords
from ._base import (InputError, Progress, WorkflowResult, progress_callback, resolve_setup)
from ._paths import check_outputs

__all__ = ["design_motion_profile"]


def _check_args(setup, *, kernel_size, planes, seed, brute_force_steps, out, span,
                restoration, deploy_depth, deploy_nsr) -> None:
    from ..design.objective import DEFAULT_FFT_SIZE
    from ..design.sweep import RESTORATIONS

    if restoration not in RESTORATIONS:
        raise InputError(f"--restoration: must be one of {', '.join(RESTORATIONS)}, got "
                         f"{restoration!r}")
    if restoration != "deployed":
        given = [name for name, v in (("--deploy-depth", deploy_depth),
                                      ("--deploy-nsr", deploy_nsr)) if v is not None]
        if given:
            raise InputError(f"{' and '.join(given)}: only with --restoration deployed")
    if deploy_depth is not None and not deploy_depth > 0:
        raise InputError(f"--deploy-depth: must be > 0 mm (inf allowed), got {deploy_depth:g}")
    if deploy_nsr is not None and not (math.isfinite(deploy_nsr) and deploy_nsr > 0):
        raise InputError(f"--deploy-nsr: must be a finite NSR > 0, got {deploy_nsr:g}")

    K = kernel_size
    W, H = setup.sensor.resolution
    # the objective's DFT grid holds the kernels: checked here, before any tracing
    k_max = min(DEFAULT_FFT_SIZE - (1 - DEFAULT_FFT_SIZE % 2), min(W, H) - 1)
    if K % 2 == 0 or not 3 <= K <= k_max:
        raise InputError(f"--kernel-size: must be odd, in [3, {k_max}] (the design's "
                         f"{DEFAULT_FFT_SIZE}-point DFT grid and the {W}x{H} sensor), "
                         f"got {K}")
    from ..design.sweep import MIN_PLANES

    if not MIN_PLANES <= planes <= 1024:
        raise InputError(f"--planes: must be in [{MIN_PLANES}, 1024], got {planes}")
    if seed < 0:
        raise InputError(f"--seed: must be >= 0, got {seed}")
    if not 0 <= brute_force_steps <= 32:
        raise InputError(f"--brute-force-steps: must be in [0, 32], got "
                         f"{brute_force_steps}")
    if not os.fspath(out).lower().endswith(".json"):
        raise InputError(f"--out {out}: a motion-profile file must end in .json")
    if span is not None:
        a, b = span
        f = setup.lens.focal_length
        if a == b:
            raise InputError(f"--span-mm {a:g} {b:g}: the two ends must differ")
        if min(a, b) <= f:
            raise InputError(f"--span-mm {a:g} {b:g}: crosses the lens focal length "
                             f"({f:g} mm): both ends must be > {f:g} mm")


def _plot_design(design, path: str | os.PathLike) -> None:
    """Time density w(i) of both profiles, and the predicted MSE per field point."""
    import numpy as np

    from ..plots import new_figure, save_figure

    fig, (a0, a1) = new_figure(1, 2, figsize=(10.0, 4.0))
    e = design.edges
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
    save_figure(fig, os.fspath(path))


@renamed_keywords(span_mm="span")
def design_motion_profile(setup: Setup | str | os.PathLike, out: str | os.PathLike, *,
                          lux: float = 50.0, objective: str = "worst", planes: int = 64,
                          span: tuple[float, float] | None = None, radii: int = 9,
                          grid: tuple[int, int] | None = None,
                          depths: Sequence[float] | None = None, rays: int = 1 << 16,
                          kernel_size: int = 31, seed: int = 0, brute_force_steps: int = 16,
                          plot: str | os.PathLike | None = None,
                          restoration: str = "matched", deploy_depth: float | None = None,
                          deploy_nsr: float | None = None,
                          progress: Progress = None) -> WorkflowResult:
    """Design the sensor's time profile over the sweep that minimises the predicted Wiener
    restoration error, and write it as a motion-profile file (``mitsweep design-sweep``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup, its TOML file, or a bundled setup's name.
    out : path-like
        The motion-profile file to write (``.json``); read back and checked against the
        setup (what the stage can run) after writing.
    lux : float
        Scene illuminance of the noise model, lux (the dataset's sensor: paper Fig. 10
        sweep settings).
    objective : {"worst", "mean"}
        Minimise the worst or the mean predicted MSE over field points x depths.
    planes : int
        Bins N of sensor distance over the span (in [MIN_PLANES, 1024]).
    span : (float, float), optional
        Sweep from sensor distance A to B, mm (default: the optimal range). Formerly
        ``span_mm`` (still accepted, with a DeprecationWarning).
    radii, grid
        Field points: radii from the centre to the FOV's edge (untilted mirrors), or a
        grid over the sensor (tilted mirrors; default 5 x 5, and under the deployed
        restoration the grid bank's, :func:`mitsweep.design.design_sweep`).
    depths : sequence of float, optional
        Depths, mm (default: the depth range's ends and the V_avg depths within it).
    rays, kernel_size, seed
        Of the plane banks' traces.
    brute_force_steps : int
        Lattice resolution of the brute-force check on 6 bins, in [0, 32] (0 skips it).
    plot : path-like, optional
        A PNG of w(i) of both profiles and the predicted error per radius.
    restoration : {"matched", "deployed"}
        The restoration whose predicted error is minimised: ``"matched"``, each depth
        restored with its own IPSF and the sensor's NSR (with a certified bound);
        ``"deployed"``, as the datasets restore: every depth with the kernels at
        ``deploy_depth`` and the NSR ``deploy_nsr`` (no certified bound, no brute-force
        check; where no profile beats the linear sweep the design returns it and says so,
        ``summary["returns_linear"]``). See :func:`mitsweep.design.design_sweep`.
    deploy_depth : float, optional
        ``"deployed"`` only: the depth whose kernels restore every depth, mm (``inf``
        allowed; default 500 mm, the datasets' bank depth).
    deploy_nsr : float, optional
        ``"deployed"`` only: the restoration's NSR, finite and > 0 (default the sensor's
        at this light level).
    progress : None, True or callable
        Progress per traced field point.

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.design.SweepDesign`. ``provenance``: what the
        file records (generator, version, trace revision, setup, lux, objective, planes,
        span, seed, rays, noise, predicted errors, certificate). ``summary``: the design's
        report (what ``mitsweep design-sweep --json`` prints).

    Raises
    ------
    InputError
        A kernel size, plane count, seed, span or output name out of range; an unknown
        restoration, a deploy depth ≤ 0 or an NSR not finite and > 0, or either deploy
        option without ``restoration="deployed"``.

    Examples
    --------
    >>> from mitsweep.workflows import design_motion_profile
    >>> r = design_motion_profile("sphere", "profile.json", rays=4096)  # doctest: +SKIP
    >>> r.summary["optimized_worst_mse"] < r.summary["linear_worst_mse"]  # doctest: +SKIP
    True
    """
    from ..deconv import paper_fig10_settings
    from ..design import design_sweep
    from ..io.atomic import check_writable
    from ..optics.motion_file import (
        check_motion_file,
        load_motion_file,
        save_motion_file,
    )
    from ..pipeline import NOISE_PIXEL_MM
    from ..tracer.kernel import TRACE_REVISION

    setup_path = None if isinstance(setup, Setup) else setup
    check_outputs([setup_path], {"--out": out, "--plot": plot})
    check_writable(os.fspath(out))
    if plot:
        from ..plots import check_figure_path

        check_figure_path(os.fspath(plot), "--plot")
    setup = resolve_setup(setup)
    _check_args(setup, kernel_size=kernel_size, planes=planes, seed=seed,
                brute_force_steps=brute_force_steps, out=out, span=span,
                restoration=restoration, deploy_depth=deploy_depth, deploy_nsr=deploy_nsr)
    noise = paper_fig10_settings(NOISE_PIXEL_MM, lux)["sweep"]
    with progress_callback(progress, None, "plane banks", "point") as step:
        design = design_sweep(setup, noise=noise, objective=objective, n_planes=planes,
                              span=None if span is None else
                              (float(span[0]), float(span[1])),
                              n_radii=radii,
                              grid=None if grid is None else (int(grid[0]), int(grid[1])),
                              depths=depths,
                              rays=rays,
                              kernel_size=kernel_size, seed=seed,
                              brute_force_steps=brute_force_steps, progress=step,
                              restoration=restoration,
                              deploy_depth=500.0 if deploy_depth is None else float(deploy_depth),
                              deploy_nsr=None if deploy_nsr is None else float(deploy_nsr))
    # the plane banks are traced: their tracer revision says which results are comparable
    report = dict(design.report, lux=lux, version=__version__, trace_revision=TRACE_REVISION)
    provenance = {"generator": "mitsweep design-sweep", "version": __version__,
                  "trace_revision": TRACE_REVISION,
                  "setup_file": str(setup_path) if setup_path is not None else None,
                  "setup": setup.name, "lux": lux,
                  "objective": objective, "planes": planes,
                  "restoration": restoration, "deploy": report["deploy"],
                  "returns_linear": report["returns_linear"],
                  "span_mm": report["span_mm"], "seed": seed, "rays": rays,
                  "noise": report["noise"],
                  "predicted": {k: report[k] for k in (
                      "linear_worst_mse", "optimized_worst_mse", "linear_mean_mse",
                      "optimized_mean_mse", "linear_v_avg", "optimized_v_avg")},
                  "certificate": {k: report["certificate"][k] for k in (
                      "objective_value", "lower_bound", "relative_gap")}}
    save_motion_file(out, design.profile, exposure_s=design.exposure_s,
                     provenance=provenance)
    # what was written must be what the stage can run: read it back as every user will
    check_motion_file(load_motion_file(out), setup)
    report["out"] = os.fspath(out)
    if plot:
        _plot_design(design, plot)
        report["plot"] = os.fspath(plot)
    return WorkflowResult(design, dict(provenance, workflow="design_motion_profile"), report)
