"""The corpus of real photographs of curved mirrors in ``tests/data/real/``, as data.

A plain module (no tests here) so that any test can ``from real_corpus import corpus``,
the way the other helpers in this folder (``camera_files``, ``rig_fixtures``) are
imported. Where each file came from, its licence and its SHA-256 are in
``tests/data/real/SOURCES.md``; the reference outlines are in
``tests/data/real/references.json``, measured by ``tests/test_real_corpus.py``
(scikit-image Canny edges in a hand-picked annulus, a RANSAC circle or, for an
elliptical outline, ellipse, a least-squares refit; no mitsweep code) and checked
against the photos there on every test run.

Each entry of :func:`corpus` is a dict:

``name``, ``path`` (absolute :class:`~pathlib.Path`), ``format`` ("jpeg", "png", "raw"),
``shape`` ((H, W) as stored), ``mirror`` ("sphere", "paraboloid", "unknown", or None for
the RAW file, which shows no mirror), ``outline`` ("sphere limb", "rim" or None),
``clipped`` (list of the frame sides the outline crosses: "top", "bottom", "left",
"right"; empty when the whole outline is in the frame), ``bright_rim`` (bool: specular
highlights sit on the outline), ``centre`` ((row, col) px, or None), ``radius`` (px, or
None), ``tolerance_px`` (how far a measurement of the centre or the radius may be from
the reference and still agree; None without a reference), ``sd_px`` (the spread of the
reference measurement itself), ``camera`` (str or None), ``note`` (str), and where the
outline is an ellipse (the reference measured with scikit-image's ``EllipseModel``;
``radius`` is then the mean of its semi-axes, ``centre`` its centre): ``semi_axes``
((major, minor) px), ``axes_tolerance_px`` and ``angle_deg`` (the major axis, from the
+column axis toward +row); None for a circle.

Pixel convention: row/column of pixel centres, (0, 0) the top-left pixel's centre, as in
NumPy indexing (scikit-image's convention); the radius is in the stored file's pixels.
"""

from __future__ import annotations

import json
from pathlib import Path

DATA = Path(__file__).resolve().parent / "data" / "real"
REFERENCES = DATA / "references.json"
SOURCES = DATA / "SOURCES.md"


def corpus(*, with_outline: bool | None = None) -> list[dict]:
    """The corpus entries (see the module docstring), in a fixed order.

    Parameters
    ----------
    with_outline : bool, optional
        True: only photos with a reference outline (the mirrors); False: only those
        without (the RAW file kept for the read path); None: all.
    """
    refs = json.loads(REFERENCES.read_text(encoding="utf-8"))
    out = []
    for name, r in refs["photos"].items():
        ref = r.get("reference")
        if with_outline is not None and (ref is not None) != with_outline:
            continue
        out.append({
            "name": name,
            "path": DATA / name,
            "format": r["format"],
            "shape": tuple(r["shape"]),
            "mirror": r.get("mirror"),
            "outline": r.get("outline"),
            "clipped": list(ref["clipped"]) if ref else [],
            "bright_rim": bool(r.get("bright_rim", False)),
            "centre": tuple(ref["centre"]) if ref else None,
            "radius": float(ref["radius"]) if ref else None,
            "tolerance_px": float(ref["tolerance_px"]) if ref else None,
            "sd_px": float(ref["sd_px"]) if ref else None,
            "camera": r.get("camera"),
            "note": r.get("note", ""),
            "semi_axes": tuple(ref["semi_axes_px"]) if ref and "semi_axes_px" in ref else None,
            "axes_tolerance_px": ref.get("axes_tolerance_px") if ref else None,
            "angle_deg": ref.get("angle_deg") if ref else None,
        })
    return out
