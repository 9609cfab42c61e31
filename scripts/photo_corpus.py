"""The real-photo corpus table (issue 24): every photograph of ``tests/data/real`` with an
outline, its reference (scikit-image Canny + RANSAC, ``tests/data/real/references.json``)
and what ``calibrate`` makes of it: ``--free`` (no setup,
:func:`mitsweep.photo.free.find_circle`) and a rough setup whose predicted outline is
+9 %, −35 % and +35 % off the photo's (:func:`mitsweep.photo.calibrate_photo`, the
default search), each with its error and wall time.

The error is the larger of the centre's largest coordinate difference and the radius
difference from the reference, px (what ``tests/test_calibrate_real.py`` asserts against
the reference's tolerance); for an outline found as an ellipse, the radius of the circle
of its area.

Usage::

    .venv/bin/python scripts/photo_corpus.py [--json docs/reference/photo_corpus.json]
        [--photos NAME ...]

Prints the Markdown table of ``docs/reference/photos.md`` and, with ``--json``, writes
the measurements it is checked against (``tests/doc_figures.py``, figure
``photo-corpus``). About four minutes on two cores.
"""

from __future__ import annotations

import argparse
import json
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

from bench_rough_setups import rough_setup  # noqa: E402
from real_corpus import corpus  # noqa: E402

from mitsweep.io.camera import read_camera_image  # noqa: E402
from mitsweep.photo import CalibrationError, calibrate_photo  # noqa: E402
from mitsweep.photo.free import find_circle  # noqa: E402

#: The rough setups' errors of the predicted outline's size (``1 + guess`` times the
#: photo's), as in tests/test_calibrate_real.py.
GUESSES = (0.09, -0.35, 0.35)


def _error(entry: dict, centre, radius: float) -> float:
    return max(float(np.abs(np.asarray(centre) - entry["centre"]).max()),
               abs(float(radius) - entry["radius"]))


def measure(entry: dict) -> dict:
    """One photo's row: its reference, and per path the error (px; None where refused),
    whether it is within the reference's tolerance, the time (s) and what refused it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img = read_camera_image(entry["path"], noise=False).data
    runs = {}
    paths = [("free", None)] + [(f"{g:+.2f}", g) for g in GUESSES]
    for key, guess in paths:
        t0 = time.perf_counter()
        err, refused = None, None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if guess is None:
                    fit, radius = find_circle(img)
                    err = _error(entry, fit.center_px, radius)
                else:
                    cal = calibrate_photo(img, rough_setup(entry, img.shape[:2], guess))
                    err = _error(entry, cal.center_px, cal.rim_radius_px)
        except CalibrationError as exc:
            refused = str(exc)
        runs[key] = {"error_px": err, "refused": refused,
                     "within_tolerance": err is not None and err < entry["tolerance_px"],
                     "time_s": time.perf_counter() - t0}
    H, W = entry["shape"]
    return {"name": entry["name"], "mirror": entry["mirror"], "outline": entry["outline"],
            "size_px": [W, H], "format": entry["format"], "clipped": entry["clipped"],
            "bright_rim": entry["bright_rim"], "centre_px": list(entry["centre"]),
            "radius_px": entry["radius"], "tolerance_px": entry["tolerance_px"],
            "semi_axes_px": entry["semi_axes"], "runs": runs}


def table(rows: list[dict]) -> str:
    """The Markdown table of the measured rows."""
    def cell(run: dict) -> str:
        t = f"({run['time_s']:.1f} s)"
        if run["error_px"] is None:
            return f"refused {t}"
        return f"{run['error_px']:.2f}{'' if run['within_tolerance'] else ' miss'} {t}"

    head = ("| photo | mirror, outline | size (px), format | reference centre (row, col) | "
            "radius | tolerance | `--free` | +9 % | −35 % | +35 % |")
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        kind = f"{r['mirror']}, {r['outline'].replace('sphere limb', 'limb')}"
        axes = r.get("semi_axes_px") or (0.0, 0.0)
        extra = [w for w, on in ((f"clipped {'/'.join(r['clipped'])}", r["clipped"]),
                                 ("bright rim", r["bright_rim"]),
                                 (f"an ellipse {axes[0]:.1f}/{axes[1]:.1f}, radius their "
                                  "mean", r.get("semi_axes_px"))) if on]
        if extra:
            kind += f" ({', '.join(extra)})"
        W, H = r["size_px"]
        cr, cc = r["centre_px"]
        lines.append(f"| {r['name']} | {kind} | {W}×{H}, {r['format'].upper()} | "
                     f"{cr:.2f}, {cc:.2f} | {r['radius_px']:.2f} | {r['tolerance_px']:.2f} | "
                     + " | ".join(cell(r["runs"][k]) for k in
                                  ["free"] + [f"{g:+.2f}" for g in GUESSES]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", type=Path, help="write the measurements here")
    ap.add_argument("--photos", nargs="+", help="corpus names (default: all with an outline)")
    args = ap.parse_args(argv)
    logging.getLogger("mitsweep").setLevel(logging.ERROR)   # the calibrations' warnings
    entries = [e for e in corpus(with_outline=True)
               if not args.photos or e["name"] in args.photos]
    rows = []
    for e in entries:
        rows.append(measure(e))
        print(f"# {e['name']}: " + ", ".join(
            f"{k} {'refused' if v['error_px'] is None else format(v['error_px'], '.2f')}"
            for k, v in rows[-1]["runs"].items()), file=sys.stderr, flush=True)
    print(table(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
