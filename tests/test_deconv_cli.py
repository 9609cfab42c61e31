"""``mitsweep deconvolve``: real EXR and bank files in and out, clear errors."""

import json

import numpy as np
import pytest
from skimage import data, transform

from mitsweep.cli.main import main
from mitsweep.deconv import deconvolve
from mitsweep.deconv.metrics import disk_mask, psnr
from mitsweep.deconv.spatial import scatter_blur
from mitsweep.deconv.weights import (MismatchProfile, blind_noise_variance,
                                     calibrate_mismatch, model_nsr)
from mitsweep.deconv.kernels import radii_px
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
    # the radial bank's mismatch profile, calibrated on this independent blur
    bank = synthetic_radial_bank(sharp.shape, size=K)
    # over the mirror's image as the photo's rule reads it (the radial bank's extent)
    extent = disk_mask(sharp.shape, float(np.max(radii_px(bank))))
    profile = calibrate_mismatch(blurred, sharp, bank, mask=extent)
    profile.write(d / "profile.json")
    MismatchProfile(profile.f, profile.share * 2.0 + 0.5, 1.0, 1e-3).write(
        d / "bad_profile.json")   # shares above 1
    return d, sharp, blurred


@pytest.mark.parametrize("bank,operator", [("radial", "polar"), ("grid", "grid"),
                                           ("radial", "grid")])
def test_deconvolve_writes_a_restored_exr_with_provenance(files, capsys, bank, operator):
    d, sharp, blurred = files
    out = d / f"out_{bank}_{operator}.exr"
    rc = main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / f"{bank}.npz"),
               "--out", str(out), "--nsr", "1e-4", "--operator", operator, "--grid", "9",
               "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert report["operator"] == operator and report["method"] == "wiener"
    chans, meta = read_exr(out)
    restored = chans["Y"]
    assert meta["bank"].endswith(f"{bank}.npz") and meta["nsr"] == 1e-4
    assert meta["operator"] == operator and meta["method"] == "wiener" and "version" in meta
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
    (["--bank", "{d}/radial.npz", "--operator", "polar", "--out", "{d}/x.jpg"], ".exr"),
    (["--bank", "{d}/radial.npz", "--center", "200", "10"], "outside"),
    (["--bank", "{d}/grid.npz", "--operator", "polar"], "radial bank"),
    (["--bank", "{d}/radial.npz", "--method", "sharpen"], "wiener"),
    (["--bank", "{d}/radial.npz", "--method", "polar", "--operator", "grid"], "--operator"),
    (["--bank", "{d}/radial.npz", "--mismatch", "{d}/missing.json"], "missing.json"),
    (["--bank", "{d}/radial.npz", "--mismatch", "{d}/sweep.exr"],
     "sweep.exr: not a mismatch profile"),
    (["--bank", "{d}/radial.npz", "--mismatch", "{d}/bad_profile.json"],
     "bad_profile.json: not a mismatch profile (f increasing, share in [0, 1]"),
    (["--bank", "{d}/radial.npz", "--mismatch", "{d}/profile.json", "--nsr", "1e-3"],
     "--mismatch and --nsr both set the weight"),
    (["--bank", "{d}/grid.npz", "--mismatch", "{d}/profile.json"],
     "give --setup (its outline) with a grid bank"),
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


def test_old_method_values_still_work_with_a_deprecation_warning(files, capsys, caplog):
    """``--method polar|grid|auto`` named the operator before restoration methods
    existed; they still run, as ``--operator``, and say so."""
    d, _, _ = files
    old, new = d / "old_method.exr", d / "new_operator.exr"
    assert main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(old), "--nsr", "1e-3", "--method", "grid", "--grid", "9"]) == 0
    assert "--method grid is deprecated" in caplog.text
    assert main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "radial.npz"),
                 "--out", str(new), "--nsr", "1e-3", "--operator", "grid", "--grid", "9"]) == 0
    a, ma = read_exr(old)
    b, mb = read_exr(new)
    np.testing.assert_array_equal(a["Y"], b["Y"])
    assert ma["operator"] == mb["operator"] == "grid" and ma["method"] == "wiener"


def test_grid_bank_is_applied_around_the_given_center(files, capsys):
    """A grid bank (tilted mirror) works on the photo shifted by whole pixels so the
    mirror's axis sits at the centre: the same photo shifted by (3, -2) px with
    --center moved by as much restores to the same pixels, shifted."""
    d, _, blurred = files
    shifted = np.roll(blurred, (3, -2), axis=(0, 1)).astype(np.float32)
    write_exr(d / "sweep_shifted.exr", shifted, metadata={"pixel_pitch": 0.018})
    a, b = d / "grid_centre.exr", d / "grid_shifted.exr"
    assert main(["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "grid.npz"),
                 "--out", str(a), "--nsr", "1e-3"]) == 0
    c = (SIZE / 2 - 0.5 + 3, SIZE / 2 - 0.5 - 2)
    assert main(["deconvolve", str(d / "sweep_shifted.exr"), "--bank", str(d / "grid.npz"),
                 "--out", str(b), "--nsr", "1e-3", "--center", str(c[0]), str(c[1])]) == 0
    ya, yb = read_exr(a)[0]["Y"], read_exr(b)[0]["Y"]
    # away from the edges, where the rolled-in pixels differ from the repeated ones the
    # window adds: the filter's reach is ~2 K (measured: 1.4e-3 at 16 px, 7e-5 at 24)
    inner = (slice(2 * K, SIZE - 2 * K), slice(2 * K, SIZE - 2 * K))
    np.testing.assert_allclose(np.roll(ya, (3, -2), axis=(0, 1))[inner], yb[inner],
                               atol=2e-4)


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


@pytest.mark.parametrize("sigma", [0.0, 0.005])
def test_a_calibrated_profile_sets_the_weight_held_out(files, capsys, tmp_path, sigma):
    """``--mismatch``: the calibrated rule's NSR (the image's own noise, the profile, over
    the radial bank's extent), on the scene turned over (held out: the profile was
    calibrated on the scene as it is), noise-free and noisy, within 0.3 dB of the best
    NSR's restoration over the same pixels (measured: within 0.01 dB)."""
    d, sharp, _ = files
    turned = sharp[::-1, :].copy()
    photo = scatter_blur(turned, synthetic_kernel_field(turned.shape, size=K))
    photo = (photo + np.random.default_rng(3).normal(0.0, sigma, photo.shape)).astype(np.float32)
    write_exr(tmp_path / "turned.exr", photo, metadata={"pixel_pitch": 0.018})
    out = tmp_path / "r.exr"
    assert main(["deconvolve", str(tmp_path / "turned.exr"), "--bank", str(d / "radial.npz"),
                 "--mismatch", str(d / "profile.json"), "--out", str(out)]) == 0
    chans, meta = read_exr(out)
    assert meta["nsr_rule"] == "calibrated" and meta["mismatch"] == str(d / "profile.json")
    bank = synthetic_radial_bank(sharp.shape, size=K)
    mask = disk_mask(sharp.shape, float(np.max(radii_px(bank))))
    assert 0 < mask.mean() < 1
    expected = model_nsr(photo, bank, float(np.sqrt(blind_noise_variance(photo))), mask=mask,
                         mismatch=MismatchProfile.read(d / "profile.json"))
    assert meta["nsr"] == pytest.approx(expected, rel=1e-6)

    def score(nsr):
        r = deconvolve(photo, bank, method="wiener", nsr=nsr, prior="natural")
        return psnr(r, turned, mask=mask)

    best = max(score(10.0 ** e) for e in np.arange(-7.0, -0.9, 0.125))
    assert psnr(chans["Y"], turned, mask=mask) > best - 0.3
