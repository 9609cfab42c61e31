"""TraceSettings: one parameter object for the tracing entry points and the bank cache.

The separate sampling keywords still work for one release, with a DeprecationWarning,
and give the same bits; the bank cache's key is that of the keyword API for equal
settings (banks cached before still hit), and ignores the deposit strategy.
"""

import json
import warnings

import numpy as np
import pytest

from mitsweep import __version__
from mitsweep.config import load_setup
from mitsweep.tracer import TraceSettings, integrated_psf, ipsf_bank
from mitsweep.tracer.cache import CACHE_LAYOUT, bank_cache_key, cached_bank
from mitsweep.tracer.ipsf import integrated_psfs
from mitsweep.tracer.kernel import TRACE_REVISION, DepositStrategy

SPHERE = load_setup("scenes/sphere.toml")
SMALL = TraceSettings(rays=1 << 13, kernel_size=11, seed=2)


@pytest.mark.parametrize("kw,message", [
    ({"rays": 0}, "rays: must be >= 1"),
    ({"rays": 2.5}, "rays: must be >= 1"),
    ({"kernel_size": 4}, "kernel_size: must be an odd integer >= 3"),
    ({"kernel_size": 1}, "kernel_size: must be an odd integer >= 3"),
    ({"kernel_size": True}, "kernel_size: must be an odd integer >= 3"),
    ({"method": "planar"}, "method: must be one of exact, continuous, planes"),
    ({"method": "continuous", "time_samples": 0}, r"time_samples: must be in \[1, 64\]"),
    ({"method": "planes", "n_planes": 65}, r"n_planes: must be in \[1, 64\]"),
    ({"seed": "7"}, "seed: must be an integer"),
    ({"deposit": {"copies": 1}}, "deposit: must be a DepositStrategy"),
])
def test_trace_settings_reject_bad_values_naming_the_key(kw, message):
    with pytest.raises(ValueError, match=message):
        TraceSettings(**kw)


def test_trace_settings_are_frozen_keyword_only_and_normalised():
    s = TraceSettings(rays=1e6, kernel_size=np.int64(15))
    assert s.rays == 1_000_000 and type(s.rays) is int and type(s.kernel_size) is int
    with pytest.raises(AttributeError):
        s.rays = 5
    with pytest.raises(TypeError):
        TraceSettings(1000)
    # the other method's count is not checked (as the keywords were not)
    assert TraceSettings(method="exact", n_planes=100).n_planes == 100


def test_old_keywords_warn_and_give_the_same_bits():
    new, info_new = integrated_psf(SPHERE, 0.5, 0.0, 800.0, settings=SMALL)
    with pytest.warns(DeprecationWarning, match=r"integrated_psf\(kernel_size=, rays=, seed="):
        old, info_old = integrated_psf(SPHERE, 0.5, 0.0, 800.0, rays=1 << 13, kernel_size=11,
                                       seed=2)
    assert np.array_equal(new, old)
    assert info_new["rays_landed"] == info_old["rays_landed"]
    # keywords override the given settings' fields
    with pytest.warns(DeprecationWarning):
        over, _ = integrated_psf(SPHERE, 0.5, 0.0, 800.0, settings=TraceSettings(seed=2),
                                 rays=1 << 13, kernel_size=11)
    assert np.array_equal(new, over)


def test_settings_reach_every_entry_point_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        one, _ = integrated_psf(SPHERE, 0.0, 0.0, 500.0, settings=SMALL)
        many = integrated_psfs(SPHERE, [(0.0, 0.0, 500.0)], settings=SMALL)
        bank = ipsf_bank(SPHERE, n_radii=2, depths=(500.0,), settings=SMALL)
    # integrated_psfs defaults its seeds to settings.seed; the bank's point j uses seed + j
    assert many[0][0].shape == one.shape == (11, 11)
    np.testing.assert_allclose(many[0][0], one, rtol=0, atol=1e-6)  # float64 summation order
    np.testing.assert_allclose(bank.kernels[0, 0], one, rtol=0, atol=1e-6)
    assert bank.metadata["rays_per_ipsf"] == SMALL.rays and bank.metadata["seed"] == 2
    with pytest.warns(DeprecationWarning, match="ipsf_bank"):
        old = ipsf_bank(SPHERE, n_radii=2, depths=(500.0,), rays=1 << 13, kernel_size=11,
                        seed=2)
    assert np.array_equal(old.kernels, bank.kernels)


@pytest.mark.parametrize("call", [
    lambda: integrated_psf(SPHERE, 0.0, 0.0, 500.0, ray=10),
    lambda: integrated_psfs(SPHERE, [(0.0, 0.0, 500.0)], seed=3),
    lambda: ipsf_bank(SPHERE, exact=True),
    lambda: bank_cache_key(SPHERE, time_samples=2),
])
def test_unknown_keywords_are_type_errors(call):
    with pytest.raises(TypeError, match="unexpected keyword argument"):
        call()


def test_cache_key_is_the_keyword_apis_for_equal_settings():
    """The trace part of the key, written out as the keyword API built it (its digest
    names the cache entry): banks cached before TraceSettings still hit."""
    name, _, trace = bank_cache_key(SPHERE, settings=TraceSettings(rays=20_000, seed=3),
                                    depths=(500.0, float("inf")), n_radii=5)
    assert trace == {"kind": "radial", "depths_mm": [500.0, "inf"], "rays": 20_000,
                     "kernel_size": 31, "seed": 3, "method": "exact", "time_samples": 4,
                     "version": __version__, "layout": CACHE_LAYOUT,
                     "trace_revision": TRACE_REVISION, "n_radii": 5}
    with pytest.warns(DeprecationWarning):
        old = bank_cache_key(SPHERE, rays=20_000, seed=3, depths=(500.0, float("inf")),
                             n_radii=5)
    assert old[0] == name
    import hashlib
    digest = hashlib.sha256(json.dumps(trace, sort_keys=True).encode()).hexdigest()
    assert name.endswith(digest[:12])


def test_cache_key_ignores_the_deposit_strategy_and_follows_the_rest():
    key = bank_cache_key(SPHERE, settings=SMALL)[0]
    fast = TraceSettings(rays=SMALL.rays, kernel_size=11, seed=2,
                         deposit=DepositStrategy(copies=1, coherent=False))
    assert bank_cache_key(SPHERE, settings=fast)[0] == key
    for other in (TraceSettings(rays=SMALL.rays + 2, kernel_size=11, seed=2),
                  TraceSettings(rays=SMALL.rays, kernel_size=11, seed=3),
                  TraceSettings(rays=SMALL.rays, kernel_size=11, seed=2, method="planes",
                                n_planes=8)):
        assert bank_cache_key(SPHERE, settings=other)[0] != key


def test_cached_bank_takes_settings_and_hits_its_own_entry(tmp_path):
    first = cached_bank(SPHERE, n_radii=2, settings=SMALL, cache_dir=tmp_path)
    assert first.traced and first.path is not None
    with pytest.warns(DeprecationWarning, match="cached_bank"):
        again = cached_bank(SPHERE, n_radii=2, rays=SMALL.rays, kernel_size=11, seed=2,
                            cache_dir=tmp_path)
    assert not again.traced and again.path == first.path
    assert np.array_equal(again.bank.kernels, first.bank.kernels)
