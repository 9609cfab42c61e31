"""Per-plane PSF banks: the PSF averaged over each bin of sensor distances.

The IPSF is linear in the time the sensor spends at each distance,

.. math:: \\mathrm{IPSF}(x) = \\int \\mathrm{PSF}(x; i)\\, w(i)\\, di ,
          \\qquad w \\ge 0,\\ \\int w\\, di = 1

(``w`` the time density, 1/velocity, per unit exposure). Split the span into bins
``[e_k, e_{k+1}]`` and hold ``w`` constant on each: with ``τ_k`` the fraction of the
exposure spent in bin ``k``, ``IPSF = Σ_k τ_k P_k`` where ``P_k`` is the PSF averaged over
the bin's distances. A motion that is piecewise linear in time with knots at the bin
edges (:meth:`mitsweep.optics.motion.MotionProfile.tabulated` with times ``Σ_{m<k} τ_m``)
has exactly this ``w``, so a design's predicted IPSF is the one the tracer and the
renderer run.

:func:`plane_psfs` traces the rays of one point source once with the tracer's kernel
(:func:`mitsweep.tracer.kernel.trace_arrays`, its sampling box fitted by
:func:`mitsweep.tracer.ipsf.fit_sampling_box`) and bins each ray's hit ``h(i) = A + B i``
at ``sub_planes`` stratified distances per bin (the bin average, by the midpoint rule),
on the reference pixel grid, exactly as the tracer's deposit bins a hit (box filter,
rows down the image). ``P_k`` is normalised by the landed weight, so it holds the
fraction of the light that falls inside the kernel window while the sensor is in bin k.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from ..config import Setup
from ..deprecation import renamed_fields, renamed_keywords
from ..tracer.ipsf import fit_sampling_box
from ..tracer.kernel import trace_arrays
from ..tracer.source import source_from_image

__all__ = ["PlaneBank", "plane_psfs", "plane_bank", "DEFAULT_PLANE_RAYS", "DEFAULT_SUB_PLANES"]

logger = logging.getLogger(__name__)

#: Rays per point of a plane bank: the plane sum with uniform weights then agrees with
#: the tracer's exact IPSF to its own seed-to-seed L1 spread (tests/test_design_sweep.py).
DEFAULT_PLANE_RAYS = 1 << 16
#: Distances per bin of the midpoint rule.
DEFAULT_SUB_PLANES = 4
_CHUNK = 1 << 20
_KEYS = ("landed", "weight", "Au", "Av", "Bu", "Bv")


@renamed_fields(edges_mm="edges", depths_mm="depths", widths_mm="widths")
@dataclass(frozen=True)
class PlaneBank:
    """Bin-averaged PSFs over a set of field points and depths.

    Attributes
    ----------
    kernels : (n_depths, n_points, n_bins, K, K) ndarray
        ``P_k`` of each point and depth (float64; sums = in-window fraction of the light).
    edges : (n_bins + 1,) ndarray
        Bin edges, sensor distances in mm, in the order the sweep runs (start → end).
    points_uv : (n_points, 2) ndarray
        Upright image points (u, v), mm at the reference sensor distance.
    depths : (n_depths,) ndarray
        Depths l of the point sources, mm.
    reference_sensor_distance : float
        mm: mid-travel of the span.
    pixel_pitch : float
        mm.
    metadata : dict
        rays, sub-planes, seed, seconds.

    The former names ``edges_mm``, ``depths_mm`` and ``widths_mm`` read on with a
    DeprecationWarning.
    """

    kernels: np.ndarray
    edges: np.ndarray
    points_uv: np.ndarray
    depths: np.ndarray
    reference_sensor_distance: float
    pixel_pitch: float
    metadata: dict = field(default_factory=dict)

    @property
    def widths(self) -> np.ndarray:
        """``|e_{k+1} − e_k|`` of each bin, mm."""
        return np.abs(np.diff(self.edges))

    def ipsf(self, tau: ArrayLike) -> np.ndarray:
        """``Σ_k τ_k P_k``: the IPSF of every point and depth for exposure fractions ``tau``.

        Parameters
        ----------
        tau : array_like
            (n_bins,) fraction of the exposure spent in each bin (a motion's τ; summing
            to 1 for a whole exposure).

        Returns
        -------
        (n_depths, n_points, K, K) ndarray
        """
        return np.tensordot(self.kernels, np.asarray(tau, dtype=float), axes=([2], [0]))

    def coarsened(self, groups: int) -> PlaneBank:
        """The same bank over ``groups`` coarser bins (consecutive bins merged).

        A merged bin's PSF is the width-weighted mean of its bins' (the average over its
        distances); used for the brute-force check of the optimiser on a small problem.

        Parameters
        ----------
        groups : int
            Number of bins of the result, in [1, n_bins]; the bins are split into
            ``groups`` runs of consecutive bins as evenly as :func:`numpy.array_split`
            does.

        Returns
        -------
        PlaneBank
            The same points, depths and pitch; ``metadata["coarsened_from"]`` the former
            number of bins.
        """
        n = self.kernels.shape[2]
        if not 1 <= groups <= n:
            raise ValueError(f"groups: must be in [1, {n}], got {groups}")
        parts = np.array_split(np.arange(n), groups)
        w = self.widths
        kern = np.stack([np.tensordot(self.kernels[:, :, p], w[p] / w[p].sum(), axes=([2], [0]))
                         for p in parts], axis=2)
        edges = np.array([self.edges[p[0]] for p in parts] + [self.edges[-1]])
        return PlaneBank(kernels=kern, edges=edges, points_uv=self.points_uv,
                         depths=self.depths,
                         reference_sensor_distance=self.reference_sensor_distance,
                         pixel_pitch=self.pixel_pitch,
                         metadata=dict(self.metadata, coarsened_from=n))


@renamed_keywords(edges_mm="edges")
def plane_psfs(setup: Setup, u: float, v: float, depth: float, edges: ArrayLike, *,
               reference_sensor_distance: float, rays: int = DEFAULT_PLANE_RAYS,
               kernel_size: int = 31, seed: int = 0,
               sub_planes: int = DEFAULT_SUB_PLANES) -> np.ndarray:
    """Bin-averaged PSFs of the point source seen at (u, v), depth ``depth``.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    u, v : float
        Upright image point, mm at ``reference_sensor_distance``.
    depth : float
        Depth l, mm (inf allowed).
    edges : (n_bins + 1,) array_like
        Bin edges, sensor distances in mm (monotonic, all > the lens focal length).
    reference_sensor_distance : float
        Pixel grid and centring distance, mm (mid-travel of the span).
    rays, kernel_size, seed
        As :func:`mitsweep.tracer.integrated_psf`.
    sub_planes : int
        Stratified distances per bin (midpoint rule).

    Returns
    -------
    (n_bins, K, K) float64 ndarray
        Rows down the image (−v), columns right (+u), the chief-ray image at the reference
        distance at ``[K//2, K//2]``; each normalised by the landed weight.

    Raises
    ------
    ValueError
        The point is outside the mirror's image or fully vignetted.
    """
    K = int(kernel_size)
    if K < 3 or K % 2 == 0:
        raise ValueError(f"kernel_size: must be an odd integer >= 3, got {kernel_size!r}")
    edges = np.asarray(edges, dtype=float)
    S = int(sub_planes)
    if S < 1:
        raise ValueError(f"sub_planes: must be >= 1, got {sub_planes!r}")
    source = source_from_image(setup, u, v, depth,
                               reference_sensor_distance=reference_sensor_distance)
    geom = source.geometry(setup)
    params, _ = fit_sampling_box(geom, seed=seed)
    pitch = setup.sensor.pixel_pitch
    cu, cv = source.image_uv
    frac = (np.arange(S) + 0.5) / S
    dists = (edges[:-1, None] + np.diff(edges)[:, None] * frac[None, :]).ravel()  # (N·S,)
    n_bins = edges.size - 1
    KK = K * K
    hist = np.zeros(n_bins * KK)
    landed_w = 0.0
    done = 0
    while done < rays:
        n = min(_CHUNK, int(rays) - done)
        r = trace_arrays(geom, params, n, offset=done, keys=_KEYS)
        done += n
        ok = r["landed"]
        w = r["weight"][ok]
        landed_w += float(w.sum())
        au = (r["Au"][ok] - cu) / pitch + (K // 2 + 0.5)
        av = -(r["Av"][ok] - cv) / pitch + (K // 2 + 0.5)
        bu, bv = r["Bu"][ok] / pitch, -r["Bv"][ok] / pitch
        step = max(1, (1 << 24) // max(1, w.size))  # distances per pass: bounded memory
        for j0 in range(0, dists.size, step):
            d = dists[j0:j0 + step]
            col = np.floor(au[None, :] + bu[None, :] * d[:, None]).astype(np.int64)
            row = np.floor(av[None, :] + bv[None, :] * d[:, None]).astype(np.int64)
            inside = (col >= 0) & (col < K) & (row >= 0) & (row < K)
            plane = (np.arange(j0, j0 + d.size) // S)[:, None]
            idx = (plane * KK + row * K + col)[inside]
            ww = np.broadcast_to(w[None, :], inside.shape)[inside]
            hist += np.bincount(idx, weights=ww, minlength=n_bins * KK)
    if not landed_w > 0:
        raise ValueError("no traced ray landed on the sensor: the point is fully vignetted")
    return hist.reshape(n_bins, K, K) / (landed_w * S)


@renamed_keywords(depths_mm="depths", edges_mm="edges")
def plane_bank(setup: Setup, points_uv: ArrayLike, depths: ArrayLike, edges: ArrayLike, *,
               reference_sensor_distance: float, rays: int = DEFAULT_PLANE_RAYS,
               kernel_size: int = 31, seed: int = 0, sub_planes: int = DEFAULT_SUB_PLANES,
               progress: Callable[[], object] | None = None) -> PlaneBank:
    """:func:`plane_psfs` over field points × depths (point ``p`` traced with ``seed + p``,
    as :func:`mitsweep.tracer.ipsf_bank` seeds its points).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sensor.
    points_uv : array_like, shape (P, 2)
        Field points, upright mm at ``reference_sensor_distance``.
    depths : array_like
        Depths l, mm.
    edges : array_like
        Edges of the sweep's bins, sensor distances, mm.
    reference_sensor_distance : float
        Sensor distance of the kernels' pixel grid, mm.
    rays : int, optional
        Rays traced per point and depth.
    kernel_size : int, optional
        Kernel side, pixels (odd).
    seed : int, optional
        Base seed (point ``p`` uses ``seed + p``).
    sub_planes : int, optional
        Distances per bin at which each ray's hits are deposited.
    progress : callable, optional
        Called once per point.
    """
    pts = np.asarray(points_uv, dtype=float).reshape(-1, 2)
    depths = np.asarray(depths, dtype=float).ravel()
    edges = np.asarray(edges, dtype=float)
    K = int(kernel_size)
    kern = np.zeros((depths.size, len(pts), edges.size - 1, K, K))
    t0 = time.perf_counter()
    for di, depth in enumerate(depths):
        for pi, (u, v) in enumerate(pts):
            kern[di, pi] = plane_psfs(setup, float(u), float(v), float(depth), edges,
                                      reference_sensor_distance=reference_sensor_distance,
                                      rays=rays, kernel_size=K, seed=seed + pi,
                                      sub_planes=sub_planes)
            if progress is not None:
                progress()
    seconds = time.perf_counter() - t0
    logger.info("plane bank: %d points x %d depths x %d bins in %.1f s", len(pts), depths.size,
                edges.size - 1, seconds)
    return PlaneBank(kernels=kern, edges=edges, points_uv=pts, depths=depths,
                     reference_sensor_distance=float(reference_sensor_distance),
                     pixel_pitch=setup.sensor.pixel_pitch,
                     metadata={"rays": int(rays), "sub_planes": int(sub_planes),
                               "seed": int(seed), "kernel_size": K, "seconds": seconds,
                               "method": "bin-averaged plane PSFs (midpoint rule)"})
