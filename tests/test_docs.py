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


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """``sphinx-build -W --keep-going`` (what scripts/docs.sh runs) into a temporary
    directory, once for this module's tests: (the html folder, the build's log, its rc)."""
    tmp = tmp_path_factory.mktemp("site")
    out = tmp / "html"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html",
                           "-d", str(tmp / "doctrees"), str(DOCS), str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=1200)
    return out, proc.stdout + proc.stderr, proc.returncode


@pytest.mark.slow
def test_site_builds_without_warnings(site):
    """Every docstring autodoc imports renders, every page and image resolves."""
    out, log, rc = site
    assert rc == 0, log[-6000:]
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


_REF = re.compile(r'<(a|link|img|script)\b[^>]*?\b(href|src)="([^"]*)"', re.I)
_ID = re.compile(r'\b(?:id|name)="([^"]+)"')


def site_links(out: Path):
    """Every page's internal links and their problems: (broken, checked, scripts)."""
    pages = {p: p.read_text(encoding="utf-8", errors="replace") for p in out.rglob("*.html")}
    ids = {p: set(_ID.findall(t)) for p, t in pages.items()}
    broken, checked, scripts = [], 0, []
    for page, text in pages.items():
        for tag, _attr, url in _REF.findall(text):
            if tag.lower() == "script":
                scripts.append(url)
            if re.match(r"^[a-z][a-z0-9+.-]*:", url, re.I) or url.startswith("//"):
                continue          # external (http, mailto, ...): not this site's
            path, _, frag = url.partition("#")
            path = path.split("?", 1)[0]
            target = (page.parent / path).resolve() if path else page
            if target.is_dir():
                target = target / "index.html"
            checked += 1
            where = f"{page.relative_to(out)} -> {url}"
            if not target.exists():
                broken.append(f"{where} (no such file)")
            elif frag and target.suffix == ".html" and frag not in ids.get(target, set()):
                broken.append(f"{where} (no such anchor)")
    return broken, checked, scripts


@pytest.mark.slow
def test_site_has_no_broken_links_and_loads_nothing_from_a_cdn(site):
    """Over the built HTML: every intra-site link and anchor resolves (zero broken), no
    page loads a script from outside the site (math is MathML written at build time),
    and an equation is there as MathML, not as raw TeX."""
    out, log, rc = site
    assert rc == 0, log[-6000:]
    broken, checked, scripts = site_links(out)
    assert checked > 1000, checked
    assert not broken, f"{len(broken)} broken of {checked} links:\n" + "\n".join(broken[:60])
    external = [s for s in scripts if re.match(r"^(https?:)?//", s)]
    assert not external, f"scripts loaded from outside the site: {sorted(set(external))}"
    html = "".join(p.read_text(encoding="utf-8") for p in out.rglob("*.html")
                   if "_modules" not in p.parts)   # source listings show docstrings' TeX
    assert not [s for s in scripts if "mathjax" in s.lower() or "katex" in s.lower()]
    assert "<math " in html and "\\frac" not in html


@pytest.mark.slow
def test_signatures_show_types_and_deprecated_aliases_are_not_listed(site):
    out, _log, _rc = site
    ipsf = (out / "api" / "generated" / "mitsweep.tracer.ipsf.html").read_text()
    sig = ipsf.split('id="mitsweep.tracer.ipsf.integrated_psf"', 1)[1].split("</dt>", 1)[0]
    assert "Setup" in sig and "float" in sig, sig[:2000]
    # the two Placement classes: each signature links the one its module means
    scene = (out / "api" / "generated" / "mitsweep.render.user_scene.html").read_text()
    assert 'href="mitsweep.config.html#mitsweep.config.Placement"' in scene
    assert "optics.placement.Placement" not in scene
    ray = (out / "api" / "generated" / "mitsweep.optics.chief_ray.html").read_text()
    assert 'href="mitsweep.optics.placement.html#mitsweep.optics.placement.Placement"' in ray
    sweep = (out / "api" / "generated" / "mitsweep.optics.sweep.html").read_text()
    assert re.search(r"<strong>focus_min\b", sweep)     # the dataclass's fields, documented
    assert not re.findall(r'id="mitsweep[.\w]*_mm"', sweep), "a deprecated *_mm alias is listed"
    index = (out / "api" / "index.html").read_text()
    assert "Start here" in index
    for name in PUBLIC:
        assert f"{name}.html" in index, name
