"""The ``mirrorpath`` integrator plugin: a path tracer whose derivative passes through the mirror.

.. list-table:: Plugin parameters
   :header-rows: 1

   * - name
     - type
     - meaning
   * - ``max_depth``
     - int
     - Longest path, in segments, as Mitsuba's ``path`` integrator counts them
       (1 ≤ max_depth ≤ :data:`~mitsweep.render.plugin_names.MIRRORPATH_MAX_DEPTH`;
       default 3: camera → mirror → surface → light).

The estimator is Mitsuba's ``path`` (``src/integrators/path.cpp``) step for step: at
every vertex the emission seen (MIS-weighted against emitter sampling at the previous
vertex, power heuristic), emitter sampling with a shadow ray at vertices whose BSDF has
a smooth component, BSDF sampling to continue; delta (mirror) bounces are followed and
add no emitter sample. Area lights, environment maps (``envmap``, ``constant``) and
point-like lights (``point``, ``spot``: through emitter sampling) are handled as there.
The loop is unrolled in Python (``max_depth`` is a small constant), so the random
numbers are drawn in the same order and with the same masks as ``path``: for
``max_depth`` ≤ 5 (``path``'s default ``rr_depth``, below which it plays no Russian
roulette) both give the same image with the same seed, to float rounding
(``tests/test_render_lit_grad.py``). Russian roulette is off; media are ignored, as by
``path`` (use ``volpath``).

Differentiation
---------------
``path`` detaches the ray after every BSDF sample and the mirror's reflection with it,
so its derivative with respect to the camera (the ``focalsweep`` sweep) is exactly zero
through a mirror. Here nothing is detached: the camera ray, the mirror hit (attached
``ray_intersect``), the reflected direction, the hit points and their texture lookups,
the BSDF values and sampled directions, the emitter samples (directions, distances,
solid-angle pdfs) and the MIS weights all stay on the AD graph. Plain AD of the render
(Mitsuba's default ``render_forward``/``render_backward`` of a sampling integrator, as
``mi.render(scene, params, ...)`` calls them) then differentiates each sample's
estimate at fixed random numbers, the quantity a central finite difference with common
random numbers measures; its expectation is the derivative of the image's continuous
part. Left out, as by plain AD anywhere: the boundary terms of visibility
discontinuities (a silhouette, a shadow edge or an area light's edge that moves
relative to the samples as the camera changes). As any plain-AD render, the gradient
pass keeps the whole render's graph in memory: size gradient renders for it.

Cost: the primal render is ``path``'s (measured side by side at 128 px, 64 spp, on
2 loaded cores: 0.85× on the lit room, 0.96× on a procedural scene of depth 4), so
:func:`mitsweep.render.scene.build_scene` uses it for every lit scene in ``*_ad_*``
variants.

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
from .plugin_names import MIRRORPATH, MIRRORPATH_MAX_DEPTH

__all__ = ["MirrorPathIntegrator", "VARIANT"]

logger = logging.getLogger(__name__)

#: The Mitsuba variant this module's class was built for.
VARIANT: str = mi.variant() or set_mitsuba_variant()


def mis_weight(pdf_a, pdf_b):
    """Power heuristic, as ``path``'s (but attached: see the module).

    Parameters
    ----------
    pdf_a : mi.Float
        Density of the strategy that drew the sample (solid angle).
    pdf_b : mi.Float
        Density of the other strategy for the same direction.

    Returns
    -------
    mi.Float
        ``pdf_a² / (pdf_a² + pdf_b²)``; 0 where that is 0/0 or not finite.
    """
    a, b = dr.square(pdf_a), dr.square(pdf_b)
    s = a + b
    # A safe denominator: where a + b is 0 the unselected 0/0 would turn the
    # backward pass's 0 adjoint into NaN.
    w = a / dr.select(s > 0.0, s, 1.0)
    return dr.select((s > 0.0) & dr.isfinite(w), w, 0.0)


#: ``path``'s surface-interaction detail (named ``Default`` from Mitsuba 3.10 on).
_SI_FLAGS = getattr(mi.RayFlags, "Default", mi.RayFlags.All)


class MirrorPathIntegrator(DepthLimitedIntegrator):
    """Path tracing with NEE and MIS, differentiable through delta reflections.

    Parameters
    ----------
    props : mi.Properties
        The plugin's properties: ``max_depth`` (int, 1 to
        :data:`~mitsweep.render.plugin_names.MIRRORPATH_MAX_DEPTH`, default 3).
    """

    NAME, MAX_DEPTH, DEFAULT_DEPTH = MIRRORPATH, MIRRORPATH_MAX_DEPTH, 3

    def sample(self, scene: mi.Scene, sampler: mi.Sampler, ray: mi.Ray3f,
               medium: mi.Medium | None = None, active: Any = True
               ) -> tuple[mi.Spectrum, Any, list[Any]]:
        """``path``'s estimate along the ray, attached through delta reflections.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        sampler : mi.Sampler
            The pixel's sampler: per bounce, as ``path`` draws them (emitter, BSDF and Russian roulette).
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
            Lanes whose path met a surface or the environment, as ``path``'s.
        aovs : list
            Empty: no AOVs.
        """
        ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray)
        alive: Any = mi.Bool(active)
        throughput = mi.Spectrum(1.0)
        result = mi.Spectrum(0.0)
        valid_ray = mi.Bool(scene.environment() is not None)
        prev_si = dr.zeros(mi.Interaction3f)
        prev_bsdf_pdf = mi.Float(1.0)
        prev_bsdf_delta = mi.Bool(True)
        # (the stubs type ``coherent`` as a Dr.Jit Bool; Mitsuba takes a Python bool)
        pi = scene.ray_intersect_preliminary(  # type: ignore[call-overload]
            ray, coherent=True, active=alive)
        # Python loop: unrolled at trace time, so plain AD records every step
        # (Dr.Jit's symbolic loops drop the derivative).
        for depth in range(self.max_depth):
            si = pi.compute_surface_interaction(ray, _SI_FLAGS, alive)

            # -- emission seen, MIS-weighted against the previous vertex's NEE --
            ds = mi.DirectionSample3f(scene, si, prev_si)
            em_pdf = scene.pdf_emitter_direction(prev_si, ds, alive & ~prev_bsdf_delta)
            em_pdf = dr.select(prev_bsdf_delta, 0.0, em_pdf)
            mis_bsdf = mis_weight(prev_bsdf_pdf, em_pdf)
            le = ds.emitter.eval(si, alive & (prev_bsdf_pdf > 0.0))
            result = dr.select(alive, dr.fma(throughput, le * mis_bsdf, result), result)

            last = depth + 1 == self.max_depth
            active_next = alive & si.is_valid() & (not last)
            bsdf = si.bsdf(ray)

            # -- emitter sampling (next-event estimation) --
            active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            sample_em = sampler.next_2d(alive)
            if not last:
                ds, em_weight = scene.sample_emitter_direction(si, sample_em, True,
                                                               active_em)
                active_em &= ds.pdf != 0.0
                wo = si.to_local(ds.d)
            else:
                wo = dr.zeros(mi.Vector3f)

            # -- BSDF value at the emitter sample, and the BSDF sample --
            sample_1, sample_2 = sampler.next_1d(alive), sampler.next_2d(alive)
            bsdf_val, bsdf_pdf, bs, bsdf_weight = bsdf.eval_pdf_sample(
                ctx, si, wo, sample_1, sample_2, alive)
            valid_ray |= alive & si.is_valid() & ~mi.has_flag(bs.sampled_type,
                                                              mi.BSDFFlags.Null)
            if last:
                break
            mis_em = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, bsdf_pdf))
            result = dr.select(active_em,
                               dr.fma(throughput, bsdf_val * em_weight * mis_em, result),
                               result)

            # -- continue along the BSDF sample (attached: see the module) --
            ray = si.spawn_ray(si.to_world(bs.wo))
            throughput *= bsdf_weight
            prev_si = mi.Interaction3f(si)
            prev_bsdf_pdf = bs.pdf
            prev_bsdf_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            sampler.next_1d(alive)   # path's Russian-roulette number (kept in step)
            alive = active_next & (dr.max(throughput) != 0.0)
            pi = scene.ray_intersect_preliminary(  # type: ignore[call-overload]
                ray, coherent=False, active=alive)
        return dr.select(valid_ray, result, 0.0), valid_ray, []


mi.register_integrator(MIRRORPATH, lambda props: MirrorPathIntegrator(props))
logger.debug("registered %s for %s", MIRRORPATH, VARIANT)
