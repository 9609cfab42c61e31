"""A bank is used only on images of the optics it was traced for (or with --force).

The images and the bank come from a real tiny dataset (the renderer writes the setup into
each EXR, the tracer writes it into the bank), so these tests also check that the two
independent writers describe one setup identically.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cli_contract import refused
from mitsweep.cli.main import main
from mitsweep.config import DEFAULT_SETUP, Sensor, load_setup, setup_to_dict
from mitsweep.deconv.kernels import bank_identity_problem, check_bank_identity
from mitsweep.deconv.synthetic import synthetic_radial_bank
from mitsweep.io import read_exr, write_exr
from mitsweep.io.bank import (BankError, load_bank, optics_fingerprint, optics_sections,
                              save_bank)
from mitsweep.pipeline import DatasetOptions, bank_kernel_size, build_dataset

ROOT = Path(__file__).resolve().parents[1]
TINY_SENSOR = Sensor(resolution=(48, 48), pixel_pitch=0.18)
TINY = replace(DEFAULT_SETUP, sensor=TINY_SENSOR)
SENSOR_TOML = "[sensor]\nresolution = [48, 48]\npixel_pitch = 0.18\n"


def toml_with_tiny_sensor(name: str) -> str:
    """scenes/NAME.toml with its [sensor] section replaced by the tiny one."""
    text = (ROOT / "scenes" / f"{name}.toml").read_text()
    head, rest = text.split("[sensor]")
    tail = rest[rest.index("[sweep]"):]
    return head + SENSOR_TOML + "\n" + tail


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from mitsweep.tracer import ipsf_bank

    d = tmp_path_factory.mktemp("identity")
    opts = DatasetOptions(scenes=1, spp={"pinhole": 1, "focused": 1, "sweep": 2, "stopped": 1},
                          bank_rays=1 << 12, light_levels_lux=(50.0,))
    build_dataset(TINY, d / "ds", opts, progress=False)
    for name in ("sphere", "paraboloid"):
        (d / f"{name}.toml").write_text(toml_with_tiny_sensor(name))
    para = load_setup(d / "paraboloid.toml")
    save_bank(d / "paraboloid.npz",
              ipsf_bank(para, kind="radial", n_radii=3, rays=1 << 12,
                        kernel_size=bank_kernel_size(para.sensor.pixel_pitch)))
    chans, meta = read_exr(d / "ds" / "scene_000" / "sweep.exr")
    rgb = np.stack([chans[c] for c in "RGB"], -1)
    write_exr(d / "capture.exr", rgb, metadata={"pixel_pitch": 0.18})   # no setup: a capture
    return d


def deconvolve_argv(d, image, bank, out="out.exr"):
    return ["deconvolve", str(d / image), "--bank", str(d / bank), "--out", str(d / out),
            "--nsr", "1e-3"]


def run(argv) -> int:
    return main([str(a) for a in argv])


def test_a_bank_of_the_same_setup_is_accepted_and_recorded(files, capsys):
    d = files
    assert run(deconvolve_argv(d, "ds/scene_000/sweep.exr", "ds/bank.npz", "same.exr")) == 0
    _, meta = read_exr(d / "same.exr")
    identity = meta["bank_identity"]
    assert identity["checked_against"] == "its metadata" and identity["forced"] is False
    assert identity["problem"] is None
    bank = load_bank(d / "ds" / "bank.npz")
    assert identity["bank_optics_sha256"] == optics_fingerprint(bank.optics)
    assert bank.optics["mirror"]["radius"] == 25.0 and "motion" in bank.optics


def test_a_bank_of_another_mirror_is_refused_naming_the_difference(files, capsys):
    d = files
    line = refused(capsys, deconvolve_argv(d, "ds/scene_000/sweep.exr", "paraboloid.npz",
                                           "never.exr"))
    assert "bank was traced for mirror (paraboloid)" in line
    assert "has mirror (sphere)" in line and "conic=-1" in line and "conic=0" in line
    assert "radius=28.2" in line and "radius=25" in line and "use --force" in line
    assert not (d / "never.exr").exists()


def test_force_overrides_and_the_override_is_in_the_provenance(files, caplog):
    d = files
    assert run(deconvolve_argv(d, "ds/scene_000/sweep.exr", "paraboloid.npz", "forced.exr")
               + ["--force"]) == 0
    assert "--force: bank was traced for mirror (paraboloid)" in caplog.text
    _, meta = read_exr(d / "forced.exr")
    assert meta["bank_identity"]["forced"] is True
    assert "mirror (paraboloid)" in meta["bank_identity"]["problem"]


def test_a_capture_without_setup_needs_setup_or_force(files, capsys):
    d = files
    line = refused(capsys, deconvolve_argv(d, "capture.exr", "ds/bank.npz", "never.exr"))
    assert "carries no setup to check the bank against" in line and "--setup" in line
    assert run(deconvolve_argv(d, "capture.exr", "ds/bank.npz", "capture_ok.exr")
                + ["--setup", d / "sphere.toml"]) == 0
    _, meta = read_exr(d / "capture_ok.exr")
    assert meta["bank_identity"]["checked_against"] == f"--setup {d / 'sphere.toml'}"
    line = refused(capsys, deconvolve_argv(d, "capture.exr", "paraboloid.npz", "never.exr")
                   + ["--setup", d / "sphere.toml"])
    assert "mirror (paraboloid)" in line


def test_setup_contradicting_the_image_metadata_is_refused(files, capsys):
    d = files
    line = refused(capsys, deconvolve_argv(d, "ds/scene_000/sweep.exr", "ds/bank.npz",
                                           "never.exr") + ["--setup", d / "paraboloid.toml"])
    assert "differs from the setup recorded" in line


def test_a_bank_that_predates_fingerprints_is_refused_unless_forced(files, capsys, tmp_path):
    d = files
    with np.load(d / "ds" / "bank.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"][()]))
    header.pop("optics"), header.pop("optics_sha256")
    header["format"] = "mitsweep-ipsf-bank/1"
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    old = tmp_path / "old.npz"
    with open(old, "wb") as f:
        np.savez(f, **arrays)
    line = refused(capsys, ["deconvolve", d / "ds/scene_000/sweep.exr", "--bank", old,
                            "--out", tmp_path / "never.exr"])
    assert "predates optics fingerprints" in line and "--force" in line
    assert run(["deconvolve", d / "ds/scene_000/sweep.exr", "--bank", old,
                 "--out", tmp_path / "ok.exr", "--force", "--nsr", "1e-3"]) == 0


def test_a_bank_header_without_kind_is_a_named_error(files, capsys, tmp_path):
    d = files
    with np.load(d / "ds" / "bank.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"][()]))
    del header["kind"]
    arrays["header"] = np.array(json.dumps(header))
    with open(tmp_path / "nokind.npz", "wb") as f:
        np.savez(f, **arrays)
    line = refused(capsys, ["deconvolve", d / "ds/scene_000/sweep.exr", "--bank",
                            tmp_path / "nokind.npz", "--out", tmp_path / "never.exr"])
    assert "the bank header lacks 'kind'" in line


# -- the API ---------------------------------------------------------------------------

def _optics(setup, f_number=None):
    s = setup if f_number is None else replace(setup, lens=replace(setup.lens,
                                                                    f_number=f_number))
    return optics_sections(setup_to_dict(s), {"kind": "linear", "start_mm": 1.0, "end_mm": 2.0})


def test_problem_names_only_the_keys_that_differ():
    bank = replace(synthetic_radial_bank((48, 48), size=5), optics=_optics(TINY))
    assert bank_identity_problem(bank, _optics(TINY)) is None
    problem = bank_identity_problem(bank, _optics(TINY, f_number=4.0), image="img.exr")
    assert problem == "bank was traced for lens f_number=2.8, img.exr has lens f_number=4"
    with pytest.raises(BankError, match="lens f_number=2.8"):
        check_bank_identity(bank, _optics(TINY, f_number=4.0))


def test_motion_is_compared_only_when_the_image_knows_it():
    bank = replace(synthetic_radial_bank((48, 48), size=5), optics=_optics(TINY))
    without_motion = optics_sections(setup_to_dict(TINY))
    assert bank_identity_problem(bank, without_motion) is None
    other_motion = {**_optics(TINY), "motion": {"kind": "linear", "start_mm": 1.0,
                                                "end_mm": 2.5}}
    assert bank_identity_problem(bank, other_motion) == (
        "bank was traced for motion end_mm=2, the image has motion end_mm=2.5")


def test_synthetic_banks_pass_only_on_images_without_optics():
    synthetic = synthetic_radial_bank((48, 48), size=5)
    assert bank_identity_problem(synthetic, None) is None
    assert "traced for no optics (synthetic)" in bank_identity_problem(synthetic, _optics(TINY))
