"""``calibrate --free`` and photos without a mirror: without a setup nothing says where a
mirror is, so a circle or an ellipse is taken for its outline only where the fit uses
most of the outline the photo shows (:data:`mitsweep.photo.free.FREE_MIN_SUPPORT`); a
setup's fit asks for less. The drawn photos here know their outline exactly; the sample
photos are scikit-image's (none shows a mirror)."""

from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest
from sample_photos import FREE_REFUSED, FREE_ROUND_THINGS, sample_photo

from conftest import SCENES
from mitsweep.photo import NoMirrorError
from mitsweep.photo.free import (FREE_MIN_SUPPORT, circle_outline, find_circle,
                                 visible_support)
from mitsweep.photo.rim import fit_rim

SIDE, RADIUS = 300, 90.0


def _disc(centre: tuple[float, float], hidden_deg: float = 0.0, k: int = 4) -> np.ndarray:
    """A textured bright disc of radius RADIUS px about ``centre`` (row, col: pixel
    centres at their index) on a dark textured background, each pixel the mean of k x k
    samples; a dark holder, as dark as the background, covers the disc's outline over
    ``hidden_deg`` degrees of azimuth (from the column axis, toward +row), from 0.8 R out."""
    sub = (np.arange(SIDE * k) + 0.5) / k - 0.5
    rows, cols = np.meshgrid(sub, sub, indexing="ij")
    dy, dx = rows - centre[0], cols - centre[1]
    r, az = np.hypot(dy, dx), np.degrees(np.arctan2(dy, dx)) % 360.0
    texture = 0.5 + 0.15 * np.sin(rows / 7.0) * np.cos(cols / 11.0)
    background = 0.08 + 0.04 * np.sin((rows + cols) / 9.0)
    img = np.where(r <= RADIUS, 0.35 + texture, background)
    img = np.where((az < hidden_deg) & (r > 0.8 * RADIUS), background, img)
    return img.reshape(SIDE, k, SIDE, k).mean(axis=(1, 3))


def _shown_share(centre: tuple[float, float]) -> float:
    """The share of the outline's 1440 points inside the frame, counted here directly."""
    t = np.arange(1440) * 2.0 * math.pi / 1440
    y, x = centre[0] + RADIUS * np.sin(t), centre[1] + RADIUS * np.cos(t)
    inside = (np.rint(y) >= 0) & (np.rint(y) < SIDE) & (np.rint(x) >= 0) & (np.rint(x) < SIDE)
    return float(inside.mean())


def test_a_disc_cut_by_the_frame_is_supported_by_what_the_frame_shows():
    """A third of the outline outside the frame: the fit uses all the rest, so its
    support is that of the points shown, not of all of them."""
    centre = (150.3, 232.6)                        # its right side 22 px past the frame
    fit, radius = find_circle(_disc(centre))
    # measured 0.002 / 0.001 px on this noiseless drawing; the bar is the calibration's
    # (0.25 px centre), kept tighter here since nothing blurs or hides the edge
    assert np.abs(np.asarray(fit.center_px) - centre).max() < 0.2
    assert abs(radius - RADIUS) < 0.2
    shown = _shown_share(centre)
    assert 0.6 < shown < 0.8                       # measured 0.767
    support = visible_support(fit, circle_outline(radius / fit.scale), _disc(centre))
    assert support > 0.95                          # measured 0.969 (the frame's edge pixels)
    # the same count two ways (measured equal); 1 % allows a point rounded onto the border
    assert support == pytest.approx(fit.points_used / fit.points_total / shown, rel=0.01)


def test_free_refuses_an_outline_a_holder_hides_much_of_and_a_setup_finds_it():
    """A holder over 150 degrees of the outline: ``--free`` takes no circle fitted to
    the rest (measured: 0.70 of its points with the bar lowered to 0; the same disc with
    a holder over 90 degrees, 0.80, is taken), and says what is needed; the setup's
    fit, told where to look, finds the disc."""
    centre = (148.6, 151.2)
    img = _disc(centre, hidden_deg=150.0)
    with pytest.raises(NoMirrorError) as err:
        find_circle(img)
    assert f"without a setup {FREE_MIN_SUPPORT:.0%} are needed" in str(err.value)
    fit = fit_rim(img, circle_outline(RADIUS * 1.05), 1.0)
    # the bars (centre 0.25 px; the radius held to the same); measured 0.019 / 0.012
    assert np.abs(np.asarray(fit.center_px) - centre).max() < 0.25
    assert abs(fit.scale * RADIUS * 1.05 - RADIUS) < 0.25


@pytest.mark.slow   # 1-11 s a photo, most of it spent refining candidates and refusing them
@pytest.mark.parametrize("name", [
    *FREE_REFUSED,
    *(pytest.param(name, marks=pytest.mark.xfail(reason=why, strict=True))
      for name, why in FREE_ROUND_THINGS.items())])
def test_free_refuses_sample_photos_without_a_mirror(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(NoMirrorError, match="^no mirror found"):
            find_circle(sample_photo(name))


def test_the_guide_states_what_free_makes_of_the_sample_photos():
    """docs/reference/photos.md counts the sample photos the lists above hold (the strict
    expected failures hold those to the code)."""
    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    n = len(FREE_REFUSED) + len(FREE_ROUND_THINGS)
    said = re.search(r"`--free` refuses (\d+) of (\d+) of scikit-image's sample photos", text)
    assert said is not None and said.groups() == (str(len(FREE_REFUSED)), str(n))


@pytest.mark.slow   # the corpus' photos of mirrors and the brick wall: about a minute
def test_the_guide_states_the_supports_free_support_measures():
    """photos.md's figures for FREE_MIN_SUPPORT are what scripts/free_support.py measures
    (the bar lowered to 0): the range over the photos of mirrors found as an outline (not
    a limb), the rim cut by the frame, and the brick wall's circle."""
    import sys

    from real_corpus import corpus

    sys.path.insert(0, str(SCENES.parent / "scripts"))
    import free_support

    names = [e["name"] for e in corpus(with_outline=True)] + ["brick"]
    got = {m["name"]: m for m in free_support.measure(names)}
    mirrors = [m["support"] for m in got.values() if m["kind"] == "mirror"
               and m["support"] is not None]
    assert len(mirrors) == 7 and got["sphere_pageos_nasa.png"]["limb"]
    assert min(mirrors) >= FREE_MIN_SUPPORT > got["brick"]["support"]
    text = " ".join((SCENES.parent / "docs" / "reference" / "photos.md").read_text().split())
    assert (f"The photos of mirrors above read {min(mirrors):.2f}–{max(mirrors):.2f}"
            in text)
    assert (f"the rim cut by the frame, {got['omni_vmr_clipped.jpg']['support']:.2f} of what "
            "the frame shows") in text
    assert f"a circle in a brick wall {got['brick']['support']:.2f}" in text
