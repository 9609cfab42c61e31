"""IPSF kernels from a bank, as the deconvolution uses them.

Helpers to pick a depth slice of an :class:`~mitsweep.io.bank.IPSFBank`, interpolate
a radial bank at any radius, rotate a kernel to a polar angle, turn a radial bank into a
grid bank, and check that a bank matches an image. Pixel conventions follow
``mitsweep/io/bank.py``: kernel rows go down the image (−v), columns right (+u), centre
at ``[K // 2, K // 2]``; pixels and sensor millimetres convert through
:mod:`mitsweep.optics.pixels` (the optical axis at the image centre).
"""

from __future__ import annotations

import logging
import math
from typing import Any
from collections.abc import Mapping

import numpy as np
import scipy.ndimage as ndi

from ..deprecation import renamed_keywords
from ..io.bank import (OPTICS_SECTIONS, BankError, IPSFBank, fill_off_mirror_nodes,
                       optics_fingerprint, optics_sections)
from ..optics.pixels import optical_center_px, pixel_to_sensor
from ..resources import check_allocation

__all__ = ["PAPER_DECONV_DEPTH_MM", "optical_center", "select_depth", "radii_px",
           "interpolate_radial", "rotate_kernel", "grid_bank_from_radial", "fill_invalid_nodes",
           "check_bank_matches", "bank_identity_problem", "check_bank_identity", "normalise"]

logger = logging.getLogger(__name__)

#: The paper deconvolves with IPSFs computed for a 50 cm scene depth (Sec. 5, Fig. 8a).
PAPER_DECONV_DEPTH_MM = 500.0


#: (row, col) of the optical axis on an image of ``shape``: the image convention's, kept
#: under the deconvolution's older name.
optical_center = optical_center_px


def normalise(k: np.ndarray) -> np.ndarray:
    """Kernel(s) scaled to unit sum over the last two axes (float64).

    Parameters
    ----------
    k : (..., K0, K1) array_like
        One kernel or a stack of kernels.

    Raises
    ------
    BankError
        A kernel's sum is zero, negative or not a number.
    """
    k = np.asarray(k, dtype=np.float64)
    s = k.sum(axis=(-2, -1), keepdims=True)
    if np.any(~(s > 0)):
        raise BankError("a kernel has a zero or negative sum")
    return k / s


@renamed_keywords(depth_mm="depth")
def select_depth(bank: IPSFBank, depth: float | str | None = None) -> np.ndarray:
    """The (n_points, K, K) unit-sum kernels used for deconvolution.

    Parameters
    ----------
    bank : IPSFBank
        The bank whose kernels (n_depths, n_points, K, K) are selected from.
    depth : float, "mean" or None
        A depth in mm picks the bank depth nearest to it (in 1/depth, so ``inf`` works);
        ``"mean"`` averages the kernels over all depths (the IPSF is quasi
        depth-invariant, paper Sec. 3); ``None`` is the paper's choice, 500 mm. The
        former keyword ``depth_mm`` is still accepted, with a :class:`DeprecationWarning`.
    """
    k = np.asarray(bank.kernels, dtype=np.float64)
    if isinstance(depth, str):
        if depth != "mean":
            raise ValueError(f"depth must be a number, 'mean' or None, got {depth!r}")
        return normalise(k.mean(axis=0))
    target = PAPER_DECONV_DEPTH_MM if depth is None else float(depth)
    if not target > 0:
        raise ValueError(f"depth must be > 0, got {depth!r}")
    depths = np.asarray(bank.depths, dtype=np.float64)
    with np.errstate(divide="ignore"):
        i = int(np.argmin(np.abs(1.0 / depths - 1.0 / target)))
    logger.debug("deconvolving with the bank's depth %g mm", depths[i])
    return normalise(k[i])


def radii_px(bank: IPSFBank) -> np.ndarray:
    """Radii of a radial bank's points, in pixels of the reference sensor distance.

    Parameters
    ----------
    bank : IPSFBank
        A radial bank (:class:`BankError` otherwise).
    """
    if bank.kind != "radial":
        raise BankError(f"a radial bank is needed here, got a {bank.kind!r} bank")
    return np.asarray(bank.radii, dtype=np.float64) / float(bank.pixel_pitch)


def interpolate_radial(kernels: np.ndarray, radii: np.ndarray, r: float) -> np.ndarray:
    """Kernel at radius ``r`` (same unit as ``radii``), linear between bank radii.

    Kernels are aligned at their chief-ray centre, so a linear blend is the standard
    interpolated-PSF model (Nagy & O'Leary 1998); beyond the ends the end kernels hold.

    Parameters
    ----------
    kernels : (n, K0, K1) ndarray
        One kernel per radius, in the order of ``radii``.
    radii : (n,) ndarray
        The kernels' radii, any order (typically px, :func:`radii_px`).
    r : float
        Radius of the kernel wanted, in the unit of ``radii``.
    """
    order = np.argsort(radii)
    radii = np.asarray(radii)[order]
    kernels = np.asarray(kernels)[order]
    if r <= radii[0]:
        return kernels[0]
    if r >= radii[-1]:
        return kernels[-1]
    j = int(np.searchsorted(radii, r)) - 1
    t = (r - radii[j]) / (radii[j + 1] - radii[j])
    return (1 - t) * kernels[j] + t * kernels[j + 1]


def rotate_kernel(kernel: np.ndarray, theta: float) -> np.ndarray:
    """``kernel`` rotated by ``theta`` radians counter-clockwise in upright image coords.

    Cubic-spline resampling about the centre pixel, clamped at 0 and renormalised to
    the input's sum (a rotation keeps energy).

    Parameters
    ----------
    kernel : (K0, K1) array_like
        The kernel, its centre at pixel (K0 // 2, K1 // 2).
    theta : float
        Rotation angle, radians, counter-clockwise.
    """
    k = np.asarray(kernel, dtype=np.float64)
    K0, K1 = k.shape
    c0, c1 = K0 // 2, K1 // 2
    rows, cols = np.mgrid[0:K0, 0:K1].astype(np.float64)
    du, dv = cols - c1, -(rows - c0)
    c, s = np.cos(theta), np.sin(theta)
    su, sv = c * du + s * dv, -s * du + c * dv   # rotate back by −θ to find the source
    out = ndi.map_coordinates(k, [c0 - sv, c1 + su], order=3, mode="constant", cval=0.0)
    out = np.clip(out, 0, None)
    tot = out.sum()
    return out * (k.sum() / tot) if tot > 0 else out


def grid_bank_from_radial(bank: IPSFBank, grid_shape: tuple[int, int],
                          image_shape: tuple[int, int]) -> IPSFBank:
    """A grid bank over ``image_shape`` made by rotating a radial bank's kernels.

    The grid points are pixel centres evenly spread from the first to the last pixel;
    each kernel is the radial bank interpolated at the point's radius and rotated to its
    polar angle. Used to deconvolve rotationally symmetric setups in Cartesian
    coordinates (and to cross-check the polar path).

    Parameters
    ----------
    bank : IPSFBank
        A radial bank.
    grid_shape : (int, int)
        Grid points (rows, cols), each at least 1 (a single row or column sits on the
        optical centre).
    image_shape : tuple of int
        The image's (H, W[, C]).
    """
    rows_n, cols_n = (int(grid_shape[0]), int(grid_shape[1]))
    if rows_n < 1 or cols_n < 1:
        raise ValueError(f"grid_shape must be positive, got {grid_shape}")
    H, W = image_shape[:2]
    cy, cx = optical_center_px((H, W))
    ys = np.linspace(0, H - 1, rows_n) if rows_n > 1 else np.array([cy])
    xs = np.linspace(0, W - 1, cols_n) if cols_n > 1 else np.array([cx])
    pitch = float(bank.pixel_pitch)
    rad = radii_px(bank)
    n_d, K0, K1 = bank.kernels.shape[0], bank.kernels.shape[2], bank.kernels.shape[3]
    # float64 kernels, then their float32 copy in the bank
    check_allocation(f"grid bank of {cols_n}x{rows_n} points from a radial bank "
                     f"({K1}x{K0} px kernels)", float(n_d) * rows_n * cols_n * K0 * K1 * 12)
    kernels = np.asarray(bank.kernels, dtype=np.float64)
    out = np.empty((kernels.shape[0], rows_n * cols_n) + kernels.shape[2:])
    pts = np.empty((rows_n * cols_n, 2))
    n = 0
    for y in ys:
        for x in xs:
            u, v = pixel_to_sensor(y, x, (H, W), pitch)
            r, th = float(np.hypot(u, v)) / pitch, float(np.arctan2(v, u))
            pts[n] = (u, v)
            for d in range(kernels.shape[0]):
                out[d, n] = rotate_kernel(interpolate_radial(kernels[d], rad, r), th)
            n += 1
    return IPSFBank(kernels=out.astype(np.float32), points_uv=pts, depths=bank.depths,
                    pixel_pitch=pitch, reference_sensor_distance=bank.reference_sensor_distance,
                    kind="grid", grid_shape=(rows_n, cols_n),
                    metadata={**bank.metadata, "derived_from": "radial bank, rotated"},
                    optics=bank.optics, fingerprinted=bank.fingerprinted)


def fill_invalid_nodes(bank: IPSFBank) -> IPSFBank:
    """A grid bank whose nodes off the mirror take the kernel of the nearest traced node.

    The tracer gives a grid node whose chief ray misses the mirror a centred delta
    kernel and marks it invalid (``metadata["valid"]``). The product-convolution then
    blends that delta into every pixel of the cells around it, so the mirror's image
    near its rim (on the tilted paraboloid, most of what lies beyond the design FOV) is
    restored with a kernel part blur, part identity: under-deconvolved. The filling is
    :func:`mitsweep.io.bank.fill_off_mirror_nodes` (the tracer's rim banks use it too).

    Parameters
    ----------
    bank : IPSFBank
        The bank; its ``metadata["valid"]`` (one flag per point) marks the traced nodes.
    """
    return fill_off_mirror_nodes(bank)


def _setup_resolution(meta: dict[str, Any]) -> tuple[int, int] | None:
    setup: Any = meta.get("setup") if isinstance(meta, dict) else None
    try:
        w, h = setup["sensor"]["resolution"]
        return int(w), int(h)
    except (TypeError, KeyError, ValueError):
        return None


def check_bank_matches(bank: IPSFBank, image_shape: tuple[int, ...], *,
                       pixel_pitch: float | None = None, rtol: float = 1e-6) -> None:
    """Raise :class:`BankError` if ``bank`` cannot belong to an image of ``image_shape``.

    Checks: the image is (H, W) or (H, W, C); the bank's pixel pitch equals
    ``pixel_pitch`` (when known, e.g. from the image's metadata); the sensor resolution
    recorded in the bank's setup (when present) equals (W, H); the kernel is smaller
    than the image.

    Parameters
    ----------
    bank : IPSFBank
        The bank to check.
    image_shape : tuple of int
        The image's shape, (H, W) or (H, W, C).
    pixel_pitch : float, optional
        The image's pixel pitch, mm, when known; None skips that check.
    rtol : float
        Relative tolerance of the pitch comparison (default 1e-6).
    """
    if len(image_shape) not in (2, 3):
        raise BankError(f"image must be (H, W) or (H, W, C), got shape {tuple(image_shape)}")
    H, W = int(image_shape[0]), int(image_shape[1])
    if pixel_pitch is not None and not np.isclose(float(pixel_pitch), float(bank.pixel_pitch),
                                                  rtol=rtol, atol=0):
        raise BankError(f"bank pixel pitch {bank.pixel_pitch:g} mm does not match the "
                        f"image's {float(pixel_pitch):g} mm")
    res = _setup_resolution(bank.metadata)
    if res is not None and res != (W, H):
        raise BankError(f"bank was made for a {res[0]}x{res[1]} sensor, the image is {W}x{H}")
    if bank.kernel_size >= min(H, W):
        raise BankError(f"bank kernels ({bank.kernel_size} px) do not fit in a {W}x{H} image")


def _same(a: Any, b: Any) -> bool:
    """Equal values, floats to 1e-9 relative (recomputed sweeps may differ in the last bit)."""
    if isinstance(a, bool) or isinstance(b, bool):
        return a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-12)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def _shown(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, list):
        inner = ",".join(_shown(x) for x in v[:4])
        return f"[{inner}{',...' if len(v) > 4 else ''}]"
    return "(absent)" if v is None else str(v)


def _mirror_shape(mirror: Mapping[str, Any]) -> str:
    k = mirror.get("conic")
    if not isinstance(k, (int, float)) or mirror.get("aspheric"):
        return "asphere" if mirror.get("aspheric") else "conic"
    if k == 0:
        return "sphere"
    if k == -1:
        return "paraboloid"
    return "hyperboloid" if k < -1 else ("prolate ellipsoid" if k < 0 else "oblate ellipsoid")


def _describe(optics: Mapping[str, Any], keys: dict[str, list[str]]) -> str:
    parts = []
    for section, names in keys.items():
        table = optics.get(section) or {}
        label = f"mirror ({_mirror_shape(table)})" if section == "mirror" else section
        parts.append(label + " " + " ".join(f"{k}={_shown(table.get(k))}" for k in names))
    return "; ".join(parts)


def bank_identity_problem(bank: IPSFBank, optics: Mapping[str, Any] | None, *,
                          image: str = "the image") -> str | None:
    """Why ``bank`` may not belong to an image of ``optics``, or None when it does.

    Parameters
    ----------
    bank : IPSFBank
        The bank to check.
    optics : mapping or None
        :func:`mitsweep.io.bank.optics_sections` of the image's setup (from its
        provenance, or the setup it was captured with); sections it lacks (``motion``
        when unknown) are not compared. ``None``: the image's optics are unknown.
    image : str
        How to name the image in the message.

    Returns
    -------
    str or None
        ``"bank was traced for mirror (sphere) conic=0 radius=25, IMAGE has mirror
        (paraboloid) conic=-1 radius=28.2"``, or why no comparison is possible: the bank
        predates fingerprints, the bank is synthetic and the image is not, or the image's
        optics are unknown.
    """
    if not bank.fingerprinted:
        return ("the bank predates optics fingerprints (bank format 1), so nothing says "
                "which optics it was traced for; trace it again with `mitsweep ipsf --bank`")
    if bank.optics is None:
        if optics is None:
            return None          # a synthetic bank on an image that claims no optics
        return (f"the bank was traced for no optics (synthetic), {image} has "
                f"{_describe(optics, {'mirror': ['conic', 'radius']})}")
    if optics is None:
        return (f"{image} carries no setup to check the bank against (the bank was traced "
                f"for {_describe(bank.optics, {'mirror': ['conic', 'radius']})})")
    theirs = optics_sections(optics, optics.get("motion"))
    mine = {k: v for k, v in bank.optics.items() if k in theirs}
    if optics_fingerprint(mine) == optics_fingerprint(theirs):
        return None
    differ: dict[str, list[str]] = {}
    for section in OPTICS_SECTIONS:
        a, b = mine.get(section), theirs.get(section)
        if a is None or b is None:
            continue
        names = sorted(k for k in set(a) | set(b) if not _same(a.get(k), b.get(k)))
        if names:
            differ[section] = names
    if not differ:
        return None
    return (f"bank was traced for {_describe(mine, differ)}, {image} has "
            f"{_describe(theirs, differ)}")


def check_bank_identity(bank: IPSFBank, optics: Mapping[str, Any] | None, *,
                        image: str = "the image") -> None:
    """Raise :class:`BankError` with :func:`bank_identity_problem`'s sentence, if any.

    Parameters
    ----------
    bank : IPSFBank
        The bank to check.
    optics : mapping or None
        The image's optics sections, as for :func:`bank_identity_problem`; None when
        unknown.
    image : str
        How to name the image in the message.
    """
    problem = bank_identity_problem(bank, optics, image=image)
    if problem is not None:
        raise BankError(problem)
