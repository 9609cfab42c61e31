"""Benchmark (issue 24 item 2): ``calibrate_photo`` with a roughly right setup on the real
photographs of ``tests/data/real`` (other people's cameras and mirrors), error and time,
the single-start rim search (``starts=1``: the outline nearest the prediction only) beside
the default (several starting points, each refined twice) in the same process.

The setup is the bundled one of the photo's mirror kind with its pitch chosen so that the
predicted outline is ``1 + guess`` times the reference's (as
``tests/test_calibrate_real.py`` builds it); the error is the larger of the centre's and
the radius's distance from the independent reference (scikit-image Canny + RANSAC,
``tests/data/real/references.json``), and a case passes within the reference's tolerance.

Usage::

    .venv/bin/python scripts/bench_rough_setups.py [--guesses 0.09 -0.35 0.35]
        [--photos NAME ...] [--starts 1 6]

Prints one line per photo, guess and ``starts``: time (s), error (px) or what refused
it, and PASS / MISS / REFUSED; then, per ``starts``, the passes and the total and
largest time.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from real_corpus import corpus  # noqa: E402

from mitsweep.config import Sensor, load_setup  # noqa: E402
from mitsweep.io.camera import read_camera_image  # noqa: E402
from mitsweep.optics.outline import predicted_outline  # noqa: E402
from mitsweep.photo import CalibrationError, calibrate_photo  # noqa: E402
from mitsweep.photo.coarse import MAX_CANDIDATES  # noqa: E402


def rough_setup(entry: dict, shape: tuple[int, int], guess: float):
    """The bundled setup of the photo's mirror kind whose outline is ``1 + guess`` times
    the reference's."""
    name = "sphere" if entry["mirror"] == "sphere" else "paraboloid"
    base = load_setup(ROOT / "scenes" / f"{name}.toml")
    H, W = shape
    pitch = predicted_outline(base).equivalent_radius_px(1.0) / (entry["radius"] * (1 + guess))
    return replace(base, sensor=Sensor(resolution=(W, H), pixel_pitch=pitch))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--guesses", type=float, nargs="+", default=[0.09, -0.35, 0.35])
    ap.add_argument("--photos", nargs="+", help="corpus names (default: all with an outline)")
    ap.add_argument("--starts", type=int, nargs="+", default=[1, MAX_CANDIDATES])
    args = ap.parse_args(argv)
    logging.getLogger("mitsweep").setLevel(logging.ERROR)   # the calibrations' warnings
    entries = [e for e in corpus(with_outline=True)
               if not args.photos or e["name"] in args.photos]
    totals = {s: [0, 0, 0.0, 0.0] for s in args.starts}   # passes, cases, sum, max time
    warm = True   # the first calibration, untimed, loads what both paths import
    for e in entries:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            img = read_camera_image(e["path"]).data
        for guess in args.guesses:
            setup = rough_setup(e, img.shape[:2], guess)
            if warm:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        calibrate_photo(img, setup, starts=1)
                except CalibrationError:
                    pass
                warm = False
            for starts in args.starts:
                t0 = time.perf_counter()
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        cal = calibrate_photo(img, setup, starts=starts)
                    err = max(float(np.abs(np.asarray(cal.center_px) - e["centre"]).max()),
                              abs(cal.rim_radius_px - e["radius"]))
                    ok = err < e["tolerance_px"]
                    what = f"{'PASS' if ok else 'MISS':7s} error {err:7.2f} px"
                except CalibrationError as exc:
                    ok, what = False, f"REFUSED {str(exc)[:60]}"
                dt = time.perf_counter() - t0
                tally(totals[starts], ok, dt)
                print(f"{e['name']:28s} {guess:+.2f} starts {starts}  {dt:6.2f} s  {what}",
                      flush=True)
    print_totals({f"starts {s}": tot for s, tot in totals.items()})
    return 0


def tally(tot: list, ok: bool, seconds: float) -> None:
    """Count one case into ``tot`` = [passes, cases, total time, largest time]."""
    tot[0] += ok
    tot[1] += 1
    tot[2] += seconds
    tot[3] = max(tot[3], seconds)


def print_totals(totals: dict) -> None:
    """One line per search: its passes, cases, total and largest time."""
    for name, (ok, n, total, worst) in totals.items():
        print(f"{name}: {ok} of {n} within tolerance, {total:.1f} s in all, "
              f"{worst:.1f} s at most")


if __name__ == "__main__":
    raise SystemExit(main())
