"""The polar deconvolution's band plan: a pure function of the grid, the kernel size and
the spacing, checked for the properties the solver relies on (windows that sum to one,
bands in rising rows each overlapping only its neighbours, contexts and FFT lengths
that fit)."""

import math

import numpy as np
import pytest

from mitsweep.deconv.polar import polar_grid
from mitsweep.deconv.polar.bands import Band, band_plan
from mitsweep.deconv.polar.grid import SPLINE_PX

GRIDS = [((256, 256), None, 1.5, 15), ((512, 384), None, 1.0, 31),
         ((300, 200), (40.5, 60.0), 2.0, 9), ((2048, 2048), None, 1.5, 63)]


def _grid(shape, center, oversampling):
    return polar_grid(shape, center=center, radial_oversampling=oversampling,
                      inner_px=SPLINE_PX, outer_px=SPLINE_PX)


@pytest.fixture(params=GRIDS, ids=lambda p: f"{p[0][0]}x{p[0][1]}-K{p[3]}")
def planned(request):
    shape, center, oversampling, K = request.param
    grid = _grid(shape, center, oversampling)
    return grid, K, band_plan(grid, K)


def test_centres_start_inside_the_disk_and_step_by_a_quarter_radius_or_a_kernel(planned):
    grid, K, plan = planned
    c = plan.centres
    assert plan.inner_radius == max(2.0 * K, 8.0)
    assert c[0] == plan.inner_radius / 2
    steps = np.diff(c[:-1])
    np.testing.assert_allclose(steps, np.maximum(0.25 * c[:-2], K), rtol=1e-12)
    assert c[-1] == pytest.approx(max(min(c[-2] + max(0.25 * c[-2], K), grid.r_max),
                                      c[-2] + 1.0))
    assert c[-2] < grid.r_max <= c[-1] or c[-1] == c[-2] + 1.0


def test_windows_sum_to_one_between_the_first_and_last_centre(planned):
    grid, _, plan = planned
    r = grid.radii
    between = (r >= plan.centres[0]) & (r <= plan.centres[-1])
    assert plan.weights.shape == (len(plan.centres), grid.n_radii)
    assert (plan.weights >= 0).all()
    np.testing.assert_allclose(plan.weights[:, between].sum(axis=0), 1.0, rtol=0, atol=1e-12)


def test_bands_rise_and_overlap_only_their_neighbours(planned):
    """The solver writes each row first from one band and adds the next: that needs
    bands in rising rows, each overlapping only the one before and the one after."""
    grid, _, plan = planned
    bands = [b for b in plan.bands if b is not None]
    assert bands and all(isinstance(b, Band) for b in bands)
    for prev, cur in zip(bands, bands[1:]):
        assert prev.rows[0] <= cur.rows[0] and prev.rows[1] <= cur.rows[1]
    for first, third in zip(bands, bands[2:]):
        assert third.rows[0] >= first.rows[1]
    # together they cover every row the Cartesian pixels read
    keep0 = int(math.floor(grid.row_of(-SPLINE_PX)))
    keep1 = int(math.ceil(grid.row_of(grid.r_max + SPLINE_PX))) + 1
    covered = np.zeros(grid.n_radii, bool)
    for b in bands:
        covered[b.rows[0]:b.rows[1]] = True
        w = plan.weights[list(plan.centres).index(b.centre)]
        assert (w[b.rows[0]:b.rows[1]] > 0).all()
    first_row = bands[0].rows[0]
    assert covered[max(first_row, keep0):keep1].all()


def test_contexts_fft_lengths_and_harmonics_fit(planned):
    grid, K, plan = planned
    step = grid.radial_step
    m_rows = math.ceil(math.ceil(1.5 * K) / step)
    M = grid.n_angles // 2 + 1
    for b in plan.bands:
        if b is None:
            continue
        (lo, hi), (s0, s1) = b.rows, b.context
        assert s0 == max(0, lo - m_rows) and s1 == min(grid.n_radii, hi + m_rows)
        assert b.fft_length >= s1 - s0
        assert abs(b.fft_length * step - round(b.fft_length * step)) < 1e-9 * b.fft_length
        r_hi = max(grid.radii[s1 - 1], b.centre)
        assert b.harmonics == min(M, math.ceil(2 * math.pi * r_hi / math.sqrt(2)) + 8)


def test_plan_is_pure_and_follows_its_arguments():
    grid = _grid((256, 256), None, 1.5)
    a, b = band_plan(grid, 15), band_plan(grid, 15)
    assert a.bands == b.bands and np.array_equal(a.weights, b.weights)
    assert len(band_plan(grid, 15, band_spacing=0.5).centres) < len(a.centres)
    wide = band_plan(grid, 15, margin=60)
    assert all(w.context[1] - w.context[0] >= v.context[1] - v.context[0]
               for v, w in zip(a.bands, wide.bands) if v is not None)


def test_plan_refuses_a_step_no_fft_length_fits():
    grid = _grid((128, 128), None, 1 / 0.7071)   # step √2/2: L·step never an integer
    with pytest.raises(ValueError, match="radial_oversampling such as"):
        band_plan(grid, 9)
