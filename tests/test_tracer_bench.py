"""mitsweep bench tracer: JSON keys, the peer's presence or absence, agreement with batoid."""

import builtins
import json

import pytest

from mitsweep.cli.main import main


@pytest.mark.slow   # one of the longest default tests (15-40 s on 2 cores): in CI's slow run
def test_bench_tracer_quick_json(capsys):
    assert main(["bench", "tracer", "--quick", "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["rays_per_s"] > 0 and res["rays_landed"] > 0.5 * res["rays"]
    assert res["rays_per_s_exact"] > 0
    # the LLVM vector width, and the cheapest deposit at the native and default widths
    from mitsweep import backend

    assert res["llvm_vector_width"] == backend.llvm_vector_width()
    assert [r["width"] for r in res["llvm_widths"]] == _compared_widths()
    # the deposit strategies side by side: each of the three for both deposits
    from mitsweep.tracer.bench import DEPOSIT_STRATEGIES

    rows = res["deposit_strategies"]
    assert sorted((r["strategy"], r["method"]) for r in rows) == sorted(
        (label, m) for label, _ in DEPOSIT_STRATEGIES
        for m in ("continuous, 1 time/ray", "exact"))
    assert all(r["rays_per_s"] > 0 and r["cpu_seconds_per_ray"] > 0 for r in rows)
    assert res["deposit_copies"] >= 1
    # Error per second: every method judged on the same reference bank; the exact
    # segment deposit reaches L1 <= 1e-3 in every kernel within the ladder (measured at
    # 2^18-2^19 rays per kernel), with no more rays than any other method needs.
    table = res["bank_error_per_second"]
    assert len(table["rows"]) == 4
    exact = table["rows"][0]
    assert exact["label"].startswith("exact") and exact["rays_per_kernel"] is not None
    assert exact["worst_l1"] <= table["target_l1"] == 1e-3
    for row in table["rows"][1:]:
        rays = row["rays_per_kernel"]
        assert rays is None or rays >= exact["rays_per_kernel"]
    assert table["reference_self_l1"] < 0.5 * table["target_l1"]
    if res["peer_rays_per_s"] is None:
        assert "batoid" in res["peer_note"] and res["ratio"] is None
    else:
        assert res["ratio"] == pytest.approx(res["rays_per_s"] / res["peer_rays_per_s"])
        assert res["ratio_exact"] == pytest.approx(res["rays_per_s_exact"]
                                                   / res["peer_rays_per_s"])
        # Where batoid's root is right (rays along the axis) both traces agree to
        # float64 rounding.
        assert res["peer_center_landed_mismatch"] <= 2
        assert res["peer_center_max_slope_diff"] < 1e-9


def test_bench_without_batoid_reports_null(monkeypatch):
    from mitsweep.tracer import bench

    real_import = builtins.__import__

    def fake_import(name, *a, **kw):
        if name.startswith("batoid"):
            raise ImportError("no batoid here")
        return real_import(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    res = bench.batoid_rate(None, None, None, 10, 1)
    assert res["peer_rays_per_s"] is None and "not installed" in res["peer_note"]


def _compared_widths():
    from mitsweep import backend

    if backend.select_backend() != "llvm":
        return []
    widths = sorted({backend.native_llvm_vector_width(), backend.auto_llvm_vector_width(),
                     backend.llvm_vector_width()})
    return widths if len(widths) > 1 else []


def test_width_comparison_times_each_width_and_restores_the_width():
    from mitsweep import backend
    from mitsweep.optics.reference import reference_geometry
    from mitsweep.tracer import bench
    from mitsweep.tracer.bank import field_radius

    setup = bench.bench_setup()
    geometry = reference_geometry(setup)
    backend.select_backend()  # applies MITSWEEP_LLVM_VECTOR_WIDTH
    before = backend.llvm_vector_width()
    rows = bench.llvm_width_comparison(setup, 0.9 * field_radius(setup, geometry), 500.0,
                                       geometry.sweep, 1 << 14, 1)
    assert backend.llvm_vector_width() == before
    assert [r["width"] for r in rows] == _compared_widths()
    for row in rows:
        assert 0 < row["cpu_seconds_per_ray"] < 1e-3 and row["rays_per_s"] > 0
