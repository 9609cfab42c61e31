"""Mitsuba 3 rendering of catadioptric focal-sweep cameras (the only package importing
mitsuba).

- :func:`register` — the ``focalsweep`` moving-sensor thin-lens plugin.
- :func:`render_image`, :func:`render_to_exr`, :func:`render_point_source` — the four
  camera modes (``pinhole``, ``focused``, ``sweep``, ``stopped``) on one reference grid.
- :mod:`mitsweep.render.mirror` — analytic sphere or error-bounded mirror meshes.
- :mod:`mitsweep.render.scene` — the textured room around the mirror.
- :func:`user_scene`, :func:`load_user_scene` — a user's Mitsuba scene (XML or dict) in
  mm in the mirror's frame (:mod:`mitsweep.render.user_scene`); ``render_image(...,
  scene=...)`` renders it.
- :func:`mirror_shape` — the setup's mirror as a Mitsuba shape for any scene (the
  analytic sphere or an in-memory mesh with its error bound).
- Integrators: ``mirrorview`` (:mod:`mitsweep.render.integrator`, emissive scenes) and
  ``mirrorpath`` (:mod:`mitsweep.render.ad_integrator`, lit scenes), both differentiable
  through the mirror; :func:`differentiable_render` (``mi.render`` checked first) raises
  :class:`NotDifferentiableError` for a sweep gradient asked of an integrator that would
  drop it. Each plugin is a class at module scope, registered per variant
  (:mod:`mitsweep.render.registry`).

Mitsuba is imported lazily, after :func:`mitsweep.backend.set_mitsuba_variant`.
"""

from .api import (AOV_NAMES, FOCUS_REFERENCE_DEPTH_MM, MODES, RenderResult, camera_dict,
                  focus_distance_mirror_centre, mirror_image_bbox, mode_camera,
                  reference_sensor_distance, render_image, render_point_source, render_to_exr)
from .gradient import differentiable_render
from .mirror import mirror_shape
from .sensor import PLUGIN_NAME, NotDifferentiableError, register
from .user_scene import (UserScene, UserSceneError, check_user_scene, check_view,
                         load_user_scene, user_scene)

__all__ = ["register", "PLUGIN_NAME", "render_image", "render_to_exr", "render_point_source",
           "RenderResult", "MODES", "AOV_NAMES", "camera_dict", "mode_camera",
           "reference_sensor_distance",
           "focus_distance_mirror_centre", "mirror_image_bbox", "FOCUS_REFERENCE_DEPTH_MM",
           "mirror_shape", "user_scene", "load_user_scene", "check_view", "check_user_scene",
           "UserScene", "UserSceneError", "NotDifferentiableError", "differentiable_render"]
