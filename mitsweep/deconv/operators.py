r"""The spatially varying blur as a matrix-free linear operator (forward and adjoint).

Two constructions of the same physical model, one per kind of IPSF bank:

- :func:`product_convolution_operator` (``kind="grid"`` banks, any setup):
  :math:`A x = \sum_b k_b \circledast (w_b \cdot x)`, zero outside the image, with the
  bilinear hat windows :math:`w_b` of :mod:`.spatial` [1]_. Its adjoint is
  :math:`A^\top y = \sum_b w_b \cdot (\tilde k_b \circledast y)` with the flipped kernels
  :math:`\tilde k_b`. This is exactly the per-pixel blur with the interpolated kernels
  :math:`k_p = \sum_b w_b(p) k_b` (:func:`~mitsweep.deconv.spatial.scatter_blur`).
- :func:`polar_operator` (``kind="radial"`` banks, untilted mirrors):
  :math:`A = B\, C\, S + P_{\text{out}}`. :math:`S` samples the image on a
  :class:`~mitsweep.deconv.polar.PolarGrid` (bilinear), :math:`C` is the blur in polar
  coordinates — circulant in angle, a product-convolution over radius with hat windows
  between band radii, each band's transfer function that of the bank's IPSF at the
  band's radius (as in :func:`~mitsweep.deconv.polar.polar_deconvolve`) — and :math:`B`
  maps back to pixels (bilinear). Pixels beyond the grid's ``r_max`` pass unchanged
  (:math:`P_{\text{out}}`). :math:`S` and :math:`B` are sparse matrices whose adjoints
  are their transposes, so the adjoint is exact to round-off.

Both are :class:`BlurOperator` objects: plain ``forward(x)`` / ``adjoint(y)`` callables
on (H, W) arrays, with :meth:`BlurOperator.as_pylops` for researchers who want to run
their own solvers (pylops is optional: imported only there).

References
----------
.. [1] J. G. Nagy and D. P. O'Leary, "Restoring images degraded by spatially variant
   blur", SIAM J. Sci. Comput. 19(4), 1063–1082, 1998.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

import numpy as np
from numpy.typing import DTypeLike
import scipy.fft as sfft
import scipy.sparse as sp
import scipy.signal as ssig

from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from .kernels import check_bank_matches, interpolate_radial, radii_px, select_depth
from .polar import PolarGrid, polar_grid
from .polar.bands import band_length, band_transfer
from .spatial import _support, grid_axes_px, grid_windows, hat_weights

__all__ = ["BlurOperator", "polar_operator", "product_convolution_operator",
           "polar_bands", "bilinear_matrix", "dense_matrix", "dot_product_error"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class BlurOperator:
    """A linear blur ``A`` on (H, W) images, given by its forward and adjoint maps.

    Attributes
    ----------
    shape : (H, W)
        Image shape the operator acts on (input and output alike).
    forward, adjoint : callable
        ``forward(x) -> A x`` and ``adjoint(y) -> Aᵀ y`` on (H, W) arrays; float32 stays
        float32.
    kind : str
        ``"polar"`` or ``"product-convolution"``.
    """

    shape: tuple[int, int]
    forward: Callable[[np.ndarray], np.ndarray]
    adjoint: Callable[[np.ndarray], np.ndarray]
    kind: str
    info: dict = field(default_factory=dict, compare=False)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.forward(x)

    def as_pylops(self, dtype: DTypeLike = np.float64) -> Any:
        """This operator as a ``pylops.LinearOperator`` with ``dims = dimsd = shape``.

        pylops is optional for mitsweep; ImportError (with the install command) when it
        is absent.

        Parameters
        ----------
        dtype : dtype
            The linear operator's dtype; vectors are cast to it before and after each
            product (default float64).
        """
        try:
            import pylops
        except ImportError:
            raise ImportError("BlurOperator.as_pylops needs pylops, which is optional for "
                              "mitsweep: pip install pylops") from None
        op = self
        dt = np.dtype(dtype)

        class _Blur(pylops.LinearOperator):
            def __init__(self):
                super().__init__(dtype=dt, dims=op.shape, dimsd=op.shape,
                                 name=f"mitsweep {op.kind} blur")

            def _matvec(self, x):
                return op.forward(np.asarray(x, dtype=dt).reshape(op.shape)).astype(
                    dt, copy=False).ravel()

            def _rmatvec(self, y):
                return op.adjoint(np.asarray(y, dtype=dt).reshape(op.shape)).astype(
                    dt, copy=False).ravel()

        return _Blur()


def _as_image(x: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    a = np.asarray(x)
    if a.shape != tuple(shape):
        raise ValueError(f"operator acts on images of shape {tuple(shape)}, got {a.shape}")
    if a.dtype != np.float32:
        a = a.astype(np.float64, copy=False)
    return a


# -- product-convolution (grid banks) ------------------------------------------------

@renamed_keywords(depth_mm="depth")
def product_convolution_operator(bank: IPSFBank, image_shape: tuple[int, int], *,
                                 depth: float | str | None = None) -> BlurOperator:
    """The blur of a ``kind="grid"`` bank as a :class:`BlurOperator` (zero boundary).

    Parameters
    ----------
    bank : IPSFBank
        A grid bank matching the image (:func:`~mitsweep.deconv.kernels.check_bank_matches`).
    image_shape : (H, W)
        The shape of the images the operator acts on.
    depth : float, "mean" or None
        The bank depth whose kernels blur, as in
        :func:`~mitsweep.deconv.kernels.select_depth` (default 500 mm).
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    check_bank_matches(bank, shape)
    if bank.kind != "grid":
        raise BankError(f"a product-convolution operator needs a grid bank, got {bank.kind!r}")
    rows, cols = grid_axes_px(bank, shape)
    wy, wx = grid_windows(rows, cols, shape)
    kernels = select_depth(bank, depth).astype(np.float64)
    n_c = wx.shape[0]
    cells = []
    for i in range(wy.shape[0]):
        y0, y1 = _support(wy[i])
        for j in range(n_c):
            x0, x1 = _support(wx[j])
            cells.append((y0, y1, x0, x1, wy[i, y0:y1, None] * wx[j, None, x0:x1],
                          kernels[i * n_c + j]))
    K = kernels.shape[-1]
    h = K // 2
    H, W = shape

    def forward(x):
        x = _as_image(x, shape)
        dt = x.dtype
        out = np.zeros((H + 2 * h, W + 2 * h), dtype=dt)
        for y0, y1, x0, x1, win, k in cells:
            out[y0:y1 + 2 * h, x0:x1 + 2 * h] += ssig.fftconvolve(
                x[y0:y1, x0:x1] * win.astype(dt), k.astype(dt), mode="full")
        return np.ascontiguousarray(out[h:h + H, h:h + W])

    def adjoint(y):
        y = _as_image(y, shape)
        dt = y.dtype
        padded = np.pad(y, h)
        out = np.zeros(shape, dtype=dt)
        for y0, y1, x0, x1, win, k in cells:
            # correlation with k = convolution with the flipped kernel, "valid" over the
            # window's support grown by the kernel's reach
            out[y0:y1, x0:x1] += win.astype(dt) * ssig.fftconvolve(
                padded[y0:y1 + 2 * h, x0:x1 + 2 * h], k[::-1, ::-1].astype(dt), mode="valid")
        return out

    return BlurOperator(shape=shape, forward=forward, adjoint=adjoint,
                        kind="product-convolution", info={"cells": len(cells), "kernel_px": K})


# -- polar (radial banks) ------------------------------------------------------------

def bilinear_matrix(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int], *,
                    wrap_cols: bool = False, dtype: DTypeLike = np.float64) -> sp.csr_matrix:
    """(n_points, H·W) sparse matrix of bilinear interpolation at fractional (rows, cols).

    Row-major (C-order) pixel indices; neighbours outside ``shape`` contribute zero
    (``wrap_cols``: columns are periodic, as the angle axis of a polar image).
    Its transpose is the exact adjoint (the spreading of each sample onto its four
    neighbours).

    Parameters
    ----------
    rows, cols : ndarray
        Fractional pixel coordinates of the points (any shape, flattened in C order).
    shape : (H, W)
        The image's shape.
    wrap_cols : bool
        Columns are periodic (default False: beyond the edges, zero).
    dtype : dtype
        The matrix's precision (default float64).
    """
    r = np.asarray(rows, dtype=np.float64).ravel()
    c = np.asarray(cols, dtype=np.float64).ravel()
    H, W = int(shape[0]), int(shape[1])
    r0 = np.floor(r)
    c0 = np.floor(c)
    fr, fc = r - r0, c - c0
    r0 = r0.astype(np.int64)
    c0 = c0.astype(np.int64)
    n = r.size
    # built directly in CSR layout, four entries per point (out-of-image neighbours get
    # weight 0 and are dropped): a COO detour cost 2 of 3 s of polar_operator at 1024²
    idx = np.empty((n, 4), dtype=np.int64)
    val = np.empty((n, 4), dtype=np.float64)
    for q, (dr, dc) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        rr, cc = r0 + dr, c0 + dc
        if wrap_cols:
            cc %= W
        w = (fr if dr else 1 - fr) * (fc if dc else 1 - fc)
        ok = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
        idx[:, q] = np.where(ok, rr * W + cc, 0)
        val[:, q] = np.where(ok, w, 0.0)
    m = sp.csr_matrix((val.ravel().astype(dtype), idx.ravel(),
                       np.arange(0, 4 * n + 1, 4, dtype=np.int64)), shape=(n, H * W))
    m.eliminate_zeros()
    return m


@dataclass(frozen=True)
class PolarBand:
    """One radial band of the polar blur (:func:`polar_bands`).

    Attributes
    ----------
    radius : float
        The band's centre radius, px.
    lo, hi : int
        Polar-grid rows ``lo:hi`` where the band's window is non-zero.
    s0, s1 : int
        Context rows ``s0:s1`` the band's convolution reads (the window's support plus
        the kernel's reach).
    L : int
        FFT length along radius.
    mc : int
        Angular harmonics filtered (the higher ones pass unchanged).
    weights : (hi - lo,) ndarray
        The band's hat window on rows ``lo:hi``.
    H : (L, mc) complex ndarray
        The band's transfer function.
    """

    radius: float
    lo: int
    hi: int
    s0: int
    s1: int
    L: int
    mc: int
    weights: np.ndarray
    H: np.ndarray


def polar_bands(kernels: np.ndarray, radii: np.ndarray, grid: PolarGrid, *,
                band_spacing: float = 0.25, margin_px: float | None = None,
                r_in: float | None = None, dtype: DTypeLike = np.float64) -> list[PolarBand]:
    """The radial bands of the polar blur on ``grid`` (as :func:`polar_deconvolve`).

    Band centres start at ``r_in / 2`` (default ``max(2 K, 8)`` px: inside ``r_in`` a
    polar grid cannot hold a kernel) and follow each other by ``band_spacing`` of their
    radius, at least one kernel size apart; hat windows between centres sum to one.
    Each band's rows ``s0:s1`` are its window's support plus ``margin_px`` (default
    K / 2 + 2: the kernel's reach, for a zero-boundary convolution), and ``L`` a fast
    FFT length of at least those rows plus the reach again.

    Parameters
    ----------
    kernels : (n, K, K) ndarray
        Unit-sum kernels of a radial bank, one per radius.
    radii : (n,) ndarray
        The kernels' radii, px.
    grid : PolarGrid
        The polar grid the blur acts on.
    band_spacing : float
        Distance between band centres as a fraction of their radius (default 0.25).
    margin_px : float, optional
        Context rows beyond each window's support, px (default K / 2 + 2).
    r_in : float, optional
        Radius, px, inside which no band is centred (default ``max(2 K, 8)``).
    dtype : float32 or float64
        Precision of the windows and transfer functions.
    """
    K = kernels.shape[-1]
    step = grid.radial_step
    cdt = np.complex64 if np.dtype(dtype) == np.float32 else np.complex128
    r_in = max(2.0 * K, 8.0) if r_in is None else float(r_in)
    centres = [r_in / 2]
    while centres[-1] < grid.r_max:
        centres.append(centres[-1] + max(band_spacing * centres[-1], float(K)))
    centres[-1] = max(min(centres[-1], grid.r_max), centres[-2] + 1.0)
    weights = hat_weights(grid.radii, np.asarray(centres))
    reach = int(math.ceil(((K // 2 + 2) if margin_px is None else margin_px) / step))
    M = grid.n_angles // 2 + 1
    bands = []
    for b, rb in enumerate(centres):
        nz = np.flatnonzero(weights[b] > 0)
        lo, hi = int(nz[0]), int(nz[-1]) + 1
        s0, s1 = max(0, lo - reach), min(grid.n_radii, hi + reach)
        L = band_length(s1 - s0 + reach, step)
        r_hi = max(float(grid.radii[s1 - 1]), rb)
        mc = int(min(M, math.ceil(2 * math.pi * r_hi / math.sqrt(2)) + 8))
        Hb = band_transfer(interpolate_radial(kernels, radii, rb), rb, step, L, mc, cdt)
        bands.append(PolarBand(radius=float(rb), lo=lo, hi=hi, s0=s0, s1=s1, L=L, mc=mc,
                               weights=weights[b, lo:hi].astype(dtype), H=Hb))
    return bands


def _polar_blur(spec: np.ndarray, bands: list[PolarBand], *, adjoint: bool) -> np.ndarray:
    """C (or Cᵀ) on the angle spectrum (n_r, M) of a polar image.

    Forward: each band's windowed rows, zero-padded to its FFT length, convolved along
    radius and angle with the band's kernel, cropped to its context rows; the adjoint
    does the same with the conjugate transfer function and windows after the blur.
    Harmonics above a band's ``mc`` (beyond what the pixel grid can hold there) pass
    unchanged, which is self-adjoint.
    """
    out = np.zeros_like(spec)
    for b in bands:
        n = b.s1 - b.s0
        mc = b.mc
        w = b.weights[:, None]
        buf = np.zeros((b.L, mc), dtype=spec.dtype)
        # in place, no temporaries: an operator call is mostly these FFTs
        if not adjoint:
            np.multiply(w, spec[b.lo:b.hi, :mc], out=buf[b.lo - b.s0:b.hi - b.s0])
            buf = sfft.fft(buf, axis=0, workers=-1, overwrite_x=True)
            buf *= b.H
        else:
            buf[:n] = spec[b.s0:b.s1, :mc]
            # conj(conj(F) H) = F conj(H)
            buf = np.conjugate(sfft.fft(buf, axis=0, workers=-1, overwrite_x=True), out=buf)
            buf *= b.H
            np.conjugate(buf, out=buf)
        buf = sfft.ifft(buf, axis=0, workers=-1, overwrite_x=True)
        if not adjoint:
            out[b.s0:b.s1, :mc] += buf[:n]
        else:
            buf = buf[b.lo - b.s0:b.hi - b.s0]
            buf *= w
            out[b.lo:b.hi, :mc] += buf
        if mc < spec.shape[1]:
            out[b.lo:b.hi, mc:] += w * spec[b.lo:b.hi, mc:]
    return out


@renamed_keywords(depth_mm="depth")
def polar_operator(bank: IPSFBank, image_shape: tuple[int, int], *,
                   depth: float | str | None = None,
                   center: tuple[float, float] | None = None, r_max: float | None = None,
                   radial_oversampling: float = 1.5, angular_oversampling: float = 1.25,
                   band_spacing: float = 0.25, dtype: DTypeLike = np.float64) -> BlurOperator:
    r"""The blur of a ``kind="radial"`` bank as a :class:`BlurOperator`.

    Parameters
    ----------
    bank : IPSFBank
        Radial bank (kernels on the +u axis).
    image_shape : (H, W)
        The shape of the images the operator acts on.
    depth, center, r_max, radial_oversampling, angular_oversampling, band_spacing
        As in :func:`~mitsweep.deconv.polar.polar_deconvolve`.
    dtype : float32 or float64
        Precision of the sparse resampling matrices and transfer functions.

    Notes
    -----
    .. math:: A = B\,\mathcal F_\theta^{-1} C\, \mathcal F_\theta\, S + P_{\text{out}},
              \qquad A^\top = S^\top \mathcal F_\theta^{-1} C^H \mathcal F_\theta\, B^\top
              + P_{\text{out}}

    with :math:`\mathcal F_\theta` the DFT along angle and :math:`C` the band filters
    (:func:`polar_bands`) on each angular harmonic.
    """
    shape = (int(image_shape[0]), int(image_shape[1]))
    check_bank_matches(bank, shape)
    kernels = select_depth(bank, depth).astype(np.float64)
    rad = radii_px(bank)
    K = kernels.shape[-1]
    dt = np.dtype(np.float32) if np.dtype(dtype) == np.float32 else np.dtype(np.float64)
    if r_max is None:
        far = polar_grid(shape, center=center).r_max
        r_max = min(float(rad.max()) + K, far)
    grid = polar_grid(shape, center=center, r_max=r_max,
                      radial_oversampling=radial_oversampling,
                      angular_oversampling=angular_oversampling, inner_px=8.0, outer_px=8.0)
    H, W = shape
    cy, cx = grid.center
    # S: pixels sampled at the polar points (pixel centres at integer coordinates)
    r = grid.radii[:, None]
    th = grid.angles[None, :]
    S = bilinear_matrix(cy - r * np.sin(th), cx + r * np.cos(th), shape, dtype=dt)
    # B: each pixel inside r_max read from the polar grid (angle periodic)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    rr = np.hypot(cy - yy, xx - cx)
    inside = (rr <= grid.r_max).ravel()
    tt = np.mod(np.arctan2(cy - yy, xx - cx), 2 * math.pi)
    Bm = bilinear_matrix(grid.row_of(rr.ravel()[inside]),
                         tt.ravel()[inside] / grid.angle_step,
                         (grid.n_radii, grid.n_angles), wrap_cols=True, dtype=dt)
    inside_idx = np.flatnonzero(inside)
    outside = ~inside
    # the adjoint's matrices stored as CSR too (a CSC product, S.T @, took 1.3 times as
    # long as the CSR one per call)
    St, Bt = S.T.tocsr(), Bm.T.tocsr()
    bands = polar_bands(kernels, rad, grid, band_spacing=band_spacing, dtype=dt)
    n_a = grid.n_angles

    def _apply(x, adj):
        x = _as_image(x, shape)
        xd = x.astype(dt, copy=False).ravel()
        if not adj:
            pol = (S @ xd).reshape(grid.n_radii, n_a)
        else:
            pol = np.zeros(grid.n_radii * n_a, dtype=dt)
            pol += Bt @ xd[inside_idx]
            pol = pol.reshape(grid.n_radii, n_a)
        # C acts on harmonics m >= 0; negative m are their conjugates (real kernels and
        # images), so the half spectrum is filtered and irfft rebuilds the rest. At m = 0
        # and n_a / 2 irfft keeps the real part, i.e. applies Re(C_m), whose transpose is
        # what the conjugate filter gives on a real input: the pair stays exact.
        fil = _polar_blur(sfft.rfft(pol, axis=1, workers=-1), bands, adjoint=adj)
        pol = sfft.irfft(fil, n=n_a, axis=1, workers=-1).astype(dt, copy=False).ravel()
        out = np.empty(H * W, dtype=dt)
        if not adj:
            out[inside_idx] = Bm @ pol
        else:
            out[:] = St @ pol
        out[outside] = (out[outside] if adj else 0.0) + xd[outside]
        return out.reshape(shape).astype(x.dtype, copy=False)

    return BlurOperator(shape=shape, forward=lambda x: _apply(x, False),
                        adjoint=lambda y: _apply(y, True), kind="polar",
                        info={"grid": grid, "bands": len(bands), "kernel_px": K})


# -- checks --------------------------------------------------------------------------

def dense_matrix(op: BlurOperator) -> np.ndarray:
    """(H·W, H·W) matrix of ``op`` (column j = forward of the j-th unit image); small
    images only.

    Parameters
    ----------
    op : BlurOperator
        An operator on images of at most 4096 pixels.
    """
    H, W = op.shape
    n = H * W
    if n > 4096:
        raise ValueError(f"dense_matrix is for small images (<= 4096 px), got {H}x{W}")
    A = np.empty((n, n))
    e = np.zeros(n)
    for j in range(n):
        e[j] = 1.0
        A[:, j] = op.forward(e.reshape(H, W)).ravel()
        e[j] = 0.0
    return A


def dot_product_error(op: BlurOperator, rng: np.random.Generator | int = 0,
                      dtype: DTypeLike = np.float64) -> float:
    """Relative error of the dot-product test ``|<A x, y> − <x, Aᵀ y>| / (|A x| |y|)``
    for random x, y.

    Parameters
    ----------
    op : BlurOperator
        The operator whose adjoint is tested.
    rng : numpy.random.Generator or int
        Source of x and y (an int seeds ``numpy.random.default_rng``; default 0).
    dtype : dtype
        Precision of x and y, and so of the operator's products (default float64).
    """
    gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(int(rng))
    x = gen.standard_normal(op.shape).astype(dtype)
    y = gen.standard_normal(op.shape).astype(dtype)
    Ax, ATy = op.forward(x), op.adjoint(y)
    lhs = float(np.vdot(Ax.astype(np.float64), y.astype(np.float64)))
    rhs = float(np.vdot(x.astype(np.float64), ATy.astype(np.float64)))
    return abs(lhs - rhs) / (float(np.linalg.norm(Ax)) * float(np.linalg.norm(y)))
