"""Packaging facts users rely on: one version, a licence file matching the declared
licence, and the typing marker shipped with the package."""

from __future__ import annotations

import importlib.metadata
import sys
from pathlib import Path

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
