"""Mitsuba 3 rendering of catadioptric focal-sweep cameras (the only package importing
mitsuba).

- :func:`register` — the ``focalsweep`` moving-sensor thin-lens plugin.
- :func:`render_image`, :func:`render_to_exr`, :func:`render_point_source` — the four
  camera modes (``pinhole``, ``focused``, ``sweep``, ``stopped``) on one reference grid.
- :mod:`mitsweep.render.mirror` — analytic sphere or error-bounded mirror meshes.
- :mod:`mitsweep.render.scene` — the textured room around the mirror.

Mitsuba is imported lazily, after :func:`mitsweep.backend.set_mitsuba_variant`.
"""

from .api import (AOV_NAMES, FOCUS_REFERENCE_DEPTH_MM, MODES, RenderResult, camera_dict,
                  focus_distance_mirror_centre, mirror_image_bbox, mode_camera,
                  reference_sensor_distance, render_image, render_point_source, render_to_exr)
from .sensor import PLUGIN_NAME, register

__all__ = ["register", "PLUGIN_NAME", "render_image", "render_to_exr", "render_point_source",
           "RenderResult", "MODES", "AOV_NAMES", "camera_dict", "mode_camera",
           "reference_sensor_distance",
           "focus_distance_mirror_centre", "mirror_image_bbox", "FOCUS_REFERENCE_DEPTH_MM"]
