"""mitsweep.workflows: each command's job called from Python gives what the command writes
(the same numbers: both run the same deterministic code on the same inputs, so arrays are
compared exactly), with its provenance.

Inputs are the CLI tests' small ones (synthetic 96 px banks of test_deconv_cli, 20 000-ray
IPSFs of test_tracer_cli, the 48 px sphere of test_dataset_integrity).
"""

import json

import numpy as np
import pytest
from conftest import SCENES
from skimage import data, transform
from test_io_write_errors import tiny_setup_toml

from mitsweep import workflows
from mitsweep.cli.common import UsageError
from mitsweep.cli.main import main
from mitsweep.config import SetupError, load_setup, setup_to_dict
from mitsweep.deconv.spatial import scatter_blur
from mitsweep.deconv.synthetic import synthetic_kernel_field, synthetic_radial_bank
from mitsweep.io import read_exr, write_exr
from mitsweep.io.bank import load_bank, save_bank
from mitsweep.workflows import (InputError, WorkflowResult, build_dataset, evaluate_dataset,
                                resolve_setup, restore_photo, trace_ipsf, trace_ipsf_bank,
                                unwarp_image)

SIZE, K = 96, 13


def _cli_json(argv, capsys):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope="module")
def sweep_photo(tmp_path_factory):
    d = tmp_path_factory.mktemp("workflows")
    sharp = transform.resize(data.camera() / 255.0, (SIZE, SIZE), anti_aliasing=True)
    blurred = scatter_blur(sharp, synthetic_kernel_field(sharp.shape, size=K))
    write_exr(d / "sweep.exr", blurred.astype(np.float32), metadata={"pixel_pitch": 0.018})
    save_bank(d / "radial.npz", synthetic_radial_bank(sharp.shape, size=K))
    return d


def test_the_errors_of_workflows_are_the_commands_usage_errors():
    assert UsageError is InputError and issubclass(InputError, ValueError)


def test_resolve_setup_takes_a_name_a_file_or_a_setup(tmp_path):
    by_name = resolve_setup("sphere")
    assert setup_to_dict(by_name) == setup_to_dict(load_setup(SCENES / "sphere.toml"))
    assert resolve_setup(SCENES / "sphere.toml").mirror == by_name.mirror
    assert resolve_setup(by_name) is by_name
    with pytest.raises(SetupError, match=r"no such setup file, nor a bundled setup name "
                                         r"\(bundled: .*sphere"):
        resolve_setup(tmp_path / "nope.toml")


@pytest.mark.parametrize("operator, center", [("polar", None), ("grid", (47.0, 48.0))])
def test_restore_photo_gives_what_deconvolve_writes(sweep_photo, capsys, operator, center):
    d = sweep_photo
    kw = dict(bank=d / "radial.npz", nsr=1e-4, operator=operator, grid=9)
    result = restore_photo(d / "sweep.exr", out=d / f"lib_{operator}.exr", center=center, **kw)
    argv = ["deconvolve", str(d / "sweep.exr"), "--bank", str(d / "radial.npz"), "--nsr",
            "1e-4", "--operator", operator, "--grid", "9", "--out", str(d / f"cli_{operator}.exr")]
    report = _cli_json(argv + (["--center", "47", "48"] if center else []), capsys)
    cli_image = read_exr(d / f"cli_{operator}.exr")[0]["Y"]
    assert isinstance(result, WorkflowResult) and result.value.dtype == np.float32
    np.testing.assert_array_equal(result.value, cli_image)
    np.testing.assert_array_equal(read_exr(d / f"lib_{operator}.exr")[0]["Y"], cli_image)
    # the summary is the command's JSON, but for the path written and the time taken
    same = {k: v for k, v in report.items() if k not in ("out", "seconds")}
    assert {k: result.summary[k] for k in same} == same
    p = result.provenance
    assert p["workflow"] == "restore_photo" and p["operator"] == operator
    assert p["pixel_pitch_from"] == "metadata" and p["pixel_pitch"] == pytest.approx(0.018)
    assert p["center_from"] == ("--center" if center else "the image centre")
    assert p["bank"] == str(d / "radial.npz") and p["bank_cache"] is None
    assert p["bank_identity"]["forced"] is False and p["seconds"] > 0
    assert p["window_shift_rc"] == ([0, 0] if operator == "grid" else None)


def test_restore_photo_without_an_output_writes_nothing(sweep_photo, tmp_path):
    result = restore_photo(sweep_photo / "sweep.exr", bank=sweep_photo / "radial.npz")
    assert result.value.shape == (SIZE, SIZE) and result.summary["out"] is None
    with pytest.raises(InputError, match=r"--center 500 3 lies outside the 96x96 image"):
        restore_photo(sweep_photo / "sweep.exr", bank=sweep_photo / "radial.npz",
                      center=(500, 3))


def test_trace_ipsf_gives_what_ipsf_writes(tmp_path, capsys):
    kw = ["--rays", "20000", "--kernel-size", "15", "--radius", "2", "--depth", "500", "2000"]
    report = _cli_json(["ipsf", "sphere", *kw, "-o", str(tmp_path / "cli.exr")], capsys)
    result = trace_ipsf("sphere", rays=20000, kernel_size=15, radius=2.0,
                        depths=[500.0, 2000.0], output=tmp_path / "lib.exr")
    assert len(result.value) == 2
    for depth, kernel in zip((500.0, 2000.0), result.value):
        tag = "l500mm" if depth == 500.0 else "l2000mm"
        chans, meta = read_exr(tmp_path / f"cli_{tag}.exr")
        np.testing.assert_array_equal(kernel, chans["Y"])
        assert kernel.sum() == pytest.approx(1.0, abs=1e-5)
    assert [e["depth_mm"] for e in report["ipsfs"]] == [500.0, 2000.0]
    for mine, theirs in zip(result.summary["ipsfs"], report["ipsfs"]):
        assert mine["vignetted_fraction"] == theirs["vignetted_fraction"]
    p = result.provenance
    assert p["workflow"] == "trace_ipsf" and p["image_uv_mm"] == [2.0, 0.0]
    assert p["depths_mm"] == [500.0, 2000.0] and p["setup"]["mirror"]["radius"] == 25.0
    assert p["sweep_range"] == meta["sweep_range"]


def test_trace_ipsf_bank_gives_what_ipsf_bank_writes(tmp_path, capsys):
    report = _cli_json(["ipsf", "sphere", "--bank", "radial", "--radii", "3", "--rays", "5000",
                        "--kernel-size", "15", "-o", str(tmp_path / "cli.npz")], capsys)
    result = trace_ipsf_bank("sphere", kind="radial", radii=3, rays=5000, kernel_size=15)
    np.testing.assert_array_equal(result.value.kernels, load_bank(tmp_path / "cli.npz").kernels)
    assert result.summary["shape"] == report["shape"] == [1, 3, 15, 15]
    assert result.provenance["rays"] == 5000 and result.provenance["method"] == "exact"
    assert result.provenance["reference_sensor_distance_mm"] == pytest.approx(
        report["reference_sensor_distance_mm"])


def test_unwarp_image_gives_what_unwarp_writes(tmp_path, capsys):
    setup = load_setup(tiny_setup_toml(tmp_path))
    img = np.random.default_rng(0).random((48, 48, 3)).astype(np.float32)
    write_exr(tmp_path / "edof.exr", img, metadata={"setup": setup_to_dict(setup)})
    report = _cli_json(["unwarp", str(tmp_path / "edof.exr"), "--projection", "cylindrical",
                        "--size", "90", "24", "--out", str(tmp_path / "cli.exr")], capsys)
    result = unwarp_image(tmp_path / "edof.exr", tmp_path / "lib.exr",
                          projection="cylindrical", size=(90, 24))
    pano, valid = result.value
    chans, meta = read_exr(tmp_path / "cli.exr")
    np.testing.assert_array_equal(pano[..., 0].astype(np.float32), chans["R"])
    np.testing.assert_array_equal(valid.astype(np.float32), chans["mask.Y"])
    assert result.summary["valid_fraction"] == report["valid_fraction"] > 0
    assert result.provenance["elevation_deg"] == meta["elevation_deg"]
    assert result.provenance["workflow"] == "unwarp_image"


@pytest.mark.slow
def test_build_and_evaluate_dataset_give_what_the_commands_write(tmp_path, capsys):
    """Two tiny datasets (48 px, 2-4 spp) and their scores: 5-14 s measured on 2 loaded
    cores (noisy), so marked slow."""
    setup = tiny_setup_toml(tmp_path)
    kw = dict(spp=(2, 2, 4, 2), lux=(50.0,), bank_rays=16384)
    assert main(["dataset", str(setup), "--out", str(tmp_path / "cli"), "--spp", "2", "2", "4",
                 "2", "--lux", "50", "--bank-rays", "16384"]) == 0
    capsys.readouterr()
    built = build_dataset(setup, tmp_path / "lib", **kw)
    assert built.value["complete"] and built.provenance["items_expected"] == len(
        built.value["items"])
    assert built.provenance["options"]["bank_rays"] == 16384
    for name in ("scene_000/sweep.exr", "scene_000/edof.exr"):
        np.testing.assert_array_equal(read_exr(tmp_path / "lib" / name)[0]["R"],
                                      read_exr(tmp_path / "cli" / name)[0]["R"])
    report = _cli_json(["evaluate", str(tmp_path / "cli")], capsys)
    scores = evaluate_dataset(tmp_path / "lib", out=tmp_path / "scores.json")
    assert scores.value["mean"] == report["mean"]
    assert json.loads((tmp_path / "scores.json").read_text())["mean"] == report["mean"]
    assert scores.provenance["dataset"] == str(tmp_path / "lib")


@pytest.mark.slow
def test_error_budget_gives_what_budget_prints(tmp_path, capsys):
    """~13 s on 2 loaded cores (the budget re-traces and re-renders on the 48 px sphere)."""
    setup = tiny_setup_toml(tmp_path)
    build_dataset(setup, tmp_path / "ds", spp=(2, 2, 4, 2), lux=(50.0,), bank_rays=16384)
    report = _cli_json(["budget", str(tmp_path / "ds")], capsys)
    budget = workflows.error_budget(tmp_path / "ds")
    assert budget.summary == report and list(budget.value["budgets"]) == list(report["budgets"])
    assert "restored from" in budget.provenance["text"]


def test_compute_sweep_range_gives_what_sweep_range_prints(capsys):
    report = _cli_json(["sweep-range", "sphere", "--depth", "300", "10000"], capsys)
    result = workflows.compute_sweep_range("sphere", depth=(300.0, 10000.0))
    assert result.summary == report
    # the paper's sphere: 339-364 mm (docs/design.md)
    assert (round(result.value.focus_min), round(result.value.focus_max)) == (339, 364)
    assert result.provenance["depth"] == (300.0, 10000.0) and not result.provenance["verify"]
    with pytest.raises(InputError, match=r"--depth: MIN \(9\) must be <= MAX \(1\)"):
        workflows.compute_sweep_range("sphere", depth=(9.0, 1.0))


def test_plan_rig_capture_gives_what_the_dry_run_prints(capsys):
    report = _cli_json(["capture", "sphere", "--dry-run"], capsys)
    result = workflows.plan_rig_capture("sphere")
    assert result.summary == report and result.value.as_dict() == report["plan"]
    assert result.value.as_dict()["translation_mm"] == pytest.approx(0.6950, abs=1e-4)
    with pytest.raises(InputError, match="--port is required"):
        workflows.capture("sphere", port=None)


def test_capture_against_the_simulator_writes_the_record(tmp_path):
    """The rig's workflow against the pty simulator (test_rig_cli's fast rig): complete,
    the measured exposure within 2 us of the plan, the record on disk."""
    from mitsweep.rig import load_capture_record
    from mitsweep.rig.simulator import ArduinoModel, PtyDevice

    setup = tmp_path / "rig.toml"
    setup.write_text((SCENES / "sphere.toml").read_text()
                     + "\n[rig]\nmax_velocity = 10.0\nacceleration = 100.0\n")
    with PtyDevice(ArduinoModel()) as dev:
        result = workflows.capture(setup, port=dev.port, out=tmp_path / "rec.json")
    s = result.summary
    assert s["complete"] and s["record"] == str(tmp_path / "rec.json")
    assert s["measured_exposure_s"] == pytest.approx(s["planned_exposure_s"], abs=2e-6)
    assert load_capture_record(tmp_path / "rec.json")["complete"]
    assert result.provenance["port"] == dev.port and result.provenance["stage"] == "arduino"
    with pytest.raises(InputError, match="exists: pass --force"):
        workflows.capture(setup, port=dev.port, out=tmp_path / "rec.json")


def test_render_exr_gives_what_render_writes(tmp_path, capsys):
    kw = ["--mode", "pinhole", "--spp", "4", "--resolution", "48", "48"]
    report = _cli_json(["render", "sphere", *kw, "--out", str(tmp_path / "cli.exr")], capsys)
    result = workflows.render_exr("sphere", tmp_path / "lib.exr", mode="pinhole", spp=4,
                                  resolution=(48, 48))
    cli = read_exr(tmp_path / "cli.exr")[0]
    np.testing.assert_array_equal(result.value.image[..., 0].astype(np.float32), cli["R"])
    assert result.summary["mean"] == report["mean"]
    assert result.summary["resolution"] == report["resolution"]
    assert result.provenance["workflow"] == "render_exr" and result.provenance["spp"] == 4


def test_calibrate_camera_gives_what_calibrate_prints(tmp_path, capsys):
    """test_calibrate's synthetic photo of the paraboloid (200 px sensor at 0.06 mm, in a
    262 x 230 frame, the axis off centre by (6.37, -9.81) px)."""
    from dataclasses import replace

    import tifffile
    from camera_files import synthetic_mirror_photo

    from mitsweep.config import Sensor, setup_to_toml
    from mitsweep.io.png import linear_to_srgb

    setup = replace(load_setup(SCENES / "paraboloid.toml"),
                    sensor=Sensor(resolution=(200, 200), pixel_pitch=0.06))
    img = synthetic_mirror_photo(setup, (230, 262), (6.37, -9.81), supersample=2)
    lin = np.clip(img / img.max() * 0.9, 0, 1)
    tifffile.imwrite(tmp_path / "photo.tif", np.round(linear_to_srgb(lin) * 65535)
                     .astype(np.uint16), photometric="rgb")
    (tmp_path / "setup.toml").write_text(setup_to_toml(setup))
    report = _cli_json(["calibrate", str(tmp_path / "photo.tif"), "--setup",
                        str(tmp_path / "setup.toml")], capsys)
    result = workflows.calibrate_camera(tmp_path / "photo.tif", tmp_path / "setup.toml",
                                        write=tmp_path / "calibrated.toml")
    assert result.value.center_px == pytest.approx(report["center_px"], abs=0)
    assert result.summary["rim_radius_px"] == report["rim_radius_px"]
    assert result.value.center_offset_px == pytest.approx((6.37, -9.81), abs=0.25)
    assert result.provenance["pixel_pitch_source"] == "setup"
    assert len(result.provenance["sha256"]) == 64
    calibrated = load_setup(tmp_path / "calibrated.toml")
    assert calibrated.sensor.resolution == (262, 230)
    free = _cli_json(["calibrate", str(tmp_path / "photo.tif"), "--free"], capsys)
    assert workflows.find_mirror_circle(tmp_path / "photo.tif").summary == free


def test_reproduce_table1_gives_what_table1_prints(capsys):
    argv = ["--ranges", "340:360", "--radii", "2", "--rays", "4000", "--kernel-size", "15"]
    report = _cli_json(["table1", "sphere", *argv], capsys)
    result = workflows.reproduce_table1("sphere", ranges=[(340.0, 360.0)], radii=2, rays=4000,
                                        kernel_size=15)
    assert result.value["rows"] == report["rows"]
    assert result.provenance["ranges"] == [[340.0, 360.0]]


def test_design_motion_profile_gives_what_design_sweep_writes(tmp_path, capsys):
    """test_design_sweep's small design: 8 planes, 2 radii, 2 depths, 4096 rays."""
    from mitsweep.optics.motion_file import load_motion_file

    kw = dict(lux=2.0, planes=8, radii=2, depths=[300.0, 10000.0], rays=4096,
              brute_force_steps=0)
    argv = ["--lux", "2", "--planes", "8", "--radii", "2", "--depth", "300", "10000",
            "--rays", "4096", "--brute-force-steps", "0"]
    report = _cli_json(["design-sweep", "paraboloid", *argv, "--out",
                        str(tmp_path / "cli.json")], capsys)
    result = workflows.design_motion_profile("paraboloid", tmp_path / "lib.json", **kw)
    assert result.summary["optimized_worst_mse"] == report["optimized_worst_mse"]
    lib, cli = load_motion_file(tmp_path / "lib.json"), load_motion_file(tmp_path / "cli.json")
    np.testing.assert_array_equal(lib.profile.positions, cli.profile.positions)
    assert result.provenance["generator"] == "mitsweep design-sweep"
    assert lib.provenance["predicted"] == cli.provenance["predicted"]


def test_every_workflow_is_exported_with_its_command():
    """The workflows the commands call are the package's public names."""
    for name in ("restore_photo", "trace_ipsf", "trace_ipsf_bank", "build_dataset",
                 "evaluate_dataset", "design_motion_profile", "unwarp_image",
                 "calibrate_photo", "calibrate_camera", "find_mirror_circle", "capture",
                 "plan_rig_capture", "compute_sweep_range", "render_exr", "run_demo",
                 "run_benchmarks", "error_budget", "make_paper_figures", "reproduce_table1"):
        assert name in workflows.__all__ and callable(getattr(workflows, name))
