"""The corpus of real photographs of curved mirrors (tests/data/real/, issue 24 item 5).

Three checks on every file: its SHA-256 is the one ``SOURCES.md`` records; it reads
through :func:`mitsweep.io.camera.read_camera_image` as a finite image of the recorded
shape; and for the mirrors, the reference outline in ``references.json`` is measured
again here, from the pixels, and agrees with the record within the stated tolerance.

The reference outline is measured by a method that shares nothing with
``mitsweep.optics.calibration``: the photo is read with Pillow, made grey, and
scikit-image's Canny detector is run inside an annulus picked by eye (its centre guess,
inner and outer radius and any excluded angular sectors are in :data:`PHOTOS`, and copied
into the JSON); a circle is fitted to those edge pixels by RANSAC
(:class:`skimage.measure.CircleModel`) and refitted by least squares on the inliers, or,
where the spec says ``model="ellipse"`` (an outline a circle does not describe: the
dome's), an ellipse (:class:`skimage.measure.EllipseModel`, its residuals the Sampson
distance, see :func:`_ellipse_model`), whose centre and mean semi-axis are the
reference's centre and radius.
Its uncertainty ``sd_px`` combines the spread over :data:`SEEDS` RANSAC seeds with a
bootstrap of the inliers (:data:`BOOTSTRAP` resamples); the tolerance is
``3 * sd_px + EDGE_FLOOR_PX`` (Canny localises an edge to about half a pixel, which no
resampling shows). Each fit was checked by eye on an overlay (``--overlay DIR``).

Angles (``exclude_deg``) are measured from the +column axis toward +row (clockwise on
screen, 0 = right, 90 = down), in degrees, around the annulus's centre guess.

Run as a script to measure again and rewrite the record, or to draw the overlays::

    .venv/bin/python tests/test_real_corpus.py --write
    .venv/bin/python tests/test_real_corpus.py --overlay /tmp/overlays
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # when run as a script
from real_corpus import DATA, REFERENCES, SOURCES, corpus  # noqa: E402

#: RANSAC seeds whose spread enters the uncertainty.
SEEDS = (0, 1, 2)
#: Bootstrap resamples of the inliers.
BOOTSTRAP = 16
#: Edge-localisation floor added to the tolerance, px.
EDGE_FLOOR_PX = 0.5
#: RANSAC trials per seed.
TRIALS = 250

#: Per photo: what it shows and where to look for its outline. ``spec`` is None for a
#: file without a mirror. ``annulus``: (r_in, r_out) px around ``centre_guess`` (row,
#: col); ``sigma``: Canny's Gaussian; ``threshold``: RANSAC residual threshold, px;
#: ``exclude_deg``: angular sectors (start, end) left out (occluders, mounts, reflections
#: that form stronger circles than the outline).
PHOTOS: dict[str, dict] = {
    "sphere_lamp.jpg": dict(
        format="jpeg", mirror="sphere", outline="sphere limb", bright_rim=False,
        camera=None,
        note="chrome sphere on a lamp post against the sky; the post occludes the "
             "bottom of the limb (excluded sector)",
        spec=dict(centre_guess=(518, 515), annulus=(455, 505), sigma=2.0, threshold=1.5,
                  exclude_deg=[(55, 125)]),
    ),
    "sphere_tokyo.jpg": dict(
        format="jpeg", mirror="sphere", outline="sphere limb", bright_rim=True,
        camera="Google Pixel 6 Pro",
        note="large public mirror sphere filling the frame; the limb comes within a few "
             "pixels of the left, top and right edges; bright sky on the upper limb",
        spec=dict(centre_guess=(588, 600), annulus=(550, 600), sigma=2.0, threshold=1.5,
                  exclude_deg=[]),
    ),
    "dome_store_bright_rim.jpg": dict(
        format="jpeg", mirror="sphere", outline="rim", bright_rim=True,
        camera="Google Pixel 6 Pro",
        note="convex shop-surveillance dome seen from below; the ceiling lights make a "
             "bright ring along the rim; profile assumed spherical (not stated). The "
             "outline is the outer edge of the grazing-reflection band against the "
             "ceiling (an annulus of 566-592 px first took a stripe inside the band, "
             "12 px in). It is an ellipse (semi-axes 595.4/587.2 px, 8 px apart: the "
             "dome's rim seen ~10 deg off its axis), so the reference is an ellipse: "
             "RANSAC with a circle at the same 1.5 px threshold keeps 2859 of the 6460 "
             "edge pixels, the sectors nearest one radius, and its centre lies 2.3 px "
             "from the ellipse's in column; the ellipse keeps 3291, rms 0.65 px",
        spec=dict(centre_guess=(611, 612), annulus=(582, 604), sigma=2.0, threshold=1.5,
                  exclude_deg=[], model="ellipse"),
    ),
    "sphere_pageos_nasa.png": dict(
        format="png", mirror="sphere", outline="sphere limb", bright_rim=True,
        camera="film, NASA 1965",
        note="PAGEOS balloon satellite (aluminised Mylar) inflated in a hangar; grey "
             "8-bit PNG; hangar lights reflected at the limb; the top of the limb is "
             "hidden by draped Mylar (excluded sector) and the balloon is only nearly "
             "spherical",
        spec=dict(centre_guess=(450, 398), annulus=(330, 372), sigma=2.0, threshold=1.5,
                  exclude_deg=[(190, 350)]),
    ),
    "paraboloid_mei.jpg": dict(
        format="jpeg", mirror="paraboloid", outline="rim", bright_rim=False,
        camera=None,
        note="C. Mei's parabolic catadioptric calibration images (img_para_*), as "
             "shipped in OCamCalib; grey 8-bit JPEG",
        spec=dict(centre_guess=(496, 640), annulus=(300, 400), sigma=2.0, threshold=1.5,
                  exclude_deg=[]),
    ),
    "paraboloid_mei_2.jpg": dict(
        format="jpeg", mirror="paraboloid", outline="rim", bright_rim=False,
        camera=None,
        note="a second image of the same parabolic rig as paraboloid_mei.jpg (another "
             "calibration-board pose): the same rim, a consistency check",
        spec=dict(centre_guess=(496, 640), annulus=(300, 400), sigma=2.0, threshold=1.5,
                  exclude_deg=[]),
    ),
    "omni_kaidan.jpg": dict(
        format="jpeg", mirror="unknown", outline="rim", bright_rim=False,
        camera=None,
        note="Kaidan 360 One VR omnidirectional mirror (profile not stated) in "
             "OCamCalib's sample set; the mirror's black mount is cut by the top and bottom of the"
             " frame, the reflective rim itself (measured) is whole",
        spec=dict(centre_guess=(244, 324), annulus=(205, 245), sigma=1.5, threshold=1.5,
                  exclude_deg=[]),
    ),
    "omni_vmr_clipped.jpg": dict(
        format="jpeg", mirror="unknown", outline="rim", bright_rim=False,
        camera=None,
        note="catadioptric camera ('VMR' images in OCamCalib's sample set, mirror "
             "profile not stated); the rim is cut by the top and bottom of the frame",
        spec=dict(centre_guess=(384, 520), annulus=(425, 470), sigma=2.0, threshold=1.5,
                  exclude_deg=[]),
    ),
    "kodak_dc50_no_mirror.kdc": dict(
        format="raw", mirror=None, outline=None, bright_rim=False,
        camera="Kodak DC50 Zoom",
        note="a real RAW file for the read path only: it shows buildings, no mirror",
        spec=None,
    ),
}


# ------------------------------------------------------------------- the measurement

def _grey(path: Path) -> np.ndarray:
    """The photo as grey float64 in [0, 1], read with Pillow (not mitsweep)."""
    from PIL import Image

    with Image.open(path) as im:
        return np.asarray(im.convert("L"), dtype=np.float64) / 255.0


def _circle_fit(points: np.ndarray):
    """Least-squares circle through (x, y) points: (xc, yc, r), or None."""
    from skimage.measure import CircleModel

    if hasattr(CircleModel, "from_estimate"):  # scikit-image >= 0.26
        m = CircleModel.from_estimate(points)
        if not m:
            return None
        return float(m.center[0]), float(m.center[1]), float(m.radius)
    m = CircleModel()
    if not m.estimate(points):
        return None
    xc, yc, r = m.params
    return float(xc), float(yc), float(r)


def edge_points(grey: np.ndarray, spec: dict) -> np.ndarray:
    """Canny edge pixels inside the spec's annulus and allowed sectors, as (x=col, y=row)."""
    from skimage import feature

    h, w = grey.shape
    rc, cc = spec["centre_guess"]
    r_in, r_out = spec["annulus"]
    rows, cols = np.mgrid[0:h, 0:w]
    rad = np.hypot(rows - rc, cols - cc)
    mask = (rad >= r_in) & (rad <= r_out)
    edges = feature.canny(grey, sigma=spec["sigma"], mask=mask)
    er, ec = np.nonzero(edges)
    ang = np.degrees(np.arctan2(er - rc, ec - cc)) % 360.0
    keep = np.ones(er.shape, bool)
    for a0, a1 in spec["exclude_deg"]:
        keep &= ~((ang >= a0) & (ang <= a1))
    # Canny marks the frame's own border when the mirror is cut by it: drop 2 px there.
    keep &= (er >= 2) & (er <= h - 3) & (ec >= 2) & (ec <= w - 3)
    return np.column_stack([ec[keep], er[keep]]).astype(np.float64)


def _ellipse_fit(points: np.ndarray):
    """Least-squares ellipse through (x, y) points: (xc, yc, (a + b) / 2, a, b, theta),
    or None. ``(a + b) / 2`` is the radius of the least-squares circle through points
    spread evenly round a nearly circular ellipse (to first order in ``a - b``), the
    number compared with a circle's radius."""
    from skimage.measure import EllipseModel

    if hasattr(EllipseModel, "from_estimate"):  # scikit-image >= 0.26
        m = EllipseModel.from_estimate(points)
        if not m:
            return None
        (xc, yc), (a, b), theta = m.center, m.axis_lengths, m.theta
    else:
        m = EllipseModel()
        if not m.estimate(points):
            return None
        xc, yc, a, b, theta = m.params
    if a < b:   # the major semi-axis first, its angle with it
        a, b, theta = b, a, theta + np.pi / 2.0
    return float(xc), float(yc), float(a + b) / 2.0, float(a), float(b), float(theta)


def _ellipse_model():
    """scikit-image's ``EllipseModel`` whose residuals are the Sampson distance (the
    implicit equation over its gradient: the geometric distance to first order, within
    0.01 px of scikit-image's exact one on a 50/40 px ellipse with 0.3 px noise,
    :func:`test_the_sampson_distance_is_the_distance_near_the_ellipse`), which
    RANSAC evaluates at every edge pixel of every trial: the exact one, a minimisation
    per pixel, takes minutes on the dome's 6460."""
    from skimage.measure import EllipseModel

    class SampsonEllipse(EllipseModel):
        def residuals(self, data):
            if hasattr(EllipseModel, "from_estimate"):  # scikit-image >= 0.26
                (xc, yc), (a, b), t = self.center, self.axis_lengths, self.theta
            else:
                xc, yc, a, b, t = self.params
            dx, dy = data[:, 0] - xc, data[:, 1] - yc
            u = np.cos(t) * dx + np.sin(t) * dy
            v = -np.sin(t) * dx + np.cos(t) * dy
            return np.abs((u / a) ** 2 + (v / b) ** 2 - 1.0) / (
                2.0 * np.hypot(u / a ** 2, v / b ** 2))

    return SampsonEllipse


def _ellipse_residuals(points: np.ndarray) -> np.ndarray:
    """Distances of (x, y) points from the least-squares ellipse through them."""
    model = _ellipse_model()
    if hasattr(model, "from_estimate"):  # scikit-image >= 0.26
        return model.from_estimate(points).residuals(points)
    m = model()
    m.estimate(points)
    return m.residuals(points)


def measure(path: Path, spec: dict) -> dict:
    """The reference outline of one photo: centre (row, col), radius, sd, clipped sides
    (and, for ``model="ellipse"``, the semi-axes: ``radius`` is then their mean)."""
    from skimage.measure import CircleModel, ransac

    grey = _grey(path)
    h, w = grey.shape
    pts = edge_points(grey, spec)
    ellipse = spec.get("model", "circle") == "ellipse"
    model, fit_of = (_ellipse_model(), _ellipse_fit) if ellipse else (CircleModel, _circle_fit)
    fits, first_inliers = [], None
    for seed in SEEDS:
        _, inliers = ransac(pts, model, min_samples=5 if ellipse else 3,
                            residual_threshold=spec["threshold"], max_trials=TRIALS,
                            rng=seed)
        fit = fit_of(pts[inliers])
        fits.append(fit)
        if first_inliers is None:
            first_inliers = inliers
    inl = pts[first_inliers]
    xc, yc, r = fits[0][:3]
    rng = np.random.default_rng(12345)
    boots = []
    for _ in range(BOOTSTRAP):
        b = fit_of(inl[rng.integers(0, len(inl), len(inl))])
        if b is not None:
            boots.append(b)
    # the spread of the centre and the radius (an ellipse's axes and angle are recorded,
    # not held to the tolerance)
    fits_a, boots_a = np.array(fits)[:, :3], np.array(boots)[:, :3]
    sd = np.sqrt(fits_a.std(axis=0) ** 2 + boots_a.std(axis=0) ** 2)
    sd_px = float(sd.max())
    resid = (_ellipse_residuals(inl) if ellipse
             else np.hypot(inl[:, 0] - xc, inl[:, 1] - yc) - r)
    clipped = [side for side, out in (("top", yc - r < -0.5), ("bottom", yc + r > h - 0.5),
                                      ("left", xc - r < -0.5), ("right", xc + r > w - 0.5))
               if out]
    return {
        "centre": [round(yc, 3), round(xc, 3)],
        "radius": round(r, 3),
        "sd_px": round(sd_px, 4),
        "tolerance_px": round(3.0 * sd_px + EDGE_FLOOR_PX, 3),
        "clipped": clipped,
        "n_edge_points": int(len(pts)),
        "n_inliers": int(first_inliers.sum()),
        "residual_rms_px": round(float(np.sqrt(np.mean(resid ** 2))), 4),
    } | (_ellipse_record(fits, boots) if ellipse else {})


def _ellipse_record(fits: list, boots: list) -> dict:
    """An ellipse's semi-axes and angle (of the first seed's fit), with the axes'
    tolerance measured as the centre's is (the seeds' spread and the bootstrap's)."""
    axes_f, axes_b = np.array(fits)[:, 3:5], np.array(boots)[:, 3:5]
    sd = float(np.sqrt(axes_f.std(axis=0) ** 2 + axes_b.std(axis=0) ** 2).max())
    return {"model": "ellipse", "semi_axes_px": [round(fits[0][3], 3), round(fits[0][4], 3)],
            "axes_tolerance_px": round(3.0 * sd + EDGE_FLOOR_PX, 3),
            # from the +column axis toward +row (clockwise on screen), as exclude_deg
            "angle_deg": round(float(np.degrees(fits[0][5])) % 180.0, 2)}


def _record() -> dict:
    """Measure every photo: the content of references.json."""
    from PIL import Image

    photos = {}
    for name, p in PHOTOS.items():
        path = DATA / name
        if p["format"] == "raw":
            import rawpy

            with rawpy.imread(str(path)) as raw:
                shape = [int(raw.sizes.height), int(raw.sizes.width)]
        else:
            with Image.open(path) as im:
                shape = [im.size[1], im.size[0]]
        entry = {k: p[k] for k in ("format", "mirror", "outline", "bright_rim", "camera",
                                   "note")}
        entry["shape"] = shape
        if p["spec"] is None:
            entry["reference"] = None
        else:
            entry["reference"] = measure(path, p["spec"])
            entry["reference"]["method"] = {
                "annulus_centre_guess_rc": list(p["spec"]["centre_guess"]),
                "annulus_px": list(p["spec"]["annulus"]),
                "exclude_deg": [list(a) for a in p["spec"]["exclude_deg"]],
                "canny_sigma": p["spec"]["sigma"],
                "ransac_threshold_px": p["spec"]["threshold"],
                "model": p["spec"].get("model", "circle"),
            }
        photos[name] = entry
    return {
        "about": "Reference outlines of the real mirror photos, measured by "
                 "tests/test_real_corpus.py (Canny + RANSAC CircleModel, or EllipseModel "
                 "where method.model says so, + least squares in a hand-picked annulus; "
                 "seeds %s, %d bootstrap resamples). centre is (row, col) of pixel "
                 "centres, radius in px of the stored file (an ellipse's: the mean of "
                 "its semi-axes); "
                 "tolerance_px = 3*sd_px + %.1f. A record, not a source of truth: the "
                 "tests measure it again." % (list(SEEDS), BOOTSTRAP, EDGE_FLOOR_PX),
        "photos": photos,
    }


def _overlay(out_dir: Path) -> None:
    """Each photo, at most 800 px, with the fitted circle (red) and the annulus (green)."""
    from PIL import Image, ImageDraw

    out_dir.mkdir(parents=True, exist_ok=True)
    refs = json.loads(REFERENCES.read_text(encoding="utf-8"))["photos"]
    for name, p in PHOTOS.items():
        if p["spec"] is None:
            continue
        ref = refs[name]["reference"]
        with Image.open(DATA / name) as im0:
            im = im0.convert("RGB")
        w, h = im.size
        pad = int(0.1 * max(w, h))
        canvas = Image.new("RGB", (w + 2 * pad, h + 2 * pad), (40, 40, 40))
        canvas.paste(im, (pad, pad))
        d = ImageDraw.Draw(canvas)
        (rc, cc), r = ref["centre"], ref["radius"]
        if ref.get("model") == "ellipse":
            (a, b), th = ref["semi_axes_px"], np.radians(ref["angle_deg"])
            t = np.linspace(0.0, 2.0 * np.pi, 721)
            x = cc + a * np.cos(t) * np.cos(th) - b * np.sin(t) * np.sin(th)
            y = rc + a * np.cos(t) * np.sin(th) + b * np.sin(t) * np.cos(th)
            d.line(list(zip(x + pad, y + pad)), fill=(255, 0, 0), width=max(1, w // 500))
        else:
            d.ellipse([cc - r + pad, rc - r + pad, cc + r + pad, rc + r + pad],
                      outline=(255, 0, 0), width=max(1, w // 500))
        gr, gc = p["spec"]["centre_guess"]
        for ra in p["spec"]["annulus"]:
            d.ellipse([gc - ra + pad, gr - ra + pad, gc + ra + pad, gr + ra + pad],
                      outline=(0, 255, 0), width=1)
        d.line([cc - 10 + pad, rc + pad, cc + 10 + pad, rc + pad], fill=(255, 0, 0))
        d.line([cc + pad, rc - 10 + pad, cc + pad, rc + 10 + pad], fill=(255, 0, 0))
        k = 800 / max(canvas.size)
        canvas.resize((round(canvas.size[0] * k), round(canvas.size[1] * k))).save(
            out_dir / (Path(name).stem + "_overlay.png"))


# ------------------------------------------------------------------------- the tests

def _sources_table() -> dict[str, str]:
    """File name -> SHA-256, from SOURCES.md's table rows."""
    rows = {}
    for line in SOURCES.read_text(encoding="utf-8").splitlines():
        m = re.match(r"\|\s*`([^`]+)`\s*\|.*\|\s*`?([0-9a-f]{64})`?\s*\|\s*$", line)
        if m:
            rows[m.group(1)] = m.group(2)
    return rows


def test_every_file_is_recorded_with_its_sha256():
    table = _sources_table()
    on_disk = sorted(p.name for p in DATA.iterdir()
                     if p.is_file() and p.name not in ("SOURCES.md", "references.json"))
    assert sorted(table) == on_disk == sorted(PHOTOS)
    for name, sha in table.items():
        assert hashlib.sha256((DATA / name).read_bytes()).hexdigest() == sha, name


def test_the_corpus_covers_what_issue_24_asks_for():
    entries = corpus()
    mirrors = corpus(with_outline=True)
    assert len(mirrors) >= 8
    assert {e["name"] for e in entries} == set(PHOTOS)
    assert any(e["outline"] == "sphere limb" for e in mirrors)
    assert any(e["mirror"] == "paraboloid" for e in mirrors)
    assert any(e["clipped"] for e in mirrors)
    assert any(e["bright_rim"] for e in mirrors)
    assert {e["format"] for e in entries} >= {"jpeg", "png", "raw"}
    for e in entries:
        assert e["path"].is_file()
    assert sum(e["path"].stat().st_size for e in entries) < 15e6


@pytest.mark.parametrize("name", sorted(PHOTOS))
def test_reads_through_read_camera_image(name):
    from mitsweep.io.camera import read_camera_image

    entry = next(e for e in corpus() if e["name"] == name)
    img = read_camera_image(entry["path"])
    assert img.kind == entry["format"]
    assert img.shape == entry["shape"]
    assert img.data.dtype == np.float32
    assert np.all(np.isfinite(img.data))
    assert float(img.data.min()) >= 0.0 and 0.05 < float(img.data.max()) <= 1.0 + 1e-6
    assert float(img.data.std()) > 0.01  # a photo, not a blank frame


@pytest.mark.parametrize("name", sorted(n for n, p in PHOTOS.items() if p["spec"]))
def test_reference_outline_is_measured_again(name):
    """The independent Canny + RANSAC measurement agrees with references.json."""
    rec = json.loads(REFERENCES.read_text(encoding="utf-8"))["photos"][name]["reference"]
    spec = PHOTOS[name]["spec"]
    assert rec["method"]["annulus_px"] == list(spec["annulus"])
    now = measure(DATA / name, spec)
    tol = rec["tolerance_px"]
    assert abs(now["centre"][0] - rec["centre"][0]) <= tol
    assert abs(now["centre"][1] - rec["centre"][1]) <= tol
    assert abs(now["radius"] - rec["radius"]) <= tol
    assert now["clipped"] == rec["clipped"]
    # The fit is a good one: hundreds of edge pixels on the circle, a thin residual
    # (busy annuli hold many more edges that are not the outline: no share is asked).
    assert now["n_inliers"] >= 300
    assert now["residual_rms_px"] < 1.5
    # and the outline lies inside the annulus picked by eye.
    r_in, r_out = spec["annulus"]
    assert r_in < now["radius"] < r_out


def test_the_sampson_distance_is_the_distance_near_the_ellipse():
    """The reference's RANSAC residual (the Sampson distance) against scikit-image's exact
    distance, on points within a pixel or so of a 50/40 px ellipse tilted 0.3 rad (0.3 px
    of noise, about a Canny edge's scatter; the dome's inliers lie within the 1.5 px
    threshold): measured 0.0099 px apart at most, two orders below that threshold; the
    bar, 0.02 px, is where RANSAC's inlier sets could begin to differ by more than a few
    pixels on the threshold's edge."""
    from skimage.measure import EllipseModel

    t = np.linspace(0.0, 2.0 * np.pi, 400)
    c, s = np.cos(0.3), np.sin(0.3)
    pts = np.column_stack([100 + 50 * np.cos(t) * c - 40 * np.sin(t) * s,
                           80 + 50 * np.cos(t) * s + 40 * np.sin(t) * c])
    pts += np.random.default_rng(0).normal(0.0, 0.3, pts.shape)
    exact = EllipseModel.from_estimate(pts) if hasattr(EllipseModel, "from_estimate") \
        else EllipseModel()
    if not hasattr(EllipseModel, "from_estimate"):
        exact.estimate(pts)
    sampson = _ellipse_residuals(pts)
    assert np.abs(sampson - exact.residuals(pts)).max() < 0.02
    assert 0.1 < float(np.sqrt(np.mean(sampson ** 2))) < 0.5   # the noise, not zeros


def test_an_elliptical_outline_is_referenced_by_its_ellipse():
    """The dome's reference is an ellipse because a circle does not describe its
    outline: at the same RANSAC threshold a circle keeps fewer edge pixels than the
    ellipse and its centre lies beyond its own tolerance from the ellipse's.
    docs/reference/photos.md states these figures."""
    name = "dome_store_bright_rim.jpg"
    spec = PHOTOS[name]["spec"]
    assert spec["model"] == "ellipse"
    ellipse = measure(DATA / name, spec)
    circle = measure(DATA / name, {k: v for k, v in spec.items() if k != "model"})
    apart = float(np.hypot(*np.subtract(circle["centre"], ellipse["centre"])))
    assert circle["n_inliers"] < ellipse["n_inliers"]
    assert apart > circle["tolerance_px"]
    a, b = ellipse["semi_axes_px"]
    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "reference"
                     / "photos.md").read_text(encoding="utf-8").split())
    tilt = np.degrees(np.arccos(b / a))    # a circle seen that far off its axis
    assert (f"semi-axes {a:.1f} and {b:.1f} px: its rim seen about {tilt:.0f}°" in text
            and f"{circle['n_inliers']} of the {circle['n_edge_points']} edge pixels "
                f"against the ellipse's {ellipse['n_inliers']}" in text
            and f"its centre lies {apart:.1f} px from the ellipse's, beyond the circle's "
                f"own stated tolerance ({circle['tolerance_px']:.2f} px)" in text)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="measure and rewrite the JSON")
    ap.add_argument("--overlay", type=Path, help="write overlays into this folder")
    a = ap.parse_args()
    if a.write:
        REFERENCES.write_text(json.dumps(_record(), indent=1) + "\n", encoding="utf-8")
        for n, e in json.loads(REFERENCES.read_text())["photos"].items():
            r = e["reference"]
            print(n, r and (r["centre"], r["radius"], r["sd_px"], r["tolerance_px"],
                            r["clipped"], r["n_inliers"], r["n_edge_points"],
                            r["residual_rms_px"]))
    if a.overlay:
        _overlay(a.overlay)
