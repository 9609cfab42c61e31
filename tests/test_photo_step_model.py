"""The blurred step on a ramp (mitsweep.photo.edges.blurred_step_offsets), on drawn
discs whose answer is known: what it places exactly, and what pulls it as it pulls the
peak of a smoothed profile's derivative (its gain on the sphere's limb is measured on
renders, tests/test_calibrate_limb.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from mitsweep.photo.edges import blurred_step_offsets, edge_offsets

CENTRE = (60.37, 63.81)
RADIUS = 40.0


def _disc_on_a_ramp(slope: float, sigma: float = 0.8, n: int = 128, sub: int = 4, *,
                    both_sides: bool = False):
    """A disc (0.2 inside, 0.6 just outside) whose outside (and inside, with
    ``both_sides``) ramps by ``slope * cos(phi)`` per px away from the edge (brighter
    outward on the right, darker on the left), drawn at ``sub``-times the resolution,
    averaged to pixels and blurred by a Gaussian of ``sigma`` px."""
    k = (np.arange(n * sub) + 0.5) / sub - 0.5
    rr, cc = np.meshgrid(k, k, indexing="ij")
    dr, dc = rr - CENTRE[0], cc - CENTRE[1]
    r = np.hypot(dr, dc)
    cos_phi = dc / np.maximum(r, 1e-9)
    out = 0.6 + slope * cos_phi * (r - RADIUS)
    inside = 0.2 + (slope * cos_phi * (r - RADIUS) if both_sides else 0.0)
    img = np.where(r < RADIUS, inside, out)
    img = img.reshape(n, sub, n, sub).mean(axis=(1, 3))
    return gaussian_filter(img, sigma)


def _outline(n: int = 720):
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    nrm = np.column_stack([np.sin(a), np.cos(a)])
    return RADIUS * nrm, nrm


def _circle(off, pts, nrm, start):
    """The circle through the edge points: least squares on the offsets along the
    normals (centre shift and radius change), independent of the library's fits."""
    good = np.isfinite(off)
    A = np.column_stack([nrm[:, 0], nrm[:, 1], np.ones(len(off))])[good]
    x, *_ = np.linalg.lstsq(A, off[good], rcond=None)
    return (start[0] + x[0], start[1] + x[1]), RADIUS + x[2]


def _both(img, start):
    """The circles from the model and from the derivative's peak (on the image smoothed
    by 1 px, as the limb fit located its steps before the model)."""
    pts, nrm = _outline()
    off, heights, sigma = blurred_step_offsets(img, start, 1.0, pts, nrm)
    peak, _, _ = edge_offsets(gaussian_filter(img, 1.0), start, 1.0, pts, nrm, 1.5)
    return _circle(off, pts, nrm, start), _circle(peak, pts, nrm, start), heights, sigma


def test_a_step_on_a_ramp_through_it_is_placed_from_a_start_off_by_half_a_pixel():
    """A gradient across the whole edge (as an uneven light): the model's own ramp."""
    start = (CENTRE[0] + 0.4, CENTRE[1] - 0.3)   # as a coarser fit leaves it
    ((cr, cc), radius), _, heights, sigma = _both(
        _disc_on_a_ramp(0.08, both_sides=True), start)
    # measured: 0.008 px, radius 0.014 px small; the bars are the flat step's (below)
    assert np.hypot(cr - CENTRE[0], cc - CENTRE[1]) < 0.02
    assert abs(radius - RADIUS) < 0.03
    assert np.all(heights > 0)   # brighter outside all round
    assert 0.5 <= sigma <= 1.6   # the drawn blur (0.8 px and the pixel's) among those tried


def test_a_ramp_on_one_side_pulls_the_model_as_it_pulls_the_derivatives_peak():
    """Not a cure for detail beside an edge: a ramp outside only (brighter outward on
    the right, darker on the left) moves both circles alike (measured 0.40 and 0.42 px
    at 0.08 per px): the model's ramp is one line through the whole profile."""
    start = (CENTRE[0] + 0.4, CENTRE[1] - 0.3)
    ((cr, cc), _), ((pr, pc), _), _, _ = _both(_disc_on_a_ramp(0.08), start)
    model_error = np.hypot(cr - CENTRE[0], cc - CENTRE[1])
    peak_error = np.hypot(pr - CENTRE[0], pc - CENTRE[1])
    # both well beyond the flat step's 0.02 px, and within a quarter of each other (5 %
    # apart measured): a change that made the model cure this ramp would fail here, and
    # the docstring of blurred_step_offsets would have to say so
    assert model_error > 0.2 and peak_error > 0.2
    assert abs(model_error - peak_error) < 0.25 * peak_error


def test_a_flat_step_gives_the_same_circle_either_way():
    """Without a ramp the derivative's peak is right too: the model agrees with it."""
    img = _disc_on_a_ramp(slope=0.0)
    pts, nrm = _outline()
    off, _, _ = blurred_step_offsets(img, CENTRE, 1.0, pts, nrm)
    peak, _, _ = edge_offsets(gaussian_filter(img, 1.0), CENTRE, 1.0, pts, nrm, 1.5)
    (cr, cc), radius = _circle(off, pts, nrm, CENTRE)
    (pr, pc), _ = _circle(peak, pts, nrm, CENTRE)
    # measured: the model 0.007 px (radius 0.013 px small), the peak 0.016 px; the bars
    # leave the pixel grid's share (a few hundredths) and no more
    assert np.hypot(cr - CENTRE[0], cc - CENTRE[1]) < 0.02
    assert np.hypot(pr - CENTRE[0], pc - CENTRE[1]) < 0.02
    assert abs(radius - RADIUS) < 0.05


@pytest.mark.parametrize("darker_outside", [False, True])
def test_a_steps_height_has_the_sign_of_the_outside(darker_outside):
    img = _disc_on_a_ramp(slope=0.0)
    if darker_outside:
        img = 1.0 - img
    pts, nrm = _outline(90)
    off, heights, _ = blurred_step_offsets(img, CENTRE, 1.0, pts, nrm)
    assert np.all(np.isfinite(off))
    assert np.all((heights < 0) if darker_outside else (heights > 0))
    # the drawn step is 0.4; measured 0.36-0.40 (a curved edge on a pixel grid, where
    # the model's blur and ramp share some of the step)
    np.testing.assert_allclose(np.abs(heights), 0.4, rtol=0.15)


def test_a_profile_that_leaves_the_photo_gives_nan():
    """The disc cut by the frame's left side (its edge 1.2 px beyond it): the normals
    whose profile leaves the photo are not measured, the others are placed."""
    img = _disc_on_a_ramp(slope=0.0)[:, 25:]
    centre = (CENTRE[0], CENTRE[1] - 25)
    pts, nrm = _outline(8)
    off, _, _ = blurred_step_offsets(img, centre, 1.0, pts, nrm)
    assert np.isnan(off[np.argmin(nrm[:, 1])])   # the leftmost normal
    assert np.isfinite(off).sum() == len(off) - 1
    right = nrm[:, 1] > 0.5
    assert np.all(np.abs(off[right]) < 0.15)   # measured 0.02-0.09 px (the pixel grid)
