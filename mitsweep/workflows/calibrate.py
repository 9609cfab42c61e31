"""Find the mirror in a photo: its centre and rim size, and a setup for the camera that
took it (``mitsweep calibrate``).

Reads the photo (RAW, TIFF, PNG, JPEG or EXR, :mod:`mitsweep.io.camera`), predicts the
mirror's outline from the setup and fits it to sub-pixel precision
(:func:`mitsweep.photo.calibrate_photo`, which takes the image array). Without a setup,
:func:`find_mirror_circle` finds the outline as a circle from the photo alone.
"""

from __future__ import annotations

import hashlib
import os

from .. import __version__
from ..config import Setup
from ._base import WorkflowResult, resolve_setup
from ._paths import check_outputs

__all__ = ["calibrate_camera", "find_mirror_circle"]


def _sha256(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def calibrate_camera(photo: str | os.PathLike, setup: Setup | str | os.PathLike, *,
                     write: str | os.PathLike | None = None, fit_roll: bool = False,
                     pixel_pitch: float | None = None, white_balance: str = "camera",
                     transfer: str | None = None) -> WorkflowResult:
    """The mirror's centre and rim radius on a photo against the setup's prediction, and
    the setup for this camera and photo (``mitsweep calibrate``).

    Parameters
    ----------
    photo : path-like
        The photo of the mirror: RAW (DNG, CR2, NEF, ARW, ...), TIFF, PNG, JPEG or EXR.
    setup : Setup, path-like or str
        The setup it was taken with (predicts the outline).
    write : path-like, optional
        Write the calibrated setup (resolution, pixel pitch, ``sensor.center_offset_px``)
        here as TOML, with a header naming the photo (and its SHA-256) and the fit.
    fit_roll : bool
        Also fit the camera's roll about its axis (tilted mirrors).
    pixel_pitch, white_balance, transfer
        Passed to :func:`mitsweep.io.camera.read_camera_image`; the pitch defaults to the
        file's, else the setup's.

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.photo.Calibration` (``center_px``,
        ``rim_radius_px``, ``predicted_radius_px``, ``fit``, ``calibrated_setup()``...).
        ``summary``: its dict with ``photo``, ``setup``, ``kind``, ``bit_depth``,
        ``pixel_pitch_source``, ``tilted``, ``warnings`` (and ``written``), what
        ``mitsweep calibrate --json`` prints. ``provenance``: ``photo``, its ``sha256``,
        ``setup``, its mirror's ``vertex_distance``, ``pixel_pitch`` and
        ``pixel_pitch_source``, ``image``
        (``kind``, ``bit_depth``), ``version``.

    Raises
    ------
    mitsweep.photo.CalibrationError
        No mirror found, or one whose size disagrees with the setup's prediction by more
        than 35 % (the message says the pitch or distance it implies).
    mitsweep.io.camera.CameraFileError, OSError
        An unreadable photo.

    Examples
    --------
    >>> from mitsweep.workflows import calibrate_camera
    >>> r = calibrate_camera("photo.tif", "paraboloid", write="calibrated.toml")  # doctest: +SKIP
    >>> r.value.center_px                                                         # doctest: +SKIP
    (91.87, 118.97)
    """
    from ..config import setup_to_toml
    from ..io import write_text_atomic
    from ..io.camera import read_camera_image
    from ..photo import calibrate_photo

    setup_path = None if isinstance(setup, Setup) else setup
    check_outputs([photo, setup_path], {"--write": write})
    setup = resolve_setup(setup)
    image = read_camera_image(os.fspath(photo), log_warnings=False, pixel_pitch=pixel_pitch,
                              white_balance=white_balance, transfer=transfer,
                              noise=False)   # no restoration is weighted here
    pitch = image.pixel_pitch or setup.sensor.pixel_pitch
    pitch_source = image.meta.get("pixel_pitch_source") or "setup"
    cal = calibrate_photo(image.data, setup, pixel_pitch=pitch, fit_roll=fit_roll)
    image.log_warnings()  # the photo's quality matters once a mirror is found in it
    out = cal.as_dict()
    out.update(photo=str(photo), setup=setup.name, kind=image.kind,
               bit_depth=image.bit_depth, pixel_pitch_source=pitch_source,
               tilted=not setup.mirror.is_symmetric,
               warnings=list(image.warnings) + list(cal.warnings))
    digest = _sha256(photo)
    if write:
        header = (f"Written by mitsweep calibrate {__version__} from {photo} "
                  f"(sha256 {digest})\nand the setup {setup_path or setup.name}: centre "
                  f"(row, col) = ({cal.center_px[0]:.3f}, {cal.center_px[1]:.3f}) px, rim "
                  f"radius {cal.rim_radius_px:.3f} px\n(setup predicts "
                  f"{cal.predicted_radius_px:.3f} px), {cal.fit.points_used} of "
                  f"{cal.fit.points_total} rim points, rms {cal.fit.residual_rms_px:.3f} px.")
        write_text_atomic(os.fspath(write), setup_to_toml(cal.calibrated_setup(setup), header=header))
        out["written"] = os.fspath(write)
    provenance = {"workflow": "calibrate_camera", "version": __version__,
                  "photo": str(photo), "sha256": digest, "setup": setup.name,
                  "pixel_pitch": pitch, "pixel_pitch_source": pitch_source,
                  "vertex_distance": setup.mirror.vertex_distance,
                  "image": {"kind": image.kind, "bit_depth": image.bit_depth}}
    return WorkflowResult(cal, provenance, out)


def find_mirror_circle(photo: str | os.PathLike, *, pixel_pitch: float | None = None,
                       white_balance: str = "camera", transfer: str | None = None
                       ) -> WorkflowResult:
    """The mirror's outline on a photo as a circle, from the photo alone, and a
    ``[sensor]`` skeleton to start a setup from (``mitsweep calibrate --free``).

    Parameters
    ----------
    photo : path-like
        The photo of the mirror (any camera file).
    pixel_pitch, white_balance, transfer
        Passed to :func:`mitsweep.io.camera.read_camera_image`.

    Returns
    -------
    WorkflowResult
        ``value``: the circle fit (:func:`mitsweep.photo.free.find_circle`'s).
        ``summary``: what ``mitsweep calibrate --free --json`` prints (``center_px``,
        ``radius_px``, ``center_offset_px``, ``setup_skeleton``, fit statistics,
        ``limb`` (the outline was found as a sphere's limb, showing no edge), and
        ``ellipse``: the ellipse through the same edge points,
        :func:`mitsweep.photo.free.ellipse_of_edges`, whose ``significant`` says the
        outline is no circle: a tilted view).
        ``provenance``: ``photo``, ``kind``, ``bit_depth``, ``version``.

    Raises
    ------
    mitsweep.photo.CalibrationError
        No circular outline found.
    mitsweep.io.camera.CameraFileError, OSError
        An unreadable photo.

    Examples
    --------
    >>> from mitsweep.workflows import find_mirror_circle
    >>> print(find_mirror_circle("photo.jpg").summary["setup_skeleton"])  # doctest: +SKIP
    """
    from ..io.camera import read_camera_image
    from ..optics.pixels import optical_center_px
    from ..photo.free import ellipse_of_edges, find_circle

    check_outputs([photo], [])
    image = read_camera_image(os.fspath(photo), log_warnings=False, pixel_pitch=pixel_pitch,
                              white_balance=white_balance, transfer=transfer,
                              noise=False)   # no restoration is weighted here
    fit, radius = find_circle(image.data)
    image.log_warnings()
    H, W = image.shape
    r0, c0 = optical_center_px((H, W))
    offset = (fit.center_px[0] - r0, fit.center_px[1] - c0)
    pitch = image.pixel_pitch
    skeleton = ["[sensor]", f"resolution = [{W}, {H}]"]
    skeleton.append(f"pixel_pitch = {pitch:.6g}" if pitch else
                    "# pixel_pitch = ?  (mm; the file does not say)")
    skeleton.append(f"center_offset_px = [{offset[0]:.3f}, {offset[1]:.3f}]")
    out = {"photo": str(photo), "kind": image.kind, "bit_depth": image.bit_depth,
           "image_shape": [H, W], "center_px": list(fit.center_px), "radius_px": radius,
           "center_offset_px": list(offset), "pixel_pitch_mm": pitch,
           "points_used": fit.points_used, "points_total": fit.points_total,
           "residual_rms_px": fit.residual_rms_px,
           "center_standard_error_px": fit.center_se_px, "limb": fit.limb,
           "setup_skeleton": "\n".join(skeleton) + "\n",
           "ellipse": ellipse_of_edges(fit),
           "warnings": list(image.warnings)}
    provenance = {"workflow": "find_mirror_circle", "version": __version__,
                  "photo": str(photo), "kind": image.kind, "bit_depth": image.bit_depth}
    return WorkflowResult(fit, provenance, out)
