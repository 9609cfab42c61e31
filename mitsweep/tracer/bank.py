"""IPSF banks over the field and depths (the deconvolution kernels, paper Sec. 5).

See :mod:`mitsweep.io.bank` for the on-disk contract (kernel orientation, centring,
radial vs grid). Radial banks (rotationally symmetric setups) hold points on the +u
half-axis from the centre out to the image of the FOV's mirror-zone edge; grid banks
(tilted setups) hold the centres of a (rows × cols) grid of cells over the sensor.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import replace
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import __version__
from ..config import Setup, setup_to_dict
from ..io.bank import IPSFBank, optics_sections
from ..optics import SweepRange, chief_ray, image_point, placement_of
from ..optics.motion import MotionProfile
from ..optics.reference import ReferenceGeometry, reference_geometry
from ..resources import check_allocation
from .ipsf import KERNEL_PIXEL_BYTES, integrated_psf, integrated_psfs
from .settings import TraceSettings, settings_from_keywords
from .source import check_depth

__all__ = ["ipsf_bank", "field_radius", "grid_points"]

logger = logging.getLogger(__name__)

#: Rays per IPSF in a bank: ~0.05 s each on 2 cores; L1 error ~1e-2 (docs/reference/tracer.md).
#: The default of :class:`~mitsweep.tracer.settings.TraceSettings` (``rays``).
BANK_RAYS = TraceSettings().rays


def field_radius(setup: Setup, geometry: ReferenceGeometry | None = None) -> float:
    """Image radius (mm, at the reference distance) of the FOV's mirror-zone edge.

    ``geometry``: the setup's reference geometry (default: resolved from the setup).
    """
    geometry = reference_geometry(setup) if geometry is None else geometry
    pl = placement_of(setup.mirror)
    edge = chief_ray(pl, pl.surface(np.array([geometry.sweep.rho_end]), np.array([0.0])))
    u, v = image_point(edge, geometry.sensor_distance)
    return float(math.hypot(float(u[0]), float(v[0])))


def grid_points(setup: Setup, grid: tuple[int, int]) -> NDArray[np.float64]:
    """(rows·cols, 2) upright (u, v) mm: cell centres of a grid over the sensor, row-major,
    rows top to bottom."""
    rows, cols = (int(x) for x in grid)
    if rows < 1 or cols < 1:
        raise ValueError(f"grid: rows and cols must be >= 1, got {grid!r}")
    w, h = setup.sensor.size_mm
    us = ((np.arange(cols) + 0.5) / cols - 0.5) * w
    vs = (0.5 - (np.arange(rows) + 0.5) / rows) * h
    vv, uu = np.meshgrid(vs, us, indexing="ij")
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def ipsf_bank(setup: Setup, *, kind: str = "radial", n_radii: int = 19,
              grid: tuple[int, int] = (9, 9), depths: ArrayLike = (500.0,),
              settings: TraceSettings | None = None,
              motion: MotionProfile | None = None, sweep: SweepRange | None = None,
              progress: Callable[[], object] | None = None,
              batched: bool = True, **deprecated: Any) -> IPSFBank:
    """A bank of IPSFs for a setup.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    kind : {"radial", "grid"}
        ``"radial"`` (untilted mirrors only): ``n_radii`` points on the +u half-axis from
        0 to :func:`field_radius`; ``"grid"``: centres of a (rows, cols) ``grid`` of cells
        over the sensor (points whose chief ray misses the mirror get a centred delta
        kernel and ``vignetted = 1``; ``metadata["valid"]`` marks them).
    depths : sequence of float
        Depths l, mm (inf allowed).
    settings : TraceSettings, optional
        As :func:`mitsweep.tracer.integrated_psf`; point ``j`` is traced with seed
        ``settings.seed + j`` (default ``TraceSettings()``).
    motion, sweep
        As :func:`mitsweep.tracer.integrated_psf`, resolved once by
        :func:`mitsweep.optics.reference.reference_geometry`, so the bank's
        ``reference_sensor_distance`` is the mid-travel of the motion it was traced for.
    progress : callable, optional
        Called with no argument after each IPSF (e.g. a tqdm ``update``); with
        ``batched``, once per IPSF's worth of rays traced.
    batched : bool
        Trace every IPSF of the bank together (default): each pilot round and each
        deposit launch serves all of them (:func:`mitsweep.tracer.ipsf.integrated_psfs`),
        instead of ~10-25 ms of fixed launch cost per IPSF. The kernels are those of
        ``batched=False`` (one :func:`mitsweep.tracer.integrated_psf` call per IPSF, same
        seeds) up to the float64 summation order of the deposit.
    **deprecated
        ``rays``, ``kernel_size``, ``seed``, ``method``, ``time_samples``, ``n_planes``:
        the fields of ``settings``, still accepted for one release (DeprecationWarning).

    Returns
    -------
    mitsweep.io.bank.IPSFBank
        With ``optics``: the setup's mirror, lens, sensor and sweep and the motion, the
        identity :func:`mitsweep.deconv.kernels.check_bank_identity` checks images by.
    """
    settings = settings_from_keywords(settings, deprecated, caller="ipsf_bank")
    if kind not in ("radial", "grid"):
        raise ValueError(f"kind: must be 'radial' or 'grid', got {kind!r}")
    depths = [check_depth(d) for d in np.atleast_1d(np.asarray(depths, dtype=float))]
    if not depths:
        raise ValueError("depths: give at least one depth")
    geometry = reference_geometry(setup, motion=motion, sweep=sweep)
    sweep, motion, ref = geometry.sweep, geometry.motion, geometry.sensor_distance
    radii = None
    grid_shape = None
    K, seed = settings.kernel_size, settings.seed
    n_points = float(n_radii) if kind == "radial" else float(grid[0]) * float(grid[1])
    # kernels (float32), per-point bookkeeping (3 float64 arrays, the grid's points) and
    # one IPSF being traced
    check_allocation(f"IPSF bank of {n_points:.0f} points x {len(depths)} depths, {K}x{K} px "
                     f"kernels", len(depths) * n_points * (K * K * 4 + 3 * 8 + 4 * 8)
                     + K * K * KERNEL_PIXEL_BYTES)
    if kind == "radial":
        if not setup.mirror.is_symmetric:
            raise ValueError(f"kind='radial' needs a rotationally symmetric setup; this mirror "
                             f"is tilted by {setup.mirror.tilt_deg:g} deg: use kind='grid'")
        if int(n_radii) < 1:
            raise ValueError(f"n_radii: must be >= 1, got {n_radii!r}")
        radii = np.linspace(0.0, field_radius(setup, geometry), int(n_radii))
        points = np.stack([radii, np.zeros_like(radii)], axis=1)
    else:
        grid_shape = (int(grid[0]), int(grid[1]))
        points = grid_points(setup, grid_shape)
    kernels = np.zeros((len(depths), len(points), K, K), np.float32)
    vign = np.zeros((len(depths), len(points)))
    outside = np.zeros((len(depths), len(points)))
    valid = np.ones(len(points), bool)
    t0 = time.perf_counter()
    common: dict[str, Any] = dict(motion=motion, sweep=sweep, reference_sensor_distance=ref)
    if batched:
        traced = integrated_psfs(setup, [(u, v, d) for d in depths for u, v in points],
                                 settings=settings,
                                 seeds=[seed + pi for _ in depths for pi in range(len(points))],
                                 progress=progress, **common)
    else:
        traced = None
    res: tuple[NDArray[np.float32], dict[str, Any]] | ValueError
    for di, depth in enumerate(depths):
        for pi, (u, v) in enumerate(points):
            if traced is None:
                try:
                    res = integrated_psf(setup, float(u), float(v), depth, **common,
                                         settings=replace(settings, seed=seed + pi))
                except ValueError as exc:
                    res = exc
                if progress is not None:
                    progress()
            else:
                res = traced[di * len(points) + pi]
            if isinstance(res, ValueError):
                if kind == "radial":
                    raise res
                logger.debug("grid point (%g, %g) skipped: %s", u, v, res)
                kernels[di, pi, K // 2, K // 2] = 1.0
                vign[di, pi] = 1.0
                valid[pi] = False
                continue
            k, info = res
            kernels[di, pi] = k
            vign[di, pi] = info["vignetted_fraction"]
            outside[di, pi] = info["outside_kernel_fraction"]
    setup_dict = setup_to_dict(setup)
    meta = {
        "setup": setup_dict, "sweep_range": sweep.as_dict(),
        "motion": motion.as_dict(), "method": settings.method,
        "time_samples": settings.time_samples if settings.method == "continuous" else None,
        "n_planes": settings.n_planes if settings.method == "planes" else None,
        "rays_per_ipsf": settings.rays, "seed": seed, "version": __version__,
        "generator": "mitsweep.tracer.ipsf_bank", "outside_kernel": outside.tolist(),
        "valid": valid.tolist(), "seconds": time.perf_counter() - t0,
    }
    return IPSFBank(kernels=kernels, points_uv=points, depths_mm=np.asarray(depths),
                    pixel_pitch=setup.sensor.pixel_pitch, reference_sensor_distance=ref,
                    kind=kind, radii_mm=radii, grid_shape=grid_shape, vignetted=vign,
                    metadata=meta, optics=optics_sections(setup_dict, motion.as_dict()))
