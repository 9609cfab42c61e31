"""The design's objective as the pipeline restores (issue 27, item 4): every depth
deconvolved with the 500-mm kernels and the deployed NSR. Checked against the matched
(MMSE) restoration it must never beat, its own gradient, and the linear fallback."""

from pathlib import Path

import numpy as np
import pytest

from mitsweep.config import load_setup
from mitsweep.deconv import paper_fig10_settings
from mitsweep.design.objective import deployed_wiener_model, wiener_model

ROOT = Path(__file__).resolve().parents[1]
NOISE = paper_fig10_settings(0.0064, 2.0)["sweep"]


@pytest.fixture(scope="module")
def kernels():
    """Random bin kernels (3 depths, 2 points, 6 bins, 7 px), unit sum."""
    rng = np.random.default_rng(0)
    k = rng.random((3, 2, 6, 7, 7)) ** 4
    return k / k.sum(axis=(-2, -1), keepdims=True)


def test_deployed_error_is_never_below_the_matched_wiener_error(kernels):
    """The matched Wiener filter is the MMSE linear estimate for the model's signal and
    noise, so restoring a depth with another depth's kernel can only add error; at the
    deployed depth (500 mm here) the two are the same filter."""
    depths = [300.0, 500.0, 2000.0]
    dep = deployed_wiener_model(kernels, depths, NOISE, n_fft=16, n_px=256)
    mat = wiener_model(kernels, NOISE, n_fft=16, n_px=256)
    rng = np.random.default_rng(1)
    taus = rng.dirichlet(np.ones(6), size=20)
    d, m = dep.mse(taus), mat.mse(taus)                     # (20, 6): depth-major
    np.testing.assert_allclose(d[:, 2:4], m[:, 2:4], rtol=1e-12)
    assert np.all(d >= m * (1 - 1e-12))
    assert np.all(d[:, [0, 1, 4, 5]] > m[:, [0, 1, 4, 5]])


@pytest.mark.parametrize("deploy_nsr", [None, 0.01])
def test_deployed_gradient_matches_finite_differences(kernels, deploy_nsr):
    dep = deployed_wiener_model(kernels, [300.0, 500.0, 2000.0], NOISE, n_fft=16, n_px=256,
                                deploy_nsr=deploy_nsr)
    tau = np.random.default_rng(2).dirichlet(np.ones(6))
    value, grad = dep.mse_and_grad(tau)
    np.testing.assert_allclose(value, dep.mse(tau), rtol=1e-12)
    h = 1e-6
    num = np.stack([(dep.mse(tau + h * e) - dep.mse(tau - h * e)) / (2 * h)
                    for e in np.eye(6)], axis=1)
    np.testing.assert_allclose(grad, num, rtol=1e-6, atol=1e-9 * np.abs(num).max())


def test_a_deployed_design_beats_linear_under_its_model_or_returns_linear():
    from mitsweep.design import design_sweep

    setup = load_setup(ROOT / "scenes" / "paraboloid.toml")
    d = design_sweep(setup, noise=NOISE, n_planes=8, n_radii=2, depths=[300.0, 500.0, 10000.0],
                     rays=4096, restoration="deployed",
                     objective="mean", deploy_nsr=0.01)
    r = d.report
    assert r["restoration"] == "deployed" and r["deploy"] == {"depth_mm": 500.0, "nsr": 0.01}
    assert r["certificate"]["lower_bound"] is None
    if r["returns_linear"]:
        np.testing.assert_allclose(d.tau, d.tau_linear)
        assert "linear sweep" in r["certificate"]["says"]
    else:
        assert r["optimized_image_mean_mse"] < r["linear_image_mean_mse"]
    # the predictions are the deployed model's: recomputed from the design's bank
    dep = deployed_wiener_model(d.bank.kernels, d.bank.depths, NOISE, deploy_nsr=0.01,
                                n_px=float(np.sqrt(np.prod(setup.sensor.resolution))))
    assert r["linear_mean_mse"] == pytest.approx(float(dep.mse(d.tau_linear).mean()),
                                                 rel=1e-9)
    # the mean minimised is over the image, to the rim's image beyond the FOV (centre,
    # FOV's edge, then radii at the same spacing to the rim), each radius weighted by the
    # annulus it stands for
    rad = np.hypot(*d.points_uv.T)
    assert len(rad) >= 3 and rad[-1] > rad[1] and np.all(np.diff(rad) > 0)
    mid = (rad[1:] + rad[:-1]) / 2
    area = np.diff(np.concatenate([[0.0], mid, [rad[-1]]]) ** 2)
    assert r["point_weights"] == pytest.approx(area / rad[-1] ** 2, rel=1e-9)
    w = np.tile(r["point_weights"], 3) / 3
    assert r["linear_image_mean_mse"] == pytest.approx(float(dep.mse(d.tau_linear) @ w),
                                                       rel=1e-9)
    with pytest.raises(Exception, match="restoration: must be one of"):
        design_sweep(setup, noise=NOISE, n_planes=8, restoration="oracle", bank=d.bank)
