"""The ``mirrorpath`` integrator's name, depth limit and registration (no Mitsuba).

The plugin is :class:`mitsweep.render.mirrorpath.MirrorPathIntegrator`: Mitsuba's
``path`` estimator step for step, differentiable through the mirror.
"""

from __future__ import annotations

from .plugin_names import MIRRORPATH, MIRRORPATH_MAX_DEPTH
from .registry import register

__all__ = ["INTEGRATOR_NAME", "MAX_DEPTH", "register_integrator"]

INTEGRATOR_NAME = MIRRORPATH
#: Deepest path the integrator unrolls (each segment adds an emitter sample to the kernel).
MAX_DEPTH = MIRRORPATH_MAX_DEPTH


def register_integrator() -> None:
    """Register mitsweep's plugins for the current Mitsuba variant (idempotent; a
    variant must be set): :func:`mitsweep.render.register`."""
    import mitsuba as mi

    if mi.variant() is None:
        raise RuntimeError(f"{INTEGRATOR_NAME}: select a Mitsuba variant first")
    register()
