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
    assert r["restoration"] == "deployed" and r["deploy"] == {"depth_mm": 500.0, "nsr": 0.01,
                                                         "grid_bank": None}
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


# -- a grid bank's blend of node filters (tilted mirrors) ------------------------------
def test_a_blend_of_a_points_own_filter_is_the_deployed_model(kernels):
    depths = [300.0, 500.0, 2000.0]
    dep = deployed_wiener_model(kernels, depths, NOISE, n_fft=16, n_px=256, deploy_nsr=0.01)
    own = deployed_wiener_model(kernels, depths, NOISE, n_fft=16, n_px=256, deploy_nsr=0.01,
                                blend=(np.array([[0], [1]]), np.ones((2, 1))))
    taus = np.random.default_rng(3).dirichlet(np.ones(6), size=4)
    np.testing.assert_allclose(own.mse(taus), dep.mse(taus), rtol=1e-12)
    for tau in taus:
        np.testing.assert_allclose(own.mse_and_grad(tau)[1], dep.mse_and_grad(tau)[1],
                                   rtol=1e-10, atol=1e-14)


def _blend_mse_by_hand(kernels, tau, index, weight, nsr, n_fft):
    """The blended restoration's MSE of every (depth, point), written out here from the
    kernels: FFT of the τ-weighted IPSF, node filters conj(Q)/(|Q|²+R_f), their blend G,
    error |1 - G K|²/R_t + |G|² summed over the DFT grid (DC out), times σ²/n²."""
    from mitsweep.design.objective import SIGNAL_MEAN

    D, P, N, K, _ = kernels.shape

    def spectrum(k):                      # chief-ray pixel K//2 at the origin
        big = np.zeros((n_fft, n_fft))
        big[:K, :K] = k
        return np.fft.fft2(np.roll(big, (-(K // 2), -(K // 2)), axis=(0, 1)))
    ipsf = np.einsum("k,dpkij->dpij", tau, kernels)
    f = np.fft.fftfreq(n_fft)
    f2 = f[:, None] ** 2 + f[None, :] ** 2
    f2[0, 0] = 1.0                        # DC: left out below
    # the natural prior S ∝ 1/|f|² over a 256 px image: R = nsr 2π ln(256/2) |f|²
    r_true = float(NOISE.nsr(SIGNAL_MEAN)) * 2 * np.pi * np.log(128) * f2
    r_filt = nsr * 2 * np.pi * np.log(128) * f2
    q = [spectrum(ipsf[1, p]) for p in range(P)] + [np.ones((n_fft, n_fft))]  # 500 mm; delta
    g_nodes = [qq.conj() / (np.abs(qq) ** 2 + r_filt) for qq in q]
    out = np.zeros((D, P))
    for d in range(D):
        for p in range(P):
            g = sum(w * g_nodes[P if i < 0 else i] for i, w in zip(index[p], weight[p]))
            e = np.abs(1 - g * spectrum(ipsf[d, p])) ** 2 / r_true + np.abs(g) ** 2
            e[0, 0] = 0.0
            out[d, p] = float(NOISE.variance(SIGNAL_MEAN)) * e.sum() / n_fft ** 2
    return out


def test_the_blended_model_is_the_blend_written_out_by_hand(kernels):
    """Point 0 restored by its own filter, point 1 by a blend of point 0's, its own and a
    node off the mirror (a delta kernel): the model against the sum written out over the
    whole DFT grid (the model sums the half grid with multiplicities)."""
    index, weight = np.array([[0, -1, -1], [0, 1, -1]]), np.array([[1.0, 0, 0], [0.3, 0.5, 0.2]])
    model = deployed_wiener_model(kernels, [300.0, 500.0, 2000.0], NOISE, n_fft=16, n_px=256,
                                  deploy_nsr=0.02, blend=(index, weight))
    tau = np.random.default_rng(4).dirichlet(np.ones(6))
    want = _blend_mse_by_hand(kernels, tau, index, weight, 0.02, 16)
    np.testing.assert_allclose(model.mse(tau).reshape(3, 2), want, rtol=1e-10)


def test_the_blended_gradient_matches_finite_differences(kernels):
    index, weight = np.array([[1, 0], [0, -1]]), np.array([[0.75, 0.25], [0.5, 0.5]])
    model = deployed_wiener_model(kernels, [300.0, 500.0, 2000.0], NOISE, n_fft=16, n_px=256,
                                  deploy_nsr=0.01, blend=(index, weight))
    tau = np.random.default_rng(5).dirichlet(np.ones(6))
    value, grad = model.mse_and_grad(tau)
    np.testing.assert_allclose(value, model.mse(tau), rtol=1e-12)
    h = 1e-6
    num = np.stack([(model.mse(tau + h * e) - model.mse(tau - h * e)) / (2 * h)
                    for e in np.eye(6)], axis=1)
    np.testing.assert_allclose(grad, num, rtol=1e-6, atol=1e-9 * np.abs(num).max())


@pytest.mark.parametrize("blend", [(np.array([[0], [2]]), np.ones((2, 1))),
                                   (np.array([[0, 1]]), np.ones((1, 2))),
                                   (np.array([[0, 1], [1, 0]]), np.full((2, 2), 0.4)),
                                   (np.array([[0, 1], [1, 0]]), np.array([[1.5, -0.5],
                                                                          [0.5, 0.5]])),
                                   (np.array([[0], [1]]), np.array([[np.nan], [1.0]]))])
def test_a_blend_that_does_not_name_points_is_refused(kernels, blend):
    with pytest.raises(ValueError, match="blend"):
        deployed_wiener_model(kernels, [300.0, 500.0, 2000.0], NOISE, n_fft=16, n_px=256,
                              blend=blend)


def test_a_tilted_mirrors_deployed_field_is_the_grid_banks_nodes_and_cell_centres():
    """The points a dataset's grid bank restores: its nodes on the mirror (each its own
    filter) and the cell centres between them (the four corners' filters at 1/4, a
    corner off the mirror a delta); the design reports the grid bank."""
    from mitsweep.deconv.spatial import grid_bank_shape
    from mitsweep.design import design_sweep
    from mitsweep.design.sweep import blended_grid_points
    from mitsweep.optics import optimal_sweep_range
    from mitsweep.tracer.bank import grid_points

    setup = load_setup(ROOT / "scenes" / "paraboloid_tilted.toml")
    sw = optimal_sweep_range(setup)
    grid = grid_bank_shape(setup)
    assert grid == (11, 11)
    points, (index, weight) = blended_grid_points(setup, 0.5 * (sw.sensor_start + sw.sensor_end),
                                                  grid)
    own = weight[:, 0] == 1.0
    n_nodes = int(own.sum())
    assert np.all(own[:n_nodes]) and not np.any(own[n_nodes:])
    np.testing.assert_array_equal(index[:n_nodes, 0], np.arange(n_nodes))
    nodes = grid_points(setup, grid)
    assert all(np.any(np.all(np.isclose(nodes, p), axis=1)) for p in points[:n_nodes])
    np.testing.assert_allclose(weight[n_nodes:], 0.25)
    for p, idx in zip(points[n_nodes:], index[n_nodes:]):
        corners = [points[i] for i in idx if i >= 0]
        assert corners, "a cell centre with no corner on the mirror"
        # each corner is half a cell away along both axes
        cell = np.array([setup.sensor.size[0] / grid[1], setup.sensor.size[1] / grid[0]])
        np.testing.assert_allclose(np.abs(np.array(corners) - p), np.broadcast_to(cell / 2,
                                   (len(corners), 2)), atol=1e-9)
    d = design_sweep(setup, noise=NOISE, n_planes=8, grid=(3, 3), depths=[300.0, 500.0],
                     rays=2048, restoration="deployed", objective="mean", deploy_nsr=0.01)
    assert d.report["deploy"]["grid_bank"] == [3, 3]
    assert len(d.points_uv) <= 9 + 4
    assert d.report["optimized_image_mean_mse"] <= d.report["linear_image_mean_mse"] * (1 + 1e-12)


def test_the_blended_model_stays_finite_on_extreme_kernels_and_profiles():
    """Delta kernels (an in-focus plane), flat ones (far out of focus), a profile that
    dwells on one plane and weights at the ends of [0, 1]: the MSE and its gradient
    stay finite and the MSE non-negative."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=40, deadline=None)
    @given(seed=st.integers(0, 2 ** 16), dwell=st.integers(-1, 5),
           w=st.floats(0.0, 1.0), flat=st.booleans())
    def check(seed, dwell, w, flat):
        rng = np.random.default_rng(seed)
        k = rng.random((2, 2, 6, 7, 7)) ** 8
        if flat:
            k[:, 1] = 1.0
        k[0, 0, :] = 0.0
        k[0, 0, :, 3, 3] = 1.0                           # an in-focus delta
        k /= k.sum(axis=(-2, -1), keepdims=True)
        model = deployed_wiener_model(k, [300.0, 500.0], NOISE, n_fft=16, n_px=256,
                                      deploy_nsr=1e-6,
                                      blend=(np.array([[0, 1], [1, -1]]),
                                             np.array([[w, 1 - w], [1 - w, w]])))
        tau = np.eye(6)[dwell] if dwell >= 0 else np.full(6, 1 / 6)
        value, grad = model.mse_and_grad(tau)
        assert np.all(np.isfinite(value)) and np.all(value >= 0)
        assert np.all(np.isfinite(grad))
    check()
