"""One output policy for every command: an output never overwrites an input.

``check_outputs`` compares resolved paths and inodes, so ``..``, symlinks and hard links
to an input are caught; the commands call it before any work.
"""

import json
import os
import shutil

import pytest

from mitsweep.cli.common import UsageError, check_outputs
from mitsweep.cli.main import main
from mitsweep.pipeline import MANIFEST, build_dataset
from cli_contract import refused
from test_io_write_errors import tiny_setup_toml
from test_pipeline_dataset import TINY, TINY_OPTS


@pytest.fixture
def setup_file(tmp_path):
    return tiny_setup_toml(tmp_path)


def test_distinct_paths_pass(tmp_path, setup_file):
    check_outputs([setup_file, None], [tmp_path / "out.exr", None, tmp_path / "out.png"])


@pytest.mark.parametrize("alias", ["same", "dotdot", "symlink", "hardlink"])
def test_output_naming_an_input_is_refused(tmp_path, setup_file, alias):
    if alias == "same":
        out = setup_file
    elif alias == "dotdot":
        (tmp_path / "sub").mkdir()
        out = tmp_path / "sub" / ".." / setup_file.name
    elif alias == "symlink":
        out = tmp_path / "link.toml"
        out.symlink_to(setup_file)
    else:
        out = tmp_path / "hard.toml"
        os.link(setup_file, out)
    with pytest.raises(UsageError) as info:
        check_outputs([str(setup_file)], [out])
    assert str(info.value) == (f"output {out} is the input {setup_file}: refusing to "
                               f"overwrite an input; choose another output path")


def test_two_outputs_on_one_file_are_refused(tmp_path):
    with pytest.raises(UsageError, match="output .*p.png and output .*p.png are the same"):
        check_outputs([], [tmp_path / "p.png", tmp_path / "." / "p.png"])


def _run(argv, capsys):
    rc = main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def _refused(rc, err, out, inp):
    return rc == 2 and err.strip() == (f"mitsweep: error: output {out} is the input {inp}: "
                                       f"refusing to overwrite an input; choose another "
                                       f"output path")


@pytest.mark.parametrize("flag", ["--out", "--preview"])
def test_render_refuses_to_overwrite_its_setup(setup_file, tmp_path, flag, capsys):
    before = setup_file.read_bytes()
    extra = ["--out", tmp_path / "x.exr"] if flag == "--preview" else []
    rc, err = _run(["render", setup_file, "--mode", "pinhole", *extra, flag, setup_file],
                   capsys)
    assert _refused(rc, err, setup_file, setup_file), err
    assert setup_file.read_bytes() == before


def test_table1_refuses_a_plot_over_its_setup(setup_file, capsys):
    rc, err = _run(["table1", setup_file, "--plot", setup_file], capsys)
    assert _refused(rc, err, setup_file, setup_file), err


def test_dataset_refuses_its_setup_as_directory_or_item(tmp_path, setup_file, capsys):
    rc, err = _run(["dataset", setup_file, "--out", setup_file], capsys)
    assert _refused(rc, err, setup_file, setup_file), err
    # A setup named like a file the run writes inside the dataset directory.
    ds = tmp_path / "ds"
    ds.mkdir()
    inside = ds / MANIFEST
    shutil.copy(setup_file, inside)
    rc, err = _run(["dataset", inside, "--out", ds], capsys)
    assert _refused(rc, err, ds / MANIFEST, inside), err
    assert sorted(p.name for p in ds.iterdir()) == [MANIFEST]  # nothing written


def test_demo_refuses_its_setup_among_its_outputs(tmp_path, setup_file, capsys):
    report = tmp_path / "report.md"
    shutil.copy(setup_file, report)
    rc, err = _run(["demo", "--setup", report, "--out", tmp_path], capsys)
    assert _refused(rc, err, report, report), err


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    build_dataset(TINY, root, TINY_OPTS, progress=False)
    return root


@pytest.mark.parametrize("flag,name", [("--out", MANIFEST), ("--plot", "scene_000/edof.exr")])
def test_evaluate_refuses_to_overwrite_the_dataset(tiny_dataset, flag, name, capsys):
    target = tiny_dataset / name
    before = target.read_bytes()
    rc, err = _run(["evaluate", tiny_dataset, flag, target], capsys)
    assert _refused(rc, err, target, target), err
    assert target.read_bytes() == before


def test_evaluate_checks_its_outputs_before_scoring(tiny_dataset, tmp_path, capsys):
    missing = tmp_path / "no" / "such" / "e.json"
    rc, err = _run(["evaluate", tiny_dataset, "--out", missing], capsys)
    assert rc == 2
    assert err.strip() == (f"mitsweep: error: cannot write {missing}: directory "
                           f"{missing.parent} does not exist")


# --json: a failure is one JSON object on stdout too (the stderr line and exit 2 unchanged).

@pytest.mark.parametrize("argv,command,message", [
    (["sweep-range", "{tmp}/missing.toml", "--json"], "sweep-range", "missing.toml"),
    (["evaluate", "{tmp}", "--json"], "evaluate", "not a mitsweep dataset"),
    (["table1", "{setup}", "--plot", "{setup}", "--json"], "table1",
     "refusing to overwrite an input"),
    (["sweep-range", "{setup}", "--fov", "-3", "--json"], "sweep-range",
     "argument --fov: must be > 0"),  # argparse's own refusal
    (["design-sweep", "{setup}", "--out", "{tmp}/p.txt", "--json"], "design-sweep",
     "must end in .json"),
])
def test_json_commands_report_failures_as_json(tmp_path, setup_file, capsys, argv, command,
                                               message):
    argv = [a.format(tmp=tmp_path, setup=setup_file) for a in argv]
    line = refused(capsys, argv)  # the contract, with stdout's object matching stderr's line
    assert message in line
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's refusals
        rc = exc.code
    obj = json.loads(capsys.readouterr().out)
    assert obj == {"error": line.split("error: ", 1)[1], "command": command,
                   "exit_status": 2} and rc == 2


def test_failure_without_json_leaves_stdout_empty(tmp_path, capsys):
    refused(capsys, ["sweep-range", tmp_path / "missing.toml"])  # asserts stdout == ""
