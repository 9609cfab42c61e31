"""Manifests are validated whenever they are read; datasets verified before use.

``evaluate`` and ``dataset`` share one validator (``validate_manifest``) whose option
limits are ``DatasetOptions``' own. Crafted manifests that used to run for ever, crash
with AttributeError or score nothing with exit status 0 are one-line user errors.
"""

import hashlib
import json
import shutil
from dataclasses import replace

import numpy as np
import OpenEXR
import pytest

from conftest import run_cli
from mitsweep.cli.main import main
from mitsweep.pipeline import tasks
from mitsweep.pipeline import (MANIFEST, MAX_SCENES, DatasetError, DatasetOptions, build_dataset,
                               evaluate_dataset, load_manifest, options_from_dict)
from test_io_write_errors import tiny_setup_toml
from test_pipeline_dataset import EXPECTED, TINY, TINY_OPTS


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    root = tmp_path_factory.mktemp("pristine")
    build_dataset(TINY, root, TINY_OPTS, progress=False)
    return root


@pytest.fixture
def dataset(pristine, tmp_path):
    """A fresh copy of the tiny dataset, for a test to damage."""
    root = tmp_path / "ds"
    shutil.copytree(pristine, root)
    return root


def _edit_manifest(root, edit):
    path = root / MANIFEST
    manifest = json.loads(path.read_text())
    manifest = edit(manifest) or manifest
    path.write_text(json.dumps(manifest))


def _set(path, value):
    def edit(m):
        *keys, last = path
        d = m
        for k in keys:
            d = d[k]
        d[last] = value
    return edit


def _del(path):
    def edit(m):
        *keys, last = path
        d = m
        for k in keys:
            d = d[k]
        del d[last]
    return edit


CRAFTED = [
    # (edit, what the message must say)
    (lambda m: [m], "top level: must be a JSON object, got list"),
    (_set(["options"], []), "options: must be an object, got list"),
    (_set(["items"], []), "items: must be an object, got list"),
    (_set(["setup"], "sphere"), "setup: must be an object"),
    (_set(["format"], "other/2"), "format: must be 'mitsweep-dataset/1'"),
    (_set(["options", "scenes"], 100_000_000),
     f"options.scenes: must be an integer in [1, {MAX_SCENES}], got 100000000"),
    (_set(["options", "scenes"], -3), "options.scenes: must be an integer in [1,"),
    (_set(["options", "scenes"], 2.0), "options.scenes: must be an integer"),
    (_set(["options", "scenes"], True), "options.scenes: must be an integer"),
    (_set(["options", "scenes"], 2), "items: a complete dataset lists every item; missing "
                                     "scene_001/"),
    (_set(["options", "light_levels_lux"], [float("nan")]),
     "options.light_levels_lux: every value must be a finite number > 0"),
    (_set(["options", "light_levels_lux"], [-1.0]), "options.light_levels_lux"),
    (_set(["options", "light_levels_lux"], 50), "options.light_levels_lux: must be a list"),
    (_set(["options", "seed"], -5), "options.seed: must be an integer in [0,"),
    (_set(["options", "spp"], {"pinhole": 1}), "options.spp: must give samples per pixel"),
    (_set(["options", "bank_depths_mm"], []), "options.bank_depths_mm"),
    (_set(["options", "extra"], 1), "options: unknown keys ['extra']"),
    (_del(["options", "grid"]), "options: missing keys ['grid']"),
    (_set(["items", "../escape.exr"], {}), "items['../escape.exr']: must stay inside"),
    (_set(["items", "/etc/passwd"], {}), "items['/etc/passwd']: must be a relative path"),
    (_set(["items", "scene_007/sweep.exr"], {}), "items['scene_007/sweep.exr']: is not an "
                                                 "item of a dataset with these options"),
    (_set(["items", "bank.npz"], []), "items['bank.npz']: must be an object"),
    (_set(["items", "bank.npz", "sha256"], 5), "items['bank.npz'].sha256: must be 64"),
    (_set(["items", "bank.npz", "bytes"], -1), "items['bank.npz'].bytes"),
    (_del(["items", "bank.npz"]), "items: a complete dataset lists every item; missing "
                                  "bank.npz"),
    (_set(["complete"], "yes"), "complete: must be true when present"),
]


@pytest.mark.parametrize("edit,message", CRAFTED, ids=[c[1][:40] for c in CRAFTED])
def test_crafted_manifest_is_refused_naming_the_field(dataset, edit, message):
    _edit_manifest(dataset, edit)
    with pytest.raises(DatasetError) as info:
        evaluate_dataset(dataset)
    assert str(info.value).startswith(f"{dataset / MANIFEST}: invalid manifest: ")
    assert message in str(info.value)
    # dataset reads it with the same validator, before writing anything.
    before = (dataset / MANIFEST).read_bytes()
    with pytest.raises(DatasetError, match="invalid manifest"):
        build_dataset(TINY, dataset, TINY_OPTS, progress=False)
    assert (dataset / MANIFEST).read_bytes() == before


@pytest.mark.parametrize("edit,message", [
    (_set(["options", "scenes"], 100_000_000), "options.scenes: must be an integer in"),
    (lambda m: [m], "top level: must be a JSON object"),
    (_set(["options", "scenes"], -3), "options.scenes"),
])
def test_cli_evaluate_crafted_manifest_is_one_line(dataset, edit, message):
    _edit_manifest(dataset, edit)
    rc, out, err = run_cli("evaluate", dataset, timeout=120)
    assert rc == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and message in err and "Traceback" not in err


def test_symlink_escaping_the_directory_is_refused(dataset, tmp_path):
    outside = tmp_path / "outside.exr"
    shutil.copy(dataset / "scene_000" / "edof.exr", outside)
    (dataset / "scene_000" / "edof.exr").unlink()
    (dataset / "scene_000" / "edof.exr").symlink_to(outside)
    with pytest.raises(DatasetError, match=r"items\['scene_000/edof.exr'\]: resolves outside"):
        load_manifest(dataset)


def test_missing_item_is_named(dataset):
    (dataset / "scene_000" / "stopped.exr").unlink()
    with pytest.raises(DatasetError) as info:
        evaluate_dataset(dataset)
    assert str(info.value).startswith(f"{dataset / 'scene_000' / 'stopped.exr'}: listed in "
                                      f"the manifest but missing")


def test_changed_item_is_named(dataset):
    with open(dataset / "scene_000" / "focused.exr", "ab") as f:
        f.write(b"\0")
    with pytest.raises(DatasetError, match=r"focused.exr: changed since it was written"):
        evaluate_dataset(dataset)


def test_incomplete_dataset_is_refused(dataset):
    _edit_manifest(dataset, _del(["complete"]))
    with pytest.raises(DatasetError, match="incomplete dataset"):
        evaluate_dataset(dataset)


def _write_raw_exr(path, rgb):
    """An EXR as another tool might write it (``write_exr`` refuses NaN)."""
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    chans = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, chans) as f:
        f.write(str(path))


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nan_pixels_are_named_not_a_math_error(dataset, bad):
    name = "scene_000/sweep.exr"
    img = tasks.read_rgb(dataset / name)[0].copy()
    img[10, 10, 1] = bad
    _write_raw_exr(dataset / name, img)

    def record(m):  # as if the dataset had been written with it
        m["items"][name]["sha256"] = hashlib.sha256((dataset / name).read_bytes()).hexdigest()
        m["items"][name]["bytes"] = (dataset / name).stat().st_size

    _edit_manifest(dataset, record)
    rc, _, err = run_cli("evaluate", dataset, timeout=120)
    assert rc == 2, err
    assert err.strip() == (f"mitsweep: error: {dataset / name}: holds NaN or inf pixels "
                           f"(channel image); cannot score it (rerun `mitsweep dataset` to "
                           f"redo it)")


def test_evaluate_scores_only_the_manifest_items(dataset):
    stray = dataset / "scene_000" / "stray.exr"
    shutil.copy(dataset / "scene_000" / "sweep.exr", stray)
    scene = evaluate_dataset(dataset)["scenes"]["scene_000"]
    assert "stray" not in scene
    assert {n for n, v in scene.items() if isinstance(v, dict)} == {
        p.split("/")[1][:-4] for p in EXPECTED if p.endswith(".exr")} - {"pinhole"}


# -- options: one set of limits, checked before anything is created ---------------------

@pytest.mark.parametrize("field,value,message", [
    ("scenes", 0, "scenes: must be an integer in [1, 10000]"),
    ("scenes", MAX_SCENES + 1, "scenes: must be an integer in [1, 10000]"),
    ("seed", -5, "seed: must be an integer in [0,"),
    ("seed", 2**32, "seed: must be an integer in [0,"),
    ("spp", {"pinhole": 1, "focused": 1, "sweep": 0, "stopped": 1}, "spp['sweep']"),
    ("light_levels_lux", (50.0, 50.0), "light_levels_lux: levels must differ"),
    ("light_levels_lux", (float("inf"),),
     "light_levels_lux: every value must be a finite number > 0"),
    ("bank_depths", (), "bank_depths: must be a list of 1 to"),
    ("bank_rays", 0, "bank_rays: must be a positive integer or null"),
    ("grid", (9,), "grid: must be two integers"),
    ("stopped_f_number", float("nan"), "stopped_f_number: must be a finite number > 0"),
    ("diffraction", 1, "diffraction: must be true or false"),
])
def test_dataset_options_are_validated(field, value, message):
    with pytest.raises(DatasetError) as info:
        replace(TINY_OPTS, **{field: value})
    assert str(info.value).startswith(message)


def test_options_round_trip_through_the_manifest():
    assert options_from_dict(TINY_OPTS.as_dict()) == TINY_OPTS
    assert options_from_dict(json.loads(json.dumps(DatasetOptions().as_dict()))) \
        == DatasetOptions()


@pytest.mark.parametrize("args,message", [
    (["--seed", "-5"], "mitsweep: error: --seed: must be an integer in [0, 4294967295]"),
    (["--scenes", "10001"], "mitsweep: error: --scenes: must be an integer in [1, 10000]"),
    (["--lux", "50", "50.0000001"], "mitsweep: error: --lux: levels must differ"),
])
def test_cli_dataset_options_fail_before_the_directory_exists(tmp_path, args, message,
                                                              capsys):
    setup = tiny_setup_toml(tmp_path)
    out = tmp_path / "new" / "ds"
    rc = main(["dataset", str(setup), "--out", str(out), *args])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(message) and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "new").exists()


def test_dataset_drops_items_of_other_options(dataset):
    """A rerun with fewer light levels keeps a manifest that validates."""
    more = replace(TINY_OPTS, light_levels_lux=(50.0, 2.0))
    build_dataset(TINY, dataset, more, progress=False)
    assert "scene_000/edof_2lux.exr" in load_manifest(dataset)["items"]
    build_dataset(TINY, dataset, TINY_OPTS, progress=False)
    assert set(load_manifest(dataset)["items"]) == EXPECTED


def test_item_changed_during_the_run_keeps_the_dataset_incomplete(tmp_path, monkeypatch):
    """Complete only when every item verifies: a file changed after it was recorded (as
    a second writer would) is caught, dropped from the manifest, and redone."""
    root = tmp_path / "ds"
    real = tasks.restore

    def deconvolve_then_tamper(setup, out, **kwargs):
        info = real(setup, out, **kwargs)
        if out.name == "edof_50lux.exr":  # the last task; focused.exr was recorded
            with open(root / "scene_000" / "focused.exr", "ab") as f:
                f.write(b"\0")
        return info

    monkeypatch.setattr(tasks, "restore", deconvolve_then_tamper)
    with pytest.raises(DatasetError, match=r"focused.exr: changed after it was written"):
        build_dataset(TINY, root, TINY_OPTS, progress=False)
    partial = load_manifest(root)
    assert "complete" not in partial and "scene_000/focused.exr" not in partial["items"]
    monkeypatch.setattr(tasks, "restore", real)
    final = build_dataset(TINY, root, TINY_OPTS, progress=False)
    assert final["complete"] is True
    focused = (root / "scene_000" / "focused.exr").read_bytes()
    assert final["items"]["scene_000/focused.exr"]["sha256"] == hashlib.sha256(focused).hexdigest()
