"""Gradient renders that refuse, instead of returning, a derivative that would be zero.

:func:`differentiable_render` is :func:`mitsuba.render` with one check first: when the
rendered sensor is a ``focalsweep`` whose sweep has a gradient enabled, an integrator
that would lose that derivative raises :class:`NotDifferentiableError` naming it and the
fix. The check reads only public state (the scene, its integrator, the sensor's
:meth:`~mitsweep.render.focalsweep.FocalSweepSensor.differentiated_parameters`), before
rendering; ``mi.render`` called directly is not checked.

Refused (see :mod:`mitsweep.render.focalsweep`): the ``prb`` family and ``ptracer``
always (they detach the camera rays, or move the pixel a sample lands in);
``path``, ``volpath``, ``direct`` and ``direct_projective`` when a shape reflects or
transmits in a delta or null lobe, e.g. the mirror (their derivative through it is
exactly zero). mitsweep's ``mirrorview`` and ``mirrorpath`` pass.
"""

from __future__ import annotations

from typing import Any
from collections.abc import Iterable

from .sensor_motion import NotDifferentiableError

__all__ = ["differentiable_render", "refuse_integrators_that_drop_the_sweep"]

#: Integrators (by class name) whose derivative with respect to the camera is lost in any
#: scene: the ``prb`` family detaches the camera rays; light tracing moves the pixel a
#: sample lands in, which plain AD does not differentiate.
_DROP_ALWAYS = {"PRBIntegrator": "prb", "BasicPRBIntegrator": "prb_basic",
                "PRBProjectiveIntegrator": "prb_projective",
                "PRBVolpathIntegrator": "prbvolpath", "ParticleTracerIntegrator": "ptracer"}
#: Integrators that differentiate what the camera sees directly but detach the ray at a
#: BSDF sample (``path``, ``volpath``) or never follow one (``direct``): through a
#: delta-reflecting (or null) surface, a mirror, their derivative is exactly zero.
_DROP_AT_DELTA = {"PathIntegrator": "path", "VolumetricSimplePathIntegrator": "volpath",
                  "VolumetricPathIntegrator": "volpath",
                  "VolumetricMISPathIntegrator": "volpathmis", "DirectIntegrator": "direct",
                  "DirectProjectiveIntegrator": "direct_projective"}
_MITSUBA_BASES = ("Integrator", "SamplingIntegrator", "MonteCarloIntegrator",
                  "AdjointIntegrator")


def _integrator_class(integrator) -> str:
    """Class name of an integrator (a Python plugin's own, else the C++ one's)."""
    name = type(integrator).__name__
    return integrator.class_name() if name in _MITSUBA_BASES else name


def refuse_integrators_that_drop_the_sweep(
        integrator: Any, scene: Any,
        keys: Iterable[str] = ("sensor_start", "sensor_end")) -> None:
    """Raise :class:`NotDifferentiableError` where ``integrator`` would return a zero
    (or no) derivative of the sweep ``keys`` for ``scene`` (see the module: the ``prb``
    family and ``ptracer`` always; ``path``, ``volpath``, ``direct`` when a shape
    reflects or transmits in a delta or null lobe, e.g. the mirror).

    Parameters
    ----------
    integrator : mitsuba.Integrator
        The integrator that would render (a C++ plugin or a Python one).
    scene : mitsuba.Scene
        The scene: its shapes' BSDFs are read for delta or null lobes.
    keys : iterable of str, optional
        The sensor parameters whose gradient is asked, for the message (default the
        sweep's ends, ``sensor_start`` and ``sensor_end``).
    """
    import mitsuba as mi

    cls = _integrator_class(integrator)
    asked = ", ".join(keys)
    fix = ("render with mitsweep's 'mirrorpath' (lit scenes) or 'mirrorview' (emissive "
           "scenes, faster), which keep the camera rays attached through the mirror")
    if cls in _DROP_ALWAYS:
        raise NotDifferentiableError(
            f"focalsweep: a gradient of {asked} was asked, but the {_DROP_ALWAYS[cls]!r} "
            f"integrator does not differentiate the camera's rays; {fix}")
    if cls in _DROP_AT_DELTA:
        delta = [sh.id() or f"shape {k}" for k, sh in enumerate(scene.shapes())
                 if sh.bsdf() is not None
                 and mi.has_flag(sh.bsdf().flags(), mi.BSDFFlags.Delta)]
        if delta:
            raise NotDifferentiableError(
                f"focalsweep: a gradient of {asked} was asked, but the "
                f"{_DROP_AT_DELTA[cls]!r} integrator does not differentiate through delta "
                f"reflections: through {delta[0]!r} its derivative would be exactly zero; "
                f"{fix}")


def differentiable_render(scene: Any, params: Any = None, sensor: Any = 0,
                          integrator: Any = None, **kwargs: Any) -> Any:
    """:func:`mitsuba.render` (same arguments: ``seed``, ``seed_grad``, ``spp``,
    ``spp_grad``), after refusing an integrator that would drop the gradient asked of a
    ``focalsweep`` sensor's sweep (:func:`refuse_integrators_that_drop_the_sweep`).

    Parameters
    ----------
    scene : mitsuba.Scene
        The scene, with a ``focalsweep`` sensor.
    params : mitsuba.SceneParameters, optional
        The scene's parameters (``mi.traverse(scene)``) whose gradients are asked.
    sensor : int or mitsuba.Sensor, optional
        The sensor to render.
    integrator : mitsuba.Integrator, optional
        Default: the scene's.
    **kwargs
        Passed to :func:`mitsuba.render` (``seed``, ``seed_grad``, ``spp``, ``spp_grad``).
    """
    import mitsuba as mi

    camera = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
    asked = getattr(camera, "differentiated_parameters", lambda: ())()
    if asked:
        refuse_integrators_that_drop_the_sweep(integrator or scene.integrator(), scene, asked)
    return mi.render(scene, params, sensor=sensor, integrator=integrator, **kwargs)
