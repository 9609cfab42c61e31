"""Sample streams of the ray kernel: which sample each lane traces, for which source.

Stage *sample* of the kernel (:mod:`mitsweep.tracer.stages` has the optics). A trace
samples the aim-plane point ``(a, b)`` of each ray (and, for stratified times, a time
coordinate) from a rank-1 lattice with Cranley-Patterson shifts drawn from the seed
(:func:`lattice_coordinates`). The lanes of a launch (:class:`Lanes`) know their sample
index and their source's values: opaque literals for one source, or rows of a
:class:`SourceBatch`'s packed table gathered by source index.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ..backend import drjit_module
from .geometry import Geometry, TraceParams

__all__ = ["SourceBatch", "lattice_coordinates"]

# Golden-ratio generalisations for rank-1 lattices (Roberts' R_d sequences): φ_d is the
# real root of x^(d+1) = x + 1 and the generators are 1/φ_d, ..., 1/φ_d^d. R3 samples
# (a, b, t) of the stratified method; every other trace samples (a, b) only, with R2:
# a projection of R3 onto two coordinates is a poor 2-D sequence (measured on the
# sphere's bank: L1 6e-3 at 2^16 rays with R3's first two generators, 3.5e-4 with R2).
_PHI3 = 1.2207440846057596
_PHI2 = 1.3247179572447460

#: drjit-core's LLVM work unit (``jit_llvm_block_size``): the lanes a worker thread runs
#: together. Lanes of one block write one copy of a deposit buffer.
LLVM_BLOCK_LOG2 = 14

R3 = tuple(int(round((1.0 / _PHI3 ** (j + 1)) % 1.0 * 2 ** 32)) & 0xFFFFFFFF for j in range(3))
R2 = tuple(int(round((1.0 / _PHI2 ** (j + 1)) % 1.0 * 2 ** 32)) & 0xFFFFFFFF for j in range(2))
#: Steps h > 16 at which R2's points come closer to each other than at any smaller step:
#: the successive minima of max_j |frac(h g_j)| (signed, from the 32-bit generators;
#: tests/test_tracer_deposit.py recomputes them). Points k, k + h, ..., k + 15h then lie on
#: a segment 16 max_j |frac(h g_j)| long (1 % of the unit square at h = 922111).
R2_STEPS = (37, 49, 65, 114, 151, 200, 465, 616, 816, 1432, 1897, 2513, 5842, 7739, 10252,
             17991, 23833, 31572, 73396, 97229, 226030, 299426, 396655, 922111)
#: Lanes of a coherent group (:func:`coherent_segments`), and segments per launch.
GROUP = 16
SEGMENTS = 4


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
        m, Float, _ = array_types(double)
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


class Lanes:
    """The lanes of one launch: each lane's sample index and its source's values.

    One source: lane ``k`` traces sample ``offset + k`` and the source's values are
    opaque literals (the kernel compiles once and is reused with new values). A
    :class:`SourceBatch` with ``2^p`` samples per source: lane ``k`` traces sample
    ``offset + (k mod 2^p)`` of source ``k >> p``, whose values are gathered from the
    batch's table. With ``coherent``, ``k`` (mod ``2^p``) is first reordered by
    :func:`coherent_order`: the same samples, in an order where neighbouring lanes
    trace neighbouring rays.

    Parameters
    ----------
    double : bool
        float64 lanes (default float32 of the backend).
    n : int
        Lanes of a one-source launch (ignored with ``batch``: ``S · 2^log2_count``).
    offset : int
        Sample index of the first lane (of each source, with ``batch``).
    columns : dict, optional
        The one source's values by name (:data:`_COLUMNS`); required without ``batch``.
    seed : int, optional
        The one source's lattice seed (default 0).
    ellipse : bool, optional
        The one source samples an ellipse (default: a box).
    batch : SourceBatch, optional
        Sources traced together; their values are gathered from its table.
    log2_count : int, optional
        Base-2 logarithm of the samples per source of ``batch`` (at most 2^32 from
        ``offset``).
    coherent : bool, optional
        Reorder the samples by :func:`coherent_order` (default False).

    Raises
    ------
    ValueError
        A one-source launch without ``columns``, or a batch beyond 2^32 samples.
    """

    def __init__(self, double: bool, n: int, offset: int, *, columns: dict | None = None,
                 seed: int = 0, ellipse: bool = False, batch: SourceBatch | None = None,
                 log2_count: int = 0, coherent: bool = False) -> None:
        import drjit as dr

        m, Float, _ = array_types(double)
        UInt32 = m.UInt32
        self._float = Float
        self._cache: dict[str | int, Any] = {}
        self.batch = batch
        #: True / False when every lane samples an ellipse / a box, None when mixed.
        self.ellipse: bool | None
        if batch is None:
            self.n = int(n)
            self.lane = dr.arange(UInt32, self.n)
            local = coherent_order(self.lane, self.n) if coherent else self.lane
            self.index = local + dr.opaque(UInt32, offset & 0xFFFFFFFF)
            self.source = None
            if columns is None:
                raise ValueError("Lanes: one source (no batch) needs its columns")
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
                local = coherent_order(local, 1 << log2_count)
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

    def value(self, name: str) -> Any:
        """The lanes' source value ``name`` (one of :data:`_COLUMNS`).

        Parameters
        ----------
        name : str
            A column of the source table, e.g. ``"depth"``, ``"cu"`` (mm).

        Returns
        -------
        drjit Float
            An opaque literal for one source; per lane, gathered, for a batch (cached).
        """
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

    def cell_base(self, cells: int, copies: int = 1) -> Any:
        """Index of each lane's first buffer cell, ``copy · S · cells + source · cells``
        (None where it is 0 for every lane: one source, one copy).

        The buffer holds ``copies`` (a power of two) copies of the ``S`` sources' cells;
        a lane writes copy ``(lane >> 14) mod copies``, so the lanes of one work unit
        (a thread's block) share a copy and concurrent blocks write different ones.

        Parameters
        ----------
        cells : int
            Cells per source (``K·K + 2``).
        copies : int, optional
            Copies of the buffer, a power of two (default 1).

        Returns
        -------
        drjit UInt32 or None
        """
        import drjit as dr

        sources = 1 if self.batch is None else self.batch.size
        base = None if self.source is None else self.source * cells
        if copies > 1:
            UInt32 = type(self.lane)
            copy = (self.lane >> LLVM_BLOCK_LOG2) & dr.opaque(UInt32, copies - 1)
            offset = copy * (sources * cells)
            base = offset if base is None else base + offset
        return base


def single_lanes(geom: Geometry, params: TraceParams, n: int, offset: int, double: bool,
                 center_uv: tuple[float, float] | None = None, coherent: bool = False
                 ) -> Lanes:
    """The lanes of a one-source launch: ``n`` samples from ``offset`` of ``params``'s
    stream, the source's values as opaque literals.

    Parameters
    ----------
    geom : Geometry
        The source and the optics.
    params : TraceParams
        Sampling domain and seed.
    n : int
        Lanes.
    offset : int
        Sample index of the first lane.
    double : bool
        float64 lanes.
    center_uv : (float, float), optional
        Window centre of a deposit, upright image mm (None: unused, zeros).
    coherent : bool, optional
        As :class:`Lanes`.

    Returns
    -------
    Lanes
    """
    return Lanes(double, n, offset, columns=_source_columns(geom, params, center_uv),
                 seed=params.seed, ellipse=params.ellipse is not None, coherent=coherent)


@functools.lru_cache(maxsize=256)
def coherent_segments(count: int) -> tuple[tuple[int, int], ...]:
    """Segments ``(start, h)`` of ``[0, count)`` for :func:`coherent_order`.

    Greedy: each segment is ``16 h`` lanes long, ``h`` the largest of
    :data:`R2_STEPS` that fits what is left; at most :data:`SEGMENTS` segments, the
    lanes after them keep their order. Padded with empty segments ``(end, 1)``.
    """
    segments: list[tuple[int, int]] = []
    start = 0
    while len(segments) < SEGMENTS:
        fits = [h for h in R2_STEPS if GROUP * h <= count - start]
        if not fits:
            break
        segments.append((start, fits[-1]))
        start += GROUP * fits[-1]
    segments += [(start, 1)] * (SEGMENTS - len(segments))
    return tuple(segments)


def coherent_order(local: Any, count: int) -> Any:
    """A permutation of the lanes ``local`` in ``[0, count)``: sample index per lane.

    In a segment ``(start, h)`` lane ``start + 16 p + j`` (``p < h``, ``j < 16``) takes
    sample ``start + p + j h``, a bijection of the segment onto itself; so the 16 lanes
    of a group trace R2's points ``x, x + δ, ..., x + 15 δ`` with ``δ = frac(h g)`` small
    (:data:`R2_STEPS`): neighbouring rays, which mostly hit the same pixels. Their
    scatters then pre-reduce within the packet (``ReduceMode.Local``), one atomic per
    distinct pixel instead of one per lane. The set of samples, and so the estimate, is
    unchanged. The segment bounds are opaque: one kernel serves every ``count``.

    Parameters
    ----------
    local : drjit UInt32
        Lane indices in ``[0, count)``.
    count : int
        Lanes per source (segments of :func:`coherent_segments`).

    Returns
    -------
    drjit UInt32
        The sample index of each lane.
    """
    import drjit as dr

    UInt32 = type(local)
    out = local
    for start, h in reversed(coherent_segments(int(count))):
        rel = local - dr.opaque(UInt32, start)
        p, j = rel >> (GROUP.bit_length() - 1), rel & (GROUP - 1)
        mapped = dr.opaque(UInt32, start) + p + j * dr.opaque(UInt32, h)
        out = dr.select(local < dr.opaque(UInt32, start + GROUP * h), mapped, out)
    return out


def array_types(double: bool) -> tuple[Any, type, type]:
    """``(module, Float, Array3)`` of the selected backend, float64 with ``double``.

    Parameters
    ----------
    double : bool
        float64 types (else float32).
    """
    m = drjit_module()
    if double:
        return m, m.Float64, m.Array3f64
    return m, m.Float, m.Array3f


def lattice_coordinates(index: Any, shifts: Sequence[Any], generators: Sequence[int],
                        Float: type) -> list:
    """Coordinates in [0, 1) of lattice points ``index`` (stage *sample*).

    Coordinate ``j`` is ``frac(index · g_j + shift_j)``, computed exactly in 32-bit fixed
    point (``g_j``, ``shift_j`` and the result scaled by 2³²; unsigned wrap-around is the
    fraction), of which the top 24 bits become a ``Float`` in [0, 1).

    Parameters
    ----------
    index : drjit UInt32 array
        Sample indices.
    shifts : sequence of drjit UInt32
        Cranley-Patterson shifts (at least one per generator; extra ones are ignored).
    generators : sequence of int
        32-bit fixed-point generators (:data:`R2` or :data:`R3`).
    Float : type
        The Dr.Jit float type of the result.
    """
    UInt32 = type(index)
    return [Float((index * UInt32(g) + s) >> 8) * (2.0 ** -24)
            for g, s in zip(generators, shifts)]

