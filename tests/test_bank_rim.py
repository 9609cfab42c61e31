"""Banks to the rim (issue 27, item 3): a radial bank extended to the image of the
mirror's rim, traced as the tracer traces any point; off-mirror grid nodes taking the
nearest traced kernel; the budget's beyond-FOV region kept at the design FOV."""

from pathlib import Path

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.deconv.budget import error_budget
from mitsweep.deconv.kernels import fill_invalid_nodes
from mitsweep.deconv.synthetic import synthetic_grid_bank, synthetic_radial_bank
from mitsweep.optics.reference import reference_geometry
from mitsweep.pipeline.rim import rim_bank, rim_image_radius, rim_radii

ROOT = Path(__file__).resolve().parents[1]


def test_rim_radii_keep_the_banks_spacing_and_end_at_the_rim():
    bank = synthetic_radial_bank((64, 64), n_radii=5, r_max_px=20.0, pixel_pitch=0.1)
    r = np.asarray(bank.radii)                      # 0, 0.5, ..., 2.0 mm
    new = rim_radii(bank, 3.3)
    np.testing.assert_allclose(new, [2.4333333, 2.8666667, 3.3], rtol=1e-6)
    assert np.all(np.diff(new) <= np.diff(r)[0] + 1e-12)
    assert rim_radii(bank, 2.0).size == 0 and rim_radii(bank, 1.0).size == 0


@pytest.fixture(scope="module")
def paraboloid():
    from mitsweep.tracer import ipsf_bank
    from mitsweep.tracer.settings import TraceSettings

    setup = load_setup(ROOT / "scenes" / "paraboloid.toml")
    bank = ipsf_bank(setup, n_radii=5, settings=TraceSettings(rays=20_000, kernel_size=15))
    return setup, bank


def test_rim_bank_traces_the_points_beyond_the_fov_as_the_tracer_does(paraboloid):
    """The new points reach the image of the rim (beyond the FOV's edge: the paraboloid's
    mirror extends past its design zone), and each kernel is the tracer's own IPSF at
    that point with the bank's settings and the next seed (an independent call of
    integrated_psf gives the same kernel to float32 round-off)."""
    from mitsweep.tracer import integrated_psf
    from mitsweep.tracer.settings import TraceSettings

    setup, bank = paraboloid
    ext = rim_bank(setup, bank)
    n0 = len(bank.radii)
    ref = reference_geometry(setup).sensor_distance
    rim = rim_image_radius(setup, ref)
    assert rim > float(np.max(bank.radii)) * 1.1
    assert float(ext.radii[-1]) == pytest.approx(rim)
    assert ext.metadata["fov_radius_mm"] == pytest.approx(float(np.max(bank.radii)))
    np.testing.assert_array_equal(ext.kernels[:, :n0], bank.kernels)
    j = len(ext.radii) - 1
    k, _ = integrated_psf(setup, float(ext.radii[j]), 0.0, float(bank.depths[0]),
                          settings=TraceSettings(rays=20_000, kernel_size=15, seed=j))
    np.testing.assert_allclose(ext.kernels[0, j], k, atol=1e-6)
    assert ext.kernels[0, j].sum() == pytest.approx(1.0, abs=1e-3)


def test_off_mirror_grid_nodes_take_the_nearest_traced_kernel():
    bank = synthetic_grid_bank((48, 48), (3, 3), size=7)
    valid = np.ones(9, bool)
    valid[[0, 8]] = False                     # two corners off the mirror
    k = np.array(bank.kernels)
    k[:, [0, 8]] = 0
    k[:, [0, 8], 3, 3] = 1                    # the tracer's stand-in delta
    from dataclasses import replace
    off = replace(bank, kernels=k, metadata={**bank.metadata, "valid": valid.tolist()})
    filled = fill_invalid_nodes(off)
    # the nearest traced neighbours of corner 0 are nodes 1 and 3 (equal distance):
    # argmin takes the first; of corner 8, nodes 5 and 7
    np.testing.assert_array_equal(filled.kernels[:, 0], k[:, 1])
    np.testing.assert_array_equal(filled.kernels[:, 8], k[:, 5])
    np.testing.assert_array_equal(filled.kernels[:, valid], k[:, valid])
    assert filled.metadata["filled_nodes"] == [0, 8]
    assert fill_invalid_nodes(bank) is bank                         # nothing to fill
    radial = synthetic_radial_bank((48, 48), size=7)
    assert fill_invalid_nodes(radial) is radial


def test_budget_beyond_fov_is_the_design_fovs_whatever_the_bank():
    shape = (48, 48)
    bank = synthetic_radial_bank(shape, size=7, n_radii=5, r_max_px=16.0, extent_px=16.0)
    from dataclasses import replace
    wider = replace(bank, metadata={**bank.metadata, "fov_radius_mm": 10.0 * bank.pixel_pitch})
    truth = np.random.default_rng(0).random(shape)
    a = error_budget(truth, truth, bank, weight=1e-3)
    b = error_budget(truth, truth, wider, weight=1e-3)
    ia, ib = a.regions.index("beyond_fov"), b.regions.index("beyond_fov")
    yy, xx = np.mgrid[0:48, 0:48]
    rr = np.hypot(yy - 23.5, xx - 23.5)
    assert a.pixels[ia] == int(np.sum(rr > 16.0))
    assert b.pixels[ib] == int(np.sum(rr > 10.0))
    assert b.info["fov_radius_px"] == pytest.approx(10.0)
