"""Only regular files are read (issue 28, item 2): a named pipe, device, socket or
directory where mitsweep reads a file is one line and exit status 2, at once, never a
process blocked in ``open`` (in Mitsuba's parser, deaf to SIGTERM). And the XML
pre-scan that finds what a scene loads resolves names as Mitsuba does."""

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mitsweep.io.scene_files import (MAX_INCLUDE_DEPTH, SceneFileError, scene_digests,
                                     scene_files)
from mitsweep.resources import FileTypeError, require_regular_file
from test_dataset_scenes_check import GOOD
from test_io_write_errors import tiny_setup_toml

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")

#: Seconds a refusal may take: the CLI's start (imports) on a loaded 2-core machine is
#: 2-5 s; a blocked open never returns at all.
PROMPT_S = 60


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


# -- the helper -------------------------------------------------------------------------

def test_regular_files_and_missing_paths_pass(tmp_path):
    f = tmp_path / "a.toml"
    f.write_text("")
    assert require_regular_file(str(f), "setup file") == f
    (tmp_path / "link").symlink_to(f)
    assert require_regular_file(tmp_path / "link", "setup file") == tmp_path / "link"
    # a missing path is the reader's to report, with its own message
    assert require_regular_file(tmp_path / "none", "setup file") == tmp_path / "none"


def test_pipes_devices_sockets_and_folders_are_refused_by_kind(tmp_path):
    sock = tmp_path / "s.sock"
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(sock))
    (tmp_path / "to_pipe").symlink_to(_fifo(tmp_path / "p"))
    try:
        for path, kind in [(tmp_path / "p", "a named pipe (FIFO)"),
                           (tmp_path / "to_pipe", "a named pipe (FIFO)"),
                           (Path(os.devnull), "a character device"),
                           (sock, "a socket"), (tmp_path, "a directory")]:
            with pytest.raises(FileTypeError) as err:
                require_regular_file(path, "photo")
            assert str(err.value) == (f"{path}: {kind}, not a regular file; the photo must "
                                      f"be a regular file")
    finally:
        server.close()


# -- the XML pre-scan -------------------------------------------------------------------

def _write(path: Path, text: str = "") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_the_scan_resolves_names_as_mitsuba_does(tmp_path, monkeypatch):
    """Includes against the including file's folder first; plugin file names (even in
    an included file) against the scene's folder; ``$`` defaults substituted (the
    first definition wins); ``<path>`` folders searched first; ``<spectrum
    filename>``; missing files left to Mitsuba's message."""
    monkeypatch.chdir(tmp_path)
    top = _write(tmp_path / "s" / "scene.xml", """<scene version="3.0.0">
      <default name="tex" value="tex/a.png"/><default name="tex" value="other.png"/>
      <path value="extra"/>
      <include filename="sub/inc.xml"/>
      <texture type="bitmap"><string name="filename" value="$tex"/></texture>
      <shape type="ply"><string name="filename" value="found_in_path.ply"/></shape>
      <shape type="ply"><string name="filename" value="gone.ply"/></shape>
      <bsdf type="diffuse"><spectrum name="reflectance" filename="refl.spd"/></bsdf>
    </scene>""")
    _write(tmp_path / "s" / "sub" / "inc.xml", """<scene version="3.0.0">
      <include filename="inc2.xml"/>
      <shape type="obj"><string name="filename" value="mesh.obj"/></shape></scene>""")
    names = ["sub/inc2.xml", "mesh.obj", "sub/mesh.obj", "tex/a.png", "other.png",
             "extra/found_in_path.ply", "refl.spd"]
    for name in names:
        _write(tmp_path / "s" / name, '<scene version="3.0.0"/>')
    found = [p.resolve().relative_to(tmp_path / "s").as_posix() for p in scene_files(top)]
    assert found == ["scene.xml", "sub/inc.xml", "sub/inc2.xml", "refl.spd", "mesh.obj",
                     "tex/a.png", "extra/found_in_path.ply"]
    digests = scene_digests(top)
    assert list(digests) == sorted(found)
    # the same files whatever the spelling of the scene's path
    assert scene_digests(Path("s/sub/../scene.xml")) == digests


def test_the_include_depth_is_mitsubas(tmp_path):
    """A chain of includes the scan accepts is one Mitsuba's parser accepts, and one
    file longer fails in both."""
    import mitsuba as mi

    cfg = mi.parser.ParserConfig("scalar_rgb")
    assert MAX_INCLUDE_DEPTH == cfg.max_include_depth
    last = MAX_INCLUDE_DEPTH + 1
    for k in range(last):
        _write(tmp_path / f"{k}.xml",
               f'<scene version="3.0.0"><include filename="{k + 1}.xml"/></scene>')
    _write(tmp_path / f"{last}.xml", '<scene version="3.0.0"/>')
    longest = tmp_path / f"{last - MAX_INCLUDE_DEPTH + 1}.xml"   # MAX_INCLUDE_DEPTH files
    assert len(scene_files(longest)) == MAX_INCLUDE_DEPTH
    mi.parser.parse_file(cfg, str(longest))
    too_long = tmp_path / f"{last - MAX_INCLUDE_DEPTH}.xml"
    with pytest.raises(SceneFileError, match=f"nested deeper than {MAX_INCLUDE_DEPTH}"):
        scene_files(too_long)
    with pytest.raises(Exception, match="recursion depth"):
        mi.parser.parse_file(cfg, str(too_long))


def test_include_cycles_are_one_line(tmp_path):
    _write(tmp_path / "a.xml", '<scene version="3.0.0"><include filename="b.xml"/></scene>')
    _write(tmp_path / "b.xml", '<scene version="3.0.0"><include filename="a.xml"/></scene>')
    with pytest.raises(SceneFileError, match="cycle"):
        scene_files(tmp_path / "a.xml")


def test_the_scan_is_as_lenient_as_mitsubas_parser(tmp_path):
    """pugixml takes ``--`` inside a comment (the shipped example scene has one), which
    Python's XML parser refuses; commented-out tags are not read; a file pugixml
    refuses is still scanned (Mitsuba's own message then names the problem)."""
    _fifo(tmp_path / "pipe.xml")
    top = _write(tmp_path / "a.xml", '<!-- run with --scene-unit m; <include '
                 'filename="pipe.xml"/> --><scene version="3.0.0">'
                 '<include filename="b.xml"/></scene>')
    _write(tmp_path / "b.xml", "<scene version='3.0.0'><shape type='sphere'/")
    assert [p.name for p in scene_files(top)] == ["a.xml", "b.xml"]


# -- the command line: one line, exit 2, at once ----------------------------------------

def _run(args, cwd: Path):
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "mitsweep", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=PROMPT_S,
                          stdin=subprocess.DEVNULL)
    return proc, time.monotonic() - t0


def _scene_with(tmp_path: Path, reference: str) -> Path:
    """A good scene (GOOD's ball and sky) that also includes, or textures from, a pipe."""
    pipe = _fifo(tmp_path / ("inc.xml" if reference == "include" else "tex.png"))
    extra = (f'<include filename="{pipe.name}"/>' if reference == "include" else
             f'<texture type="bitmap" id="t"><string name="filename" value="{pipe.name}"/>'
             f'</texture>')
    return _write(tmp_path / "scene.xml", GOOD.replace("<emitter", extra + "<emitter", 1))


RENDER = ["--mode", "pinhole", "--spp", "1", "--out", "o.exr"]
CASES = {
    "setup": lambda d, s: (["render", _fifo(d / "pipe.toml"), *RENDER], "pipe.toml"),
    "--scene": lambda d, s: (["render", s, "--scene", _fifo(d / "pipe.xml"), *RENDER],
                             "pipe.xml"),
    "--motion": lambda d, s: (["dataset", s, "--out", d / "ds", "--motion",
                               _fifo(d / "pipe.json")], "pipe.json"),
    "include": lambda d, s: (["render", s, "--scene", _scene_with(d, "include"), *RENDER],
                             "inc.xml"),
    "texture": lambda d, s: (["render", s, "--scene", _scene_with(d, "texture"), *RENDER],
                             "tex.png"),
    "--scenes-from scene": lambda d, s: (["dataset", s, "--out", d / "ds", "--scenes-from",
                                          _fifo(_dir(d / "scenes") / "a.xml").parent],
                                         "a.xml"),
    "include under --scenes-from": lambda d, s: (
        ["dataset", s, "--out", d / "ds", "--scenes-from",
         _scene_with(_dir(d / "scenes"), "include").parent], "inc.xml"),
}


def _dir(path: Path) -> Path:
    path.mkdir()
    return path


@pytest.mark.parametrize("case", list(CASES))
def test_a_named_pipe_is_one_line_and_exit_2_at_once(tmp_path, case):
    setup = tiny_setup_toml(tmp_path)
    args, name = CASES[case](tmp_path, setup)
    proc, seconds = _run(args, tmp_path)
    assert proc.returncode == 2, proc.stderr
    err = proc.stderr
    assert err.count("\n") == 1 and err.startswith("mitsweep: error: "), err
    assert f"{name}: a named pipe (FIFO), not a regular file" in err
    assert seconds < PROMPT_S
    assert not (tmp_path / "o.exr").exists() and not (tmp_path / "ds").exists()
