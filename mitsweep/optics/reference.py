"""The reference geometry: the one answer to "which sensor distance is the pixel grid's".

Every image mitsweep makes of a setup (the four render modes, the tracer's IPSFs, the
kernel banks, the deconvolved EDOF images, the ground truth) is expressed on one pixel
grid: the pinhole camera's at the *reference sensor distance* ``i_ref``, with the
setup's pixel pitch (see :mod:`mitsweep.optics.pixels`). ``i_ref`` is mid-travel of the
sensor motion that is actually run, ``(min i(t) + max i(t)) / 2``: for the default
motion over the optimal sweep range that is the range's midpoint; for a measured
(tabulated) motion whose span differs from the optimal range it is the measured span's
midpoint, so renders and banks made for that motion still share one grid.

Render, tracer, banks, the dataset pipeline and capture records all resolve it here,
through :func:`reference_geometry`.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..config import Setup
from .motion import MotionProfile, motion_for
from .sweep import SweepRange, optimal_sweep_range

__all__ = ["ReferenceGeometry", "reference_geometry"]


@dataclass(frozen=True)
class ReferenceGeometry:
    """The sweep, the motion run over it, and the reference sensor distance.

    Attributes
    ----------
    sweep : SweepRange
        The setup's sweep range (optimal, Eq. 8–9, unless the setup fixes the focus
        range or one was given).
    motion : MotionProfile
        The sensor motion during the exposure (from the setup's profile over ``sweep``
        unless one was given, e.g. a measured rig log).
    sensor_distance : float
        Reference sensor distance ``i_ref``, mm: mid-travel of ``motion``.
    """

    sweep: SweepRange
    motion: MotionProfile
    sensor_distance: float

    def as_dict(self) -> dict:
        return {"reference_sensor_distance_mm": self.sensor_distance,
                "sweep": self.sweep.as_dict(), "motion": self.motion.as_dict()}


def reference_geometry(setup: Setup, *, motion: MotionProfile | None = None,
                       sweep: SweepRange | None = None) -> ReferenceGeometry:
    """Resolve the sweep, the motion and the reference sensor distance of a setup.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    motion : MotionProfile, optional
        The motion run (default: :func:`~mitsweep.optics.motion.motion_for` the setup
        over ``sweep``). A given motion sets the reference distance, whatever ``sweep``.
    sweep : SweepRange, optional
        Default: :func:`~mitsweep.optics.optimal_sweep_range` of the setup.

    Returns
    -------
    ReferenceGeometry
    """
    if motion is not None and not isinstance(motion, MotionProfile):
        raise TypeError(f"motion: expected a MotionProfile (linear, trapezoidal or "
                        f"tabulated), got {type(motion).__name__}")
    if sweep is not None and not isinstance(sweep, SweepRange):
        raise TypeError(f"sweep: expected a SweepRange, got {type(sweep).__name__}")
    if sweep is None:
        sweep = optimal_sweep_range(setup)
    if motion is None:
        motion = motion_for(setup, sweep)
    return ReferenceGeometry(sweep=sweep, motion=motion, sensor_distance=float(motion.midpoint))
