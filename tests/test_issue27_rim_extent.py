"""Banks to the rim in the tracer (issue 27, item 3): ``ipsf_bank(..., extent="rim")``.

A radial rim bank is the FOV bank with points at the same spacing out to the image of
the mirror's rim, traced with the same settings and the next seeds (the same kernels as
extending the FOV bank afterwards, :func:`mitsweep.tracer.bank.extend_to_rim`); a grid
rim bank gives its off-mirror nodes the nearest traced kernel, as
:func:`mitsweep.deconv.kernels.fill_invalid_nodes` does. The default ``"fov"`` bank and
its cache key are unchanged."""

from pathlib import Path

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.optics.reference import reference_geometry
from mitsweep.tracer import ipsf_bank
from mitsweep.tracer.bank import (EXTENTS, extend_to_rim, field_radius, fill_off_mirror_nodes,
                                  rim_field_radius)
from mitsweep.tracer.settings import TraceSettings

ROOT = Path(__file__).resolve().parents[1]
SETTINGS = TraceSettings(rays=20_000, kernel_size=15)


@pytest.fixture(scope="module")
def paraboloid():
    setup = load_setup(ROOT / "scenes" / "paraboloid.toml")
    fov = ipsf_bank(setup, n_radii=5, settings=SETTINGS)
    rim = ipsf_bank(setup, n_radii=5, settings=SETTINGS, extent="rim")
    return setup, fov, rim


def test_radial_rim_bank_covers_the_rim_radius(paraboloid):
    setup, fov, rim = paraboloid
    geometry = reference_geometry(setup)
    r_fov, r_rim = field_radius(setup, geometry), rim_field_radius(setup, geometry)
    assert r_rim > 1.1 * r_fov                 # the paraboloid's mirror extends past its FOV
    radii = np.asarray(rim.radii)
    assert float(radii[-1]) == pytest.approx(r_rim, rel=1e-12)
    # the FOV's points first, then the same spacing (at most) out to the rim
    np.testing.assert_array_equal(radii[:5], fov.radii)
    step = float(np.diff(fov.radii)[0])
    assert np.all(np.diff(radii[4:]) <= step * (1 + 1e-9))
    assert rim.kernels.shape == (1, len(radii), 15, 15)
    assert rim.metadata["extent"] == "rim"
    assert rim.metadata["fov_radius_mm"] == pytest.approx(r_fov, rel=1e-12)
    assert rim.metadata["rim_radius_mm"] == pytest.approx(r_rim, rel=1e-12)
    assert rim.metadata["rim_points"] == len(radii) - 5
    assert "extent" not in fov.metadata        # the default bank's metadata as before
    # each rim kernel is a traced IPSF, not the stand-in delta: normalised to unit sum
    # (float32 rounding: 1e-6; measured 1.0) and spread (peak 0.13 measured; a delta is 1)
    for k in rim.kernels[0, 5:]:
        assert k.sum() == pytest.approx(1.0, abs=1e-6) and k.max() < 0.9


def test_radial_rim_bank_is_the_fov_bank_extended(paraboloid):
    """Tracing to the rim at once and extending the FOV bank afterwards give the same
    kernels (same settings, point j seeded seed + j), to the deposit's summation order."""
    setup, fov, rim = paraboloid
    ext = extend_to_rim(setup, fov)
    np.testing.assert_array_equal(ext.radii, rim.radii)
    # float32 kernels: 1e-6 allows the deposit's summation order (measured: identical)
    np.testing.assert_allclose(ext.kernels, rim.kernels, atol=1e-6)
    np.testing.assert_allclose(ext.vignetted, rim.vignetted, atol=1e-9)
    for key in ("extent", "fov_radius_mm", "rim_radius_mm", "rim_points"):
        assert ext.metadata[key] == pytest.approx(rim.metadata[key])
    # a rim bank is already at the rim: extending it adds nothing
    again = extend_to_rim(setup, rim)
    assert again.kernels is rim.kernels
    assert again.metadata["fov_radius_mm"] == rim.metadata["fov_radius_mm"]


def test_pipeline_rim_bank_keeps_its_public_behaviour(paraboloid):
    from mitsweep.pipeline.rim import rim_bank, rim_image_radius, rim_radii

    setup, fov, rim = paraboloid
    ref = reference_geometry(setup).sensor_distance
    assert rim_image_radius(setup, ref) == rim_field_radius(setup)
    np.testing.assert_array_equal(rim_radii(fov, rim_image_radius(setup, ref)),
                                  np.asarray(rim.radii)[5:])
    ext = rim_bank(setup, fov)
    # float32 kernels: 1e-6 allows the deposit's summation order (measured: identical)
    np.testing.assert_allclose(ext.kernels, rim.kernels, atol=1e-6)
    assert ext.metadata["fov_radius_mm"] == pytest.approx(float(np.max(fov.radii)))
    with pytest.raises(ValueError, match="extends radial banks"):
        rim_bank(setup, ipsf_bank(setup, kind="grid", grid=(2, 2), settings=SETTINGS))


def test_grid_rim_bank_fills_off_mirror_nodes_as_fill_invalid_nodes_does():
    from mitsweep.deconv.kernels import fill_invalid_nodes

    setup = load_setup(ROOT / "scenes" / "paraboloid_tilted.toml")
    s = TraceSettings(rays=8_000, kernel_size=11)
    fov = ipsf_bank(setup, kind="grid", grid=(3, 3), settings=s)
    rim = ipsf_bank(setup, kind="grid", grid=(3, 3), settings=s, extent="rim")
    valid = np.asarray(fov.metadata["valid"], bool)
    assert not valid.all() and valid.any()      # corners of the sensor miss the mirror
    ref = fill_invalid_nodes(fov)
    np.testing.assert_array_equal(rim.kernels, ref.kernels)
    np.testing.assert_array_equal(rim.kernels[:, valid], fov.kernels[:, valid])
    assert rim.metadata["filled_nodes"] == ref.metadata["filled_nodes"] == \
        np.flatnonzero(~valid).tolist()
    assert rim.metadata["filled_from"] == ref.metadata["filled_from"]
    assert rim.metadata["extent"] == "rim" and rim.metadata["valid"] == fov.metadata["valid"]
    # the tracer's own fill is the deconv one, and extend_to_rim of the FOV grid bank
    # is the rim grid bank
    np.testing.assert_array_equal(fill_off_mirror_nodes(fov).kernels, ref.kernels)
    np.testing.assert_array_equal(extend_to_rim(setup, fov).kernels, rim.kernels)


def test_unknown_extent_is_refused_before_tracing():
    setup = load_setup(ROOT / "scenes" / "paraboloid.toml")
    assert EXTENTS == ("fov", "rim")
    with pytest.raises(ValueError, match="extent: must be one of 'fov', 'rim', got 'mirror'"):
        ipsf_bank(setup, n_radii=3, extent="mirror")


def test_fov_default_keeps_the_bank_and_its_cache_key():
    """``extent="fov"`` is the default: the same kernels as without it, and the cache key
    has no extent (banks cached before still hit)."""
    from mitsweep.tracer.cache import bank_cache_key

    setup = load_setup(ROOT / "scenes" / "sphere.toml")
    s = TraceSettings(rays=4_000, kernel_size=9)
    a = ipsf_bank(setup, n_radii=3, settings=s)
    b = ipsf_bank(setup, n_radii=3, settings=s, extent="fov")
    np.testing.assert_array_equal(a.kernels, b.kernels)
    np.testing.assert_array_equal(a.radii, b.radii)
    assert set(a.metadata) - {"seconds"} == set(b.metadata) - {"seconds"}
    name, _, trace = bank_cache_key(setup, settings=s, n_radii=3)
    assert "extent" not in trace


def test_rim_radii_former_keyword_still_works_with_a_warning():
    from mitsweep.deconv.synthetic import synthetic_radial_bank
    from mitsweep.pipeline.rim import rim_radii

    bank = synthetic_radial_bank((64, 64), n_radii=5, r_max_px=20.0, pixel_pitch=0.1)
    with pytest.warns(DeprecationWarning, match="rim_mm"):
        old = rim_radii(bank, rim_mm=3.3)
    np.testing.assert_array_equal(old, rim_radii(bank, rim=3.3))


def test_a_rim_bank_is_cached_under_a_key_of_its_own(tmp_path, paraboloid):
    """``cached_bank(extent="rim")`` traces the rim bank once and reads it back; its key
    differs from the FOV bank's, whose key is unchanged (no ``extent`` in it)."""
    from mitsweep.tracer.cache import bank_cache_key, cached_bank

    setup, _fov, rim = paraboloid
    fov_name, _, fov_trace = bank_cache_key(setup, settings=SETTINGS, n_radii=5)
    rim_name, _, rim_trace = bank_cache_key(setup, settings=SETTINGS, n_radii=5, extent="rim")
    assert rim_name != fov_name and "extent" not in fov_trace
    assert rim_trace == {**fov_trace, "extent": "rim"}
    first = cached_bank(setup, settings=SETTINGS, n_radii=5, extent="rim", cache_dir=tmp_path)
    again = cached_bank(setup, settings=SETTINGS, n_radii=5, extent="rim", cache_dir=tmp_path)
    assert first.traced and not again.traced and first.path == again.path
    assert first.path.parent.name == rim_name
    np.testing.assert_array_equal(again.bank.kernels, first.bank.kernels)
    np.testing.assert_array_equal(again.bank.radii, rim.radii)   # to the rim
    assert again.bank.metadata["extent"] == "rim"
    with pytest.raises(ValueError, match="extent: must be one of 'fov', 'rim'"):
        bank_cache_key(setup, settings=SETTINGS, extent="whole")
