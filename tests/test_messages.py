"""Messages name the file, option or variable and what is allowed (issue 28, item 11).

Each refusal is checked with the CLI's user-error contract (:func:`cli_contract.refused`:
exit status 2, one line, no traceback, nothing on stdout); the byte-order-mark case is the
other way round, a valid scene that must be accepted.
"""

from __future__ import annotations

import codecs

import numpy as np
import pytest

from cli_contract import refused
from conftest import run_cli
from mitsweep.cli.main import main
from mitsweep.io import write_exr
from test_io_write_errors import tiny_setup_toml

#: A valid scene: a constant environment and a sphere 1 m off the mirror.
GOOD_SCENE = ('<scene version="3.0.0"><emitter type="constant"/><shape type="sphere">'
              '<point name="center" x="1000" y="0" z="0"/><float name="radius" value="200"/>'
              '</shape></scene>\n')
#: A card 100 mm in front of the mirror vertex, 1 m wide: it hides every probed ray.
BLOCKING_SCENE = ('<scene version="3.0.0"><emitter type="constant"/><shape type="rectangle" '
                  'id="card"><transform name="to_world"><scale value="500"/>'
                  '<translate z="100"/></transform></shape></scene>\n')


@pytest.fixture
def tiny(tmp_path):
    return tiny_setup_toml(tmp_path)


@pytest.fixture
def photo(tmp_path):
    """A 48 x 48 image with the tiny setup's pixel pitch."""
    path = tmp_path / "photo.exr"
    write_exr(path, np.random.default_rng(0).random((48, 48)).astype(np.float32),
              metadata={"pixel_pitch": 0.18})
    return path


@pytest.mark.parametrize("value,message", [
    ("1e-9", "--sensor-distance 1e-09: must exceed the lens focal length, 50 mm"),
    ("50", "--sensor-distance 50: must exceed the lens focal length, 50 mm"),
    ("1e6", "--sensor-distance 1e+06: the 48x48 frame sees no range of elevations for a "
            "cylindrical panorama at that distance"),
])
def test_unwarp_sensor_distance_is_named(capsys, tmp_path, tiny, photo, value, message):
    line = refused(capsys, ["unwarp", photo, "--setup", tiny, "--projection", "cylindrical",
                            "--sensor-distance", value, "--out", tmp_path / "pano.png"])
    assert message in line
    assert "elevation range" not in line


@pytest.mark.parametrize("value", ["inf", "nan", "-1", "0", "1e-300", "1e300"])
@pytest.mark.parametrize("command", ["design-sweep", "dataset"])
def test_lux_must_be_an_illuminance_the_noise_model_takes(capsys, tmp_path, tiny, value,
                                                          command):
    """Refused when read, before any tracing: 1e-300 lux used to warn (NumPy) and fail
    after 30 s of tracing naming ``nsr``; 1e300 overflowed."""
    line = refused(capsys, [command, tiny, "--lux", value, "--out", tmp_path / "d.json"])
    assert line == (f"mitsweep {command}: error: argument --lux: must be an illuminance "
                    f"in [0.0001, 1e+06] lux, got {value}")


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_render_empty_scene_path_is_refused_before_mitsuba(capsys, tmp_path, tiny,
                                                          json_flag):
    line = refused(capsys, ["render", tiny, "--mode", "pinhole", "--out",
                            tmp_path / "o.exr", "--scene", "", *json_flag])
    assert line == "mitsweep: error: --scene: an empty path; give a Mitsuba XML scene file"


def test_a_scene_that_hides_the_mirror_says_100_percent(capsys, tmp_path, tiny):
    scene = tmp_path / "card.xml"
    scene.write_text(BLOCKING_SCENE)
    line = refused(capsys, ["render", tiny, "--mode", "pinhole", "--spp", "1", "--out",
                            tmp_path / "o.exr", "--scene", scene])
    assert "shape 'card' lies between the lens and the mirror (it hides 100 % of the " \
           "probed lens-to-mirror rays)" in line, line


def test_a_scene_with_a_utf8_byte_order_mark_renders(capsys, tmp_path, tiny):
    scene = tmp_path / "bom.xml"
    scene.write_bytes(codecs.BOM_UTF8 + GOOD_SCENE.encode())
    out = tmp_path / "o.exr"
    assert main(["render", str(tiny), "--mode", "pinhole", "--spp", "1", "--out", str(out),
                 "--scene", str(scene)]) == 0, capsys.readouterr().err
    assert out.is_file()


@pytest.mark.parametrize("value", ["\u00b2", *(pytest.param(v, marks=pytest.mark.slow)
                                                for v in ("x8", "8.0", "-16"))])
def test_llvm_vector_width_variable_is_named(tmp_path, tiny, value):
    # a fresh process: the backend (and the width) is chosen once per process
    rc, out, err = run_cli("render", tiny, "--mode", "pinhole", "--spp", "1", "--out",
                           tmp_path / "o.exr", env={"MITSWEEP_LLVM_VECTOR_WIDTH": value,
                                                    "MITSWEEP_BACKEND": "llvm"})
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert lines[0] == (f"mitsweep: error: MITSWEEP_LLVM_VECTOR_WIDTH: must be an integer, "
                        f"'auto' or 'native', got {value!r}") or \
        lines[0].startswith("mitsweep: error: MITSWEEP_LLVM_VECTOR_WIDTH: must be a power "
                            "of two"), lines
    assert out == ""
