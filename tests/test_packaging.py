"""Packaging facts users rely on: one version, a licence file matching the declared
licence, the typing marker shipped with the package, and the bundled setups (scenes/)
carried by a wheel and found from an installed package."""

from __future__ import annotations

import importlib.metadata
import json
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import mitsweep

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_version_is_written_once_and_installed_metadata_agrees():
    project = _pyproject()["project"]
    assert "version" not in project and "version" in project["dynamic"]
    attr = _pyproject()["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "mitsweep.__version__"
    assert importlib.metadata.version("mitsweep") == mitsweep.__version__


def test_licence_file_matches_the_declared_licence():
    project = _pyproject()["project"]
    assert project["license"] == "BSD-3-Clause"
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("BSD 3-Clause License")
    assert "Neither the name of the copyright holder" in text   # clause 3 of BSD-3
    assert project["license-files"] == ["LICENSE"]


def test_typing_marker_ships_with_the_package():
    assert (Path(mitsweep.__file__).parent / "py.typed").is_file()
    assert "py.typed" in _pyproject()["tool"]["setuptools"]["package-data"]["mitsweep"]


# -- the bundled setups ship in the wheel -------------------------------------------------

SCENES = ROOT / "scenes"
#: The files of scenes/ a wheel carries (the previews are documentation, not data).
BUNDLED_PATTERNS = ("*.toml", "*.xml")


def _bundled_files() -> list[str]:
    return sorted(p.name for pattern in BUNDLED_PATTERNS for p in SCENES.glob(pattern))


def test_package_list_is_the_source_tree_plus_the_scenes_folder():
    """pyproject.toml lists the packages (one is mapped from outside mitsweep/): the list
    must hold every package of the tree, so none is left out of a wheel."""
    from setuptools import find_packages

    tool = _pyproject()["tool"]["setuptools"]
    assert sorted(tool["packages"]) == sorted(find_packages(str(ROOT), include=["mitsweep*"])
                                              + ["mitsweep.scenes"])
    assert tool["package-dir"] == {"mitsweep.scenes": "scenes"}
    assert tool["package-data"]["mitsweep.scenes"] == list(BUNDLED_PATTERNS)


def test_bundled_setups_resolve_in_the_source_tree():
    from mitsweep.config import load_setup
    from mitsweep.pipeline.figures import PAPER_SETUPS
    from mitsweep.resources import bundled_setup, bundled_setup_names

    names = bundled_setup_names()
    assert set(PAPER_SETUPS) <= set(names)
    for name in names:
        assert load_setup(bundled_setup(name)).mirror is not None
    with pytest.raises(ValueError, match=r"'ellipsoid': not a bundled setup \(bundled: .*sphere"):
        bundled_setup("ellipsoid")


def test_a_setup_argument_may_name_a_bundled_setup(tmp_path, monkeypatch, capsys):
    """``mitsweep sweep-range sphere`` from a folder with no such file: the bundled one."""
    from mitsweep.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main(["sweep-range", "sphere", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["focus_min_mm"] == pytest.approx(339.0, abs=0.5)


@pytest.mark.slow
def test_wheel_carries_the_bundled_setups_and_finds_them_installed(tmp_path):
    """A non-editable install: build the wheel from a copy of the working tree, check its
    file list, install it (no dependencies) into a fresh virtual environment and resolve
    and load every bundled setup there, from the installed package."""
    src = tmp_path / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "previews")
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    for name in ("mitsweep", "scenes"):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", str(src), "-w",
                    str(wheels)], check=True, capture_output=True, timeout=600)
    (wheel,) = wheels.glob("mitsweep-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for f in _bundled_files():
        assert f"mitsweep/scenes/{f}" in names, f
    assert "mitsweep/py.typed" in names
    assert not any(n.startswith("mitsweep/scenes/previews") for n in names)

    env = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(env)], check=True, timeout=300)
    py = env / "bin" / "python"
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", str(wheel)],
                   check=True, capture_output=True, timeout=600)
    # mitsweep.config and mitsweep.resources need the standard library and NumPy (a
    # setup's reach is checked when it is read): NumPy from this environment, appended
    # to the new one's path by a .pth file (no network; the wheel's own mitsweep, in the
    # new site-packages, comes first on the path).
    import numpy

    purelib = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()"
                              "['purelib'])"], check=True, capture_output=True, text=True,
                             timeout=120).stdout.strip()
    (Path(purelib) / "outer_numpy.pth").write_text(str(Path(numpy.__file__).parents[1]) + "\n")
    code = ("import json, mitsweep, mitsweep.resources as r, mitsweep.config as c\n"
            "d = r.bundled_scenes_dir()\n"
            "print(json.dumps({'package': mitsweep.__file__, 'dir': str(d),\n"
            "    'names': r.bundled_setup_names(),\n"
            "    'loaded': [c.load_setup(r.bundled_setup(n)).name\n"
            "               for n in r.bundled_setup_names()]}))\n")
    out = subprocess.run([str(py), "-c", code], check=True, capture_output=True, text=True,
                         cwd=tmp_path, timeout=120).stdout
    found = json.loads(out)
    package = Path(found["package"]).parent
    assert package.is_relative_to(env) and Path(found["dir"]) == package / "scenes"
    assert found["names"] == sorted(Path(f).stem for f in _bundled_files() if f.endswith(".toml"))
    assert len(found["loaded"]) == len(found["names"])
