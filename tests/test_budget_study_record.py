"""The recorded error budgets of docs/guide/budget.md (scripts/budget_study.py): what the
issue asks them to show, and that each is a budget (its terms add up to the measured
error, per radius too). The table itself is checked against the record by
tests/test_doc_figures.py."""

import json
import math
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RECORD = json.loads((ROOT / "docs" / "reference" / "budget_study.json").read_text())


def test_the_record_holds_the_demos_edof_images_and_the_three_mirrors_at_2_lux():
    names = list(RECORD["budgets"])
    assert any(n.startswith("demo (sphere)") and n.endswith("/edof.exr") for n in names)
    for setup in ("sphere", "paraboloid", "paraboloid_tilted"):
        assert f"{setup} scene_000/edof_2lux.exr" in names
    for b in RECORD["budgets"].values():   # with the second seed: Monte Carlo measured
        assert b["order"][:1] == ["information"] and "monte_carlo" in b["order"]


@pytest.mark.parametrize("name", list(RECORD["budgets"]))
def test_each_recorded_budget_adds_up_to_its_measured_error(name):
    b = RECORD["budgets"][name]
    total, radius = b["total"], b["per_radius"]
    assert math.fsum(total["terms"].values()) == pytest.approx(total["mse"], rel=1e-9)
    assert total["psnr"] == pytest.approx(-10 * math.log10(total["mse"]), abs=1e-9)
    for i, n in enumerate(radius["pixels"]):
        if n:
            parts = math.fsum(v[i] for v in radius["terms"].values())
            assert parts == pytest.approx(radius["mse"][i], rel=1e-9)
    # the radial bins partition the mirror's pixels: their pixel-weighted mean is `all`
    assert sum(radius["pixels"]) == total["pixels"]
    mean = sum(n * m for n, m in zip(radius["pixels"], radius["mse"]) if n) / total["pixels"]
    assert mean == pytest.approx(total["mse"], rel=1e-9)
