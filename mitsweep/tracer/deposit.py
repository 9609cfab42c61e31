"""The deposit stage of the ray kernel: traced sensor hits binned into a pixel window.

A landed ray's hit moves along ``h(i) = A + B i`` while the sensor sweeps
(:func:`mitsweep.tracer.stages.thin_lens`). :func:`deposit_time_samples` adds its weight at
given sensor distances; :func:`deposit_sweeps` adds its exact sweep integral, the time its
hit spends in each pixel. Both write a float64 buffer of ``K·K + 2`` cells per source
(cell ``K·K``: landed weight outside the window; ``K·K+1``: weight only the rim stopped),
in one or more copies (:class:`DepositStrategy`) that :func:`fold_buffer` sums.

How the weights are added (buffer copies, Dr.Jit's scatter reduction mode, the lanes'
order) is a :class:`DepositStrategy` passed in explicitly; it changes the speed, and the
result only up to the float64 summation order.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..backend import drjit_module
from ..deprecation import renamed_keywords

__all__ = ["DepositStrategy", "deposit_copies", "fold_buffer", "new_buffer",
           "sensor_distances", "deposit_time_samples", "deposit_sweeps"]

#: A Dr.Jit array of the selected backend: ``Any`` in annotations.
DrJitArray = Any

#: Upper bound of :func:`deposit_copies` (memory: copies x the buffer).
MAX_COPIES = 64
#: drjit's reduction modes, by name (``drjit.ReduceMode``).
REDUCE_MODES = ("Auto", "Direct", "Local", "NoConflicts", "Permute", "Expand")


@dataclass(frozen=True)
class DepositStrategy:
    """How a deposit adds its rays' weights: the speed, not the result.

    The defaults are the fastest measured. On LLVM: plain atomics (``Direct``) into
    per-block copies of the buffer (:func:`deposit_copies`). One shared buffer made the
    cores fight over its cache lines: on the 2-core LLVM machine, idle, the periphery's
    deposit then ran at 26-29 M rays per CPU second against ~105 M without contention.
    Dr.Jit's own per-thread copies (``Expand``) avoid that too, but resolve each packet's
    conflicts with a 16-lane reduction per active lane: 78 M rays per CPU second. The
    segment deposit's lanes are ordered coherently
    (:func:`mitsweep.tracer.sampling.coherent_order`): a packet's lanes mostly hit the same
    pixels, and pre-reducing them in the packet (``Local``) before one atomic per distinct
    pixel measured 1.8x faster than ``Direct`` there (55 against 30 M rays per CPU second
    at the sphere's periphery); the stratified times' third coordinate leaves too little
    coherence for it to pay (+4 %, within the noise). Off LLVM: one copy, Dr.Jit's choice.

    Attributes
    ----------
    copies : int, optional
        Copies of a new buffer, a power of two from 1 to 64 (default
        :func:`deposit_copies`); a given buffer keeps its own count.
    mode : str or drjit.ReduceMode, optional
        Scatter reduction mode of both deposits (default: ``Direct`` for time samples and
        ``Local`` for sweeps on LLVM, ``Auto`` elsewhere); kept as its name.
    coherent : bool
        Order the sweep deposit's lanes coherently (default True).
    """

    copies: int | None = None
    mode: Any = None
    coherent: bool = True

    def __post_init__(self) -> None:
        c = self.copies
        if c is not None and (not isinstance(c, (int, np.integer)) or c < 1 or c & (c - 1)
                              or c > MAX_COPIES):
            raise ValueError(f"copies: must be a power of two from 1 to {MAX_COPIES}, "
                             f"got {c!r}")
        if self.mode is not None:
            name = self.mode if isinstance(self.mode, str) else getattr(self.mode, "name", None)
            if name not in REDUCE_MODES:
                raise ValueError(f"mode: must be one of {', '.join(REDUCE_MODES)} "
                                 f"(drjit.ReduceMode), got {self.mode!r}")
            object.__setattr__(self, "mode", name)
        object.__setattr__(self, "coherent", bool(self.coherent))

    def reduce_modes(self) -> tuple[Any, Any]:
        """``(time-sample mode, sweep mode)`` as ``drjit.ReduceMode`` for the selected
        backend."""
        import drjit as dr

        if self.mode is not None:
            mode = getattr(dr.ReduceMode, self.mode)
            return mode, mode
        if drjit_module().__name__.endswith("llvm"):
            return dr.ReduceMode.Direct, dr.ReduceMode.Local
        return dr.ReduceMode.Auto, dr.ReduceMode.Auto

    def buffer_copies(self) -> int:
        """Copies of a new buffer: ``copies``, or :func:`deposit_copies`."""
        return deposit_copies() if self.copies is None else int(self.copies)


def deposit_copies(strategy: DepositStrategy | None = None) -> int:
    """Copies of a new deposit buffer that the lanes spread their atomic adds over.

    ``strategy.copies`` where given; else 1 off the LLVM backend (the GPU's atomics are
    resolved in its caches); on LLVM the power of two at least twice Dr.Jit's worker
    threads (at most 64), so that the blocks the threads run at the same time seldom write
    the same copy. A buffer keeps its copies across launches; :func:`fold_buffer` sums
    them.

    Parameters
    ----------
    strategy : DepositStrategy, optional
        Its ``copies``, where set, is the answer.

    Returns
    -------
    int
        A power of two from 1 to :data:`MAX_COPIES`.
    """
    import drjit as dr

    if strategy is not None and strategy.copies is not None:
        return int(strategy.copies)
    if not drjit_module().__name__.endswith("llvm"):
        return 1
    threads = max(int(dr.thread_count()), 1)
    return min(1 << (2 * threads - 1).bit_length(), MAX_COPIES) if threads > 1 else 1


def fold_buffer(buffer: DrJitArray, sources: int, kernel_size: int) -> NDArray[np.float64]:
    """A deposit buffer as NumPy: the ``(sources, K·K + 2)`` float64 sum of its copies.

    Parameters
    ----------
    buffer : drjit Float64
        ``copies · sources · (K·K + 2)`` cells, copy-major (:func:`new_buffer`).
    sources : int
        Sources deposited into it.
    kernel_size : int
        K, px.

    Returns
    -------
    (sources, K·K + 2) ndarray of float64
    """
    cells = int(kernel_size) ** 2 + 2
    arr = np.asarray(buffer.numpy(), dtype=np.float64)
    return arr.reshape(-1, int(sources), cells).sum(axis=0)


def new_buffer(buffer: DrJitArray | None, sources: int, cells: int, copies: int
               ) -> tuple[DrJitArray, int]:
    """``buffer`` (or a float64 zero one of ``copies`` copies) and its copy count.

    Parameters
    ----------
    buffer : drjit Float64, optional
        A buffer to keep depositing into; None makes a zero one.
    sources : int
        Sources per copy.
    cells : int
        Cells per source, ``K·K + 2``.
    copies : int
        Copies of a new buffer (a power of two); a given buffer keeps its own count.

    Returns
    -------
    buffer : drjit Float64
    copies : int
        Its number of copies.

    Raises
    ------
    ValueError
        A given buffer that is not a power-of-two number of copies of the cells.
    """
    import drjit as dr

    if buffer is None:
        buffer = dr.zeros(drjit_module().Float64, copies * sources * cells)
    copies, rest = divmod(dr.width(buffer), sources * cells)
    if rest or copies < 1 or copies & (copies - 1):
        raise ValueError(f"deposit buffer: {dr.width(buffer)} cells is not a power-of-two "
                         f"number of copies of {sources} x {cells}")
    return buffer, copies


def _window(hits: dict, center: Sequence[DrJitArray], pixel_pitch: float, K: int) -> tuple:
    """Pixel coordinates (col, row; integers at pixel edges) of ``h(i) = A + B i``:
    ``(au, av, bu, bv)`` with ``col = au + bu i``, ``row = av + bv i``."""
    import drjit as dr

    inv_p = dr.opaque(type(hits["Au"]), 1.0 / float(pixel_pitch))
    au = dr.fma(hits["Au"] - center[0], inv_p, K // 2 + 0.5)
    av = dr.fma(center[1] - hits["Av"], inv_p, K // 2 + 0.5)
    return au, av, hits["Bu"] * inv_p, -hits["Bv"] * inv_p


def _table_lookup(table: np.ndarray, Float: type, clip: bool) -> Callable:
    """Linear interpolation in ``table`` (values at uniform ``x`` in [0, 1])."""
    import drjit as dr

    UInt32 = drjit_module().UInt32
    tab = Float(np.asarray(table, dtype=np.float64 if Float is drjit_module().Float64
                           else np.float32))
    nt = len(table) - 1

    def lookup(s):
        x = (dr.clip(s, 0.0, 1.0) if clip else s) * nt
        k0 = UInt32(dr.minimum(dr.floor(x), nt - 1))
        v0 = dr.gather(Float, tab, k0)
        if clip:
            return v0 + (dr.gather(Float, tab, k0 + 1) - v0) * (x - Float(k0))
        fr = x - Float(k0)
        v1 = dr.gather(Float, tab, k0 + 1)
        return v0 + (v1 - v0) * fr

    return lookup


def sensor_distances(xi: DrJitArray | None, *, times: Sequence[float] | None = None,
                     time_samples: int = 1, linear: tuple[float, float] | None = None,
                     sensor_table: np.ndarray | None = None, Float: type) -> list:
    """The sensor distances at which a ray deposits (stage *deposit*).

    Fixed ``times`` (sensor distances, mm: a PSF, or the N-plane sum) as opaque values;
    else ``M = time_samples`` stratified times ``t_j = (j + ξ)/M`` per ray (``xi`` its
    third lattice coordinate) mapped by the motion: ``linear = (start, end)`` exactly, or
    by linear interpolation in ``sensor_table`` (distances at uniform times).

    Parameters
    ----------
    xi : drjit Float, optional
        The rays' third lattice coordinate in [0, 1); needed unless ``times`` is given.
    times : sequence of float, optional
        Fixed sensor distances, mm; when given the other parameters are not used.
    time_samples : int, optional
        M >= 1, stratified times per ray (default 1).
    linear : (float, float), optional
        ``(start, end)`` sensor distances of a linear motion, mm.
    sensor_table : ndarray, optional
        Sensor distances at uniform times from 0 to 1, mm (a tabulated motion); used when
        ``linear`` is None.
    Float : type
        The Dr.Jit float type of the launch (keyword only).

    Returns
    -------
    list of drjit Float
        One sensor distance per time sample (per ray), mm.
    """
    import drjit as dr

    def op(x):
        return dr.opaque(Float, float(x))

    if times is not None:
        return [op(x) for x in times]
    M = int(time_samples)
    assert M >= 1
    if xi is None:
        raise ValueError("sensor_distances: xi (the rays' time coordinate) is needed "
                         "unless times are given")
    if linear is None:
        if sensor_table is None:
            raise ValueError("sensor_distances: give times, linear or sensor_table")
        lookup = _table_lookup(sensor_table, Float, clip=False)
    dists = []
    for j in range(M):
        tt = (xi + j) * (1.0 / M)
        if linear is not None:
            dists.append(dr.fma(op(linear[1]) - op(linear[0]), tt, op(linear[0])))
        else:
            dists.append(lookup(tt))
    return dists


@renamed_keywords(pitch="pixel_pitch")
def deposit_time_samples(buffer: DrJitArray, hits: dict, dists: Sequence[DrJitArray], *,
                         center: Sequence[DrJitArray], pixel_pitch: float, kernel_size: int,
                         base: DrJitArray | None = None, mode: Any = None) -> DrJitArray:
    """Add each ray's weight, split equally over the sensor distances ``dists``, to the
    pixels its hit ``A + B i`` falls in (stage *deposit*; box filter on the window).

    Parameters
    ----------
    buffer : drjit Float64
        ``K·K + 2`` cells (per source and copy; ``base`` offsets each lane's cells).
    hits : dict
        ``landed``, ``landed_free``, ``weight``, ``Au``, ``Av``, ``Bu``, ``Bv``
        (:func:`mitsweep.tracer.stages.trace_lanes`).
    dists : sequence of Float
        :func:`sensor_distances`.
    center : (Float, Float)
        Window centre (u, v), upright image mm.
    pixel_pitch : float
        Pixel pitch, mm.
    kernel_size : int
        K.
    base, mode
        Per-lane first cell, and the ``drjit.ReduceMode`` (default ``Auto``).

    Returns
    -------
    buffer
        In-window hits added to their pixel ``row·K + col`` (row down the image), those
        of landed rays outside to cell ``K·K``, the full weight of rays only the rim
        stopped to cell ``K·K+1``.
    """
    import drjit as dr

    m = drjit_module()
    UInt32, Int32, Acc = m.UInt32, m.Int32, type(buffer)
    mode = dr.ReduceMode.Auto if mode is None else mode
    K = int(kernel_size)
    KK = K * K
    au, av, bu, bv = _window(hits, center, pixel_pitch, K)
    landed, weight = hits["landed"], hits["weight"]
    wj = Acc(weight * (1.0 / len(dists)))
    free_only = hits["landed_free"] & ~landed
    for j, dist in enumerate(dists):
        col = Int32(dr.floor(dr.fma(bu, dist, au)))
        row = Int32(dr.floor(dr.fma(bv, dist, av)))
        ok = landed & (col >= 0) & (col < K) & (row >= 0) & (row < K)
        # One scatter per sample: in-window hits to their pixel, out-of-window hits of
        # landed rays to cell K·K; the first sample also sends the full weight of rays
        # that only the rim stopped to cell K·K+1.
        index = UInt32(dr.select(ok, row * K + col, KK))
        if j == 0:
            index = dr.select(free_only, UInt32(KK + 1), index)
        if base is not None:
            index = base + index
        if j == 0:
            value = dr.select(free_only, Acc(weight), wj)
            dr.scatter_reduce(dr.ReduceOp.Add, buffer, value, index,
                              active=hits["landed_free"], mode=mode)
        else:
            dr.scatter_reduce(dr.ReduceOp.Add, buffer, wj, index, active=landed, mode=mode)
    return buffer


def _slab(p0: DrJitArray, dp: DrJitArray, K: int) -> tuple[DrJitArray, DrJitArray]:
    """``[lo, hi]``: the ``s`` for which ``p0 + s dp`` lies in ``[0, K)`` (±inf bounds for
    a segment parallel to the slab)."""
    import drjit as dr

    inv = 1.0 / dp  # ±inf for a segment parallel to the slab
    t0, t1 = -p0 * inv, (K - p0) * inv
    flat = dp == 0.0
    inside = (p0 >= 0.0) & (p0 < K)
    lo = dr.select(flat, dr.select(inside, -math.inf, math.inf), dr.minimum(t0, t1))
    hi = dr.select(flat, dr.select(inside, math.inf, -math.inf), dr.maximum(t0, t1))
    return lo, hi


@renamed_keywords(pitch="pixel_pitch")
def deposit_sweeps(buffer: DrJitArray, hits: dict, *, center: Sequence[DrJitArray],
                   pixel_pitch: float, kernel_size: int, span: tuple[float, float],
                   cdf_table: np.ndarray | None = None, base: DrJitArray | None = None,
                   mode: Any = None) -> DrJitArray:
    """Add each ray's *whole sweep* to the pixels its hit crosses (stage *deposit*).

    The hit moves along ``h(i) = A + B i``, ``i`` over ``span = (i_lo, i_hi)``; the time
    it spends in a pixel is ``F(i_b) − F(i_a)``, ``[i_a, i_b]`` the part of the span over
    which it is in that pixel and ``F`` the fraction of the exposure during which the
    sensor distance is below ``i`` (linear for ``cdf_table=None``; else ``cdf_table``
    holds ``F`` at uniform ``s = (i − i_lo)/(i_hi − i_lo)``, interpolated linearly). The
    segment is clipped to the window (slab test) and walked pixel by pixel (a 2-D DDA,
    Amanatides & Woo 1987). Cells ``K·K`` and ``K·K+1`` and the other parameters as in
    :func:`deposit_time_samples`.

    Parameters
    ----------
    buffer, hits, center, pixel_pitch, kernel_size
        As :func:`deposit_time_samples`.
    span : (float, float)
        ``(i_lo, i_hi)``: the sensor distances at the sweep's ends, mm.
    cdf_table : ndarray, optional
        ``F`` at uniform ``s`` in [0, 1] (a tabulated motion); None: linear motion.
    base : drjit UInt32, optional
        Per-lane index of the first cell (None: 0 for every lane).
    mode : drjit.ReduceMode, optional
        Scatter reduction mode (default ``Auto``).

    Returns
    -------
    buffer
        With each landed ray's sweep added.

    References
    ----------
    .. [1] J. Amanatides, A. Woo, "A fast voxel traversal algorithm for ray tracing",
       Eurographics 1987.
    """
    import drjit as dr

    Float = type(hits["Au"])
    mode = dr.ReduceMode.Auto if mode is None else mode
    K = int(kernel_size)
    i_lo, i_hi = dr.opaque(Float, float(span[0])), dr.opaque(Float, float(span[1]))
    au, av, bu, bv = _window(hits, center, pixel_pitch, K)
    # Pixel coordinates (col x, row y; integers at pixel edges) along s ∈ [0, 1].
    x0, y0 = dr.fma(bu, i_lo, au), dr.fma(bv, i_lo, av)
    dx, dy = bu * (i_hi - i_lo), bv * (i_hi - i_lo)
    if cdf_table is None:
        cdf = lambda s: s  # linear motion: F is linear in i
    else:
        cdf = _table_lookup(cdf_table, Float, clip=True)
    lx, hx = _slab(x0, dx, K)
    ly, hy = _slab(y0, dy, K)
    s_in = dr.maximum(dr.maximum(lx, ly), 0.0)
    s_out = dr.minimum(dr.minimum(hx, hy), 1.0)
    landed = hits["landed"]
    crosses = landed & (s_in < s_out)
    f_in = dr.select(crosses, cdf(s_in), 0.0)
    f_out = dr.select(crosses, cdf(s_out), 0.0)
    w = type(buffer)(hits["weight"])
    # The part outside the window (all of it if the segment misses it) to cell K·K; the
    # weight of rays only the rim stopped to cell K·K+1.
    UInt32 = drjit_module().UInt32
    free_only = hits["landed_free"] & ~landed
    rest = w * type(buffer)(1.0 - (f_out - f_in))
    outside = dr.select(free_only, UInt32(K * K + 1), UInt32(K * K))
    dr.scatter_reduce(dr.ReduceOp.Add, buffer, dr.select(free_only, w, rest),
                      outside if base is None else base + outside,
                      active=free_only | (landed & (rest > 0.0)), mode=mode)
    _walk_segments(buffer, w, (x0, y0, dx, dy), (s_in, s_out, f_in, f_out, crosses), cdf,
                   K=K, base=base, mode=mode)
    return buffer


def _walk_segments(buffer, w, line, clip, cdf, *, K, base, mode) -> None:
    """The DDA of :func:`deposit_sweeps`: add ``w (F(s_next) − F(s))`` to each pixel the
    clipped segment ``(x0 + s dx, y0 + s dy)``, ``s_in ≤ s ≤ s_out``, crosses."""
    import drjit as dr

    m = drjit_module()
    UInt32, Int32, Acc = m.UInt32, m.Int32, type(buffer)
    x0, y0, dx, dy = line
    s_in, s_out, f_in, f_out, crosses = clip
    Float = type(x0)
    KK = K * K
    xs, ys = x0 + dx * s_in, y0 + dy * s_in
    col = Int32(dr.clip(dr.floor(xs), 0, K - 1))
    row = Int32(dr.clip(dr.floor(ys), 0, K - 1))
    # DDA state: s of the next column / row edge (inf if the segment runs parallel) and
    # the s step between edges.
    pos_x, pos_y = dx > 0.0, dy > 0.0
    step_c = dr.select(pos_x, Int32(1), Int32(-1))
    step_r = dr.select(pos_y, Int32(1), Int32(-1))
    flat_x, flat_y = dx == 0.0, dy == 0.0
    inv_dx = 1.0 / dr.select(flat_x, 1.0, dx)
    inv_dy = 1.0 / dr.select(flat_y, 1.0, dy)
    sx = dr.select(flat_x, math.inf, (Float(col) + dr.select(pos_x, 1.0, 0.0) - x0) * inv_dx)
    sy = dr.select(flat_y, math.inf, (Float(row) + dr.select(pos_y, 1.0, 0.0) - y0) * inv_dy)
    dsx, dsy = dr.abs(inv_dx), dr.abs(inv_dy)

    def cond(s, f_s, index, sx, sy, active):
        return active

    def body(s, f_s, index, sx, sy, active):
        along_x = sx <= sy
        s_next = dr.maximum(dr.minimum(dr.select(along_x, sx, sy), s_out), s)
        last = s_next >= s_out
        f_next = dr.select(last, f_out, cdf(s_next))
        cell = UInt32(index) if base is None else base + UInt32(index)
        dr.scatter_reduce(dr.ReduceOp.Add, buffer, w * Acc(f_next - f_s), cell,
                          active=active, mode=mode)
        index = index + dr.select(along_x, step_c, step_r * K)
        sx = dr.select(along_x, sx + dsx, sx)
        sy = dr.select(along_x, sy, sy + dsy)
        active = active & ~last & (index >= 0) & (index < KK)
        return s_next, f_next, index, sx, sy, active

    dr.while_loop(state=(s_in, f_in, row * K + col, sx, sy, crosses), cond=cond, body=body,
                  labels=("s", "f_s", "index", "sx", "sy", "active"), label="segment DDA")
