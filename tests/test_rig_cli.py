"""``mitsweep capture``: dry run, bad input (exit 2, one line, before any motion), and a
full capture from the command line against the pty simulator.

The refusals run the command in this process (``cli_contract.refused``: the same
``main`` a ``mitsweep`` process runs, without a Python start-up each); the captures and
the dry run run it as a real process (``conftest.run_cli``)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from cli_contract import refused
from conftest import run_cli

from mitsweep.rig import load_capture_record
from mitsweep.rig.simulator import ArduinoModel, Fault, PtyDevice

SCENES = Path(__file__).resolve().parents[1] / "scenes"

FAST_RIG = """
[rig]
max_velocity = 10.0
acceleration = 100.0
"""


def setup_file(tmp_path, extra_rig="", sweep_velocity=None, name="sphere_rig"):
    text = (SCENES / "sphere.toml").read_text()
    if sweep_velocity is not None:
        text = text.replace("velocity = 1.0", f"velocity = {sweep_velocity}")
    path = tmp_path / f"{name}.toml"
    path.write_text(text + FAST_RIG + extra_rig)
    return path


def test_dry_run_prints_plan_without_opening_a_port(tmp_path):
    # the port does not exist: a dry run must not try it
    rc, out, err = run_cli("capture", SCENES / "sphere.toml", "--port", tmp_path / "ttyNONE",
                           "--dry-run", "--json", timeout=120)
    assert rc == 0, err
    plan = json.loads(out)["plan"]
    assert plan["stage"] == "arduino"
    assert plan["translation_mm"] == pytest.approx(0.6950, abs=1e-4)   # paper: 0.69 mm
    assert plan["planned_exposure_s"] == pytest.approx(0.695, abs=1e-3)


@pytest.mark.parametrize("extra, velocity, args, message", [
    ("travel = 0.5\n", None, [], "more than the soft limits allow"),
    ("", 12.0, [], "more than the stage can hold"),
    ("min_exposure_s = 1.0\n", None, [], "outside the camera's range"),
    ("", None, ["--stage", "zaber"], "expected 'arduino' or 'zaber:PORT'"),
    ("", None, ["--port", "/dev/ttyDOESNOTEXIST"], "cannot open"),
    ("", None, [], "--port is required"),
], ids=["travel", "velocity", "exposure", "stage-syntax", "missing-port", "no-port"])
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, extra, velocity, args, message):
    setup = setup_file(tmp_path, extra, velocity)
    argv = ["capture", setup, *args]
    if "--port" not in args and message != "--port is required":
        argv += ["--port", "/dev/ttyDOESNOTEXIST"]   # must be refused before it is tried
    assert message in refused(capsys, [*argv, "--out", tmp_path / "rec.json"])
    assert not (tmp_path / "rec.json").exists()   # nothing captured, nothing recorded


def test_cli_capture_against_simulator(tmp_path):
    setup = setup_file(tmp_path)
    out = tmp_path / "rec.json"
    with PtyDevice(ArduinoModel()) as dev:
        rc, stdout, err = run_cli("capture", setup, "--port", dev.port, "--out", out,
                                  "--checksums", "--json", timeout=120)
    assert rc == 0, err
    summary = json.loads(stdout)
    assert summary["complete"]
    assert summary["measured_exposure_s"] == pytest.approx(summary["planned_exposure_s"],
                                                           abs=2e-6)
    assert load_capture_record(out)["complete"]


def test_cli_fault_exits_1_with_incomplete_record(tmp_path):
    setup = setup_file(tmp_path)
    out = tmp_path / "rec.json"
    with PtyDevice(ArduinoModel([Fault("fault_flag", at_fraction=0.4)])) as dev:
        rc, stdout, err = run_cli("capture", setup, "--port", dev.port, "--out", out,
                                  timeout=120)
        assert not dev.model.shutter_open and not dev.model.moving(time.monotonic())
    assert rc == 1
    assert "capture incomplete (fault)" in err and str(out) in err
    assert load_capture_record(out)["status"] == "fault"


def test_unwritable_record_path_exits_2_before_opening_ports(tmp_path, capsys):
    setup = setup_file(tmp_path)
    with PtyDevice(ArduinoModel()) as dev:
        err = refused(capsys, ["capture", setup, "--port", dev.port,
                               "--out", tmp_path / "missing_dir" / "rec.json"])
        assert not [line for _, d, line in dev.model.log if d == "rx"], "port was used"
    assert "does not exist" in err


def test_out_refuses_an_existing_file_without_force(tmp_path, capsys):
    setup = setup_file(tmp_path)
    out = tmp_path / "rec.json"
    out.write_text("an earlier capture\n")
    with PtyDevice(ArduinoModel()) as dev:
        err = refused(capsys, ["capture", setup, "--port", dev.port, "--out", out])
        assert not [line for _, d, line in dev.model.log if d == "rx"], "port was used"
    assert err.startswith("mitsweep: error: --out") and "--force" in err
    assert out.read_text() == "an earlier capture\n"


def test_out_with_force_replaces_an_existing_file(tmp_path):
    setup = setup_file(tmp_path)
    out = tmp_path / "rec.json"
    out.write_text("an earlier capture\n")
    with PtyDevice(ArduinoModel()) as dev:
        rc, _, err = run_cli("capture", setup, "--port", dev.port, "--out", out, "--force",
                             timeout=120)
    assert rc == 0, err
    assert load_capture_record(out)["complete"]


@pytest.mark.parametrize("alias", ["same", "relative", "symlink", "hardlink"])
def test_out_is_never_the_setup_file_even_with_force(tmp_path, capsys, alias):
    import os

    setup = setup_file(tmp_path)
    before = setup.read_text()
    out = {"same": setup, "relative": tmp_path / "sub" / ".." / setup.name,
           "symlink": tmp_path / "link.json", "hardlink": tmp_path / "hard.json"}[alias]
    (tmp_path / "sub").mkdir()
    if alias == "symlink":
        out.symlink_to(setup)
    elif alias == "hardlink":
        os.link(setup, out)
    with PtyDevice(ArduinoModel()) as dev:
        err = refused(capsys, ["capture", setup, "--port", dev.port, "--out", out, "--force"])
        assert not [line for _, d, line in dev.model.log if d == "rx"], "port was used"
    assert "is the input" in err
    assert setup.read_text() == before
