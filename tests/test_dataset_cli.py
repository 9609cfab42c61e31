"""``mitsweep dataset``'s scale-out options: a bad value is one line, exit status 2,
before anything is created; restoration methods come from ``deconv.METHODS``."""

import pytest

from mitsweep.cli.main import main
from mitsweep.pipeline import DatasetError, DatasetOptions, edof_name, item_names
from test_io_write_errors import tiny_setup_toml


def _dataset_error(tmp_path, capsys, args):
    """``mitsweep dataset`` of a tiny setup with ``args``, which must fail: exit status 2,
    one line on stderr (returned), nothing created."""
    setup = tiny_setup_toml(tmp_path)
    out = tmp_path / "new" / "ds"
    try:
        rc = main(["dataset", str(setup), "--out", str(out), *args])
    except SystemExit as exc:  # argparse's own one-line errors
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert not (tmp_path / "new").exists()
    return err


@pytest.mark.parametrize("args,message", [
    (["--shard", "3/2"], "argument --shard: must be K/N with 1 <= K <= N <= 10000, got 3/2"),
    (["--shard", "0/4"], "argument --shard: must be K/N with 1 <= K <= N"),
    (["--shard", "two"], "argument --shard: must be K/N with 1 <= K <= N <= 10000 (e.g. 1/4), "
                         "got 'two'"),
    (["--scheduler", "localhost:8786"], "argument --scheduler: must be a Dask scheduler "
                                        "address tcp://HOST:PORT (port 1-65535), got "
                                        "'localhost:8786'"),
    (["--scheduler", "tcp://host:99999"], "argument --scheduler: must be a Dask scheduler"),
    (["--scheduler", "http://host:8786"], "argument --scheduler: must be a Dask scheduler"),
    (["--scheduler", "tcp://127.0.0.1:8786", "--executor", "process"],
     "mitsweep: error: --scheduler: needs --executor dask (or no --executor), got "
     "--executor process"),
    (["--executor", "ray"], "argument --executor: invalid choice: 'ray'"),
    (["--methods", "wiener,nope"], "mitsweep: error: --methods: unknown restoration method "
                                   "'nope'; allowed: wiener"),
    (["--methods", "wiener,wiener"], "mitsweep: error: --methods: each method at most once"),
    (["--methods", "wiener,"], "argument --methods: expected method names separated by "
                               "commas"),
    (["--retries", "-1"], "argument --retries: must be >= 0, got -1"),
])
def test_bad_scale_out_options_are_one_line(tmp_path, capsys, args, message):
    assert message in _dataset_error(tmp_path, capsys, args)


def test_methods_are_read_from_deconv_at_validation_time(monkeypatch):
    from mitsweep import deconv

    with pytest.raises(DatasetError, match="unknown restoration method 'later'"):
        DatasetOptions(methods=("wiener", "later"))
    monkeypatch.setattr(deconv, "METHODS", (*deconv.METHODS, "later"))
    opts = DatasetOptions(methods=("wiener", "later"), light_levels_lux=(50.0,))
    names = item_names(opts)
    # Wiener keeps the names the demo and the plots read; another method has its own.
    assert {"scene_000/edof.exr", "scene_000/edof_50lux.exr", "scene_000/edof_later.exr",
            "scene_000/edof_later_50lux.exr"} <= set(names)
    assert edof_name("wiener") == "edof" and edof_name("later", "_2lux") == "edof_later_2lux"


def test_unreachable_scheduler_is_one_line(tmp_path, capsys):
    err = _dataset_error(tmp_path, capsys, ["--scheduler", "tcp://127.0.0.1:9"])
    assert err.startswith("mitsweep: error: scheduler: cannot reach a Dask scheduler at "
                          "tcp://127.0.0.1:9 within 10 s")


# -- scenes: --family, --family-param, --scenes-from, --scene-unit ---------------------

NOT_XML = "this is not a scene\n"
UNKNOWN_PLUGIN = '<scene version="3.0.0"><shape type="teapot_of_doom"/></scene>\n'
MISSING_FILE = ('<scene version="3.0.0"><shape type="ply"><string name="filename" '
                'value="nowhere.ply"/></shape></scene>\n')
GOOD = ('<scene version="3.0.0"><emitter type="constant"/><shape type="sphere">'
        '<point name="center" x="1000" y="0" z="0"/><float name="radius" value="200"/>'
        '</shape></scene>\n')


@pytest.mark.parametrize("args,message", [
    (["--family", "forest"], "argument --family: invalid choice: 'forest'"),
    (["--family", "procedural", "--family-param", "objects=0"],
     "mitsweep: error: --family-param: objects: must be an integer in [1, 256], got 0"),
    (["--family", "procedural", "--family-param", "shapes=torus"],
     "mitsweep: error: --family-param: shapes: unknown 'torus'; allowed: sphere, cube"),
    (["--family", "procedural", "--family-param", "hue=3"],
     "mitsweep: error: --family-param: hue: not a parameter of the procedural family"),
    (["--family", "procedural", "--family-param", "objects"],
     "argument --family-param: expected KEY=VALUE, got 'objects'"),
    (["--family-param", "objects=3"],
     "mitsweep: error: --family-param: applies to --family procedural only, got --family room"),
    (["--scene-unit", "m"], "mitsweep: error: --scene-unit: applies to --scenes-from scenes "
                            "only"),
])
def test_bad_family_options_are_one_line(tmp_path, capsys, args, message):
    assert message in _dataset_error(tmp_path, capsys, args)


@pytest.mark.parametrize("files,extra,message", [
    ({}, [], "no *.xml scene files"),
    ({"a.xml": GOOD}, ["--family", "procedural"], "--family: not with --scenes-from (each "
                                                  "*.xml file of"),
    ({"a.xml": GOOD}, ["--scenes", "3"], "--scenes: not with --scenes-from"),
    ({"a.xml": GOOD, "b.xml": NOT_XML}, [], "b.xml: not a Mitsuba XML scene"),
    ({"a.xml": UNKNOWN_PLUGIN}, [], "teapot_of_doom"),
    ({"a.xml": GOOD, "c.xml": MISSING_FILE}, [], "nowhere.ply"),
])
def test_bad_scene_directories_are_refused_up_front(tmp_path, capsys, files, extra, message):
    folder = tmp_path / "scenes"
    folder.mkdir()
    for name, text in files.items():
        (folder / name).write_text(text)
    err = _dataset_error(tmp_path, capsys, ["--scenes-from", str(folder), *extra])
    assert message in err
    if len(files) > 1:  # the bad file is named, not the good one
        bad = sorted(files)[-1]
        assert bad in err and sorted(files)[0] not in err.replace(str(folder), "")


def test_scenes_from_a_missing_directory_is_one_line(tmp_path, capsys):
    err = _dataset_error(tmp_path, capsys, ["--scenes-from", str(tmp_path / "nope")])
    assert "nope: not a directory (--scenes-from takes a folder of Mitsuba XML scenes)" in err
