"""The ``focalsweep`` sensor plugin: a thin-lens camera whose sensor moves during the exposure.

.. list-table:: Plugin parameters
   :header-rows: 1

   * - name
     - type
     - meaning
   * - ``focal_length``
     - float
     - Thin-lens focal length f, mm (required, > 0).
   * - ``aperture_radius`` / ``f_number``
     - float
     - Entrance-pupil radius a (mm, >= 0; 0 is a pinhole), or the f-number N with
       ``a = f / (2 N)``. Give at most one; default: a pinhole.
   * - ``pixel_pitch``
     - float
     - Physical pixel pitch on the sensor, mm (required, > 0). Pixels are fixed
       physical positions, so the magnification "breathes" as the sensor moves.
   * - ``sensor_distance``
     - float
     - A fixed lens-to-sensor distance i, mm (the sweep collapsed; a normal camera).
   * - ``sensor_start``, ``sensor_end``
     - float
     - Sensor distance at shutter open and close, mm (instead of ``sensor_distance``).
   * - ``profile``
     - string
     - Stage motion between them: ``linear`` (default), ``trapezoidal`` (with
       ``accel_fraction``) or ``tabulated`` (with ``times`` and ``positions``, each a
       whitespace/comma-separated string or a ``TensorXf``).
   * - ``shutter_open``, ``shutter_close``
     - float
     - Exposure interval, s (Mitsuba's; the normalised time is
       ``(time − open) / (close − open)``). A sweep needs ``close > open``.
   * - ``near_clip``, ``far_clip``
     - float
     - Clip distances, mm (defaults 0.01 and 1e4 as in Mitsuba: set ``far_clip``).
   * - ``to_world``
     - transform
     - Camera-to-world (``look_at``); local +z is the viewing direction, local +x
       the image's left, local +y its up, as in Mitsuba's built-in cameras.

Ray generation (camera-local frame, see :func:`_sensor_point`): a film sample gives
upright sensor coordinates ``(u, v)`` in mm (pixel (0, 0) top-left, image centre on the
axis). At time t the sensor sits at ``i(t)``; the thin lens ``1/f = 1/i + 1/o`` focuses
it on the plane ``z = o(t)``, where the sensor point images to
``q = (−u o/i, v o/i, o)``. A uniformly sampled aperture point ``p_a = (a ξ, 0)`` gives
the ray ``p_a → q``. With ``i`` fixed this is exactly Mitsuba's ``thinlens`` with
``x_fov = 2 atan(W p / 2 i)`` and ``focus_distance = o`` (and ``perspective`` for a = 0).
As in ``thinlens``, the ray weight is 1 (no cos⁴ fall-off; the 1/i² irradiance change
during the sweep, < 0.2 % for the paper's setups, is ignored).

Importance for light tracing (:meth:`FocalSweepSensor.sample_direction`) samples the
aperture uniformly; the contribution is ``W(ω) / dist²`` with the pinhole importance
``W = 1 / (A cos³θ)``, ``A = W H p² / i(t)²`` the image area at unit distance, and the
pixel found where the ray through the aperture point crosses the focal plane.

Differentiation (``*_ad_*`` variants)
-------------------------------------
:func:`mitsuba.traverse` exposes the motion under the names of the plugin's own
properties; these are differentiable in forward and reverse mode, the sensor distance
``i(t)`` staying attached to them all the way into the ray origins and directions:

.. list-table::
   :header-rows: 1

   * - motion
     - differentiable keys
     - how ``i(t)`` depends on them
   * - fixed (``sensor_distance``)
     - ``sensor_distance``
     - ``i = sensor_distance``
   * - ``linear``, ``trapezoidal``
     - ``sensor_start``, ``sensor_end``
     - ``i = start + (end − start) g(t)``, ``g(t) = t`` or the trapezoid's normalised
       shape (fixed by ``accel_fraction``)
   * - ``tabulated``
     - ``positions`` (all n knots; ``sensor_start``/``end`` are its first and last)
     - linear between the two knots around t; the knot index and weight come from the
       (detached) time by a binary search, the value from the differentiable knots

Not differentiable: ``to_world`` (as in Mitsuba's own cameras), ``aperture_radius``,
``pixel_pitch``, ``focal_length`` and the tabulated ``times``; ``accel_fraction`` is
not exposed. Enabling a gradient on one of these (``dr.enable_grad(params[key])``)
raises :class:`NotDifferentiableError` at ``params.update()`` or at the next render,
instead of Mitsuba's warning and a zero derivative. The scalar variant has no AD.

Usage::

    params = mi.traverse(scene)
    dr.enable_grad(params["sensor.sensor_end"])
    params.update()
    img = differentiable_render(scene, params, seed=1, seed_grad=2)  # mitsweep.render
    dr.forward(params["sensor.sensor_end"])     # dr.grad(img): dI/d(end), an image
    # or: dr.backward(loss(img)); dr.grad(params["sensor.sensor_end"])

The gradient pass draws its samples from ``seed_grad``: a finite-difference check with
common random numbers renders with ``seed=seed_grad``.

Integrators: mitsweep's ``mirrorview`` (emissive scenes) and ``mirrorpath`` (lit scenes:
:mod:`mitsweep.render.ad_integrator`, a path tracer with emitter sampling and MIS whose
image equals ``path``'s) differentiate through the mirror's reflections;
:func:`mitsweep.render.scene.build_scene` picks one of them in ``*_ad_*`` variants
(``path`` only beyond ``mirrorpath``'s depth limit of 8, or at an unlimited depth).
Mitsuba's ``path``, ``volpath``, ``direct`` and ``direct_projective`` differentiate what
the camera sees directly, but ``path`` detaches the ray at every BSDF sample (measured:
exactly zero through a mirror, with symbolic or evaluated loops); ``prb``, ``prb_basic``,
``prb_projective`` and ``prbvolpath`` detach the camera rays. Asking for a sweep gradient
through :func:`mitsweep.render.differentiable_render` (``mi.render`` with mitsweep's
check first) with one of these raises :class:`NotDifferentiableError` naming the
integrator, instead of a zero: the ``prb`` family (and ``ptracer``) always, the others
when a shape reflects or transmits in a delta or null lobe (the mirror). The check
reads the scene, its integrator and :meth:`FocalSweepSensor.differentiated_parameters`
before rendering; :func:`mitsuba.render` called directly is not checked (a sensor has
no public way to see the integrator that calls it). With ``path`` and no
mirror, the derivative of a lit view still lacks every term after the first bounce
(light reflected between surfaces): render lit scenes with ``mirrorpath``.
Light tracing (``ptracer``, through :meth:`FocalSweepSensor.sample_direction`)
is not covered: there the sweep moves the pixel a sample lands in, a derivative plain
AD does not give. The derivative is that of the image's continuous part: as
for any camera parameter differentiated by plain AD, an edge (silhouette, a shadow
edge, a texture with nearest filtering) that moves across pixels or samples as the
sweep changes contributes a boundary term that is not included
(``tests/test_render_sweep_grad.py`` checks the derivative against finite differences
on a smoothly textured scene, ``tests/test_render_lit_grad.py`` on a lit one through
the mirror; ``examples/inverse_sweep.py`` recovers a sweep end from an image).

One class for every variant
---------------------------
As Mitsuba's own Python plugins (``mitsuba/python/ad/integrators/prb.py``), the class
is defined at module scope, deriving from ``mi.Sensor``, and registered at the end of
the module. ``mi.Sensor`` (like ``mi.Float``) resolves through the variant that is set
when the class statement runs, so this module is bound to one variant
(:data:`VARIANT`): :func:`mitsweep.render.register` imports it after selecting a variant
and reloads it (``importlib.reload``) after a change of variant, as Mitsuba's
``set_variant`` reloads ``mitsuba.ad.integrators``. Importing it with no variant set
selects mitsweep's (:func:`mitsweep.backend.set_mitsuba_variant`), so that
documentation tools and type checkers see the class. The code is written once over the
variant's array type: in the scalar variant ``mi.Float`` is a Python float and the
motion tables are ``drjit.scalar.ArrayXf64`` (read by :func:`_at`); in the vectorised
variants they are ``mi.Float`` arrays read by ``dr.gather``. The scalar variant has no
AD, and its parameters are Python floats that a traversal cannot update in place: it
exposes ``to_world`` only.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Any, cast

import drjit as dr
import mitsuba as mi
import numpy as np

from ..backend import set_mitsuba_variant
from .sensor_motion import (DIFFERENTIABLE, PLUGIN_NAME, NotDifferentiableError, SensorMotion,
                            motion_from_properties)

__all__ = ["FocalSweepSensor", "VARIANT"]

logger = logging.getLogger(__name__)

#: The Mitsuba variant this module's class was built for (mitsweep's, set here, when
#: the module is imported with none set: for its documentation or types).
VARIANT: str = mi.variant() or set_mitsuba_variant()
#: Vectorised (JIT, differentiable) variant; in the scalar one ``mi.Float`` is ``float``.
_VECTORISED = dr.is_jit_v(mi.Float)


def _table(values: np.ndarray):
    """A 1-D float table in the variant's array type (float32 when vectorised, as the
    renderer computes; float64 in the scalar variant, whose ``mi.Float`` is a double)."""
    if _VECTORISED:
        return mi.Float(np.asarray(values).astype(np.float32))
    return dr.scalar.ArrayXf64(np.asarray(values, dtype=float))


def _at(table, index):
    """``table[index]``: a gather (vectorised variants) or an item (scalar variant)."""
    if _VECTORISED:
        return dr.gather(mi.Float, table, index)
    return table[int(index)]


def _float(props: mi.Properties, name: str, default: float) -> float:
    """A scalar property as a float (``Properties.get`` is typed ``object``: its type is
    the stored value's)."""
    return float(cast(float, props.get(name, default)))


def _first(value: Any) -> float:
    """The value of a one-wide parameter (a Dr.Jit array, or a float in the scalar
    variant) as a float (``dr.slice`` is typed ``object``: it also slices PyTrees)."""
    return float(cast(float, dr.slice(value, 0)))


def _positive(props, name: str) -> float:
    value = props.get(name, None)
    if value is None or not (float(value) > 0):
        raise ValueError(f"focalsweep: {name} must be > 0 mm, got {value!r}")
    return float(value)


def _aperture_radius(props, focal_length: float) -> float:
    """The entrance-pupil radius from ``aperture_radius`` or ``f_number``."""
    has_a, has_n = ("aperture_radius" in props), ("f_number" in props)
    if has_a and has_n:
        raise ValueError("focalsweep: give aperture_radius or f_number, not both")
    if has_n:
        n = float(props.get("f_number"))
        if not n > 0:
            raise ValueError(f"focalsweep: f_number must be > 0, got {n}")
        radius = focal_length / (2.0 * n)
    else:
        radius = float(props.get("aperture_radius", 0.0))
    if not (radius >= 0 and math.isfinite(radius)):
        raise ValueError(f"focalsweep: aperture_radius must be >= 0 mm, got {radius}")
    return radius


class FocalSweepSensor(mi.Sensor):
    """A thin-lens sensor translating along its axis during the exposure (see the
    module for its parameters, ray generation and derivatives).

    Parameters
    ----------
    props : mi.Properties
        The plugin's properties (the module's table: ``focal_length``, ``pixel_pitch``,
        ``aperture_radius`` or ``f_number``, the motion, clip distances in mm, the
        shutter in s, ``to_world``, the film and sampler); a fault raises ValueError
        naming the property.
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.m_needs_sample_3 = True  # aperture sample (docs/design.md, pitfalls)
        self.focal_length = _positive(props, "focal_length")
        self.pixel_pitch = _positive(props, "pixel_pitch")
        self.aperture_radius = _aperture_radius(props, self.focal_length)
        self.near_clip = _float(props, "near_clip", 0.01)
        self.far_clip = _float(props, "far_clip", 1e4)
        if not (0 < self.near_clip < self.far_clip):
            raise ValueError(f"focalsweep: need 0 < near_clip < far_clip, got "
                             f"{self.near_clip}, {self.far_clip}")
        self.motion = motion_from_properties(props)
        lo, hi = self.motion_span
        if not lo > self.focal_length:
            raise ValueError(
                f"focalsweep: the sensor distance reaches {lo:g} mm, at or inside the "
                f"focal length ({self.focal_length:g} mm); every sensor distance of the "
                f"sweep must be > focal_length")
        if self.motion_kind != "fixed" and not self.shutter_open_time() > 0:
            raise ValueError("focalsweep: a moving sensor needs shutter_close > "
                             "shutter_open (the exposure interval)")
        film = self.film()
        # Plain Python floats: NumPy scalars would pull symbolic Dr.Jit values into
        # NumPy (an evaluation, refused inside the integrators' recorded loops).
        self.size = tuple(float(x) for x in film.size())
        self.crop_offset = tuple(float(x) for x in film.crop_offset())
        self.crop_size = tuple(float(x) for x in film.crop_size())
        self._set_variant_parameters()

    # -- parameters ------------------------------------------------------------------
    @property
    def motion_kind(self) -> str:
        """``fixed``, ``linear``, ``trapezoidal`` or ``tabulated``."""
        return self.motion.kind

    @property
    def motion_span(self) -> tuple[float, float]:
        """Least and greatest sensor distance of the motion, mm."""
        return self.motion.span

    def differentiable_parameters(self) -> tuple[str, ...]:
        """Names (in :func:`mitsuba.traverse`) of the differentiable parameters (none in
        the scalar variant)."""
        return DIFFERENTIABLE[self.motion_kind] if _VECTORISED else ()

    def differentiated_parameters(self) -> tuple[str, ...]:
        """The differentiable parameters whose gradient is enabled now."""
        values = {"sensor_distance": self.m_start, "sensor_start": self.m_start,
                  "sensor_end": self.m_end, "positions": getattr(self, "m_positions", None)}
        return tuple(k for k in self.differentiable_parameters()
                     if dr.grad_enabled(values[k]))

    def _opaque_parameters(self) -> list:
        out = [self.m_aperture, self.m_pitch, self.m_f, self.m_start, self.m_end]
        if self.motion_kind == "tabulated":
            out += [self.m_times, self.m_positions]
        return out

    def _set_variant_parameters(self):
        """The parameters in the variant's types (Python floats in the scalar variant)."""
        motion = self.motion
        self.m_aperture = mi.Float(self.aperture_radius)
        self.m_pitch = mi.Float(self.pixel_pitch)
        self.m_f = mi.Float(self.focal_length)
        self.m_start = mi.Float(motion.start)
        # A fixed sensor has one distance: both ends are the same variable.
        self.m_end = self.m_start if motion.kind == "fixed" else mi.Float(motion.end)
        if motion.times is not None:
            self.m_times = _table(motion.times)
            self.m_positions = _table(motion.positions)
        opaque = self._opaque_parameters()
        if motion.shape is not None:
            self.m_shape = _table(motion.shape)
            opaque.append(self.m_shape)
        dr.make_opaque(*opaque)

    def _non_differentiable_parameters(self):
        """(name, value) of the parameters exposed as non-differentiable."""
        out = [("to_world", self.m_to_world), ("aperture_radius", self.m_aperture),
               ("pixel_pitch", self.m_pitch), ("focal_length", self.m_f)]
        if self.motion_kind == "tabulated":
            out.append(("times", self.m_times))
        return out

    def _refuse_gradients_of_non_differentiable(self):
        """Raise if a non-differentiable parameter was given a gradient: Mitsuba would
        only log a warning, and the derivative would be zero or unchecked."""
        for name, value in self._non_differentiable_parameters():
            if dr.grad_enabled(value):
                allowed = ", ".join(self.differentiable_parameters())
                raise NotDifferentiableError(
                    f"focalsweep: {name} is not differentiable; with motion "
                    f"{self.motion_kind!r} the differentiable parameters are: {allowed}")

    # -- geometry --------------------------------------------------------------------
    def sensor_distance(self, time: Any) -> Any:
        """Sensor distance i(t), mm, at Mitsuba time ``time`` (s).

        In ``*_ad_*`` variants it is attached to the AD graph of ``sensor_start`` /
        ``sensor_end`` (or ``positions``): the table index and weight are computed from
        the (detached) time, the value from the differentiable entries.

        Parameters
        ----------
        time : mi.Float
            Mitsuba time, s: clamped to the exposure ``[shutter_open, shutter_close]``
            (ignored by a fixed sensor).
        """
        motion = self.motion
        if motion.kind == "fixed":
            return self.m_start
        t = dr.clip((time - self.shutter_open()) / self.shutter_open_time(), 0.0, 1.0)
        if motion.times is not None:  # tabulated
            times, n = self.m_times, len(motion.times)
            k = dr.binary_search(0, n - 2, lambda j: _at(times, j + 1) <= t)
            t0, t1 = _at(times, k), _at(times, k + 1)
            w = dr.clip((t - t0) / (t1 - t0), 0.0, 1.0)
            a, b = _at(self.m_positions, k), _at(self.m_positions, k + 1)
            return dr.fma(b - a, w, a)
        if motion.shape is not None:  # trapezoidal
            n = len(motion.shape) - 1
            x = t * n
            k = mi.UInt32(dr.clip(dr.floor(x), 0, n - 1))
            w = x - mi.Float(k)
            g0, g1 = _at(self.m_shape, k), _at(self.m_shape, k + 1)
            t = dr.fma(g1 - g0, w, g0)
        return dr.fma(self.m_end - self.m_start, t, self.m_start)

    def _sensor_point(self, sample2):
        """Upright sensor coordinates (u, v), mm, of a film sample (crop-relative)."""
        px = (self.crop_offset[0] + sample2.x * self.crop_size[0]) / self.size[0]
        py = (self.crop_offset[1] + sample2.y * self.crop_size[1]) / self.size[1]
        u = (px - 0.5) * (self.size[0] * self.m_pitch)
        v = (0.5 - py) * (self.size[1] * self.m_pitch)
        return u, v

    def _rays(self, time, sample1, sample2, sample3, active, differentials):
        self._refuse_gradients_of_non_differentiable()
        wavelengths, wav_weight = self.sample_wavelengths(
            dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        i = self.sensor_distance(time)
        o = self.m_f * i / (i - self.m_f)      # thin lens, paper Eq. 1
        scale = o / i
        u, v = self._sensor_point(sample2)
        focus_p = mi.Vector3f(-u * scale, v * scale, o)
        disk = mi.warp.square_to_uniform_disk_concentric(sample3) * self.m_aperture
        aperture_p = mi.Vector3f(disk.x, disk.y, 0.0)
        d = dr.normalize(focus_p - aperture_p)
        to_world = self.world_transform()
        ray = mi.RayDifferential3f() if differentials else mi.Ray3f()
        ray.time = time
        ray.wavelengths = wavelengths
        ray.o = to_world @ mi.Point3f(aperture_p)
        ray.d = to_world @ d
        inv_z = dr.rcp(d.z)
        near_t = self.near_clip * inv_z
        far_t = self.far_clip * inv_z
        ray.o = ray.o + ray.d * near_t
        ray.maxt = far_t - near_t
        if differentials:
            step = self.m_pitch * scale
            ray.o_x = ray.o
            ray.o_y = ray.o
            ray.d_x = to_world @ dr.normalize(focus_p + mi.Vector3f(-step, 0, 0) - aperture_p)
            ray.d_y = to_world @ dr.normalize(focus_p + mi.Vector3f(0, -step, 0) - aperture_p)
            ray.has_differentials = True
        return ray, wav_weight

    def sample_ray(self, time: Any, sample1: Any, sample2: mi.Point2f,
                   sample3: mi.Point2f, active: Any = True) -> tuple[mi.Ray3f, mi.Spectrum]:
        """A camera ray and its spectral weight, as ``mi.Sensor.sample_ray``.

        Parameters
        ----------
        time : mi.Float
            Mitsuba time of the ray, s: where the sensor is (:meth:`sensor_distance`).
        sample1 : mi.Float
            Uniform sample in [0, 1) for the wavelengths (spectral variants).
        sample2 : mi.Point2f
            Position on the film, in [0, 1)² of the crop window.
        sample3 : mi.Point2f
            Uniform sample in [0, 1)² of the aperture disk.
        active : mi.Bool, optional
            Lanes to compute (default: all).
        """
        return self._rays(time, sample1, sample2, sample3, active, False)

    def sample_ray_differential(self, time: Any, sample1: Any, sample2: mi.Point2f,
                                sample3: mi.Point2f, active: Any = True
                                ) -> tuple[mi.RayDifferential3f, mi.Spectrum]:
        """:meth:`sample_ray` with differentials: the rays through the next pixel along
        x and y, from the same aperture point.

        Parameters
        ----------
        time : mi.Float
            Mitsuba time of the ray, s.
        sample1 : mi.Float
            Uniform sample in [0, 1) for the wavelengths (spectral variants).
        sample2 : mi.Point2f
            Position on the film, in [0, 1)² of the crop window.
        sample3 : mi.Point2f
            Uniform sample in [0, 1)² of the aperture disk.
        active : mi.Bool, optional
            Lanes to compute (default: all).
        """
        return self._rays(time, sample1, sample2, sample3, active, True)

    def sample_direction(self, it: mi.Interaction3f, sample: mi.Point2f, active: Any = True
                         ) -> tuple[mi.DirectionSample3f, mi.Spectrum]:
        """Connect a scene point to a sampled aperture point (for light tracing).

        Parameters
        ----------
        it : mi.Interaction3f
            The scene point (its position, mm, and time, s).
        sample : mi.Point2f
            Uniform sample in [0, 1)² of the aperture disk.
        active : mi.Bool, optional
            Lanes to compute (default: all).

        Returns
        -------
        ds : mi.DirectionSample3f
            The aperture point, the direction and distance to it, its pdf (solid angle
            at ``it``; 0 where the point is outside the frame or the clip range) and the
            film position ``uv`` (px of the crop window).
        weight : mi.Spectrum
            The importance ``W / dist²`` (see the module), 0 where ``ds.pdf`` is.
        """
        self._refuse_gradients_of_non_differentiable()
        to_world = self.world_transform()
        ref = to_world.inverse() @ it.p
        i = self.sensor_distance(it.time)
        o = self.m_f * i / (i - self.m_f)
        disk = mi.warp.square_to_uniform_disk_concentric(sample) * self.m_aperture
        aperture_p = mi.Point3f(disk.x, disk.y, 0.0)
        local_d = mi.Vector3f(ref - aperture_p)
        dist = dr.norm(local_d)
        inv_dist = dr.rcp(dist)
        local_d *= inv_dist
        ct = local_d.z
        inv_ct = dr.rcp(ct)
        q = aperture_p + local_d * (o * inv_ct)     # crossing of the focal plane
        u = -q.x * i / o
        v = q.y * i / o
        px = u / (self.size[0] * self.m_pitch) + 0.5
        py = 0.5 - v / (self.size[1] * self.m_pitch)
        cx = (px * self.size[0] - self.crop_offset[0]) / self.crop_size[0]
        cy = (py * self.size[1] - self.crop_offset[1]) / self.crop_size[1]
        valid = (active & (ref.z >= self.near_clip) & (ref.z <= self.far_clip)
                 & (ct > 0) & (cx >= 0) & (cx <= 1) & (cy >= 0) & (cy <= 1))
        area = self.size[0] * self.size[1] * self.m_pitch * self.m_pitch / (i * i)
        value = dr.select(valid, inv_ct * inv_ct * inv_ct / area, 0.0)
        # Any: the stubs type its fields with ``drjit.auto.ad`` arrays, a class apart from
        # ``mi.Float``, and refuse the Python scalars and vectors that convert implicitly
        ds: Any = dr.zeros(mi.DirectionSample3f)
        ds.uv = mi.Point2f(cx * self.crop_size[0], cy * self.crop_size[1])
        ds.p = to_world @ aperture_p
        ds.d = mi.Vector3f(ds.p - it.p) * inv_dist
        ds.dist = dist
        ds.n = to_world @ mi.Vector3f(0, 0, 1)
        ds.time = it.time
        lens_area = math.pi * self.aperture_radius ** 2
        pdf = (dist * dist * inv_ct / lens_area) if lens_area > 0 else mi.Float(1.0)
        ds.pdf = dr.select(valid, pdf, 0.0)
        ds.delta = lens_area == 0
        return ds, mi.Spectrum(value * inv_dist * inv_dist)

    def bbox(self) -> mi.ScalarBoundingBox3f:
        p = self.world_transform() @ mi.ScalarPoint3f(0.0)
        return mi.ScalarBoundingBox3f(p, p)

    # -- traversal -------------------------------------------------------------------
    def traverse(self, callback: mi.TraversalCallback) -> None:
        """Expose the parameters to :func:`mitsuba.traverse` (the module's table of
        differentiable keys); in the scalar variant ``to_world`` only.

        Parameters
        ----------
        callback : mi.TraversalCallback
            Mitsuba's collector: each parameter is put under its property name, flagged
            differentiable or not.
        """
        flag = mi.ParamFlags
        callback.put("to_world", self.m_to_world, flag.NonDifferentiable)
        if not _VECTORISED:  # Python floats: a traversal could not update them in place
            return
        callback.put("aperture_radius", self.m_aperture, flag.NonDifferentiable)
        callback.put("pixel_pitch", self.m_pitch, flag.NonDifferentiable)
        callback.put("focal_length", self.m_f, flag.NonDifferentiable)
        kind = self.motion_kind
        if kind == "fixed":
            callback.put("sensor_distance", self.m_start, flag.Differentiable)
        elif kind == "tabulated":
            callback.put("positions", self.m_positions, flag.Differentiable)
            callback.put("times", self.m_times, flag.NonDifferentiable)
        else:
            callback.put("sensor_start", self.m_start, flag.Differentiable)
            callback.put("sensor_end", self.m_end, flag.Differentiable)

    def parameters_changed(self, keys: Sequence[str] = ()) -> None:
        """Check and take up parameters changed through a traversal: refuse a gradient on
        a non-differentiable one, a table whose length changed, or a sensor distance at
        or inside the focal length (ValueError).

        Parameters
        ----------
        keys : sequence of str
            Names of the changed parameters (as :meth:`traverse` put them); every one is
            checked whatever the names.
        """
        super().parameters_changed(keys)
        self._refuse_gradients_of_non_differentiable()
        sizes = [("sensor_start", self.m_start, 1), ("sensor_end", self.m_end, 1)]
        motion = self.motion
        if motion.times is not None and motion.positions is not None:  # tabulated
            sizes += [("positions", self.m_positions, len(motion.positions)),
                      ("times", self.m_times, len(motion.times))]
        for name, value, n in sizes:
            if dr.width(value) != n:
                raise ValueError(f"focalsweep: {name} must keep its length {n}, "
                                 f"got {dr.width(value)}")
        # Keep the Python-side copies (used for validation and repr) in step.
        self.aperture_radius = _first(self.m_aperture)
        self.pixel_pitch = _first(self.m_pitch)
        self.focal_length = _first(self.m_f)
        self.motion = dataclasses.replace(self.motion, start=_first(self.m_start),
                                          end=_first(self.m_end))
        if self.motion_kind == "tabulated":
            self.motion = _tabulated_update(self.motion, self.m_times, self.m_positions)
        if not self.motion_span[0] > self.focal_length:
            raise ValueError("focalsweep: a sensor distance is at or inside the focal "
                             "length")
        dr.make_opaque(*self._opaque_parameters())

    def to_string(self) -> str:
        lo, hi = self.motion_span
        return (f"FocalSweepSensor[focal_length={self.focal_length}, "
                f"aperture_radius={self.aperture_radius}, pixel_pitch={self.pixel_pitch}, "
                f"motion={self.motion_kind}, sensor_distance={lo}..{hi}, "
                f"film={self.film()}]")


def _tabulated_update(motion: SensorMotion, times, positions) -> SensorMotion:
    """A tabulated motion with the (traversed, possibly changed) knots, checked."""
    positions = np.array(dr.detach(positions), dtype=float)
    times = np.array(dr.detach(times), dtype=float)
    if not (np.all(np.diff(times) > 0) and times[0] == 0 and times[-1] == 1):
        raise ValueError("focalsweep: times must rise strictly from 0 to 1 "
                         "(the normalised exposure)")
    return dataclasses.replace(motion, start=float(positions[0]), end=float(positions[-1]),
                               times=times, positions=positions)


mi.register_sensor(PLUGIN_NAME, lambda props: FocalSweepSensor(props))
logger.debug("registered %s for %s", PLUGIN_NAME, VARIANT)
