"""``mitsweep dataset --scenes-from``: every scene's view of the mirror is probed when the
dataset is planned, so a scene that would render wrong stops the command before any
work (one line naming the file, exit 2, nothing created), not at its first render."""

import pytest

from mitsweep.cli.main import main
from test_io_write_errors import tiny_setup_toml

# The paper sphere's setup: mirror vertex at the origin, the lens at z = 327 mm.
GOOD = ('<scene version="3.0.0"><emitter type="constant"/><shape type="sphere">'
        '<point name="center" x="1000" y="0" z="0"/><float name="radius" value="200"/>'
        '</shape></scene>\n')
#: A ball on the camera axis halfway between the lens and the mirror.
BLOCKING = ('<scene version="3.0.0"><emitter type="constant"/><shape type="sphere" '
            'id="ball"><point name="center" x="0" y="0" z="160"/>'
            '<float name="radius" value="20"/></shape></scene>\n')
#: A ball behind the mirror, lit by a point light, and no environment.
HIDDEN = ('<scene version="3.0.0"><emitter type="point"><point name="position" x="0" y="0" '
          'z="-900"/></emitter><shape type="sphere"><point name="center" x="0" y="0" '
          'z="-500"/><float name="radius" value="50"/></shape></scene>\n')
#: A ball in view but no light at all.
DARK = ('<scene version="3.0.0"><shape type="sphere"><point name="center" x="1000" y="0" '
        'z="0"/><float name="radius" value="200"/></shape></scene>\n')


def _dataset(tmp_path, capsys, files: dict):
    setup = tiny_setup_toml(tmp_path)
    folder = tmp_path / "scenes"
    folder.mkdir()
    for name, text in files.items():
        (folder / name).write_text(text)
    out = tmp_path / "new" / "ds"
    rc = main(["dataset", str(setup), "--out", str(out), "--scenes-from", str(folder)])
    return rc, capsys.readouterr().err


@pytest.mark.parametrize("bad, message", [
    (BLOCKING, "shape 'ball' lies between the lens and the mirror"),
    (HIDDEN, "nothing in the mirror's view"),
    (DARK, "no emitter"),
])
def test_a_scene_that_would_render_wrong_stops_the_dataset_at_plan_time(tmp_path, capsys,
                                                                         bad, message):
    rc, err = _dataset(tmp_path, capsys, {"a.xml": GOOD, "b.xml": bad})
    assert rc == 2, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert message in err
    line = err.replace(str(tmp_path / "scenes"), "")
    assert "b.xml" in line and "a.xml" not in line     # the bad file is named
    assert not (tmp_path / "new").exists()              # refused before any work


def test_the_plan_time_check_passes_a_good_scene(tmp_path):
    """The same check on its own: a scene with geometry in view passes and says how
    much of the mirror's view meets a shape."""
    from mitsweep.config import load_setup
    from mitsweep.render.user_scene import check_user_scene

    setup = load_setup(tiny_setup_toml(tmp_path))
    path = tmp_path / "good.xml"
    path.write_text(GOOD)
    out = check_user_scene(setup, path)
    assert out["probe_rays"] > 0 and 0 < out["in_view_fraction"] < 1
