"""PSFs at one sensor distance and IPSFs over a focal sweep (paper Sec. 3).

An IPSF is the time average of the PSF while the sensor moves,

.. math:: \\mathrm{IPSF}(x) = \\int_0^1 \\mathrm{PSF}\\big(x;\\, i(t)\\big)\\,dt ,

with ``i(t)`` the stage motion (:class:`mitsweep.optics.motion.MotionProfile`, linear by
default). Each traced ray lands at ``h(i) = A + B i`` (affine in the sensor distance,
see :mod:`mitsweep.tracer.kernel`), so over the sweep its hit runs along a straight
segment, and the sweep integral of one ray is that segment deposited exactly
(``method="exact"``, the default): each pixel receives the fraction of the exposure the
hit spends in it, with no time samples. ``method="continuous"`` deposits each ray at
``M`` stratified, jittered times ``t_j = (j + ξ)/M`` instead (ξ from a low-discrepancy
sequence, different for every ray); the paper's sum over ``N`` focal planes
(``method="planes"``) is offered for comparison. The exact method reaches a given L1
error with 3–5× fewer rays than 4 stratified times per ray (docs: IPSF convergence).
Pixels are those of the sensor (physical positions, so magnification breathing is
included), binned on the grid of the
reference sensor distance (mid-travel) around the chief-ray image there: row = down the
image (−v), column = right (+u), the chief-ray image at ``[K//2, K//2]``.

Sampling is importance-driven and adaptive: rays are drawn in a box of the aim plane
(perpendicular to the chief ray at the mirror point) fitted by pilot passes to the
rays that reach the lens aperture, or in an ellipse fitted inside it, so typically ~90 %
of traced rays land.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Setup
from ..optics.motion import MotionProfile
from ..optics.pixels import optical_center_px, pixel_to_sensor
from ..optics.reference import reference_geometry
from ..optics.sweep import SweepRange
from ..resources import check_allocation
from .kernel import (DepositStrategy, Geometry, SourceBatch, TraceParams, deposit,
                     deposit_batch, deposit_copies, deposit_segments, fold_buffer,
                     resolve_strategy, trace_arrays, trace_arrays_batch)
from .settings import (DEFAULT_KERNEL_SIZE, DEFAULT_RAYS, DEFAULT_TIME_SAMPLES, METHODS,
                       TraceSettings, settings_from_keywords)
from .source import PointSource, source_from_image

__all__ = ["integrated_psf", "integrated_psfs", "psf", "render_source", "render_sources",
           "fit_sampling_box", "fit_sampling_boxes", "METHODS",
           "DEFAULT_RAYS", "DEFAULT_KERNEL_SIZE",
           "DEFAULT_TIME_SAMPLES", "TraceSettings"]

logger = logging.getLogger(__name__)

#: Rays per launch: the kernel holds no per-ray arrays, so this bounds only the index
#: range; 2^24 keeps the per-launch cost (graph, literals, launch) under 1 %.
_CHUNK = 1 << 24
#: Rays per source from which a batch deposits source by source (one-source launches,
#: literals) instead of in batched launches (per-lane table reads): measured on the
#: 2-core LLVM machine, the table reads cost ~30 % of the trace, a launch ~2-4 ms.
BATCH_DEPOSIT_RAYS = 1 << 18
_PILOT_LOG2 = 14
_PILOT = 1 << _PILOT_LOG2
_PILOT_KEYS = ("landed_free", "a", "b")
_PILOT_RAY_BYTES = 2 * (1 + 4 + 4) + 8 + 8 + 1
_SENSOR_TABLE = 4097
#: Chords per ramp of a trapezoidal motion in the exact method's time CDF: its sensor
#: distance then deviates from the parabola by < |Δi| a / (8·256² (1 − a)) mm
#: (:meth:`MotionProfile.segments`), ~1e-7 mm on the paper's sweeps.
_RAMP_CHORDS = 256
#: Bytes per kernel pixel while an IPSF is binned: the Dr.Jit buffer (float32), its
#: float64 copy, the normalised kernel, the index grids and centroid products.
KERNEL_PIXEL_BYTES = 64


def fit_sampling_box(geom: Geometry, *, seed: int = 0, double: bool = False,
                     max_rounds: int = 40) -> tuple[TraceParams, dict]:
    """Fit the aim-plane sampling box to the rays that reach the lens (rim ignored).

    Pilot passes of 2^14 low-discrepancy rays grow the box while landed rays touch its
    edge and shrink it to their bounding box (plus three lattice spacings) while it is
    loose; the box returned is always one a pilot pass found no landed ray near the
    edges of. The rim is ignored here so that the vignetted fraction can be measured.
    Where a validated ellipse around the footprint is smaller than the box, the rays are
    drawn in the ellipse instead (:func:`_fit_ellipse`): ~90 % of them then land, against
    ~71 % (an ellipse fills π/4 of its bounding box).

    Parameters
    ----------
    geom : Geometry
        The source's geometry (:meth:`mitsweep.tracer.source.PointSource.geometry`).
    seed : int, optional
        Seed of the pilot passes' lattice, and of the returned ``params`` (default 0).
    double : bool, optional
        Trace the pilot passes in float64 (default float32).
    max_rounds : int, optional
        Pilot passes at most (default 40).

    Returns
    -------
    params : TraceParams
    info : dict
        ``pilot_rays`` traced, ``box_mm`` (a0, a1, b0, b1), ``ellipse_mm`` (the
        sampling ellipse ``(ca, cb, m00, m01, m10, m11)`` of :class:`TraceParams`, or None
        where the box is used).

    Raises
    ------
    ValueError
        If no ray from the source reaches the lens aperture.
    """
    steps = _sampling_box_steps(geom, seed=seed, max_rounds=max_rounds)
    request = next(steps)
    while True:
        try:
            request = steps.send(trace_arrays(geom, request, _PILOT, double=double,
                                              keys=_PILOT_KEYS))
        except StopIteration as done:
            return done.value


def fit_sampling_boxes(geoms: Iterable[Geometry], *, seeds: Iterable[int],
                       double: bool = False, max_rounds: int = 40
                       ) -> list[tuple[TraceParams, dict] | ValueError]:
    """:func:`fit_sampling_box` for many sources at once: each pilot round is one launch.

    The sources run the same algorithm in lockstep; each round traces the pending pilot
    pass of every source still fitting in one :func:`~mitsweep.tracer.kernel.
    trace_arrays_batch` launch, so a bank pays the launch and read-back cost once per
    round instead of once per source and round. Every source gets the box (and ellipse)
    :func:`fit_sampling_box` gives it: the pilot rays are the same, bit for bit.

    Parameters
    ----------
    geoms : iterable of Geometry
        The sources' geometries.
    seeds : iterable of int
        One seed per source, as :func:`fit_sampling_box`'s ``seed``.
    double, max_rounds
        As :func:`fit_sampling_box`.

    Returns
    -------
    list
        Per source ``(params, info)``, or the ``ValueError`` its fit raised.
    """
    geoms = list(geoms)
    # a round's three arrays per ray, in Dr.Jit (float32, bool) and as float64 NumPy copies
    check_allocation(f"pilot rounds of {len(geoms)} sources", len(geoms) * _PILOT * _PILOT_RAY_BYTES)
    results: list = [None] * len(geoms)
    pending = {}
    for j, (geom, seed) in enumerate(zip(geoms, seeds)):
        steps = _sampling_box_steps(geom, seed=int(seed), max_rounds=max_rounds)
        pending[j] = (steps, next(steps))
    while pending:
        order = sorted(pending)
        batch = SourceBatch([geoms[j] for j in order], [pending[j][1] for j in order],
                            double=double)
        traced = trace_arrays_batch(batch, _PILOT_LOG2, keys=_PILOT_KEYS)
        for j, r in zip(order, traced):
            steps = pending[j][0]
            try:
                pending[j] = (steps, steps.send(r))
            except StopIteration as done:
                results[j] = done.value
                del pending[j]
            except ValueError as exc:
                results[j] = exc
                del pending[j]
    return results


def _sampling_box_steps(geom, *, seed: int, max_rounds: int):
    """The fit of :func:`fit_sampling_box` as a generator: it yields the TraceParams of
    each pilot pass (``_PILOT`` rays, keys ``_PILOT_KEYS``), is sent the traced arrays,
    and returns ``(params, info)``."""
    cos_i = abs(float(geom.w @ np.array([0.0, 0.0, 1.0])))
    h0 = max(geom.aperture_radius * (0.5 * geom.radius + 1.0) / geom.vertex_distance, 1e-3)
    a0, a1, b0, b1 = -h0, h0, -h0 / max(cos_i, 0.05), h0 / max(cos_i, 0.05)
    traced = 0
    for _ in range(max_rounds):
        params = TraceParams(a0, a1, b0, b1, seed=seed + 7919)
        r = yield params
        traced += _PILOT
        ok = r["landed_free"]
        wa, wb = a1 - a0, b1 - b0
        if not ok.any():
            if max(wa, wb) > 4.0 * geom.margin:
                raise ValueError("no ray from this point source reaches the lens aperture "
                                 "(the point is fully vignetted or hidden)")
            ca, cb = 0.5 * (a0 + a1), 0.5 * (b0 + b1)
            a0, a1, b0, b1 = ca - 2 * wa, ca + 2 * wa, cb - 2 * wb, cb + 2 * wb
            continue
        sa, sb = r["a"][ok], r["b"][ok]
        # Lattice spacing of the pilot ~ width / sqrt(n): landed rays closer than one
        # spacing to an edge may continue beyond it (grow); otherwise the footprint ends
        # within a spacing of the landed rays' bounding box (keep three).
        ga, gb = wa / math.sqrt(_PILOT), wb / math.sqrt(_PILOT)
        lo_a, hi_a, lo_b, hi_b = sa.min(), sa.max(), sb.min(), sb.max()
        grow = False
        if lo_a - a0 < ga:
            a0, grow = a0 - wa, True
        if a1 - hi_a < ga:
            a1, grow = a1 + wa, True
        if lo_b - b0 < gb:
            b0, grow = b0 - wb, True
        if b1 - hi_b < gb:
            b1, grow = b1 + wb, True
        if grow:
            continue
        na0, na1 = lo_a - 3 * ga, hi_a + 3 * ga
        nb0, nb1 = lo_b - 3 * gb, hi_b + 3 * gb
        tight = (na1 - na0) > 0.9 * wa and (nb1 - nb0) > 0.9 * wb
        if tight:
            # Keep the box this pass validated (no landed ray near its edges); a shrunk
            # box would be returned untested, and a footprint thinner than the pilot's
            # lattice could then reach past it (seen: 2 % of the flux lost, unreported,
            # for a steep hyperboloid at 1e9 mm).
            break
        a0, a1, b0, b1 = na0, na1, nb0, nb1
    else:
        logger.warning("sampling box not settled after %d pilot rounds", max_rounds)
    # A steep mirror can send light into the lens from a second, detached part of its
    # surface (a second image of the point: seen on a hyperboloid, R 9, k -2, at
    # 1e9 mm, 2.7 % of the flux). Growing from the first footprint never finds it, so
    # probe a box three times as wide and take in whatever lands there.
    for _ in range(4):
        wa, wb = a1 - a0, b1 - b0
        probe = TraceParams(a0 - wa, a1 + wa, b0 - wb, b1 + wb, seed=seed + 104729)
        r = yield probe
        traced += _PILOT
        ok = r["landed_free"]
        sa, sb = r["a"][ok], r["b"][ok]
        out = (sa < a0) | (sa > a1) | (sb < b0) | (sb > b1)
        if not out.any():
            break
        ga, gb = 3 * wa / math.sqrt(_PILOT), 3 * wb / math.sqrt(_PILOT)
        a0, a1 = min(a0, sa.min() - 3 * ga), max(a1, sa.max() + 3 * ga)
        b0, b1 = min(b0, sb.min() - 3 * gb), max(b1, sb.max() + 3 * gb)
    params = TraceParams(a0, a1, b0, b1, seed=seed)
    ellipse, n_pilot = yield from _fit_ellipse(geom, params, seed=seed)
    traced += n_pilot
    if ellipse is not None:
        params = TraceParams(a0, a1, b0, b1, seed=seed, ellipse=ellipse)
    return params, {"pilot_rays": traced, "box_mm": [a0, a1, b0, b1],
                    "ellipse_mm": None if ellipse is None else list(ellipse)}


def _fit_ellipse(geom, box: TraceParams, *, seed: int):
    """An ellipse around the footprint the box holds, if it is validated and smaller.

    The landed rays of a pilot pass in the box are whitened by their covariance; the
    ellipse is their largest whitened radius ρ plus three lattice spacings
    ``ρ √(π / n_landed)``. A pilot pass in the ellipse then must find no landed ray within
    1.5 of its lattice spacings of its edge (else it grows by 25 %, at most 3 times); an ellipse not
    smaller than 0.9 of the box is not used. Returns ``(ellipse or None, pilot rays)``; a
    generator like :func:`_sampling_box_steps`.
    """
    r = yield box
    traced = _PILOT
    ok = r["landed_free"]
    n_ok = int(ok.sum())
    if n_ok < 256:
        return None, traced
    pa, pb = r["a"][ok], r["b"][ok]
    centre = (float(pa.mean()), float(pb.mean()))
    da, db = pa - centre[0], pb - centre[1]
    # Cholesky factor [[l00, 0], [l10, l11]] of the sample covariance, written out (2x2)
    # (x * y).sum(), not x @ y: BLAS threads fight the tracer's for the cores (11 ms a dot)
    caa, cab, cbb = (float((x * y).sum()) / (n_ok - 1) for x, y in ((da, da), (da, db), (db, db)))
    l00 = math.sqrt(caa) if caa > 0 else 0.0
    l10 = cab / l00 if l00 > 0 else 0.0
    schur = cbb - l10 * l10
    if not (l00 > 0 and schur > 0):  # a degenerate (line-like) footprint
        return None, traced
    l11 = math.sqrt(schur)

    def whitened_radius(xa, xb):  # |L⁻¹ (x − centre)|
        z0 = (xa - centre[0]) / l00
        z1 = (xb - centre[1] - l10 * z0) / l11
        return np.sqrt(z0 * z0 + z1 * z1)

    rho = float(whitened_radius(pa, pb).max())
    spacing = rho * math.sqrt(math.pi / n_ok)
    radius = rho + 3.0 * spacing
    for _ in range(4):
        ellipse = (centre[0], centre[1], l00 * radius, 0.0, l10 * radius, l11 * radius)
        trial = TraceParams(box.a0, box.a1, box.b0, box.b1, seed=seed + 15485863,
                            ellipse=ellipse)
        if trial.area > 0.9 * box.area:
            return None, traced
        r = yield trial
        traced += _PILOT
        ok = r["landed_free"]
        if not ok.any():
            return None, traced
        z = whitened_radius(r["a"][ok], r["b"][ok])
        # the trial's own lattice spacing, whitened: radius · sqrt(π / n)
        if z.max() < radius * (1.0 - 1.5 * math.sqrt(math.pi / _PILOT)):
            return ellipse, traced
        radius *= 1.25
    return None, traced


def sweep_cdf(motion: MotionProfile, n: int = _SENSOR_TABLE) -> np.ndarray | None:
    """The motion's time CDF over its span, for the exact method; None when it is linear.

    ``F(s)``, at ``n`` uniform ``s = (i − i_lo)/(i_hi − i_lo)`` over the span
    ``[i_lo, i_hi]`` of the sensor distance: the fraction of the exposure during which
    the sensor distance is ≤ ``i``. Built from the motion's piecewise-linear knots
    (:meth:`MotionProfile.segments`), each chord adding its duration spread uniformly over
    the distances it covers, so non-monotonic (measured) motions are handled too.

    Parameters
    ----------
    motion : MotionProfile
        The stage's motion.
    n : int, optional
        Table size: values of ``F`` at ``n`` uniform ``s`` from 0 to 1.

    Returns
    -------
    (n,) ndarray or None
        ``F``, from 0 to 1; None for a linear motion (``F(s) = s``) and for a sensor that
        stands still.
    """
    if motion.kind == "linear":
        return None
    lo, hi = motion.span
    if not hi > lo:
        return None  # the sensor stands still: every ray deposits at one point
    t, pos = motion.segments(_RAMP_CHORDS)
    s = np.linspace(0.0, 1.0, int(n))
    i = lo + s * (hi - lo)
    cdf = np.zeros_like(s)
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        p0, p1 = sorted((pos[k], pos[k + 1]))
        if p1 > p0:
            cdf += dt * np.clip((i - p0) / (p1 - p0), 0.0, 1.0)
        else:
            cdf += dt * (i >= p0)
    cdf /= cdf[-1]
    cdf[0] = 0.0
    return cdf


@dataclass(frozen=True)
class _DepositArgs:
    """What the deposit launches of one trace share: the sweep's sampling
    (:func:`_sweep_arguments`), the precision and the deposit strategy."""

    exact: bool
    times: list | None
    linear: tuple[float, float] | None
    sensor_table: np.ndarray | None
    cdf_table: np.ndarray | None
    span: tuple[float, float] | None
    time_samples: int
    double: bool
    strategy: DepositStrategy

    def kernel_keywords(self) -> dict[str, Any]:
        """Keywords of :func:`~mitsweep.tracer.kernel.deposit_segments` (``exact``) or
        :func:`~mitsweep.tracer.kernel.deposit`."""
        if self.exact:
            return {"span": self.span, "cdf_table": self.cdf_table, "strategy": self.strategy}
        return {"times": self.times, "sensor_table": self.sensor_table, "linear": self.linear,
                "time_samples": self.time_samples, "strategy": self.strategy}


def _deposit_args(setup, *, times, motion, exact, time_samples, double,
                  deposit: DepositStrategy | None) -> _DepositArgs:
    """:func:`_sweep_arguments` with the rest of a trace's deposit arguments."""
    times, linear, table, cdf = _sweep_arguments(setup, times=times, motion=motion,
                                                 exact=exact, time_samples=time_samples)
    return _DepositArgs(exact=bool(exact and times is None), times=times, linear=linear,
                        sensor_table=table, cdf_table=cdf,
                        span=None if motion is None else motion.span,
                        time_samples=int(time_samples), double=bool(double),
                        strategy=resolve_strategy(deposit))


def _sweep_arguments(setup, *, times, motion, exact, time_samples):
    """Validated deposit arguments: ``(times, linear, sensor_table, cdf_table)``."""
    linear = table = cdf = None
    if times is None:
        if motion is None:
            raise ValueError("render_source: give sensor distances or a motion profile")
        if exact:
            cdf = sweep_cdf(motion)
        elif not 1 <= int(time_samples) <= 64:
            raise ValueError(f"time_samples: must be in [1, 64], got {time_samples!r}")
        elif motion.kind == "linear":
            linear = (motion.start, motion.end)
        else:
            table = np.asarray(motion.sensor_distance(np.linspace(0.0, 1.0, _SENSOR_TABLE)))
    else:
        times = [float(x) for x in np.atleast_1d(times)]
        if not times or len(times) > 64:
            raise ValueError(f"sensor distances: give 1 to 64 of them, got {len(times)}")
        if not all(x > setup.lens.focal_length for x in times):
            raise ValueError(f"sensor distances must be > lens.focal_length "
                             f"({setup.lens.focal_length:g} mm), got min {min(times):g}")
    return times, linear, table, cdf


def _check_sizes(kernel_size, rays, sources: int = 1) -> tuple[int, int]:
    K = int(kernel_size)
    if K < 3 or K % 2 == 0:
        raise ValueError(f"kernel_size: must be an odd integer >= 3, got {kernel_size!r}")
    check_allocation(f"{sources} x {K}x{K} px kernel{'s' if sources > 1 else ''}",
                     sources * K * K * KERNEL_PIXEL_BYTES)
    rays = int(rays)
    if rays < 1:
        raise ValueError(f"rays: must be >= 1, got {rays!r}")
    return K, rays


def render_source(setup: Setup, source: PointSource, *, times: ArrayLike | None = None,
                  motion: MotionProfile | None = None,
                  time_samples: int = DEFAULT_TIME_SAMPLES, exact: bool = False,
                  rays: int = DEFAULT_RAYS,
                  kernel_size: int = DEFAULT_KERNEL_SIZE, seed: int = 0,
                  double: bool = False, aperture_radius: float | None = None,
                  deposit: DepositStrategy | None = None
                  ) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """Trace ``rays`` rays from ``source`` and bin them on the reference pixel grid.

    Give either fixed sensor distances ``times`` (mm; equal weights) or a ``motion``,
    with ``time_samples`` stratified times per ray, or, with ``exact``, each ray's whole
    sweep deposited as its segment (:func:`mitsweep.tracer.kernel.deposit_segments`),
    the way ``deposit`` says (default :class:`~mitsweep.tracer.kernel.DepositStrategy`).
    Returns ``(kernel, info)`` as :func:`integrated_psf`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The optics; the kernel's pixels are ``setup.sensor.pixel_pitch`` wide.
    source : PointSource
        The point source, with its chief-ray image ``image_uv`` (the window's centre).
    times : array_like, optional
        Fixed sensor distances, mm, each weighted equally (a PSF, or the paper's plane
        sum).
    motion : MotionProfile, optional
        The stage's motion, used when ``times`` is None.
    time_samples : int, optional
        Stratified times per ray along ``motion`` (without ``exact``).
    exact : bool, optional
        Deposit each ray's whole sweep segment instead of time samples.
    rays : int, optional
        Rays traced, >= 1.
    kernel_size : int, optional
        K, px: odd, >= 3.
    seed : int, optional
        Seed of the sample stream (default 0).
    double : bool, optional
        Trace in float64 (default float32).
    aperture_radius : float, optional
        Override the lens aperture radius, mm.
    deposit : DepositStrategy, optional
        How the weights are added (the speed, not the result).

    Returns
    -------
    kernel : (K, K) float32 ndarray
    info : dict
        As :func:`integrated_psf`.
    """
    K, rays = _check_sizes(kernel_size, rays)
    t_start = time.perf_counter()
    geom = source.geometry(setup, aperture_radius=aperture_radius)
    params, box_info = fit_sampling_box(geom, seed=seed, double=double)
    pitch = setup.sensor.pixel_pitch
    args = _deposit_args(setup, times=times, motion=motion, exact=exact,
                         time_samples=time_samples, double=double, deposit=deposit)
    buf = _deposit_source(geom, params, source.image_uv, rays, K, pitch, args)
    return _kernel_and_info(buf, K, rays, source, box_info, seed=seed, double=double,
                            seconds=time.perf_counter() - t_start, pitch=pitch)


def _deposit_source(geom, params, center_uv, rays, K, pitch, args: _DepositArgs
                    ) -> np.ndarray:
    """Trace and deposit ``rays`` rays of one source; its (K·K + 2) buffer as NumPy."""
    import drjit as dr

    buffer = None
    done = 0
    launch = deposit_segments if args.exact else deposit
    while done < rays:  # chunks bound the memory: the kernel holds no per-ray arrays
        n = min(_CHUNK, rays - done)
        buffer = launch(geom, params, n, offset=done, kernel_size=K, pixel_pitch=pitch,
                        center_uv=center_uv, buffer=buffer, double=args.double,
                        **args.kernel_keywords())
        dr.eval(buffer)
        done += n
    dr.sync_thread()
    return fold_buffer(buffer, 1, K)[0]


def render_sources(setup: Setup, sources: Iterable[PointSource], *, seeds: Iterable[int],
                   times: ArrayLike | None = None, motion: MotionProfile | None = None,
                   time_samples: int = DEFAULT_TIME_SAMPLES, exact: bool = False,
                   rays: int = DEFAULT_RAYS, kernel_size: int = DEFAULT_KERNEL_SIZE,
                   double: bool = False, aperture_radius: float | None = None,
                   progress: Callable[[], object] | None = None,
                   deposit: DepositStrategy | None = None
                   ) -> list[tuple[NDArray[np.float32], dict[str, Any]] | ValueError]:
    """:func:`render_source` for many sources of one setup, traced together.

    Each pilot round of the sampling-box fits is one launch (:func:`fit_sampling_boxes`),
    and the deposit launches trace ``2^p`` samples of every source at once
    (:func:`mitsweep.tracer.kernel.deposit_batch`, ``2^p`` the largest power of two that
    fits the samples left and the chunk), so the fixed cost of a launch (compile-cache
    lookup, literals, synchronisation, read-back: ~10–25 ms per IPSF one by one) is paid
    once per launch, not per source. Source ``j``'s rays are those :func:`render_source`
    traces with ``seed=seeds[j]``: the kernels agree up to the float64 summation order.

    Parameters
    ----------
    sources : sequence of PointSource
    seeds : sequence of int
        One per source.
    progress : callable, optional
        Called with no argument once per source's worth of rays traced.
    Others
        As :func:`render_source` (``deposit`` included).

    Returns
    -------
    list
        Per source ``(kernel, info)`` as :func:`render_source` returns, or the
        ``ValueError`` that source raised (fully vignetted, PSF outside the window);
        ``info["seconds"]`` is the batch's wall time shared equally, ``info["batch_size"]``
        the number of sources traced together.
    """
    sources, seeds = list(sources), [int(x) for x in seeds]
    if len(seeds) != len(sources):
        raise ValueError(f"seeds: give one per source ({len(sources)}), got {len(seeds)}")
    if not sources:
        return []
    K, rays = _check_sizes(kernel_size, rays, len(sources))
    strategy = resolve_strategy(deposit)
    # the stacked float64 buffer (its copies, kernel.deposit_copies) and NumPy copies
    check_allocation(f"deposit buffer of {len(sources)} IPSFs",
                     len(sources) * (K * K + 2) * 8 * (2 * deposit_copies(strategy) + 1))
    t_start = time.perf_counter()
    args = _deposit_args(setup, times=times, motion=motion, exact=exact,
                         time_samples=time_samples, double=double, deposit=strategy)
    geoms = [s.geometry(setup, aperture_radius=aperture_radius) for s in sources]
    fits = fit_sampling_boxes(geoms, seeds=seeds, double=double)
    fitted = {j: f for j, f in enumerate(fits) if not isinstance(f, Exception)}
    ok = list(fitted)
    results: list = list(fits)
    if progress is not None:
        for _ in range(len(sources) - len(ok)):
            progress()
    if not ok:
        return results
    pitch = setup.sensor.pixel_pitch
    if rays >= BATCH_DEPOSIT_RAYS:
        # Many rays per source: the launch cost is amortised, and the literals of a
        # one-source launch are cheaper than the batch's per-lane table reads.
        buf = np.empty((len(ok), K * K + 2))
        for row, j in enumerate(ok):
            buf[row] = _deposit_source(geoms[j], fitted[j][0], sources[j].image_uv, rays, K,
                                       pitch, args)
            if progress is not None:
                progress()
    else:
        buf = _deposit_batch(SourceBatch([geoms[j] for j in ok], [fitted[j][0] for j in ok],
                                         center_uv=[sources[j].image_uv for j in ok],
                                         double=double),
                             rays, K, pitch, args, progress=progress)
    seconds = (time.perf_counter() - t_start) / len(sources)
    for row, j in enumerate(ok):
        try:
            kernel, info = _kernel_and_info(buf[row], K, rays, sources[j], fitted[j][1],
                                            seed=seeds[j], double=double, seconds=seconds,
                                            pitch=pitch)
            info["batch_size"] = len(sources)
            results[j] = (kernel, info)
        except ValueError as exc:
            results[j] = exc
    return results


def _deposit_batch(batch, rays, K, pitch, args: _DepositArgs, *, progress) -> np.ndarray:
    """Trace and deposit ``rays`` rays of every source of ``batch``; (S, K·K + 2) NumPy."""
    import drjit as dr

    per_launch = max(_CHUNK // batch.size, 1)
    buffer = None
    done = reported = 0
    while done < rays:
        log2_count = min(rays - done, per_launch).bit_length() - 1
        buffer = deposit_batch(batch, log2_count, offset=done, kernel_size=K, pixel_pitch=pitch,
                               exact=args.exact, buffer=buffer, **args.kernel_keywords())
        dr.eval(buffer)
        done += 1 << log2_count
        if progress is not None:
            for _ in range(batch.size * done // rays - reported):
                progress()
            reported = batch.size * done // rays
    dr.sync_thread()
    return fold_buffer(buffer, batch.size, K)


def _kernel_and_info(buf, K, rays, source, box_info, *, seed, double, seconds, pitch):
    """Normalise a (K·K + 2) deposit buffer into the kernel and its ``info``."""
    KK = K * K
    img = buf[:KK].reshape(K, K)
    in_w = img.sum()
    landed_w = in_w + buf[KK]
    free_w = landed_w + buf[KK + 1]
    if not landed_w > 0:
        raise ValueError("no traced ray landed on the sensor: the point is fully vignetted")
    total = img.sum()
    if not total > 0:
        raise ValueError(f"the whole PSF falls outside the {K}x{K} kernel window")
    kernel = (img / total).astype(np.float32)
    rows, cols = np.mgrid[0:K, 0:K]
    row, col = float((img * rows).sum() / total), float((img * cols).sum() / total)
    # the kernel is the image grid's (K, K) window centred on the chief-ray image
    du, dv = pixel_to_sensor(row, col, (K, K), pitch)
    c_row, c_col = (x - c for x, c in zip((row, col), optical_center_px((K, K))))
    landed_est = landed_w  # weights are (1 + |a|²/l²)^(-3/2) ≈ 1 for rays near the chief ray
    info = {
        "vignetted_fraction": float(max(0.0, 1.0 - landed_w / free_w)),
        "outside_kernel_fraction": float(max(0.0, 1.0 - in_w / landed_w)),
        "landed_fraction": float(landed_est / rays),
        "rays_traced": rays + box_info["pilot_rays"],
        "rays_landed": int(round(landed_est)),
        "centroid_px": (c_row, c_col),
        "centroid_uv_mm": (source.image_uv[0] + du, source.image_uv[1] + dv),
        "center_uv_mm": source.image_uv,
        "mirror_point_mm": source.mirror_point.tolist(),
        "depth_mm": source.depth,
        "reference_sensor_distance_mm": source.reference_sensor_distance,
        "box_mm": box_info["box_mm"],
        "ellipse_mm": box_info["ellipse_mm"],
        "seed": int(seed),
        "seconds": seconds,
        "precision": "float64" if double else "float32",
    }
    return kernel, info


def integrated_psf(setup: Setup, u: float, v: float, depth: float, *,
                   settings: TraceSettings | None = None,
                   motion: MotionProfile | None = None, sweep: SweepRange | None = None,
                   reference_sensor_distance: float | None = None,
                   double: bool = False, aperture_radius: float | None = None,
                   **deprecated: Any) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """The IPSF of a point source seen at image point (u, v), over the focal sweep.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    u, v : float
        Upright image coordinates of the chief-ray image at the reference sensor
        distance, mm.
    depth : float
        Depth l of the source along the world-bound reflected chief ray, mm (inf allowed).
    settings : TraceSettings, optional
        Rays, kernel size K (pixels of ``setup.sensor.pixel_pitch``), seed, method
        (``"exact"``: each ray's whole sweep, its sensor-hit segment, deposited
        analytically, no time samples, :func:`mitsweep.tracer.kernel.deposit_segments`;
        ``"continuous"``: ``time_samples`` stratified times per ray; ``"planes"``: the
        paper's sum over ``n_planes`` equally spaced-in-time focal planes) and the
        deposit strategy. Default ``TraceSettings()``.
    motion : MotionProfile, optional
        Stage motion (default: ``motion_for(setup, sweep)``, from ``sweep.profile``), e.g.
        a measured (tabulated) one.
    sweep : mitsweep.optics.SweepRange, optional
        Default: ``optimal_sweep_range(setup)`` (honours ``sweep.focus_min/max``).
        ``sweep`` and ``motion`` are resolved by
        :func:`mitsweep.optics.reference.reference_geometry`, as the renderer does.
    reference_sensor_distance : float, optional
        Pixel grid and centring distance, mm (default: the reference geometry's, the
        mid-travel of ``motion``; give another only to study a mismatched grid).
    double : bool
        Trace in float64 (reference runs; float32 agrees to ~1e-4 in L1, see tests).
    aperture_radius : float, optional
        Override the lens aperture radius, mm.
    **deprecated
        ``rays``, ``kernel_size``, ``seed``, ``method``, ``time_samples``, ``n_planes``:
        the fields of ``settings``, still accepted for one release (DeprecationWarning).

    Returns
    -------
    kernel : (K, K) float32 ndarray
        Unit sum; rows down the image (−v), columns right (+u), the chief-ray image at
        the reference distance at ``[K//2, K//2]``.
    info : dict
        ``vignetted_fraction`` (energy reaching the aperture that the rim removes),
        ``outside_kernel_fraction`` (landed energy outside the window, dropped before
        normalising), ``centroid_px`` (row, col offset from the centre), ``rays_traced``,
        ``rays_landed``, ``landed_fraction``, ``seconds``, the geometry and the sweep.

    Raises
    ------
    ValueError
        Image point outside the mirror's image, depth <= 0, unknown method, bad sizes.
    mitsweep.config.SetupError
        Empty sweep or an unknown motion profile.
    """
    settings = settings_from_keywords(settings, deprecated, caller="integrated_psf")
    geometry, ref, sweep_kw, extra = _sweep_setup(setup, settings, motion=motion, sweep=sweep,
                                                  reference_sensor_distance=reference_sensor_distance)
    source = source_from_image(setup, u, v, depth, reference_sensor_distance=ref)
    kernel, info = render_source(setup, source, rays=settings.rays,
                                 kernel_size=settings.kernel_size, seed=settings.seed,
                                 double=double, aperture_radius=aperture_radius,
                                 deposit=settings.deposit, **sweep_kw)
    info.update(extra)
    info["image_uv_mm"] = (float(u), float(v))
    return kernel, info


def integrated_psfs(setup: Setup, points: Iterable[tuple[float, float, float]], *,
                    settings: TraceSettings | None = None,
                    seeds: Iterable[int] | None = None, motion: MotionProfile | None = None,
                    sweep: SweepRange | None = None,
                    reference_sensor_distance: float | None = None, double: bool = False,
                    aperture_radius: float | None = None,
                    progress: Callable[[], object] | None = None, **deprecated: Any
                    ) -> list[tuple[NDArray[np.float32], dict[str, Any]] | ValueError]:
    """:func:`integrated_psf` of many points of one setup, traced together.

    Parameters
    ----------
    points : sequence of (u, v, depth)
        Image points (mm, at the reference distance) and depths (mm, inf allowed).
    seeds : sequence of int, optional
        One per point (default: all ``settings.seed``).
    progress : callable, optional
        Called with no argument once per IPSF's worth of rays traced.
    Others
        As :func:`integrated_psf` (``**deprecated`` but ``seed``); the sweep, motion and
        reference distance are resolved once for all points.

    Returns
    -------
    list
        Per point ``(kernel, info)`` equal to :func:`integrated_psf` with that point's
        seed (up to the float64 summation order of the deposit; see
        :func:`render_sources`), or the ``ValueError`` that point raised (outside the
        mirror's image, fully vignetted, PSF outside the window).

    Raises
    ------
    ValueError
        Unknown method or bad sizes (errors of the whole batch).
    """
    settings = settings_from_keywords(settings, deprecated, caller="integrated_psfs",
                                      allowed=_PSFS_KEYWORDS)
    points = [(float(u), float(v), d) for u, v, d in points]
    seeds = [settings.seed] * len(points) if seeds is None else [int(x) for x in seeds]
    if len(seeds) != len(points):
        raise ValueError(f"seeds: give one per point ({len(points)}), got {len(seeds)}")
    geometry, ref, sweep_kw, extra = _sweep_setup(setup, settings, motion=motion, sweep=sweep,
                                                  reference_sensor_distance=reference_sensor_distance)
    results: list = [None] * len(points)
    sources, index = [], []
    for j, (u, v, depth) in enumerate(points):
        try:
            sources.append(source_from_image(setup, u, v, depth, reference_sensor_distance=ref))
            index.append(j)
        except ValueError as exc:
            results[j] = exc
            if progress is not None:
                progress()
    traced = render_sources(setup, sources, seeds=[seeds[j] for j in index],
                            rays=settings.rays, kernel_size=settings.kernel_size,
                            double=double, aperture_radius=aperture_radius, progress=progress,
                            deposit=settings.deposit, **sweep_kw)
    for j, res in zip(index, traced):
        if not isinstance(res, Exception):
            res[1].update(extra)
            res[1]["image_uv_mm"] = points[j][:2]
        results[j] = res
    return results


#: The deprecated keywords of :func:`integrated_psfs` (it took ``seeds``, not ``seed``).
_PSFS_KEYWORDS = frozenset({"rays", "kernel_size", "method", "time_samples", "n_planes"})


def _sweep_setup(setup, settings, *, motion, sweep, reference_sensor_distance):
    """Resolve the sweep of an IPSF: ``(geometry, reference distance, render_source
    keywords, info entries)``."""
    method, time_samples, n_planes = settings.method, settings.time_samples, settings.n_planes
    if method not in METHODS:
        raise ValueError(f"method: must be one of {', '.join(METHODS)}, got {method!r}")
    geometry = reference_geometry(setup, motion=motion, sweep=sweep)
    motion = geometry.motion
    ref = geometry.sensor_distance if reference_sensor_distance is None \
        else float(reference_sensor_distance)
    extra = {"method": method, "motion": motion.as_dict()}
    if method == "planes":
        if not 1 <= int(n_planes) <= 64:
            raise ValueError(f"n_planes: must be in [1, 64], got {n_planes!r}")
        t = (np.arange(int(n_planes)) + 0.5) / int(n_planes)
        kw = {"times": motion.sensor_distance(t)}
        extra["n_planes"] = int(n_planes)
    elif method == "exact":
        kw = {"motion": motion, "exact": True}
    else:
        kw = {"motion": motion, "time_samples": time_samples}
        extra["time_samples"] = int(time_samples)
    return geometry, ref, kw, extra


def psf(setup: Setup, u: float, v: float, depth: float, sensor_distance: float, *,
        rays: int = DEFAULT_RAYS, kernel_size: int = DEFAULT_KERNEL_SIZE, seed: int = 0,
        reference_sensor_distance: float | None = None, double: bool = False,
        aperture_radius: float | None = None) -> tuple[NDArray[np.float32], dict[str, Any]]:
    """The PSF at one sensor distance (mm), on the reference grid (default: that distance).

    Same conventions and ``info`` as :func:`integrated_psf`.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The optics.
    u, v : float
        Upright image coordinates of the chief-ray image at the reference sensor
        distance, mm.
    depth : float
        Depth l of the source, mm (inf allowed).
    sensor_distance : float
        The sensor's distance from the lens, mm.
    rays, kernel_size, seed, double, aperture_radius
        As :func:`render_source`.
    reference_sensor_distance : float, optional
        Pixel grid and centring distance, mm (default ``sensor_distance``).

    Returns
    -------
    kernel : (K, K) float32 ndarray
    info : dict
        As :func:`integrated_psf`, with ``sensor_distance_mm`` and ``image_uv_mm``.
    """
    ref = float(sensor_distance) if reference_sensor_distance is None \
        else float(reference_sensor_distance)
    source = source_from_image(setup, u, v, depth, reference_sensor_distance=ref)
    kernel, info = render_source(setup, source, times=[sensor_distance], rays=rays,
                                 kernel_size=kernel_size, seed=seed, double=double,
                                 aperture_radius=aperture_radius)
    info["sensor_distance_mm"] = float(sensor_distance)
    info["image_uv_mm"] = (float(u), float(v))
    return kernel, info
