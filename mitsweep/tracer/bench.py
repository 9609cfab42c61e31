"""``mitsweep bench tracer``: useful rays per second of a peripheral sphere IPSF, vs batoid,
and error per second: the time to a whole bank at L1 <= 1e-3 per kernel, method by method.

*Useful rays* are rays that reach the sensor, counted once each, with everything that
produced them timed: pilot passes, generation, intersection, reflection, thin lens and
deposition at ``time_samples`` stratified sweep times. The peer, batoid (C++, the
fastest of the ray tracers the optics were cross-checked with: batoid, KrakenOS,
pyoptools, DeepLens), reflects the *same* rays (generated in
NumPy beforehand, not timed) off the same sphere on the same threads; only its
``Surface.reflect`` call is timed, and its useful rays are those of its output that pass
the lens aperture (computed afterwards, not timed), so the comparison favours the peer.
Both run in this process, one after the other, so the ratio survives a noisy machine.

The LLVM backend's vector width (``llvm_vector_width``, set by
``MITSWEEP_LLVM_VECTOR_WIDTH``, :func:`mitsweep.backend.set_llvm_vector_width`) is
reported, and ``llvm_widths`` times the cheapest deposit at the CPU's register width and
at the default width side by side, interleaved in this process (Dr.Jit compiles a
kernel per width), with the peer's CPU per ray over each.

``deposit_strategies`` times the cheapest and the exact deposit with the buffer's atomics
as they were (one shared buffer, lanes in sample order), with Dr.Jit's per-thread copies
(``ReduceMode.Expand``) and as they are (per-block copies; the segment deposit's lanes in
a coherent order, pre-reduced per packet), interleaved in this process.

Useful rays are reported for the cheapest deposit (one stratified sweep time per ray),
the default 4 times and the exact segment deposit; ``ratio_cpu`` compares the CPU
seconds per ray of the same two runs (all threads), which a loaded machine disturbs
less than wall time. What a user waits for is the error per second of
:func:`bank_error_per_second`, where the exact deposit's lower error per ray outweighs
its cost per ray, and where a bank's IPSFs are traced together (batched launches).
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import resource
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .. import backend
from ..config import DEFAULT_SETUP, Setup, load_setup
from ..optics.reference import reference_geometry
from . import kernel
from .bank import field_radius, ipsf_bank
from .ipsf import DEFAULT_TIME_SAMPLES, fit_sampling_box, integrated_psf
from .kernel import DepositStrategy, trace_arrays
from .settings import TraceSettings as Settings
from .source import source_from_image

__all__ = ["run_bench", "bank_error_per_second"]

logger = logging.getLogger(__name__)


def bench_setup() -> Setup:
    """The setup the benchmark traces: ``scenes/sphere.toml`` of the source tree where it
    is there, else :data:`mitsweep.config.DEFAULT_SETUP` (an installed package).

    Returns
    -------
    Setup
        The benchmark's setup.
    """
    path = os.path.join(os.path.dirname(__file__), "..", "..", "scenes", "sphere.toml")
    return load_setup(path) if os.path.exists(path) else DEFAULT_SETUP


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _rays_for(setup, source, n: int):
    """The kernel's own sample rays (float64, local frame) as NumPy origins/directions."""
    geom = source.geometry(setup)
    params, _ = fit_sampling_box(geom)
    r = trace_arrays(geom, params, n, double=True)
    a, b = r["a"], r["b"]
    inv_l = 1.0 / geom.depth
    d = -geom.w + np.outer(a * inv_l, geom.e1) + np.outer(b * inv_l, geom.e2)
    d /= np.linalg.norm(d, axis=1)[:, None]
    q = geom.origin_pr + np.outer(a, geom.e1) + np.outer(b, geom.e2)
    back = np.minimum(geom.margin, geom.depth * np.sqrt(1 + (a * inv_l) ** 2 + (b * inv_l) ** 2))
    return geom, r, q - d * back[:, None], d


def _batoid_trace(batoid, bg, setup, geom, o, d, threads: int):
    # batoid's sphere: z = R (1 - sqrt(1 - r²/R²)); R < 0 gives our convex z = -s(ρ).
    surface = batoid.Sphere(-setup.mirror.radius)
    old = bg._batoid_max_threads
    bg._batoid_max_threads = threads
    try:
        best = best_cpu = math.inf
        for _ in range(3):
            rv = batoid.RayVector(o[:, 0].copy(), o[:, 1].copy(), o[:, 2].copy(),
                                  d[:, 0].copy(), d[:, 1].copy(), d[:, 2].copy())
            c0, t0 = time.process_time(), time.perf_counter()
            surface.reflect(rv)
            best = min(best, time.perf_counter() - t0)
            best_cpu = min(best_cpu, time.process_time() - c0)
    finally:
        bg._batoid_max_threads = old
    ok = ~(rv.vignetted | rv.failed)
    p = np.stack([rv.x, rv.y, rv.z], axis=1) @ geom.rotation.T
    v = np.stack([rv.vx, rv.vy, rv.vz], axis=1) @ geom.rotation.T
    with np.errstate(divide="ignore", invalid="ignore"):
        tl = (geom.vertex_distance - p[:, 2]) / v[:, 2]
        lx, ly = p[:, 0] + tl * v[:, 0], p[:, 1] + tl * v[:, 1]
        landed = ok & (v[:, 2] > 0) & (lx * lx + ly * ly <= geom.aperture_radius ** 2)
        slope_u = lx / geom.focal_length - v[:, 0] / v[:, 2]
    return best, best_cpu, landed, slope_u


def batoid_rate(setup, source, center, n: int, threads: int) -> dict:
    """The peer's useful rays per second: batoid reflects the same rays as the tracer off
    the same sphere, only its ``Surface.reflect`` timed (best of 3), and agrees with the
    tracer at the image centre.

    Parameters
    ----------
    setup : Setup
        The setup whose mirror both trace.
    source : PointSource
        The peripheral point whose rays are timed (:func:`~.source.source_from_image`).
    center : PointSource
        A point at the image centre, where batoid's sphere root is right: the two traces'
        landed masks and sensor slopes are compared there (2^16 rays).
    n : int
        Rays timed.
    threads : int
        batoid's thread count (set for the call, restored after).

    Returns
    -------
    dict
        ``peer_rays_per_s`` (the raw rate times the tracer's landed fraction of the same
        rays), ``peer_raw_rays_per_s``, ``peer_cpu_seconds_per_ray``, ``peer_rays``,
        ``peer_threads``, ``peer_wrong_root_fraction``, ``peer_center_landed_mismatch``
        and ``peer_center_max_slope_diff``; without batoid installed only
        ``peer_rays_per_s`` (None) and ``peer_note`` (why), the other arguments unread.
    """
    try:
        import batoid
        import batoid.global_vars as bg
    except ImportError:
        return {"peer_rays_per_s": None,
                "peer_note": "batoid is not installed (pip install batoid)"}
    geom, r, o, d = _rays_for(setup, source, n)
    best, best_cpu, landed, _ = _batoid_trace(batoid, bg, setup, geom, o, d, threads)
    ours = r["landed"]
    # At the periphery the rays run nearly along the surface (grazing): batoid's
    # intersection returns the far root of the sphere for most of them, so almost none
    # of its reflections reach the lens. Its useful rate is counted as if its roots were
    # right: its raw rate times the landed fraction of the same rays in our trace.
    wrong = float(((~landed) & ours).sum() / max(ours.sum(), 1))
    out = {
        "peer": f"batoid {batoid.__version__}",
        "peer_rays_per_s": float(ours.mean() * n / best),
        "peer_raw_rays_per_s": float(n / best),
        "peer_cpu_seconds_per_ray": float(best_cpu / n),
        "peer_rays": int(n), "peer_threads": int(threads),
        "peer_wrong_root_fraction": wrong,
    }
    # At the image centre (rays along the axis) batoid is right: check the two traces
    # agree there (landed masks, and the sensor-hit slope B_u in float64).
    geom, r, o, d = _rays_for(setup, center, 1 << 16)
    _, _, landed, slope_u = _batoid_trace(batoid, bg, setup, geom, o, d, threads)
    both = landed & r["landed"]
    out["peer_center_landed_mismatch"] = int((landed != r["landed"]).sum())
    out["peer_center_max_slope_diff"] = float(np.max(np.abs(slope_u[both] - r["Bu"][both])))
    return out


def llvm_width_comparison(setup, u: float, depth: float, sweep, rays: int,
                          repeats: int) -> list:
    """The cheapest deposit (one sweep time per ray) at the native and the default LLVM
    vector widths, interleaved: per width, the best of ``repeats`` CPU seconds per ray
    and useful rays per second. Empty off the LLVM backend or when both widths agree.
    The width in effect before is restored.

    Parameters
    ----------
    setup : Setup
        The setup traced.
    u : float
        Image-plane radius of the point traced, mm.
    depth : float
        Its depth, mm.
    sweep : SweepRange
        The focal sweep.
    rays : int
        Rays per measurement.
    repeats : int
        Timed repeats per width, after one untimed pass that compiles each width's kernels.

    Returns
    -------
    list of dict
        One row per width, in increasing order: ``width``, ``cpu_seconds_per_ray`` and
        ``rays_per_s``.
    """
    if backend.select_backend() != "llvm":
        return []
    candidates = {backend.native_llvm_vector_width(), backend.auto_llvm_vector_width(),
                  backend.llvm_vector_width()}
    widths = sorted(w for w in candidates if w is not None)
    if len(widths) < 2:
        return []
    rows = {w: {"width": w, "cpu_seconds_per_ray": math.inf, "rays_per_s": 0.0}
            for w in widths}
    for rep in range(-1, repeats):  # rep -1: each width's kernels compiled, not timed
        for w in widths:
            with backend.llvm_vector_width_scope(w):
                c0 = time.process_time()
                _, info = integrated_psf(setup, u, 0.0, depth, sweep=sweep, settings=Settings(
                    rays=rays, seed=rep + 1, time_samples=1, method="continuous"))
                cpu = time.process_time() - c0
            if rep >= 0:
                row = rows[w]
                row["cpu_seconds_per_ray"] = min(row["cpu_seconds_per_ray"], cpu / rays)
                row["rays_per_s"] = max(row["rays_per_s"], info["rays_landed"] / info["seconds"])
    return [rows[w] for w in widths]


#: Deposit strategies timed side by side (:func:`_strategy_comparison`): label and
#: :class:`mitsweep.tracer.kernel.DepositStrategy` fields (absent: the default).
DEPOSIT_STRATEGIES: tuple[tuple[str, dict[str, Any]], ...] = (
    ("one shared buffer, direct atomics, lanes in sample order (before)",
     {"copies": 1, "mode": "Direct", "coherent": False}),
    ("Dr.Jit's per-thread copies (ReduceMode.Expand), lanes in sample order",
     {"copies": 1, "mode": "Expand", "coherent": False}),
    ("per-block copies; segment deposit coherent and packet-local (default)", {}),
)


def _strategy_comparison(setup, u: float, depth: float, sweep, rays: int, repeats: int) -> list:
    """The cheapest deposit (one sweep time per ray) and the exact segment deposit under
    each of :data:`DEPOSIT_STRATEGIES`, interleaved in this process: per strategy and
    method, the best of ``repeats`` useful rays per second and CPU seconds per ray. The
    kernels agree to the float64 summation order (tests/test_tracer_deposit.py)."""
    methods = (("continuous, 1 time/ray", {"method": "continuous", "time_samples": 1}),
               ("exact", {"method": "exact"}))
    rows: dict[tuple[str, str], dict[str, Any]] = {
        (label, m): {"strategy": label, "method": m, "rays_per_s": 0.0,
                     "cpu_seconds_per_ray": math.inf}
        for label, _ in DEPOSIT_STRATEGIES for m, _ in methods}
    for rep in range(-1, repeats):  # rep -1: each strategy's kernels compiled, not timed
        for m, kw in methods:
            for label, strategy in DEPOSIT_STRATEGIES:
                settings = Settings(rays=rays, seed=rep + 1, deposit=DepositStrategy(**strategy),
                                    **kw)
                c0 = time.process_time()
                _, info = integrated_psf(setup, u, 0.0, depth, sweep=sweep, settings=settings)
                cpu = time.process_time() - c0
                if rep >= 0:
                    row = rows[(label, m)]
                    row["cpu_seconds_per_ray"] = min(row["cpu_seconds_per_ray"], cpu / rays)
                    row["rays_per_s"] = max(row["rays_per_s"],
                                            info["rays_landed"] / info["seconds"])
    return list(rows.values())


#: The error-per-second target: L1 of every kernel of the bank against the reference.
BANK_L1_TARGET = 1e-3
#: The paper's focal-plane count (its IPSFs are sums over 26 sensor planes).
PAPER_PLANES = 26
#: Methods compared for error per second: (label, integrated_psf keywords).
BANK_METHODS = (
    ("exact (segment per ray)", {"method": "exact"}),
    ("continuous, 1 time/ray", {"method": "continuous", "time_samples": 1}),
    ("continuous, 4 times/ray", {"method": "continuous", "time_samples": 4}),
    (f"paper: {PAPER_PLANES}-plane sum", {"method": "planes", "n_planes": PAPER_PLANES}),
)


def bank_error_per_second(setup: Setup, *, n_radii: int = 19,
                          depths: Sequence[float] = (500.0, 1000.0, 5000.0, 10000.0),
                          reference_rays: int = 1 << 21, max_rays: int = 1 << 19,
                          target: float = BANK_L1_TARGET,
                          methods: Sequence[tuple[str, Mapping[str, Any]]] = BANK_METHODS
                          ) -> dict:
    """Time to a radial bank whose every kernel is within ``target`` (L1) of the true IPSF.

    The reference bank is the exact method at ``reference_rays`` per kernel with other
    seeds (its own error, the L1 between it and a second reference at the first depth, is
    reported). Each method traces the whole bank at rays per kernel doubling from 2^12
    up to ``max_rays``; the first count at which the worst kernel meets ``target`` is
    the method's, and that bank's wall time (pilot passes included, as
    :func:`mitsweep.tracer.ipsf_bank` runs it) is its time. The paper's plane sum
    converges to its own rectangle-rule approximation of the sweep, so it is also judged
    against a reference of itself (``own_limit``, at half the reference rays), which
    isolates its Monte Carlo error.

    Banks are traced batched (:func:`mitsweep.tracer.ipsf_bank`'s default); the exact
    row also gives ``seconds_one_ipsf_at_a_time``, the same bank traced with
    ``batched=False``.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        A rotationally symmetric setup (the bank is radial).
    n_radii : int, optional
        Field points of the bank, on the +u half-axis (default 19).
    depths : sequence of float, optional
        Depths of the point sources, mm.
    reference_rays : int, optional
        Rays per kernel of the exact-method reference bank (default 2^21).
    max_rays : int, optional
        Largest rays per kernel tried; the counts double from 2^12 up to it (default 2^19).
    target : float, optional
        L1 error every kernel must meet (default :data:`BANK_L1_TARGET`).
    methods : sequence of (str, mapping), optional
        Label and :class:`mitsweep.tracer.settings.TraceSettings` fields of each method
        timed (default :data:`BANK_METHODS`).

    Returns
    -------
    dict
        ``rows``: per method {label, rays_per_kernel (None if not reached), seconds,
        worst_l1, floor_l1 (worst L1 at ``max_rays``, when not reached)}; the bank's
        shape, ``reference_rays``, ``reference_self_l1``; ``exact_speedup_vs_planes``
        (the plane sum's seconds over the exact method's; None where the sum never
        reaches the target) and ``exact_speedup_vs_planes_own_limit``.
    """
    geometry = reference_geometry(setup)
    kw: dict[str, Any] = dict(kind="radial", n_radii=n_radii, depths=depths,
                              sweep=geometry.sweep, motion=geometry.motion)
    ref = ipsf_bank(setup, settings=Settings(rays=reference_rays, method="exact", seed=1000),
                    **kw).kernels
    ref2 = ipsf_bank(setup, settings=Settings(rays=reference_rays, method="exact", seed=2000),
                     **dict(kw, depths=depths[:1])).kernels
    self_l1 = float(np.abs(ref[:1] - ref2).sum(axis=(2, 3)).max())

    def ladder(extra, reference):
        rows, rays = [], 1 << 12
        while rays <= max_rays:
            t0 = time.perf_counter()
            bank = ipsf_bank(setup, settings=Settings(rays=rays, seed=0, **extra), **kw)
            seconds = time.perf_counter() - t0
            worst = float(np.abs(bank.kernels - reference).sum(axis=(2, 3)).max())
            rows.append((rays, seconds, worst))
            if worst <= target:
                break
            rays *= 2
        rays, seconds, worst = rows[-1]
        hit = worst <= target
        return {"rays_per_kernel": rays if hit else None, "seconds": seconds if hit else None,
                "worst_l1": worst, "floor_l1": None if hit else min(r[2] for r in rows),
                "ladder": [{"rays": r, "seconds": t, "worst_l1": e} for r, t, e in rows]}

    out_rows = []
    for label, extra in methods:
        row = {"label": label, **ladder(extra, ref)}
        if extra.get("method") == "planes":
            # half the rays: its deposit costs n_planes scatters per ray
            own = ipsf_bank(setup, settings=Settings(rays=reference_rays // 2, seed=1000, **extra),
                            **kw).kernels
            row["own_limit"] = ladder(extra, own)
        if row["rays_per_kernel"] is not None and extra.get("method") == "exact":
            # the same bank traced one IPSF at a time (as before batching), same rays
            t0 = time.perf_counter()
            ipsf_bank(setup, settings=Settings(rays=row["rays_per_kernel"], seed=0, **extra),
                      batched=False, **kw)
            row["seconds_one_ipsf_at_a_time"] = time.perf_counter() - t0
        out_rows.append(row)
    out = {"setup": setup.name, "n_radii": int(n_radii), "depths_mm": list(depths),
           "target_l1": target, "reference_rays": int(reference_rays),
           "reference_self_l1": self_l1, "max_rays": int(max_rays), "rows": out_rows}
    # Side by side: how many times faster the exact deposit reaches the target than the
    # paper's plane sum (against the true IPSF, and against the sum's own limit).
    exact = next((r for r in out_rows if r["label"].startswith("exact")), None)
    planes = next((r for r in out_rows if r["label"].startswith("paper")), None)
    if exact is not None and planes is not None and exact["seconds"]:
        out["exact_speedup_vs_planes"] = (planes["seconds"] / exact["seconds"]
                                          if planes["seconds"] else None)
        own = planes.get("own_limit", {}).get("seconds")
        out["exact_speedup_vs_planes_own_limit"] = own / exact["seconds"] if own else None
    return out


def run_bench(args: argparse.Namespace) -> dict:
    """Run the benchmark; ``args.quick`` shrinks the problem. Returns a flat-ish dict.

    Parameters
    ----------
    args : argparse.Namespace
        The command line's; only ``quick`` (bool, absent: False) is read: 2^23 rays per
        measurement instead of 2^26 and fewer repeats.
    """
    quick = bool(getattr(args, "quick", False))
    setup = bench_setup()
    geometry = reference_geometry(setup)
    sweep = geometry.sweep
    u = 0.9 * field_radius(setup, geometry)
    depth = 500.0
    rays = (1 << 23) if quick else (1 << 26)
    threads = os.cpu_count() or 1
    llvm = backend.select_backend() == "llvm"
    # Warm-up: compile the kernel (Dr.Jit caches it for the process and on disk).
    integrated_psf(setup, u, 0.0, depth, settings=Settings(rays=1 << 16), sweep=sweep)

    integrated_psf(setup, u, 0.0, depth, settings=Settings(rays=1 << 16, method="exact"),
                   sweep=sweep)

    def measure(samples, method="continuous"):
        best = None
        for rep in range(2 if quick else 3):
            c0 = time.process_time()
            _, info = integrated_psf(setup, u, 0.0, depth, sweep=sweep, settings=Settings(
                rays=rays, seed=rep, time_samples=samples, method=method))
            info["cpu_seconds"] = time.process_time() - c0
            rate = info["rays_landed"] / info["seconds"]
            if best is None or rate > best[0]:
                best = (rate, info)
        return best

    # One stratified sweep time per ray: the cheapest deposit (the rate peers can match).
    rate, info = measure(1)
    rate_default, _ = measure(DEFAULT_TIME_SAMPLES)
    # The whole sweep of every ray (the default method): the most accurate per ray.
    rate_exact, _ = measure(None, "exact")
    source = source_from_image(setup, u, 0.0, depth,
                               reference_sensor_distance=geometry.sensor_distance)
    out = {
        "target": "tracer", "setup": setup.name,
        "image_point_mm": [u, 0.0], "depth_mm": depth,
        "rays": rays, "rays_landed": info["rays_landed"],
        "landed_fraction": info["landed_fraction"], "seconds": info["seconds"],
        "time_samples": info["time_samples"], "threads": threads,
        "rays_per_s": rate,
        "rays_per_s_default_time_samples": rate_default,
        "default_time_samples": DEFAULT_TIME_SAMPLES,
        "rays_per_s_exact": rate_exact,
        # CPU seconds (all threads; pilot passes included) per ray: less sensitive than
        # wall time to other processes sharing the cores
        "cpu_seconds_per_ray": info["cpu_seconds"] / rays,
    }
    center = source_from_image(setup, 0.0, 0.0, depth,
                               reference_sensor_distance=geometry.sensor_distance)
    out.update(batoid_rate(setup, source, center, (1 << 20) if quick else (1 << 22), threads))
    peer = out.get("peer_rays_per_s")
    out["ratio"] = (rate / peer) if peer else None
    out["ratio_default_time_samples"] = (rate_default / peer) if peer else None
    out["ratio_exact"] = (rate_exact / peer) if peer else None
    # The same comparison in CPU time: the peer's CPU per ray over ours (both count every
    # traced ray; the landed fractions cancel as in "ratio").
    peer_cpu = out.get("peer_cpu_seconds_per_ray")
    out["ratio_cpu"] = (peer_cpu / out["cpu_seconds_per_ray"]) if peer_cpu else None
    out["llvm_vector_width"] = backend.llvm_vector_width() if llvm else None
    out["llvm_native_vector_width"] = backend.native_llvm_vector_width() if llvm else None
    out["llvm_widths"] = llvm_width_comparison(setup, u, depth, sweep, rays, 2 if quick else 3)
    out["deposit_copies"] = kernel.deposit_copies()
    out["deposit_strategies"] = _strategy_comparison(setup, u, depth, sweep, rays,
                                                     2 if quick else 3)
    for row in out["llvm_widths"] + out["deposit_strategies"]:
        row["ratio_cpu"] = (peer_cpu / row["cpu_seconds_per_ray"]) if peer_cpu else None
        row["ratio"] = (row["rays_per_s"] / peer) if peer else None
    # Error per second: a whole bank at L1 <= 1e-3 per kernel, each method side by side
    # (quick: a 3 x 2 bank).
    if quick:
        out["bank_error_per_second"] = bank_error_per_second(
            setup, n_radii=3, depths=(500.0, 10000.0), reference_rays=1 << 20,
            max_rays=1 << 18)
    else:
        out["bank_error_per_second"] = bank_error_per_second(
            setup, reference_rays=1 << 21, max_rays=1 << 19)
    if not quick:
        # Bounded memory: 1e9 rays in chunks of 2^22 (no per-ray arrays are stored).
        rss0 = _peak_rss_mb()
        t0 = time.perf_counter()
        _, big = integrated_psf(setup, u, 0.0, depth, settings=Settings(rays=1_000_000_000),
                                sweep=sweep)
        out["rays_1e9_seconds"] = time.perf_counter() - t0
        out["rays_1e9_peak_rss_growth_mb"] = _peak_rss_mb() - rss0
    out["peak_rss_mb"] = _peak_rss_mb()
    return out
