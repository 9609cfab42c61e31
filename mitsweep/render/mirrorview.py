"""The ``mirrorview`` integrator plugin: camera → delta reflections → emitter, nothing else.

.. list-table:: Plugin parameters
   :header-rows: 1

   * - name
     - type
     - meaning
   * - ``max_depth``
     - int
     - Longest path, in segments, as Mitsuba's ``path`` integrator counts them
       (1 ≤ max_depth ≤ :data:`~mitsweep.render.plugin_names.MIRRORVIEW_MAX_DEPTH`;
       default 2: camera → mirror → emitter).

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
(``mitsweep bench render``). :func:`~mitsweep.render.integrator.integrator_dict` picks it
only where it is exact:
emissive lighting and a finite depth. Lit scenes get ``mirrorpath``
(:mod:`mitsweep.render.mirrorpath`: ``path``'s estimator, differentiable through the
mirror) where a gradient can be asked (``differentiable``), else ``path``.

A plugin module bound to one Mitsuba variant (:data:`VARIANT`), registered at its end;
:func:`mitsweep.render.register` imports or reloads it (see
:mod:`mitsweep.render.focalsweep`).
"""

from __future__ import annotations

import logging

from typing import Any

import drjit as dr
import mitsuba as mi

from ..backend import set_mitsuba_variant
from .integrator_base import DepthLimitedIntegrator
from .plugin_names import MIRRORVIEW, MIRRORVIEW_MAX_DEPTH

__all__ = ["MirrorViewIntegrator", "VARIANT"]

logger = logging.getLogger(__name__)

#: The Mitsuba variant this module's class was built for.
VARIANT: str = mi.variant() or set_mitsuba_variant()


class MirrorViewIntegrator(DepthLimitedIntegrator):
    """Emission seen directly or through delta reflections (see the module).

    Parameters
    ----------
    props : mi.Properties
        The plugin's properties: ``max_depth`` (int, 1 to
        :data:`~mitsweep.render.plugin_names.MIRRORVIEW_MAX_DEPTH`, default 2).
    """

    NAME, MAX_DEPTH, DEFAULT_DEPTH = MIRRORVIEW, MIRRORVIEW_MAX_DEPTH, 2

    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f,
               medium: mi.Medium | None = None, active: Any = True
               ) -> tuple[mi.Spectrum, Any, list[Any]]:
        """Emission along the ray and its delta reflections.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        sampler : mi.Sampler
            The pixel's sampler: one 1-D and one 2-D sample per bounce, for the BSDF.
        ray : mi.Ray3f
            The camera ray (a ``RayDifferential3f``; its differentials are not used).
        medium : mi.Medium, optional
            Ignored (no participating media).
        active : mi.Bool, optional
            Lanes to compute (default: all).

        Returns
        -------
        spectrum : mi.Spectrum
            The radiance estimate.
        valid : mi.Bool
            Lanes whose camera ray hit a surface.
        aovs : list
            Empty: no AOVs.
        """
        ray = mi.Ray3f(ray)
        ctx = mi.BSDFContext()
        throughput = mi.Spectrum(1.0)
        result = mi.Spectrum(0.0)
        first_valid = None
        alive: Any = mi.Bool(active)
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
            bsdf = si.bsdf(ray)  # type: ignore[call-overload]  # a Ray3f converts implicitly
            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(alive),
                                     sampler.next_2d(alive), alive)
            alive &= mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta) & (dr.max(weight) > 0)
            throughput *= weight
            ray = si.spawn_ray(si.to_world(bs.wo))
        return result, first_valid, []


mi.register_integrator(MIRRORVIEW, lambda props: MirrorViewIntegrator(props))
logger.debug("registered %s for %s", MIRRORVIEW, VARIANT)
