"""Which integrator renders a scene: ``mirrorview``, ``mirrorpath`` or ``path``.

The plugins are :class:`mitsweep.render.mirrorview.MirrorViewIntegrator` (emissive
scenes: camera → delta reflections → emitter, bit for bit ``path``'s image at a quarter
of its cost) and :class:`mitsweep.render.mirrorpath.MirrorPathIntegrator` (lit scenes:
``path``'s estimator, differentiable through the mirror); this variant-free module
picks one (:func:`integrator_dict`) and registers them (:func:`register_integrator`).
"""

from __future__ import annotations

from .plugin_names import MIRRORPATH, MIRRORPATH_MAX_DEPTH, MIRRORVIEW, MIRRORVIEW_MAX_DEPTH
from .registry import register

__all__ = ["INTEGRATOR_NAME", "MAX_DEPTH", "integrator_dict", "register_integrator"]

#: The emissive scenes' integrator.
INTEGRATOR_NAME = MIRRORVIEW
#: Deepest path ``mirrorview`` unrolls (delta bounces are unrolled at trace time).
MAX_DEPTH = MIRRORVIEW_MAX_DEPTH


def integrator_dict(lighting: str, max_depth: int, *, differentiable: bool = False) -> dict:
    """The integrator of a scene: ``mirrorview`` where it is exact, else ``mirrorpath``
    (``differentiable``) or ``path``.

    ``mirrorview`` needs ``lighting == "emissive"`` (every non-mirror BSDF black) and
    ``1 <= max_depth <= MAX_DEPTH``. Otherwise, with ``differentiable`` (an ``*_ad_*``
    variant) and ``1 <= max_depth <= MIRRORPATH_MAX_DEPTH``: ``mirrorpath``, whose
    image is ``path``'s and whose derivative passes through the mirror (``path``'s is
    zero there). ``path`` (``hide_emitters`` off) takes the rest, e.g. an unlimited
    depth (-1): a sweep gradient asked of it through a mirror raises
    :class:`~mitsweep.render.sensor.NotDifferentiableError` in
    :func:`~mitsweep.render.differentiable_render`.

    Parameters
    ----------
    lighting : {"emissive", "lit"}
        The scene's lighting (:attr:`mitsweep.config.Scene.lighting`).
    max_depth : int
        Longest path in segments, as ``path`` counts them (-1: unlimited).
    differentiable : bool, optional
        Whether a gradient may be asked (an ``*_ad_*`` variant; default False).
    """
    if lighting == "emissive" and 1 <= max_depth <= MAX_DEPTH:
        return {"type": INTEGRATOR_NAME, "max_depth": int(max_depth)}
    if differentiable and 1 <= max_depth <= MIRRORPATH_MAX_DEPTH:
        return {"type": MIRRORPATH, "max_depth": int(max_depth)}
    return {"type": "path", "max_depth": int(max_depth), "hide_emitters": False}


def register_integrator() -> None:
    """Register mitsweep's plugins for the current Mitsuba variant (idempotent; a
    variant must be set): :func:`mitsweep.render.register`."""
    import mitsuba as mi

    if mi.variant() is None:
        raise RuntimeError(f"{INTEGRATOR_NAME}: select a Mitsuba variant first")
    register()
