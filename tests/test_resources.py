"""Sizes that cannot fit are refused before anything is allocated, saying what they need."""

from dataclasses import replace

import numpy as np
import pytest

from cli_contract import refused
from memory_peak import traced_peak
from mitsweep import resources
from mitsweep.config import DEFAULT_SETUP, Sensor
from mitsweep.deconv import polar_deconvolve, spatially_varying_deconvolve, wiener_deconvolve
from mitsweep.deconv.kernels import grid_bank_from_radial
from mitsweep.deconv.synthetic import synthetic_grid_bank, synthetic_radial_bank
from mitsweep.io import write_exr
from mitsweep.io.bank import save_bank
from mitsweep.resources import (GIB, MAX_MEMORY_ENV, ResourceError, check_allocation,
                                format_bytes)

SPHERE = """\
[mirror]
kind = "sphere"
radius = 25.0
center_distance = 352.0
[sweep]
fov_deg = 237.0
[sensor]
resolution = [{w}, {h}]
pixel_pitch = {pitch}
"""


@pytest.mark.parametrize("nbytes,text", [(512, "512 B"), (3 << 20, "3.0 MiB"),
                                         (48 * GIB, "48.0 GiB"), (1.5 * (GIB << 10), "1.5 TiB")])
def test_sizes_are_shown_in_binary_units(nbytes, text):
    assert format_bytes(nbytes) == text


def test_available_memory_is_read_from_the_system():
    avail = resources.available_memory_bytes()
    assert 0 < avail < (1 << 50)     # some memory, less than a petabyte


def test_over_the_cap_names_the_need_the_cap_and_the_variable(monkeypatch):
    monkeypatch.delenv(MAX_MEMORY_ENV, raising=False)
    with pytest.raises(ResourceError, match=r"^film: needs 65\.0 GiB, over the 64\.0 GiB cap "
                                            r"\(\$MITSWEEP_MAX_MEMORY_GB\)"):
        check_allocation("film", 65 * GIB)
    check_allocation("film", GIB // 2)                # well inside both limits


def test_the_cap_follows_the_environment(monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, "0.5")
    with pytest.raises(ResourceError, match=r"needs 1\.0 GiB, over the 512\.0 MiB cap"):
        check_allocation("x", GIB)
    monkeypatch.setenv(MAX_MEMORY_ENV, "lots")
    with pytest.raises(ResourceError, match=r"MITSWEEP_MAX_MEMORY_GB: expected a positive number"):
        check_allocation("x", 1)


def test_more_than_available_says_how_much_is_available(monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, "1000")
    monkeypatch.setattr(resources, "available_memory_bytes", lambda: int(21.3 * GIB))
    with pytest.raises(ResourceError, match=r"^render: needs 48\.0 GiB, 21\.3 GiB available"):
        check_allocation("render", 48 * GIB)


# -- the estimates against NumPy's own accounting --------------------------------------

def _spy(monkeypatch):
    seen = []
    real = resources.check_allocation

    def spy(what, nbytes):
        seen.append(nbytes)
        real(what, nbytes)
    import mitsweep.deconv.polar as polar
    import mitsweep.deconv.spatial as spatial
    import mitsweep.deconv.wiener as wiener
    for mod in (polar, spatial, wiener):
        monkeypatch.setattr(mod, "check_allocation", spy)
    return seen


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("method", ["wiener", "polar", "spatial"])
def test_deconvolution_estimates_bound_the_traced_peak(monkeypatch, method, channels, dtype):
    # tracemalloc sees every NumPy array (not pocketfft's scratch), Dr.Jit's watermark
    # its kernels' arrays (the polar resampling's): the estimate must cover
    # that peak, without crying wolf (measured 1.07-1.6x of it on 256² images).
    # The measurement is of the call, not of the first import of Dr.Jit that the polar
    # resampling makes: tracemalloc counts the modules' objects too (4.7 MB, 13.1 against
    # 8.1 MB for polar at 256², when this test ran without another test importing Dr.Jit
    # first). Importing is not a warm-up call: Dr.Jit's watermark of a second call would
    # miss the arrays its allocator cached in the first.
    from mitsweep import jit

    if jit.available() is not None:
        import mitsweep.jit.spline  # noqa: F401
    shape = (256, 256) if channels == 1 else (256, 256, channels)
    img = np.random.default_rng(0).random(shape).astype(dtype)
    radial = synthetic_radial_bank((256, 256), size=15)
    grid = synthetic_grid_bank((256, 256), (5, 5), size=15)
    run = {"wiener": lambda: wiener_deconvolve(img, radial.kernels[0, 3], nsr=1e-3),
           "polar": lambda: polar_deconvolve(img, radial, nsr=1e-3),
           "spatial": lambda: spatially_varying_deconvolve(img, grid, nsr=1e-3)}[method]
    seen = _spy(monkeypatch)
    peak = traced_peak(run)
    estimate = max(seen)
    assert peak <= estimate <= 2 * peak, (peak, estimate)


# -- refusals through the API ----------------------------------------------------------

def test_grid_bank_from_radial_refuses_a_5000_grid_before_allocating():
    bank = synthetic_radial_bank((96, 96), size=31)
    # 25e6 kernels of 31² px: float64 (179 GiB, the MemoryError once met) + a float32 copy
    with pytest.raises(ResourceError, match=r"grid bank of 5000x5000 points .*: needs 268\.5 GiB"):
        grid_bank_from_radial(bank, (5000, 5000), (96, 96))


def test_a_huge_kernel_is_refused_before_tracing():
    from mitsweep.tracer import integrated_psf

    with pytest.raises(ResourceError, match=r"100001x100001 px kernel: needs \d+\.\d GiB"):
        integrated_psf(DEFAULT_SETUP, 0.0, 0.0, 500.0, kernel_size=100001)


def test_a_huge_bank_is_refused_before_tracing():
    from mitsweep.tracer import ipsf_bank

    with pytest.raises(ResourceError, match=r"IPSF bank of 25000000 points x 1 depths"):
        ipsf_bank(DEFAULT_SETUP, kind="grid", grid=(5000, 5000))


def test_a_render_over_the_cap_is_refused_before_mitsuba_runs(monkeypatch):
    from mitsweep.render import api

    monkeypatch.setenv(MAX_MEMORY_ENV, "0.001")          # ~1 MiB
    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(256, 256), pixel_pitch=0.036))
    monkeypatch.setattr(api, "render_passes", lambda *a, **k: pytest.fail("rendered"))
    with pytest.raises(ResourceError, match=r"render of 256x256 px .*: needs .* over the 1\.0 MiB"):
        api.render_image(setup, "pinhole", spp=4)


def test_render_estimate_counts_the_full_image():
    from mitsweep.render.api import render_memory_bytes

    need = render_memory_bytes((30000, 30000), (30000, 30000), 64)
    assert need > 30000 * 30000 * 3 * 4 * 4          # image, film, accumulators at least
    assert need > 64 * GIB


def test_deconvolutions_respect_the_cap(monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, str(64 / 1024 / 1024))   # 64 KiB
    img = np.ones((64, 64), np.float32)
    bank = synthetic_radial_bank((64, 64), size=9)
    for fn, what in ((lambda: polar_deconvolve(img, bank, nsr=1e-3), "polar deconvolution"),
                     (lambda: wiener_deconvolve(img, bank.kernels[0, 0], nsr=1e-3),
                      "Wiener deconvolution"),
                     (lambda: spatially_varying_deconvolve(
                         img, synthetic_grid_bank((64, 64), (3, 3), size=9), nsr=1e-3),
                      "spatially varying deconvolution")):
        with pytest.raises(ResourceError, match=what):
            fn()


# -- refusals through the CLI ----------------------------------------------------------

def test_render_of_a_32768_frame_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv(MAX_MEMORY_ENV, raising=False)
    s = tmp_path / "big.toml"
    s.write_text(SPHERE.format(w=32768, h=32768, pitch=0.0003))
    line = refused(capsys, ["render", s, "--mode", "pinhole", "--spp", "1",
                            "--out", tmp_path / "o.exr", "--full-frame"])
    assert "render of 32768x32768 px" in line and "needs" in line and "GiB" in line
    assert not (tmp_path / "o.exr").exists()


def test_resolution_beyond_the_config_bound_is_refused(tmp_path, capsys):
    s = tmp_path / "huge.toml"
    s.write_text(SPHERE.format(w=65536, h=65536, pitch=0.018))
    assert "sensor.resolution" in refused(capsys, ["sweep-range", s])


@pytest.mark.parametrize("args,words", [
    (["--kernel-size", "100001"], "--kernel-size: must be odd, >= 3 and smaller than the 512x512"),
    (["--kernel-size", "513"], "smaller than the 512x512 sensor"),
    (["--bank", "grid", "--grid", "5000", "5000"], "--grid 5000 5000: at most 512 512"),
    (["--bank", "radial", "--radii", "100000"], "--radii 100000: at most 512"),
])
def test_ipsf_sizes_are_bounded_by_the_sensor(tmp_path, capsys, args, words):
    s = tmp_path / "s.toml"
    s.write_text(SPHERE.format(w=512, h=512, pitch=0.018))
    assert words in refused(capsys, ["ipsf", s, *args, "--rays", "1000"])


def test_deconvolve_grid_is_bounded_by_the_image(tmp_path, capsys):
    write_exr(tmp_path / "i.exr", np.ones((96, 96), np.float32), metadata={"pixel_pitch": 0.018})
    save_bank(tmp_path / "b.npz", synthetic_radial_bank((96, 96), size=13))
    line = refused(capsys, ["deconvolve", tmp_path / "i.exr", "--bank", tmp_path / "b.npz",
                            "--out", tmp_path / "o.exr", "--method", "grid", "--grid", "5000"])
    assert "--grid 5000: at most 24 for a 96x96 image" in line
