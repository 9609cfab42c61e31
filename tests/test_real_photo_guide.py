"""docs/guide/real-photo.md runs as written: its Python block, from the repository's
root, finds the real photo's mirror, calibrates it and makes the panorama."""

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from real_corpus import corpus

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guide" / "real-photo.md"


@pytest.mark.slow  # 11-14 s: in CI's slow run (the default run keeps the real photos' own tests)
def test_the_real_photo_guide_runs_and_finds_the_reference_centre(monkeypatch, capsys):
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 1
    monkeypatch.chdir(ROOT)
    scope: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(compile(blocks[0], str(PAGE), "exec"), scope)
    ref = next(e for e in corpus(with_outline=True) if e["name"] == "paraboloid_mei.jpg")
    # the calibrated centre agrees with the independent reference (Canny + RANSAC)
    assert np.abs(np.asarray(scope["cal"].center_px) - ref["centre"]).max() \
        < ref["tolerance_px"]
    assert "centre row" in capsys.readouterr().out
    pano, seen = scope["panorama"], scope["seen"]
    assert np.all(np.isfinite(pano)) and seen.mean() > 0.9
    assert scope["pmap"].up == "away"
