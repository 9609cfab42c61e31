"""Calibrate a photograph against a setup: :func:`calibrate_photo` finds the setup's
outline (:func:`mitsweep.photo.rim.fit_rim`) and says what it implies: the optical
axis's pixel (the setup's ``sensor.center_offset_px``), and, from the outline's size,
the pixel pitch or the lens–mirror distance."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..config import Setup
from ..optics.outline import predicted_outline
from ..optics.pixels import optical_center_px
from ..optics.reference import reference_geometry
from .coarse import COARSE_SCALE_STEP, MAX_CANDIDATES
from .rim import PLAUSIBLE_SCALE, CalibrationError, RimFit, SetupMismatchError, fit_rim

__all__ = ["Calibration", "calibrate_photo", "WARN_SCALE", "WIDE_SCALES",
           "WARN_CENTRE_SE_PX", "WARN_ROLL_DEG"]

logger = logging.getLogger(__name__)

#: Relative difference above which the calibration warns that the setup is off.
WARN_SCALE = 0.01
#: The wide band of scales searched when the plausible one finds no mirror, so that a
#: setup far off is reported as such, not as a photo without a mirror.
WIDE_SCALES = (1.0 / 3.0, 3.0)
#: Standard error (px) of the fitted centre (from the inliers' scatter) above which the
#: calibration warns that the centre is uncertain (the issue's bar on it is 0.25 px).
WARN_CENTRE_SE_PX = 0.25
#: Roll (degrees) above which the calibration warns: setups have no roll, so banks and
#: panoramas made from the calibrated setup are turned by it.
WARN_ROLL_DEG = 0.5


@dataclass(frozen=True)
class Calibration:
    """A photo's calibration against a setup (see :func:`calibrate_photo`).

    Attributes
    ----------
    fit : RimFit
        The outline as found (centre, scale, inliers, residuals).
    image_shape : (int, int)
        ``(H, W)`` of the photo, px.
    pixel_pitch : float
        The setup's pixel pitch, mm.
    predicted_radius_px : float
        Equivalent radius of the outline the setup predicts, px.
    rim_radius_px : float
        Equivalent radius of the outline found, px.
    center_offset_px : (float, float)
        The optical axis's offset ``(drow, dcol)`` from the image centre, px (a setup's
        ``sensor.center_offset_px``).
    implied_pixel_pitch : float
        The pitch (mm) at which the setup's prediction would match the photo.
    implied_vertex_distance : float or None
        The lens-mirror distance (mm) at which it would, where one exists.
    sensor_distance : float
        Lens-sensor distance (mm) of the prediction.
    warnings : list of str
        What the calibration noticed (a setup off its prediction, a limb fit, …).
    """

    fit: RimFit
    image_shape: tuple[int, int]
    pixel_pitch: float
    predicted_radius_px: float
    rim_radius_px: float
    center_offset_px: tuple[float, float]
    implied_pixel_pitch: float
    implied_vertex_distance: float | None
    sensor_distance: float
    warnings: list = field(default_factory=list)

    @property
    def center_px(self) -> tuple[float, float]:
        return self.fit.center_px

    @property
    def radius_ratio(self) -> float:
        return self.rim_radius_px / self.predicted_radius_px

    def calibrated_setup(self, setup: Setup) -> Setup:
        """The setup for this camera and photo: resolution, pitch, centre offset.

        Parameters
        ----------
        setup : Setup
            The setup the photo was calibrated against; its sensor is replaced by the photo's
            resolution, ``pixel_pitch`` and the measured ``center_offset_px``.
        """
        from ..config import Sensor

        H, W = self.image_shape
        return replace(setup, sensor=Sensor(resolution=(W, H), pixel_pitch=self.pixel_pitch,
                                            center_offset_px=self.center_offset_px))

    def as_dict(self) -> dict:
        return {"center_px": list(self.center_px),
                "center_offset_px": list(self.center_offset_px),
                "image_shape": list(self.image_shape),
                "pixel_pitch_mm": self.pixel_pitch,
                "rim_radius_px": self.rim_radius_px,
                "predicted_rim_radius_px": self.predicted_radius_px,
                "radius_ratio": self.radius_ratio,
                "implied_pixel_pitch_mm": self.implied_pixel_pitch,
                "implied_vertex_distance_mm": self.implied_vertex_distance,
                "reference_sensor_distance_mm": self.sensor_distance,
                "points_used": self.fit.points_used, "points_total": self.fit.points_total,
                "residual_rms_px": self.fit.residual_rms_px,
                "center_standard_error_px": self.fit.center_se_px,
                "roll_deg": self.fit.roll_deg,
                "warnings": list(self.warnings)}


def _implied_vertex_distance(setup, pitch: float, radius_px: float) -> float | None:
    """The lens–vertex distance (mm) at which the setup predicts ``radius_px``, the
    rest of the setup (pitch, lens, sweep settings) kept; None when no distance within
    50% of the first guess does. The reference sensor distance follows the mirror: it is computed at the
    setup's distance and at the first guess, and interpolated in between (the sweep
    moves smoothly with the mirror)."""
    from scipy.optimize import brentq

    from ..config import Mirror, SetupError

    m = setup.mirror

    def moved(vd: float):
        return replace(setup, mirror=Mirror(kind=m.kind, radius=m.radius, conic=m.conic,
                                            rim_radius=m.rim_radius, vertex_distance=vd,
                                            tilt_deg=m.tilt_deg, aspheric=m.aspheric))

    try:
        vd0, i0 = m.vertex_distance, reference_geometry(setup).sensor_distance
        r0 = predicted_outline(setup, sensor_distance=i0, n_points=360)
        guess = vd0 * r0.equivalent_radius_px(pitch) / radius_px  # radius goes as ~1/distance
        i1 = reference_geometry(moved(guess)).sensor_distance
    except (SetupError, ValueError) as exc:
        logger.info("no implied lens-mirror distance: %s", exc)
        return None
    slope = (i1 - i0) / (guess - vd0) if guess != vd0 else 0.0

    def excess(vd: float) -> float:
        try:
            i = i0 + slope * (vd - vd0)
            out = predicted_outline(moved(vd), sensor_distance=i, n_points=360)
            return out.equivalent_radius_px(pitch) - radius_px
        except (SetupError, ValueError):
            return math.nan

    for width in (0.01, 0.05, 0.2, 0.5):
        lo = max(guess * (1 - width), setup.lens.focal_length * 1.05)
        hi = guess * (1 + width)
        flo, fhi = excess(lo), excess(hi)
        if math.isfinite(flo) and math.isfinite(fhi) and flo * fhi <= 0:
            return float(brentq(excess, lo, hi, xtol=1e-3))
    return None


def calibrate_photo(image: np.ndarray, setup: Setup, *, pixel_pitch: float | None = None,
                    plausible_scale: float = PLAUSIBLE_SCALE,
                    fit_roll: bool = False, starts: int = MAX_CANDIDATES) -> Calibration:
    """Calibrate a photograph of the setup's mirror: centre, rim size, what it implies.

    Parameters
    ----------
    image : (H, W) or (H, W, 3) ndarray
        Linear photograph (e.g. :attr:`mitsweep.io.camera.CameraImage.data`).
    setup : mitsweep.config.Setup
    pixel_pitch : float, optional
        The photo's pitch, mm (default: the setup's).
    plausible_scale : float
        Largest relative error of the predicted outline size (against the measured one)
        that is searched and accepted (default ±35%; beyond
        :data:`WARN_SCALE` the calibration warns with the pitch or distance it implies).
    fit_roll : bool
        Fit the camera's roll too (tilted mirrors), see :func:`fit_rim`.
    starts : int
        Starting points of the rim search refined at most, see :func:`fit_rim` (1: the
        outline nearest the prediction only, faster where the setup is nearly right).

    Returns
    -------
    Calibration

    Raises
    ------
    mitsweep.photo.NoMirrorError
        No outline of the mirror's shape stands out in the photo (at any size from a
        third to three times the prediction).
    mitsweep.photo.SetupMismatchError
        A mirror was found whose size disagrees with the setup by more than
        ``plausible_scale``; the message says the pitch or distance it implies.
    Both are :class:`mitsweep.photo.CalibrationError`.
    """
    pitch = float(pixel_pitch or setup.sensor.pixel_pitch)
    if not 0.0 < plausible_scale < 1.0:
        raise ValueError(f"plausible_scale must be in (0, 1), got {plausible_scale!r}")
    # A prediction off by up to ±plausible_scale of the true size: the measured outline
    # is 1/(1 ± plausible_scale) times the predicted one.
    plausible = (1.0 / (1.0 + plausible_scale), 1.0 / (1.0 - plausible_scale))
    # accepted: what was searched, to the coarse search's resolution (a fit at the range's
    # end may land a fraction of a step beyond it)
    accepted = (plausible[0] / COARSE_SCALE_STEP, plausible[1] * COARSE_SCALE_STEP)
    outline = predicted_outline(setup)
    predicted = outline.equivalent_radius_px(pitch)
    try:
        fit = fit_rim(image, outline, pitch, scale_range=accepted, fit_roll=fit_roll,
                      starts=starts)
    except CalibrationError as within:
        # a mirror far off the predicted size is a wrong setup, not a missing mirror
        try:
            fit = fit_rim(image, outline, pitch, scale_range=WIDE_SCALES, fit_roll=fit_roll,
                          starts=starts)
        except CalibrationError:
            raise within from None
        if accepted[0] <= fit.scale <= accepted[1]:  # found on the second look after all
            logger.info("rim found in the wide search: %s", within)
    measured = predicted * fit.scale
    shape = (int(np.shape(image)[0]), int(np.shape(image)[1]))
    r0, c0 = optical_center_px(shape)
    offset = (fit.center_px[0] - r0, fit.center_px[1] - c0)
    implied_pitch = pitch / fit.scale
    if not accepted[0] <= fit.scale <= accepted[1]:
        vd = _implied_vertex_distance(setup, pitch, measured)
        raise SetupMismatchError(
            f"found a mirror {100 * (1 / fit.scale - 1):+.0f}% off the setup's prediction "
            f"(more than {100 * plausible_scale:.0f}%): its outline measures "
            f"{measured:.1f} px, the setup predicts {predicted:.1f} px (centre row "
            f"{fit.center_px[0]:.1f}, col {fit.center_px[1]:.1f}); it implies a pixel pitch "
            f"of {implied_pitch:.5g} mm (setup {pitch:g})"
            + (f" or a lens-mirror distance of {vd:.1f} mm (setup "
               f"{setup.mirror.vertex_distance:g})" if vd is not None else "")
            + ": set sensor.pixel_pitch or mirror.vertex_distance to match, or run "
              "calibrate --free")
    implied_vd = _implied_vertex_distance(setup, pitch, measured)
    warnings = []
    if abs(fit.scale - 1.0) > WARN_SCALE:
        vd_text = f"{implied_vd:.2f}" if implied_vd is not None else "?"
        warnings.append(
            f"rim radius {measured:.2f} px differs from the setup's {predicted:.2f} px by "
            f"{100 * (fit.scale - 1):+.2f}%: the pixel pitch would be {implied_pitch:.5g} mm "
            f"(setup {pitch:g}) or the lens-mirror distance {vd_text} mm "
            f"(setup {setup.mirror.vertex_distance:g})")
        if not outline.on_rim.any() and not fit.limb:
            # A hemisphere's outline is its limb, seen at grazing incidence, where the
            # reflection continues what lies behind the mirror: a render shows no edge
            # there (the sphere at 200 px: the fit found the boards' reflection 14.7%
            # inside, reflected rays at 114 deg), so the size says nothing of the pitch.
            warnings.append(
                "the outline is the mirror's limb (grazing reflection), which shows no "
                "edge where the reflection continues the background behind the mirror: "
                "the fitted outline may be an edge inside the reflection, not the limb, "
                "and its size then says nothing of the pitch or the distance")
    if fit.limb:
        warnings.append(
            "the outline was found as the mirror's limb, where the photo shows no edge, "
            "from how the image changes across it (a render's noise, steps of either "
            "sign): measured on renders to 0.25 px, not on real photos")
    if fit.center_se_px > WARN_CENTRE_SE_PX:
        warnings.append(
            f"the rim is a faint edge: its {fit.points_used} edge points scatter by "
            f"{fit.residual_rms_px:.2f} px RMS, which leaves the centre uncertain by "
            f"{fit.center_se_px:.2f} px")
    if fit.roll_deg is not None and abs(fit.roll_deg) > WARN_ROLL_DEG:
        warnings.append(
            f"the camera is rolled by {fit.roll_deg:+.2f} deg about its axis; setups have no "
            f"roll, so banks and panoramas of the calibrated setup are turned by it")
    H, W = shape
    if not (0 <= fit.center_px[0] <= H - 1 and 0 <= fit.center_px[1] <= W - 1):
        warnings.append("the mirror's axis lies outside the photo")
    for w in warnings:
        logger.warning("%s", w)
    return Calibration(fit=fit, image_shape=shape, pixel_pitch=pitch,
                       predicted_radius_px=predicted, rim_radius_px=measured,
                       center_offset_px=offset, implied_pixel_pitch=implied_pitch,
                       implied_vertex_distance=implied_vd,
                       sensor_distance=outline.sensor_distance, warnings=warnings)
