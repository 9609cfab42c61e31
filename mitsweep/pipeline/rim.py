"""Radial banks traced to the mirror's rim, beyond the design FOV (issue 27, item 3).

:func:`mitsweep.tracer.ipsf_bank` places a radial bank's points from the axis to the
image of the FOV's mirror-zone edge (:func:`mitsweep.tracer.bank.field_radius`); on the
paraboloid 29 % of the mirror's image lies beyond, where
:func:`~mitsweep.deconv.polar.polar_deconvolve` extrapolates the last kernel (and
leaves pixels a kernel beyond it unrestored). The sweep does not reach focus there,
but the blur is still known: the tracer traces it like any other point.

The tracer builds such banks (``ipsf_bank(..., extent="rim")``) and extends one already
traced (:func:`mitsweep.tracer.bank.extend_to_rim`); this module keeps the names the
datasets' studies and the budget used first: :func:`rim_bank` extends a traced radial
bank (a dataset's) with points at the same spacing out to the image of the mirror's rim,
traced with the bank's own settings and seeds that continue its own. It records the
FOV's edge (``metadata["fov_radius_mm"]``), which the error budget's ``beyond_fov``
region keeps.
"""

from __future__ import annotations

import numpy as np

from ..config import Setup
from ..deprecation import renamed_keywords
from ..io.bank import IPSFBank

__all__ = ["rim_image_radius", "rim_radii", "rim_bank"]


def rim_image_radius(setup: Setup, sensor_distance: float) -> float:
    """Image radius (mm, at ``sensor_distance``) of the chief ray from the mirror's rim
    (``setup.mirror.rim_radius``) in the +u direction
    (:func:`mitsweep.tracer.bank.rim_field_radius`).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup whose mirror's rim is imaged.
    sensor_distance : float
        The image plane's sensor distance, mm.
    """
    from ..tracer.bank import rim_field_radius

    return rim_field_radius(setup, sensor_distance=sensor_distance)


@renamed_keywords(rim_mm="rim")
def rim_radii(bank: IPSFBank, rim: float) -> np.ndarray:
    """The radii (mm) beyond ``bank``'s last one, at its own spacing, the last one at
    ``rim`` (none if the bank already reaches it;
    :func:`mitsweep.tracer.bank.rim_radii`).

    Parameters
    ----------
    bank : IPSFBank
        A radial bank.
    rim : float
        The radius to reach, mm (:func:`rim_image_radius`). Formerly ``rim_mm`` (still
        accepted, with a DeprecationWarning).
    """
    from ..tracer.bank import rim_radii as radii_to

    return radii_to(np.asarray(bank.radii, dtype=np.float64), rim)


def rim_bank(setup: Setup, bank: IPSFBank, *, rays: int | None = None) -> IPSFBank:
    """``bank`` (radial, traced for ``setup``) with points out to the mirror's rim
    (:func:`mitsweep.tracer.bank.extend_to_rim`).

    The new points are traced with :func:`mitsweep.tracer.ipsf.integrated_psfs` at
    every depth of the bank, with its kernel size and method, ``rays`` per IPSF
    (default the bank's ``rays_per_ipsf``) and seeds after the bank's. A point whose
    trace fails (fully vignetted) raises, as in a radial bank.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup the bank was traced for (the same reference sensor distance).
    bank : IPSFBank
        A radial bank.
    rays : int, optional
        Rays per new IPSF (default the bank's ``rays_per_ipsf``).

    Raises
    ------
    ValueError
        A grid bank (:func:`mitsweep.tracer.bank.fill_off_mirror_nodes` is theirs), a
        bank traced at another reference sensor distance, a failed trace.
    """
    from ..tracer.bank import extend_to_rim
    from ..tracer.settings import TraceSettings

    if bank.kind != "radial":
        raise ValueError(f"rim_bank extends radial banks; got a {bank.kind!r} bank")
    meta = bank.metadata or {}
    settings = None
    if rays is not None:
        settings = TraceSettings(rays=int(rays), kernel_size=int(bank.kernels.shape[-1]),
                                 method=str(meta.get("method", "exact")),
                                 seed=int(meta.get("seed", 0)))
    return extend_to_rim(setup, bank, settings=settings)
