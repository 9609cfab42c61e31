"""Issue 28, round 3: the probe classes that still lacked a command-line case.

Every case runs the real CLI and asserts the user-error contract of
:func:`cli_contract.refused` (exit status 2, one line, no traceback, no Python warning,
nothing on stdout, or one JSON object with ``--json``) and that nothing was written (the
scratch folder is byte-for-byte as before). Subprocess cases carry a timeout.

Where each probe class of the issue ("Why", 1-11) is tested
-----------------------------------------------------------

==  ==================================  ==========================================================
#   Probe class                         Tests (CLI-level exit 2 + one line + nothing written)
==  ==================================  ==========================================================
1   resumed dataset mixes old/new       test_dataset_integrity (changed XML, include, texture redo
    content                             their items with real renders; a render refuses a scene
                                        changed since planning; another spelling of the setup
                                        resumes)
2   tracebacks instead of one line      test_png_fuzz (gAMA, iCCP, fuzzed PNGs), test_memory_gate
                                        (20000² PNG, unwarp --size, MITSWEEP_MAX_MEMORY_GB=1e300),
                                        test_bank_validation (radii <= 0, deep header),
                                        test_network_waits (HTTP scheduler); here: motion files
                                        with a 400-digit number or a provenance nested 100 000
                                        deep
3   hangs (FIFO, silent scheduler)      test_regular_files (FIFO as setup, --scene, --motion,
                                        include, texture, under --scenes-from; timeout),
                                        test_network_waits (silent listener, HTTP; bounded time)
4   memory cap not applied              test_memory_gate (photos, inflating PNG data, panoramas,
                                        peaks measured in a child), test_bank_validation (zip
                                        bomb)
5   cache outside named places / fatal  test_cache_optional (switch words, empty HOME, file-shaped
                                        and read-only caches, a bare word is one line)
6   writes through symlinked folders    test_dataset_integrity (dataset, shard and item folders)
7   --json stdout not JSON              test_stdout_clean (Mitsuba's warning on stderr), here: a
                                        refused --json command prints one JSON object
8   warning noise, multi-line refusals  test_memory_gate (95 MP truncated header), test_png_fuzz;
                                        here: deconvolve, calibrate and unwarp refuse an 8-bit,
                                        clipped PNG or JPEG in one line (its quality warnings only
                                        once it is used); a motion interval of 1e-300;
                                        test_messages: design-sweep / dataset --lux 1e-300 and
                                        1e300 refused when read
9   late refusals                       test_memory_gate (figures --seed, design-sweep
                                        --kernel-size); here: non-UTF-8 output names for every
                                        writing command, and non-ASCII ones under LC_ALL=C with
                                        PYTHONUTF8=0, refused before any work naming the option
10  corrupt banks accepted              test_bank_validation (NaN depths, points, vignetting,
                                        reversed radii, string depths, with deconvolve)
11  unclear messages                    test_messages (--sensor-distance, --lux, --scene '',
                                        'hides 100 %', UTF-8 BOM, MITSWEEP_LLVM_VECTOR_WIDTH),
                                        test_bank_validation (string depths), test_io_camera (EXIF
                                        unit codes)
==  ==================================  ==========================================================

The earlier rounds' corpus is tests/test_bad_input_corpus.py.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_contract import refused
from conftest import run_cli
from PIL import Image
from test_io_write_errors import tiny_setup_toml

from mitsweep.cli.common import UsageError, check_output_name
from mitsweep.io import read_exr, write_exr

#: A byte that is not UTF-8: Python's argv carries it as the surrogate U+DCFF.
NOT_UTF8 = os.fsdecode(b"\xff")


def _tree(root: Path) -> dict:
    """Every file and folder under ``root``: its SHA-256 (files) or None (folders)."""
    return {p.relative_to(root).as_posix():
            hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None
            for p in sorted(root.rglob("*"))}


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A scratch folder with the tiny setup and a 48 x 48 photo (the setup in its
    metadata); the working directory."""
    monkeypatch.chdir(tmp_path)
    tiny_setup_toml(tmp_path)
    write_exr(tmp_path / "photo.exr",
              np.random.default_rng(0).random((48, 48)).astype(np.float32),
              metadata={"pixel_pitch": 0.18})
    return tmp_path


def refused_writing_nothing(capsys, root: Path, argv) -> str:
    before = _tree(root)
    line = refused(capsys, argv)
    assert _tree(root) == before, "a refused command changed the files"
    return line


# -- 9: output names that cannot be written as given, refused before any work -------------

#: (id, option, argv with NAME where the output's name goes). Each command's other
#: arguments are valid, so the output name is the one thing refused.
OUTPUT_NAME_CASES = [
    ("render-out", "--out", ["render", "tiny.toml", "--mode", "pinhole", "--out", "NAME.exr"]),
    ("render-preview", "--preview", ["render", "tiny.toml", "--mode", "pinhole", "--out",
                                     "ok.exr", "--preview", "NAME.png"]),
    ("deconvolve-exr", "--out", ["deconvolve", "photo.exr", "--setup", "tiny.toml", "--out",
                                 "NAME.exr"]),
    ("deconvolve-png", "--out", ["deconvolve", "photo.exr", "--setup", "tiny.toml", "--out",
                                 "NAME.png"]),
    ("unwarp", "--out", ["unwarp", "photo.exr", "--setup", "tiny.toml", "--projection",
                         "cylindrical", "--out", "NAME.exr"]),
    ("design-sweep-out", "--out", ["design-sweep", "tiny.toml", "--out", "NAME.json"]),
    ("design-sweep-plot", "--plot", ["design-sweep", "tiny.toml", "--out", "ok.json",
                                     "--plot", "NAME.png"]),
    ("ipsf-output", "--output", ["ipsf", "tiny.toml", "--radius", "1", "-o", "NAME.exr"]),
    ("ipsf-plot", "--plot", ["ipsf", "tiny.toml", "--radius", "1", "--plot", "NAME.png"]),
    ("ipsf-depths", "--output", ["ipsf", "tiny.toml", "--radius", "1", "--depth", "500",
                                 "--depth", "1000", "-o", "NAME.exr"]),
    ("ipsf-bank", "--output", ["ipsf", "tiny.toml", "--bank", "radial", "-o", "NAME.npz"]),
    ("figures", "--out", ["figures", "--quick", "--setup", "tiny.toml", "--out", "NAME"]),
    ("dataset", "--out", ["dataset", "tiny.toml", "--out", "NAME"]),
    ("calibrate-write", "--write", ["calibrate", "photo.exr", "--setup", "tiny.toml",
                                    "--write", "NAME.toml"]),
    ("capture", "--out", ["capture", "tiny.toml", "--port", "/dev/mitsweep-none", "--out",
                          "NAME.json"]),
    ("sweep-range-plot", "--plot", ["sweep-range", "tiny.toml", "--plot", "NAME.png"]),
    ("table1-plot", "--plot", ["table1", "tiny.toml", "--plot", "NAME.png"]),
    ("demo", "--out", ["demo", "--out", "NAME"]),
]

#: Where a bad byte sits: in the file's own name, or in a folder on its path.
BAD_NAMES = {"name": f"out{NOT_UTF8}", "folder": f"d{NOT_UTF8}/out"}


def _argv(template, name: str) -> list[str]:
    return [a.replace("NAME", name) for a in template]


@pytest.mark.parametrize("where", sorted(BAD_NAMES))
@pytest.mark.parametrize("option,template", [c[1:] for c in OUTPUT_NAME_CASES],
                         ids=[c[0] for c in OUTPUT_NAME_CASES])
def test_a_non_utf8_output_name_is_refused_before_any_work(option, template, where, work,
                                                          capsys):
    if where == "folder":
        (work / f"d{NOT_UTF8}").mkdir()
    line = refused_writing_nothing(capsys, work, _argv(template, BAD_NAMES[where]))
    # the option and the path as the shell shows it, the bad byte as \xff
    assert f"error: {option} " in line and "\\xff" in line and "not valid UTF-8" in line, line


def test_a_refused_output_name_with_json_prints_one_json_object(work, capsys):
    line = refused_writing_nothing(capsys, work, ["render", "tiny.toml", "--mode", "pinhole",
                                                  "--out", f"{NOT_UTF8}.exr", "--json"])
    assert "--out" in line


#: The commands above, under an ASCII file-system encoding (``LC_ALL=C PYTHONUTF8=0``):
#: a non-ASCII name's bytes are not those OpenEXR would write.
ASCII_LOCALE = {"LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0"}
LOCALE_CASES = ["render-out", "deconvolve-exr", "dataset", "sweep-range-plot"]


@pytest.mark.parametrize("case", LOCALE_CASES)
def test_a_non_ascii_output_name_under_an_ascii_locale_is_refused_at_once(case, work):
    template = {c[0]: c[2] for c in OUTPUT_NAME_CASES}[case]
    option = {c[0]: c[1] for c in OUTPUT_NAME_CASES}[case]
    argv = [str(work / a) if a in ("tiny.toml", "photo.exr") else a
            for a in _argv(template, str(work / "été"))]
    before = _tree(work)
    rc, out, err = run_cli(*argv, env=ASCII_LOCALE, timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and out == "", (rc, out, err)
    assert f"error: {option} " in lines[0] and "ascii file system encoding" in lines[0], lines
    assert _tree(work) == before


def test_a_non_utf8_name_from_a_real_argv_is_refused_in_one_line(work):
    """The surrogate comes from the process's own argv (bytes 0xff), not from a test."""
    before = _tree(work)
    rc, out, err = run_cli("render", work / "tiny.toml", "--mode", "pinhole", "--out",
                           work / f"{NOT_UTF8}.exr", timeout=120)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2 and len(lines) == 1 and out == "", (rc, out, err)
    assert "--out" in lines[0] and "\\xff.exr" in lines[0], lines
    assert _tree(work) == before


@pytest.mark.skipif(sys.getfilesystemencoding().lower().replace("-", "") != "utf8",
                    reason="needs a UTF-8 file-system encoding")
@pytest.mark.parametrize("name", ["plain.exr", "été.exr", "日本.exr", "a b.exr"])
def test_what_the_name_check_accepts_openexr_writes_under_that_name(name, tmp_path):
    """The check's rule is OpenEXR's: whatever it accepts, ``write_exr`` writes there."""
    check_output_name(tmp_path / name, "--out")
    write_exr(tmp_path / name, np.ones((2, 3), np.float32))
    assert os.listdir(tmp_path) == [name]
    channels, _ = read_exr(tmp_path / name)
    assert [a.shape for a in channels.values()] == [(2, 3)]


@pytest.mark.parametrize("name,words", [
    (f"{NOT_UTF8}.exr", "not valid UTF-8"),
    (os.fsdecode(b"\xc3\x28.png"), "not valid UTF-8"),       # a broken 2-byte sequence
    (os.fsdecode(b"d\xe9/x.json"), "not valid UTF-8"),        # Latin-1 bytes in a folder
    ("\udcc3\udca9.exr", "non-ASCII name"),   # valid UTF-8 bytes, as an ASCII argv holds them
])
def test_the_name_check_names_the_option_and_the_cause(name, words):
    with pytest.raises(UsageError, match=rf"^--plot .*: .*{words}"):
        check_output_name(name, "--plot")


# -- 8 / 10: a photo's quality warnings only once the command uses it ----------------------

def _photo_8bit(path: Path) -> Path:
    """An 8-bit RGB photo, its top rows clipped at 255 (warned: 8-bit, clipping, JPEG)."""
    a = (np.random.default_rng(1).random((48, 48, 3)) * 200).astype(np.uint8)
    a[:6] = 255
    Image.fromarray(a).save(path, quality=92) if path.suffix == ".jpg" else \
        Image.fromarray(a).save(path)
    return path


#: Refusals that come after the photo is read: each must be the only line.
PHOTO_REFUSALS = {
    "deconvolve-no-setup": (["deconvolve", "PHOTO", "--out", "o.exr"], "no setup"),
    "deconvolve-not-a-bank": (["deconvolve", "PHOTO", "--bank", "tiny.toml",
                                         "--out", "o.exr"], "not an IPSF bank"),
    "deconvolve-grid-too-fine": (["deconvolve", "PHOTO", "--setup", "tiny.toml",
                                  "--operator", "grid", "--grid", "40", "--out", "o.exr"],
                                 "--grid 40"),
    "deconvolve-center-outside": (["deconvolve", "PHOTO", "--setup", "tiny.toml",
                                   "--center", "500", "500", "--out", "o.exr"], "center"),
    "calibrate-no-mirror": (["calibrate", "FLAT", "--setup", "tiny.toml"], "no mirror"),
    "unwarp-sensor-distance": (["unwarp", "PHOTO", "--setup", "tiny.toml", "--projection",
                                "cylindrical", "--sensor-distance", "1e-9", "--out", "u.png"],
                               "--sensor-distance"),
}


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
@pytest.mark.parametrize("case", sorted(PHOTO_REFUSALS))
def test_a_refused_photo_is_one_line_without_its_quality_warnings(case, suffix, work, capsys,
                                                                   caplog):
    # the warnings go through logging, whose handler may hold another stderr than capsys's
    caplog.set_level(logging.WARNING)
    photo = _photo_8bit(work / f"p8{suffix}")
    Image.fromarray(np.full((48, 48, 3), 120, np.uint8)).save(work / f"flat{suffix}")
    template, words = PHOTO_REFUSALS[case]
    argv = [str(photo) if a == "PHOTO" else str(work / f"flat{suffix}") if a == "FLAT"
            else a for a in template]
    line = refused_writing_nothing(capsys, work, argv)
    assert words.lower() in line.lower(), line
    assert not [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]


def test_an_accepted_photo_still_warns_about_its_quality(work, capsys, caplog):
    """The other side: deconvolve goes on with the 8-bit photo, so its warnings are
    logged (once)."""
    photo = _photo_8bit(work / "p8.png")
    caplog.set_level(logging.WARNING)
    from mitsweep.cli.main import main

    assert main(["deconvolve", str(photo), "--setup", "tiny.toml", "--out", "o.exr"]) == 0
    said = [r.getMessage() for r in caplog.records if str(photo) in r.getMessage()]
    assert any("8-bit" in s for s in said), said
    assert len(said) == len(set(said)), said


# -- 2 / 8: motion files that still end in a traceback or a NumPy warning ------------------

GOOD_MOTION = {"format": "mitsweep-motion-profile", "version": 1, "times": [0.0, 1.0],
               "sensor_distances_mm": [57.0, 58.0], "exposure_s": 0.5, "provenance": {}}


def _motion_text(kind: str) -> str:
    if kind == "400-digit-number":
        return json.dumps(GOOD_MOTION).replace("57.0", "1" + "0" * 400)
    if kind == "provenance-nested-100000":
        deep = "[" * 100_000 + "]" * 100_000
        return json.dumps(GOOD_MOTION).replace('"provenance": {}', f'"provenance": {{"a": {deep}}}')
    assert kind == "interval-1e-300"
    return json.dumps(dict(GOOD_MOTION, times=[0.0, 1e-300, 1.0],
                           sensor_distances_mm=[57.0, 57.5, 58.0]))


@pytest.mark.parametrize("kind", ["400-digit-number", "provenance-nested-100000",
                                  "interval-1e-300"])
@pytest.mark.parametrize("command", ["ipsf", "render"])
def test_a_hostile_motion_file_is_one_line(command, kind, work, capsys):
    (work / "m.json").write_text(_motion_text(kind))
    argv = {"ipsf": ["ipsf", "tiny.toml", "--radius", "1", "--motion", "m.json"],
            "render": ["render", "tiny.toml", "--mode", "sweep", "--motion", "m.json",
                       "--out", "o.exr"]}[command]
    line = refused_writing_nothing(capsys, work, argv)
    assert "m.json" in line, line
