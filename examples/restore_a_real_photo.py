"""Restore a photo from a real camera: read it, calibrate it, deconvolve it, unwarp it.

Without a rig at hand the "photo" is made here as a camera would: a Mitsuba focal-sweep
render of the paper's paraboloid (:func:`mitsweep.render.render_image`), placed in a
larger frame with its optical axis off the frame's centre by a known sub-pixel offset
(as a camera whose axis is not exactly on the mirror's would see it), encoded as sRGB in
a 16-bit TIFF (``photo.tif``). Then, as for a real file:

1. :func:`mitsweep.io.camera.read_camera_image`: decoded to linear values (the TIFF's
   sRGB transfer undone);
2. :func:`mitsweep.workflows.calibrate_photo`: the mirror's centre and rim
   radius on the photo, and the setup for this camera (``calibrated.toml``:
   resolution, pitch, centre offset);
3. :func:`mitsweep.workflows.restore_photo`: the IPSF bank of the photo's geometry
   (traced and cached) and the deconvolution about the calibrated centre
   (``restored.exr``, with its provenance);
4. :func:`mitsweep.workflows.unwarp_image`: the cylindrical panorama of the restored
   image (``panorama.png``).

Run::

    python examples/restore_a_real_photo.py                 # 200 px render, 128 spp
    python examples/restore_a_real_photo.py --photo my.tif --setup scenes/paraboloid.toml

Measured (2 loaded cores): centre found 0.088 px from the true one, rim radius 74.29 px
against the predicted 74.16 px, panorama 466 × 283 px, in 14 s all told; ``--quick``
(160 px, 48 spp): 0.081 px, rim 59.44 against 59.33 px, in 8 s.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Where the render goes in the frame: integer rows/cols of its top-left corner, plus a
#: sub-pixel shift (row, col).
PLACE = (12, 40)
SUBPIXEL = (0.37, -0.61)


def make_photo(path: Path, setup, *, spp: int, seed: int = 3) -> tuple[float, float]:
    """Write a 16-bit sRGB TIFF of a sweep render placed off-centre in a larger frame;
    return the true optical centre on it (row, col), px."""
    import tifffile
    from scipy.ndimage import fourier_shift

    from mitsweep.io.png import linear_to_srgb
    from mitsweep.optics.pixels import optical_center_px
    from mitsweep.render import render_image

    res = render_image(setup, "sweep", spp=spp, seed=seed, mirror_only=False)
    H, W = res.image.shape[:2]
    frame = np.zeros((H + 30, W + 62, 3))
    top, left = PLACE
    frame[top:top + H, left:left + W] = res.image
    frame = np.stack([np.real(np.fft.ifft2(fourier_shift(np.fft.fft2(frame[..., c]),
                                                         SUBPIXEL)))
                      for c in range(3)], axis=-1)
    linear = np.clip(frame / frame.max() * 0.9, 0.0, 1.0)
    tifffile.imwrite(path, np.round(linear_to_srgb(linear) * 65535).astype(np.uint16),
                     photometric="rgb")
    row, col = optical_center_px((H, W))
    return row + top + SUBPIXEL[0], col + left + SUBPIXEL[1]


def restore(photo_path: Path, setup, out: Path, *, rays: int) -> dict:
    """Calibrate, restore and unwarp the photo with the library's workflows (what
    ``mitsweep calibrate``, ``deconvolve`` and ``unwarp`` run)."""
    from mitsweep.config import setup_to_toml
    from mitsweep.io.camera import read_camera_image
    from mitsweep.workflows import calibrate_photo, restore_photo, unwarp_image

    photo = read_camera_image(photo_path, pixel_pitch=setup.sensor.pixel_pitch)
    cal = calibrate_photo(photo.data, setup)
    calibrated = cal.calibrated_setup(setup)
    (out / "calibrated.toml").write_text(setup_to_toml(calibrated))
    # the bank of the photo's geometry is traced about the calibrated centre and cached
    restored = restore_photo(photo_path, setup=calibrated, out=out / "restored.exr",
                             depth=1000.0, rays=rays, pixel_pitch=setup.sensor.pixel_pitch,
                             cache_dir=out / "bank_cache")
    # the restored image carries its setup, centre and pitch: the panorama reads them
    pano = unwarp_image(out / "restored.exr", out / "panorama.png", projection="cylindrical")
    panorama, valid = pano.value
    return {"calibration": cal.as_dict(), "nsr": restored.provenance["nsr"],
            "center_from": restored.provenance["center_from"],
            "panorama_shape": list(panorama.shape),
            "panorama_valid_fraction": float(valid.mean()), "out": str(out)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--photo", type=Path,
                    help="a photo of the mirror (TIFF, PNG, JPEG, RAW; default: make one)")
    ap.add_argument("--setup", type=Path, default=ROOT / "scenes" / "paraboloid.toml",
                    help="the setup it was taken with")
    ap.add_argument("--size", type=int, default=200, help="the made photo's render, px")
    ap.add_argument("--spp", type=int, default=128, help="its samples per pixel")
    ap.add_argument("--out", type=Path, help="output directory (default: a new temp dir)")
    ap.add_argument("--quick", action="store_true", help="160 px, 48 spp (for the tests)")
    ap.add_argument("--json", action="store_true", help="print the result as JSON")
    args = ap.parse_args(argv)
    from mitsweep.config import load_setup

    out = args.out or Path(tempfile.mkdtemp(prefix="mitsweep_photo_"))
    out.mkdir(parents=True, exist_ok=True)
    setup = load_setup(args.setup)
    truth = None
    if args.photo is None:
        size, spp = (160, 48) if args.quick else (args.size, args.spp)
        # the sensor area of the calibration tests: the mirror's image ~74 px in radius
        # at 200 px; the pitch scales with the size
        sensor = dataclasses.replace(setup.sensor, resolution=(size, size),
                                     pixel_pitch=0.06 * 200 / size)
        setup = dataclasses.replace(setup, sensor=sensor)
        args.photo = out / "photo.tif"
        truth = make_photo(args.photo, setup, spp=spp)
    result = restore(args.photo, setup, out, rays=1 << 14 if args.quick else 1 << 17)
    c = result["calibration"]
    if truth is not None:
        result["true_center_px"] = list(truth)
        result["center_error_px"] = float(np.hypot(c["center_px"][0] - truth[0],
                                                   c["center_px"][1] - truth[1]))
    if args.json:
        json.dump(result, sys.stdout, indent=1)
        print()
        return 0
    print(f"photo         {args.photo} ({c['image_shape'][1]}x{c['image_shape'][0]} px)")
    print(f"calibrated    centre ({c['center_px'][0]:.2f}, {c['center_px'][1]:.2f}) px, rim "
          f"{c['rim_radius_px']:.2f} px (predicted {c['predicted_rim_radius_px']:.2f} px)")
    if truth is not None:
        print(f"true centre   ({truth[0]:.2f}, {truth[1]:.2f}) px: off by "
              f"{result['center_error_px']:.3f} px")
    print(f"restored      Wiener, NSR {result['nsr']}, centre from {result['center_from']} -> "
          f"{out / 'restored.exr'}")
    print(f"panorama      {result['panorama_shape'][1]}x{result['panorama_shape'][0]} px -> "
          f"{out / 'panorama.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
