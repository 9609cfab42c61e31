"""IPSF banks: layout contract of mitsweep.io.bank, round trip, speed, field coverage."""

import time

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.io.bank import load_bank, save_bank
from mitsweep.tracer import integrated_psf, ipsf_bank

SPHERE = load_setup("scenes/sphere.toml")
TILTED = load_setup("scenes/paraboloid_tilted.toml")


def test_radial_bank_round_trip_and_contract(tmp_path):
    t0 = time.perf_counter()
    bank = ipsf_bank(SPHERE, depths=(500.0, 5000.0), rays=200_000)
    # Brief: a 19-radius x 1-depth sphere bank "well under a minute on 2 cores";
    # this is 2 depths at 1/5 of the default rays.
    assert time.perf_counter() - t0 < 30
    assert bank.kernels.shape == (2, 19, 31, 31)
    np.testing.assert_allclose(bank.kernels.sum(axis=(2, 3)), 1.0, atol=1e-5)
    assert bank.radii_mm[0] == 0.0 and np.all(np.diff(bank.radii_mm) > 0)
    np.testing.assert_array_equal(bank.points_uv[:, 1], 0.0)
    # The bank's kernel equals a direct integrated_psf call with the same seed.
    k, _ = integrated_psf(SPHERE, float(bank.radii_mm[7]), 0.0, 5000.0, rays=200_000, seed=7)
    np.testing.assert_array_equal(bank.kernels[1, 7], k)
    path = save_bank(tmp_path / "b.npz", bank)
    back = load_bank(path)
    np.testing.assert_array_equal(back.kernels, bank.kernels)
    assert back.reference_sensor_distance == pytest.approx(bank.reference_sensor_distance)
    assert back.metadata["setup"]["mirror"]["radius"] == 25.0
    assert back.metadata["rays_per_ipsf"] == 200_000


def test_radial_bank_refuses_tilted_mirror():
    with pytest.raises(ValueError, match="grid"):
        ipsf_bank(TILTED, kind="radial", rays=1000)


def test_grid_bank_marks_points_off_the_mirror():
    bank = ipsf_bank(TILTED, kind="grid", grid=(3, 3), rays=100_000)
    assert bank.kernels.shape == (1, 9, 31, 31)
    valid = np.array(bank.metadata["valid"])
    # The centre cell sees the mirror; the paper's tilted paraboloid fills part of the
    # 10.24 mm sensor only, so some corner cells miss it.
    assert valid[4] and not valid.all()
    np.testing.assert_allclose(bank.kernels.sum(axis=(2, 3)), 1.0, atol=1e-5)
    assert np.all(bank.vignetted[0, ~valid] == 1.0)
