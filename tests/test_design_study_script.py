"""``scripts/design_study.py --measured``: the measured study of a designed sweep against
the linear one, end to end on a tiny problem (64 px, 4 spp, one scene, 8 planes), through
``mitsweep dataset --motion`` and ``mitsweep evaluate``, with its ``--diagnose`` model."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT

from mitsweep.optics.motion_file import load_motion_file

SCRIPT = ROOT / "scripts" / "design_study.py"


def run_script(*args, timeout=600):
    proc = subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)
    return proc.returncode, proc.stdout, proc.stderr


@pytest.mark.slow
def test_measured_study_runs_both_profiles_on_the_same_scene_and_noise(tmp_path):
    rc, out, err = run_script(tmp_path, "--measured", "sphere", "2", "--resolution", "64",
                              "--spp", 4, 4, 4, 4, "--scenes", 1, "--planes", 8,
                              "--rays", 4096, "--diagnose")
    assert rc == 0, err[-3000:]
    data = json.loads((tmp_path / "measured.json").read_text())
    assert data["options"]["light_levels"] == [50.0, 2.0, 0.5]
    (row,) = data["cases"]
    assert (row["setup"], row["lux"], row["scenes"]) == ("sphere", 2.0, 1)
    for which in ("linear", "optimized"):
        r = row[which]
        assert len(r["psnr"]) == 1 and np.isfinite(r["psnr"][0])
        assert len(r["per_radius_psnr"]) == 8
    assert row["paired_db"]["per_scene"][0] == pytest.approx(
        row["optimized"]["psnr"][0] - row["linear"]["psnr"][0], abs=1e-12)
    # each dataset ran its own profile: the linear one (2 knots) and the designed one
    # (a knot per bin edge), over the same span, in every render and in the bank
    lin = load_motion_file(tmp_path / "profiles" / "sphere_linear.json").profile
    opt = load_motion_file(tmp_path / "profiles" / "sphere_2lux.json").profile
    assert lin.times.size == 2 and opt.times.size == 9
    assert (opt.start, opt.end) == (lin.start, lin.end)
    for tag, prof in (("linear", lin), ("opt_2lux", opt)):
        items = json.loads((tmp_path / "datasets" / "sphere" / tag / "manifest.json")
                           .read_text())["items"]
        motions = {k: v["params"]["motion"] for k, v in items.items()
                   if k == "bank.npz" or k.endswith("/sweep.exr")}
        # the calibration scene's sweep (the calibrated weight's) runs the profile too
        assert sorted(motions) == ["bank.npz", "calibration/sweep.exr", "scene_000/sweep.exr"]
        for m in motions.values():
            np.testing.assert_allclose(m["positions_mm"], prof.positions, rtol=0, atol=1e-12)
            np.testing.assert_allclose(m["times"], prof.times, rtol=0, atol=1e-12)
    # the two profiles differ, so their sweeps do (same seed, same scene)
    assert row["optimized"]["sweep_psnr_mean"] != row["linear"]["sweep_psnr_mean"]
    assert "| sphere | 2 |" in (tmp_path / "measured.md").read_text()
    # the diagnosis: its matched model is the design's (the plane bank traced again), and
    # the NSR it deploys is the one the dataset's EDOF images were deconvolved with
    d, pred = row["diagnosis"], row["predicted"]
    for which in ("linear", "optimized"):
        assert d[which]["matched"]["worst_db"] == pytest.approx(
            pred[f"{which}_worst_psnr_db"], abs=0.01)
        assert d[which]["matched"]["mean_db"] == pytest.approx(
            pred[f"{which}_mean_psnr_db"], abs=0.01)
    used = d["nsr_used_per_scene"]
    assert d["nsr_used"] == pytest.approx(np.mean(used["linear"] + used["optimized"]))
    assert d["nsr_used"] >= d["nsr_model"]


@pytest.mark.parametrize("args, message", [
    (["--measured", "cube", "2"], "--measured: setup must be one of"),
    (["--measured", "sphere", "dark"], "--measured: LUX must be a number > 0"),
    (["--all", "--scenes", "0"], "--scenes: need at least 1"),
])
def test_bad_arguments_exit_2_with_one_line(tmp_path, args, message):
    rc, out, err = run_script(tmp_path / "o", *args, timeout=60)
    assert rc == 2
    assert message in err.strip().splitlines()[-1]
    assert not (tmp_path / "o").exists()
