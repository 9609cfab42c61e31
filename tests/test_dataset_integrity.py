"""A resumed dataset never mixes old and new scene content, resumes whatever the spelling
of its setup's path, and never writes through a symlinked folder (issue 28, items 1, 7).

The scene is the setup's own ``[scene] file``: an XML file that includes its light and
textures its ball from an EXR, so that a change in each kind of file it loads is tried.
Renders are 48 px at 2-4 spp (about 3 s a dataset)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from mitsweep.cli.main import main
from mitsweep.config import load_setup
from mitsweep.io import write_exr
from mitsweep.pipeline import DatasetError, build_dataset, load_manifest, tasks
from test_io_write_errors import tiny_setup_toml
from test_pipeline_dataset import TINY, TINY_OPTS

SCENE = """<scene version="3.0.0">
  <include filename="light.xml"/>
  <shape type="sphere">
    <point name="center" x="1000" y="0" z="0"/><float name="radius" value="400"/>
    <bsdf type="diffuse">
      <texture type="bitmap" name="reflectance"><string name="filename" value="tex.exr"/></texture>
    </bsdf>
  </shape>
</scene>
"""
LIGHT = '<scene version="3.0.0"><emitter type="constant"><rgb name="radiance" value="{}"/>' \
        '</emitter></scene>\n'
ARGS = ["--spp", "2", "2", "4", "2", "--lux", "50", "--bank-rays", "16384"]
RENDERS = [f"scene_000/{m}.exr" for m in ("pinhole", "focused", "sweep", "stopped")]


def _write_world(folder: Path) -> Path:
    """The scene files and a tiny setup naming them (relative to the setup); the setup."""
    (folder / "scene.xml").write_text(SCENE)
    (folder / "light.xml").write_text(LIGHT.format(0.5))
    write_exr(folder / "tex.exr", np.full((4, 4, 3), 0.5, np.float32))
    setup = tiny_setup_toml(folder)
    setup.write_text(setup.read_text() + '\n[scene]\nfile = "scene.xml"\n')
    return setup


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A complete dataset of the world, made with the setup given by its absolute path."""
    folder = tmp_path_factory.mktemp("world")
    setup = _write_world(folder)
    assert main(["dataset", str(setup.resolve()), "--out", str(folder / "ds"), *ARGS]) == 0
    return folder


@pytest.fixture
def world(made, tmp_path):
    """A copy of the made world and dataset to change."""
    copy = tmp_path / "world"
    shutil.copytree(made, copy, symlinks=True)
    return copy


def _mean(path: Path) -> float:
    return float(tasks.read_rgb(path)[0].mean())


def _items(root: Path) -> dict:
    return load_manifest(root)["items"]


def _stamps(root: Path) -> dict:
    """Each item's inode and modification time: equal only if it was not written again
    (items are replaced by a rename)."""
    return {n: ((root / n).stat().st_ino, (root / n).stat().st_mtime_ns) for n in _items(root)}


@pytest.mark.parametrize("change", [
    "radiance in the included file",
    *(pytest.param(c, marks=pytest.mark.slow) for c in ("the scene XML", "the texture"))])
def test_a_changed_scene_file_redoes_every_item_made_from_it(world, capsys, change):
    """The issue's case: change the scene, delete one item, rerun. Every item of the
    scene is made again (the bank, which does not see the scene, is kept), so no old
    render sits beside a new one."""
    ds = world / "ds"
    before = _items(ds)
    old_pinhole = _mean(ds / "scene_000/pinhole.exr")
    old_ratio = _mean(ds / "scene_000/sweep.exr") / old_pinhole
    if change == "radiance in the included file":
        (world / "light.xml").write_text(LIGHT.format(3.0))
    elif change == "the scene XML":
        (world / "scene.xml").write_text(SCENE.replace('value="400"', 'value="300"'))
    else:
        write_exr(world / "tex.exr", np.full((4, 4, 3), 0.9, np.float32))
    (ds / "scene_000/sweep.exr").unlink()
    assert main(["dataset", str(world / "tiny.toml"), "--out", str(ds), *ARGS]) == 0
    after = load_manifest(ds)
    assert after["complete"]
    assert after["items"]["bank.npz"] == before["bank.npz"]
    redone = [n for n in before if n != "bank.npz"]
    assert all(after["items"][n]["sha256"] != before[n]["sha256"] for n in redone), change
    # Old and new renders side by side would break the sweep/pinhole ratio (x6 in the
    # radiance case); the renders are linear in the light and share their seeds, so
    # the ratio holds to float rounding (measured: 1e-6).
    ratio = _mean(ds / "scene_000/sweep.exr") / _mean(ds / "scene_000/pinhole.exr")
    if change == "radiance in the included file":
        assert ratio == pytest.approx(old_ratio, rel=1e-4)
        assert _mean(ds / "scene_000/pinhole.exr") == pytest.approx(6.0 * old_pinhole,
                                                                   rel=1e-4)
    files = after["items"]["scene_000/pinhole.exr"]["params"]["setup_scene"]
    assert set(files) == {"scene.xml", "light.xml", "tex.exr"}


@pytest.mark.parametrize("how", ["setup by a relative path", "scene by an absolute path"])
def test_another_spelling_of_the_same_files_resumes_without_work(world, monkeypatch, how):
    """Made with the setup's absolute path; resumed with a relative one, or with a setup
    naming the same scene by its absolute path: the same dataset, nothing made again."""
    ds = world / "ds"
    stamps = _stamps(ds)
    monkeypatch.chdir(world)
    setup = Path("tiny.toml")
    if how == "scene by an absolute path":
        setup.write_text(setup.read_text().replace('"scene.xml"',
                                                   json.dumps(str(world / "scene.xml"))))
    assert main(["dataset", str(setup), "--out", "ds", *ARGS]) == 0
    assert load_manifest(ds)["complete"] and _stamps(ds) == stamps


def test_a_render_refuses_a_scene_changed_since_planning(world, tmp_path):
    """An item made again alone from its manifest entry checks every file of the scene
    first, naming the one that changed."""
    ds = world / "ds"
    params = _items(ds)["scene_000/pinhole.exr"]["params"]
    setup = load_setup(world / "tiny.toml")
    write_exr(world / "tex.exr", np.full((4, 4, 3), 0.9, np.float32))
    with pytest.raises(DatasetError, match=r"tex\.exr: changed since the dataset was planned"):
        tasks.render(setup, tmp_path / "again.exr", **params)
    assert not (tmp_path / "again.exr").exists()


# -- symlinked folders ------------------------------------------------------------------

@pytest.mark.parametrize("folder", ["scene_000", "logs"])
def test_a_symlinked_dataset_folder_is_refused_and_never_written_through(tmp_path, capsys,
                                                                         folder):
    outside = tmp_path / "outside"
    outside.mkdir()
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / folder).symlink_to(outside, target_is_directory=True)
    with pytest.raises(DatasetError, match=f"{folder}: a symbolic link"):
        build_dataset(TINY, ds, TINY_OPTS, progress=False)
    assert list(outside.iterdir()) == []
    # at the command line: one line, exit 2
    setup = tiny_setup_toml(tmp_path)
    assert main(["dataset", str(setup), "--out", str(ds), *ARGS]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{ds / folder}: a symbolic link" in err
    assert list(outside.iterdir()) == []


def test_a_symlinked_shard_folder_is_refused(tmp_path):
    outside = tmp_path / "outside"
    outside.mkdir()
    ds = tmp_path / "ds"
    ds.mkdir()
    (ds / "shards").symlink_to(outside, target_is_directory=True)
    with pytest.raises(DatasetError, match="shards: a symbolic link"):
        build_dataset(TINY, ds, TINY_OPTS, shard="1/2", progress=False)
    assert list(outside.iterdir()) == []


@pytest.mark.parametrize("where", ["inside", "outside"])
def test_a_symlinked_item_is_never_written_through(world, capsys, where):
    """An item that is a link to a file with its bytes (so its checksum matches): to a
    file outside the dataset, the manifest is refused as the reader refuses it; to one
    inside, the item is made again and the link replaced by the dataset's own file.
    Either way the linked file is left as it was."""
    ds = world / "ds"
    item = ds / "scene_000" / "stopped_50lux.exr"
    target = (ds if where == "inside" else world) / "spare.exr"
    shutil.copyfile(item, target)
    data = target.read_bytes()
    item.unlink()
    item.symlink_to(target)
    rc = main(["dataset", str(world / "tiny.toml"), "--out", str(ds), *ARGS])
    assert target.read_bytes() == data
    if where == "outside":
        err = capsys.readouterr().err
        assert rc == 2 and err.count("\n") == 1 and "resolves outside" in err
        return
    assert rc == 0 and load_manifest(ds)["complete"]
    assert not item.is_symlink() and item.is_file()
