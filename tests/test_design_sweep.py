"""mitsweep design-sweep: plane banks against the tracer, the objective and its bound,
the optimiser and its certificate, the command line and its refusals."""

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mitsweep.cli.main import main
from mitsweep.config import load_setup
from mitsweep.deconv import paper_fig10_settings
from mitsweep.design import (StageLimits, brute_force, certified_lower_bound, local_optimum,
                             plane_bank, plane_psfs, wiener_model)
from mitsweep.design.optimize import stage_feasible
from mitsweep.optics import optimal_sweep_range
from mitsweep.optics.motion import MotionProfile
from mitsweep.optics.motion_file import check_motion_file, load_motion_file, save_motion_file
from mitsweep.tracer import integrated_psf

SCENES = Path(__file__).resolve().parents[1] / "scenes"
PARABOLOID = SCENES / "paraboloid.toml"


@pytest.fixture(scope="module")
def setup():
    return load_setup(PARABOLOID)


@pytest.fixture(scope="module")
def sweep(setup):
    return optimal_sweep_range(setup)


def _profile(tau, edges):
    times = np.concatenate([[0.0], np.cumsum(tau)])
    times[-1] = 1.0
    return MotionProfile.tabulated(times, edges)


def test_plane_bank_sums_to_the_tracers_ipsf_for_uniform_and_shaped_sweeps(setup, sweep):
    """Σ τ_k P_k is the IPSF the tracer deposits for the motion with knots at the bin edges.

    Measured (paraboloid, r = 3 mm and the centre, 16 bins × 4 sub-planes, 2^16 rays):
    L1 to a 2^20-ray exact IPSF of 2e-4 .. 4e-4, while the shaped profile moves the
    IPSF by 0.04 in L1. Tolerance: a tenth of that shift, and 5x the measured error.
    """
    edges = np.linspace(sweep.sensor_start, sweep.sensor_end, 17)
    i_ref = 0.5 * (sweep.sensor_start + sweep.sensor_end)
    P = plane_psfs(setup, 3.0, 0.0, 1000.0, edges, reference_sensor_distance=i_ref,
                   rays=1 << 16, seed=0)
    tau = np.random.default_rng(1).random(16) + 0.3
    tau /= tau.sum()
    ref_lin, _ = integrated_psf(setup, 3.0, 0.0, 1000.0, rays=1 << 20, seed=5)
    ref_tab, info = integrated_psf(setup, 3.0, 0.0, 1000.0, rays=1 << 20, seed=5,
                                   motion=_profile(tau, edges))
    assert info["reference_sensor_distance_mm"] == pytest.approx(i_ref, abs=1e-12)
    shift = np.abs(ref_lin - ref_tab).sum()
    assert shift > 0.02  # the shaped profile does change the IPSF
    for weights, ref in ((np.full(16, 1 / 16), ref_lin), (tau, ref_tab)):
        mine = np.tensordot(weights, P, axes=1)
        mine = mine / mine.sum()
        err = np.abs(mine - ref).sum()
        assert err < min(0.1 * shift, 2e-3)


@pytest.fixture(scope="module")
def small(setup, sweep):
    """A real problem, small: 2 radii x 2 depths x 16 bins at 0.5 lux."""
    edges = np.linspace(sweep.sensor_start, sweep.sensor_end, 17)
    i_ref = 0.5 * (sweep.sensor_start + sweep.sensor_end)
    bank = plane_bank(setup, [(0.0, 0.0), (3.5, 0.0)], [300.0, 10000.0], edges,
                      reference_sensor_distance=i_ref, rays=1 << 14)
    noise = paper_fig10_settings(0.0064, 0.5)["sweep"]
    model = wiener_model(bank.kernels, noise, n_fft=32, n_px=512)
    limits = StageLimits(exposure_s=sweep.exposure_s, max_velocity=setup.rig.max_velocity,
                         acceleration=setup.rig.acceleration)
    return bank, model, limits


def test_mse_gradient_matches_finite_differences(small):
    _, model, _ = small
    tau = np.random.default_rng(2).random(16) + 0.5
    tau /= tau.sum()
    value, grad = model.mse_and_grad(tau)
    bvalue, bgrad = model.bound_and_grad(tau)
    for k in (0, 7, 15):
        e = np.zeros(16)
        e[k] = 1e-6
        # central differences: error O(h²) ~ 1e-12 relative to values ~1e-2, plus float64
        # cancellation in the difference; measured: at most 1.7e-6 relative for the MSE,
        # 6.9e-10 for the bound (rtol 1e-5: 6x the first)
        np.testing.assert_allclose((model.mse(tau + e) - model.mse(tau - e)) / 2e-6,
                                   grad[:, k], rtol=1e-5)
        fd = (model.bound_and_grad(tau + e)[0] - model.bound_and_grad(tau - e)[0]) / 2e-6
        np.testing.assert_allclose(fd, bgrad[:, k], rtol=1e-5)
    np.testing.assert_allclose(value, model.mse(tau), rtol=1e-12)


def test_convex_bound_is_below_the_mse_and_convex(small):
    _, model, _ = small
    rng = np.random.default_rng(3)
    taus = rng.dirichlet(np.ones(16), size=200)
    for t in taus:
        assert np.all(model.bound_and_grad(t)[0] <= model.mse(t) * (1 + 1e-12))
    for a, b in zip(taus[:100], taus[100:]):
        la, lb = model.bound_and_grad(a)[0], model.bound_and_grad(b)[0]
        lm = model.bound_and_grad(0.5 * (a + b))[0]
        assert np.all(lm <= 0.5 * (la + lb) * (1 + 1e-12))


@pytest.mark.parametrize("objective, weighted", [("worst", False), ("mean", False),
                                                  ("mean", True)])
def test_optimiser_improves_on_uniform_feasibly_and_is_certified(small, objective, weighted):
    bank, model, limits = small
    widths = bank.widths
    uniform = np.full(16, 1 / 16)
    # weighted: a mean that leans on some kernels (as the image's area weights do)
    w = np.linspace(1.0, 5.0, model.n_kernels) if weighted else None
    if objective == "worst":
        reduce = np.max
    else:
        reduce = np.mean if w is None else (lambda m: float(m @ w) / w.sum())
    sol = local_optimum(model, widths, limits, objective=objective, weights=w)
    again = local_optimum(model, widths, limits, objective=objective, weights=w)
    np.testing.assert_array_equal(sol.tau, again.tau)  # deterministic
    assert stage_feasible(sol.tau, widths, limits)
    assert sol.value <= reduce(model.mse(uniform))
    bound, _ = certified_lower_bound(model, widths, limits, objective=objective, weights=w)
    assert bound <= sol.value
    # the written profile is one the stage can follow, through the file's own check
    assert sol.value == pytest.approx(reduce(model.mse(sol.tau)), rel=1e-12)


def test_brute_force_agrees_with_the_optimiser_on_a_small_problem(small):
    bank, _, limits = small
    coarse = bank.coarsened(4)
    noise = paper_fig10_settings(0.0064, 0.5)["sweep"]
    model = wiener_model(coarse.kernels, noise, n_fft=32, n_px=512)
    res = brute_force(model, coarse.widths, limits, steps=12)
    assert res["feasible_points"] > 10
    assert res["agrees"] and res["same_optimum"]
    assert res["lower_bound"] <= res["local_value"] <= res["lattice_best"] * (1 + 1e-9)


def test_brute_force_agrees_with_the_optimiser_on_a_weighted_mean(small):
    bank, _, limits = small
    coarse = bank.coarsened(4)
    noise = paper_fig10_settings(0.0064, 0.5)["sweep"]
    model = wiener_model(coarse.kernels, noise, n_fft=32, n_px=512)
    w = np.arange(1.0, model.n_kernels + 1.0) ** 2
    res = brute_force(model, coarse.widths, limits, steps=12, objective="mean", weights=w)
    assert res["agrees"] and res["same_optimum"]
    assert res["lower_bound"] <= res["local_value"] <= res["lattice_best"] * (1 + 1e-9)
    with pytest.raises(ValueError, match="weights: must be"):
        local_optimum(model, coarse.widths, limits, objective="mean", weights=-w)


def test_image_area_weights_are_the_annuli_each_radius_stands_for():
    from mitsweep.design import image_area_weights

    r = np.linspace(0.0, 4.0, 5)                      # cells 0-.5, .5-1.5, ..., 3.5-4
    w = image_area_weights(np.stack([r, 0 * r], axis=1), symmetric=True)
    area = np.array([0.25, 1.5 ** 2 - 0.25, 2.5 ** 2 - 1.5 ** 2, 3.5 ** 2 - 2.5 ** 2,
                     16 - 3.5 ** 2])
    np.testing.assert_allclose(w, area / 16.0)
    grid = np.random.default_rng(0).random((7, 2))
    np.testing.assert_allclose(image_area_weights(grid, symmetric=False), np.full(7, 1 / 7))


def test_uniform_is_the_only_design_when_the_stage_is_at_its_limit(small, sweep):
    """With rig.max_velocity equal to the sweep's velocity every bin is at the bound:
    the uniform sweep is the optimum, whatever the error (why a uniform optimum occurs)."""
    bank, model, _ = small
    span = abs(sweep.sensor_end - sweep.sensor_start)
    limits = StageLimits(exposure_s=sweep.exposure_s, max_velocity=span / sweep.exposure_s,
                         acceleration=10.0)
    sol = local_optimum(model, bank.widths, limits)
    np.testing.assert_allclose(sol.tau, np.full(16, 1 / 16), rtol=1e-9)


def _cli(args, capsys):
    rc = main(args)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_design_sweep_command_writes_a_profile_that_ipsf_runs(tmp_path, capsys, setup, sweep):
    out = tmp_path / "profile.json"
    rc, stdout, err = _cli(["design-sweep", str(PARABOLOID), "--lux", "2", "--planes", "8",
                            "--radii", "2", "--depth", "300", "10000", "--rays", "4096",
                            "--brute-force-steps", "6", "--out", str(out),
                            "--plot", str(tmp_path / "d.png"), "--json"], capsys)
    assert rc == 0, err
    rep = json.loads(stdout)
    for key in ("linear_worst_mse", "optimized_worst_mse", "linear_mean_mse",
                "optimized_mean_mse", "linear_v_avg", "optimized_v_avg", "linear_worst_at",
                "optimized_worst_at", "seconds", "certificate"):
        assert key in rep
    assert rep["optimized_worst_mse"] <= rep["linear_worst_mse"]
    c = rep["certificate"]
    assert c["lower_bound"] <= c["objective_value"] == rep["optimized_worst_mse"]
    assert (tmp_path / "d.png").stat().st_size > 0
    mf = check_motion_file(load_motion_file(out), setup)
    assert mf.exposure_s == pytest.approx(sweep.exposure_s)
    assert mf.provenance["generator"] == "mitsweep design-sweep"
    # the tracer revision the plane banks were traced with, in the file and the report
    from mitsweep.tracer.kernel import TRACE_REVISION

    assert mf.provenance["trace_revision"] == rep["trace_revision"] == TRACE_REVISION
    assert mf.profile.span == pytest.approx(
        (min(sweep.sensor_start, sweep.sensor_end), max(sweep.sensor_start, sweep.sensor_end)))
    rc, stdout, err = _cli(["ipsf", str(PARABOLOID), "--radius", "2", "--rays", "20000",
                            "--motion", str(out), "--json"], capsys)
    assert rc == 0, err
    info = json.loads(stdout)
    assert info["motion"]["kind"] == "tabulated"
    assert info["reference_sensor_distance_mm"] == pytest.approx(mf.profile.midpoint, abs=1e-12)


def _one_line_exit_2(args, capsys, match):
    rc, stdout, err = _cli(args, capsys)
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith("mitsweep: error: ") and match in err, err
    return err


def test_design_sweep_refuses_bad_input_before_tracing(tmp_path, capsys, setup):
    f = setup.lens.focal_length
    base = ["design-sweep", str(PARABOLOID), "--out", str(tmp_path / "p.json")]
    _one_line_exit_2(base + ["--span-mm", str(f - 1), str(f + 1)], capsys, "focal length")
    _one_line_exit_2(base + ["--planes", "4"], capsys, "--planes")
    # 5 mm of travel in the 0.5 s exposure: 10 mm/s against rig.max_velocity = 5 mm/s
    _one_line_exit_2(base + ["--span-mm", "58", "63"], capsys, "rig.max_velocity")
    _one_line_exit_2(["design-sweep", str(PARABOLOID), "--out", str(PARABOLOID)], capsys,
                     "refusing to overwrite an input")
    assert not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("doc, match", [
    ({"times": [], "sensor_distances_mm": []}, "empty table"),
    ({"times": [0, 0.5, 1], "sensor_distances_mm": [57.5, 57.9, 57.6]}, "strictly monotonic"),
    ({"times": [0, 0.5, 1], "sensor_distances_mm": [49.0, 50.5, 51.0]}, "focal length"),
    ({"times": [0, 0.5, 1], "sensor_distances_mm": [57.5, 57.7, 57.9], "exposure_s": 0.01},
     "rig.max_velocity"),
    # 0.1 then 3.9 mm/s, changed within 0.1 s: 38 mm/s² against 10
    ({"times": [0, 0.5, 1], "sensor_distances_mm": [57.5, 57.51, 57.9], "exposure_s": 0.2},
     "rig.acceleration"),
])
def test_ipsf_refuses_a_bad_motion_file_in_one_line(tmp_path, capsys, doc, match):
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"format": "mitsweep-motion-profile", "version": 1, **doc}))
    _one_line_exit_2(["ipsf", str(PARABOLOID), "--motion", str(p), "--rays", "1000"], capsys,
                     match)


def test_ipsf_motion_and_motion_table_exclude_each_other(tmp_path, capsys):
    p = save_motion_file(tmp_path / "m.json", MotionProfile.linear(57.5, 57.9), exposure_s=None,
                         provenance={})
    table = tmp_path / "t.csv"
    table.write_text("0,57.5\n1,57.9\n")
    _one_line_exit_2(["ipsf", str(PARABOLOID), "--motion", str(p), "--motion-table",
                      str(table)], capsys, "give one")


def test_design_sweep_runs_as_a_program(tmp_path):
    """The registered command, in a fresh process: help lists it."""
    r = subprocess.run([sys.executable, "-m", "mitsweep", "design-sweep", "--help"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "--objective" in r.stdout and "--span-mm" in r.stdout


def test_a_wider_span_is_scored_against_the_uniform_sweep_over_the_optimal_range(setup, sweep):
    from mitsweep.design import design_sweep

    noise = paper_fig10_settings(0.0064, 2.0)["sweep"]
    a, b = sweep.sensor_start + 0.05, sweep.sensor_end - 0.05  # the sweep runs a -> b
    d = design_sweep(setup, noise=noise, n_planes=8, span=(a, b), n_radii=2,
                     depths=[300.0, 10000.0], rays=4096, brute_force_steps=0)
    assert d.profile.start == a and d.profile.end == b
    assert d.report["optimal_range_mm"] == [sweep.sensor_start, sweep.sensor_end]
    # the baseline is the uniform sweep over the optimal range (its own bank), not the
    # uniform sweep of the wider span, which the design's feasible set holds instead
    assert d.report["certificate"]["uniform_value"] is None
    wide = wiener_model(d.bank.kernels, noise, n_px=512).mse(d.tau_linear).max()
    assert d.report["linear_worst_mse"] != pytest.approx(float(wide), rel=1e-3)
    assert d.report["optimized_worst_mse"] <= float(wide)
