"""IPSF banks over the field and depths (the deconvolution kernels, paper Sec. 5).

See :mod:`mitsweep.io.bank` for the on-disk contract (kernel orientation, centring,
radial vs grid). Radial banks (rotationally symmetric setups) hold points on the +u
half-axis from the centre out to the image of the FOV's mirror-zone edge; grid banks
(tilted setups) hold the centres of a (rows × cols) grid of cells over the sensor.

Banks to the rim (``extent="rim"``, issue 27): the mirror's image reaches beyond the
design FOV (29 % of the paraboloid's lies beyond), where the sweep does not reach focus
but the blur is still known. A radial bank then continues its points at their own
spacing out to the image of the mirror's rim (:func:`rim_field_radius`,
:func:`rim_radii`), traced with the same settings and the next seeds; a grid bank,
whose nodes already cover the sensor, gives each node whose chief ray misses the mirror
the kernel of the nearest traced node (:func:`fill_off_mirror_nodes`) instead of the
stand-in delta. :func:`extend_to_rim` extends a bank already traced (a dataset's).
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
from ..io.bank import IPSFBank, fill_off_mirror_nodes, optics_sections
from ..optics import SweepRange, chief_ray, image_point, placement_of
from ..optics.motion import MotionProfile
from ..optics.reference import ReferenceGeometry, reference_geometry
from ..resources import check_allocation
from .ipsf import KERNEL_PIXEL_BYTES, integrated_psf, integrated_psfs
from .settings import TraceSettings, settings_from_keywords
from .source import check_depth

__all__ = ["ipsf_bank", "field_radius", "grid_points", "EXTENTS", "rim_field_radius",
           "rim_radii", "fill_off_mirror_nodes", "extend_to_rim"]

logger = logging.getLogger(__name__)

#: Rays per IPSF in a bank: ~0.05 s each on 2 cores; L1 error ~1e-2 (docs/reference/tracer.md).
#: The default of :class:`~mitsweep.tracer.settings.TraceSettings` (``rays``).
BANK_RAYS = TraceSettings().rays
#: How far a bank's points reach: the design FOV's image (the default) or the mirror
#: rim's (``ipsf_bank(..., extent=...)``).
EXTENTS = ("fov", "rim")


def field_radius(setup: Setup, geometry: ReferenceGeometry | None = None) -> float:
    """Image radius (mm, at the reference distance) of the FOV's mirror-zone edge.

    Parameters
    ----------
    setup : Setup
        The camera, mirror and sweep.
    geometry : ReferenceGeometry, optional
        The setup's reference geometry (default: resolved from the setup).
    """
    geometry = reference_geometry(setup) if geometry is None else geometry
    pl = placement_of(setup.mirror)
    edge = chief_ray(pl, pl.surface(np.array([geometry.sweep.rho_end]), np.array([0.0])))
    u, v = image_point(edge, geometry.sensor_distance)
    return float(math.hypot(float(u[0]), float(v[0])))


def rim_field_radius(setup: Setup, geometry: ReferenceGeometry | None = None, *,
                     sensor_distance: float | None = None) -> float:
    """Image radius (mm) of the chief ray from the mirror's rim
    (``setup.mirror.rim_radius``) in the +u direction.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup whose mirror's rim is imaged.
    geometry : ReferenceGeometry, optional
        The setup's reference geometry (default: resolved from the setup); its sensor
        distance is the image plane's.
    sensor_distance : float, optional
        The image plane's sensor distance, mm, instead of ``geometry``'s.
    """
    if sensor_distance is None:
        geometry = reference_geometry(setup) if geometry is None else geometry
        sensor_distance = geometry.sensor_distance
    pl = placement_of(setup.mirror)
    edge = chief_ray(pl, pl.surface(np.array([float(setup.mirror.rim_radius)]),
                                    np.array([0.0])))
    u, v = image_point(edge, float(sensor_distance))
    return float(math.hypot(float(u[0]), float(v[0])))


def rim_radii(radii: ArrayLike, rim: float) -> NDArray[np.float64]:
    """The radii (mm) beyond the last of ``radii``, at their own spacing (the median
    step), the last one at ``rim`` (none if ``radii`` already reach it).

    Parameters
    ----------
    radii : array_like
        A radial bank's radii, mm.
    rim : float
        The radius to reach, mm (:func:`rim_field_radius`).
    """
    r = np.asarray(radii, dtype=np.float64)
    last = float(r.max())
    if rim <= last * (1 + 1e-9):
        return np.zeros(0)
    step = float(np.median(np.diff(np.sort(r)))) if len(r) > 1 else rim - last
    n = max(1, int(math.ceil((rim - last) / step - 1e-9)))
    return np.linspace(last, rim, n + 1)[1:]


def _rim_metadata(fov: float, new: NDArray[np.float64]) -> dict[str, Any]:
    """A radial rim bank's metadata: where the FOV ends (the error budget's
    ``beyond_fov`` region), where the rim is and how many points reach it."""
    meta: dict[str, Any] = {"extent": "rim", "fov_radius_mm": float(fov)}
    if len(new):
        meta.update(rim_radius_mm=float(new[-1]), rim_points=int(len(new)))
    return meta


def extend_to_rim(setup: Setup, bank: IPSFBank, *,
                  settings: TraceSettings | None = None) -> IPSFBank:
    """``bank`` (traced for ``setup``) extended to the mirror's rim: what
    ``ipsf_bank(..., extent="rim")`` would have traced, from a bank already traced.

    A radial bank gets points at its own spacing beyond its last radius out to the image
    of the mirror's rim (:func:`rim_radii`), traced at every depth of the bank with its
    kernel size and method and the seeds after its own (point ``j``: ``seed + j``, as
    :func:`ipsf_bank` seeds); a grid bank gets its off-mirror nodes filled
    (:func:`fill_off_mirror_nodes`). ``metadata["extent"]`` becomes ``"rim"``;
    ``metadata["fov_radius_mm"]`` keeps the radial bank's former last radius.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup the bank was traced for (its reference sensor distance must be the
        setup's: the same sweep and motion).
    bank : IPSFBank
        A radial or grid bank.
    settings : TraceSettings, optional
        The new points' trace settings (default: the bank's ``rays_per_ipsf``,
        ``method`` and ``seed`` from its metadata, its kernel size); radial banks only.

    Raises
    ------
    ValueError
        The bank was traced at another reference sensor distance; a new point's trace
        fails (fully vignetted).
    """
    meta = dict(bank.metadata or {})
    if bank.kind != "radial":
        filled = fill_off_mirror_nodes(bank)
        return replace(filled, metadata={**filled.metadata, "extent": "rim"})
    geometry = reference_geometry(setup)
    if not math.isclose(geometry.sensor_distance, bank.reference_sensor_distance,
                        rel_tol=1e-9, abs_tol=1e-9):
        raise ValueError("extend_to_rim: the bank was traced at another reference sensor "
                         "distance than the setup's (another sweep or motion)")
    radii0 = np.asarray(bank.radii, dtype=np.float64)
    fov = float(meta.get("fov_radius_mm", radii0.max()))
    new = rim_radii(radii0, rim_field_radius(setup, geometry))
    if not len(new):
        return replace(bank, metadata={**meta, **_rim_metadata(fov, new)})
    K = int(bank.kernels.shape[-1])
    if settings is None:
        settings = TraceSettings(rays=int(meta.get("rays_per_ipsf") or BANK_RAYS),
                                 kernel_size=K, method=str(meta.get("method", "exact")),
                                 seed=int(meta.get("seed", 0)))
    n0 = len(radii0)
    depths = [float(d) for d in bank.depths]
    traced = integrated_psfs(setup, [(float(r), 0.0, d) for d in depths for r in new],
                             settings=settings,
                             seeds=[settings.seed + n0 + i for _ in depths
                                    for i in range(len(new))],
                             sweep=geometry.sweep, motion=geometry.motion,
                             reference_sensor_distance=geometry.sensor_distance)
    extra = np.zeros((len(depths), len(new), K, K), np.float32)
    vign = np.zeros((len(depths), len(new)))
    for j, res in enumerate(traced):
        if isinstance(res, ValueError):
            raise res
        extra[j // len(new), j % len(new)] = res[0]
        vign[j // len(new), j % len(new)] = res[1]["vignetted_fraction"]
    radii = np.concatenate([radii0, new])
    vig0 = np.zeros((len(depths), n0)) if bank.vignetted is None else np.asarray(bank.vignetted)
    return replace(bank, kernels=np.concatenate([bank.kernels, extra], axis=1),
                   radii=radii, points_uv=np.stack([radii, np.zeros_like(radii)], axis=1),
                   vignetted=np.concatenate([vig0, vign], axis=1),
                   metadata={**meta, **_rim_metadata(fov, new)})


def grid_points(setup: Setup, grid: tuple[int, int]) -> NDArray[np.float64]:
    """(rows·cols, 2) upright (u, v) mm: cell centres of a grid over the sensor, row-major,
    rows top to bottom.

    Parameters
    ----------
    setup : Setup
        Its sensor's size spans the grid.
    grid : (int, int)
        ``(rows, cols)``, each at least 1.
    """
    rows, cols = (int(x) for x in grid)
    if rows < 1 or cols < 1:
        raise ValueError(f"grid: rows and cols must be >= 1, got {grid!r}")
    w, h = setup.sensor.size
    us = ((np.arange(cols) + 0.5) / cols - 0.5) * w
    vs = (0.5 - (np.arange(rows) + 0.5) / rows) * h
    vv, uu = np.meshgrid(vs, us, indexing="ij")
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def ipsf_bank(setup: Setup, *, kind: str = "radial", n_radii: int = 19,
              grid: tuple[int, int] = (9, 9), depths: ArrayLike = (500.0,),
              settings: TraceSettings | None = None,
              motion: MotionProfile | None = None, sweep: SweepRange | None = None,
              progress: Callable[[], object] | None = None,
              batched: bool = True, extent: str = "fov", **deprecated: Any) -> IPSFBank:
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
    extent : {"fov", "rim"}
        How far the points reach. ``"fov"`` (default): as above. ``"rim"``: a radial
        bank's ``n_radii`` points to :func:`field_radius` continue at the same spacing
        out to the image of the mirror's rim (:func:`rim_field_radius`,
        :func:`rim_radii`), traced with the same settings, point ``j`` with seed
        ``settings.seed + j`` (``metadata["fov_radius_mm"]``, ``"rim_radius_mm"`` and
        ``"rim_points"`` record where the FOV and the rim are); a grid bank's nodes off
        the mirror take the nearest traced node's kernel (:func:`fill_off_mirror_nodes`).
        ``metadata["extent"]`` records it, and the bank cache
        (:func:`mitsweep.tracer.cache.cached_bank`) keys by it.
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
    if extent not in EXTENTS:
        raise ValueError(f"extent: must be one of {', '.join(map(repr, EXTENTS))}, got "
                         f"{extent!r}")
    depths = [check_depth(d) for d in np.atleast_1d(np.asarray(depths, dtype=float))]
    if not depths:
        raise ValueError("depths: give at least one depth")
    geometry = reference_geometry(setup, motion=motion, sweep=sweep)
    sweep, motion, ref = geometry.sweep, geometry.motion, geometry.sensor_distance
    radii = None
    grid_shape = None
    K, seed = settings.kernel_size, settings.seed
    fov = rim_new = None
    if kind == "radial" and extent == "rim" and int(n_radii) >= 1 \
            and setup.mirror.is_symmetric:   # else refused below, as for "fov"
        fov = field_radius(setup, geometry)
        rim_new = rim_radii(np.linspace(0.0, fov, int(n_radii)),
                            rim_field_radius(setup, geometry))
    n_extra = 0 if rim_new is None else len(rim_new)
    n_points = float(n_radii) + n_extra if kind == "radial" else \
        float(grid[0]) * float(grid[1])
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
        if rim_new is not None:
            radii = np.concatenate([radii, rim_new])
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
    if extent != "fov":
        # "fov" banks keep the metadata they always had (an absent extent reads "fov")
        meta["extent"] = extent
        if fov is not None and rim_new is not None:
            meta.update(_rim_metadata(fov, rim_new))
    bank = IPSFBank(kernels=kernels, points_uv=points, depths=np.asarray(depths),
                    pixel_pitch=setup.sensor.pixel_pitch, reference_sensor_distance=ref,
                    kind=kind, radii=radii, grid_shape=grid_shape, vignetted=vign,
                    metadata=meta, optics=optics_sections(setup_dict, motion.as_dict()))
    return fill_off_mirror_nodes(bank) if extent == "rim" and kind == "grid" else bank
