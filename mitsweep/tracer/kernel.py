"""The Dr.Jit ray kernel: point source → mirror → thin lens → sensor, fused in one pass.

Everything here is Dr.Jit; the rest of :mod:`mitsweep.tracer` talks NumPy. The kernel
is written once, generic over the float type (``Float`` = float32 by default, ``Float64``
for reference runs), and re-used for every chunk with opaque parameters, so it compiles
once per process.

The kernel is a chain of named stages, each a function of its own:

- *sample* (:mod:`mitsweep.tracer.sampling`: the lattice, the lanes of a launch, source
  batches; :func:`mitsweep.tracer.stages.source_rays`: the rays),
- *intersect* (:func:`~mitsweep.tracer.stages.intersect_conic`,
  :func:`~mitsweep.tracer.stages.intersect_asphere`),
- *reflect* (:func:`~mitsweep.tracer.stages.surface_normal`,
  :func:`~mitsweep.tracer.stages.reflect`),
- *lens* (:func:`~mitsweep.tracer.stages.thin_lens`),
- *deposit* (:mod:`mitsweep.tracer.deposit`), run the way a :class:`DepositStrategy`
  says (passed in; nothing global changes at run time).

This module composes them into the tracer's entry points.

Ray generation (independent of :mod:`mitsweep.optics` and of the renderer)
---------------------------------------------------------------------------
The point source sits at ``S = p_r + l w`` (mirror point ``p_r``, world-bound chief
direction ``w``, depth ``l``). Rays are parametrised by their crossing ``Q = p_r + a e₁ +
b e₂`` of the *aim plane* through ``p_r`` perpendicular to ``w`` (``e₁, e₂ ⊥ w``), with
``(a, b)`` uniform in a box fitted to the part of the mirror whose reflections reach the
lens (see :mod:`mitsweep.tracer.ipsf`). The direction is

.. math:: \\hat d \\propto -w + (a/l)\\,e_1 + (b/l)\\,e_2,

which stays exact in float32 for ``l → ∞`` (parallel rays), and the solid-angle weight of
the sample is ``(1 + (a² + b²)/l²)^{-3/2}``. The ray starts on the true line from ``S``,
at most ``margin`` mm before ``Q`` (the whole mirror lies within ``margin`` of ``p_r``),
so float32 never carries the 10⁹ mm of a far source.

Intersection
------------
In the mirror's local frame the conic is ``F(p) = x² + y² + (1+k) z² + 2 R z = 0`` with
the mirror on the branch ``R + (1+k) z ≥ 0``. Along ``p = o + t d`` this is a quadratic
``α t² + β t + γ = 0`` solved without cancellation (``q = −(β + sign(β) √Δ)/2``, roots
``q/α`` and ``γ/q``; the second stays finite when ``α → 0``: paraboloid rays parallel to
the axis). The hit is the nearest positive root on the mirror's branch; for a convex body
and a ray from outside it is the entry point, so the hit must also face the ray
(``d·n < 0``) and lie inside the rim. One Newton step on ``F`` polishes the root unless
the ray grazes (``|∇F·d| < 10⁻³ |∇F|``, where Newton is ill-conditioned and the
quadratic formula is the better estimate). Even-asphere terms are added by Newton steps
on ``z + s(ρ) = 0`` from the conic root.

Thin lens and sensor
--------------------
A reflected ray reaching the lens plane at ``L`` (``|L| ≤`` aperture radius) with
direction ``r`` leaves toward the point ``f r_xy / r_z`` of the focal plane; on a sensor
at distance ``i`` it lands at ``L (1 − i/f) + i r_xy/r_z``, affine in ``i``. In upright
image coordinates (docs/design.md) the hit is ``h(i) = A + B i`` with ``A = −L_xy`` and
``B = L_xy/f − r_xy/r_z``.
"""

from __future__ import annotations

import contextlib
import contextvars
import warnings
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from ..deprecation import renamed_keywords
from . import deposit as _deposit
from .deposit import (DepositStrategy, deposit_sweeps, deposit_time_samples, fold_buffer,
                      new_buffer, sensor_distances)
from .geometry import Geometry, TraceParams
from .sampling import Lanes, SourceBatch, array_types, single_lanes
from .stages import trace_lanes

__all__ = ["Geometry", "TraceParams", "SourceBatch", "DepositStrategy", "trace_arrays",
           "trace_arrays_batch", "deposit", "deposit_segments", "deposit_batch",
           "deposit_copies", "deposit_strategy_scope", "resolve_strategy", "fold_buffer",
           "TRACE_REVISION"]

#: Bumped whenever the rays a seed produces or the way they are deposited change, so that
#: kernels cached under an unchanged package version are not served stale (2: R2 lattice
#: for (a, b), the elliptic sampling domain and the exact segment deposit; 3: fewer
#: operations per ray — one square root for direction, weight and start, reflection
#: about the unnormalised normal — the same rays to float32 rounding; 4: fused
#: multiply-adds, the same rays to float32 rounding).
TRACE_REVISION = 4

#: A Dr.Jit array of the selected backend (``drjit.llvm.Float64``, ``drjit.cuda.Float64``,
#: ...): ``Any`` in annotations, so that importing this module does not import drjit.
DrJitArray = Any

#: The strategy of :func:`deposit_strategy_scope` (deprecated): context-local, so
#: threads and asynchronous tasks do not see each other's.
_SCOPED_STRATEGY: contextvars.ContextVar[DepositStrategy | None] = contextvars.ContextVar(
    "mitsweep_deposit_strategy", default=None)


def resolve_strategy(strategy: DepositStrategy | None = None) -> DepositStrategy:
    """``strategy``, else that of an enclosing :func:`deposit_strategy_scope`
    (deprecated), else the default :class:`DepositStrategy`.

    Parameters
    ----------
    strategy : DepositStrategy, optional
        A strategy given explicitly; it wins.

    Returns
    -------
    DepositStrategy
    """
    if strategy is not None:
        return strategy
    return _SCOPED_STRATEGY.get() or DepositStrategy()


def deposit_copies(strategy: DepositStrategy | None = None) -> int:
    """Copies of a new deposit buffer (:func:`mitsweep.tracer.deposit.deposit_copies`) for
    ``strategy`` resolved by :func:`resolve_strategy` (so an enclosing deprecated
    :func:`deposit_strategy_scope` still sets the count).

    Parameters
    ----------
    strategy : DepositStrategy, optional
        As :func:`resolve_strategy`.

    Returns
    -------
    int
        A power of two from 1 to 64.
    """
    return _deposit.deposit_copies(resolve_strategy(strategy))


_ARRAY_KEYS = ("landed", "landed_free", "weight", "Au", "Av", "Bu", "Bv", "a", "b")


def trace_arrays(geom: Geometry, params: TraceParams, n: int, *, offset: int = 0,
                 double: bool = False, keys: Sequence[str] = _ARRAY_KEYS
                 ) -> dict[str, np.ndarray]:
    """Trace ``n`` rays and return NumPy arrays (pilot passes, focus, tests).

    Keys as in the kernel: ``landed``, ``landed_free`` (bool), ``weight``, ``Au``,
    ``Av``, ``Bu``, ``Bv``, ``a``, ``b`` (float64 copies of the traced values); ``keys``
    selects some (the pilot passes need three: each array read back costs ~0.3 ms).

    Parameters
    ----------
    geom : Geometry
        The source and the optics.
    params : TraceParams
        Sampling domain and seed.
    n : int
        Rays traced.
    offset : int, optional
        Index of the first sample in ``params``'s stream (default 0).
    double : bool, optional
        Trace in float64 (default float32).
    keys : sequence of str, optional
        The arrays to read back (default all).

    Returns
    -------
    dict of str to (n,) ndarray
        bool for ``landed*``, float64 otherwise.

    Raises
    ------
    ValueError
        An unknown key.
    """
    return _read_arrays(geom, single_lanes(geom, params, n, offset, double), double, keys)


def trace_arrays_batch(batch: SourceBatch, log2_count: int, *, offset: int = 0,
                       keys: Sequence[str] = _ARRAY_KEYS) -> list[dict[str, np.ndarray]]:
    """Trace samples ``offset … offset + 2^log2_count − 1`` of every source of ``batch``
    in one launch; one dict per source, as :func:`trace_arrays` returns.

    Parameters
    ----------
    batch : SourceBatch
        The sources, with their sampling domains and seeds.
    log2_count : int
        Base-2 logarithm of the samples per source.
    offset : int, optional
        Index of each source's first sample (default 0).
    keys : sequence of str, optional
        As :func:`trace_arrays`.

    Returns
    -------
    list of dict
        One per source, in the batch's order.
    """
    lanes = Lanes(batch.double, 0, offset, batch=batch, log2_count=int(log2_count))
    res = _read_arrays(batch.geometry, lanes, batch.double, keys)
    count = 1 << int(log2_count)
    return [{k: v[j * count:(j + 1) * count] for k, v in res.items()}
            for j in range(batch.size)]


def _read_arrays(geom, lanes, double, keys):
    import drjit as dr

    unknown = set(keys) - set(_ARRAY_KEYS)
    if unknown:
        raise ValueError(f"keys: unknown {sorted(unknown)}; allowed: {', '.join(_ARRAY_KEYS)}")
    out = trace_lanes(geom, lanes, double)
    vals = [out[k] for k in keys]
    dr.eval(*vals)
    res = {}
    for k, v in zip(keys, vals):
        arr = np.asarray(v.numpy())
        res[k] = arr.astype(bool) if k.startswith("landed") else arr.astype(np.float64)
    return res



@renamed_keywords(pitch="pixel_pitch")
def deposit(geom: Geometry, params: TraceParams, n: int, *, offset: int, kernel_size: int,
            pixel_pitch: float, center_uv: tuple[float, float], times: list | None,
            sensor_table: np.ndarray | None, linear: tuple[float, float] | None,
            time_samples: int, buffer: DrJitArray | None = None,
            double: bool = False, strategy: DepositStrategy | None = None) -> DrJitArray:
    """Trace ``n`` rays and add their sensor hits to a (K·K + 2) Dr.Jit buffer.

    Each landed ray deposits its weight, split equally over ``M`` time samples: fixed
    sensor distances ``times`` (PSF at one distance, or the N-plane sum), or ``M``
    stratified times ``t_j = (j + ξ)/M`` (ξ per ray from the lattice) mapped to sensor
    distances by the motion (``linear = (start, end)`` exactly, else linear
    interpolation in ``sensor_table``, the distances at uniform times). Hits are binned
    in pixels of the reference grid (box filter: the pixel integral of the irradiance).
    Cell ``K·K`` accumulates the landed weight that falls outside the window, cell
    ``K·K+1`` the weight of rays that reach the aperture only without the rim; so the
    landed weight is the pixel sum plus cell K·K, the rim-free one that plus K·K+1.

    The buffer holds :func:`deposit_copies` copies of those cells (``strategy.copies``;
    a given ``buffer`` keeps its own count); ``fold_buffer(buffer, 1, K)`` sums them.
    ``strategy`` (default :class:`DepositStrategy`) says how the weights are added.

    Parameters
    ----------
    geom : Geometry
        The source and the optics.
    params : TraceParams
        Sampling domain and seed.
    n : int
        Rays traced in this launch.
    offset : int
        Index of the launch's first sample in ``params``'s stream.
    kernel_size : int
        K, px.
    pixel_pitch : float
        Pixel pitch, mm.
    center_uv : (float, float)
        Window centre (u, v), upright image mm at the reference sensor distance.
    times : list of float or None
        Fixed sensor distances, mm; None: time samples along the motion.
    sensor_table : ndarray or None
        Sensor distances at uniform times, mm (a tabulated motion).
    linear : (float, float) or None
        ``(start, end)`` sensor distances of a linear motion, mm.
    time_samples : int
        M, stratified times per ray (without ``times``).
    buffer : drjit Float64, optional
        A buffer to add to (None: a new zero one).
    double : bool, optional
        Trace in float64 (default float32).
    strategy : DepositStrategy, optional
        How the weights are added (:func:`resolve_strategy`).

    Returns
    -------
    drjit Float64
        The buffer.
    """
    lanes = single_lanes(geom, params, n, offset, double, center_uv)
    return _deposit_samples(geom, lanes, kernel_size=kernel_size, pixel_pitch=pixel_pitch,
                            times=times, sensor_table=sensor_table, linear=linear,
                            time_samples=time_samples, buffer=buffer, double=double,
                            strategy=resolve_strategy(strategy))


def _deposit_samples(geom, lanes, *, kernel_size, pixel_pitch, times, sensor_table, linear,
                     time_samples, buffer, double, strategy):
    """Trace ``lanes`` and deposit them at time samples (:func:`deposit`)."""
    _, Float, _ = array_types(double)
    K = int(kernel_size)
    sources = 1 if lanes.batch is None else lanes.batch.size
    buffer, copies = new_buffer(buffer, sources, K * K + 2, strategy.buffer_copies())
    base = lanes.cell_base(K * K + 2, copies)
    out = trace_lanes(geom, lanes, double, time_dim=times is None)
    dists = sensor_distances(out["xi_t"], times=times, time_samples=time_samples,
                             linear=linear, sensor_table=sensor_table, Float=Float)
    return deposit_time_samples(buffer, out, dists, center=(lanes.value("cu"),
                                                            lanes.value("cv")),
                                pixel_pitch=pixel_pitch, kernel_size=K, base=base,
                                mode=strategy.reduce_modes()[0])


@renamed_keywords(pitch="pixel_pitch")
def deposit_segments(geom: Geometry, params: TraceParams, n: int, *, offset: int,
                     kernel_size: int, pixel_pitch: float, center_uv: tuple[float, float],
                     span: tuple[float, float], cdf_table: np.ndarray | None,
                     buffer: DrJitArray | None = None, double: bool = False,
                     strategy: DepositStrategy | None = None) -> DrJitArray:
    """Trace ``n`` rays and add each ray's *whole sweep* to a (K·K + 2) Dr.Jit buffer.

    During the exposure a ray's sensor hit moves along the straight segment
    ``h(i) = A + B i``, ``i`` over the motion's span ``[i_lo, i_hi]``; each ray deposits
    its exact sweep integral, no time samples, no time noise
    (:func:`mitsweep.tracer.deposit.deposit_sweeps`). ``F`` (the motion's time CDF over
    its span) is linear for a linear motion (``cdf_table=None``: exact); otherwise
    ``cdf_table`` holds ``F`` at uniform ``s = (i − i_lo)/(i_hi − i_lo)``. Cells ``K·K``,
    ``K·K+1``, the buffer's copies and ``strategy`` as in :func:`deposit`.

    Parameters
    ----------
    geom, params, n, offset, kernel_size, pixel_pitch, center_uv, buffer, double, strategy
        As :func:`deposit`.
    span : (float, float)
        ``(i_lo, i_hi)``, the sensor distances at the sweep's ends, mm.
    cdf_table : ndarray or None
        ``F`` at uniform ``s`` (:func:`mitsweep.tracer.ipsf.sweep_cdf`); None: linear.

    Returns
    -------
    drjit Float64
        The buffer.
    """
    strategy = resolve_strategy(strategy)
    lanes = single_lanes(geom, params, n, offset, double, center_uv,
                         coherent=strategy.coherent)
    return _deposit_sweeps(geom, lanes, kernel_size=kernel_size, pixel_pitch=pixel_pitch,
                           span=span, cdf_table=cdf_table, buffer=buffer, double=double,
                           strategy=strategy)


def _deposit_sweeps(geom, lanes, *, kernel_size, pixel_pitch, span, cdf_table, buffer, double,
                    strategy):
    """Trace ``lanes`` and deposit their whole sweeps (:func:`deposit_segments`)."""
    K = int(kernel_size)
    sources = 1 if lanes.batch is None else lanes.batch.size
    buffer, copies = new_buffer(buffer, sources, K * K + 2, strategy.buffer_copies())
    base = lanes.cell_base(K * K + 2, copies)
    out = trace_lanes(geom, lanes, double)
    return deposit_sweeps(buffer, out, center=(lanes.value("cu"), lanes.value("cv")),
                          pixel_pitch=pixel_pitch, kernel_size=K, span=span, cdf_table=cdf_table,
                          base=base, mode=strategy.reduce_modes()[1])


@renamed_keywords(pitch="pixel_pitch")
def deposit_batch(batch: SourceBatch, log2_count: int, *, offset: int, kernel_size: int,
                  pixel_pitch: float, exact: bool, times: list | None = None,
                  sensor_table: np.ndarray | None = None,
                  linear: tuple[float, float] | None = None, time_samples: int = 1,
                  span: tuple[float, float] | None = None,
                  cdf_table: np.ndarray | None = None,
                  buffer: DrJitArray | None = None,
                  strategy: DepositStrategy | None = None) -> DrJitArray:
    """Trace samples ``offset … offset + 2^log2_count − 1`` of every source of ``batch``
    and deposit them, in one launch, into a stacked (S·(K·K + 2)) Dr.Jit buffer.

    Source ``j`` owns cells ``j·(K·K+2) …`` of each of the buffer's copies (as in
    :func:`deposit`; ``fold_buffer(buffer, S, K)`` sums them), laid out as the
    one-source buffer of :func:`deposit_segments` (``exact``: ``span``, ``cdf_table``) or
    :func:`deposit` (``times``, ``sensor_table``, ``linear``, ``time_samples``); the window
    of source ``j`` is centred on the batch's ``center_uv[j]``.

    Parameters
    ----------
    batch : SourceBatch
        The sources, with their sampling domains, seeds and window centres.
    log2_count : int
        Base-2 logarithm of the samples per source.
    offset, kernel_size, pixel_pitch, buffer, strategy
        As :func:`deposit`.
    exact : bool
        Deposit whole sweeps (:func:`deposit_segments`) instead of time samples.
    times, sensor_table, linear, time_samples
        As :func:`deposit` (without ``exact``).
    span, cdf_table
        As :func:`deposit_segments` (with ``exact``).

    Returns
    -------
    drjit Float64
        The buffer.
    """
    strategy = resolve_strategy(strategy)
    lanes = Lanes(batch.double, 0, offset, batch=batch, log2_count=int(log2_count),
                  coherent=exact and strategy.coherent)
    if exact:
        return _deposit_sweeps(batch.geometry, lanes, kernel_size=kernel_size,
                               pixel_pitch=pixel_pitch, span=span, cdf_table=cdf_table,
                               buffer=buffer, double=batch.double, strategy=strategy)
    return _deposit_samples(batch.geometry, lanes, kernel_size=kernel_size,
                            pixel_pitch=pixel_pitch, times=times, sensor_table=sensor_table, linear=linear,
                            time_samples=time_samples, buffer=buffer, double=batch.double,
                            strategy=strategy)


@contextlib.contextmanager
def deposit_strategy_scope(*, copies: int | None = None, mode: Any = None,
                           coherent: bool | None = None) -> Iterator[None]:
    """Deprecated: pass a :class:`DepositStrategy` instead (``strategy=`` of the deposit
    functions, ``TraceSettings.deposit`` of the IPSF functions).

    Inside the block, deposits given no strategy use ``copies`` buffer copies, scatter
    reduction ``mode`` (a ``drjit.ReduceMode``, for both deposits) and the segment
    deposit's lanes ordered ``coherent`` ly or not (None: the default). The setting is
    context-local (:mod:`contextvars`), not a module global.

    Parameters
    ----------
    copies : int, optional
        Copies of a new buffer, a power of two from 1 to 64 (None: the default).
    mode : str or drjit.ReduceMode, optional
        Scatter reduction mode (None: the default).
    coherent : bool, optional
        Order the segment deposit's lanes coherently (None: True).
    """
    warnings.warn("deposit_strategy_scope is deprecated: pass strategy=DepositStrategy(...) "
                  "(or TraceSettings(deposit=...)) instead", DeprecationWarning, stacklevel=3)
    strategy = DepositStrategy(copies=copies, mode=mode,
                               coherent=True if coherent is None else coherent)
    token = _SCOPED_STRATEGY.set(strategy)
    try:
        yield
    finally:
        _SCOPED_STRATEGY.reset(token)
