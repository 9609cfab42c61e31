"""``mitsweep deconvolve``: real EXR and bank files in and out, clear errors."""

import json

import numpy as np
import pytest
from skimage import data, transform

from mitsweep.cli.main import main
from mitsweep.deconv.metrics import disk_mask, psnr
from mitsweep.deconv.spatial import scatter_blur
from mitsweep.deconv.synthetic import (synthetic_grid_bank, synthetic_kernel_field,
                                       synthetic_radial_bank)
from mitsweep.io import read_exr, write_exr
from mitsweep.io.bank import save_bank

SIZE, K = 96, 13


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("deconv_cli")
    sharp = transform.resize(data.camera() / 255.0, (SIZE, SIZE), anti_aliasing=True)
    blurred = scatter_blur(sharp, synthetic_kernel_field(sharp.shape, size=K))
    write_exr(d / "sweep.exr", blurred.astype(np.float32), metadata={"pixel_pitch": 0.018})
    rgb = np.stack([blurred, blurred, blurred], -1).astype(np.float32)
    write_exr(d / "sweep_rgb.exr", rgb, metadata={"pixel_pitch": 0.018})
    save_bank(d / "radial.npz", synthetic_radial_bank(sharp.shape, size=K))
    save_bank(d / "grid.npz", synthetic_grid_bank(sharp.shape, (9, 9), size=K))
    save_bank(d / "other.npz", synthetic_radial_bank((128, 128), size=K))
    save_bank(d / "pitch.npz", synthetic_radial_bank(sharp.shape, size=K, pixel_pitch=0.009))
    return d, sharp, blurred


@pytest.mark.parametrize("bank,method", [("radial", "polar"), ("grid", "grid"),
                                         ("radial", "grid")])
def test_deconvolve_writes_a_restored_exr_with_provenance(files, capsys, bank, method):
    d, sharp, blurred = files
    out = d / f"out_{bank}_{method}.exr"
    rc = main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / f"{bank}.npz"),
               "--out", str(out), "--nsr", "1e-4", "--method", method, "--grid", "9", "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["method"] == method
    chans, meta = read_exr(out)
    restored = chans["Y"]
    assert meta["bank"].endswith(f"{bank}.npz") and meta["nsr"] == 1e-4
    assert meta["method"] == method and "version" in meta
    m = disk_mask(sharp.shape, 40)
    # restoration gains >= 6 dB over the blurred image inside the disk (measured 9.4-10.8 dB
    # on this small image; float32 EXR storage costs nothing at this level)
    assert psnr(restored, sharp, mask=m) > psnr(blurred, sharp, mask=m) + 6


def test_colour_exr_round_trips(files, capsys):
    d, _, _ = files
    out = d / "out_rgb.exr"
    assert main(["deconvolve", str(d / "sweep_rgb.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(out)]) == 0
    chans, _ = read_exr(out)
    assert set(chans) == {"R", "G", "B"}
    np.testing.assert_array_equal(chans["R"], chans["G"])


@pytest.mark.parametrize("args,message", [
    (["--bank", "{d}/other.npz"], "128x128 sensor"),
    (["--bank", "{d}/pitch.npz"], "pixel pitch"),
    (["--bank", "{d}/missing.npz"], "no such bank file"),
    (["--bank", "{d}/sweep.exr"], "not an IPSF bank"),
    (["--bank", "{d}/radial.npz", "--depth", "near"], "--depth"),
    (["--bank", "{d}/radial.npz", "--method", "polar", "--out", "{d}/x.png"], ".exr"),
    (["--bank", "{d}/radial.npz", "--center", "200", "10"], "outside"),
    (["--bank", "{d}/grid.npz", "--center", "40", "40"], "(radial banks) only"),
])
def test_bad_inputs_get_one_clear_line_and_status_2(files, capsys, args, message):
    d, _, _ = files
    argv = ["deconvolve", str(d / "sweep.exr"), "--out", str(d / "never.exr")]
    argv += [a.format(d=d) for a in args]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mitsweep: error:") and message in err and "\n" not in err
    assert not (d / "never.exr").exists()


def test_center_option_moves_the_pole(files, capsys):
    d, _, _ = files
    a, b = d / "c_default.exr", d / "c_shifted.exr"
    assert main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(a), "--nsr", "1e-3"]) == 0
    assert main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(b), "--nsr", "1e-3", "--center", "47.5", "47.5"]) == 0
    ya, ma = read_exr(a)
    yb, mb = read_exr(b)
    np.testing.assert_array_equal(ya["Y"], yb["Y"])      # 47.5 is this image's centre
    assert ma["center_rc"] is None and mb["center_rc"] == [47.5, 47.5]


def test_missing_image_is_reported(files, capsys):
    d, _, _ = files
    assert main(["deconvolve", str(d / "nope.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(d / "o.exr")]) == 2
    assert "no such image file" in capsys.readouterr().err


def test_image_without_usable_channels_is_reported(files, capsys):
    d, _, _ = files
    write_exr(d / "depth_only.exr", channels={"depth.Z": np.ones((SIZE, SIZE), np.float32)})
    assert main(["deconvolve", str(d / "depth_only.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(d / "o.exr")]) == 2
    assert "Y channel or R, G, B" in capsys.readouterr().err
