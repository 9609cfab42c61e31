"""The calibration's errors on the synthetic photos of ``tests/test_calibrate.py``.

Makes each photo the test makes (230×262 px frames with the mirror's axis offset by
(6.37, −9.81) px, a dark holder, an arm, a textured background and vignetting; 16-bit
sRGB TIFF, 8-bit JPEG and DNG), runs ``mitsweep calibrate --json`` on it with the setup
and prints each case's centre error (the largest of the row and column errors, px) and
rim-radius error (measured against predicted, px), and the worst of each per setup.
docs/reference/photos.md's first table is this output (``tests/test_doc_figures.py``).

Usage: ``.venv/bin/python scripts/calibration_errors.py [--json]`` (about 20 s).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from camera_files import synthetic_mirror_photo  # noqa: E402
from test_calibrate import (CASES, FRAME, OFFSET, save_photo, setup_file,  # noqa: E402
                            small_setup, true_centre)

from mitsweep.cli.main import main as mitsweep_main  # noqa: E402


def calibration_errors() -> dict:
    """Per case and per setup, the centre and rim-radius errors (px)."""
    cases, photos = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, kind in CASES:
            if name not in photos:      # as the test's fixture: one photo per setup
                photos[name] = synthetic_mirror_photo(small_setup(name), FRAME, OFFSET,
                                                      supersample=2)
            photo = save_photo(photos[name], Path(tmp) / f"{name}.{kind}", kind)
            setup = setup_file(Path(tmp), small_setup(name), f"{name}.toml")
            printed = io.StringIO()
            with contextlib.redirect_stdout(printed):
                rc = mitsweep_main(["calibrate", str(photo), "--setup", str(setup), "--json"])
            if rc != 0:
                raise RuntimeError(f"calibrate {name} {kind}: exit {rc}: {printed.getvalue()}")
            out = json.loads(printed.getvalue())
            centre = float(np.abs(np.asarray(out["center_px"]) - true_centre()).max())
            radius = abs(out["rim_radius_px"] - out["predicted_rim_radius_px"])
            cases.append({"setup": name, "file": kind, "centre_error_px": centre,
                          "radius_error_px": radius})
    worst = {name: {"centre_error_px": max(c["centre_error_px"] for c in cases
                                           if c["setup"] == name),
                    "radius_error_px": max(c["radius_error_px"] for c in cases
                                           if c["setup"] == name)}
             for name in dict.fromkeys(c["setup"] for c in cases)}
    return {"frame_px": list(FRAME), "offset_px": list(OFFSET), "cases": cases,
            "worst": worst}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    a = ap.parse_args(argv)
    result = calibration_errors()
    if a.json:
        print(json.dumps(result, indent=1))
        return 0
    for c in result["cases"]:
        print(f"{c['setup']:18s} {c['file']:4s} centre {c['centre_error_px']:.3f} px, "
              f"radius {c['radius_error_px']:.3f} px")
    for name, w in result["worst"].items():
        print(f"worst {name}: centre {w['centre_error_px']:.3f} px, "
              f"radius {w['radius_error_px']:.3f} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
