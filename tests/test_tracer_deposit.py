"""How the deposit runs, not what it computes: the coherent lane order is a permutation
of the same samples, the per-block buffer copies sum to the single buffer, and every
deposit strategy gives the same IPSF up to the float64 summation order."""

import numpy as np
import pytest

from mitsweep import backend
from mitsweep.config import load_setup
from mitsweep.optics.reference import reference_geometry
from mitsweep.tracer import TraceSettings, integrated_psf, ipsf_bank
from mitsweep.tracer import kernel, sampling
from mitsweep.tracer.deposit import MAX_COPIES, DepositStrategy
from mitsweep.tracer.bank import field_radius

SPHERE = load_setup("scenes/sphere.toml")
GEOM = reference_geometry(SPHERE)
EDGE = field_radius(SPHERE, GEOM)


def _signed_fractions(h, generators):
    """|frac(h g_j)| as signed 32-bit fixed point, for each generator, max over j."""
    h = np.asarray(h, dtype=np.uint64)
    out = np.zeros(h.shape)
    for g in generators:
        v = ((h * np.uint64(g)) & np.uint64(0xFFFFFFFF)).astype(np.int64)
        out = np.maximum(out, np.abs(np.where(v >= 2 ** 31, v - 2 ** 32, v)) / 2.0 ** 32)
    return out


def test_r2_steps_are_the_successive_closest_returns():
    h = np.arange(1, sampling.R2_STEPS[-1] + 1)
    d = _signed_fractions(h, sampling.R2)
    records = h[d < np.minimum.accumulate(np.concatenate(([np.inf], d[:-1])))]
    assert tuple(int(x) for x in records[records > sampling.GROUP]) == sampling.R2_STEPS
    # the largest step keeps a group of 16 lanes within 1 % of the unit square
    assert sampling.GROUP * _signed_fractions(922111, sampling.R2) < 0.011


@pytest.mark.parametrize("count", [1, 15, 16, 591, 592, 593, 4096, 12345, 1 << 14,
                                   1_000_003,
                                   pytest.param(1 << 24, marks=pytest.mark.slow)])  # 3 s
def test_coherent_order_is_a_permutation(count):
    m = backend.drjit_module()
    import drjit as dr

    idx = sampling.coherent_order(dr.arange(m.UInt32, count), count).numpy()
    assert np.array_equal(np.sort(idx), np.arange(count))
    segments = sampling.coherent_segments(count)
    assert len(segments) == sampling.SEGMENTS
    covered = sum(sampling.GROUP * h for _, h in segments if h > 1)
    # the lanes left in order: fewer than 0.3 % of a launch of 2^24 (measured 46240)
    if count >= 1 << 20:
        assert count - covered < 3e-3 * count


def test_fold_buffer_sums_the_copies():
    m = backend.drjit_module()
    a = np.arange(3 * 2 * 11, dtype=np.float64)  # 3 copies of 2 sources of a 3x3 kernel
    folded = kernel.fold_buffer(m.Float64(a), 2, 3)
    assert folded.shape == (2, 11)
    assert np.array_equal(folded, a.reshape(3, 2, 11).sum(axis=0))


def test_deposit_copies_is_a_power_of_two():
    c = kernel.deposit_copies()
    assert c >= 1 and c & (c - 1) == 0 and c <= MAX_COPIES
    for bad in (0, 3, 2 * MAX_COPIES):
        with pytest.raises(ValueError, match="power of two"):
            DepositStrategy(copies=bad)
    with pytest.raises(ValueError, match="ReduceMode"):
        DepositStrategy(mode="Fastest")
    assert kernel.deposit_copies(DepositStrategy(copies=4)) == 4


def test_deposit_strategy_scope_is_deprecated_and_context_local():
    """The old scope still applies its strategy (for one release), warns, and restores
    the default on exit; it sets a context variable, not module globals."""
    with pytest.warns(DeprecationWarning, match="DepositStrategy"):
        with kernel.deposit_strategy_scope(copies=2, coherent=False):
            assert kernel.resolve_strategy(None) == DepositStrategy(copies=2, coherent=False)
            assert kernel.resolve_strategy(DepositStrategy()) == DepositStrategy()
            assert kernel.deposit_copies() == 2  # as the old scope set the count
    assert kernel.resolve_strategy(None) == DepositStrategy()


def test_deprecated_scope_still_reaches_the_ipsf_deposits(monkeypatch):
    """Under the old scope, integrated_psf with default settings deposits with the scoped
    strategy; an explicit TraceSettings.deposit wins over it."""
    from mitsweep.tracer import ipsf

    seen = []
    real = ipsf.deposit_segments

    def spy(*args, **kw):
        seen.append(kw["strategy"])
        return real(*args, **kw)

    monkeypatch.setattr(ipsf, "deposit_segments", spy)
    scoped = DepositStrategy(copies=2, coherent=False)
    explicit = DepositStrategy(copies=1)
    with pytest.warns(DeprecationWarning):
        with kernel.deposit_strategy_scope(copies=2, coherent=False):
            integrated_psf(SPHERE, 0.0, 0.0, 500.0, settings=TraceSettings(rays=1 << 12))
            integrated_psf(SPHERE, 0.0, 0.0, 500.0,
                           settings=TraceSettings(rays=1 << 12, deposit=explicit))
    assert seen == [scoped, explicit]
    with pytest.raises(ValueError, match="power of two"):
        with pytest.warns(DeprecationWarning):
            with kernel.deposit_strategy_scope(copies=3):
                pass


@pytest.mark.parametrize("method, extra", [("exact", {}), ("continuous", {"time_samples": 2}),
                                           ("planes", {"n_planes": 4})])
def test_every_deposit_strategy_gives_the_same_ipsf(method, extra):
    """One shared buffer with plain atomics (the earlier deposit), per-block copies,
    Dr.Jit's Expand, with and without the coherent order: the same rays, so kernels and
    fractions agree to float64 summation order (bound 1e-7 in L1, as for batching)."""
    import drjit as dr

    runs = []
    for kw in ({"copies": 1, "mode": dr.ReduceMode.Direct, "coherent": False}, {},
               {"copies": 1, "mode": dr.ReduceMode.Expand}, {"coherent": False}):
        settings = TraceSettings(rays=300_000, method=method, deposit=DepositStrategy(**kw),
                                 **extra)
        runs.append(integrated_psf(SPHERE, 0.9 * EDGE, 0.0, 500.0, sweep=GEOM.sweep,
                                   settings=settings))
    k0, i0 = runs[0]
    for k, info in runs[1:]:
        assert np.abs(k - k0).sum() < 1e-7
        assert info["outside_kernel_fraction"] == pytest.approx(i0["outside_kernel_fraction"],
                                                                abs=1e-9)
        assert info["rays_landed"] == i0["rays_landed"]


def test_batched_bank_with_copies_matches_single_buffer():
    import drjit as dr

    kw = dict(kind="radial", n_radii=3, depths=(500.0, 5000.0))
    single = DepositStrategy(copies=1, mode=dr.ReduceMode.Direct, coherent=False)
    a = ipsf_bank(SPHERE, settings=TraceSettings(rays=1 << 14, seed=3, deposit=single),
                  **kw).kernels
    b = ipsf_bank(SPHERE, settings=TraceSettings(rays=1 << 14, seed=3), **kw).kernels
    assert np.abs(a - b).sum(axis=(2, 3)).max() < 1e-7
