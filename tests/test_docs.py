"""The documentation site (docs/, built by scripts/docs.sh): it builds with warnings as
errors, its API reference covers every public package, and its gallery shows every
figure in docs/images."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: The public packages and modules the API reference must document.
PUBLIC = ["mitsweep.config", "mitsweep.optics", "mitsweep.photo", "mitsweep.tracer",
          "mitsweep.render", "mitsweep.deconv", "mitsweep.design", "mitsweep.pipeline",
          "mitsweep.rig", "mitsweep.io", "mitsweep.backend", "mitsweep.datasets"]


def test_api_reference_lists_every_public_package():
    listed = set(re.findall(r"^\s+generated/(mitsweep(?:\.\w+)+)\s*$", (DOCS / "api" / "index.rst").read_text(),
                            re.M))
    assert not set(PUBLIC) - listed, f"missing from docs/api/index.rst: {set(PUBLIC) - listed}"


def test_gallery_shows_every_picture():
    gallery = (DOCS / "gallery.md").read_text()
    pictures = sorted(DOCS.glob("images/figures/*.png")) + sorted(DOCS.glob("images/procedural_*.png"))
    assert pictures, "docs/images holds no pictures"
    missing = [p.relative_to(DOCS).as_posix() for p in pictures
               if p.relative_to(DOCS).as_posix() not in gallery]
    assert not missing, f"not in docs/gallery.md: {missing}"


def test_every_page_is_in_a_toctree():
    index = (DOCS / "index.md").read_text()
    pages = [p.relative_to(DOCS).with_suffix("").as_posix()
             for p in sorted(DOCS.rglob("*.md")) if "_build" not in p.parts]
    pages = [p for p in pages if p != "index"]
    missing = [p for p in pages if not re.search(rf"^{re.escape(p)}$", index, re.M)]
    assert not missing, f"pages in no toctree of docs/index.md: {missing}"


@pytest.mark.slow
def test_site_builds_without_warnings(tmp_path):
    """``sphinx-build -W --keep-going`` (what scripts/docs.sh runs) into a temporary
    directory: every docstring autodoc imports renders, every page and image resolves."""
    out = tmp_path / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html",
                           "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=1200)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-6000:]
    assert "build succeeded" in log, log[-6000:]
    for page in ["index", "getting-started", "design", "benchmarks", "gallery", "api/index",
                 *(f"guide/{g}" for g in ("design", "analyse", "render", "datasets", "restore",
                                          "capture", "real-photo", "train", "budget"))]:
        assert (out / f"{page}.html").is_file(), page
    # The API reference: a page per public package, and one per module under it, with
    # the numpydoc sections rendered (a Parameters field list, not raw text).
    for name in PUBLIC:
        assert (out / "api" / "generated" / f"{name}.html").is_file(), name
    ipsf = (out / "api" / "generated" / "mitsweep.tracer.ipsf.html").read_text()
    assert 'id="mitsweep.tracer.ipsf.integrated_psf"' in ipsf
    assert "Parameters" in ipsf and "<dl class=\"field-list" in ipsf
    # The gallery's pictures are copied into the site.
    gallery = (out / "gallery.html").read_text()
    for png in sorted(DOCS.glob("images/figures/*.png")):
        assert png.name in gallery, png.name
        assert (out / "_images" / png.name).is_file(), png.name
