"""The ``mirrorview`` integrator: camera → delta reflections → emitter, nothing else.

.. list-table:: Plugin parameters
   :header-rows: 1

   * - name
     - type
     - meaning
   * - ``max_depth``
     - int
     - Longest path, in segments, as Mitsuba's ``path`` integrator counts them
       (1 ≤ max_depth ≤ :data:`MAX_DEPTH`; default 2: camera → mirror → emitter).

In the ``emissive`` surroundings (:mod:`mitsweep.render.scene`) every surface but the
mirror is a textured area emitter with a black diffuse BSDF, so the only light paths
are: camera → emitter, and camera → one or more delta (mirror) reflections → emitter.
This integrator follows exactly those: at each hit it adds the surface's emission and
continues only through a delta reflection, whose sample consumes no random numbers.

Mitsuba's ``path`` integrator on such a scene computes the same estimate (emitter
sampling at the black surfaces adds zero; at the mirror it is skipped, and the MIS
weight of a delta-sampled hit is 1), but evaluates emitter sampling, shadow rays and
MIS for every lane of its recorded loop. With the same sampler and seed the images are
bit for bit identical (``tests/test_render_integrator.py``) and about 4× cheaper
(``mitsweep bench render``). :func:`integrator_dict` picks it only where it is exact:
emissive lighting and a finite depth. Lit scenes get ``mirrorpath``
(:mod:`mitsweep.render.ad_integrator`: ``path``'s estimator, differentiable through the
mirror) where a gradient can be asked (``differentiable``), else ``path``.
"""

from __future__ import annotations

import logging
from typing import Callable

__all__ = ["INTEGRATOR_NAME", "MAX_DEPTH", "integrator_dict", "register_integrator"]

logger = logging.getLogger(__name__)

INTEGRATOR_NAME = "mirrorview"
#: Deepest path the integrator unrolls (delta bounces are unrolled at trace time).
MAX_DEPTH = 8

_registered_for: set[str] = set()


def integrator_dict(lighting: str, max_depth: int, *, differentiable: bool = False) -> dict:
    """The integrator of a scene: ``mirrorview`` where it is exact, else ``mirrorpath``
    (``differentiable``) or ``path``.

    ``mirrorview`` needs ``lighting == "emissive"`` (every non-mirror BSDF black) and
    ``1 <= max_depth <= MAX_DEPTH``. Otherwise, with ``differentiable`` (an ``*_ad_*``
    variant) and ``1 <= max_depth <= ad_integrator.MAX_DEPTH``: ``mirrorpath``, whose
    image is ``path``'s and whose derivative passes through the mirror (``path``'s is
    zero there). ``path`` (``hide_emitters`` off) takes the rest, e.g. an unlimited
    depth (-1): a sweep gradient asked of it through a mirror raises
    :class:`~mitsweep.render.sensor.NotDifferentiableError`.
    """
    from .ad_integrator import INTEGRATOR_NAME as LIT_NAME, MAX_DEPTH as LIT_MAX_DEPTH

    if lighting == "emissive" and 1 <= max_depth <= MAX_DEPTH:
        return {"type": INTEGRATOR_NAME, "max_depth": int(max_depth)}
    if differentiable and 1 <= max_depth <= LIT_MAX_DEPTH:
        return {"type": LIT_NAME, "max_depth": int(max_depth)}
    return {"type": "path", "max_depth": int(max_depth), "hide_emitters": False}


def _make_class():
    import drjit as dr
    import mitsuba as mi

    class MirrorViewIntegrator(depth_limited_integrator(INTEGRATOR_NAME, MAX_DEPTH, 2)):
        """Emission seen directly or through delta reflections (see the module)."""

        def sample(self, scene, sampler, ray, medium=None, active=True):
            ray = mi.Ray3f(ray)
            ctx = mi.BSDFContext()
            throughput = mi.Spectrum(1.0)
            result = mi.Spectrum(0.0)
            first_valid = None
            alive = mi.Bool(active)
            # Python loop: unrolled at trace time (max_depth is a small constant).
            for depth in range(self.max_depth):
                si = scene.ray_intersect(ray, alive)
                alive &= si.is_valid()
                if first_valid is None:
                    first_valid = mi.Bool(alive)
                emitter = si.emitter(scene, alive)
                result += dr.select(alive, throughput * emitter.eval(si, alive), 0.0)
                if depth + 1 == self.max_depth:
                    break
                bsdf = si.bsdf(ray)
                bs, weight = bsdf.sample(ctx, si, sampler.next_1d(alive),
                                         sampler.next_2d(alive), alive)
                alive &= mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta) & (dr.max(weight) > 0)
                throughput *= weight
                ray = si.spawn_ray(si.to_world(bs.wo))
            return result, first_valid, []

    return MirrorViewIntegrator


def register_integrator() -> None:
    """Register ``mirrorview`` for the current Mitsuba variant (idempotent)."""
    register_python_integrator(INTEGRATOR_NAME, _make_class, _registered_for)


def depth_limited_integrator(name: str, max_depth: int, default_depth: int) -> type:
    """The base of mitsweep's Python integrators in the current Mitsuba variant: a
    ``mi.SamplingIntegrator`` that reads the plugin parameter ``max_depth`` (default
    ``default_depth``) and refuses one outside ``1..max_depth`` with a ValueError naming
    plugin ``name``; no AOVs; printed as ``ClassName[max_depth=N]``. A subclass defines
    ``sample``."""
    import mitsuba as mi

    class DepthLimitedIntegrator(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            depth = int(props.get("max_depth", default_depth))
            if not 1 <= depth <= max_depth:
                raise ValueError(f"{name}: max_depth must be in 1..{max_depth}, got {depth}")
            self.max_depth = depth

        def aov_names(self):
            return []

        def to_string(self):
            return f"{type(self).__name__}[max_depth={self.max_depth}]"

    return DepthLimitedIntegrator


def register_python_integrator(name: str, make_class: Callable[[], type],
                               registered_for: set[str]) -> None:
    """Register the integrator class ``make_class()`` builds as plugin ``name`` for the
    current Mitsuba variant, once per variant (``registered_for`` records them)."""
    import mitsuba as mi

    variant = mi.variant()
    if variant is None:
        raise RuntimeError(f"{name}: select a Mitsuba variant first")
    if variant not in registered_for:
        cls = make_class()
        mi.register_integrator(name, lambda props: cls(props))
        registered_for.add(variant)
        logger.debug("registered %s for %s", name, variant)
