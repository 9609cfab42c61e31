r"""Prior-based restoration of the spatially varying focal-sweep blur.

- :func:`richardson_lucy`: Richardson–Lucy (the Poisson maximum-likelihood iteration)
  with any :class:`~mitsweep.deconv.operators.BlurOperator`, damped as White (1994) so
  that residuals within the noise stop driving the update, stopped by the
  discrepancy principle [1]_ [2]_.
- :func:`hqs_deconvolve`: half-quadratic splitting [3]_ for

  .. math:: \min_x \tfrac12 \lVert A x - y \rVert^2 + \lambda \sum_p \phi(\nabla x_p),
            \qquad \phi(g) = |g| \;(\text{TV}) \text{ or } |g_1|^{2/3} + |g_2|^{2/3}
            \;(\text{hyper-Laplacian})

  alternating a pointwise shrinkage of the gradients (soft threshold for TV, the
  α = 2/3 shrinkage by table for the hyper-Laplacian) with a quadratic step
  :math:`(A^\top A + \beta D^\top D)\,x = A^\top y + \beta D^\top z` for increasing β.
  The quadratic step uses the structure the Wiener filters use: for a radial bank it is
  solved in polar coordinates, band by band, in the Fourier domain of (radius, angular
  harmonic) where the blur of a band is circulant in angle
  (:func:`~mitsweep.deconv.polar.polar_deconvolve`'s bands); for a grid bank tile by tile
  with each tile's IPSF, blended by the product-convolution windows
  (:func:`~mitsweep.deconv.spatial.spatially_varying_deconvolve`'s tiles). Each step is
  then a few FFTs, as in Krishnan and Fergus's shift-invariant solver.

Both are deterministic, keep float32 as float32, never clip their output, and report
progress (tqdm on stderr) when asked.

References
----------
.. [1] L. B. Lucy, "An iterative technique for the rectification of observed
   distributions", Astron. J. 79, 745, 1974.
.. [2] R. L. White, "Image restoration using the damped Richardson-Lucy method",
   Proc. SPIE 2198, 1342–1348, 1994.
.. [3] D. Krishnan and R. Fergus, "Fast image deconvolution using hyper-Laplacian
   priors", NIPS 2009.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np
import scipy.fft as sfft

from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from .kernels import check_bank_matches, interpolate_radial, radii_px, select_depth
from .noise import SensorNoise
from .operators import BlurOperator, polar_bands
from .polar import _channels, from_polar, polar_grid, to_polar
from .regularization import (DISCREPANCY_TAU, _discrepancy, _gcv, _residual_spectrum,
                             noise_sigma, prior_weight, surrogate_kernel)
from .spatial import _support, grid_axes_px, grid_windows
from .wiener import check_image_values, fast_shape, kernel_spectrum, working_dtype

__all__ = ["richardson_lucy", "hqs_deconvolve", "shrink_tv", "shrink_hyper_laplacian",
           "PRIORS", "DATA_TERMS", "DEFAULT_HQS_STEPS", "BETA_MAX", "MAX_RL_ITERATIONS",
           "RL_BOUNDARIES"]

logger = logging.getLogger(__name__)

#: Gradient priors of :func:`hqs_deconvolve` and their exponent α.
PRIORS = {"tv": 1.0, "hyperlaplacian": 2.0 / 3.0}
#: β steps of HQS when ``iterations`` is None: β/λ from 1 to (2√2)^7 ≈ 181 (Krishnan and
#: Fergus's schedule, one inner iteration per β).
DEFAULT_HQS_STEPS = 8
_BETA_RATE = 2.0 * math.sqrt(2.0)
#: Richardson–Lucy's cap when the stopping rule decides.
MAX_RL_ITERATIONS = 60
#: Largest β of the continuation, in units of the data term's largest ``|H|²`` (1): beyond,
#: the prior's quadratic term outweighs the data's so far that the approximate x-steps
#: (the polar bands' D^T D at their centre radius) stop being pinned by the data, and
#: the solution drifted in rings from step to step (a 0.05-lux image with its noise
#: model, λ ≈ 1: 21.1 dB after one step, 18.6 dB at β = 172, 2.8 dB at β = 1380). Bench
#: and rendered images end their schedule at β < 25.
BETA_MAX = 64.0
#: Data terms of :func:`hqs_deconvolve`.
DATA_TERMS = ("gaussian", "poisson-gaussian")
#: Smoothing (Gaussian σ, px) of the image that gives each pixel's level for its noise
#: variance in the Poisson–Gaussian data term.
_LEVEL_SMOOTHING_PX = 2.0
#: Smallest relative variance of a pixel (a floor against a zero threshold).
_MIN_REL_VAR = 1e-3


def _bar(total, desc, enabled):
    if not enabled:
        return None
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit="it", leave=False)


# -- shrinkage -----------------------------------------------------------------------

def shrink_tv(g1: np.ndarray, g2: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    r"""Isotropic soft threshold: :math:`\arg\min_z \tau |z| + \tfrac12 |z - g|^2`.

    Parameters
    ----------
    g1, g2 : ndarray
        The two components of the gradient g (same shape and dtype).
    tau : float or ndarray
        The threshold τ, a scalar or one per element.

    Returns
    -------
    (ndarray, ndarray)
        The two components of z, in the dtype of ``g1``.
    """
    dt = g1.dtype.type
    t = np.asarray(tau, dtype=g1.dtype) if np.ndim(tau) else dt(tau)   # scalar or per pixel
    s = np.hypot(g1, g2)
    np.maximum(s, t, out=s)                       # |g| <= τ: factor 1 − τ/τ = 0
    np.divide(t, s, out=s)
    np.subtract(dt(1), s, out=s)
    return g1 * s, g2 * s


#: Table of the α-shrinkage for τ = 1: uniform on [0, _HL_VMAX] (beyond, the one-term
#: asymptote w = v − α v^(α−1) is within 1e-4 of the root).
_HL_VMAX = 400.0
_HL_N = 32768


def _hl_table(alpha: float) -> np.ndarray:
    """w(v) = argmin_w |w|^α + (w − v)²/2 on ``_HL_N + 1`` uniform v in [0, _HL_VMAX]."""
    v = np.linspace(0.0, _HL_VMAX, _HL_N + 1)
    # the minimiser is 0 below the threshold, else the larger root of
    # α w^(α−1) + w − v = 0 in (0, v): Newton from w = v, which stays above the root
    w = v.copy()
    for _ in range(60):
        wp = np.maximum(w, 1e-12)
        f = alpha * wp ** (alpha - 1) + wp - v
        fp = alpha * (alpha - 1) * wp ** (alpha - 2) + 1
        w = np.clip(wp - f / fp, 0, v)
    e_w = np.abs(w) ** alpha + 0.5 * (w - v) ** 2
    e_0 = 0.5 * v * v
    root = np.abs(alpha * np.maximum(w, 1e-12) ** (alpha - 1) + w - v) < 1e-6 * (1 + v)
    return np.where((e_w < e_0) & root, w, 0.0)


_HL_TABLES: dict = {}


def shrink_hyper_laplacian(g: np.ndarray, tau: float, alpha: float = 2.0 / 3.0) -> np.ndarray:
    r""":math:`\arg\min_z \tau |z|^\alpha + \tfrac12 (z - g)^2`, elementwise.

    With :math:`s = \tau^{1/(2-\alpha)}` the problem is :math:`s\, w(g / s)` for the
    τ = 1 minimiser w, tabulated once on a uniform grid (Newton on the stationarity
    condition, checked against z = 0) and read by linear interpolation at an index
    computed directly (Krishnan and Fergus's lookup table).

    Parameters
    ----------
    g : ndarray
        The values to shrink (float32 stays float32).
    tau : float or ndarray
        The weight τ > 0, a scalar or one per element.
    alpha : float
        The exponent α, in (0, 1) (default 2/3; a table is built per α).
    """
    if alpha not in _HL_TABLES:
        _HL_TABLES[alpha] = _hl_table(alpha).astype(g.dtype if g.dtype == np.float32
                                                    else np.float64)
    tab = _HL_TABLES[alpha]
    dt = g.dtype.type
    if np.ndim(tau):                                       # a threshold per element
        s = np.asarray(tau, dtype=g.dtype) ** dt(1.0 / (2.0 - alpha))
        s = np.broadcast_to(s, g.shape)
        zero = s == 0
        s_div = np.where(zero, dt(1), s)
        pos = np.abs(g) * dt(_HL_N / _HL_VMAX) / s_div
    else:
        s = float(tau) ** (1.0 / (2.0 - alpha))
        if s == 0:
            return g.copy()
        zero, s_div = None, dt(s)
        pos = np.abs(g) * dt(_HL_N / (_HL_VMAX * s))       # fractional table index
    far = pos >= _HL_N
    np.minimum(pos, dt(_HL_N - 1e-3), out=pos)
    i = pos.astype(np.int32)
    pos -= i
    lo = tab[i]
    out = lo + pos * (tab[i + 1] - lo)
    if far.any():
        sf = s_div[far] if np.ndim(s_div) else s_div
        a = np.abs(g[far]) / sf
        out[far] = a - dt(alpha) * a ** dt(alpha - 1)
    out *= s_div
    out = np.copysign(out, g).astype(g.dtype, copy=False)
    if zero is not None and zero.any():
        out[zero] = g[zero]                                # τ = 0: no shrinkage
    return out


def _shrink(g1, g2, tau, alpha):
    if alpha == 1.0:
        return shrink_tv(g1, g2, tau)
    return shrink_hyper_laplacian(g1, tau, alpha), shrink_hyper_laplacian(g2, tau, alpha)


def _moment(g1, g2, alpha, weights=None):
    """Mean of φ(g): |g| (α = 1, isotropic) or |g1|^α + |g2|^α, optionally weighted."""
    phi = np.sqrt(g1 * g1 + g2 * g2) if alpha == 1.0 else \
        np.abs(g1) ** alpha + np.abs(g2) ** alpha
    if weights is None:
        return float(np.mean(phi))
    return float(np.sum(phi * weights) / (np.sum(weights) * phi.shape[1]))


# -- quadratic-step problems ---------------------------------------------------------

def _sym_ext(a: np.ndarray, L: int) -> tuple[np.ndarray, int]:
    n = a.shape[0]
    off = (L - n) // 2
    return np.pad(a, [(off, L - n - off)] + [(0, 0)] * (a.ndim - 1), mode="symmetric"), off


class _PolarProblem:
    """HQS on a polar grid: x-steps band by band, gradients along radius and arc.

    The grid is sampled less finely than polar Wiener's (1.25 rows per pixel of radius,
    one angle per pixel of the rim; context 2 K around each band): on the bench's
    1024 px problem that halved the time for 0.05 dB (30.93 against 30.98 dB; 1.0 and
    1.0 lost 0.2 dB), and a 3 K context gained nothing.
    """

    def __init__(self, y, kernels, rad, *, center, r_max, band_spacing, dt,
                 oversampling=(1.25, 1.0), margin_k=2.0):
        self.dt = dt
        self.cdt = np.complex64 if dt == np.float32 else np.complex128
        K = kernels.shape[-1]
        self.grid = g = polar_grid(y.shape, center=center, r_max=r_max, inner_px=8.0,
                                   outer_px=8.0, radial_oversampling=oversampling[0],
                                   angular_oversampling=oversampling[1])
        self.n_a = g.n_angles
        self.r_in = max(2.0 * K, 8.0)
        self.spec_y = sfft.rfft(to_polar(y, g), axis=1, workers=-1).astype(self.cdt)
        self.bands = polar_bands(kernels, rad, g, band_spacing=band_spacing,
                                 margin_px=margin_k * K,
                                 r_in=self.r_in, dtype=dt)
        self.dr = g.radial_step
        dth = g.angle_step
        r_abs = np.maximum(np.abs(g.radii), self.r_in / 2)
        self.inv_arc = (1.0 / (r_abs * dth)).astype(dt)[:, None]
        self.area = np.where((np.abs(g.radii) >= self.r_in) & (g.radii <= g.r_max),
                             np.abs(g.radii), 0.0)[:, None].astype(dt)
        self.cache = []
        for b in self.bands:
            ext, off = _sym_ext(self.spec_y[b.s0:b.s1, :b.mc], b.L)
            Y = sfft.fft(ext, axis=0, workers=-1)
            p = sfft.fftfreq(b.L).astype(dt)[:, None]
            m = np.arange(b.mc, dtype=dt)[None, :]
            # the band's centre radius: rows inside it have a larger tangential D^T D than
            # this symbol (a bound at the smallest radius was stable but lost 0.5-1 dB);
            # the divergence guard of _run_hqs catches what that can grow
            lap = (2 * np.sin(np.pi * p) / self.dr) ** 2 + \
                (2 * np.sin(np.pi * m / self.n_a) / (b.radius * dth)) ** 2
            self.cache.append((np.conj(b.H) * Y, (np.abs(b.H) ** 2).astype(dt),
                               lap.astype(dt), off))

    def xstep(self, v, beta):
        spec_v = None if v is None else sfft.rfft(v, axis=1, workers=-1)
        acc = np.zeros_like(self.spec_y)
        for b, (HY, H2, lap, off) in zip(self.bands, self.cache):
            num = HY.copy()
            if spec_v is not None:
                ext, _ = _sym_ext(spec_v[b.s0:b.s1, :b.mc], b.L)
                num += self.dt.type(beta) * sfft.fft(ext, axis=0, workers=-1)
            else:
                # the first step: the natural prior's |2πf|², as polar Wiener's filter
                # (the difference symbol above regularises high frequencies 2.5x less)
                p = sfft.fftfreq(b.L)[:, None]
                m = np.arange(b.mc)[None, :]
                lap = ((2 * np.pi * p / self.dr) ** 2 + (m / b.radius) ** 2).astype(self.dt)
            num /= H2 + self.dt.type(beta) * lap
            u = sfft.ifft(num, axis=0, workers=-1, overwrite_x=True)
            w = b.weights[:, None]
            acc[b.lo:b.hi, :b.mc] += w * u[b.lo - b.s0 + off:b.hi - b.s0 + off]
            if b.mc < acc.shape[1]:
                acc[b.lo:b.hi, b.mc:] += w * self.spec_y[b.lo:b.hi, b.mc:]
        return sfft.irfft(acc, n=self.n_a, axis=1, workers=-1).astype(self.dt, copy=False)

    def grad(self, u):
        gr = np.zeros_like(u)
        gr[:-1] = (u[1:] - u[:-1]) / self.dr
        gt = (np.roll(u, -1, axis=1) - u) * self.inv_arc
        return gr, gt

    def grad_t(self, gr, gt):
        v = np.empty_like(gr)
        v[0] = -gr[0]
        v[1:] = gr[:-1] - gr[1:]
        v /= self.dr
        h = gt * self.inv_arc
        v += np.roll(h, 1, axis=1) - h
        return v

    def moment(self, u, alpha):
        return _moment(*self.grad(u), alpha, weights=self.area)

    def sample(self, image):
        """A per-pixel map (H, W) on this problem's polar grid."""
        return to_polar(image.astype(self.dt, copy=False), self.grid)


class _TileProblem:
    """HQS on pixels: x-steps tile by tile with each tile's IPSF (one tile: shift-invariant)."""

    def __init__(self, y, tiles, margin, dt):
        self.dt = dt
        self.shape = y.shape
        self.m = m = int(margin)
        pad = np.pad(y, m, mode="symmetric")
        self.tiles = []
        for y0, y1, x0, x1, win, k in tiles:
            region = pad[y0:y1 + 2 * m, x0:x1 + 2 * m]
            M, N = fast_shape(region.shape, (0, 0))
            ext, oy, ox = self._ext(region, (M, N))
            Hk = kernel_spectrum(k, (M, N), dtype=dt)
            fy = sfft.fftfreq(M).astype(dt)[:, None]
            fx = sfft.rfftfreq(N).astype(dt)[None, :]
            lap = (2 * np.sin(np.pi * fy)) ** 2 + (2 * np.sin(np.pi * fx)) ** 2
            HY = np.conj(Hk) * sfft.rfft2(ext, workers=-1)
            self.tiles.append((y0, y1, x0, x1, None if win is None else win.astype(dt),
                               (M, N), oy, ox, HY, (np.abs(Hk) ** 2).astype(dt),
                               lap.astype(dt)))

    @staticmethod
    def _ext(a, shape):
        oy, ox = (shape[0] - a.shape[0]) // 2, (shape[1] - a.shape[1]) // 2
        return np.pad(a, [(oy, shape[0] - a.shape[0] - oy), (ox, shape[1] - a.shape[1] - ox)],
                      mode="symmetric"), oy, ox

    def xstep(self, v, beta):
        m = self.m
        out = np.zeros(self.shape, dtype=self.dt)
        vpad = None if v is None else np.pad(v, m, mode="symmetric")
        b = self.dt.type(beta)
        for y0, y1, x0, x1, win, (M, N), oy, ox, HY, H2, lap in self.tiles:
            num = HY.copy()
            if vpad is not None:
                ext, _, _ = self._ext(vpad[y0:y1 + 2 * m, x0:x1 + 2 * m], (M, N))
                num += b * sfft.rfft2(ext, workers=-1)
            else:                   # the first step: the natural prior's |2πf|², as Wiener's
                fy = sfft.fftfreq(M)[:, None]
                fx = sfft.rfftfreq(N)[None, :]
                lap = ((2 * np.pi) ** 2 * (fy * fy + fx * fx)).astype(self.dt)
            num /= H2 + b * lap
            u = sfft.irfft2(num, s=(M, N), workers=-1)[oy + m:oy + m + y1 - y0,
                                                     ox + m:ox + m + x1 - x0]
            out[y0:y1, x0:x1] += u if win is None else win * u
        return out

    @staticmethod
    def grad(u):
        g1 = np.zeros_like(u)
        g2 = np.zeros_like(u)
        g1[:-1] = u[1:] - u[:-1]
        g2[:, :-1] = u[:, 1:] - u[:, :-1]
        return g1, g2

    @staticmethod
    def grad_t(g1, g2):
        v = np.empty_like(g1)
        v[0] = -g1[0]
        v[1:] = g1[:-1] - g1[1:]
        v[:, 0] -= g2[:, 0]
        v[:, 1:] += g2[:, :-1] - g2[:, 1:]
        return v

    def moment(self, u, alpha):
        return _moment(*self.grad(u), alpha)

    def sample(self, image):
        """A per-pixel map (H, W) in this problem's domain: the pixels themselves."""
        return image.astype(self.dt, copy=False)


def _run_hqs(prob, *, beta_wiener, sigma, alpha, weight, steps, time_limit_s, bar, bound,
             variance=None):
    """The HQS iteration on ``prob``; returns (solution, λ, steps done). A step whose
    result exceeds ``bound`` in magnitude is rejected and ends the iteration.
    ``variance``: the noise variance per sample of ``prob``'s domain relative to its
    mean (the Poisson–Gaussian data term), which scales the shrinkage threshold."""
    t0 = time.perf_counter()
    u = prob.xstep(None, beta_wiener)
    lam = prior_weight(prob.moment(u, alpha), sigma, alpha) if weight is None else float(weight)
    done = 0
    for k in range(steps):
        beta = lam * _BETA_RATE ** k
        if beta > BETA_MAX and k > 0:
            logger.info("HQS: beta %.3g beyond %g after %d steps: continuation ended", beta,
                        BETA_MAX, done)
            break
        tau = lam / beta if variance is None else variance * prob.dt.type(lam / beta)
        z1, z2 = _shrink(*prob.grad(u), tau, alpha)
        u_new = prob.xstep(prob.grad_t(z1, z2), beta)
        peak = float(np.max(np.abs(u_new))) if u_new.size else 0.0
        if not np.isfinite(peak) or peak > bound:
            # divergence guard: the approximate x-step is not an exact minimiser, and on
            # degenerate data (a box kernel's zeros, a pure-noise image) the iteration
            # was seen to grow without limit; keep the last good iterate
            logger.warning("HQS step %d grew the solution to %.3g (bound %.3g): stopped, "
                           "keeping step %d", k + 1, peak, bound, done)
            break
        u = u_new
        done += 1
        if bar is not None:
            bar.update(1)
        if time_limit_s is not None and time.perf_counter() - t0 > time_limit_s:
            logger.info("HQS stopped by its time limit after %d steps", done)
            break
    return u, lam, done


@renamed_keywords(depth_mm="depth")
def hqs_deconvolve(image: np.ndarray, bank: IPSFBank, *, prior: str = "hyperlaplacian",
                   weight: float | None = None, iterations: int | None = None,
                   noise: SensorNoise | float | None = None, depth: float | str | None = None,
                   center: tuple[float, float] | None = None, band_spacing: float = 0.25,
                   nsr: float | None = None, time_limit_s: float | None = None,
                   data_term: str = "gaussian", progress: bool = False, info: dict | None = None
                  ) -> np.ndarray:
    r"""Restore a focal-sweep image with a TV or hyper-Laplacian gradient prior (HQS).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Focal-sweep image on the bank's reference pixel grid; float32 stays float32.
    bank : IPSFBank
        ``kind="radial"`` (polar quadratic step) or ``kind="grid"`` (tiled).
    prior : {"tv", "hyperlaplacian"}
        ``φ(g) = |g|`` (isotropic TV) or ``|g₁|^{2/3} + |g₂|^{2/3}``.
    weight : float, optional
        λ; default :func:`~mitsweep.deconv.regularization.prior_weight` from σ and the
        gradients of the first (Wiener) step, where σ is the largest of ``noise``'s,
        the discrepancy principle's leftover and the GCV estimate
        (:func:`~mitsweep.deconv.regularization.gcv_noise`).
    iterations : int, optional
        β steps (default :data:`DEFAULT_HQS_STEPS`).
    noise : SensorNoise, float or None
        The noise (:func:`~mitsweep.deconv.regularization.noise_sigma`).
    nsr : float, optional
        NSR of the first (Wiener) step; default by the discrepancy principle.
    time_limit_s : float, optional
        Stop after the β step that passes this wall time (per channel).
    data_term : {"gaussian", "poisson-gaussian"}
        ``"gaussian"``: :math:`\tfrac12\lVert Ax - y\rVert^2`, one σ for the image.
        ``"poisson-gaussian"``: each pixel weighted by the inverse of its own noise
        variance, :math:`\tfrac12\sum_p (Ax - y)_p^2\, \bar\sigma^2/\sigma_p^2`, with
        :math:`\sigma_p^2` ``noise.variance`` (shot plus read noise) at the pixel's level
        (``y`` smoothed over a few pixels), plus what the image holds beyond the model
        (σ² minus the model's mean variance, when positive: Monte Carlo noise, bank
        mismatch). Needs ``noise`` to be a :class:`~mitsweep.deconv.noise.SensorNoise`.
        See Notes. Measured, it does not gain on the test photographs nor on a
        rendered sphere sweep: +0.04 to −0.05 dB at 50 lux, −0.07 to −0.35 dB at 0.5 lux
        (tests/test_deconv_lowlight.py); the Gaussian term stays the default.
    info : dict, optional
        Filled with ``sigma``, ``nsr`` (the first step's), ``weight``, ``steps``.

    Notes
    -----
    The first quadratic step has z = 0 and β equal to the natural-prior Wiener
    regulariser whose NSR the discrepancy principle gives
    (:func:`~mitsweep.deconv.regularization.discrepancy_nsr`): the start is a calibrated
    Wiener restoration. Then for β = λ (2√2)^k, k = 0 … n−1:
    :math:`z = \operatorname{shrink}_{\lambda/\beta}(\nabla x)`,
    :math:`x = (A^\top A + \beta D^\top D)^{-1}(A^\top y + \beta D^\top z)`, with
    :math:`A^\top A` of each band or tile its own circulant IPSF.

    The Poisson–Gaussian data term keeps that structure: where the variance changes
    slowly over a kernel's support, minimising
    :math:`\tfrac12\sum_p w_p (Ax - y)_p^2 + \lambda\sum_p \phi(\nabla x_p)` is locally
    the same as minimising :math:`\tfrac12\lVert Ax - y\rVert^2 + \sum_p (\lambda / w_p)
    \phi(\nabla x_p)`, so the weights move onto the prior: each pixel's shrinkage
    threshold is scaled by :math:`1/w_p = \sigma_p^2 / \bar\sigma^2` (the MAP weight
    :math:`\kappa\sigma_p^2/(\alpha m)` with the pixel's own variance), and the
    quadratic step is unchanged. Dark regions, whose noise is read noise only, are then
    smoothed less than bright ones, whose shot noise is larger.
    """
    if data_term not in DATA_TERMS:
        raise ValueError(f"data_term must be one of {', '.join(DATA_TERMS)}, "
                         f"got {data_term!r}")
    if data_term == "poisson-gaussian" and not hasattr(noise, "variance"):
        raise ValueError("data_term 'poisson-gaussian' needs noise= a SensorNoise (its "
                         f"variance per level), got {noise!r}")
    if prior not in PRIORS:
        raise ValueError(f"prior must be one of {tuple(PRIORS)}, got {prior!r}")
    alpha = PRIORS[prior]
    steps = DEFAULT_HQS_STEPS if iterations is None else int(iterations)
    if steps < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations!r}")
    if weight is not None and not (np.isfinite(float(weight)) and float(weight) > 0):
        raise ValueError(f"weight must be a number > 0, got {weight!r}")
    img, squeeze = _channels(image)
    check_bank_matches(bank, img.shape)
    dt = working_dtype(img)
    img = img.astype(dt, copy=False)
    check_image_values(img)
    kernels = select_depth(bank, depth)
    K = kernels.shape[-1]
    H, W = img.shape[:2]
    n_px = float(np.sqrt(H * W))
    k_mid = surrogate_kernel(bank, img.shape, depth=depth, center=center)
    if bank.kind == "radial":
        rad = radii_px(bank)
        r_max = min(float(rad.max()) + K, polar_grid(img.shape, center=center).r_max)
    elif bank.kind == "grid":
        rows, cols = grid_axes_px(bank, (H, W))
        wy, wx = grid_windows(rows, cols, (H, W))
    else:
        raise BankError(f"unknown bank kind {bank.kind!r}")
    out = np.empty_like(img)
    bar = _bar(steps * img.shape[2], f"{prior} deconvolution", progress)
    record = {}
    try:
        for c in range(img.shape[2]):
            y = img[..., c]
            spec = _residual_spectrum(y, k_mid, None)
            # what blur plus σ cannot explain (Monte Carlo noise, a bank that does not
            # fit the image) is noise too: GCV's σ, which needs no noise model (rendered
            # sweeps: 1.9 times the image's σ; TV +1 to +2 dB), and the discrepancy's
            # leftover when it has no solution. The first step's NSR is the discrepancy's
            # with that σ: with the wavelet σ alone (0.028 where the Poisson–Gaussian
            # noise of a 0.5-lux image was 0.033) the principle under-regularised the
            # start 400-fold, whose noisy gradients then made λ 10 times too small
            # (TV 21.8 dB, below the blurred image's 22.4; with it 25.7 dB)
            sigma = max(noise_sigma(y, noise), _gcv(spec)[1])
            nsr_d, sigma_res = _discrepancy(spec, sigma, DISCREPANCY_TAU, y, None)
            nsr_c = nsr_d if nsr is None else float(nsr)
            sigma = max(sigma, sigma_res)
            # natural-prior Wiener: R = nsr · 2π ln(n/2) |f|², β D^T D ≈ β 4π² |f|²
            beta_w = nsr_c * math.log(max(n_px / 2, 2.0)) / (2 * math.pi)
            # no restoration of y may exceed 4 times its range: HQS is stopped there
            bound = 4.0 * (float(np.max(np.abs(y))) + sigma) + 1e-30
            kw = dict(beta_wiener=beta_w, sigma=sigma, alpha=alpha, weight=weight,
                      steps=steps, time_limit_s=time_limit_s, bar=bar, bound=bound)
            rel = None if data_term == "gaussian" else _relative_variance(y, noise, sigma, k_mid)
            if bank.kind == "radial":
                prob = _PolarProblem(y, kernels, rad, center=center, r_max=r_max,
                                     band_spacing=band_spacing, dt=dt)
                u, lam, done = _run_hqs(prob, variance=None if rel is None else
                                        np.maximum(prob.sample(rel), dt.type(_MIN_REL_VAR)),
                                        **kw)
                res = from_polar(u, prob.grid, (H, W), outside=y)
                _blend_centre(res, y, interpolate_radial(kernels, rad, 0.0), prob,
                              {**kw, "weight": lam}, rel)
            else:
                tiles = []
                n_c = wx.shape[0]
                for i in range(wy.shape[0]):
                    y0, y1 = _support(wy[i])
                    for j in range(n_c):
                        x0, x1 = _support(wx[j])
                        tiles.append((y0, y1, x0, x1, wy[i, y0:y1, None] * wx[j, None, x0:x1],
                                      kernels[i * n_c + j]))
                tile_prob = _TileProblem(y, tiles, 3 * K, dt)
                res, lam, done = _run_hqs(tile_prob, variance=None if rel is None else
                                          tile_prob.sample(rel), **kw)
            out[..., c] = res
            record = dict(sigma=sigma, nsr=nsr_c, weight=lam, steps=done, data_term=data_term)
            logger.info("%s: sigma %.3g, start NSR %.3g, weight %.3g, %d steps", prior,
                        sigma, nsr_c, lam, done)
    finally:
        if bar is not None:
            bar.close()
    if info is not None:
        info.update(record)
    return out[..., 0] if squeeze else out


def _relative_variance(y, noise, sigma, kernel):
    r"""σ_q² / mean σ² of the Poisson–Gaussian data term (see :func:`hqs_deconvolve`).

    Each pixel p of ``y`` has the model's variance at its level (``y`` smoothed with a
    Gaussian of :data:`_LEVEL_SMOOTHING_PX`: a sweep image is smooth, its noise is not)
    plus the excess of σ² over the model's mean variance. A restored pixel q sees the
    data through its kernel: :math:`(A^\top W A)_{qq} = \sum_p A_{pq}^2 w_p`, so its
    weight is the average of :math:`w_p = 1/\sigma_p^2` under the squared kernel, and its
    variance the inverse of that.
    """
    from scipy.ndimage import gaussian_filter
    from scipy.signal import fftconvolve

    level = gaussian_filter(np.maximum(y.astype(np.float64), 0.0), _LEVEL_SMOOTHING_PX,
                            mode="reflect")
    var = np.asarray(noise.variance(level), dtype=np.float64)
    var += max(float(sigma) ** 2 - float(np.mean(var)), 0.0)
    mean = float(np.mean(var))
    if not (np.isfinite(mean) and mean > 0):
        return np.ones_like(y)
    k2 = np.asarray(kernel, dtype=np.float64) ** 2
    k2 = k2[::-1, ::-1] / k2.sum()
    K = k2.shape[0]
    w = np.pad(mean / var, K // 2 + 1, mode="reflect")
    w = fftconvolve(w, k2, mode="same")[K // 2 + 1:-(K // 2 + 1), K // 2 + 1:-(K // 2 + 1)]
    return np.maximum(1.0 / np.maximum(w, 1e-12), _MIN_REL_VAR).astype(y.dtype)


def _blend_centre(res, y, k0, prob, kw, rel=None):
    """The disk r < r_in around the pole, where a polar grid cannot hold a kernel:
    restored in pixels with the centre IPSF (shift-invariant HQS) and blended in."""
    H, W = y.shape
    K = k0.shape[-1]
    cy, cx = prob.grid.center
    r_in = prob.r_in
    half = int(math.ceil(r_in)) + 3 * K
    y0, y1 = max(0, int(cy) - half), min(H, int(cy) + half + 2)
    x0, x1 = max(0, int(cx) - half), min(W, int(cx) + half + 2)
    if y1 - y0 <= K or x1 - x0 <= K:
        return
    patch = y[y0:y1, x0:x1]
    tp = _TileProblem(patch, [(0, y1 - y0, 0, x1 - x0, None, k0)], 2 * K, prob.dt)
    cart, _, _ = _run_hqs(tp, **{**kw, "bar": None},
                          variance=None if rel is None else tp.sample(rel[y0:y1, x0:x1]))
    yy, xx = np.mgrid[y0:y1, x0:x1]
    rr = np.hypot(yy - cy, xx - cx)
    blend = np.clip((r_in - rr) / (r_in / 2), 0, 1).astype(res.dtype)
    res[y0:y1, x0:x1] = blend * cart + (1 - blend) * res[y0:y1, x0:x1]


# -- Richardson–Lucy -----------------------------------------------------------------

#: Boundary treatments of :func:`richardson_lucy`.
RL_BOUNDARIES = ("normalized", "zero")


def richardson_lucy(image: np.ndarray, op: BlurOperator, *, iterations: int | None = None,
                    noise: SensorNoise | float | None = None, damping: float | None = 1.0,
                    max_iterations: int = MAX_RL_ITERATIONS, boundary: str = "normalized",
                    time_limit_s: float | None = None, progress: bool = False,
                    info: dict | None = None) -> np.ndarray:
    r"""Damped Richardson–Lucy with a spatially varying blur ``op``.

    Parameters
    ----------
    image : (H, W) ndarray
        Blurred image, linear values ≥ 0 (negative read-noise values count as 0 in the
        ratio); float32 stays float32 (give ``op`` float32 too: it computes in its own
        precision).
    op : BlurOperator
        The blur (:func:`~mitsweep.deconv.operators.polar_operator` or
        :func:`~mitsweep.deconv.operators.product_convolution_operator`).
    iterations : int, optional
        Fixed iteration count; None: stop by the discrepancy principle (the residual's
        mean square reaches σ²) or when the relative update falls below 1e-4, at most
        ``max_iterations``.
    noise : SensorNoise, float or None
        The noise (:func:`~mitsweep.deconv.regularization.noise_sigma`).
    damping : float or None
        White's threshold T in units of σ: residuals within about T σ do not drive the
        update (None: plain RL).
    boundary : {"normalized", "zero"}
        ``"zero"``: ``op`` as it is (dark outside the image: at the border it loses the
        light that would come from outside, and RL brightens the border to make up for
        it, an error that walks inward). ``"normalized"``: each pixel's blur renormalised
        to unit weight, :math:`A' = D^{-1} A` with :math:`D = \operatorname{diag}(A 1)`
        (normalised convolution [3]_: the unseen outside counts as the average of what the
        kernel sees inside), so that :math:`A' 1 = 1` and a constant image is a fixed
        point; the update is normalised by :math:`A'^\top 1` as Bertero and Boccacci do
        for RL with boundaries [4]_.
    time_limit_s : float, optional
        Wall time of the call, setup included: before each iteration the clock is read
        and the iteration is not started if its expected cost (the longest of the last
        three iterations; before the first, the cost of the setup's forward and adjoint
        pair) would cross the limit.
    info : dict, optional
        Filled with ``sigma``, ``iterations``, ``rms_residual``, ``stopped_by``,
        ``seconds_per_iteration``.

    Notes
    -----
    .. math:: x_{k+1} = \frac{x_k}{A^\top 1}\; A^\top\!\left[1 + U^{N-1}(N - (N-1)U)
              \frac{y - A x_k}{A x_k}\right], \qquad
              U = \min\!\left(1, \frac{(y - A x_k)^2}{T^2 \sigma^2}\right), N = 10

    (White 1994, with the Gaussian form of the deviance); U = 1 gives plain RL.

    References
    ----------
    .. [3] H. Knutsson and C.-F. Westin, "Normalized and differential convolution",
       Proc. CVPR 1993, 515–523.
    .. [4] M. Bertero and P. Boccacci, "A simple method for the reduction of boundary
       effects in the Richardson-Lucy approach to image deconvolution", Astron.
       Astrophys. 437, 369–374, 2005.
    """
    t0 = time.perf_counter()
    y = np.asarray(image)
    if y.ndim != 2:
        raise ValueError(f"richardson_lucy takes an (H, W) image, got shape {y.shape}")
    if boundary not in RL_BOUNDARIES:
        raise ValueError(f"boundary must be one of {', '.join(RL_BOUNDARIES)}, "
                         f"got {boundary!r}")
    dt = working_dtype(y)
    y = y.astype(dt, copy=False)
    check_image_values(y)
    if tuple(y.shape) != tuple(op.shape):
        raise ValueError(f"image {y.shape} does not match the operator's {op.shape}")
    n_max = int(iterations) if iterations is not None else int(max_iterations)
    if n_max < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations!r}")
    sigma = noise_sigma(y, noise)
    yp = np.maximum(y, 0)
    tiny = dt.type(max(1e-12, 1e-7 * float(yp.max(initial=0.0))))
    ones = np.ones_like(yp)
    t_pair = time.perf_counter()
    if boundary == "normalized":
        # a pixel that no light reaches (none with unit-sum kernels) keeps weight 1
        row = op.forward(ones).astype(dt, copy=False)
        inv_row = np.where(row > dt.type(1e-6), 1 / np.maximum(row, dt.type(1e-6)),
                           dt.type(1)).astype(dt)
        forward = lambda x: op.forward(x) * inv_row
        adjoint = lambda r: op.adjoint(r * inv_row)
        norm = adjoint(ones)
    else:
        forward, adjoint = op.forward, op.adjoint
        norm = adjoint(ones)
        op.forward(ones)                # the forward half of the measured pair
    costs = [time.perf_counter() - t_pair]
    inv_norm = (1 / np.maximum(norm.astype(dt, copy=False), tiny)).astype(dt)
    # start from the image itself (positive): the low frequencies are right from the
    # first iteration, so RL spends its iterations on detail
    x = np.maximum(yp, tiny)
    thr = dt.type(1.0 / ((damping * sigma) ** 2 + 1e-30)) if damping is not None else None
    bar = _bar(n_max, "rl deconvolution", progress)
    stopped = "iterations"
    done = 0
    rms = float("nan")
    try:
        for k in range(n_max):
            if time_limit_s is not None:
                now = time.perf_counter()
                if now - t0 + max(costs[-3:]) > time_limit_s:
                    stopped = "time limit"
                    break
            t_it = time.perf_counter()
            Ax = np.maximum(forward(x), tiny)
            res = yp - Ax
            rms = math.sqrt(float(np.mean(res * res, dtype=np.float64)))
            if iterations is None and rms <= sigma:
                stopped = "discrepancy"
                break
            ratio = res / Ax
            if thr is not None:
                U = res * res
                U *= thr
                np.minimum(U, 1, out=U)
                # U^9 (10 − 9 U) by three squarings and a product, in place
                U9 = U * U
                U9 *= U9
                U9 *= U9
                U9 *= U
                U *= dt.type(-9)
                U += dt.type(10)
                U *= U9
                ratio *= U
            ratio += 1
            x_new = adjoint(ratio).astype(dt, copy=False)
            x_new *= x
            x_new *= inv_norm
            np.maximum(x_new, 0, out=x_new)
            change = float(np.linalg.norm(x_new - x)) / max(float(np.linalg.norm(x)), 1e-30)
            x = x_new
            done = k + 1
            costs.append(time.perf_counter() - t_it)
            if bar is not None:
                bar.update(1)
            if iterations is None and change < 1e-4:
                stopped = "converged"
                break
    finally:
        if bar is not None:
            bar.close()
    per_it = float(np.mean(costs[1:])) if len(costs) > 1 else costs[0]
    if info is not None:
        info.update(sigma=sigma, iterations=done, rms_residual=rms, stopped_by=stopped,
                    seconds_per_iteration=per_it)
    logger.info("RL: %d iterations (%s), rms residual %.3g, sigma %.3g, %.3g s each",
                done, stopped, rms, sigma, per_it)
    return x
