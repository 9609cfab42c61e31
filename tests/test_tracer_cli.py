"""CLI: mitsweep ipsf, mitsweep table1, mitsweep sweep-range --verify (tracer side)."""

import json
from pathlib import Path

import numpy as np
import pytest

from mitsweep.cli.main import main
from mitsweep.io import read_exr
from mitsweep.io.bank import load_bank


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_ipsf_single_to_exr_with_provenance(tmp_path, capsys):
    out = tmp_path / "k.exr"
    res = _json(capsys, ["ipsf", "scenes/sphere.toml", "--radius", "3", "--angle", "90",
                         "--rays", "200000", "-o", str(out), "--plot", str(tmp_path / "k.png"),
                         "--json"])
    assert res["vignetted_fraction"] == 0.0
    assert res["image_uv_mm"][1] == pytest.approx(3.0)
    chans, meta = read_exr(out)
    k = chans["Y"]
    assert k.shape == (31, 31) and k.sum() == pytest.approx(1.0, abs=1e-5)
    assert meta["setup"]["name"] == "sphere" and meta["seed"] == 0
    assert (tmp_path / "k.png").stat().st_size > 0


def test_ipsf_bank_to_npz(tmp_path, capsys):
    out = tmp_path / "bank.npz"
    res = _json(capsys, ["ipsf", "scenes/sphere.toml", "--bank", "radial", "--radii", "5",
                         "--depth", "500", "inf", "--rays", "100000", "-o", str(out), "--json"])
    assert res["shape"] == [2, 5, 31, 31]
    bank = load_bank(out)
    assert np.isinf(bank.depths[1])
    np.testing.assert_allclose(bank.kernels.sum(axis=(2, 3)), 1.0, atol=1e-5)


@pytest.mark.parametrize("suffix", [".exr", ".npz"])
def test_ipsf_several_depths_for_one_point_write_one_kernel_per_depth(tmp_path, capsys,
                                                                      suffix):
    """--depth 500 inf at one point: two IPSFs, each file named for its depth, each the
    kernel a one-depth run traces (same seed: identical, the traces are independent)."""
    out = tmp_path / f"k{suffix}"
    common = ["ipsf", "scenes/sphere.toml", "--radius", "3", "--rays", "50000",
              "--kernel-size", "15"]
    res = _json(capsys, [*common, "--depth", "500", "inf", "-o", str(out),
                         "--plot", str(tmp_path / "k.png"), "--json"])
    assert res["depths_mm"] == [500.0, "inf"] and res["image_uv_mm"] == [3.0, 0.0]
    names = [(f"k_l500mm{suffix}", "k_l500mm.png"), (f"k_linf{suffix}", "k_linf.png")]
    assert [(Path(e["output"]).name, Path(e["plot"]).name) for e in res["ipsfs"]] == names
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(sum(names, ()))

    def kernel(path):
        return read_exr(path)[0]["Y"] if suffix == ".exr" else load_bank(path).kernels[0, 0]

    for entry, depth in zip(res["ipsfs"], ("500", "inf")):
        one = tmp_path / "one" / f"k{suffix}"
        one.parent.mkdir(exist_ok=True)
        single = _json(capsys, [*common, "--depth", depth, "-o", str(one), "--json"])
        assert single["depth_mm"] == entry["depth_mm"]
        np.testing.assert_array_equal(kernel(entry["output"]), kernel(one))
    # the two depths differ (a focal sweep's IPSF is nearly, not exactly, depth-invariant)
    k500, kinf = (kernel(e["output"]) for e in res["ipsfs"])
    assert np.abs(k500 - kinf).sum() > 0


def test_ipsf_several_depths_print_one_block_per_depth(capsys):
    assert main(["ipsf", "scenes/sphere.toml", "--rays", "20000", "--kernel-size", "15",
                 "--depth", "500", "2000"]) == 0
    text = capsys.readouterr().out
    assert "-- depth 500 mm" in text and "-- depth 2000 mm" in text
    assert text.index("-- depth 500 mm") < text.index("-- depth 2000 mm")


def test_ipsf_psf_at_one_sensor_distance(capsys):
    res = _json(capsys, ["ipsf", "scenes/paraboloid.toml", "--point", "1", "0.5",
                         "--sensor-distance", "58.2", "--rays", "100000", "--json"])
    assert res["sensor_distance_mm"] == 58.2


@pytest.mark.parametrize("argv,match", [
    (["--point", "60", "0"], "outside the mirror"),
    (["--kernel-size", "30"], "odd"),
    (["--bank", "radial", "--point", "1", "0"], "drop --point"),
    (["--depth", "500", "900", "500"], "give each depth once"),
    (["-o", "x.txt"], "must end in"),
])
def test_ipsf_bad_input_is_one_line_and_status_2(capsys, argv, match):
    assert main(["ipsf", "scenes/sphere.toml", "--rays", "1000", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert match in err and "\n" not in err


def test_ipsf_radial_bank_of_tilted_mirror_is_refused(capsys):
    assert main(["ipsf", "scenes/paraboloid_tilted.toml", "--bank", "radial",
                 "--rays", "1000"]) == 2
    assert "grid" in capsys.readouterr().err


def test_table1_json_has_rows_and_conventional(capsys):
    res = _json(capsys, ["table1", "scenes/sphere.toml", "--ranges", "339:348", "339:374",
                         "--radii", "3", "--rays", "100000", "--json"])
    assert [r["focus_max_mm"] for r in res["rows"]] == [348.0, 374.0]
    assert res["conventional"]["v_avg"] > 100 * max(r["v_avg"] for r in res["rows"])


def test_sweep_range_verify_adds_traced_range(capsys):
    res = _json(capsys, ["sweep-range", "scenes/sphere.toml", "--verify", "--json"])
    # Same field and depths as the analytic range; see test_tracer_focus for the bound.
    assert res["traced_focus_min_mm"] == pytest.approx(res["focus_min_mm"], abs=0.05)
    assert res["traced_focus_max_mm"] == pytest.approx(res["focus_max_mm"], abs=0.05)


def test_ipsf_refusal_with_json_is_a_json_object(capsys):
    from cli_contract import refused

    line = refused(capsys, ["ipsf", "scenes/sphere.toml", "--depth", "500", "500", "--json"])
    assert "give each depth once" in line
