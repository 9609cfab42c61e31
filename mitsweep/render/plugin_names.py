"""Names and depth limits of mitsweep's Mitsuba plugins (no Mitsuba).

Shared by the plugin modules (:mod:`~mitsweep.render.focalsweep`,
:mod:`~mitsweep.render.mirrorview`, :mod:`~mitsweep.render.mirrorpath`) and the
variant-free modules that build scenes with them.
"""

from __future__ import annotations

__all__ = ["FOCALSWEEP", "MIRRORVIEW", "MIRRORVIEW_MAX_DEPTH", "MIRRORPATH",
           "MIRRORPATH_MAX_DEPTH"]

#: The moving-sensor thin-lens camera (:class:`mitsweep.render.focalsweep.FocalSweepSensor`).
FOCALSWEEP = "focalsweep"
#: Camera → delta reflections → emitter (:mod:`mitsweep.render.mirrorview`).
MIRRORVIEW = "mirrorview"
#: Deepest path ``mirrorview`` unrolls (delta bounces are unrolled at trace time).
MIRRORVIEW_MAX_DEPTH = 8
#: Path tracing differentiable through the mirror (:mod:`mitsweep.render.mirrorpath`).
MIRRORPATH = "mirrorpath"
#: Deepest path ``mirrorpath`` unrolls (each segment adds an emitter sample to the kernel).
MIRRORPATH_MAX_DEPTH = 8
