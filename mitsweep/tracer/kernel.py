"""The Dr.Jit ray kernel: point source → mirror → thin lens → sensor, fused in one pass.

Everything here is Dr.Jit; the rest of :mod:`mitsweep.tracer` talks NumPy. The kernel
is written once, generic over the float type (``Float`` = float32 by default, ``Float64``
for reference runs), and re-used for every chunk with opaque parameters, so it compiles
once per process.

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
import functools
import math
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..backend import drjit_module

__all__ = ["Geometry", "TraceParams", "SourceBatch", "trace_arrays", "trace_arrays_batch",
           "deposit", "deposit_segments", "deposit_batch", "deposit_copies",
           "deposit_strategy_scope", "fold_buffer", "TRACE_REVISION"]

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

# Golden-ratio generalisations for rank-1 lattices (Roberts' R_d sequences): φ_d is the
# real root of x^(d+1) = x + 1 and the generators are 1/φ_d, ..., 1/φ_d^d. R3 samples
# (a, b, t) of the stratified method; every other trace samples (a, b) only, with R2:
# a projection of R3 onto two coordinates is a poor 2-D sequence (measured on the
# sphere's bank: L1 6e-3 at 2^16 rays with R3's first two generators, 3.5e-4 with R2).
_PHI3 = 1.2207440846057596
_PHI2 = 1.3247179572447460
# Reduction mode of the deposits: plain atomics (Direct) on LLVM, into per-block copies of
# the buffer (deposit_copies). One shared buffer made the cores fight over its cache lines:
# on the 2-core LLVM machine, idle, the periphery's deposit then ran at 26-29 M rays per
# CPU second against ~105 M without contention. Dr.Jit's own per-thread copies (Expand)
# avoid that too, but resolve each packet's conflicts with a 16-lane reduction per
# active lane: 78 M rays per CPU second, against ~105 M for the atomics into copies.
# The segment deposit's lanes are ordered coherently (_coherent_order): a packet's lanes
# mostly hit the same pixels, and pre-reducing them in the packet (Local) before one
# atomic per distinct pixel measured 1.8x faster than Direct there (55 against 30 M rays
# per CPU second at the sphere's periphery); the stratified times' third coordinate
# leaves too little coherence for it to pay (+4 %, within the noise).
_MODE = None
_SWEEP_MODE = None
_coherent_setting = True
#: drjit-core's LLVM work unit (``jit_llvm_block_size``): the lanes a worker thread runs
#: together. Lanes of one block write one copy of a deposit buffer.
_LLVM_BLOCK_LOG2 = 14
#: Upper bound of :func:`deposit_copies` (memory: copies x the buffer).
_MAX_COPIES = 64
_copies_setting = None

_R3 = tuple(int(round((1.0 / _PHI3 ** (j + 1)) % 1.0 * 2 ** 32)) & 0xFFFFFFFF for j in range(3))
_R2 = tuple(int(round((1.0 / _PHI2 ** (j + 1)) % 1.0 * 2 ** 32)) & 0xFFFFFFFF for j in range(2))
#: Steps h > 16 at which R2's points come closer to each other than at any smaller step:
#: the successive minima of max_j |frac(h g_j)| (signed, from the 32-bit generators;
#: tests/test_tracer_deposit.py recomputes them). Points k, k + h, ..., k + 15h then lie on
#: a segment 16 max_j |frac(h g_j)| long (1 % of the unit square at h = 922111).
_R2_STEPS = (37, 49, 65, 114, 151, 200, 465, 616, 816, 1432, 1897, 2513, 5842, 7739, 10252,
             17991, 23833, 31572, 73396, 97229, 226030, 299426, 396655, 922111)
#: Lanes of a coherent group (:func:`_coherent_segments`), and segments per launch.
_GROUP = 16
_SEGMENTS = 4


@dataclass(frozen=True)
class Geometry:
    """Everything the kernel needs, in the mirror's local frame, float64 (NumPy side).

    Attributes
    ----------
    radius, conic : float
        Vertex radius R (mm) and conic constant k.
    aspheric : tuple of float
        a4, a6, ... (ρ⁴, ρ⁶, ... coefficients).
    rim_radius : float
        mm; ``inf`` disables the rim (used to measure vignetting).
    rotation : (3, 3) ndarray
        Local-to-world rotation.
    vertex_distance, focal_length, aperture_radius : float
        Lens centre at world (0, 0, vertex_distance); thin lens f; aperture radius, mm.
    origin_pr : (3,) ndarray
        The chief mirror point p_r, local frame.
    w, e1, e2 : (3,) ndarray
        Local-frame unit vectors: world-bound chief direction and the aim-plane axes.
    depth : float
        l, mm (inf allowed).
    margin : float
        Upper bound of the distance from p_r to any mirror point, mm.
    """

    radius: float
    conic: float
    aspheric: tuple
    rim_radius: float
    rotation: np.ndarray
    vertex_distance: float
    focal_length: float
    aperture_radius: float
    origin_pr: np.ndarray
    w: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    depth: float
    margin: float


@dataclass(frozen=True)
class TraceParams:
    """Sampling domain in the aim plane (mm) and the sample stream.

    Samples are uniform in the box ``[a0, a1] × [b0, b1]``, or, with ``ellipse =
    (ca, cb, m00, m01, m10, m11)``, uniform in the ellipse ``(a, b) = c + M x`` over the
    unit disc ``|x| ≤ 1`` (the lattice mapped by the area-preserving polar map
    ``x = √u (cos 2πv, sin 2πv)``), which fits a pupil's footprint more closely than its
    bounding box. The polar map keeps the rank-1 lattice's quality (periodic in ``v``;
    measured: the same or lower L1 per ray than the box, where Shirley & Chiu's
    concentric map, with its kinks on the diagonals, gave 1.3–1.5× higher).
    """

    a0: float
    a1: float
    b0: float
    b1: float
    seed: int = 0
    ellipse: tuple | None = None

    @property
    def area(self) -> float:
        """Area of the sampling domain, mm² (the flux estimate's scale)."""
        if self.ellipse is not None:
            m00, m01, m10, m11 = self.ellipse[2:]
            return math.pi * abs(m00 * m11 - m01 * m10)
        return (self.a1 - self.a0) * (self.b1 - self.b0)


#: Per-source values of a trace, in the order of a :class:`SourceBatch`'s packed table:
#: chief direction w, aim-plane axes e1 and e2, mirror point p_r (local frame), 1/l, l,
#: margin, the sampling box, the sampling ellipse (zeros where the box is used) and the
#: chief-ray image (u, v) the deposit centres its window on.
_COLUMNS = ("w0", "w1", "w2", "e10", "e11", "e12", "e20", "e21", "e22", "p0", "p1", "p2",
            "inv_l", "depth", "margin", "a0", "a1", "b0", "b1",
            "ca", "cb", "m00", "m01", "m10", "m11", "cu", "cv")
_COLUMN = {name: j for j, name in enumerate(_COLUMNS)}
#: Table rows are read as packets of 8 contiguous values (one vector load per packet and
#: a transpose: measured ~5x cheaper than one gather per value on AVX2).
_PACKET = 8
_ROW = -(-len(_COLUMNS) // _PACKET) * _PACKET
#: Geometry fields every source of a batch shares (the setup's mirror, lens and rim).
_SHARED = ("radius", "conic", "aspheric", "rim_radius", "rotation", "vertex_distance",
           "focal_length", "aperture_radius")


def _source_columns(geom: Geometry, params: TraceParams, center_uv=None) -> dict:
    inv_l = 0.0 if math.isinf(geom.depth) else 1.0 / geom.depth
    ellipse = params.ellipse if params.ellipse is not None else (0.0,) * 6
    values = (*geom.w, *geom.e1, *geom.e2, *geom.origin_pr, inv_l, geom.depth, geom.margin,
              params.a0, params.a1, params.b0, params.b1, *ellipse,
              *(center_uv if center_uv is not None else (0.0, 0.0)))
    return dict(zip(_COLUMNS, (float(x) for x in values)))


@functools.lru_cache(maxsize=4096)
def _block_shifts(seed: int, block: int) -> tuple:
    return tuple(int(x) for x in np.random.default_rng([seed, block]).integers(
        0, 2 ** 32, size=3, dtype=np.uint64))


def _lattice_shifts(seed: int, offset: int) -> tuple:
    """Cranley-Patterson shifts of the lattice from the seed (and the 2^32 block)."""
    return _block_shifts(int(seed), int(offset) >> 32)


def _shared_key(geom: Geometry) -> tuple:
    return tuple(np.asarray(getattr(geom, name), dtype=float).tobytes() for name in _SHARED)


class SourceBatch:
    """Point sources traced together: one kernel launch serves all of them.

    The sources share the setup's mirror, lens and rim (a bank's sources do); each has
    its own geometry (chief ray, depth), sampling domain, seed and window centre, held in
    one packed Dr.Jit table that the kernel gathers from by source index. A launch
    traces ``2^p`` consecutive samples of every source (:func:`trace_arrays_batch`,
    :func:`deposit_batch`): sample ``k`` of a source is the ray the one-source functions
    trace for sample ``k`` with the same parameters, bit for bit.

    Parameters
    ----------
    geoms : sequence of Geometry
    params : sequence of TraceParams
        One per source (``seed`` included).
    center_uv : sequence of (u, v), optional
        Window centres of a deposit, mm (upright image coordinates).
    double : bool
        float64 tables and kernels.

    Raises
    ------
    ValueError
        No source, mismatched lengths, or sources that do not share the mirror and lens.
    """

    def __init__(self, geoms: Iterable[Geometry], params: Iterable[TraceParams], *,
                 center_uv: Sequence[tuple[float, float]] | None = None,
                 double: bool = False) -> None:
        geoms, params = list(geoms), list(params)
        if not geoms or len(geoms) != len(params):
            raise ValueError(f"SourceBatch: give one TraceParams per geometry "
                             f"({len(geoms)} geometries, {len(params)} params)")
        if center_uv is not None and len(center_uv) != len(geoms):
            raise ValueError("SourceBatch: give one window centre per source")
        first = geoms[0]
        key = _shared_key(first)
        if any(_shared_key(g) != key for g in geoms[1:]):
            raise ValueError("SourceBatch: the sources must share the mirror, lens and rim")
        m, Float, _ = _types(double)
        rows = [_source_columns(g, p, None if center_uv is None else center_uv[j])
                for j, (g, p) in enumerate(zip(geoms, params))]
        table = np.zeros((len(rows), _ROW))
        table[:, :len(_COLUMNS)] = [[r[name] for name in _COLUMNS] for r in rows]
        kinds = [p.ellipse is not None for p in params]
        codes = np.array([[*_lattice_shifts(p.seed, 0), int(k)] for p, k in zip(params, kinds)],
                         dtype=np.uint64)
        self.geometry = first
        self.size = len(geoms)
        self.double = bool(double)
        #: True / False when every source samples an ellipse / a box, None when mixed.
        self.ellipse = kinds[0] if len(set(kinds)) == 1 else None
        self.table = Float(table.ravel().astype(np.float64 if double else np.float32))
        self.codes = m.UInt32(codes.ravel().astype(np.uint32))


class _Lanes:
    """The lanes of one launch: each lane's sample index and its source's values.

    One source: lane ``k`` traces sample ``offset + k`` and the source's values are
    opaque literals (the kernel compiles once and is reused with new values). A
    :class:`SourceBatch` with ``2^p`` samples per source: lane ``k`` traces sample
    ``offset + (k mod 2^p)`` of source ``k >> p``, whose values are gathered from the
    batch's table. With ``coherent``, ``k`` (mod ``2^p``) is first reordered by
    :func:`_coherent_order`: the same samples, in an order where neighbouring lanes
    trace neighbouring rays.
    """

    def __init__(self, double: bool, n: int, offset: int, *, columns: dict | None = None,
                 seed: int = 0, ellipse: bool = False, batch: SourceBatch | None = None,
                 log2_count: int = 0, coherent: bool = False):
        import drjit as dr

        m, Float, _ = _types(double)
        UInt32 = m.UInt32
        self._float = Float
        self._cache = {}
        self.batch = batch
        if batch is None:
            self.n = int(n)
            self.lane = dr.arange(UInt32, self.n)
            local = _coherent_order(self.lane, self.n) if coherent else self.lane
            self.index = local + dr.opaque(UInt32, offset & 0xFFFFFFFF)
            self.source = None
            self._columns = columns
            self.shifts = [dr.opaque(UInt32, int(x)) for x in _lattice_shifts(seed, offset)]
            self.ellipse = bool(ellipse)
            self.infinite_depth = math.isinf(columns["depth"])
        else:
            if offset + (1 << log2_count) > 2 ** 32:
                raise ValueError("SourceBatch: at most 2^32 samples per source")
            self.n = batch.size << log2_count
            lane = self.lane = dr.arange(UInt32, self.n)
            self.source = lane >> dr.opaque(UInt32, log2_count)
            local = lane & dr.opaque(UInt32, (1 << log2_count) - 1)
            if coherent:
                local = _coherent_order(local, 1 << log2_count)
            self.index = local + dr.opaque(UInt32, offset)
            self._row = self.source * (_ROW // _PACKET)
            self._packet_type = m.ArrayXf64 if double else m.ArrayXf
            codes = dr.gather(m.ArrayXu, batch.codes, self.source, shape=(4, self.n))
            self.shifts = [codes[j] for j in range(3)]
            self.ellipse = batch.ellipse
            if self.ellipse is None:
                self.is_ellipse = codes[3] != 0
            # l = inf needs no branch here: 1/l = 0 and min(margin, l·√(1 + 0)) = margin.
            self.infinite_depth = False

    def value(self, name: str):
        """The lanes' source value ``name`` (one of :data:`_COLUMNS`)."""
        import drjit as dr

        v = self._cache.get(name)
        if v is None:
            if self.batch is None:
                v = dr.opaque(self._float, self._columns[name])
            else:
                packet, k = divmod(_COLUMN[name], _PACKET)
                values = self._cache.get(packet)
                if values is None:
                    values = dr.gather(self._packet_type, self.batch.table, self._row + packet,
                                       shape=(_PACKET, self.n))
                    self._cache[packet] = values
                v = values[k]
            self._cache[name] = v
        return v

    def cell_base(self, cells: int, copies: int = 1):
        """Index of each lane's first buffer cell, ``copy · S · cells + source · cells``
        (None where it is 0 for every lane: one source, one copy).

        The buffer holds ``copies`` (a power of two) copies of the ``S`` sources' cells;
        a lane writes copy ``(lane >> 14) mod copies``, so the lanes of one work unit
        (a thread's block) share a copy and concurrent blocks write different ones.
        """
        import drjit as dr

        sources = 1 if self.batch is None else self.batch.size
        base = None if self.source is None else self.source * cells
        if copies > 1:
            UInt32 = type(self.lane)
            copy = (self.lane >> _LLVM_BLOCK_LOG2) & dr.opaque(UInt32, copies - 1)
            offset = copy * (sources * cells)
            base = offset if base is None else base + offset
        return base


def _single_lanes(geom, params, n, offset, double, center_uv=None, coherent=False) -> _Lanes:
    return _Lanes(double, n, offset, columns=_source_columns(geom, params, center_uv),
                  seed=params.seed, ellipse=params.ellipse is not None, coherent=coherent)


@functools.lru_cache(maxsize=256)
def _coherent_segments(count: int) -> tuple:
    """Segments ``(start, h)`` of ``[0, count)`` for :func:`_coherent_order`.

    Greedy: each segment is ``16 h`` lanes long, ``h`` the largest of
    :data:`_R2_STEPS` that fits what is left; at most :data:`_SEGMENTS` segments, the
    lanes after them keep their order. Padded with empty segments ``(end, 1)``.
    """
    segments, start = [], 0
    while len(segments) < _SEGMENTS:
        fits = [h for h in _R2_STEPS if _GROUP * h <= count - start]
        if not fits:
            break
        segments.append((start, fits[-1]))
        start += _GROUP * fits[-1]
    segments += [(start, 1)] * (_SEGMENTS - len(segments))
    return tuple(segments)


def _coherent_order(local, count: int):
    """A permutation of the lanes ``local`` in ``[0, count)``: sample index per lane.

    In a segment ``(start, h)`` lane ``start + 16 p + j`` (``p < h``, ``j < 16``) takes
    sample ``start + p + j h``, a bijection of the segment onto itself; so the 16 lanes
    of a group trace R2's points ``x, x + δ, ..., x + 15 δ`` with ``δ = frac(h g)`` small
    (:data:`_R2_STEPS`): neighbouring rays, which mostly hit the same pixels. Their
    scatters then pre-reduce within the packet (``ReduceMode.Local``), one atomic per
    distinct pixel instead of one per lane. The set of samples, and so the estimate, is
    unchanged. The segment bounds are opaque: one kernel serves every ``count``.
    """
    import drjit as dr

    UInt32 = type(local)
    out = local
    for start, h in reversed(_coherent_segments(int(count))):
        rel = local - dr.opaque(UInt32, start)
        p, j = rel >> (_GROUP.bit_length() - 1), rel & (_GROUP - 1)
        mapped = dr.opaque(UInt32, start) + p + j * dr.opaque(UInt32, h)
        out = dr.select(local < dr.opaque(UInt32, start + _GROUP * h), mapped, out)
    return out


def _types(double: bool):
    m = drjit_module()
    if double:
        return m, m.Float64, m.Array3f64
    return m, m.Float, m.Array3f


def _deposit_types(double: bool):
    """``(module, Float, UInt32, Int32)`` of a deposit; sets the scatter modes once
    (:data:`_MODE`, :data:`_SWEEP_MODE`: direct and packet-local scatters on LLVM,
    Dr.Jit's choice elsewhere)."""
    import drjit as dr

    global _MODE, _SWEEP_MODE
    m, Float, _ = _types(double)
    if _MODE is None:
        llvm = m.__name__.endswith("llvm")
        _MODE = dr.ReduceMode.Direct if llvm else dr.ReduceMode.Auto
        _SWEEP_MODE = dr.ReduceMode.Local if llvm else dr.ReduceMode.Auto
    return m, Float, m.UInt32, m.Int32


def deposit_copies() -> int:
    """Copies of a new deposit buffer that the lanes spread their atomic adds over.

    1 off the LLVM backend (the GPU's atomics are resolved in its caches); on LLVM the
    power of two at least twice Dr.Jit's worker threads (at most 64), so that the blocks
    the threads run at the same time seldom write the same copy. A buffer keeps its
    copies across launches; :func:`fold_buffer` sums them.
    :func:`deposit_strategy_scope` overrides the count (the benchmark's side-by-side).
    """
    import drjit as dr

    if _copies_setting is not None:
        return _copies_setting
    if not drjit_module().__name__.endswith("llvm"):
        return 1
    threads = max(int(dr.thread_count()), 1)
    return min(1 << (2 * threads - 1).bit_length(), _MAX_COPIES) if threads > 1 else 1


@contextlib.contextmanager
def deposit_strategy_scope(*, copies: int | None = None, mode: Any = None,
                           coherent: bool | None = None) -> Iterator[None]:
    """Deposit with ``copies`` buffer copies, scatter reduction ``mode`` (a
    ``drjit.ReduceMode``, for both deposits) and the segment deposit's lanes ordered
    ``coherent`` ly or not inside the block, then restore the defaults; for side-by-side
    timing. The results agree up to the float64 summation order."""
    global _copies_setting, _MODE, _SWEEP_MODE, _coherent_setting
    if copies is not None and (copies < 1 or copies & (copies - 1) or copies > _MAX_COPIES):
        raise ValueError(f"copies: must be a power of two from 1 to {_MAX_COPIES}, "
                         f"got {copies!r}")
    _deposit_types(False)  # the default modes, to restore
    old = _copies_setting, _MODE, _SWEEP_MODE, _coherent_setting
    if copies is not None:
        _copies_setting = copies
    if mode is not None:
        _MODE = _SWEEP_MODE = mode
    if coherent is not None:
        _coherent_setting = bool(coherent)
    try:
        yield
    finally:
        _copies_setting, _MODE, _SWEEP_MODE, _coherent_setting = old


def fold_buffer(buffer: DrJitArray, sources: int, kernel_size: int) -> NDArray[np.float64]:
    """A deposit buffer as NumPy: the ``(sources, K·K + 2)`` float64 sum of its copies."""
    cells = int(kernel_size) ** 2 + 2
    arr = np.asarray(buffer.numpy(), dtype=np.float64)
    return arr.reshape(-1, int(sources), cells).sum(axis=0)


def _new_buffer(buffer, Acc, sources: int, cells: int):
    """``buffer`` (or a zero one of :func:`deposit_copies` copies) and its copy count."""
    import drjit as dr

    if buffer is None:
        buffer = dr.zeros(Acc, deposit_copies() * sources * cells)
    copies, rest = divmod(dr.width(buffer), sources * cells)
    if rest or copies < 1 or copies & (copies - 1):
        raise ValueError(f"deposit buffer: {dr.width(buffer)} cells is not a power-of-two "
                         f"number of copies of {sources} x {cells}")
    return buffer, copies


def _trace(geom: Geometry, lanes: _Lanes, double: bool, time_dim: bool = False):
    """Trace the rays of ``lanes`` (:class:`_Lanes`: sample indices, per-source values).

    ``geom`` gives what every source shares (mirror, lens, rim); the chief ray, depth,
    margin and sampling domain are the lanes' own. Returns a dict of Dr.Jit arrays:
    ``landed`` (reaches the sensor through the rim and the aperture), ``landed_free``
    (would, without the rim), ``weight``, ``Au, Av, Bu, Bv`` (sensor hit ``A + B i``,
    upright image mm), ``a, b`` (aim-plane sample) and, with ``time_dim``, ``xi_t`` (a
    third low-discrepancy coordinate in [0, 1) for time: the samples are then R3's, else
    R2's).
    """
    import drjit as dr

    m, Float, Array3 = _types(double)
    UInt32 = m.UInt32
    idx, shifts = lanes.index, lanes.shifts
    gen = _R3 if time_dim else _R2

    def lattice(j):
        # Exact fixed-point frac(idx * g_j + shift_j); top 24 bits -> [0, 1).
        return Float((idx * UInt32(gen[j]) + shifts[j]) >> 8) * (2.0 ** -24)

    ua, ub = lattice(0), lattice(1)
    ut = lattice(2) if time_dim else None
    op = lambda x: dr.opaque(Float, float(x))  # noqa: E731 - compile once, update values
    val = lanes.value

    # a·b + c is written dr.fma(a, b, c) throughout: LLVM contracts nothing by itself,
    # and a fused multiply-add is one instruction instead of two and one rounding instead
    # of two (measured on the sphere's periphery: 323 instead of 380 operations per lane
    # in the deposit kernel, 6 % fewer CPU seconds per ray, kernels within 1.4e-5 in L1).
    fma = dr.fma

    def in_box():
        return (fma(val("a1") - val("a0"), ua, val("a0")),
                fma(val("b1") - val("b0"), ub, val("b0")))

    def in_ellipse():
        rad = dr.sqrt(ua)  # uniform on the unit disc
        sin_p, cos_p = dr.sincos((2.0 * math.pi) * ub)
        xd, yd = rad * cos_p, rad * sin_p
        return (fma(val("m01"), yd, fma(val("m00"), xd, val("ca"))),
                fma(val("m11"), yd, fma(val("m10"), xd, val("cb"))))

    if lanes.ellipse is None:  # a batch of both kinds
        (a_box, b_box), (a_ell, b_ell) = in_box(), in_ellipse()
        a = dr.select(lanes.is_ellipse, a_ell, a_box)
        b = dr.select(lanes.is_ellipse, b_ell, b_box)
    else:
        a, b = in_ellipse() if lanes.ellipse else in_box()

    inv_l = val("inv_l")
    w = Array3(val("w0"), val("w1"), val("w2"))
    e1 = Array3(val("e10"), val("e11"), val("e12"))
    e2 = Array3(val("e20"), val("e21"), val("e22"))
    pr = Array3(val("p0"), val("p1"), val("p2"))
    al, bl = a * inv_l, b * inv_l
    # (w, e1, e2) is orthonormal, so |−w + al e1 + bl e2| = sqrt(1 + al² + bl²): one
    # square root serves the direction, the solid-angle weight and the start distance.
    root = dr.sqrt(fma(al, al, fma(bl, bl, 1.0)))
    inv_root = 1.0 / root
    d = fma(e1, al, fma(e2, bl, -w)) * inv_root
    weight = inv_root * inv_root * inv_root
    q_pt = fma(e1, a, fma(e2, b, pr))
    # Distance from S to Q is l·sqrt(1 + (a² + b²)/l²); start no farther back than the margin.
    if lanes.infinite_depth:
        back = val("margin")
    else:
        back = dr.minimum(val("margin"), val("depth") * root)
    o = fma(d, -back, q_pt)

    R, ok = op(geom.radius), op(1.0 + geom.conic)

    def conic(p, q):
        """x_p x_q + y_p y_q + (1+k) z_p z_q (the conic's quadratic form)."""
        return fma(p.x, q.x, fma(p.y, q.y, (ok * p.z) * q.z))

    alpha = conic(d, d)
    beta = 2.0 * fma(R, d.z, conic(o, d))
    gamma = fma(2.0 * R, o.z, conic(o, o))
    disc = fma(beta, beta, -4.0 * alpha * gamma)
    has = disc >= 0.0
    sq = dr.sqrt(dr.maximum(disc, 0.0))
    qq = -0.5 * (beta + dr.copysign(sq, beta))
    t1 = qq / alpha
    t2 = gamma / qq
    inf = Float(math.inf)

    def valid(t):
        z = fma(t, d.z, o.z)
        return has & dr.isfinite(t) & (t > 0.0) & (fma(ok, z, R) >= -1e-6 * R)

    t1v, t2v = valid(t1), valid(t2)
    t = dr.minimum(dr.select(t1v, t1, inf), dr.select(t2v, t2, inf))
    hit = t1v | t2v
    t = dr.select(hit, t, 0.0)
    # Newton polish on F along the ray, skipped at grazing incidence.
    p = fma(d, t, o)
    grad = Array3(p.x, p.y, fma(ok, p.z, R))
    g_dot_d = dr.dot(grad, d)
    f_val = fma(2.0 * R, p.z, conic(p, p))
    polish = g_dot_d * g_dot_d > 1e-6 * dr.squared_norm(grad)  # |∇F·d| > 1e-3 |∇F|
    t = dr.select(polish, fma(-0.5, f_val / dr.select(polish, g_dot_d, 1.0), t), t)

    coeffs = [float(c) for c in geom.aspheric]

    def asphere_terms(r2):
        """Even-asphere sag Σ c_j ρ^(2j+4) and its s'/ρ, Σ (2j+4) c_j ρ^(2j+2)."""
        sag_p, slope_p = Float(0.0), Float(0.0)
        for j, c in enumerate(coeffs):
            sag_p = sag_p + c * r2 ** (j + 2)
            slope_p = slope_p + (2 * j + 4) * c * r2 ** (j + 1)
        return sag_p, slope_p

    if any(coeffs):
        for _ in range(4):  # Newton on G(t) = z + s(ρ) from the conic root
            p = fma(d, t, o)
            r2 = p.x * p.x + p.y * p.y
            qc = dr.sqrt(dr.maximum(R * R - ok * r2, 0.0))
            sag_p, slope_p = asphere_terms(r2)
            g_over = 1.0 / dr.maximum(qc, 1e-12) + slope_p  # s'/ρ
            dg = d.z + g_over * (p.x * d.x + p.y * d.y)
            t = t - (p.z + r2 / (R + qc) + sag_p) / dg
    p = fma(d, t, o)
    r2 = fma(p.x, p.x, p.y * p.y)
    if any(coeffs):
        # n ∝ (x (1 + q P), y (1 + q P), q): finite on the axis and at q = 0.
        qc = dr.sqrt(dr.maximum(R * R - ok * r2, 0.0))
        h = 1.0 + qc * asphere_terms(r2)[1]
        n_loc = Array3(p.x * h, p.y * h, qc)
    else:
        n_loc = Array3(p.x, p.y, fma(ok, p.z, R))
    # Reflection about the unnormalised normal m: d − 2 (d·m) m / |m|² (no square root).
    d_dot_n = dr.dot(d, n_loc)
    front = hit & (d_dot_n < 0.0)
    inside = r2 <= op(geom.rim_radius ** 2 if math.isfinite(geom.rim_radius) else 3.0e38)
    refl = fma(n_loc, -2.0 * d_dot_n / dr.squared_norm(n_loc), d)

    rot = np.asarray(geom.rotation, dtype=float)

    def to_world(v):
        # Zero entries (an untilted mirror: the identity; a tilt about one axis: four)
        # are left out and unit ones multiply nothing: the same values, fewer operations.
        comps = (v.x, v.y, v.z)

        def row(i):
            terms = [(1.0 if rot[i, j] == 1.0 else op(rot[i, j]), comps[j])
                     for j in range(3) if rot[i, j] != 0.0]
            scale, comp = terms[0]
            total = comp if isinstance(scale, float) else scale * comp
            for scale, comp in terms[1:]:
                total = total + comp if isinstance(scale, float) else fma(scale, comp, total)
            return total

        return Array3(row(0), row(1), row(2))

    pw_ = to_world(p)
    rw = to_world(refl)
    toward = rw.z > 0.0
    inv_rz = 1.0 / dr.select(toward, rw.z, 1.0)
    tl = (op(geom.vertex_distance) - pw_.z) * inv_rz
    lx, ly = fma(rw.x, tl, pw_.x), fma(rw.y, tl, pw_.y)
    in_ap = fma(lx, lx, ly * ly) <= op(geom.aperture_radius ** 2)
    landed_free = front & toward & in_ap
    landed = landed_free & inside
    inv_f = op(1.0 / geom.focal_length)
    return {"landed": landed, "landed_free": landed_free, "weight": weight,
            "Au": -lx, "Av": -ly, "Bu": fma(lx, inv_f, -rw.x * inv_rz),
            "Bv": fma(ly, inv_f, -rw.y * inv_rz), "a": a, "b": b, "xi_t": ut}


_ARRAY_KEYS = ("landed", "landed_free", "weight", "Au", "Av", "Bu", "Bv", "a", "b")


def trace_arrays(geom: Geometry, params: TraceParams, n: int, *, offset: int = 0,
                 double: bool = False, keys: Sequence[str] = _ARRAY_KEYS
                 ) -> dict[str, np.ndarray]:
    """Trace ``n`` rays and return NumPy arrays (pilot passes, focus, tests).

    Keys as in the kernel: ``landed``, ``landed_free`` (bool), ``weight``, ``Au``,
    ``Av``, ``Bu``, ``Bv``, ``a``, ``b`` (float64 copies of the traced values); ``keys``
    selects some (the pilot passes need three: each array read back costs ~0.3 ms).
    """
    return _read_arrays(geom, _single_lanes(geom, params, n, offset, double), double, keys)


def trace_arrays_batch(batch: SourceBatch, log2_count: int, *, offset: int = 0,
                       keys: Sequence[str] = _ARRAY_KEYS) -> list[dict[str, np.ndarray]]:
    """Trace samples ``offset … offset + 2^log2_count − 1`` of every source of ``batch``
    in one launch; one dict per source, as :func:`trace_arrays` returns."""
    lanes = _Lanes(batch.double, 0, offset, batch=batch, log2_count=int(log2_count))
    res = _read_arrays(batch.geometry, lanes, batch.double, keys)
    count = 1 << int(log2_count)
    return [{k: v[j * count:(j + 1) * count] for k, v in res.items()}
            for j in range(batch.size)]


def _read_arrays(geom, lanes, double, keys):
    import drjit as dr

    unknown = set(keys) - set(_ARRAY_KEYS)
    if unknown:
        raise ValueError(f"keys: unknown {sorted(unknown)}; allowed: {', '.join(_ARRAY_KEYS)}")
    out = _trace(geom, lanes, double)
    vals = [out[k] for k in keys]
    dr.eval(*vals)
    res = {}
    for k, v in zip(keys, vals):
        arr = np.asarray(v.numpy())
        res[k] = arr.astype(bool) if k.startswith("landed") else arr.astype(np.float64)
    return res


def deposit(geom: Geometry, params: TraceParams, n: int, *, offset: int, kernel_size: int,
            pitch: float, center_uv: tuple[float, float], times: list | None,
            sensor_table: np.ndarray | None, linear: tuple[float, float] | None,
            time_samples: int, buffer: DrJitArray | None = None,
            double: bool = False) -> DrJitArray:
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

    The buffer holds :func:`deposit_copies` copies of those cells (a given ``buffer``
    keeps its own count); ``fold_buffer(buffer, 1, K)`` sums them.
    """
    lanes = _single_lanes(geom, params, n, offset, double, center_uv)
    return _deposit_samples(geom, lanes, kernel_size=kernel_size, pitch=pitch, times=times,
                            sensor_table=sensor_table, linear=linear,
                            time_samples=time_samples, buffer=buffer, double=double)


def _deposit_samples(geom, lanes, *, kernel_size, pitch, times, sensor_table, linear,
                     time_samples, buffer, double):
    import drjit as dr

    m, Float, UInt32, Int32 = _deposit_types(double)
    K = int(kernel_size)
    KK = K * K
    Acc = m.Float64  # float32 sums of millions of rays drift by ~1 %: accumulate in float64
    sources = 1 if lanes.batch is None else lanes.batch.size
    buffer, copies = _new_buffer(buffer, Acc, sources, KK + 2)
    base = lanes.cell_base(KK + 2, copies)
    out = _trace(geom, lanes, double, time_dim=times is None)
    op = lambda x: dr.opaque(Float, float(x))  # noqa: E731
    landed, weight = out["landed"], out["weight"]
    inv_p = op(1.0 / pitch)
    au = dr.fma(out["Au"] - lanes.value("cu"), inv_p, K // 2 + 0.5)
    av = dr.fma(lanes.value("cv") - out["Av"], inv_p, K // 2 + 0.5)
    bu, bv = out["Bu"] * inv_p, -out["Bv"] * inv_p
    if times is not None:
        M = len(times)
        dists = [op(x) for x in times]
    else:
        M = int(time_samples)
        assert M >= 1
        xi = out["xi_t"]
        if linear is None:
            tab = Float(np.asarray(sensor_table, dtype=np.float64 if double else np.float32))
            nt = len(sensor_table) - 1
        dists = []
        for j in range(M):
            tt = (xi + j) * (1.0 / M)
            if linear is not None:
                dists.append(dr.fma(op(linear[1]) - op(linear[0]), tt, op(linear[0])))
            else:
                x = tt * nt
                k0 = UInt32(dr.minimum(dr.floor(x), nt - 1))
                fr = x - Float(k0)
                v0 = dr.gather(Float, tab, k0)
                v1 = dr.gather(Float, tab, k0 + 1)
                dists.append(v0 + (v1 - v0) * fr)
    wj = Acc(weight * (1.0 / M))
    free_only = out["landed_free"] & ~landed
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
                              active=out["landed_free"], mode=_MODE)
        else:
            dr.scatter_reduce(dr.ReduceOp.Add, buffer, wj, index, active=landed, mode=_MODE)
    return buffer


def deposit_segments(geom: Geometry, params: TraceParams, n: int, *, offset: int,
                     kernel_size: int, pitch: float, center_uv: tuple[float, float],
                     span: tuple[float, float], cdf_table: np.ndarray | None,
                     buffer: DrJitArray | None = None, double: bool = False) -> DrJitArray:
    """Trace ``n`` rays and add each ray's *whole sweep* to a (K·K + 2) Dr.Jit buffer.

    During the exposure a ray's sensor hit moves along the straight segment
    ``h(i) = A + B i``, ``i`` over the motion's span ``[i_lo, i_hi]``; the time it spends
    in a pixel is ``F(i_b) − F(i_a)``, where ``[i_a, i_b]`` is the part of the span over
    which the hit is in that pixel and ``F`` is the fraction of the exposure during which
    the sensor distance is below ``i`` (the motion's time CDF over its span). The
    segment is clipped to the window (slab test) and walked pixel by pixel (a 2-D DDA,
    Amanatides & Woo 1987), so each ray deposits its exact sweep integral: no time
    samples, no time noise. ``F`` is linear for a linear motion (``cdf_table=None``:
    exact); otherwise ``cdf_table`` holds ``F`` at uniform ``s = (i − i_lo)/(i_hi − i_lo)``
    and is interpolated linearly. Cells ``K·K`` and ``K·K+1`` as in :func:`deposit`.

    References
    ----------
    .. [1] J. Amanatides, A. Woo, "A fast voxel traversal algorithm for ray tracing",
       Eurographics 1987.
    """
    lanes = _single_lanes(geom, params, n, offset, double, center_uv,
                          coherent=_coherent_setting)
    return _deposit_sweeps(geom, lanes, kernel_size=kernel_size, pitch=pitch, span=span,
                           cdf_table=cdf_table, buffer=buffer, double=double)


def _deposit_sweeps(geom, lanes, *, kernel_size, pitch, span, cdf_table, buffer, double):
    import drjit as dr

    m, Float, UInt32, Int32 = _deposit_types(double)
    K = int(kernel_size)
    KK = K * K
    Acc = m.Float64
    sources = 1 if lanes.batch is None else lanes.batch.size
    buffer, copies = _new_buffer(buffer, Acc, sources, KK + 2)
    base = lanes.cell_base(KK + 2, copies)
    out = _trace(geom, lanes, double)
    op = lambda x: dr.opaque(Float, float(x))  # noqa: E731
    landed, weight = out["landed"], out["weight"]
    inv_p = op(1.0 / pitch)
    i_lo, i_hi = op(span[0]), op(span[1])
    # Pixel coordinates (col x, row y; integers at pixel edges) along s ∈ [0, 1].
    bu, bv = out["Bu"] * inv_p, -out["Bv"] * inv_p
    x0 = dr.fma(bu, i_lo, dr.fma(out["Au"] - lanes.value("cu"), inv_p, K // 2 + 0.5))
    y0 = dr.fma(bv, i_lo, dr.fma(lanes.value("cv") - out["Av"], inv_p, K // 2 + 0.5))
    dx, dy = bu * (i_hi - i_lo), bv * (i_hi - i_lo)
    if cdf_table is None:
        cdf = lambda s: s  # noqa: E731 - linear motion: F is linear in i
    else:
        tab = Float(np.asarray(cdf_table, dtype=np.float64 if double else np.float32))
        nt = len(cdf_table) - 1

        def cdf(s):
            x = dr.clip(s, 0.0, 1.0) * nt
            k0 = UInt32(dr.minimum(dr.floor(x), nt - 1))
            v0 = dr.gather(Float, tab, k0)
            return v0 + (dr.gather(Float, tab, k0 + 1) - v0) * (x - Float(k0))

    # Slab clip to the window [0, K)²: s_in ≤ s ≤ s_out is inside.
    def slab(p0, dp):
        inv = 1.0 / dp  # ±inf for a segment parallel to the slab
        t0, t1 = -p0 * inv, (K - p0) * inv
        flat = dp == 0.0
        inside = (p0 >= 0.0) & (p0 < K)
        lo = dr.select(flat, dr.select(inside, -math.inf, math.inf), dr.minimum(t0, t1))
        hi = dr.select(flat, dr.select(inside, math.inf, -math.inf), dr.maximum(t0, t1))
        return lo, hi

    lx, hx = slab(x0, dx)
    ly, hy = slab(y0, dy)
    s_in = dr.maximum(dr.maximum(lx, ly), 0.0)
    s_out = dr.minimum(dr.minimum(hx, hy), 1.0)
    crosses = landed & (s_in < s_out)
    f_in = dr.select(crosses, cdf(s_in), 0.0)
    f_out = dr.select(crosses, cdf(s_out), 0.0)
    w = Acc(weight)
    # The part outside the window (all of it if the segment misses it) to cell K·K; the
    # weight of rays only the rim stopped to cell K·K+1.
    free_only = out["landed_free"] & ~landed
    rest = w * Acc(1.0 - (f_out - f_in))
    outside = dr.select(free_only, UInt32(KK + 1), UInt32(KK))
    dr.scatter_reduce(dr.ReduceOp.Add, buffer, dr.select(free_only, w, rest),
                      outside if base is None else base + outside,
                      active=free_only | (landed & (rest > 0.0)), mode=_SWEEP_MODE)

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
                          active=active, mode=_SWEEP_MODE)
        index = index + dr.select(along_x, step_c, step_r * K)
        sx = dr.select(along_x, sx + dsx, sx)
        sy = dr.select(along_x, sy, sy + dsy)
        active = active & ~last & (index >= 0) & (index < KK)
        return s_next, f_next, index, sx, sy, active

    dr.while_loop(state=(s_in, f_in, row * K + col, sx, sy, crosses), cond=cond, body=body,
                  labels=("s", "f_s", "index", "sx", "sy", "active"), label="segment DDA")
    return buffer


def deposit_batch(batch: SourceBatch, log2_count: int, *, offset: int, kernel_size: int,
                  pitch: float, exact: bool, times: list | None = None,
                  sensor_table: np.ndarray | None = None,
                  linear: tuple[float, float] | None = None, time_samples: int = 1,
                  span: tuple[float, float] | None = None,
                  cdf_table: np.ndarray | None = None,
                  buffer: DrJitArray | None = None) -> DrJitArray:
    """Trace samples ``offset … offset + 2^log2_count − 1`` of every source of ``batch``
    and deposit them, in one launch, into a stacked (S·(K·K + 2)) Dr.Jit buffer.

    Source ``j`` owns cells ``j·(K·K+2) …`` of each of the buffer's copies (as in
    :func:`deposit`; ``fold_buffer(buffer, S, K)`` sums them), laid out as the
    one-source buffer of :func:`deposit_segments` (``exact``: ``span``, ``cdf_table``) or
    :func:`deposit` (``times``, ``sensor_table``, ``linear``, ``time_samples``); the window
    of source ``j`` is centred on the batch's ``center_uv[j]``.
    """
    lanes = _Lanes(batch.double, 0, offset, batch=batch, log2_count=int(log2_count),
                   coherent=exact and _coherent_setting)
    if exact:
        return _deposit_sweeps(batch.geometry, lanes, kernel_size=kernel_size, pitch=pitch,
                               span=span, cdf_table=cdf_table, buffer=buffer,
                               double=batch.double)
    return _deposit_samples(batch.geometry, lanes, kernel_size=kernel_size, pitch=pitch,
                            times=times, sensor_table=sensor_table, linear=linear,
                            time_samples=time_samples, buffer=buffer, double=batch.double)
