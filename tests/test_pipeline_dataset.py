"""Dataset runner: real renders, real EXR files, resumable and atomic; evaluation."""

import hashlib
import json
from dataclasses import replace

import numpy as np
import pytest

from conftest import run_cli
from mitsweep import pipeline
from mitsweep.pipeline import tasks
from mitsweep.config import DEFAULT_SETUP, Sensor
from mitsweep.io.bank import load_bank
from mitsweep.pipeline import (DatasetError, DatasetOptions, build_dataset, evaluate_dataset,
                               load_manifest)

# A tiny frame (48 px, the mirror's image ~36 px across) and a few samples per pixel:
# enough to exercise every task for real in a few seconds.
TINY = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(48, 48), pixel_pitch=0.18))
TINY_OPTS = DatasetOptions(scenes=1, spp={"pinhole": 2, "focused": 2, "sweep": 4, "stopped": 2},
                           bank_rays=1 << 14, light_levels_lux=(50.0,))
EXPECTED = {"bank.npz", "calibration/pinhole.exr", "calibration/sweep.exr",
            "calibration/mismatch.json", "scene_000/pinhole.exr", "scene_000/focused.exr",
            "scene_000/sweep.exr", "scene_000/stopped.exr", "scene_000/edof.exr",
            "scene_000/sweep_50lux.exr", "scene_000/stopped_50lux.exr",
            "scene_000/edof_50lux.exr"}


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    manifest = build_dataset(TINY, root, TINY_OPTS, progress=False)
    return root, manifest


def test_dataset_holds_every_item_with_checksums(tiny_dataset):
    root, manifest = tiny_dataset
    assert set(manifest["items"]) == EXPECTED
    assert manifest["complete"] is True
    for name, item in manifest["items"].items():
        assert (root / name).is_file()
        assert item["sha256"] == hashlib.sha256((root / name).read_bytes()).hexdigest()
    assert manifest["versions"]["mitsuba"] and manifest["setup"]["name"] == "sphere"


def test_rerun_skips_complete_items(tiny_dataset, monkeypatch):
    root, manifest = tiny_dataset
    calls = []
    for fn in ("render", "trace_bank", "add_noise", "restore", "calibrate_weights"):
        monkeypatch.setattr(tasks, fn, lambda *a, _fn=fn, **k: calls.append(_fn))
    again = build_dataset(TINY, root, TINY_OPTS, progress=False)
    assert calls == []
    assert again["items"] == manifest["items"]


def test_corrupt_or_missing_items_are_redone(tmp_path):
    root = tmp_path / "ds"
    build_dataset(TINY, root, TINY_OPTS, progress=False)
    before = load_manifest(root)["items"]
    edof = tasks.read_rgb(root / "scene_000" / "edof.exr")[0]
    (root / "scene_000" / "edof.exr").write_bytes(b"garbage")   # corrupted
    (root / "scene_000" / "stopped_50lux.exr").unlink()         # lost
    after = build_dataset(TINY, root, TINY_OPTS, progress=False)["items"]
    # Redone from the same inputs: the same pixels.
    np.testing.assert_array_equal(tasks.read_rgb(root / "scene_000" / "edof.exr")[0], edof)
    assert (root / "scene_000" / "stopped_50lux.exr").is_file()
    # Everything else was kept as it was (same checksums, renders not redone).
    for name in EXPECTED - {"scene_000/edof.exr", "scene_000/stopped_50lux.exr"}:
        assert after[name] == before[name]


def test_interrupted_run_keeps_finished_items_and_resumes(tmp_path, monkeypatch):
    root = tmp_path / "ds"
    real = tasks.add_noise

    def boom(*args, **kwargs):
        raise KeyboardInterrupt  # as if Ctrl-C arrived during this task

    monkeypatch.setattr(tasks, "add_noise", boom)
    with pytest.raises(KeyboardInterrupt):
        build_dataset(TINY, root, TINY_OPTS, progress=False)
    partial = load_manifest(root)
    assert "complete" not in partial
    done = set(partial["items"])
    assert {"bank.npz", "scene_000/sweep.exr"} <= done
    assert not any(p.name.startswith(".") for p in root.rglob("*"))  # no temp files left
    monkeypatch.setattr(tasks, "add_noise", real)
    redone = []
    orig_render = tasks.render
    monkeypatch.setattr(tasks, "render",
                        lambda *a, **k: (redone.append(k["mode"]), orig_render(*a, **k))[1])
    final = build_dataset(TINY, root, TINY_OPTS, progress=False)
    assert set(final["items"]) == EXPECTED
    assert redone == []  # the finished renders were not redone
    for name in done:
        assert final["items"][name]["sha256"] == partial["items"][name]["sha256"]


def test_dataset_of_another_setup_is_refused(tiny_dataset):
    root, _ = tiny_dataset
    other = replace(TINY, lens=replace(TINY.lens, f_number=4.0))
    with pytest.raises(DatasetError, match="holds a dataset of another setup"):
        build_dataset(other, root, TINY_OPTS, progress=False)


def test_evaluate_scores_every_image(tiny_dataset):
    root, _ = tiny_dataset
    res = evaluate_dataset(root)
    scene = res["scenes"]["scene_000"]
    for name in ("focused", "sweep", "edof", "stopped", "edof_50lux", "stopped_50lux"):
        assert np.isfinite(scene[name]["psnr"]) and -1 <= scene[name]["ssim"] <= 1
        assert len(scene[name]["per_radius"]["psnr"]) == 8
    # The ground truth scored against itself would be inf: it is the reference, not scored.
    assert "pinhole" not in scene


@pytest.mark.slow   # 6 s CPU starting processes; the thread and Dask executors run by default
def test_process_executor_gives_the_same_files(tiny_dataset, tmp_path):
    """Same seeds → the same renders, bank and noise, whichever process ran them."""
    from mitsweep.io.bank import load_bank

    root, _ = tiny_dataset
    other = tmp_path / "p"
    build_dataset(TINY, other, TINY_OPTS, executor="process", jobs=2, progress=False)
    for name in ("scene_000/pinhole.exr", "scene_000/sweep.exr", "scene_000/sweep_50lux.exr",
                 "scene_000/edof.exr"):
        np.testing.assert_array_equal(tasks.read_rgb(root / name)[0],
                                      tasks.read_rgb(other / name)[0])
    np.testing.assert_array_equal(load_bank(root / "bank.npz").kernels,
                                  load_bank(other / "bank.npz").kernels)


def test_cli_evaluate_json_and_bad_directory(tiny_dataset, tmp_path):
    root, _ = tiny_dataset
    rc, out, err = run_cli("evaluate", root, "--json", "--plot", tmp_path / "pr.png",
                           "--out", tmp_path / "eval.json")
    assert rc == 0, err
    assert "edof" in json.loads(out)["mean"]
    assert (tmp_path / "pr.png").is_file()

    # the file holds what --json printed, as strict JSON (no Infinity/NaN constants)
    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    assert (tmp_path / "eval.json").read_text() == out
    json.loads(out, parse_constant=refuse)
    rc, _, err = run_cli("evaluate", tmp_path)
    assert rc == 2 and "not a mitsweep dataset" in err and "Traceback" not in err


@pytest.mark.parametrize("args,message", [
    (["--scenes", "0"], "--scenes: must be > 0"),
    (["--lux", "-5"], "--lux: must be an illuminance in"),
    (["--executor", "cluster"], "invalid choice"),
])
def test_cli_dataset_bad_input(tmp_path, scenes_dir, args, message):
    rc, _, err = run_cli("dataset", scenes_dir / "sphere.toml", "--out", tmp_path / "d", *args)
    assert rc == 2 and message in err


def test_bank_that_is_not_npz_is_named(tmp_path):
    from mitsweep.io.bank import BankError, load_bank

    bad = tmp_path / "bank.npz"
    bad.write_text("hello")
    with pytest.raises(BankError, match="not an IPSF bank"):
        load_bank(bad)


def test_a_tilted_mirrors_grid_bank_is_refined_to_its_image_and_recorded():
    """The bank task's recorded grid is the one traced: refined for the tilted
    paraboloid (whose image a 9x9 frame grid crosses with 5 nodes), as given otherwise."""
    from conftest import SCENES

    from mitsweep.config import load_setup
    from mitsweep.deconv.spatial import mirror_grid_shape
    from mitsweep.pipeline.tasks import BANK, plan

    opts = pipeline.DatasetOptions()
    tilted = load_setup(SCENES / "paraboloid_tilted.toml")
    sphere = load_setup(SCENES / "sphere.toml")

    def grid(setup):
        return next(t for t in plan(opts, setup) if t.name == BANK).params["grid"]

    fine = mirror_grid_shape(tilted)
    assert grid(tilted) == [max(9, fine[0]), max(9, fine[1])]
    assert min(grid(tilted)) > 9
    assert grid(sphere) == [9, 9] == grid(None)


def test_a_dataset_with_a_motion_profile_renders_and_traces_that_motion(tmp_path, tiny_dataset):
    """``DatasetOptions(motion=...)`` (``dataset --motion``): the sweep render and the bank
    follow the profile, the manifest records it (and a room dataset's options do not
    mention it); the other modes share the profile's reference grid."""
    from mitsweep.io.bank import load_bank
    from mitsweep.io.exr import read_exr
    from mitsweep.optics.sweep import optimal_sweep_range

    sr = optimal_sweep_range(TINY)
    a, b = sr.sensor_start, sr.sensor_end
    motion = {"times": [0.0, 0.8, 1.0], "positions_mm": [a, a + 0.1 * (b - a), b]}
    opts = replace(TINY_OPTS, motion=motion)
    manifest = build_dataset(TINY, tmp_path, opts, progress=False)
    assert manifest["options"]["motion"] == motion
    linear_root, linear = tiny_dataset
    assert "motion" not in linear["options"]
    bank = load_bank(tmp_path / "bank.npz")
    assert bank.metadata["motion"]["kind"] == "tabulated"
    assert bank.metadata["motion"]["positions_mm"] == motion["positions_mm"]

    def sweep(root):
        ch, meta = read_exr(root / "scene_000" / "sweep.exr")
        return ch["R"], meta

    img, meta = sweep(tmp_path)
    lin, lin_meta = sweep(linear_root)
    assert np.abs(img - lin).max() > 0
    assert meta["motion"]["kind"] == "tabulated" and lin_meta["motion"]["kind"] != "tabulated"
    with pytest.raises(DatasetError, match="motion"):
        replace(TINY_OPTS, motion={"times": [0.0, 1.0], "positions_mm": [a, a]})


# -- the calibration scene: the weights' mismatch profile, measured held out -----------

def test_the_calibration_scene_is_held_out_and_gives_the_restorations_profile(tiny_dataset):
    from mitsweep.datasets import open_dataset
    from mitsweep.deconv.weights import MismatchProfile

    root, manifest = tiny_dataset
    calib = tasks.read_rgb(root / "calibration" / "pinhole.exr")
    scene = tasks.read_rgb(root / "scene_000" / "pinhole.exr")
    # another scene variation (texture layout), the same rig: the truths differ, the
    # mirror's image does not
    assert calib[2]["scene_index"] == tasks.CALIBRATION_SCENE
    assert np.abs(calib[0] - scene[0]).mean() > 0.05 * scene[0].mean()
    np.testing.assert_array_equal(calib[1]["mask.Y"], scene[1]["mask.Y"])
    assert manifest["items"]["calibration/sweep.exr"]["params"]["seed"] == \
        TINY_OPTS.seed + tasks.CALIBRATION_SCENE
    # the profile the restorations read is calibration_profile's on those renders
    profile = MismatchProfile.from_dict(json.loads((root / tasks.MISMATCH).read_text()))
    again = tasks.calibration_profile(root / "calibration" / "pinhole.exr",
                                      root / "calibration" / "sweep.exr",
                                      load_bank(root / "bank.npz"))
    np.testing.assert_allclose(profile.share, again.share)
    assert profile.scale == pytest.approx(again.scale)
    assert np.all((profile.share >= 0) & (profile.share <= 1)) and profile.scale > 0
    for item in ("edof", "edof_50lux"):
        meta = tasks.read_rgb(root / "scene_000" / f"{item}.exr")[2]
        assert meta["nsr_rule"] == "calibrated" and meta["nsr"] > 0
        assert manifest["items"][f"scene_000/{item}.exr"]["params"]["mismatch"] == tasks.MISMATCH
    # and it is no scene of the dataset: the reader and the evaluation list scene_000 only
    assert open_dataset(root).scenes == ("scene_000",)
    assert list(evaluate_dataset(root)["scenes"]) == ["scene_000"]


def test_a_dataset_restored_under_the_former_rule_redoes_only_its_restorations(tmp_path,
                                                                              monkeypatch):
    """A manifest of the ``model`` rule (before the calibration scene): a rerun adds the
    calibration scene and restores again; renders and noisy images stay as they are."""
    root = tmp_path / "ds"
    build_dataset(TINY, root, TINY_OPTS, progress=False)
    manifest = json.loads((root / pipeline.MANIFEST).read_text())
    for name in [n for n in manifest["items"] if n.startswith("calibration/")]:
        del manifest["items"][name]
    for name, item in manifest["items"].items():
        if item["params"].get("weights") == "calibrated":
            item["params"]["weights"] = "model"
            del item["params"]["mismatch"]
    (root / pipeline.MANIFEST).write_text(json.dumps(manifest))
    kept = {n: (root / n).read_bytes() for n in manifest["items"] if "edof" not in n}
    # such a dataset is still complete and valid: it is read and scored as it is
    assert load_manifest(root)["complete"] is True
    assert list(evaluate_dataset(root)["scenes"]) == ["scene_000"]
    again = build_dataset(TINY, root, TINY_OPTS, progress=False)
    redone = {n for n, item in again["items"].items()
              if manifest["items"].get(n, {}).get("params") != item["params"]}
    assert redone == {"calibration/pinhole.exr", "calibration/sweep.exr",
                      "calibration/mismatch.json", "scene_000/edof.exr",
                      "scene_000/edof_50lux.exr"}
    assert all((root / n).read_bytes() == b for n, b in kept.items())
