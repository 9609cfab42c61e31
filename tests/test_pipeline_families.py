"""Datasets of the user's world: scenes from a directory of Mitsuba XML files and from the
procedural family, each scene's source in its render tasks' parameters (so any item can
be made again alone), evaluated end to end; room datasets' options and parameters are
what they were before the families existed."""

import argparse
import json
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from mitsweep.pipeline import (DatasetError, DatasetOptions, build_dataset, evaluate_dataset,
                               load_manifest, options_from_dict)
from mitsweep.pipeline import options as pipeline_options, tasks
from mitsweep.pipeline.dataset import scene_files_from
from mitsweep.pipeline.runner import sha256
from mitsweep.render.procedural import resolve_params
from test_pipeline_dataset import TINY, TINY_OPTS

#: The keys of a room dataset's options and render parameters before the families.
ROOM_OPTION_KEYS = {"scenes", "seed", "spp", "light_levels_lux", "bank_depths_mm", "bank_rays",
                    "grid", "stopped_f_number", "diffraction", "methods"}
ROOM_RENDER_KEYS = {"scene", "mode", "spp", "seed", "f_number", "diffraction", "sampler"}

#: Two small scenes in metres, off the camera's line of sight (the lens is 0.327 m up
#: the axis): a constant sky, textured and glossy shapes, an area light.
SCENE_A = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <emitter type="constant"><rgb name="radiance" value="0.4, 0.45, 0.5"/></emitter>
  <shape type="sphere">
    <point name="center" x="1.0" y="0.2" z="0.2"/><float name="radius" value="0.4"/>
    <bsdf type="diffuse">
      <texture type="checkerboard" name="reflectance">
        <transform name="to_uv"><scale value="8"/></transform>
      </texture>
    </bsdf>
  </shape>
  <shape type="rectangle">
    <transform name="to_world">
      <scale value="1.5"/><rotate y="1" angle="90"/><translate x="-2" y="0" z="0.5"/>
    </transform>
    <bsdf type="roughplastic"/>
  </shape>
  <shape type="cube">
    <transform name="to_world"><scale value="0.3"/><translate x="0" y="-1.5" z="0"/></transform>
    <bsdf type="roughconductor"/>
  </shape>
</scene>
"""
SCENE_B = """<scene version="3.0.0">
  <default name="floor_y" value="-0.6"/>
  <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
  <shape type="rectangle">
    <transform name="to_world">
      <scale value="3"/><rotate x="1" angle="90"/><translate y="$floor_y"/>
    </transform>
    <bsdf type="twosided">
      <bsdf type="diffuse">
        <texture type="checkerboard" name="reflectance">
          <transform name="to_uv"><scale value="10"/></transform>
        </texture>
      </bsdf>
    </bsdf>
  </shape>
  <shape type="sphere">
    <point name="center" x="-0.4" y="0" z="0.1"/><float name="radius" value="0.15"/>
    <bsdf type="plastic"/>
  </shape>
  <shape type="sphere">
    <point name="center" x="0" y="1.5" z="0.3"/><float name="radius" value="0.2"/>
    <emitter type="area"><rgb name="radiance" value="5"/></emitter>
  </shape>
</scene>
"""


def write_scenes(folder):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "b_floor.xml").write_text(SCENE_B)
    (folder / "a_shapes.xml").write_text(SCENE_A)
    (folder / "notes.txt").write_text("not a scene: only *.xml files are")
    return folder


def test_room_options_and_render_parameters_are_unchanged():
    assert set(DatasetOptions().as_dict()) == ROOM_OPTION_KEYS
    assert set(TINY_OPTS.as_dict()) == ROOM_OPTION_KEYS
    for t in tasks.plan(TINY_OPTS):
        if t.fn is tasks.render:
            assert set(t.params) == ROOM_RENDER_KEYS
    # A manifest written before the families reads back as a room dataset.
    old = json.loads(json.dumps(TINY_OPTS.as_dict()))
    assert options_from_dict(old) == TINY_OPTS and options_from_dict(old).family == "room"


def test_procedural_scenes_are_in_the_render_parameters():
    opts = replace(TINY_OPTS, scenes=3, seed=10, family="procedural",
                   family_params={"objects": 12})
    assert opts.family_params == resolve_params(objects=12)  # stored resolved
    assert options_from_dict(json.loads(json.dumps(opts.as_dict()))) == opts
    sources = {t.name: t.params["scene_source"] for t in tasks.plan(opts) if t.fn is tasks.render}
    assert len(sources) == 3 * 4 + 2   # and the calibration scene's pinhole and sweep
    for name, src in sources.items():
        folder = name.split("/")[0]
        i = tasks.CALIBRATION_SCENE if folder == tasks.CALIBRATION_DIR \
            else int(folder.split("_")[1])
        assert src == {"family": "procedural", "seed": 10 + i, "params": opts.family_params}
    # the calibration scene is none of the dataset's, however many it grows to
    assert tasks.CALIBRATION_SCENE >= pipeline_options.MAX_SCENES


@pytest.mark.parametrize("kw,message", [
    ({"family": "forest"}, "family: must be one of room, procedural, xml"),
    ({"family_params": {"objects": 3}}, "family_params: apply to the procedural family only"),
    ({"family": "procedural", "family_params": {"objects": -1}},
     "family_params.objects: must be an integer in [1, 256]"),
    ({"family": "xml"}, "scene_files: one file per scene: 1 scenes, 0 files"),
    ({"family": "xml", "scene_files": [{"path": "a.xml", "sha256": "x" * 64}]},
     "scene_files[0].sha256: must be 64 lowercase hex digits"),
    ({"family": "xml", "scene_files": [{"path": "a.obj", "sha256": "0" * 64}]},
     "scene_files[0].path: must be the path of an .xml file"),
    ({"scene_unit": "m"}, "scene_unit: applies to family 'xml' only"),
    ({"family": "xml", "scene_unit": "inch", "scene_files": [{"path": "a.xml",
                                                              "sha256": "0" * 64}]},
     "scene_unit: must be one of mm, cm, m or null"),
])
def test_bad_scene_options_name_the_field(kw, message):
    with pytest.raises(DatasetError) as info:
        DatasetOptions(**kw)
    assert message in str(info.value)


def test_scene_files_are_the_sorted_xml_files_with_their_checksums(tmp_path):
    folder = write_scenes(tmp_path / "scenes")
    files = scene_files_from(folder, TINY, unit="m")  # loads each, as the render will
    assert [f["path"] for f in files] == [str((folder / n).resolve())
                                          for n in ("a_shapes.xml", "b_floor.xml")]
    assert [f["sha256"] for f in files] == [sha256(folder / "a_shapes.xml"),
                                            sha256(folder / "b_floor.xml")]


def test_a_scene_file_changed_after_planning_is_refused(tmp_path):
    folder = write_scenes(tmp_path / "scenes")
    files = scene_files_from(folder)
    opts = replace(TINY_OPTS, scenes=2, family="xml", scene_files=files, scene_unit="m")
    (folder / "a_shapes.xml").write_text(SCENE_A.replace("0.4, 0.45", "0.9, 0.45"))
    task = next(t for t in tasks.plan(opts) if t.name == "scene_000/pinhole.exr")
    with pytest.raises(DatasetError, match="a_shapes.xml: changed since the dataset was "
                                           "planned"):
        tasks.render(TINY, tmp_path / "x.exr", **task.params)
    assert not (tmp_path / "x.exr").exists()


def _regenerates_alone(root, manifest, name, tmp_path):
    """An item made again from its manifest entry alone (the setup and the item's
    parameters), in a fresh process with another hash seed, has the recorded bytes."""
    out = tmp_path / "again" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    script = ("import json, sys\n"
              "from mitsweep.config import setup_from_dict\n"
              "from mitsweep.pipeline import tasks\n"
              "m = json.load(open(sys.argv[1]))\n"
              "tasks.render(setup_from_dict(m['setup']), sys.argv[3], "
              "**m['items'][sys.argv[2]]['params'])\n")
    env = dict(os.environ, PYTHONHASHSEED="12345")
    subprocess.run([sys.executable, "-c", script, str(root / "manifest.json"), name, str(out)],
                   check=True, env=env, timeout=600, capture_output=True)
    return sha256(out) == manifest["items"][name]["sha256"]


def _finite_scores(results, n_scenes):
    assert len(results["scenes"]) == n_scenes
    for scene in results["scenes"].values():
        for key in ("edof", "focused", "stopped", "sweep", "edof_50lux"):
            assert np.isfinite(scene[key]["psnr"]) and np.isfinite(scene[key]["ssim"]), key
    return True


@pytest.mark.slow  # about 4 minutes loaded: 5 scenes of path-traced renders
def test_xml_and_procedural_datasets_evaluate_end_to_end(tmp_path):
    folder = write_scenes(tmp_path / "scenes")
    xml = replace(TINY_OPTS, scenes=2, family="xml", scene_unit="m",
                  scene_files=scene_files_from(folder, TINY, unit="m"))
    manifest = build_dataset(TINY, tmp_path / "xml", xml, progress=False)
    assert manifest["complete"] and load_manifest(tmp_path / "xml")["options"]["family"] == "xml"
    for i, name in enumerate(("a_shapes.xml", "b_floor.xml")):
        src = manifest["items"][f"scene_{i:03d}/sweep.exr"]["params"]["scene_source"]
        assert src == {"family": "xml", "file": str((folder / name).resolve()),
                       "sha256": sha256(folder / name), "unit": "m"}
    results = evaluate_dataset(tmp_path / "xml")
    assert _finite_scores(results, 2)
    assert results["scenes"]["scene_001"]["source"]["file"].endswith("b_floor.xml")
    assert "source" not in results["mean"]
    assert results["scenes"]["scene_000"]["focused"]["psnr"] != \
        results["scenes"]["scene_001"]["focused"]["psnr"]  # two different scenes

    proc = replace(TINY_OPTS, scenes=3, family="procedural", family_params={"objects": 12})
    manifest = build_dataset(TINY, tmp_path / "proc", proc, progress=False)
    assert manifest["complete"]
    results = evaluate_dataset(tmp_path / "proc")
    assert _finite_scores(results, 3)
    assert [s["source"]["seed"] for s in results["scenes"].values()] == [0, 1, 2]
    psnrs = {s["focused"]["psnr"] for s in results["scenes"].values()}
    assert len(psnrs) == 3  # three scene variations, not one scene three times
    # Any item can be made again alone, from its manifest entry: the same bytes.
    assert _regenerates_alone(tmp_path / "proc", manifest, "scene_002/pinhole.exr", tmp_path)


def _scene_options(args, setup) -> dict:
    """DatasetOptions fields of the command's scene options, passed as ``mitsweep
    dataset`` passes them to the library (:func:`mitsweep.workflows.dataset.build_dataset`,
    which calls :func:`~mitsweep.workflows.dataset.scene_options`)."""
    from mitsweep.workflows.dataset import scene_options

    return scene_options(setup, scenes=args.scenes, family=args.family,
                         family_params=args.family_param, scenes_from=args.scenes_from,
                         scene_unit=args.scene_unit)


def test_cli_family_options_make_the_dataset_options(tmp_path):
    from mitsweep.cli import dataset as cli

    p = argparse.ArgumentParser()
    cli.add_arguments(p)
    args = p.parse_args(["s.toml", "--out", "x", "--family", "procedural", "--scenes", "3",
                         "--family-param", "objects=12", "--family-param", "shapes=sphere,cube",
                         "--family-param", "env_scale=0.5"])
    kw = _scene_options(args, TINY)
    opts = DatasetOptions(**kw)
    assert opts.scenes == 3 and opts.family == "procedural"
    assert opts.family_params == resolve_params(objects=12, shapes="sphere,cube", env_scale=0.5)
    folder = write_scenes(tmp_path / "scenes")
    args = p.parse_args(["s.toml", "--out", "x", "--scenes-from", str(folder),
                         "--scene-unit", "m"])
    opts = DatasetOptions(**_scene_options(args, TINY))
    assert opts.scenes == 2 and opts.family == "xml" and opts.scene_unit == "m"
    assert opts.scene_files == scene_files_from(folder)
