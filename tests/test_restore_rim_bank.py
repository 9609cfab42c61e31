"""``deconvolve --bank-extent rim`` (``restore_photo(bank_extent="rim")``): the traced
bank of a photo reaches the mirror's rim, is cached under its own key, and restores the
whole mirror image; a given bank cannot be asked to reach further."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_contract import refused
from skimage import data, transform

from mitsweep.io import write_exr
from mitsweep.io.bank import load_bank, save_bank
from mitsweep.workflows import restore_photo

ROOT = Path(__file__).resolve().parents[1]
SIDE, PITCH = 64, 0.16          # the paraboloid's 512 px frame at 1/8 the resolution


@pytest.fixture(scope="module")
def photo(tmp_path_factory):
    d = tmp_path_factory.mktemp("rim_photo")
    text = (ROOT / "scenes" / "paraboloid.toml").read_text()
    text = text.replace("resolution = [512, 512]", f"resolution = [{SIDE}, {SIDE}]")
    text = text.replace("pixel_pitch = 0.02", f"pixel_pitch = {PITCH}")
    (d / "setup.toml").write_text(text)
    img = transform.resize(data.camera() / 255.0, (SIDE, SIDE), anti_aliasing=True)
    write_exr(d / "photo.exr", img.astype(np.float32), metadata={"pixel_pitch": PITCH})
    return d


def _restore(d: Path, extent: str):
    return restore_photo(d / "photo.exr", setup=d / "setup.toml", bank_extent=extent,
                         rays=20_000, nsr=1e-3, cache_dir=d / "cache")


def test_a_rim_bank_is_traced_once_and_reaches_the_rim(photo):
    first = _restore(photo, "rim")
    again = _restore(photo, "rim")
    fov = _restore(photo, "fov")
    p, q = first.provenance, again.provenance
    assert p["bank_extent"] == "rim" and fov.provenance["bank_extent"] == "fov"
    assert p["bank_cache"]["traced"] and not q["bank_cache"]["traced"]
    assert p["bank_cache"]["path"] == q["bank_cache"]["path"] != fov.provenance["bank"]
    np.testing.assert_array_equal(first.value, again.value)
    rim_bank = load_bank(p["bank_cache"]["path"])
    fov_bank = load_bank(fov.provenance["bank_cache"]["path"])
    assert rim_bank.metadata["rim_points"] > 0
    assert len(rim_bank.radii) == len(fov_bank.radii) + rim_bank.metadata["rim_points"]
    assert float(rim_bank.radii[-1]) > 1.1 * float(fov_bank.radii[-1])
    assert np.all(np.isfinite(first.value)) and first.value.shape == (SIDE, SIDE)
    # the FOV's kernels are the same; beyond the FOV the restorations differ
    assert not np.array_equal(first.value, fov.value)


def test_bank_extent_with_a_given_bank_is_refused(photo, capsys):
    fov = _restore(photo, "fov")
    save_bank(photo / "given.npz", load_bank(fov.provenance["bank_cache"]["path"]))
    line = refused(capsys, ["deconvolve", photo / "photo.exr", "--setup", photo / "setup.toml",
                            "--bank", photo / "given.npz", "--bank-extent", "rim",
                            "--out", photo / "x.exr"])
    assert "--bank-extent applies to a traced bank only" in line
    assert not (photo / "x.exr").exists()
    line = refused(capsys, ["deconvolve", photo / "photo.exr", "--bank-extent", "mirror",
                            "--out", photo / "x.exr"])
    assert "--bank-extent" in line and "fov" in line and "rim" in line
