"""Photographs of the mirror: find its outline and calibrate the camera against a setup.

The setup predicts where the mirror's outline lands on the sensor
(:func:`mitsweep.optics.outline.predicted_outline`); this unit finds it in a photo, in
three steps kept in modules of their own: a coarse search of position and scale
(:mod:`~mitsweep.photo.coarse`), a sub-pixel edge along each of the outline's normals
(:mod:`~mitsweep.photo.edges`) fitted robustly (:mod:`~mitsweep.photo.robust`), and the
tests that tell a mirror from texture (:mod:`~mitsweep.photo.rim`).
:func:`calibrate_photo` turns the fit into what it implies for the setup
(:mod:`~mitsweep.photo.calibrate`).

It sits above :mod:`mitsweep.optics` (pure optics, which it uses for the prediction) and
never imports the renderer or the tracer.
"""

from .calibrate import WARN_SCALE, Calibration, calibrate_photo
from .image import luminance, photo_void
from .rim import (PLAUSIBLE_SCALE, CalibrationError, NoMirrorError, RimFit,
                  SetupMismatchError, fit_rim)

__all__ = ["CalibrationError", "NoMirrorError", "SetupMismatchError", "RimFit", "Calibration",
           "fit_rim", "calibrate_photo",
           "luminance", "photo_void", "PLAUSIBLE_SCALE", "WARN_SCALE"]
