"""The paper's Table 1: depth variance (V_avg) and IPSF sharpness (kurtosis) per sweep range.

For each sweep range (focus distances, mm), a 19-radius IPSF bank at the depths
{0.5, 1, 5, 10} m gives V_avg (Eq. 3) and the kurtosis of the radial and tangential
cross-sections at the image centre (radius 0) and periphery (the FOV edge), averaged
over the depths. A conventional camera (same lens and sensor, no mirror, no sweep,
focused at the dioptric middle of the depth range) gives the V_avg to compare with.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Setup
from ..io.bank import IPSFBank
from ..optics import image_distance, optimal_sweep_range
from .bank import ipsf_bank
from .settings import TraceSettings
from .metrics import EPSILON, cross_sections, kurtosis, v_avg

__all__ = ["PAPER_DEPTHS_MM", "PAPER_RANGE_FRACTIONS", "default_ranges", "conventional_psf",
           "conventional_v_avg", "table1_banks", "table1"]

logger = logging.getLogger(__name__)

#: Depths of Eq. 3, mm.
PAPER_DEPTHS_MM = (500.0, 1000.0, 5000.0, 10000.0)
#: The paper's Table 1 sweeps (339–348, 339–357, 339–374 mm) as lengths relative to the
#: sphere's optimal range 339–364.25 mm: applied to any setup's optimal range, they give
#: back the paper's rows for scenes/sphere.toml.
PAPER_RANGE_FRACTIONS = (9.0 / 25.25, 18.0 / 25.25, 35.0 / 25.25)


def default_ranges(setup: Setup) -> list[tuple[float, float]]:
    """The paper's three ranges scaled to the setup, then the optimal range itself.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its optimal sweep range (:func:`mitsweep.optics.optimal_sweep_range`) is scaled
        by :data:`PAPER_RANGE_FRACTIONS` from its near end.

    Returns
    -------
    list of (float, float)
        ``(focus_min, focus_max)`` of each range, mm.
    """
    sr = optimal_sweep_range(setup)
    lo, span = sr.focus_min, sr.focus_max - sr.focus_min
    rows = [(lo, lo + frac * span) for frac in PAPER_RANGE_FRACTIONS]
    rows.append((lo, sr.focus_max))
    return rows


def conventional_psf(setup: Setup, distance: float, focus_distance: float, *, kernel_size: int,
                     supersample: int = 16) -> NDArray[np.float32]:
    """Geometric defocus PSF of a conventional camera (thin lens, no mirror), unit sum.

    A point on the axis at ``distance`` mm from the lens, sensor focused at
    ``focus_distance``: a uniform disk of radius ``a |1 − i_s / i_o|`` (``a`` the
    aperture radius, ``i_o`` the point's image distance, ``i_s`` the sensor's), integrated
    over pixels by ``supersample²`` sub-pixel samples. A disk narrower than a pixel
    falls into the central pixel.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its lens (focal length, aperture radius) and pixel pitch.
    distance : float
        The point's distance from the lens, mm.
    focus_distance : float
        The distance the camera focuses at, mm.
    kernel_size : int
        K, px.
    supersample : int, optional
        Sub-pixel samples per pixel side (default 16).

    Returns
    -------
    (K, K) float32 ndarray
    """
    f, a = setup.lens.focal_length, setup.lens.aperture_radius
    i_s = float(image_distance(f, focus_distance))
    i_o = float(image_distance(f, distance))
    r_px = a * abs(1.0 - i_s / i_o) / setup.sensor.pixel_pitch
    K = int(kernel_size)
    s = int(supersample)
    x = (np.arange(K * s) + 0.5) / s - K / 2.0
    inside = (x[:, None] ** 2 + x[None, :] ** 2) <= r_px * r_px
    k = inside.reshape(K, s, K, s).sum(axis=(1, 3)).astype(np.float64)
    if k.sum() == 0:
        k[K // 2, K // 2] = 1.0
    return (k / k.sum()).astype(np.float32)


def conventional_v_avg(setup: Setup, depths: ArrayLike = PAPER_DEPTHS_MM, *,
                       kernel_size: int = 63, epsilon: float = EPSILON) -> tuple[float, float]:
    """V_avg (Eq. 3) of a conventional camera over ``depths`` and its focus distance.

    The camera focuses at the dioptric middle ``2 / (1/d_min + 1/d_max)``; its defocus
    PSF does not depend on the field point, so the average over points is one term.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        Its lens and pixel pitch.
    depths : array_like, optional
        Depths of Eq. 3, mm (default :data:`PAPER_DEPTHS_MM`).
    kernel_size : int, optional
        K, px (default 63).
    epsilon : float, optional
        Regulariser of Eq. 3 (default :data:`mitsweep.tracer.metrics.EPSILON`).

    Returns
    -------
    v_avg : float
    focus_distance : float
        mm.
    """
    d = np.asarray(depths, dtype=float)
    focus = 2.0 / (1.0 / d.min() + 1.0 / d.max())
    kernels = np.stack([conventional_psf(setup, x, focus, kernel_size=kernel_size)
                        for x in d])[:, None]
    return v_avg(kernels, epsilon=epsilon), float(focus)


def _range_setup(setup, fmin: float, fmax: float):
    if not (setup.lens.focal_length < fmin < fmax):
        raise ValueError(f"sweep range {fmin:g}-{fmax:g} mm: need "
                         f"lens.focal_length ({setup.lens.focal_length:g}) < min < max")
    s = dataclasses.replace(setup, sweep=dataclasses.replace(setup.sweep, focus_min=fmin,
                                                             focus_max=fmax))
    return s, optimal_sweep_range(s)  # the given range; the field is still the setup's FOV


def table1_banks(setup: Setup, *, ranges: Sequence[tuple[float, float]] | None = None,
                 depths: Sequence[float] = PAPER_DEPTHS_MM, n_radii: int = 19,
                 rays: int = 1_000_000, kernel_size: int = 63, seed: int = 0,
                 progress: Callable[[], object] | None = None) -> list[IPSFBank]:
    """The radial IPSF banks Table 1 measures, one per sweep range (parameters as
    :func:`table1`): to reuse them elsewhere (Fig. 5) and pass them back as its
    ``banks``.

    Parameters
    ----------
    setup, ranges, depths, n_radii, rays, kernel_size, seed, progress
        As :func:`table1`.

    Returns
    -------
    list of mitsweep.io.bank.IPSFBank
        One radial bank per range.
    """
    ranges = (default_ranges(setup) if ranges is None
              else [(float(lo), float(hi)) for lo, hi in ranges])
    banks = []
    for fmin, fmax in ranges:
        s, sr = _range_setup(setup, fmin, fmax)
        banks.append(ipsf_bank(s, kind="radial", n_radii=n_radii, depths=depths,
                               settings=TraceSettings(rays=rays, kernel_size=kernel_size,
                                                      seed=seed),
                               sweep=sr, progress=progress))
    return banks


def table1(setup: Setup, *, ranges: Sequence[tuple[float, float]] | None = None,
           depths: Sequence[float] = PAPER_DEPTHS_MM, n_radii: int = 19,
           rays: int = 1_000_000, kernel_size: int = 63, seed: int = 0,
           epsilon: float = EPSILON, progress: Callable[[], object] | None = None,
           banks: Sequence[IPSFBank] | None = None) -> dict:
    """Compute Table 1 for a rotationally symmetric setup.

    Parameters
    ----------
    ranges : sequence of (focus_min, focus_max), mm, optional
        Sweep ranges (default :func:`default_ranges`).
    depths : sequence of float
        Depths of Eq. 3, mm; the first is the reference.
    n_radii, rays, kernel_size, seed
        Bank parameters (:func:`mitsweep.tracer.ipsf_bank`).
    progress : callable, optional
        Called after each IPSF.
    banks : sequence of mitsweep.io.bank.IPSFBank, optional
        The banks of :func:`table1_banks` with these parameters, one per range, already
        traced; each is checked against its range, depths and radii.

    Returns
    -------
    dict
        ``rows``: one dict per range (``focus_min_mm``, ``focus_max_mm``, ``v_avg``,
        ``kurtosis`` {center, periphery} × {tangential, radial}, ``periphery_radius_mm``);
        ``conventional``: {``v_avg``, ``focus_distance_mm``}; the parameters.
    """
    if not setup.mirror.is_symmetric:
        raise ValueError("table1: needs a rotationally symmetric setup (radial IPSF bank); "
                         f"this mirror is tilted by {setup.mirror.tilt_deg:g} deg")
    ranges = (default_ranges(setup) if ranges is None
              else [(float(lo), float(hi)) for lo, hi in ranges])
    if banks is None:
        banks = table1_banks(setup, ranges=ranges, depths=depths, n_radii=n_radii, rays=rays,
                             kernel_size=kernel_size, seed=seed, progress=progress)
    elif len(banks) != len(ranges):
        raise ValueError(f"banks: one per sweep range ({len(ranges)}), got {len(banks)}")
    rows = []
    for (fmin, fmax), bank in zip(ranges, banks):
        _, sr = _range_setup(setup, fmin, fmax)
        swept = bank.metadata["sweep_range"]
        radii = bank.radii
        if (bank.kind != "radial" or radii is None or len(radii) != int(n_radii)
                or not np.allclose(bank.depths, depths)
                or not np.allclose((swept["focus_min_mm"], swept["focus_max_mm"]), (fmin, fmax))):
            raise ValueError(f"banks: the bank for {fmin:g}-{fmax:g} mm is not Table 1's "
                             f"(radial, {int(n_radii)} radii, depths {list(depths)} mm, that "
                             f"range)")
        kz = {}
        for where, idx in (("center", 0), ("periphery", len(radii) - 1)):
            tan, rad = [], []
            for j in range(len(depths)):
                _, r_cs, t_cs = cross_sections(bank.kernels[j, idx], 0.0)
                rad.append(kurtosis(r_cs))
                tan.append(kurtosis(t_cs))
            kz[where] = {"tangential": float(np.mean(tan)), "radial": float(np.mean(rad))}
        rows.append({
            "focus_min_mm": fmin, "focus_max_mm": fmax,
            "sensor_travel_mm": sr.translation,
            "v_avg": v_avg(bank.kernels, epsilon=epsilon), "kurtosis": kz,
            "periphery_radius_mm": float(radii[-1]),
            "max_outside_kernel": float(np.max(bank.metadata["outside_kernel"])),
        })
        logger.info("table1 range %.1f-%.1f: V_avg %.3g", fmin, fmax, rows[-1]["v_avg"])
    conv, focus = conventional_v_avg(setup, depths, kernel_size=kernel_size, epsilon=epsilon)
    return {"setup": setup.name, "rows": rows,
            "conventional": {"v_avg": conv, "focus_distance_mm": focus},
            "depths_mm": [float(d) for d in depths], "n_radii": int(n_radii),
            "rays_per_ipsf": int(rays), "kernel_size": int(kernel_size),
            "epsilon": float(epsilon), "seed": int(seed),
            "kurtosis_definition": "intensity-weighted 4th standardised moment of the "
                                   "cross-section through the centroid (Gaussian = 3)",
            "weighting": "W = 1/|f|, f in cycles/pixel, W(0) = 0"}
