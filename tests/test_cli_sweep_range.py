"""``mitsweep sweep-range``: output, plot, and one-line errors with exit status 2."""

import json

import pytest

from cli_contract import run_main
from conftest import run_cli

JSON_KEYS = {"focus_min_mm", "focus_max_mm", "sensor_start_mm", "sensor_end_mm",
             "translation_mm", "exposure_s", "rho_max_mm"}


def test_json_output_has_the_documented_keys(scenes_dir):
    rc, out, err = run_cli("sweep-range", scenes_dir / "sphere.toml", "--json")
    assert rc == 0, err
    data = json.loads(out)
    assert JSON_KEYS <= set(data)
    assert 338.0 <= data["focus_min_mm"] <= 340.0 and 363.0 <= data["focus_max_mm"] <= 365.0


def test_fov_and_depth_overrides(scenes_dir, capsys):
    rc, out, _ = run_main(capsys, "sweep-range", scenes_dir / "sphere.toml", "--json",
                         "--fov", "180", "--depth", "500", "inf")
    assert rc == 0
    data = json.loads(out)
    assert data["fov_deg"] == 180.0 and data["depth_max_mm"] == "inf"


def test_plot_is_written(scenes_dir, tmp_path, capsys):
    png = tmp_path / "fig6.png"
    rc, _, err = run_main(capsys, "sweep-range", scenes_dir / "paraboloid_tilted.toml",
                          "--plot", png)
    assert rc == 0, err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _write(tmp_path, text):
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


GOOD = """
[mirror]
kind = "sphere"
radius = 25.0
center_distance = 352.0
[lens]
focal_length = 50.0
f_number = {fnum}
[sweep]
fov_deg = {fov}
depth_min = {dmin}
depth_max = 10000.0
"""


@pytest.mark.parametrize("fmt,args,message", [
    (dict(fnum=2.8, fov=355, dmin=300), [], "the largest FOV it gives is 351.85"),
    (dict(fnum=0, fov=237, dmin=300), [], "lens.f_number: must be > 0"),
    (dict(fnum=2.8, fov=237, dmin=20000), [], "sweep.depth_min: must be <= sweep.depth_max"),
    (dict(fnum=2.8, fov=237, dmin=300), ["--depth", "900", "100"], "--depth: MIN (900) must be <= MAX"),
    (dict(fnum=2.8, fov=237, dmin=300), ["--fov", "-3"], "--fov: must be > 0"),
])
def test_bad_input_exits_2_with_one_line(tmp_path, fmt, args, message, capsys):
    path = _write(tmp_path, GOOD.format(**fmt))
    rc, out, err = run_main(capsys, "sweep-range", path, *args)
    assert rc == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err


@pytest.mark.parametrize("text,message", [
    ("[mirror\n", "not a valid TOML file"),
    (GOOD.format(fnum=2.8, fov=237, dmin=300).replace("radius = 25.0", "radius = 25.0\nradus = 3"),
     "mirror.radus: unknown key"),
    (GOOD.format(fnum=2.8, fov=237, dmin=300).replace("fov_deg = 237", "# no fov"),
     "sweep.fov_deg: missing"),
    (GOOD.format(fnum=2.8, fov=237, dmin=300).replace("center_distance = 352.0",
                                                      "center_distance = 60.0"),
     "mirror.vertex_distance: must be > lens.focal_length"),
    (GOOD.format(fnum=2.8, fov=237, dmin=300) + "focus_min = 45.0\nfocus_max = 400.0\n",
     "sweep.focus_min: must be > lens.focal_length"),
])
def test_bad_setup_files_exit_2(tmp_path, text, message, capsys):
    rc, _, err = run_main(capsys, "sweep-range", _write(tmp_path, text))
    assert rc == 2 and message in err and "Traceback" not in err


def test_missing_file_exits_2(tmp_path, capsys):
    rc, _, err = run_main(capsys, "sweep-range", tmp_path / "none.toml")
    assert rc == 2 and "no such" in err and "none.toml" in err and "Traceback" not in err


def test_unwritable_plot_path_exits_2(scenes_dir, tmp_path, capsys):
    rc, _, err = run_main(capsys, "sweep-range", scenes_dir / "sphere.toml", "--plot",
                         tmp_path / "no" / "such" / "dir" / "f.png")
    assert rc == 2 and "does not exist" in err and "Traceback" not in err


@pytest.mark.parametrize("args,message", [
    (["--field", "mirror"], "--field: chooses the field of the traced range; give it "
                            "with --verify"),
    (["--verify", "--field", "disc"], "argument --field: invalid choice: 'disc'"),
    (["--verify", "--field", "mirror"], "the lens does not see all of this field"),
])
def test_bad_field_exits_2_with_one_line(scenes_dir, args, message, capsys):
    rc, _, err = run_main(capsys, "sweep-range", scenes_dir / "sphere.toml", *args)
    assert rc == 2 and message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err


def test_plot_onto_the_setup_file_is_refused(scenes_dir, tmp_path, capsys):
    setup = tmp_path / "s.toml"
    setup.write_text((scenes_dir / "sphere.toml").read_text())
    rc, _, err = run_main(capsys, "sweep-range", setup, "--plot", setup)
    assert rc == 2 and "refusing to overwrite an input" in err
    assert setup.read_text() == (scenes_dir / "sphere.toml").read_text()


TRACED_KEYS = {"traced_field", "traced_focus_min_mm", "traced_focus_max_mm",
               "traced_focus_min_at", "traced_focus_max_at", "traced_convergence"}


@pytest.mark.slow
@pytest.mark.parametrize("field,farthest,on_rim", [("mirror", 470.979, True),
                                                  ("fov", 391.409, False)])
def test_verify_reports_the_field_and_where(scenes_dir, field, farthest, on_rim, capsys):
    rc, out, err = run_main(capsys, "sweep-range", scenes_dir / "paraboloid_tilted.toml",
                            "--verify", "--field", field, "--json")
    assert rc == 0, err
    data = json.loads(out)
    assert TRACED_KEYS <= set(data) and data["traced_field"] == field
    # Both reach past the paper's tilt-plane range (362.84-389.52 mm) at 10 m: the whole
    # mirror at its far rim, the 2-D FOV off the tilt plane on its boundary (values
    # measured with `--verify --field`, converged to < 1 µm; 5 µm allows the rounding).
    assert data["traced_focus_min_mm"] == pytest.approx(362.835, abs=0.005)
    assert data["traced_focus_max_mm"] == pytest.approx(farthest, abs=0.005)
    at = data["traced_focus_max_at"]
    assert at["on_boundary"] and at["on_rim"] == on_rim and at["depth_mm"] == 10000.0
    assert len(at["image_uv_mm"]) == 2
    # The keys of earlier versions: the whole 2-D field of a tilted mirror.
    assert data["traced_field_focus_max_mm"] == pytest.approx(470.979, abs=0.005)
    assert data["traced_field_focus_min_mm"] == pytest.approx(362.835, abs=0.005)


@pytest.mark.slow
@pytest.mark.parametrize("scene,lo,hi", [("sphere", 339.00, 364.25),
                                         ("paraboloid", 365.47, 387.11),
                                         ("paraboloid_tilted", 362.84, 389.52)])
def test_verify_default_field_is_the_papers(scenes_dir, scene, lo, hi, capsys):
    rc, out, err = run_main(capsys, "sweep-range", scenes_dir / f"{scene}.toml", "--verify",
                            "--json")
    assert rc == 0, err
    data = json.loads(out)
    assert data["traced_field"] == "plane"
    assert round(data["traced_focus_min_mm"], 2) == lo
    assert round(data["traced_focus_max_mm"], 2) == hi
    assert ("traced_field_focus_max_mm" in data) == (scene == "paraboloid_tilted")
