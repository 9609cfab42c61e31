"""The ``focalsweep`` sensor, seen from variant-free code (no Mitsuba at import).

The plugin itself — its parameters, ray generation and derivatives — is
:class:`mitsweep.render.focalsweep.FocalSweepSensor`, a class at module scope bound to
the Mitsuba variant set when :func:`register` imports it. This module gathers what code
that builds scenes needs before a variant is set: :func:`register`, the plugin's name,
:func:`motion_table` and :class:`NotDifferentiableError` (raised for a gradient that
would be lost; :func:`mitsweep.render.differentiable_render` checks the integrator).
"""

from __future__ import annotations

from .gradient import refuse_integrators_that_drop_the_sweep
from .registry import register
from .sensor_motion import (MOTION_TABLE_SIZE, PLUGIN_NAME, NotDifferentiableError,
                            motion_table)

__all__ = ["register", "motion_table", "NotDifferentiableError", "PLUGIN_NAME",
           "MOTION_TABLE_SIZE", "refuse_integrators_that_drop_the_sweep"]
