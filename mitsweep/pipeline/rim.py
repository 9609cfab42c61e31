"""Radial banks traced to the mirror's rim, beyond the design FOV (issue 27, item 3).

:func:`mitsweep.tracer.ipsf_bank` places a radial bank's points from the axis to the
image of the FOV's mirror-zone edge (:func:`mitsweep.tracer.bank.field_radius`); on the
paraboloid 29 % of the mirror's image lies beyond, where
:func:`~mitsweep.deconv.polar.polar_deconvolve` extrapolates the last kernel (and
leaves pixels a kernel beyond it unrestored). The sweep does not reach focus there,
but the blur is still known: the tracer traces it like any other point.
:func:`rim_bank` extends a traced radial bank with points at the same spacing out to
the image of the mirror's rim, traced with the bank's own settings and seeds that
continue its own. It records the FOV's edge (``metadata["fov_radius_mm"]``), which
the error budget's ``beyond_fov`` region keeps.

The radii belong in the tracer's bank builder (``ipsf_bank(..., extent="rim")``); this
extends a bank already traced, so that datasets and the budget can use one now.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..config import Setup
from ..io.bank import IPSFBank

__all__ = ["rim_image_radius", "rim_radii", "rim_bank"]


def rim_image_radius(setup: Setup, sensor_distance: float) -> float:
    """Image radius (mm, at ``sensor_distance``) of the chief ray from the mirror's rim
    (``setup.mirror.rim_radius``) in the +u direction."""
    from ..optics import chief_ray, image_point, placement_of

    pl = placement_of(setup.mirror)
    edge = chief_ray(pl, pl.surface(np.array([float(setup.mirror.rim_radius)]),
                                    np.array([0.0])))
    u, v = image_point(edge, sensor_distance)
    return float(math.hypot(float(u[0]), float(v[0])))


def rim_radii(bank: IPSFBank, rim_mm: float) -> np.ndarray:
    """The radii (mm) beyond ``bank``'s last one, at its own spacing, the last one at
    ``rim_mm`` (none if the bank already reaches it)."""
    r = np.asarray(bank.radii_mm, dtype=np.float64)
    last = float(r.max())
    if rim_mm <= last * (1 + 1e-9):
        return np.zeros(0)
    step = float(np.median(np.diff(np.sort(r)))) if len(r) > 1 else rim_mm - last
    n = max(1, int(math.ceil((rim_mm - last) / step - 1e-9)))
    return np.linspace(last, rim_mm, n + 1)[1:]


def rim_bank(setup: Setup, bank: IPSFBank, *, rays: int | None = None) -> IPSFBank:
    """``bank`` (radial, traced for ``setup``) with points out to the mirror's rim.

    The new points are traced with :func:`mitsweep.tracer.ipsf.integrated_psfs` at
    every depth of the bank, with its kernel size and method, ``rays`` per IPSF
    (default the bank's ``rays_per_ipsf``) and seeds after the bank's. A point whose
    trace fails (fully vignetted) raises, as in a radial bank.
    """
    from ..optics.reference import reference_geometry
    from ..tracer.ipsf import integrated_psfs
    from ..tracer.settings import TraceSettings

    if bank.kind != "radial":
        raise ValueError(f"rim_bank extends radial banks; got a {bank.kind!r} bank")
    meta = dict(bank.metadata or {})
    geometry = reference_geometry(setup)
    if not math.isclose(geometry.sensor_distance, bank.reference_sensor_distance,
                        rel_tol=1e-9, abs_tol=1e-9):
        raise ValueError("rim_bank: the bank was traced at another reference sensor "
                         "distance than the setup's (another sweep or motion)")
    new = rim_radii(bank, rim_image_radius(setup, geometry.sensor_distance))
    fov = float(np.max(bank.radii_mm))
    if not len(new):
        return replace(bank, metadata={**meta, "fov_radius_mm": fov})
    K = int(bank.kernels.shape[-1])
    settings = TraceSettings(rays=int(rays or meta.get("rays_per_ipsf") or TraceSettings().rays),
                             kernel_size=K, method=str(meta.get("method", "exact")),
                             seed=int(meta.get("seed", 0)))
    n0 = len(bank.radii_mm)
    depths = [float(d) for d in bank.depths_mm]
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
    radii = np.concatenate([np.asarray(bank.radii_mm, float), new])
    vig0 = np.zeros((len(depths), n0)) if bank.vignetted is None else np.asarray(bank.vignetted)
    return replace(bank, kernels=np.concatenate([bank.kernels, extra], axis=1),
                   radii_mm=radii, points_uv=np.stack([radii, np.zeros_like(radii)], axis=1),
                   vignetted=np.concatenate([vig0, vign], axis=1),
                   metadata={**meta, "fov_radius_mm": fov, "rim_radius_mm": float(new[-1]),
                             "rim_points": len(new)})
