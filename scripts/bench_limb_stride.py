"""Benchmark: a large photo's limb refined at full resolution on every pixel of its annulus
(``stride`` 1, as before) beside every ``f``-th pixel row and column (``f`` the reduction
its search ran at: what :func:`mitsweep.photo.rim.refine_at_full_resolution` and
``--free`` do now, :func:`mitsweep.photo.limb.fit_limb`'s ``stride``), in one process.

Cases: scikit-image's ``camera`` photo (no mirror) enlarged 9.5 times (4864², 24 MP):
``--free`` finds a limb on the copy reduced 5 times and looks for it again at full
resolution, where it is refused; the PAGEOS balloon of ``tests/data/real`` enlarged 2
times (1600x2000), with the bundled sphere setup 9% too large. Each line: the case, the
path, the wall time and the outcome (the error against the reference for PAGEOS).

Usage::

    .venv/bin/python scripts/bench_limb_stride.py [--cases camera pageos]

About four minutes on two cores (three of them the camera photo on every pixel).
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
sys.path.insert(0, str(ROOT / "scripts"))

import bench_large_photos  # noqa: E402
from sample_photos import sample_photo  # noqa: E402
from test_calibrate_real import _rough_setup  # noqa: E402

import mitsweep.photo.limb as limb  # noqa: E402
from mitsweep.photo import calibrate_photo  # noqa: E402
from mitsweep.photo.free import find_circle  # noqa: E402
from mitsweep.photo.rim import CalibrationError  # noqa: E402


def _camera_24mp() -> np.ndarray:
    from scipy.ndimage import zoom

    small = sample_photo("camera")
    return np.stack([zoom(small[..., c], 9.5, order=1) for c in range(3)],
                    axis=-1).astype(np.float32)


def cases(names):
    """(name, run) pairs: ``run()`` returns the outcome's text."""
    if "camera" in names:
        img = _camera_24mp()

        def camera():
            try:
                fit, radius = find_circle(img)
            except CalibrationError as exc:
                return f"refused: {str(exc)[:90]}"
            return f"found: centre {fit.center_px}, radius {radius:.1f} px"
        yield f"camera x9.5 {img.shape[1]}x{img.shape[0]} --free", camera
    if "pageos" in names:
        big, entry = bench_large_photos.enlarged("sphere_pageos_nasa.png", 2)
        setup = _rough_setup(entry, big.shape[:2], 0.09)

        def pageos():
            cal = calibrate_photo(big, setup)
            err = max(np.abs(np.subtract(cal.center_px, entry["centre"])).max(),
                      abs(cal.rim_radius_px - entry["radius"]))
            return (f"{'limb' if cal.fit.limb else 'edge'}, error {err:.2f} px "
                    f"(tolerance {entry['tolerance_px']:.2f})")
        yield f"pageos x2 {big.shape[1]}x{big.shape[0]} setup +9%", pageos


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=["camera", "pageos"],
                    choices=["camera", "pageos"])
    args = ap.parse_args(argv)
    for name in ("mitsweep.io.camera", "mitsweep.photo.calibrate"):   # the known warnings
        logging.getLogger(name).setLevel(logging.ERROR)
    fit_limb = limb.fit_limb

    def every_pixel(*a, **k):
        return fit_limb(*a, **{**k, "stride": 1})

    for name, run in cases(args.cases):
        for path, fn in (("stride f", fit_limb), ("stride 1", every_pixel)):
            limb.fit_limb = fn   # the callers import it from the module at call time
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = time.perf_counter()
                outcome = run()
                dt = time.perf_counter() - t
            print(f"{name:36s} {path:8s} {dt:7.1f} s  {outcome}", flush=True)
        limb.fit_limb = fit_limb
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
