"""Benchmark (issue 24 item 3): ``calibrate_photo`` on large photos, the search on a copy
reduced to the working size then refined at full resolution (the default,
:func:`mitsweep.photo.rim.working_factor`) beside the search at full resolution (the
working size set beyond the photo), in the same process; or (``fixed-smoothing``) the
reduced search refined with the working size's smoothing of the edge profiles rather than
one grown with the reduction (:data:`mitsweep.photo.rim.REFINE_SMOOTHING_GROWS`); or
(``no-concentric``) the reduced search without the starts about a first fit's centre
(:data:`mitsweep.photo.rim.CONCENTRIC_STARTS`).

The photos are the real ones of ``tests/data/real`` enlarged ``k`` times (bilinear): the
same outline with ``k`` times wider edges, as a high-resolution camera's soft edge. The
reference (scikit-image Canny + RANSAC, ``tests/data/real/references.json``) maps to
``(c + 0.5) k - 0.5`` and its tolerance to ``k`` times its own. The setup is the bundled
one of the photo's mirror kind, 9% too large (as ``tests/test_calibrate_real.py``).

Usage::

    .venv/bin/python scripts/bench_large_photos.py [--cases NAME:K ...]
        [--paths reduced full fixed-smoothing no-concentric]

Prints one line per case and path: the photo's size, time (s), the centre's and radius'
errors (px) against the tolerance, PASS / MISS / REFUSED; then, per path, the passes and
the total and largest time. The full-resolution path of sphere_tokyo.jpg x3.5 takes
~5 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from real_corpus import corpus  # noqa: E402

from mitsweep.io.camera import read_camera_image  # noqa: E402
from mitsweep.photo import CalibrationError, calibrate_photo, rim  # noqa: E402

sys.path.insert(0, str(ROOT / "scripts"))
from bench_rough_setups import print_totals, rough_setup, tally  # noqa: E402

CASES = ["sphere_tokyo.jpg:1.5", "sphere_tokyo.jpg:2", "sphere_tokyo.jpg:3.5",
         "sphere_lamp.jpg:2", "sphere_lamp.jpg:3", "sphere_lamp.jpg:4",
         "paraboloid_mei.jpg:2.5", "omni_vmr_clipped.jpg:3", "omni_kaidan.jpg:2",
         "omni_kaidan.jpg:4"]

#: The paths compared (see ``--paths``).
PATHS = ("reduced", "full", "fixed-smoothing", "no-concentric")


def enlarged(name: str, k: float) -> tuple[np.ndarray, dict]:
    """The corpus photo ``name`` enlarged ``k`` times and its reference mapped to it."""
    from skimage.transform import rescale

    entry = next(e for e in corpus(with_outline=True) if e["name"] == name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img = read_camera_image(entry["path"]).data
    img = rescale(img, k, order=1, channel_axis=-1 if img.ndim == 3 else None)
    truth = (np.asarray(entry["centre"]) + 0.5) * k - 0.5
    return img.astype(np.float32), dict(entry, centre=truth, radius=entry["radius"] * k,
                                        tolerance_px=entry["tolerance_px"] * k)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=CASES, help="NAME:K, corpus photo and "
                    "enlargement")
    ap.add_argument("--paths", nargs="+", choices=PATHS, default=["reduced", "full"],
                    help="reduced: the default; full: the search at full resolution; "
                         "fixed-smoothing: reduced, refined with the working size's "
                         "smoothing (rim.REFINE_SMOOTHING_GROWS off); no-concentric: "
                         "reduced, without rim.CONCENTRIC_STARTS")
    args = ap.parse_args(argv)
    logging.getLogger("mitsweep").setLevel(logging.ERROR)   # the calibrations' warnings
    working = rim.WORKING_SIDE_PX
    totals = {p: [0, 0, 0.0, 0.0] for p in args.paths}   # passes, cases, sum, max time
    for case in args.cases:
        name, k = case.rsplit(":", 1)
        img, e = enlarged(name, float(k))
        setup = rough_setup(e, img.shape[:2], 0.09)
        for path in args.paths:
            # the full-resolution search: a working size beyond the photo (factor 1)
            rim.WORKING_SIDE_PX = 10 ** 9 if path == "full" else working
            rim.REFINE_SMOOTHING_GROWS = path != "fixed-smoothing"
            rim.CONCENTRIC_STARTS = path != "no-concentric"
            t0 = time.perf_counter()
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    cal = calibrate_photo(img, setup)
                dc = float(np.abs(np.asarray(cal.center_px) - e["centre"]).max())
                dr = abs(cal.rim_radius_px - e["radius"])
                ok = max(dc, dr) < e["tolerance_px"]
                what = (f"{'PASS' if ok else 'MISS':7s} centre {dc:6.2f} radius {dr:6.2f} px "
                        f"(tolerance {e['tolerance_px']:.2f})")
            except CalibrationError as exc:
                ok, what = False, f"REFUSED {str(exc)[:60]}"
            finally:
                rim.WORKING_SIDE_PX, rim.REFINE_SMOOTHING_GROWS = working, True
                rim.CONCENTRIC_STARTS = True
            dt = time.perf_counter() - t0
            tally(totals[path], ok, dt)
            H, W = img.shape[:2]
            print(f"{name:22s} x{float(k):<4g} {W}x{H} {path:8s} {dt:7.2f} s  {what}",
                  flush=True)
    print_totals(totals)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
