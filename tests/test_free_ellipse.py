"""``calibrate --free`` reports the ellipse through the circle fit's edge points
(:func:`mitsweep.photo.free.ellipse_of_edges`): a slightly tilted view's outline is an
ellipse, and a circle's stays a circle. The photos are drawn here, supersampled, with
their outline known exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from cli_contract import run_main
from mitsweep.photo import NoMirrorError
from mitsweep.photo.free import ellipse_of_edges, find_circle

SIDE, CENTRE = 400, (201.3, 188.7)
#: The same centre in mitsweep's pixel coordinates (a pixel's centre is its index; the
#: drawing below puts pixel i's centre at i + 0.5).
TRUE_CENTRE_PX = (CENTRE[0] - 0.5, CENTRE[1] - 0.5)


def _photo(a: float, b: float, angle_deg: float, k: int = 4) -> np.ndarray:
    """A textured bright disc bounded by the ellipse (semi-axes a, b px, the major axis
    ``angle_deg`` counter-clockwise from the column axis as displayed) on a dark textured
    background, each pixel the mean of k x k samples."""
    sub = (np.arange(SIDE * k) + 0.5) / k
    rows, cols = np.meshgrid(sub, sub, indexing="ij")
    dy, dx = rows - CENTRE[0], cols - CENTRE[1]
    t = math.radians(angle_deg)
    along = dx * math.cos(t) - dy * math.sin(t)       # rows point down: -dy is up
    across = dx * math.sin(t) + dy * math.cos(t)
    inside = (along / a) ** 2 + (across / b) ** 2 <= 1.0
    texture = 0.5 + 0.15 * np.sin(rows / 7.0) * np.cos(cols / 11.0)
    img = np.where(inside, 0.35 + texture, 0.08 + 0.04 * np.sin((rows + cols) / 9.0))
    return img.reshape(SIDE, k, SIDE, k).mean(axis=(1, 3))


@pytest.mark.parametrize("a, b, angle", [(150.0, 146.0, 30.0), (149.0, 146.5, 120.0)])
def test_a_slightly_tilted_view_is_reported_as_its_ellipse(a, b, angle):
    fit, _radius = find_circle(_photo(a, b, angle))
    e = ellipse_of_edges(fit)
    assert e is not None and e["significant"]
    # measured: semi-axes within 0.035 px, angle 0.14 deg, centre 0.01 px
    np.testing.assert_allclose(e["semi_axes_px"], (a, b), atol=0.1)
    assert abs((e["angle_deg"] - angle + 90) % 180 - 90) < 0.5
    assert np.abs(np.asarray(e["center_px"]) - TRUE_CENTRE_PX).max() < 0.05
    assert e["residual_rms_px"] < 0.5 * fit.residual_rms_px     # the circle left 5-7x more


# in CI's slow run (10-18 s each), to keep the default run under 4 minutes on 2 cores;
# the default run finds the ellipse of a slightly tilted view (below) and the CLI's
@pytest.mark.slow
@pytest.mark.parametrize("a, b, angle", [(150.0, 141.0, 30.0), (150.0, 130.0, 120.0),
                                         (150.0, 110.0, 60.0)])
def test_a_tilted_view_no_circle_explains_is_found_as_its_ellipse(a, b, angle):
    """Axis ratios 0.94, 0.87, 0.73 (views tilted by ~20, 30 and 43 degrees): no circle is
    accepted, and the ellipse search finds the outline; measured: semi-axes within
    0.02 px, angle 0.1 deg, centre 0.02 px."""
    fit, radius = find_circle(_photo(a, b, angle))
    e = ellipse_of_edges(fit)
    assert e is not None and e["significant"]
    np.testing.assert_allclose(e["semi_axes_px"], (a, b), atol=0.1)
    assert abs((e["angle_deg"] - angle + 90) % 180 - 90) < 0.5
    assert np.abs(np.asarray(fit.center_px) - TRUE_CENTRE_PX).max() < 0.05
    assert abs(radius - math.sqrt(a * b)) < 0.1         # the circle of the same area
    assert fit.residual_rms_px < 0.5                     # the outline is the ellipse


@pytest.mark.slow       # 9 s: CI's slow run
def test_an_ellipse_flatter_than_the_search_allows_is_refused_naming_both():
    with pytest.raises(NoMirrorError, match="nor an ellipse of axis ratio 0.7 or more"):
        find_circle(_photo(150.0, 90.0, 45.0))


def test_a_circle_stays_a_circle():
    fit, radius = find_circle(_photo(148.0, 148.0, 0.0))
    e = ellipse_of_edges(fit)
    assert e is not None and not e["significant"]
    # measured: axis ratio 0.99975, radius 0.007 px off
    assert e["axis_ratio"] > 0.999 and abs(radius - 148.0) < 0.05


def test_free_cli_prints_the_ellipse(tmp_path, capsys):
    path = tmp_path / "tilted.png"
    Image.fromarray(np.round(_photo(150.0, 146.0, 30.0) * 255).astype(np.uint8)).save(path)
    rc, out, err = run_main(capsys, "calibrate", path, "--free")
    assert rc == 0, err
    line = next(ln for ln in out.splitlines() if ln.startswith("ellipse"))
    assert "no circle: a tilted view?" in line
    a, b = (float(v) for v in line.split("semi-axes ")[1].split(" px")[0].split(" x "))
    assert abs(a - 150.0) < 0.25 and abs(b - 146.0) < 0.25


@pytest.mark.slow  # ~6 s: a 2100-px drawing
def test_a_large_photos_ellipse_is_found_on_the_reduced_copy_and_reshaped_at_full_size():
    """A photo whose shorter side is over twice FREE_WORKING_SIDE_PX: the candidates are
    compared on a copy reduced by 2, and the ellipse found there is reshaped at full
    resolution (axis ratio 0.8). Measured: semi-axes within 0.02 px, centre 0.02 px,
    angle 0.001 deg; the tolerances are the small photos' above."""
    side, centre, a, b, angle = 2100, (1050.3, 1000.7), 700.0, 560.0, 50.0
    sub = (np.arange(side * 2) + 0.5) / 2
    rows, cols = np.meshgrid(sub, sub, indexing="ij")
    dy, dx = rows - centre[0], cols - centre[1]
    t = math.radians(angle)
    inside = ((dx * math.cos(t) - dy * math.sin(t)) / a) ** 2 \
        + ((dx * math.sin(t) + dy * math.cos(t)) / b) ** 2 <= 1.0
    texture = 0.5 + 0.15 * np.sin(rows / 7.0) * np.cos(cols / 11.0)
    img = np.where(inside, 0.35 + texture, 0.08 + 0.04 * np.sin((rows + cols) / 9.0))
    img = img.reshape(side, 2, side, 2).mean(axis=(1, 3))
    fit, radius = find_circle(img)
    e = ellipse_of_edges(fit)
    assert e is not None and e["significant"]
    np.testing.assert_allclose(e["semi_axes_px"], (a, b), atol=0.1)
    assert abs((e["angle_deg"] - angle + 90) % 180 - 90) < 0.5
    assert np.abs(np.asarray(fit.center_px) - (centre[0] - 0.5, centre[1] - 0.5)).max() < 0.05
    assert abs(radius - math.sqrt(a * b)) < 0.1
