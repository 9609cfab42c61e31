"""``design_sweep``: the exposure-time profile of a focal sweep that minimises the
predicted restoration error (the objective is stated in :mod:`mitsweep.design`)."""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass, field
from collections.abc import Callable, Sequence

import numpy as np

from ..config import Setup, SetupError
from ..deprecation import renamed_fields, renamed_keywords
from ..deconv.noise import SensorNoise
from ..deconv.spatial import grid_bank_shape
from ..optics import optimal_sweep_range
from ..optics.motion import MotionProfile
from ..optics.reference import ReferenceGeometry, reference_geometry
from ..tracer.bank import field_radius, grid_points, rim_field_radius, rim_radii
from ..tracer.metrics import v_avg
from ..tracer.source import source_from_image
from .objective import DEFAULT_FFT_SIZE, deployed_wiener_model, wiener_model
from .optimize import (OBJECTIVES, StageLimits, brute_force, certified_lower_bound,
                       local_optimum, stage_feasible)
from .planes import DEFAULT_PLANE_RAYS, DEFAULT_SUB_PLANES, PlaneBank, plane_bank

__all__ = ["SweepDesign", "design_sweep", "design_depths", "design_points",
           "image_area_weights", "V_DEPTHS_MM", "MIN_PLANES", "RESTORATIONS"]

logger = logging.getLogger(__name__)

#: The V_avg depths of the paper (Eq. 3), mm.
V_DEPTHS_MM = (500.0, 1000.0, 5000.0, 10000.0)
#: Fewest bins a design may have (the brute-force check coarsens to 6 of them).
MIN_PLANES = 8
_BRUTE_BINS = 6


@renamed_fields(edges_mm="edges", depths_mm="depths")
@dataclass(frozen=True)
class SweepDesign:
    """A designed sweep and its predictions against the uniform (linear) sweep.

    Attributes
    ----------
    profile : MotionProfile
        Tabulated: knots at the bin edges, times ``Σ τ`` (normalised).
    tau, tau_linear : (N,) ndarray
        Exposure fractions per bin of the design and of the uniform sweep.
    edges : (N + 1,) ndarray
        Bin edges, sensor distances in mm, start → end.
    exposure_s : float
    mse, mse_linear : (n_depths, n_points) ndarray
        Predicted Wiener MSE per depth and field point (relative exposure²).
    points_uv : (n_points, 2) ndarray
    depths : (n_depths,) ndarray
        Depths of the design, mm.
    report : dict
        Everything ``mitsweep design-sweep --json`` prints.
    bank : PlaneBank or None
        The plane bank the design was optimised on.

    The former names ``edges_mm`` and ``depths_mm`` read on with a DeprecationWarning
    (the report keeps its keys).
    """

    profile: MotionProfile
    tau: np.ndarray
    tau_linear: np.ndarray
    edges: np.ndarray
    exposure_s: float
    mse: np.ndarray
    mse_linear: np.ndarray
    points_uv: np.ndarray
    depths: np.ndarray
    report: dict = field(default_factory=dict)
    bank: PlaneBank | None = field(default=None, repr=False)


#: The restorations a design can predict (:func:`design_sweep`'s ``restoration``).
RESTORATIONS = ("matched", "deployed")


def design_depths(setup: Setup) -> list[float]:
    """The setup's depth range's ends and the paper's V_avg depths within it, mm.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its ``[sweep]`` depth range.
    """
    s = setup.sweep
    inner = [d for d in V_DEPTHS_MM if s.depth_min <= d <= s.depth_max]
    return sorted({float(s.depth_min), *inner, float(s.depth_max)})


def design_points(setup: Setup, i_ref: float, geometry: ReferenceGeometry, *, n_radii: int,
                  grid: tuple[int, int], to_rim: bool = False) -> np.ndarray:
    """Field points: ``n_radii`` radii from the centre to the FOV's edge (untilted), or
    the centres of a grid over the sensor that see the mirror (tilted; the 2-D field).
    ``to_rim``: an untilted mirror's radii go on at their spacing beyond the FOV to the
    image of the mirror's rim (:func:`mitsweep.tracer.bank.rim_field_radius`), where
    the sweep does not reach focus but the image still has pixels.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sensor.
    i_ref : float
        Reference sensor distance, mm.
    geometry : mitsweep.optics.reference.ReferenceGeometry
        The reference grid.
    n_radii : int
        Radii of an untilted mirror's field.
    grid : tuple of int
        ``(rows, cols)`` of a tilted mirror's grid.
    to_rim : bool
        Radii beyond the FOV to the rim's image (untilted mirrors).
    """
    if setup.mirror.is_symmetric:
        r = np.linspace(0.0, field_radius(setup, geometry), int(n_radii))
        if to_rim:
            r = np.concatenate([r, rim_radii(r, rim_field_radius(setup, geometry))])
        return np.stack([r, np.zeros_like(r)], axis=1)
    pts = []
    for u, v in grid_points(setup, grid):
        try:
            source_from_image(setup, float(u), float(v), 1000.0, reference_sensor_distance=i_ref)
        except ValueError:
            continue
        pts.append((u, v))
    if not pts:
        raise SetupError("design: no grid point sees the mirror")
    return np.asarray(pts, dtype=float)


def blended_grid_points(setup: Setup, i_ref: float, grid: tuple[int, int]
                        ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """A tilted mirror's field points under the deployed restoration: the nodes of the
    grid bank it is restored with (cell centres of a ``grid`` over the sensor,
    :func:`mitsweep.tracer.bank.grid_points`) and the centres of the cells between
    them, those that see the mirror, with the blend of node filters that restores each
    (:func:`mitsweep.deconv.spatial.spatially_varying_deconvolve`): a node its own, a
    cell centre the four corners' at 1/4 each (-1: a corner off the mirror, whose bank
    kernel is a delta). Nodes and centres are a regular (checkerboard) sampling of the
    image: equal shares of it.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sensor.
    i_ref : float
        Reference sensor distance, mm.
    grid : (int, int)
        The grid bank's ``(rows, cols)`` (:func:`mitsweep.deconv.spatial.grid_bank_shape`).

    Returns
    -------
    points : (P, 2) ndarray
        Nodes first, then cell centres, (u, v) mm.
    blend : (index (P, 4), weight (P, 4))
        Each point's filters (point indices of nodes, -1 off the mirror) and weights.
    """
    rows, cols = (int(g) for g in grid)
    nodes = grid_points(setup, (rows, cols)).reshape(rows, cols, 2)

    def sees(u: float, v: float) -> bool:
        try:
            source_from_image(setup, u, v, 1000.0, reference_sensor_distance=i_ref)
        except ValueError:
            return False
        return True

    node_id = -np.ones((rows, cols), dtype=int)
    points: list[np.ndarray] = []
    index: list[list[int]] = []
    weight: list[list[float]] = []
    for r in range(rows):
        for c in range(cols):
            if sees(*(float(x) for x in nodes[r, c])):
                node_id[r, c] = len(points)
                points.append(nodes[r, c])
                index.append([len(points) - 1, -1, -1, -1])
                weight.append([1.0, 0.0, 0.0, 0.0])
    for r in range(rows - 1):
        for c in range(cols - 1):
            centre = nodes[r:r + 2, c:c + 2].reshape(4, 2).mean(axis=0)
            if sees(float(centre[0]), float(centre[1])):
                points.append(centre)
                index.append(node_id[r:r + 2, c:c + 2].ravel().tolist())
                weight.append([0.25] * 4)
    if not points:
        raise SetupError("design: no grid point sees the mirror")
    return np.asarray(points, dtype=float), (np.asarray(index), np.asarray(weight))


def image_area_weights(points: np.ndarray, symmetric: bool) -> np.ndarray:
    """Each field point's share of the image it stands for: an untilted mirror's radii
    ``0 … R`` (:func:`design_points`) the annuli between their midpoints (area
    ``π (r_hi² − r_lo²)``: the outer radii stand for most pixels), a tilted mirror's grid
    points equal shares (the cells of a regular grid). The mean objective weighs the
    predicted MSE by them, so that it is the mean over the image's pixels, as a PSNR
    over the image is, rather than over the design points.

    Parameters
    ----------
    points : (P, 2) ndarray
        The design's field points, mm (:func:`design_points`).
    symmetric : bool
        Whether they are an untilted mirror's radii (along ``u``).
    """
    points = np.asarray(points, dtype=float)
    if not symmetric or len(points) < 2:
        return np.full(len(points), 1.0 / len(points))
    r = np.hypot(points[:, 0], points[:, 1])
    mid = 0.5 * (r[1:] + r[:-1])
    lo = np.concatenate([[0.0], mid])
    hi = np.concatenate([mid, [r[-1]]])
    area = hi ** 2 - lo ** 2
    return area / area.sum()


def _predicted_errors(mse_lin: np.ndarray, mse: np.ndarray, points, depths,
                      point_weights: np.ndarray) -> dict:
    """A design report's predicted errors of the linear and the optimised profile
    (``(depths, points)`` MSE arrays): worst, mean over points × depths, mean over the
    image (:func:`image_area_weights`), where the worst lies, and per point."""
    out: dict = {"point_weights": point_weights.tolist()}
    for which, m in (("linear", mse_lin), ("optimized", mse)):
        image_mean = float(np.mean(m @ point_weights))
        out.update({f"{which}_worst_mse": float(m.max()), f"{which}_mean_mse": float(m.mean()),
                    f"{which}_image_mean_mse": image_mean,
                    f"{which}_worst_psnr_db": _psnr(float(m.max())),
                    f"{which}_mean_psnr_db": _psnr(float(m.mean())),
                    f"{which}_image_mean_psnr_db": _psnr(image_mean),
                    f"{which}_worst_at": _where(m, points, depths)})
    out["per_point"] = {"linear_mse": mse_lin.tolist(), "optimized_mse": mse.tolist()}
    return out


def _where(mse, points, depths) -> dict:
    d, p = np.unravel_index(int(np.argmax(mse)), mse.shape)
    u, v = (float(x) for x in points[p])
    return {"radius_mm": math.hypot(u, v), "u_mm": u, "v_mm": v, "depth_mm": float(depths[d]),
            "mse": float(mse[d, p])}


def _psnr(mse: float) -> float:
    return 10.0 * math.log10(1.0 / mse)


def _v_avg(kernels, depths) -> tuple[float, list]:
    """V_avg (Eq. 3) over the paper's depths when all are designed, else all depths."""
    sel = [j for j, d in enumerate(depths) if d in V_DEPTHS_MM]
    if len(sel) != len(V_DEPTHS_MM):
        sel = list(range(len(depths)))
    k = kernels[sel]
    k = k / k.sum(axis=(-2, -1), keepdims=True)
    return float(v_avg(k)), [float(depths[j]) for j in sel]


@renamed_keywords(span_mm="span", deploy_depth_mm="deploy_depth")
def design_sweep(setup: Setup, *, noise: SensorNoise, objective: str = "worst",
                 n_planes: int = 64, span: tuple[float, float] | None = None,
                 n_radii: int = 9, grid: tuple[int, int] | None = None,
                 depths: Sequence[float] | None = None, rays: int = DEFAULT_PLANE_RAYS,
                 kernel_size: int = 31, seed: int = 0, n_fft: int = DEFAULT_FFT_SIZE,
                 sub_planes: int = DEFAULT_SUB_PLANES, brute_force_steps: int = 16,
                 bank: PlaneBank | None = None,
                 progress: Callable[[], object] | None = None,
                 restoration: str = "matched", deploy_depth: float = 500.0,
                 deploy_nsr: float | None = None) -> SweepDesign:
    """Design the time profile of a focal sweep (objective in :mod:`mitsweep.design`).

    Parameters
    ----------
    setup : mitsweep.config.Setup
    noise : mitsweep.deconv.SensorNoise
        The sensor at the design's light level.
    objective : {"worst", "mean"}
        Minimise the largest predicted MSE over field points × depths, or the mean over
        the image: the depths alike, each field point weighted by the image area it
        stands for (:func:`image_area_weights`).
    n_planes : int
        Bins N of the span (>= 8).
    span : (start, end), optional
        Sensor distances the sweep runs between, mm (default: the optimal range,
        ``sensor_start`` → ``sensor_end``). The exposure is the setup's sweep exposure
        over the optimal range either way.
    n_radii, grid : field points (:func:`design_points`; ``grid`` default 5 x 5). Under
        the deployed restoration a tilted mirror's ``grid`` is the grid bank's it is
        restored with (default :func:`mitsweep.deconv.spatial.grid_bank_shape`, as
        datasets use), its nodes and cell centres the points
        (:func:`blended_grid_points`).
    depths : sequence of float, optional
        Default :func:`design_depths`.
    rays, kernel_size, seed, sub_planes : the plane banks (:func:`plane_bank`).
    n_fft : int
        DFT grid of the MSE sum.
    brute_force_steps : int
        Lattice resolution of the brute-force check (0 skips it; so does
        ``restoration="deployed"``, whose objective has no convex bound to check against).
    bank : PlaneBank, optional
        A plane bank of an earlier design of this setup with the same span, planes,
        points and depths (``SweepDesign.bank``): reused instead of traced again (the
        bank does not depend on the light level).
    progress : callable, optional
        Called after each traced point.
    restoration : {"matched", "deployed"}
        The restoration whose error is predicted: ``"matched"``, each depth restored
        with its own IPSF and the sensor's NSR (:func:`~mitsweep.design.wiener_model`,
        with a certified bound); ``"deployed"``, as the pipeline restores: every depth
        with the kernels at ``deploy_depth`` and the NSR ``deploy_nsr`` (default the
        sensor's; a dataset's is :func:`mitsweep.deconv.weights.model_nsr` of its
        images) (:func:`~mitsweep.design.objective.deployed_wiener_model`; no certified
        bound). When the designed profile does not beat the linear one under this
        model, the design returns the linear profile and says so
        (``report["returns_linear"]``).

    Returns
    -------
    SweepDesign

    Raises
    ------
    SetupError
        A span that reaches the focal length, that the stage cannot run in the exposure,
        or an unknown objective.
    """
    t_start = time.perf_counter()
    sweep = optimal_sweep_range(setup)
    T = float(sweep.exposure_s)
    start, end, limits = _checked_design_inputs(setup, sweep, span, objective, restoration,
                                                n_planes)
    rig = setup.rig
    depths = design_depths(setup) if depths is None else [float(d) for d in depths]
    N = int(n_planes)
    edges = np.linspace(start, end, N + 1)
    motion_lin = MotionProfile.linear(start, end)
    geom = reference_geometry(setup, sweep=sweep, motion=motion_lin)
    i_ref = geom.sensor_distance
    deployed = restoration == "deployed"
    points, blend, grid = _field(setup, geom, deployed, objective, n_radii, grid)
    trace_bank = functools.partial(plane_bank, rays=rays, kernel_size=kernel_size, seed=seed,
                                   sub_planes=sub_planes, progress=progress)
    if bank is None:
        bank = trace_bank(setup, points, depths, edges, reference_sensor_distance=i_ref)
    elif not (np.array_equal(bank.edges, edges) and np.array_equal(bank.points_uv, points)
              and np.array_equal(bank.depths, np.asarray(depths, dtype=float))):
        raise ValueError("bank: traced for other planes, points or depths than this design")
    widths = bank.widths
    n_px = math.sqrt(setup.sensor.resolution[0] * setup.sensor.resolution[1])
    t0 = time.perf_counter()

    def predictor(b: PlaneBank):
        if deployed:
            return deployed_wiener_model(b.kernels, b.depths, noise, n_fft=n_fft, n_px=n_px,
                                         deploy_depth=deploy_depth,
                                         deploy_nsr=deploy_nsr, blend=blend)
        return wiener_model(b.kernels, noise, n_fft=n_fft, n_px=n_px)

    model = predictor(bank)
    shape = (len(depths), len(points))
    point_weights = image_area_weights(points, setup.mirror.is_symmetric)
    weights = np.tile(point_weights, len(depths)) / len(depths)   # kernels: depth-major
    w = weights if objective == "mean" else None

    def reduced(m: np.ndarray) -> float:
        return float(m.max()) if objective == "worst" else float(np.ravel(m) @ weights)
    # the uniform sweep over the optimal range, same exposure: the baseline
    optimal = span is None or (np.isclose(start, sweep.sensor_start, rtol=0, atol=1e-12)
                                  and np.isclose(end, sweep.sensor_end, rtol=0, atol=1e-12))
    tau_lin = widths / widths.sum()
    if optimal:
        mse_lin = model.mse(tau_lin).reshape(shape)
        kernels_lin = bank.ipsf(tau_lin)
        lin_feasible = stage_feasible(tau_lin, widths, limits)
    else:
        mse_lin, kernels_lin = _linear_over_the_optimal_range(
            setup, sweep, N, depths, shape, trace_bank, predictor, n_radii=n_radii,
            grid=grid or (5, 5), points=points if blend is not None else None,
            rim_points=points if objective == "mean" and setup.mirror.is_symmetric else None)
        lin_feasible = True
    sol = local_optimum(model, widths, limits, objective=objective, weights=w)
    if deployed:
        bound, bound_info = None, {"relaxed_value": None}
    else:
        bound, bound_info = certified_lower_bound(model, widths, limits, objective=objective,
                                                  weights=w)
    free = local_optimum(model, widths, limits, objective=objective, acceleration=False,
                         weights=w)
    t_opt = time.perf_counter() - t0
    brute = None
    if brute_force_steps and not deployed:     # its check holds the convex bound's
        small = bank.coarsened(_BRUTE_BINS)
        brute = brute_force(predictor(small),
                            small.widths, limits, objective=objective,
                            steps=brute_force_steps, weights=w)
    # uniform τ is in the design's feasible set only when the span is the optimal range
    uniform_value = None
    if optimal and lin_feasible:
        uniform_value = reduced(mse_lin)
    tau = sol.tau
    times = np.concatenate([[0.0], np.cumsum(tau)])
    times[-1] = 1.0
    profile = MotionProfile.tabulated(times, edges)
    mse = sol.mse.reshape(shape)
    value = sol.value
    lin_value = reduced(mse_lin)
    returns_linear = bool(deployed and optimal and lin_feasible and value >= lin_value)
    if returns_linear:
        # under the deployed restoration no profile the optimiser found beats linear
        tau, mse, value = tau_lin, mse_lin, lin_value
        profile = motion_lin
    kernels = bank.ipsf(tau)
    v_opt, v_depths = _v_avg(kernels, depths)
    v_lin, _ = _v_avg(kernels_lin, depths)
    velocity = widths / (tau * T)
    accel = np.diff(velocity) / (np.minimum(tau[:-1], tau[1:]) * T)
    report = {
        "setup": setup.name, "objective": objective, "planes": N,
        "restoration": restoration,
        "deploy": ({"depth_mm": float(deploy_depth), "nsr": deploy_nsr,
                    "grid_bank": None if blend is None or grid is None
                    else [int(g) for g in grid]}
                   if deployed else None),
        "returns_linear": returns_linear,
        "span_mm": [start, end], "optimal_range_mm": [sweep.sensor_start, sweep.sensor_end],
        "exposure_s": T, "noise": noise.as_dict(), "depths_mm": list(depths),
        "points_uv_mm": points.tolist(),
        **_predicted_errors(mse_lin, mse, points, depths, point_weights),
        "linear_v_avg": v_lin, "optimized_v_avg": v_opt, "v_avg_depths_mm": v_depths,
        "tau": tau.tolist(), "edges_mm": edges.tolist(),
        "velocity_mm_s": [float(velocity.min()), float(velocity.max())],
        "max_acceleration_mm_s2": float(np.abs(accel).max()) if accel.size else 0.0,
        "stage_limits": {"max_velocity_mm_s": rig.max_velocity,
                         "acceleration_mm_s2": rig.acceleration},
        "certificate": _certificate(sol, value, bound, bound_info, uniform_value, free, brute,
                                    says=_verdict(returns_linear, bound, value, lin_value)),
        "seconds": {"plane_bank": bank.metadata["seconds"], "optimise_and_bound": t_opt,
                    "brute_force": None if brute is None else brute["seconds"],
                    "total": time.perf_counter() - t_start},
        "plane_bank": {k: bank.metadata[k] for k in ("rays", "sub_planes", "seed",
                                                     "kernel_size")},
        "n_fft": int(n_fft),
    }
    return SweepDesign(profile=profile, tau=tau, tau_linear=tau_lin, edges=edges,
                       exposure_s=T, mse=mse, mse_linear=mse_lin, points_uv=points,
                       depths=np.asarray(depths), report=report, bank=bank)


def _field(setup: Setup, geom: ReferenceGeometry, deployed: bool, objective: str,
           n_radii: int, grid: tuple[int, int] | None):
    """:func:`design_sweep`'s field points, their blend of filters (None: each its own)
    and the grid they come from."""
    if deployed and not setup.mirror.is_symmetric:
        # restored between the bank's nodes by a blend of their filters
        grid = grid or grid_bank_shape(setup)
        points, blend = blended_grid_points(setup, geom.sensor_distance, grid)
        return points, blend, grid
    # the image's mean has pixels beyond the FOV (29 % of the paraboloid's mirror image)
    grid = grid or (5, 5)
    return design_points(setup, geom.sensor_distance, geom, n_radii=n_radii, grid=grid,
                         to_rim=objective == "mean"), None, grid


def _checked_design_inputs(setup: Setup, sweep, span, objective: str, restoration: str,
                           n_planes: int) -> tuple[float, float, StageLimits]:
    """The design's sensor span ``(start, end)`` (mm; the optimal range unless ``span``)
    and the stage's limits, after the checks of :func:`design_sweep`'s arguments against
    the setup's lens and rig (:class:`SetupError` naming what is wrong)."""
    if objective not in OBJECTIVES:
        raise SetupError(f"objective: must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if restoration not in RESTORATIONS:
        raise SetupError(f"restoration: must be one of {', '.join(RESTORATIONS)}, got "
                         f"{restoration!r}")
    if int(n_planes) < MIN_PLANES:
        raise SetupError(f"planes: need at least {MIN_PLANES}, got {n_planes}")
    T = float(sweep.exposure_s)
    f = setup.lens.focal_length
    start, end = (sweep.sensor_start, sweep.sensor_end) if span is None else \
        (float(span[0]), float(span[1]))
    if not (math.isfinite(start) and math.isfinite(end)) or start == end:
        raise SetupError(f"span: need two different finite sensor distances, got "
                         f"{start:g} {end:g} mm")
    if min(start, end) <= f:
        raise SetupError(f"span {start:g} .. {end:g} mm reaches the lens focal length "
                         f"({f:g} mm): both ends must be > {f:g} mm")
    rig = setup.rig
    limits = StageLimits(exposure_s=T, max_velocity=rig.max_velocity,
                         acceleration=rig.acceleration)
    if abs(end - start) > rig.travel:
        raise SetupError(f"span {start:g} .. {end:g} mm: travel {abs(end - start):g} mm exceeds "
                         f"rig.travel ({rig.travel:g} mm)")
    if abs(end - start) / T > rig.max_velocity:
        raise SetupError(f"span {start:g} .. {end:g} mm cannot be swept in the exposure "
                         f"{T:g} s: it needs at least {abs(end - start) / T:g} mm/s, more than "
                         f"rig.max_velocity ({rig.max_velocity:g} mm/s)")
    if not rig.min_exposure_s <= T <= rig.max_exposure_s:
        raise SetupError(f"exposure {T:g} s is outside rig.min_exposure_s .. rig.max_exposure_s")
    return start, end, limits


def _linear_over_the_optimal_range(setup: Setup, sweep, N: int, depths, shape, trace_bank,
                                   predictor, *, n_radii: int, grid: tuple[int, int],
                                   rim_points: np.ndarray | None = None,
                                   points: np.ndarray | None = None):
    """The baseline of a design over another span: the linear sweep over the optimal
    range, traced on its own planes and points; its predicted MSE (``shape``) and its
    kernels. ``rim_points``: the design's radii to the rim, scaled to this geometry's rim
    (the same count); ``points``: the design's own (a grid bank's nodes and centres)."""
    lin_edges = np.linspace(sweep.sensor_start, sweep.sensor_end, N + 1)
    lin_geom = reference_geometry(setup, sweep=sweep)
    if points is not None:
        lin_points = points
    elif rim_points is not None:
        lin_points = rim_points * (rim_field_radius(setup, lin_geom)
                                   / float(np.hypot(*rim_points.T).max()))
    else:
        lin_points = design_points(setup, lin_geom.sensor_distance, lin_geom,
                                   n_radii=n_radii, grid=grid)
    lin_bank = trace_bank(setup, lin_points, depths, lin_edges,
                          reference_sensor_distance=lin_geom.sensor_distance)
    lw = lin_bank.widths
    mse_lin = predictor(lin_bank).mse(lw / lw.sum()).reshape(shape)
    return mse_lin, lin_bank.ipsf(lw / lw.sum())


def _verdict(returns_linear: bool, bound: float | None, value: float,
             lin_value: float) -> str:
    """What a design says of itself (its report's ``certificate.says``)."""
    if returns_linear:
        return ("no profile found beats the linear sweep under the deployed restoration: "
                "the design is the linear sweep")
    if bound is None:  # the deployed restoration
        return ("the deployed restoration's objective has no certified bound; the "
                f"profile found predicts {value:.6g} against linear {lin_value:.6g}")
    gap = value - bound
    return (f"the optimum of this objective (worst/mean predicted MSE over the "
            f"bank, these stage limits) lies in [{bound:.6g}, {value:.6g}]: the "
            f"profile found is within {100 * gap / value:.3g} % of it")


def _certificate(sol, value: float, bound: float | None, bound_info: dict,
                 uniform_value: float | None, free, brute, *, says: str) -> dict:
    """A design report's ``certificate``: the objective's value, its lower bound and gap
    (None under the deployed restoration), the baselines and the optimiser's record."""
    gap = None if bound is None else value - bound
    return {"objective_value": value, "lower_bound": bound,
            "gap": gap, "relative_gap": None if gap is None else gap / value,
            "uniform_value": uniform_value, "relaxed_value": bound_info["relaxed_value"],
            "without_acceleration_value": free.value,
            "starts": sol.info["starts"], "best_start": sol.info["best_start"],
            "iterations": sol.info["iterations"], "says": says, "brute_force": brute}
