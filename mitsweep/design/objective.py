"""The predicted restoration error of a sweep: the Wiener MSE of a natural image.

For one field point and depth, with exposure fractions ``τ`` over the bins of a
:class:`~mitsweep.design.planes.PlaneBank`, the IPSF's transfer function is linear in τ,

.. math:: \\hat K(f; τ) = \\sum_k τ_k \\hat P_k(f),

and the mean squared error per pixel of the Wiener (MMSE) estimate of an image with
power spectrum ``S(f) = A / |f|²`` (the natural-image prior of the V metric, paper
Eq. 2; ``A`` such that the image variance is ``σ_s²``, :func:`mitsweep.deconv.wiener.
natural_prior_scale`) under white noise of variance ``σ²`` is

.. math:: \\mathrm{MSE}(τ) = \\frac{1}{n^2} \\sum_{f \\ne 0}
          \\frac{S(f)\\, σ^2}{|\\hat K(f; τ)|^2 S(f) + σ^2}
          = \\frac{σ^2}{n^2} \\sum_{f \\ne 0} \\frac{1}{|\\hat K(f; τ)|^2 + R(f)},

``R(f) = σ²/S(f) = nsr · 2π ln(n_px/2) · |f|²`` the regulariser of mitsweep's natural
Wiener filter (:func:`mitsweep.deconv.wiener.regulariser`), ``nsr = σ²/σ_s²``, on an
``n × n`` DFT grid (cycles per pixel; DC left out: the image mean is known). Noise and
signal are in relative exposure (white = 1): ``σ² =`` :meth:`SensorNoise.variance` at
the mean level 0.5 and ``σ_s = 0.5`` (:meth:`SensorNoise.nsr`), so ``10 log10(1/MSE)``
is a predicted PSNR.

Convexity, and the bound used to certify the optimiser
------------------------------------------------------
``1/(y² + R)`` is not convex in ``y = |K̂|`` (it is concave for ``y < √(R/3)``) and
``|K̂|`` is not linear in τ, so the MSE is not convex in τ. Two steps give a convex
lower bound: the triangle inequality ``|K̂(f; τ)| ≤ Σ_k τ_k |P̂_k(f)| =: y_f(τ)`` (linear
in τ; the MSE term decreases in ``|K̂|``), and the convex envelope of ``h(y) = 1/(y² + R)``
on ``y ≥ 0``: the tangent from ``(0, h(0))``, which touches ``h`` at ``y = √R``,

.. math:: \\check h(y) = \\frac{1}{R}\\Big(1 - \\frac{y}{2\\sqrt R}\\Big)\\ (y < \\sqrt R),
          \\qquad \\check h(y) = h(y)\\ (y \\ge \\sqrt R),

so ``L(τ) = σ²/n² Σ_f ȟ_f(y_f(τ)) ≤ MSE(τ)`` for every τ, and ``L`` is convex in τ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import fft as sfft

from ..deconv.noise import SensorNoise
from ..deconv.wiener import regulariser
from ..deprecation import renamed_keywords

__all__ = ["WienerModel", "wiener_model", "DeployedWienerModel", "BlendedWienerModel",
           "deployed_wiener_model", "DEFAULT_FFT_SIZE", "SIGNAL_MEAN"]

#: DFT grid of the MSE sum (steps of 1/32 cycle/pixel; a 31 px kernel fits). Measured on
#: the paraboloid at 50 and 0.5 lux: uniform and optimised worst-case MSE within 0.1 % of
#: a 128-point grid's, the optimised τ the same to 3 digits.
DEFAULT_FFT_SIZE = 32
#: Mean level of the natural image (relative exposure), also its rms contrast
#: (:meth:`mitsweep.deconv.noise.SensorNoise.nsr`).
SIGNAL_MEAN = 0.5


@dataclass(frozen=True)
class WienerModel:
    """The MSE of every field point and depth as a function of τ (module docstring).

    Attributes
    ----------
    spectra_re, spectra_im : (J, N, F) ndarray
        Real and imaginary parts of ``P̂_k(f)`` of the J = n_depths · n_points kernels
        (depth-major) on the rfft grid, DC removed.
    magnitude : (J, N, F) ndarray
        ``|P̂_k(f)|`` (the convex bound's).
    weight : (F,) ndarray
        ``c_f / n²``: rfft multiplicity over the grid size.
    reg : (F,) ndarray
        ``R(f)``.
    noise_var : float
        ``σ²``, relative exposure².
    """

    spectra_re: np.ndarray
    spectra_im: np.ndarray
    magnitude: np.ndarray
    weight: np.ndarray
    reg: np.ndarray
    noise_var: float

    @property
    def n_kernels(self) -> int:
        return self.spectra_re.shape[0]

    @staticmethod
    def _combine(t: np.ndarray, spectra: np.ndarray) -> np.ndarray:
        """``Σ_k τ_k S[j, k, f]``: (J, F) for τ (N,), (B, J, F) for (B, N)."""
        if t.ndim == 1:
            return np.matmul(t, spectra)
        return np.matmul(t[None], spectra).transpose(1, 0, 2)

    def _transfer(self, t):
        return self._combine(t, self.spectra_re), self._combine(t, self.spectra_im)

    def mse(self, tau: ArrayLike) -> np.ndarray:
        """(J,) predicted MSE at exposure fractions ``tau`` (N,), or (B, J) for (B, N).

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N) where
            the method says so).
        """
        kr, ki = self._transfer(np.asarray(tau, dtype=float))
        return self.noise_var * (self.weight / (kr * kr + ki * ki + self.reg)).sum(axis=-1)

    def mse_and_grad(self, tau: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(J,) MSE and its (J, N) gradient in τ.

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N) where
            the method says so).
        """
        kr, ki = self._transfer(np.asarray(tau, dtype=float))
        d = kr * kr + ki * ki + self.reg
        value = self.noise_var * (self.weight / d).sum(axis=-1)
        # d/dτ_k 1/d = −2 Re(conj(K) P̂_k) / d²
        coef = -2.0 * self.noise_var * self.weight / (d * d)  # (J, F)
        grad = np.matmul(self.spectra_re, (coef * kr)[:, :, None])[..., 0] \
            + np.matmul(self.spectra_im, (coef * ki)[:, :, None])[..., 0]
        return value, grad

    def bound_and_grad(self, tau: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(J,) convex lower bound ``L(τ) <= MSE(τ)`` and its (J, N) gradient.

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N) where
            the method says so).
        """
        y = self._combine(np.asarray(tau, dtype=float), self.magnitude)
        sq = np.sqrt(self.reg)
        lin = y < sq
        h = np.where(lin, (1.0 - y / (2.0 * sq)) / self.reg, 1.0 / (y * y + self.reg))
        dh = np.where(lin, -1.0 / (2.0 * self.reg * sq), -2.0 * y / (y * y + self.reg) ** 2)
        value = self.noise_var * (self.weight * h).sum(axis=-1)
        grad = self.noise_var * np.matmul(self.magnitude, (self.weight * dh)[:, :, None])[..., 0]
        return value, grad


def wiener_model(kernels: np.ndarray, noise: SensorNoise, *, n_fft: int = DEFAULT_FFT_SIZE,
                 n_px: float) -> WienerModel:
    """The :class:`WienerModel` of bin-averaged kernels.

    Parameters
    ----------
    kernels : (n_depths, n_points, N, K, K) ndarray
        ``P_k`` (:attr:`PlaneBank.kernels`), the chief-ray image at ``[K//2, K//2]``.
    noise : mitsweep.deconv.SensorNoise
        The sensor at the light level of the design.
    n_fft : int
        DFT grid n (>= K).
    n_px : float
        Image size that sets the prior's lowest frequency (the sensor's, as the Wiener
        filter of a whole image uses).
    """
    k = np.asarray(kernels, dtype=float)
    D, P, N, K, K2 = k.shape
    if K != K2 or K > n_fft:
        raise ValueError(f"kernels: need square kernels no larger than n_fft = {n_fft}, "
                         f"got {K}x{K2}")
    big = np.zeros((D * P * N, n_fft, n_fft))
    big[:, :K, :K] = k.reshape(-1, K, K)
    big = np.roll(big, (-(K // 2), -(K // 2)), axis=(1, 2))
    spec = sfft.rfft2(big, workers=-1).reshape(D * P, N, -1)[:, :, 1:]  # DC is index 0
    nsr = float(noise.nsr(SIGNAL_MEAN))
    reg = regulariser((n_fft, n_fft), nsr, "natural", n_px=n_px).ravel()
    mult = np.full(n_fft // 2 + 1, 2.0)
    mult[0] = 1.0
    if n_fft % 2 == 0:
        mult[-1] = 1.0
    weight = np.broadcast_to(mult, (n_fft, n_fft // 2 + 1)).ravel() / n_fft ** 2
    return WienerModel(spectra_re=np.ascontiguousarray(spec.real),
                       spectra_im=np.ascontiguousarray(spec.imag), magnitude=np.abs(spec),
                       weight=weight[1:].copy(), reg=reg[1:].astype(float),
                       noise_var=float(noise.variance(SIGNAL_MEAN)))


@dataclass(frozen=True)
class DeployedWienerModel:
    r"""The MSE of the *deployed* restoration as a function of τ.

    The pipeline does not restore depth d with its own IPSF and the design's NSR: it
    deconvolves every depth with the bank's kernel at one depth :math:`d_0` (500 mm)
    and its own NSR. With :math:`K_d(f;τ) = \sum_k τ_k \hat P_{d,k}(f)`, the deployed
    filter :math:`G = K_{d_0}^*/(|K_{d_0}|^2 + R_f)` (:math:`R_f` = the deployed NSR ×
    the natural prior's :math:`c(f)`) and a natural image of spectrum
    :math:`S = σ^2/R_t` (:math:`R_t` from the sensor noise, as :class:`WienerModel`),
    the error of depth d is

    .. math:: \mathrm{MSE}_d(τ) = \frac{σ^2}{n^2}\sum_{f\ne 0}
              \frac{|D - K_{d_0}^* K_d|^2}{R_t D^2} + \frac{|K_{d_0}|^2}{D^2},
              \qquad D = |K_{d_0}|^2 + R_f ,

    which is :class:`WienerModel`'s MSE when :math:`K_d = K_{d_0}` and
    :math:`R_f = R_t`. It is not convex in τ and has no certified bound here; the same
    optimiser (:func:`~mitsweep.design.optimize.local_optimum`) minimises it.

    Attributes
    ----------
    spectra_re, spectra_im : (J, N, F) ndarray
        :math:`\hat P_{d,k}` of each kernel j = (depth, point).
    deployed_re, deployed_im : (J, N, F) ndarray
        :math:`\hat P_{d_0,k}` of the same point at the deployed depth.
    weight, reg_true, reg_filter : (F,) ndarray
    noise_var : float
    """

    spectra_re: np.ndarray
    spectra_im: np.ndarray
    deployed_re: np.ndarray
    deployed_im: np.ndarray
    weight: np.ndarray
    reg_true: np.ndarray
    reg_filter: np.ndarray
    noise_var: float

    @property
    def n_kernels(self) -> int:
        return self.spectra_re.shape[0]

    def _parts(self, tau):
        t = np.asarray(tau, dtype=float)
        c = WienerModel._combine
        kr, ki = c(t, self.spectra_re), c(t, self.spectra_im)
        qr, qi = c(t, self.deployed_re), c(t, self.deployed_im)
        D = qr * qr + qi * qi + self.reg_filter
        # N = D - conj(K0) K
        nr = D - (qr * kr + qi * ki)
        ni = -(qr * ki - qi * kr)
        return t, kr, ki, qr, qi, D, nr, ni

    def mse(self, tau: ArrayLike) -> np.ndarray:
        """(J,) deployed MSE at ``tau`` (N,), or (B, J) for (B, N).

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N) where
            the method says so).
        """
        _, _, _, qr, qi, D, nr, ni = self._parts(tau)
        e = (nr * nr + ni * ni) / (self.reg_true * D * D) + (qr * qr + qi * qi) / (D * D)
        return self.noise_var * (self.weight * e).sum(axis=-1)

    def mse_and_grad(self, tau: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(J,) deployed MSE and its (J, N) gradient in τ (for one τ).

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N) where
            the method says so).
        """
        _, kr, ki, qr, qi, D, nr, ni = self._parts(tau)
        n2, q2 = nr * nr + ni * ni, qr * qr + qi * qi
        Rt = self.reg_true
        e = n2 / (Rt * D * D) + q2 / (D * D)
        value = self.noise_var * (self.weight * e).sum(axis=-1)
        # M = conj(N) K, L = N K0: d|N|²/dτ_k = 2 Re(N) dD_k - 2 Re(conj(Q_k) M)
        # - 2 Re(P_k conj(L)), with P_k, Q_k the bin spectra of K_d and K_{d0}
        mr, mi = nr * kr + ni * ki, nr * ki - ni * kr
        lr, li = nr * qr - ni * qi, nr * qi + ni * qr
        s = self.noise_var * self.weight
        a = 2.0 / (Rt * D * D)
        dD = -2.0 * n2 / (Rt * D ** 3) + 1.0 / (D * D) - 2.0 * q2 / D ** 3   # ∂e/∂D (+q2 term)
        # ∂e/∂τ_k = a (Re(N) dD_k - Re(conj(Q_k) M) - Re(P_k conj(L)))
        #           + (-2 n2/(Rt D³) - 2 q2/D³) dD_k + dq2_k / D²,  dD_k = dq2_k = 2 Re(conj(K0) Q_k)
        coef_q2 = a * nr + dD                       # multiplies dD_k = 2 (qr Qr + qi Qi)
        cqr = s * (2.0 * coef_q2 * qr - a * mr)
        cqi = s * (2.0 * coef_q2 * qi - a * mi)
        cpr = -s * a * lr
        cpi = -s * a * li
        grad = (np.matmul(self.deployed_re, cqr[:, :, None])[..., 0]
                + np.matmul(self.deployed_im, cqi[:, :, None])[..., 0]
                + np.matmul(self.spectra_re, cpr[:, :, None])[..., 0]
                + np.matmul(self.spectra_im, cpi[:, :, None])[..., 0])
        return value, grad


@dataclass(frozen=True)
class BlendedWienerModel:
    r"""The deployed restoration's MSE where a point is restored by a blend of other
    points' filters: the spatially varying deconvolution of a grid bank
    (:func:`mitsweep.deconv.spatial.spatially_varying_deconvolve`) restores a pixel
    between grid nodes with :math:`G = \sum_b a_b G_b`, the hat-weighted Wiener filters
    :math:`G_b = Q_b^*/(|Q_b|^2 + R_f)` of the nodes' kernels :math:`Q_b` at the deployed
    depth, while the pixel's own blur is :math:`K`. With :math:`E = 1 - G K`,

    .. math:: \mathrm{MSE}(τ) = \frac{σ^2}{n^2}\sum_{f\ne 0}
              \frac{|E|^2}{R_t} + |G|^2 ,

    which is :class:`DeployedWienerModel`'s MSE when the blend is the point's own node
    (one filter, weight 1). Between nodes it counts what a design at the nodes alone
    does not see: a profile whose kernels change fast across the field is restored with
    its neighbours' filters.

    Attributes
    ----------
    spectra_re, spectra_im : (J, N, F) ndarray
        Blur spectra :math:`\hat P_{d,k}` of each kernel j = (depth, point).
    filters : (B, N, F) complex ndarray
        :math:`\hat Q_{b,k}` of the B filter sources (the nodes at the deployed depth;
        a node off the mirror holds a delta kernel, spectrum 1).
    blend_index : (J, M) int ndarray
        The filters each kernel's restoration blends.
    blend_weight : (J, M) ndarray
        Their weights :math:`a_b` (rows summing to 1).
    weight, reg_true, reg_filter : (F,) ndarray
    noise_var : float
    """

    spectra_re: np.ndarray
    spectra_im: np.ndarray
    filters: np.ndarray
    blend_index: np.ndarray
    blend_weight: np.ndarray
    weight: np.ndarray
    reg_true: np.ndarray
    reg_filter: np.ndarray
    noise_var: float

    @property
    def n_kernels(self) -> int:
        return self.spectra_re.shape[0]

    def _parts(self, t: np.ndarray):
        c = WienerModel._combine
        k = c(t, self.spectra_re) + 1j * c(t, self.spectra_im)          # (J, F)
        q = np.matmul(t, self.filters)                                  # (B, F)
        d = (q * q.conj()).real + self.reg_filter
        g_b = q.conj() / d
        g = np.einsum("jm,jmf->jf", self.blend_weight, g_b[self.blend_index])
        return k, q, d, g

    def mse(self, tau: ArrayLike) -> np.ndarray:
        """(J,) MSE at ``tau`` (N,), or (B, J) for a batch (B, N).

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1 (or a batch (B, N)).
        """
        t = np.asarray(tau, dtype=float)
        if t.ndim == 2:
            return np.stack([self.mse(row) for row in t])
        k, _, _, g = self._parts(t)
        e = 1.0 - g * k
        err = (e * e.conj()).real / self.reg_true + (g * g.conj()).real
        return self.noise_var * (self.weight * err).sum(axis=-1)

    def mse_and_grad(self, tau: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(J,) MSE and its (J, N) gradient in τ (for one τ).

        Parameters
        ----------
        tau : array_like
            Exposure fractions of the N planes, (N,) summing to 1.
        """
        t = np.asarray(tau, dtype=float)
        k, q, d, g = self._parts(t)
        e = 1.0 - g * k
        s = self.noise_var * self.weight
        value = (s * ((e * e.conj()).real / self.reg_true + (g * g.conj()).real)).sum(axis=-1)
        # dMSE = 2 Re Σ_f s [-(E* G / R_t) dK + (G* - E* K / R_t) dG]
        c = -s * e.conj() * g / self.reg_true                          # (J, F)
        grad = 2.0 * (np.matmul(self.spectra_re, c.real[:, :, None])[..., 0]
                      - np.matmul(self.spectra_im, c.imag[:, :, None])[..., 0])
        h = s * (g.conj() - e.conj() * k / self.reg_true)              # (J, F)
        # dG_b/dτ_k = α_b Q*_bk - β_b Q_bk, α_b = R_f/D_b², β_b = (Q_b*)²/D_b²
        alpha = self.reg_filter / (d * d)
        beta = q.conj() ** 2 / (d * d)
        for m in range(self.blend_index.shape[1]):
            b, a = self.blend_index[:, m], self.blend_weight[:, m]
            for node in np.unique(b[a != 0]):
                rows = np.flatnonzero((b == node) & (a != 0))
                hr = h[rows] * a[rows, None]
                z = (alpha[node] * hr) @ self.filters[node].conj().T \
                    - (beta[node] * hr) @ self.filters[node].T
                grad[rows] += 2.0 * z.real
        return value, grad


@renamed_keywords(depths_mm="depths", deploy_depth_mm="deploy_depth")
def deployed_wiener_model(kernels: np.ndarray, depths: ArrayLike, noise: SensorNoise, *,
                          deploy_depth: float = 500.0, deploy_nsr: float | None = None,
                          n_fft: int = DEFAULT_FFT_SIZE, n_px: float,
                          blend: tuple[np.ndarray, np.ndarray] | None = None
                          ) -> DeployedWienerModel | BlendedWienerModel:
    """The :class:`DeployedWienerModel` of bin-averaged kernels (n_depths, n_points, N,
    K, K): each depth restored with the kernels of the bank depth nearest
    ``deploy_depth`` (in 1/depth, as :func:`mitsweep.deconv.kernels.select_depth`)
    and the NSR ``deploy_nsr`` (default the sensor's, :meth:`SensorNoise.nsr` at 0.5:
    then only the kernel's depth differs from :func:`wiener_model`).

    Parameters
    ----------
    kernels : (n_depths, n_points, N, K, K) ndarray
        The plane bank's bin-averaged kernels.
    depths : array_like
        The bank's depths, mm (n_depths; inf allowed).
    noise : SensorNoise
        The sensor at the design's light level.
    deploy_depth : float
        The depth whose kernels restore every depth, mm (inf allowed; default 500 mm,
        the datasets' bank depth).
    deploy_nsr : float, optional
        The restoration's NSR (default the sensor's at relative exposure 0.5).
    n_fft : int
        DFT grid of the MSE sum.
    n_px : float
        The restored image's size, px (the prior's scale).
    blend : (index, weight), optional
        Each point restored by a blend of nodes' filters (a grid bank's spatially varying
        deconvolution): ``index`` (n_points, M) the points whose kernels at the deployed
        depth are the nodes (-1: a node off the mirror, a delta kernel), ``weight``
        (n_points, M) their hat weights. Then a :class:`BlendedWienerModel`.
    """
    base = wiener_model(kernels, noise, n_fft=n_fft, n_px=n_px)
    k = np.asarray(kernels)
    D, P = k.shape[:2]
    depths = np.asarray(depths, dtype=float)
    if depths.shape != (D,):
        raise ValueError(f"depths: need {D} depths, got {depths.shape}")
    with np.errstate(divide="ignore"):
        d0 = int(np.argmin(np.abs(1.0 / depths - 1.0 / float(deploy_depth))))
    idx = np.array([d0 * P + p for _ in range(D) for p in range(P)])
    c = base.reg / float(noise.nsr(SIGNAL_MEAN))
    reg_f = base.reg if deploy_nsr is None else c * float(deploy_nsr)
    if blend is not None:
        return _blended(base, blend, d0, D, P, reg_f)
    return DeployedWienerModel(spectra_re=base.spectra_re, spectra_im=base.spectra_im,
                               deployed_re=np.ascontiguousarray(base.spectra_re[idx]),
                               deployed_im=np.ascontiguousarray(base.spectra_im[idx]),
                               weight=base.weight, reg_true=base.reg, reg_filter=reg_f,
                               noise_var=base.noise_var)


def _blended(base: WienerModel, blend, d0: int, D: int, P: int,
             reg_f: np.ndarray) -> BlendedWienerModel:
    """:func:`deployed_wiener_model`'s :class:`BlendedWienerModel`: the filters are the
    points' spectra at the deployed depth ``d0`` and, last, a delta kernel's (1)."""
    index, weight = (np.asarray(x) for x in blend)
    if index.shape != weight.shape or index.ndim != 2 or index.shape[0] != P:
        raise ValueError(f"blend: need (index, weight) of shape ({P}, M), got "
                         f"{index.shape} and {weight.shape}")
    if np.any(index < -1) or np.any(index >= P):
        raise ValueError(f"blend: indices must be points 0..{P - 1} or -1 (delta)")
    w = np.asarray(weight, dtype=float)
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.allclose(w.sum(axis=1), 1.0,
                                                                       rtol=0, atol=1e-9):
        raise ValueError("blend: weights must be finite, >= 0 and sum to 1 for each point")
    spec = base.spectra_re[d0 * P:(d0 + 1) * P] + 1j * base.spectra_im[d0 * P:(d0 + 1) * P]
    delta = np.ones((1,) + spec.shape[1:], dtype=complex)
    filters = np.concatenate([spec, delta])
    idx = np.where(index < 0, P, index).astype(np.intp)
    return BlendedWienerModel(spectra_re=base.spectra_re, spectra_im=base.spectra_im,
                              filters=filters, blend_index=np.tile(idx, (D, 1)),
                              blend_weight=np.tile(weight.astype(float), (D, 1)),
                              weight=base.weight, reg_true=base.reg, reg_filter=reg_f,
                              noise_var=base.noise_var)
