"""IPSF banks: layout contract of mitsweep.io.bank, round trip, speed, field coverage."""

import math
import time

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.io.bank import load_bank, save_bank
from mitsweep.tracer import TraceSettings, integrated_psf, ipsf_bank

SPHERE = load_setup("scenes/sphere.toml")
TILTED = load_setup("scenes/paraboloid_tilted.toml")


def test_radial_bank_round_trip_and_contract(tmp_path):
    t0 = time.perf_counter()
    bank = ipsf_bank(SPHERE, depths=(500.0, 5000.0), settings=TraceSettings(rays=200_000))
    # Brief: a 19-radius x 1-depth sphere bank "well under a minute on 2 cores";
    # this is 2 depths at 1/5 of the default rays.
    assert time.perf_counter() - t0 < 30
    assert bank.kernels.shape == (2, 19, 31, 31)
    np.testing.assert_allclose(bank.kernels.sum(axis=(2, 3)), 1.0, atol=1e-5)
    assert bank.radii[0] == 0.0 and np.all(np.diff(bank.radii) > 0)
    np.testing.assert_array_equal(bank.points_uv[:, 1], 0.0)
    # The bank's kernel equals a direct integrated_psf call with the same seed.
    k, _ = integrated_psf(SPHERE, float(bank.radii[7]), 0.0, 5000.0,
                          settings=TraceSettings(rays=200_000, seed=7))
    np.testing.assert_array_equal(bank.kernels[1, 7], k)
    path = save_bank(tmp_path / "b.npz", bank)
    back = load_bank(path)
    np.testing.assert_array_equal(back.kernels, bank.kernels)
    assert back.reference_sensor_distance == pytest.approx(bank.reference_sensor_distance)
    assert back.metadata["setup"]["mirror"]["radius"] == 25.0
    assert back.metadata["rays_per_ipsf"] == 200_000


def test_radial_bank_refuses_tilted_mirror():
    with pytest.raises(ValueError, match="grid"):
        ipsf_bank(TILTED, kind="radial", settings=TraceSettings(rays=1000))


def test_grid_bank_marks_points_off_the_mirror():
    bank = ipsf_bank(TILTED, kind="grid", grid=(3, 3), settings=TraceSettings(rays=100_000))
    assert bank.kernels.shape == (1, 9, 31, 31)
    valid = np.array(bank.metadata["valid"])
    # The centre cell sees the mirror; the paper's tilted paraboloid fills part of the
    # 10.24 mm sensor only, so some corner cells miss it.
    assert valid[4] and not valid.all()
    np.testing.assert_allclose(bank.kernels.sum(axis=(2, 3)), 1.0, atol=1e-5)
    assert np.all(bank.vignetted[0, ~valid] == 1.0)


@pytest.mark.parametrize("method", ["exact", "planes", "continuous"])
@pytest.mark.parametrize("batch_deposit", [True, False])
def test_batched_bank_equals_one_ipsf_at_a_time(method, batch_deposit, monkeypatch):
    # Batched tracing only regroups the work: every source traces the same rays (same
    # lattice, same fitted sampling domain), so the kernels may differ only by the
    # float64 summation order of the deposit, ~1e-16 relative: far below float32's
    # 6e-8, so they are equal to 1e-7. 3001 rays per kernel: 9 batched launches of
    # 2^k samples (2048 + 512 + ... + 1) and pilot rounds in lockstep; the depth inf
    # takes the finite-depth formula in a batch. batch_deposit=False: pilot rounds
    # batched, deposits source by source (what rays >= 2^18 per kernel do).
    from mitsweep.tracer import ipsf as ipsf_module

    if not batch_deposit:
        monkeypatch.setattr(ipsf_module, "BATCH_DEPOSIT_RAYS", 1)
    kw = dict(n_radii=5, depths=(500.0, math.inf),
              settings=TraceSettings(rays=3001, method=method, seed=3))
    one = ipsf_bank(SPHERE, batched=False, **kw)
    calls = []
    both = ipsf_bank(SPHERE, batched=True, progress=lambda: calls.append(1), **kw)
    np.testing.assert_allclose(both.kernels, one.kernels, rtol=0, atol=1e-7)
    np.testing.assert_allclose(both.vignetted, one.vignetted, rtol=0, atol=1e-12)
    np.testing.assert_allclose(both.metadata["outside_kernel"], one.metadata["outside_kernel"],
                               rtol=0, atol=1e-12)
    assert len(calls) == 10


def test_batched_grid_bank_marks_the_same_points():
    kw = dict(kind="grid", grid=(3, 3), settings=TraceSettings(rays=5000))
    one = ipsf_bank(TILTED, batched=False, **kw)
    both = ipsf_bank(TILTED, batched=True, **kw)
    assert both.metadata["valid"] == one.metadata["valid"]
    np.testing.assert_allclose(both.kernels, one.kernels, rtol=0, atol=1e-7)
    np.testing.assert_array_equal(both.vignetted, one.vignetted)


def test_source_batch_refuses_sources_of_different_setups():
    from mitsweep.tracer.ipsf import fit_sampling_box
    from mitsweep.tracer.kernel import SourceBatch
    from mitsweep.tracer.source import source_from_image

    geoms = [source_from_image(s, 0.5, 0.0, 500.0, reference_sensor_distance=58.0).geometry(s)
             for s in (SPHERE, TILTED)]
    params = [fit_sampling_box(g)[0] for g in geoms]
    with pytest.raises(ValueError, match="share the mirror"):
        SourceBatch(geoms, params)
    SourceBatch(geoms[:1] * 2, params[:1] * 2)  # one setup: accepted
