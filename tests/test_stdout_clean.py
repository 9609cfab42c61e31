"""stdout is the command's alone: Mitsuba's and Dr.Jit's log lines go through ``logging``
(loggers ``mitsuba`` and ``drjit``) to stderr, with or without ``--json``.

The warning is a real one: Mitsuba warns about a sphere whose ``to_world`` scales
non-uniformly (its stream appender wrote that line to stdout, in colour).
"""

from __future__ import annotations

import ctypes
import json
import logging

import pytest

from conftest import run_cli
from mitsweep import backend
from test_io_write_errors import tiny_setup_toml

#: A scene Mitsuba loads with one warning: the sphere is scaled 200 x 100 x 150.
SQUASHED_SPHERE = """<scene version="3.0.0">
  <emitter type="constant"/>
  <shape type="sphere">
    <transform name="to_world">
      <scale x="200" y="100" z="150"/>
      <translate x="1000" y="0" z="0"/>
    </transform>
  </shape>
</scene>
"""
MITSUBA_WARNING = "WARNING mitsuba: [Sphere] 'to_world' transform shouldn't contain " \
                  "non-uniform scaling!"


@pytest.fixture
def squashed(tmp_path):
    scene = tmp_path / "squashed.xml"
    scene.write_text(SQUASHED_SPHERE)
    return tiny_setup_toml(tmp_path), scene


@pytest.mark.parametrize("json_flag", [True, pytest.param(False, marks=pytest.mark.slow)],
                         ids=["json", "text"])
def test_mitsuba_warning_goes_to_stderr_not_stdout(tmp_path, squashed, json_flag):
    setup, scene = squashed
    out = tmp_path / "out.exr"
    rc, stdout, stderr = run_cli("render", setup, "--mode", "pinhole", "--spp", "1",
                                 "--scene", scene, "--out", out,
                                 *(["--json"] if json_flag else []))
    assert rc == 0, stderr
    assert "\x1b[" not in stdout and "WARN" not in stdout
    if json_flag:
        assert json.loads(stdout)["out"] == str(out)
    else:
        assert stdout.startswith(f"{out}: pinhole, 1 spp") and stdout.count("\n") == 1
    assert MITSUBA_WARNING in stderr.splitlines(), stderr


def test_mitsuba_log_reaches_the_mitsuba_logger(squashed, caplog):
    import mitsuba as mi

    backend.set_mitsuba_variant()
    with caplog.at_level(logging.WARNING, logger="mitsuba"):
        mi.load_file(str(squashed[1]))
    records = [r for r in caplog.records if r.name == "mitsuba"]
    assert [r.getMessage() for r in records] == [MITSUBA_WARNING.split("mitsuba: ", 1)[1]]
    assert records[0].levelno == logging.WARNING


def test_drjit_log_reaches_the_drjit_logger(caplog, capfd):
    assert backend.route_drjit_log()
    lib = backend.drjit_core()
    jit_log = lib["_Z7jit_log8LogLevelPKcz"]  # drjit-core's own logging entry point
    jit_log.restype = None
    with caplog.at_level(logging.DEBUG, logger="drjit"):
        jit_log(ctypes.c_int(2), b"a warning from %s", b"drjit-core")
        jit_log(ctypes.c_int(3), b"an info line stays below the routed level")
    assert [(r.levelno, r.getMessage()) for r in caplog.records if r.name == "drjit"] == \
        [(logging.WARNING, "a warning from drjit-core")]
    out, err = capfd.readouterr()
    assert "drjit-core" not in out and "drjit-core" not in err  # not written directly
