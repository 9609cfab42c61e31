"""Several starting points for a rough setup: the coarse search's candidates
(:func:`mitsweep.photo.coarse.coarse_candidates`), the consensus of edges along the
normals (:func:`mitsweep.photo.robust.consensus_lstsq`) and the choice between the fits
(:func:`mitsweep.photo.rim.fit_support`). The real photos they are for are in
``tests/test_calibrate_real.py``; here each piece against a case whose answer is known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mitsweep.photo.coarse import coarse_candidates, coarse_search, search_scales
from mitsweep.photo.rim import (CLEARLY_BETTER, RimFit, choose_fit, fit_support, settled,
                                 unbeatable)
from mitsweep.photo.robust import consensus_lstsq


def _circle(n: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    a = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    nrm = np.column_stack([np.sin(a), np.cos(a)])
    return radius * nrm, nrm


def _rows(pts: np.ndarray, nrm: np.ndarray) -> np.ndarray:
    """The rim fit's design: a normal offset is n . dc + dk (p . n)."""
    return np.column_stack([nrm[:, 0], nrm[:, 1], np.sum(pts * nrm, axis=1)])


def _misleading_candidates(seed: int, truth: np.ndarray, wrong_share: float,
                           k: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Rows whose true offset is among k candidates, the first (the strongest) wrong on
    ``wrong_share`` of them: a strong edge of the reflection beside a dim rim."""
    rng = np.random.default_rng(seed)
    pts, nrm = _circle(360, 100.0)
    A = _rows(pts, nrm)
    b = A @ truth + rng.normal(0.0, 0.1, len(A))
    cand = rng.uniform(-20.0, 20.0, (len(A), k))
    wrong = rng.random(len(A)) < wrong_share
    cand[~wrong, 0] = b[~wrong]
    cand[wrong, rng.integers(1, k, wrong.sum())] = b[wrong]
    return A, cand


def test_consensus_finds_the_outline_the_strongest_edges_miss():
    truth = np.array([3.0, -2.0, 0.05])
    A, cand = _misleading_candidates(1, truth, wrong_share=0.7)
    x, chosen = consensus_lstsq(A, cand, tolerance=1.0)
    # the true offsets carry 0.1 px noise over 360 rows: the fit's own spread is ~0.01,
    # so 0.05 is ~5 sd; a wrong outline is off by pixels
    np.testing.assert_allclose(x, truth, atol=0.05)
    assert np.isfinite(chosen).mean() > 0.95   # every row has its true offset in reach
    # the baseline it replaces: least squares on each row's strongest edge is far off
    naive, *_ = np.linalg.lstsq(A, cand[:, 0], rcond=None)
    assert np.abs(naive[:2] - truth[:2]).max() > 0.5


def test_consensus_is_reproducible_and_skips_rows_without_candidates():
    truth = np.array([-1.0, 4.0, -0.02])
    A, cand = _misleading_candidates(2, truth, wrong_share=0.5)
    cand[:40] = np.nan
    x1, chosen1 = consensus_lstsq(A, cand, tolerance=1.0)
    x2, chosen2 = consensus_lstsq(A, cand, tolerance=1.0)
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(chosen1, chosen2)
    assert np.isnan(chosen1[:40]).all()
    np.testing.assert_allclose(x1, truth, atol=0.05)


def test_consensus_without_enough_rows_is_nan():
    A = _rows(*_circle(8, 50.0))
    cand = np.full((8, 4), np.nan)
    cand[:2, 0] = 1.0
    x, chosen = consensus_lstsq(A, cand, tolerance=1.0)
    assert np.isnan(x).all() and np.isnan(chosen).all()


@settings(max_examples=25, deadline=None)
@given(dr=st.floats(-10, 10), dc=st.floats(-10, 10), dk=st.floats(-0.1, 0.1),
       seed=st.integers(0, 2**16))
def test_consensus_recovers_any_small_displacement(dr, dc, dk, seed):
    truth = np.array([dr, dc, dk])
    A, cand = _misleading_candidates(seed, truth, wrong_share=0.6)
    x, _ = consensus_lstsq(A, cand, tolerance=1.0)
    np.testing.assert_allclose(x, truth, atol=0.05)


def _discs(shape, centre, radii, levels) -> np.ndarray:
    """Concentric discs on a dark background, outermost first."""
    rr, cc = np.indices(shape, dtype=float)
    r = np.hypot(rr - centre[0], cc - centre[1])
    img = np.full(shape, 0.1)
    for radius, level in zip(radii, levels):
        img[r <= radius] = level
    return img


def test_candidates_offer_the_rim_beside_a_nearer_concentric_edge():
    """A guess 35% too small: a dark disc inside the mirror (the camera's reflection,
    radius 66) lies nearer the prediction (60) than the rim (90), which is the stronger
    edge; the rule alone keeps the inner disc, the candidates include the rim."""
    centre = (150.0, 170.0)
    img = _discs((300, 340), centre, radii=(90.0, 66.0), levels=(0.8, 0.3))
    pts, nrm = _circle(720, 60.0)
    scales = search_scales(0.65, 2.0)
    starts = coarse_candidates(img, pts, nrm, scales)
    assert starts[0] == coarse_search(img, pts, nrm, scales)
    # radii to the coarse scale step (4%: 2.6 px at 66, 3.6 px at 90) ...
    assert abs(60.0 * starts[0][1] - 66.0) < 3.0
    radii = [60.0 * s for _, s, _ in starts]
    near_rim = [i for i, r in enumerate(radii) if abs(r - 90.0) < 4.0]
    assert near_rim, radii
    (row, col), _, score = starts[near_rim[0]]
    # ... and the centre to the reduced pixel (1 px here: a 60 px outline is not reduced)
    assert max(abs(row - centre[0]), abs(col - centre[1])) <= 2.0
    assert score > starts[0][2]     # stronger, but farther from the prediction
    assert len(starts) <= 6 and all(s[2] >= 0.5 * max(t[2] for t in starts) for s in starts)


@pytest.mark.parametrize("centre", [(399.5, 419.5), (400.0, 420.0), (401.3, 418.6)])
def test_each_concentric_edge_is_one_candidate(centre):
    """Wherever the centre falls between reduced pixels, each edge is offered once (the
    flat top of the score around it is one outline, not several starts)."""
    img = _discs((800, 840), centre, radii=(300.0, 225.0), levels=(0.9, 0.3))
    pts, nrm = _circle(720, 150.0)
    starts = coarse_candidates(img, pts, nrm, search_scales(0.65, 2.2))
    radii = np.array([150.0 * s for _, s, _ in starts])
    # a 150 px outline is searched reduced by 4: two reduced pixels are 8 px, and a
    # coarse scale step 9 px at 225 (the other maxima are off-centre, tangent circles)
    concentric = [(row, col) for (row, col), _, _ in starts
                  if math.hypot(row - centre[0], col - centre[1]) < 8.0]
    assert len(concentric) == 2, starts
    assert np.sum(np.abs(radii - 225.0) < 10.0) == 1
    assert np.sum(np.abs(radii - 300.0) < 13.0) == 1


def _fit(points: int, rms: float) -> RimFit:
    return RimFit(center_px=(0.0, 0.0), scale=1.0, points_used=points, points_total=1440,
                  residual_rms_px=rms, edge_points_px=np.zeros((0, 2)), iterations=1)


@pytest.mark.parametrize("second, kept", [
    (_fit(1300, 0.40), 1),    # tighter and more points: clearly better
    (_fit(1300, 0.90), 0),    # a little better: the outline nearest the prediction stays
    (_fit(1400, 0.05), 1),    # below the RMS floor the support saturates, still better
])
def test_choose_keeps_the_first_unless_another_is_clearly_better(second, kept):
    first = _fit(1200, 1.0)
    fits = [first, second]
    assert choose_fit(fits) is fits[kept]
    ratio = fit_support(second) / fit_support(first)
    assert (ratio > CLEARLY_BETTER) == bool(kept)


@pytest.mark.parametrize("points, rms, stop", [
    (1440, 0.30, True), (1300, 0.25, True), (1440, 0.33, False), (1100, 0.10, False)])
def test_a_first_fit_no_other_could_replace_ends_the_search(points, rms, stop):
    first = _fit(points, rms)
    assert unbeatable(first) == stop
    # the best any other fit could be: every point, at the floor of the RMS
    best_possible = _fit(1440, 0.0)
    assert (choose_fit([first, best_possible]) is first) == stop


@pytest.mark.parametrize("points, rms, stop", [
    (1440, 0.30, True),      # unbeatable
    (1348, 0.36, True),      # a rendered tilted rim with roll: 94% within 0.36 px
    (1389, 1.14, False),     # a real paraboloid's rim: refine the others too
    (1200, 0.40, False),     # too few points
    (1307, 3.24, False)])    # a mount's edge nearer the guess
def test_a_tight_first_fit_is_kept_without_the_others(points, rms, stop):
    assert settled(_fit(points, rms)) == stop


@pytest.mark.parametrize("starts", [0, -1, 1.5, "6"])
def test_starts_must_be_a_whole_number_of_at_least_one(starts):
    from mitsweep.config import load_setup
    from mitsweep.photo import calibrate_photo

    from conftest import SCENES

    setup = load_setup(SCENES / "paraboloid.toml")
    with pytest.raises(ValueError, match="starts must be a whole number"):
        calibrate_photo(np.zeros((64, 64)), setup, starts=starts)
