"""Spatially varying blur and deconvolution by product-convolution (grid banks).

The IPSF at a pixel p is the bilinear interpolation of the bank's kernels at the four
surrounding grid points, ``k_p = Σ_b w_b(p) k_b``, with hat windows ``w_b`` that sum to
one everywhere (clamped beyond the outermost grid lines). Then

- the blur (forward operator) is exactly ``y = Σ_b k_b ⊛ (w_b · x)`` [1]_;
- the deconvolution is ``x̂ = Σ_b w_b · (g_b ⊛ y)``, ``g_b`` the Wiener filter of
  ``k_b``: each region is restored with its own IPSF (paper Sec. 5, tilted paraboloid)
  and the results are blended with the same smooth windows, so there are no seams.

References
----------
.. [1] J. G. Nagy and D. P. O'Leary, "Restoring images degraded by spatially variant
   blur", SIAM J. Sci. Comput. 19(4), 1063–1082, 1998.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.signal as ssig

from ..config import Setup
from ..deprecation import renamed_keywords
from ..io.bank import BankError, IPSFBank
from ..optics.pixels import sensor_to_pixel
from ..resources import check_allocation
from .kernels import check_bank_matches, select_depth
from .wiener import (check_image_values, check_nsr, estimate_nsr, wiener_deconvolve,
                     wiener_memory_bytes, working_dtype)

__all__ = ["mirror_grid_shape", "grid_bank_shape", "hat_weights", "grid_axes_px", "grid_windows",
           "product_convolve",
           "scatter_blur", "grid_kernel_field", "spatially_varying_blur",
           "spatially_varying_deconvolve"]

logger = logging.getLogger(__name__)

#: Grid nodes across the mirror's image (its narrower extent) that :func:`mirror_grid_shape`
#: asks for. Measured on the tilted paraboloid (200 px render, 0.06 mm pitch, 128 spp,
#: Wiener, natural prior): 9x9 over the sensor puts 5 nodes across the mirror and gives
#: 26.8 dB; 12-15 cells a side (8-10 nodes across) 27.3-27.6 dB; one kernel everywhere
#: 27.6 dB.
MIRROR_GRID_NODES = 8


def mirror_grid_shape(setup: Setup, *, nodes_across: int = MIRROR_GRID_NODES,
                      max_cells: int = 64) -> tuple[int, int]:
    """(rows, cols) of a grid bank's sensor grid fine enough for the mirror's image.

    A grid bank's points are cell centres of a grid over the whole sensor
    (:func:`mitsweep.tracer.bank.grid_points`), but a tilted mirror's image covers only
    part of the frame, off-centre: a grid sized for the frame puts few nodes on the
    mirror. Nodes off the mirror hold delta kernels, and the hat windows spread them, and
    the fast-changing kernels of the nodes next to the rim, a whole cell into the mirror.
    This returns the square grid whose cells put ``nodes_across`` nodes across the
    narrower extent of the mirror's predicted outline
    (:func:`mitsweep.optics.outline.predicted_outline`), at most ``max_cells`` a side
    and at most a quarter of the image's smaller side (cells of at least 4 px).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The image's geometry (its sensor: resolution and pitch).
    nodes_across : int
        Nodes wanted across the mirror's image, >= 2.
    max_cells : int
        Upper bound on cells a side (the bank traces rows x cols IPSFs).
    """
    from ..optics.outline import predicted_outline

    if int(nodes_across) < 2:
        raise ValueError(f"nodes_across: must be >= 2, got {nodes_across!r}")
    uv = predicted_outline(setup, n_points=360).uv
    w, h = setup.sensor.size
    ratio = max(w / np.ptp(uv[:, 0]), h / np.ptp(uv[:, 1]))
    W, H = setup.sensor.resolution
    n = int(np.ceil(int(nodes_across) * ratio - 1e-9))
    n = max(1, min(n, int(max_cells), max(1, min(W, H) // 4)))
    return n, n


def grid_bank_shape(setup: Setup, grid: tuple[int, int] = (9, 9)) -> tuple[int, int]:
    """(rows, cols) of the grid bank a dataset restores with: ``grid`` (the datasets'
    default 9 x 9), refined to :func:`mirror_grid_shape` where the mirror's image covers
    only part of the frame (a tilted mirror: 11 x 11 for the tilted paraboloid).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The image's geometry.
    grid : (int, int)
        The grid asked for, ``(rows, cols)``.
    """
    fine = mirror_grid_shape(setup)
    return max(int(grid[0]), int(fine[0])), max(int(grid[1]), int(fine[1]))


def hat_weights(x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(n_nodes, len(x)) piecewise-linear interpolation weights, summing to one.

    ``w_j(nodes[j]) = 1``, falling linearly to 0 at the neighbouring nodes; the first and
    last hats stay 1 beyond the end nodes. ``nodes`` must increase strictly.

    Parameters
    ----------
    x : array_like
        Positions to weigh (any shape, flattened).
    nodes : (n_nodes,) array_like
        The hats' centres, strictly increasing, in the unit of ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    nodes = np.asarray(nodes, dtype=np.float64)
    n = len(nodes)
    if n == 1:
        return np.ones((1, x.size))
    if np.any(np.diff(nodes) <= 0):
        raise ValueError("grid nodes must increase strictly")
    xc = np.clip(x, nodes[0], nodes[-1])
    j = np.clip(np.searchsorted(nodes, xc, side="right") - 1, 0, n - 2)
    t = (xc - nodes[j]) / (nodes[j + 1] - nodes[j])
    w = np.zeros((n, x.size))
    w[j, np.arange(x.size)] = 1 - t
    w[j + 1, np.arange(x.size)] += t
    return w


def grid_axes_px(bank: IPSFBank, image_shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Row and column pixel coordinates of a grid bank's grid lines.

    Parameters
    ----------
    bank : IPSFBank
        A grid bank whose points lie on a regular (rows × cols) grid.
    image_shape : (H, W)
        The image's shape (fixes where the optical axis lies).
    """
    if bank.kind != "grid":
        raise BankError(f"a grid bank is needed here, got a {bank.kind!r} bank")
    if bank.grid_shape is None:
        raise BankError("a grid bank without its grid_shape")
    rows_n, cols_n = bank.grid_shape
    pitch = float(bank.pixel_pitch)
    pts = np.asarray(bank.points_uv, dtype=np.float64).reshape(rows_n, cols_n, 2)
    rows, _ = sensor_to_pixel(0.0, pts[:, 0, 1], image_shape, pitch)
    _, cols = sensor_to_pixel(pts[0, :, 0], 0.0, image_shape, pitch)
    uv = pts / pitch
    # a regular grid: every row shares the column positions and vice versa
    if not (np.allclose(uv[:, :, 0], uv[0:1, :, 0], atol=1e-3)
            and np.allclose(uv[:, :, 1], uv[:, 0:1, 1], atol=1e-3)):
        raise BankError("grid bank points are not on a regular (rows x cols) grid")
    return np.asarray(rows), np.asarray(cols)


def grid_windows(rows: np.ndarray, cols: np.ndarray, image_shape: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
    """Separable hat windows: (wy (n_rows, H), wx (n_cols, W)); w_ij = wy[i] ⊗ wx[j].

    Parameters
    ----------
    rows, cols : ndarray
        Pixel coordinates of the grid lines, increasing (:func:`grid_axes_px`).
    image_shape : (H, W)
        The image's shape.
    """
    H, W = image_shape[:2]
    return hat_weights(np.arange(H), rows), hat_weights(np.arange(W), cols)


def _support(w: np.ndarray) -> tuple[int, int]:
    nz = np.flatnonzero(w > 0)
    return int(nz[0]), int(nz[-1]) + 1


def product_convolve(image: np.ndarray, kernels: np.ndarray, wy: np.ndarray,
                     wx: np.ndarray) -> np.ndarray:
    """``y = Σ_ij k_ij ⊛ ((wy_i ⊗ wx_j) · x)`` with zero outside the image.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
    kernels : (n_rows * n_cols, K, K) ndarray, row-major, centre at [K//2, K//2]
    wy, wx : (n_rows, H), (n_cols, W) windows from :func:`grid_windows`.
    """
    img = np.asarray(image)
    dt = working_dtype(img)
    img = img.astype(dt, copy=False)
    squeeze = img.ndim == 2
    if squeeze:
        img = img[..., None]
    H, W, C = img.shape
    K = kernels.shape[-1]
    h = K // 2
    out = np.zeros((H + 2 * h, W + 2 * h, C), dtype=dt)
    n_c = wx.shape[0]
    for i in range(wy.shape[0]):
        y0, y1 = _support(wy[i])
        for j in range(n_c):
            x0, x1 = _support(wx[j])
            win = (wy[i, y0:y1, None] * wx[j, None, x0:x1]).astype(dt)
            k = kernels[i * n_c + j].astype(dt)
            for c in range(C):
                out[y0:y1 + 2 * h, x0:x1 + 2 * h, c] += ssig.fftconvolve(
                    img[y0:y1, x0:x1, c] * win, k, mode="full")
    out = out[h:h + H, h:h + W]
    return out[..., 0] if squeeze else out


def scatter_blur(image: np.ndarray, kernel_field: np.ndarray) -> np.ndarray:
    """Dense reference blur: each pixel p spreads ``x[p] · k_p`` around itself.

    ``y[p + s] += x[p] k_p[s]`` with zero outside the image; O(H W K²), for small images
    and for checking the fast operators.

    Parameters
    ----------
    image : (H, W) ndarray
    kernel_field : (H, W, K, K) ndarray, per-pixel kernels, centre at [K//2, K//2]
    """
    x = np.asarray(image, dtype=np.float64)
    H, W = x.shape
    K = kernel_field.shape[-1]
    h = K // 2
    out = np.zeros((H + 2 * h, W + 2 * h))
    for a in range(K):
        for c in range(K):
            out[a:a + H, c:c + W] += x * kernel_field[:, :, a, c]
    return out[h:h + H, h:h + W]


def grid_kernel_field(kernels: np.ndarray, wy: np.ndarray, wx: np.ndarray) -> np.ndarray:
    """(H, W, K, K) per-pixel kernels ``k_p = Σ_ij w_ij(p) k_ij`` (small images only).

    Parameters
    ----------
    kernels : (n_rows · n_cols, K, K) ndarray
        The grid's kernels, row-major.
    wy, wx : ndarray
        The hat windows (n_rows, H) and (n_cols, W) of :func:`grid_windows`.
    """
    n_r, n_c = wy.shape[0], wx.shape[0]
    k = np.asarray(kernels, dtype=np.float64).reshape(n_r, n_c, *kernels.shape[-2:])
    return np.einsum("iy,jx,ijab->yxab", wy, wx, k)


def _grid_setup(image, bank, depth):
    img = np.asarray(image)
    check_bank_matches(bank, img.shape)
    if bank.kind != "grid":
        raise BankError(f"spatially varying deconvolution needs a grid bank, got "
                        f"{bank.kind!r} (convert with kernels.grid_bank_from_radial)")
    rows, cols = grid_axes_px(bank, img.shape[:2])
    wy, wx = grid_windows(rows, cols, img.shape[:2])
    return img, select_depth(bank, depth), wy, wx


@renamed_keywords(depth_mm="depth")
def spatially_varying_blur(image: np.ndarray, bank: IPSFBank, *,
                           depth: float | str | None = None) -> np.ndarray:
    """Blur ``image`` by a grid bank's interpolated IPSFs (:func:`product_convolve`).

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        The sharp image, on the bank's reference pixel grid.
    bank : IPSFBank
        A grid bank.
    depth : float, "mean" or None
        The bank depth, as in :func:`~mitsweep.deconv.kernels.select_depth` (default
        500 mm).
    """
    img, kernels, wy, wx = _grid_setup(image, bank, depth)
    return product_convolve(img, kernels, wy, wx)


@renamed_keywords(depth_mm="depth")
def spatially_varying_deconvolve(image: np.ndarray, bank: IPSFBank, *,
                                 nsr: float | None = None, prior: str = "natural",
                                 depth: float | str | None = None,
                                 margin: int | None = None) -> np.ndarray:
    r"""Deconvolve a spatially varying blur given by a grid bank.

    Parameters
    ----------
    image : (H, W) or (H, W, C) ndarray
        Focal-sweep image on the bank's reference pixel grid (float32 stays float32).
    bank : IPSFBank
        ``kind="grid"`` bank (a radial one can be converted with
        :func:`~mitsweep.deconv.kernels.grid_bank_from_radial`).
    nsr, prior
        Wiener regulariser, see :func:`~mitsweep.deconv.wiener.wiener_deconvolve`;
        ``nsr=None`` estimates one NSR from the whole image (the same for every region,
        so that regions agree).
    depth
        Which depth of the bank, see :func:`~mitsweep.deconv.kernels.select_depth`.
    margin : int, optional
        Context pixels around each window's support that its Wiener filter sees
        (default 3 K): the inverse filter's support must fit in it.

    Returns
    -------
    (H, W) or (H, W, C) ndarray

    Notes
    -----
    .. math:: \hat x = \sum_b w_b \cdot \mathcal{F}^{-1}\!\left[
              \frac{H_b^*}{|H_b|^2 + R}\, \mathcal{F}[y]\right]

    evaluated on each window's support plus ``margin`` (symmetric extension beyond
    the image border), with bilinear hat windows :math:`w_b` summing to one.
    """
    img, kernels, wy, wx = _grid_setup(image, bank, depth)
    dt = working_dtype(img)
    img = img.astype(dt, copy=False)
    check_image_values(img)
    if nsr is None:
        nsr = estimate_nsr(img)
        logger.info("estimated NSR %.3g", nsr)
    nsr = check_nsr(nsr)
    K = kernels.shape[-1]
    m = 3 * K if margin is None else int(margin)
    if m < 0:
        raise ValueError(f"margin must be >= 0, got {margin}")
    H, W = img.shape[:2]
    C = img.shape[2] if img.ndim == 3 else 1
    # the padded image, the output and a working copy of the input, plus the largest
    # tile's Wiener deconvolution (NumPy's traced peak is ~0.9 of this, tests)
    tile = (max(_support(w)[1] - _support(w)[0] for w in wy) + 2 * m,
            max(_support(w)[1] - _support(w)[0] for w in wx) + 2 * m)
    check_allocation(f"spatially varying deconvolution of {W}x{H} px with "
                     f"{wy.shape[0]}x{wx.shape[0]} grid cells",
                     (float(H + 2 * m) * (W + 2 * m) + 2.0 * H * W) * C * dt.itemsize
                     + wiener_memory_bytes(tile, C, dt))
    widths = [(m, m), (m, m)] + [(0, 0)] * (img.ndim - 2)
    padded = np.pad(img, widths, mode="symmetric")
    out = np.zeros(img.shape, dtype=dt)
    n_c = wx.shape[0]
    for i in range(wy.shape[0]):
        y0, y1 = _support(wy[i])
        for j in range(n_c):
            x0, x1 = _support(wx[j])
            patch = padded[y0:y1 + 2 * m, x0:x1 + 2 * m]
            rest = wiener_deconvolve(patch, kernels[i * n_c + j], nsr=nsr, prior=prior, pad=0,
                                     n_px=float(np.sqrt(H * W)))
            win = (wy[i, y0:y1, None] * wx[j, None, x0:x1]).astype(dt)
            if img.ndim == 3:
                win = win[..., None]
            out[y0:y1, x0:x1] += win * rest[m:m + y1 - y0, m:m + x1 - x0]
    return out
