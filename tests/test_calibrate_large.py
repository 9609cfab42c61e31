"""A real chrome ball on a large photo (the issue's first report: a 16 MP JPEG of a chrome
ball was refused). The corpus' real photos (tests/data/real, at most 1232 px) enlarged
k times (bilinear): the same outline with k times wider edges and k times the pixels,
as a high-resolution camera's soft edge. The reference (tests/test_real_corpus.py) maps
to ``(c + 0.5) k - 0.5`` and its tolerance to k times its own.

Photos from 1536 px on their shorter side are searched on a copy reduced by a whole
factor (:func:`mitsweep.photo.rim.working_factor`) and refined at full resolution near
what was found there. Measured before that (the search at full resolution, 2 cores):
sphere_tokyo.jpg x1.5 3.2 px off (tolerance 2.4) in 13 s, x2 (5.6 MP) 8.2 px off in 20 s,
x3.5 (17 MP) 24 px off in 321 s, sphere_lamp.jpg x3 in 41 s; after: 0.7 px in 5 s, 0.5 px
in 7 s, 1.9 px (tolerance 5.6) in 7 s, 6 s.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from real_corpus import corpus
from test_calibrate_real import _rough_setup

from mitsweep.io.camera import read_camera_image
from mitsweep.photo import calibrate_photo
from mitsweep.photo.free import find_circle

#: sphere_lamp.jpg x3: the radius 1.92 px off (tolerance 1.79), the centre within it; at
#: 1x the same photo reads ~0.6 px of its 0.6 px tolerance, and the search at 1/3 keeps
#: that share (the refinement at full resolution does not improve the limb's radius).
LARGE_MISSES = {("sphere_lamp.jpg", 3): "radius 1.92 px off, tolerance 1.79 px"}

CASES = [("sphere_tokyo.jpg", 1.5), ("sphere_tokyo.jpg", 2), ("sphere_tokyo.jpg", 3.5), ("sphere_lamp.jpg", 2),
         ("sphere_lamp.jpg", 3)]


def _enlarged(name: str, k: float):
    from skimage.transform import rescale

    entry = next(e for e in corpus(with_outline=True) if e["name"] == name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        img = read_camera_image(entry["path"]).data
    img = rescale(img, k, order=1, channel_axis=-1).astype(np.float32)
    truth = (np.asarray(entry["centre"]) + 0.5) * k - 0.5
    return img, dict(entry, centre=truth, radius=entry["radius"] * k,
                     tolerance_px=entry["tolerance_px"] * k)


def _params():
    for name, k in CASES:
        marks = [pytest.mark.slow]
        if (name, k) in LARGE_MISSES:
            marks.append(pytest.mark.xfail(reason=LARGE_MISSES[name, k], strict=True))
        yield pytest.param(name, k, id=f"{name}x{k:g}", marks=marks)


@pytest.mark.parametrize("name, k", list(_params()))
def test_a_chrome_ball_on_a_large_photo_calibrates(name, k):
    img, entry = _enlarged(name, k)
    cal = calibrate_photo(img, _rough_setup(entry, img.shape[:2], 0.09))
    tol = entry["tolerance_px"]
    assert np.abs(np.subtract(cal.center_px, entry["centre"])).max() < tol
    assert abs(cal.rim_radius_px - entry["radius"]) < tol


@pytest.mark.slow
def test_free_finds_a_chrome_ball_on_a_large_photo():
    img, entry = _enlarged("sphere_tokyo.jpg", 3.5)
    fit, radius = find_circle(img)
    tol = entry["tolerance_px"]
    assert np.abs(np.subtract(fit.center_px, entry["centre"])).max() < tol
    assert abs(radius - entry["radius"]) < tol
