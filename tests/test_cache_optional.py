"""The cache is optional: switches parsed as booleans, never a folder derived from an empty
HOME, and an unusable cache costs one warning while the work goes on in memory.

The CLI cases run ``python -m mitsweep`` with real environment values: a render of a
meshed mirror (the paraboloid, which caches its mesh) and a deconvolution that traces
its bank (which caches the bank). Tests run as root, where a read-only mode bit stops no
write: the unusable caches are a file where the folder should be, and a tmpfs mounted
read-only (EROFS stops root too).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitsweep.io import cache as cache_mod
from mitsweep.io import write_exr
from mitsweep.io.cache import (CACHE_OFF, CACHE_ON, CacheSettingError, CacheUnavailable,
                               cache_dir, cache_enabled, cache_root)
from test_io_write_errors import tiny_setup_toml, tmpfs  # noqa: F401 (a fixture)

ROOT = Path(__file__).resolve().parents[1]
CACHE_VARS = ("MITSWEEP_CACHE", "MITSWEEP_CACHE_DIR", "XDG_CACHE_HOME")


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    """No cache variable set, HOME a fresh folder, the working directory a fresh one,
    and no warning remembered from an earlier test."""
    for name in CACHE_VARS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    cache_mod.forget_warnings()
    return work


# -- the settings, in process ------------------------------------------------------------

@pytest.mark.parametrize("value", [*CACHE_ON, "ON", "True", " yes ", ""])
def test_on_switch_means_the_default_folder(clean_env, monkeypatch, tmp_path, value):
    monkeypatch.setenv("MITSWEEP_CACHE", value)
    assert cache_enabled()
    assert cache_root() == tmp_path / "home" / ".cache" / "mitsweep"
    assert cache_dir("meshes") == tmp_path / "home" / ".cache" / "mitsweep" / "meshes"
    assert list(clean_env.iterdir()) == []  # no folder named after the switch


@pytest.mark.parametrize("value", [*CACHE_OFF, "OFF", "False", " no "])
def test_off_switch_writes_nothing(clean_env, monkeypatch, tmp_path, value):
    monkeypatch.setenv("MITSWEEP_CACHE", value)
    assert not cache_enabled()
    assert cache_dir("meshes") is None
    assert list(tmp_path.rglob("*")) == [clean_env]


@pytest.mark.parametrize("value,expected", [
    ("./here", "work/here"), ("nested/cache", "work/nested/cache"), ("ABS", "abs"),
])
def test_a_path_names_the_folder(clean_env, monkeypatch, tmp_path, value, expected):
    monkeypatch.setenv("MITSWEEP_CACHE", str(tmp_path / "abs") if value == "ABS" else value)
    assert cache_root().resolve() == (tmp_path / expected).resolve()


@pytest.mark.parametrize("value", ["maybe", "2", "enabled", "cache"])
def test_a_word_that_is_neither_switch_nor_path_is_refused(clean_env, monkeypatch, value):
    monkeypatch.setenv("MITSWEEP_CACHE", value)
    with pytest.raises(CacheSettingError) as info:
        cache_enabled()
    message = str(info.value)
    assert message.startswith("MITSWEEP_CACHE: must be 1/on/true/yes") and "0/off/false/no" \
        in message and f"got {value!r}" in message
    assert len(message.splitlines()) == 1


@pytest.mark.parametrize("home", ["", "relative/home"])
def test_no_cache_folder_from_an_empty_or_relative_home(clean_env, monkeypatch, caplog,
                                                        home):
    monkeypatch.setenv("HOME", home)
    with pytest.raises(CacheUnavailable, match="HOME is"):
        cache_root()
    assert cache_dir("meshes") is None and cache_dir("banks") is None
    warnings = [r for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and "working without the cache" in warnings[0].getMessage()
    assert list(clean_env.iterdir()) == []


def test_xdg_cache_home_still_serves_an_empty_home(clean_env, monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir("banks") == tmp_path / "xdg" / "mitsweep" / "banks"


# -- the commands, in subprocesses --------------------------------------------------------

#: Dr.Jit's kernel cache, which follows HOME unless DRJIT_CACHE_DIR says otherwise: the
#: commands below keep this process's, so that a HOME of the test's own does not make
#: them compile every kernel afresh (seconds each; mitsweep's cache is what is tested).
DRJIT_CACHE = os.environ.get("DRJIT_CACHE_DIR") or str(Path.home() / ".drjit")


def _mitsweep(args, env: dict, cwd: Path, timeout: float = 300):
    full = {k: v for k, v in os.environ.items() if k not in CACHE_VARS}
    full["DRJIT_CACHE_DIR"] = DRJIT_CACHE
    full.update(env)
    proc = subprocess.run([sys.executable, "-m", "mitsweep", *map(str, args)],
                          capture_output=True, text=True, env=full, cwd=cwd, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.fixture
def paraboloid(tmp_path) -> Path:
    """The paper's paraboloid (a meshed mirror) cut at half its rim (0.22 M triangles
    where the whole one has 1.0 M: Mitsuba loads it in a quarter of the time) and its
    FOV cut to what that rim reaches, on a 48 px frame: renders in a second."""
    text = (ROOT / "scenes" / "paraboloid.toml").read_text()
    for old, new in (("resolution = [512, 512]", "resolution = [48, 48]"),
                     ("pixel_pitch = 0.02", "pixel_pitch = 0.2"),
                     ("rim_radius = 28.25", "rim_radius = 14.0"),
                     ("fov_deg = 167.0", "fov_deg = 100.0")):
        assert old in text, old
        text = text.replace(old, new)
    path = tmp_path / "para.toml"
    path.write_text(text)
    return path


def _render(setup: Path, out: Path) -> list:
    return ["render", setup, "--mode", "pinhole", "--spp", "1", "--out", out, "--json"]


def _deconvolve(tmp_path: Path) -> list:
    photo = tmp_path / "photo.exr"
    write_exr(photo, np.random.default_rng(0).random((48, 48)).astype(np.float32),
              metadata={"pixel_pitch": 0.18})
    return ["deconvolve", photo, "--setup", tiny_setup_toml(tmp_path), "--rays", "20000",
            "--out", tmp_path / "restored.exr", "--json"]


def _one_cache_warning(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("WARNING mitsweep.io.cache: ") and \
        "working without the cache" in lines[0], err
    return lines[0]


@pytest.mark.parametrize("command", [pytest.param("render", marks=pytest.mark.slow),
                                     "deconvolve"])
def test_a_file_in_place_of_the_cache_folder_is_one_warning(tmp_path, paraboloid, command):
    blocker = tmp_path / "cache"
    blocker.write_text("not a folder\n")
    args = _render(paraboloid, tmp_path / "out.exr") if command == "render" else \
        _deconvolve(tmp_path)
    rc, out, err = _mitsweep(args, {"MITSWEEP_CACHE_DIR": str(blocker),
                                    "HOME": str(tmp_path / "home")}, tmp_path)
    assert rc == 0, err
    assert str(blocker) in _one_cache_warning(err) and "Not a directory" in err
    report = json.loads(out)
    if command == "deconvolve":
        assert report["bank"] == "traced (not cached)" and report["bank_traced"]
    assert blocker.read_text() == "not a folder\n"


def test_a_read_only_cache_is_one_warning(tmp_path, paraboloid, tmpfs):  # noqa: F811
    ro = tmpfs(64, "ro")
    rc, out, err = _mitsweep(_render(paraboloid, tmp_path / "out.exr"),
                             {"MITSWEEP_CACHE_DIR": str(ro), "HOME": str(tmp_path / "home")},
                             tmp_path)
    assert rc == 0, err
    assert "Read-only file system" in _one_cache_warning(err)
    json.loads(out)


@pytest.mark.slow   # 4 s; the cache's other switches stay; to keep the default run under 4 minutes on 2 cores
def test_an_empty_home_puts_no_cache_anywhere(tmp_path, paraboloid):
    before = sorted(Path("/.cache/mitsweep").rglob("*")) if Path("/.cache").exists() else []
    # Dr.Jit's kernel cache has its own warning for an empty HOME, and its own variable
    # (set by _mitsweep)
    rc, out, err = _mitsweep(_render(paraboloid, tmp_path / "out.exr"), {"HOME": ""},
                             tmp_path)
    assert rc == 0, err
    assert "HOME is ''" in _one_cache_warning(err)
    after = sorted(Path("/.cache/mitsweep").rglob("*")) if Path("/.cache").exists() else []
    assert after == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.exr", "para.toml"]


def test_switch_on_caches_in_the_default_folder_not_the_working_directory(tmp_path,
                                                                           paraboloid):
    work = tmp_path / "work"
    work.mkdir()
    rc, _, err = _mitsweep(_render(paraboloid, tmp_path / "out.exr"),
                           {"MITSWEEP_CACHE": "1", "XDG_CACHE_HOME": str(tmp_path / "xdg")},
                           work)
    assert rc == 0 and err == "", err
    assert list(work.iterdir()) == []
    assert len(list((tmp_path / "xdg" / "mitsweep" / "meshes").glob("mirror-*.npz"))) == 1


def test_an_unrecognised_switch_is_one_line_naming_the_variable(tmp_path, paraboloid):
    rc, out, err = _mitsweep(_render(paraboloid, tmp_path / "out.exr"),
                             {"MITSWEEP_CACHE": "maybe", "HOME": str(tmp_path / "home")},
                             tmp_path)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1, err
    assert lines[0].startswith("mitsweep: error: MITSWEEP_CACHE: must be 1/on/true/yes")
    assert json.loads(out)["exit_status"] == 2
    assert not (tmp_path / "maybe").exists() and not (tmp_path / "out.exr").exists()
