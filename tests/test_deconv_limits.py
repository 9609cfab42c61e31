"""Values at the edge of float range are refused in words, never as RuntimeWarnings."""

import warnings

import numpy as np
import OpenEXR
import pytest

from cli_contract import refused
from mitsweep.deconv import polar_deconvolve, spatially_varying_deconvolve, wiener_deconvolve
from mitsweep.deconv.synthetic import synthetic_grid_bank, synthetic_radial_bank
from mitsweep.deconv.wiener import MAX_ABS_VALUE, MAX_NSR, check_nsr
from mitsweep.io.bank import save_bank

SIZE = 64


def raw_exr(path, image):
    """An EXR written by OpenEXR itself (mitsweep's writer refuses non-finite values)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
              "mitsweep:pixel_pitch": "0.018"}
    with OpenEXR.File(header, {"Y": np.asarray(image, np.float32)}) as f:
        f.write(str(path))
    return path


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(0)
    raw_exr(tmp_path / "image.exr", rng.random((SIZE, SIZE)))
    save_bank(tmp_path / "bank.npz", synthetic_radial_bank((SIZE, SIZE), size=9))
    return tmp_path


def argv(d, *extra):
    return ["deconvolve", d / "image.exr", "--bank", d / "bank.npz", "--out", d / "o.exr",
            *extra]


@pytest.mark.parametrize("nsr", ["1e300", "inf", "1e7"])
def test_an_absurd_nsr_is_refused_naming_the_flag(files, capsys, nsr):
    line = refused(capsys, argv(files, "--nsr", nsr))
    assert "--nsr" in line and f"(0, {MAX_NSR:g}]" in line


def test_the_largest_nsr_computes_cleanly(files, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from mitsweep.cli.main import main

        assert main([str(a) for a in argv(files, "--nsr", f"{MAX_NSR:g}", "--prior",
                                          "constant")]) == 0


@pytest.mark.parametrize("value", [3e38, -3e38, 1e21])
def test_values_near_float32_max_are_refused(files, capsys, value):
    raw_exr(files / "image.exr", np.full((SIZE, SIZE), value))
    line = refused(capsys, argv(files))
    assert "image values reach" in line and "rescale the image" in line


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_pixels_are_refused(files, capsys, bad):
    img = np.ones((SIZE, SIZE))
    img[3, 4] = bad
    raw_exr(files / "image.exr", img)
    assert "holds NaN or infinite values" in refused(capsys, argv(files))


def _calls(img):
    radial = synthetic_radial_bank((SIZE, SIZE), size=9)
    grid = synthetic_grid_bank((SIZE, SIZE), (3, 3), size=9)
    return [lambda nsr: wiener_deconvolve(img, radial.kernels[0, 0], nsr=nsr),
            lambda nsr: polar_deconvolve(img, radial, nsr=nsr),
            lambda nsr: spatially_varying_deconvolve(img, grid, nsr=nsr)]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("method", range(3), ids=["wiener", "polar", "spatial"])
def test_api_refuses_huge_values_and_nsr_without_warnings(dtype, method):
    huge = _calls(np.full((SIZE, SIZE), 1e30, dtype))[method]
    fine = _calls(np.random.default_rng(1).random((SIZE, SIZE)).astype(dtype))[method]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"image values reach 1e\+30"):
            huge(1e-3)
        with pytest.raises(ValueError, match="nsr must be a number in"):
            fine(1e300)


def test_values_just_below_the_bound_deconvolve_finitely():
    img = np.full((SIZE, SIZE), MAX_ABS_VALUE / 2, np.float32)
    img[::7] *= 0.5
    radial = synthetic_radial_bank((SIZE, SIZE), size=9)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = polar_deconvolve(img, radial, nsr=1e-3)
    assert np.all(np.isfinite(out))


@pytest.mark.parametrize("nsr", [-1.0, np.nan, np.inf, MAX_NSR * 10])
def test_check_nsr_bounds(nsr):
    with pytest.raises(ValueError, match="nsr must be a number in"):
        check_nsr(nsr)
    assert check_nsr(0.0) == 0.0 and check_nsr(MAX_NSR) == MAX_NSR


@pytest.mark.parametrize("args,flag", [
    (["--point", "inf", "0"], "--point"),
    (["--point", "0", "nan"], "--point"),
    (["--radius", "inf"], "--radius"),
    (["--radius", "5", "--angle", "inf"], "--angle"),
    (["--radius", "1e9"], "--radius 1e+09 --angle 0: image point"),
    (["--point", "1e9", "0"], "--point 1e+09 0: image point"),
])
def test_ipsf_points_off_the_mirror_are_refused_naming_the_flag(capsys, scenes_dir, args, flag):
    line = refused(capsys, ["ipsf", scenes_dir / "sphere.toml", *args, "--rays", "1000"])
    assert flag in line
