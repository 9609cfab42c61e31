"""Error budgets (mitsweep.deconv.budget, mitsweep budget): each term checked on a case
whose answer is known, the terms adding up to the measured error, the oracle weight, and
the command on a small real dataset.

Exact zeros: a step whose input equals the previous step's input is restored by the same
deterministic computation (the polar filter sums its bands in a fixed order), so its
term is 0.0, not merely small. Additivity: the terms are differences of consecutive
steps' MSEs, so they telescope to the last MSE up to float64 round-off (1e-12 relative).
"""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, run_cli
from mitsweep.deconv import SensorNoise, blur_operator, deconvolve, psnr
from mitsweep.deconv.budget import TERMS, error_budget, layered_blur, oracle_weight
from mitsweep.deconv.synthetic import synthetic_radial_bank

SHAPE = (64, 64)


def _truth() -> np.ndarray:
    from skimage import data, transform

    img = transform.resize(data.astronaut()[100:356, 150:406] / 255.0, (*SHAPE, 3),
                           anti_aliasing=True)
    return img.astype(np.float64)


def _model(truth, bank, depth=None):
    op = blur_operator(bank, truth.shape, depth=depth)
    return np.stack([op.forward(truth[..., c]) for c in range(truth.shape[2])], axis=-1)


@pytest.fixture(scope="module")
def case():
    """Truth, a two-depth synthetic bank (the 3 m kernels wider), a depth map with a near
    disc on a far wall, the mirror's disc as mask."""
    bank = synthetic_radial_bank(SHAPE, n_radii=9, size=11, extent_px=24.0,
                                 depths=(500.0, 3000.0))
    k = np.asarray(bank.kernels).copy()
    from scipy.ndimage import gaussian_filter

    k[1] = [gaussian_filter(kk, 0.8) for kk in k[1]]
    k[1] /= k[1].sum(axis=(-1, -2), keepdims=True)
    bank = replace(bank, kernels=k.astype(np.float32))
    truth = _truth()
    yy, xx = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    r = np.hypot(yy - 31.5, xx - 31.5)
    mask = r < 30
    depth = np.where(np.hypot(yy - 20, xx - 40) < 9, 400.0, 2500.0)
    return truth, bank, mask, depth


def _check_additive(b):
    """Terms sum to the last step's MSE in every region, to 1e-12 relative."""
    tm = b.term_mse
    ok = np.isfinite(b.mse[-1])
    np.testing.assert_allclose(tm.sum(axis=0)[ok], b.mse[-1][ok], rtol=1e-12, atol=0)


def test_pure_model_blur_has_zero_mismatch_and_no_sensor_noise(case):
    truth, bank, mask, _ = case
    model = _model(truth, bank)
    b = error_budget(truth, model, bank, mask=mask, weight=1e-3)
    assert b.terms == ("information", "mismatch", "sensor", "weight")
    tm = dict(zip(b.terms, b.term_mse))
    assert np.all(tm["mismatch"][np.isfinite(tm["mismatch"])] == 0.0)
    assert np.all(tm["sensor"][np.isfinite(tm["sensor"])] == 0.0)
    assert tm["information"][0] > 0          # the model blur loses information
    _check_additive(b)


def test_depth_term_and_mismatch_cancel_on_the_layered_model(case):
    """Rendered as the layered model: the depth term is the whole mismatch (the two add
    to 0 exactly in the sense of the steps: the mismatch step adds nothing)."""
    truth, bank, mask, depth = case
    render = layered_blur(truth, bank, depth)
    b = error_budget(truth, render, bank, mask=mask, depth=depth, weight=1e-3)
    assert b.terms == ("information", "depth", "mismatch", "sensor", "weight")
    tm = dict(zip(b.terms, b.term_mse))
    assert tm["mismatch"][0] == 0.0
    assert tm["depth"][0] != 0.0             # the near disc is blurred with its own kernels
    _check_additive(b)
    # one layer only: the layered blur is the model blur itself, bit for bit
    far = np.full(SHAPE, 500.0)
    np.testing.assert_array_equal(layered_blur(truth, bank, far), _model(truth, bank))


def test_noise_free_render_has_zero_sensor_term_and_noisy_one_a_positive_one(case):
    truth, bank, mask, _ = case
    gen = np.random.default_rng(3)
    render = _model(truth, bank) + 0.004 * gen.standard_normal(truth.shape)  # "Monte Carlo"
    b = error_budget(truth, render, bank, clean_observed=render, mask=mask, weight=1e-2)
    assert b.term_mse[b.terms.index("sensor")][0] == 0.0
    noise = SensorNoise(illuminance_lux=0.5, exposure_s=0.6, f_number=2.8,
                        pixel_pitch=0.0064)
    noisy = noise.apply(np.clip(render, 0, None), 7)
    b = error_budget(truth, noisy, bank, clean_observed=render, mask=mask, noise=noise)
    assert b.term_mse[b.terms.index("sensor")][0] > 0
    _check_additive(b)


def test_terms_add_up_to_the_measured_error_and_bins_to_the_total(case):
    truth, bank, mask, depth = case
    gen = np.random.default_rng(5)
    clean = layered_blur(truth, bank, depth) + 0.003 * gen.standard_normal(truth.shape)
    second = layered_blur(truth, bank, depth) + 0.003 * gen.standard_normal(truth.shape)
    noisy = clean + 0.01 * gen.standard_normal(truth.shape)
    restored = deconvolve(noisy, bank, weight=3e-3)
    b = error_budget(truth, noisy, bank, clean_observed=clean, second_seed=second,
                     restored=restored, depth=depth, mask=mask, weight=3e-3)
    assert b.terms == TERMS
    _check_additive(b)
    # the last step is the restoration that was made: its PSNR is the evaluation's
    assert -10 * math.log10(b.mse[-1][0]) == pytest.approx(psnr(restored, truth, mask=mask),
                                                          abs=1e-9)
    # radial bins partition the mask: their pixel-weighted MSEs are the total's
    rows = [j for j, r in enumerate(b.regions) if r[0] == "r" and r[1:].isdigit()]
    n = b.pixels[rows]
    assert n.sum() == b.pixels[0] == mask.sum()
    for k in range(len(b.terms)):
        assert np.sum(n * b.term_mse[k, rows]) / n.sum() == pytest.approx(
            b.term_mse[k, 0], rel=1e-9, abs=1e-15)
    # the oracle steps are never worse than the chosen weight overall
    assert b.term_mse[-1][0] >= 0
    d = b.as_dict()
    json.dumps(d, allow_nan=False)
    assert set(d["per_radius"]["terms"]) == set(TERMS)
    assert "beyond_fov" in d["regions"] and "occlusion_edges" in d["regions"]
    assert all(t in b.table() for t in ("info", "mismatch", "MC", "sensor", "weight"))


def test_identical_second_seed_has_zero_monte_carlo_term(case):
    truth, bank, mask, _ = case
    render = _model(truth, bank) + 0.003 * np.random.default_rng(1).standard_normal(truth.shape)
    b = error_budget(truth, render, bank, second_seed=render.copy(), mask=mask, weight=1e-2)
    assert b.term_mse[b.terms.index("monte_carlo")][0] == 0.0


def test_oracle_weight_beats_every_weight_of_a_grid(case):
    truth, bank, mask, _ = case
    noisy = _model(truth, bank) + 0.01 * np.random.default_rng(2).standard_normal(truth.shape)

    def restore(x, w):
        return deconvolve(x, bank, weight=w)

    w, x, mse = oracle_weight(noisy, truth, restore, mask=mask)
    assert float(np.mean(((x - truth) ** 2).mean(axis=2)[mask])) == pytest.approx(mse, rel=1e-12)
    for g in np.geomspace(1e-5, 1e-1, 9):
        e = float(np.mean(((restore(noisy, g) - truth) ** 2).mean(axis=2)[mask]))
        assert mse <= e * (1 + 1e-9), (g, e, w, mse)


def test_a_method_without_a_scalar_weight_is_refused(case):
    truth, bank, _, _ = case
    with pytest.raises(ValueError, match="no scalar weight"):
        error_budget(truth, truth, bank, method="rl")


# -- the command on a real dataset -----------------------------------------------------

@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    """The smallest real dataset the dataset tests use (48 px, a few spp, 50 lux)."""
    from mitsweep.config import DEFAULT_SETUP, Sensor
    from mitsweep.pipeline import DatasetOptions, build_dataset

    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(48, 48), pixel_pitch=0.18))
    opts = DatasetOptions(scenes=1, spp={"pinhole": 2, "focused": 2, "sweep": 4, "stopped": 2},
                          bank_rays=1 << 14, light_levels_lux=(50.0,))
    root = tmp_path_factory.mktemp("ds")
    build_dataset(setup, root, opts, progress=False)
    return root


@pytest.mark.slow   # one of the longest default tests (15-40 s on 2 cores): in CI's slow run
def test_budget_command_prints_every_term_per_bin(tiny_dataset, tmp_path):
    out = tmp_path / "budget"
    rc, stdout, stderr = run_cli("budget", tiny_dataset, "--json", "--out", out)
    assert rc == 0, stderr
    data = json.loads(stdout)
    assert set(data["budgets"]) == {"scene_000/edof.exr", "scene_000/edof_50lux.exr"}
    evaluation = json.loads(run_cli("evaluate", tiny_dataset, "--json")[1])
    for name, b in data["budgets"].items():
        assert b["order"] == ["information", "mismatch", "sensor", "weight"]
        n_bins = len(b["per_radius"]["edges_px"]) - 1
        for t in b["order"]:
            assert len(b["per_radius"]["terms"][t]) == n_bins
            assert len(b["per_depth_band"]["terms"][t]) == len(b["per_depth_band"]["edges_mm"]) - 1
        total = b["total"]
        assert sum(total["terms"].values()) == pytest.approx(total["mse_after"]["weight"],
                                                             rel=1e-12)
        # the budget ends at the dataset's measured error of that image
        stem = Path(name).stem
        assert total["psnr_after"]["weight"] == pytest.approx(
            evaluation["scenes"]["scene_000"][stem]["psnr"], abs=1e-6)
    assert b["total"]["terms"]["sensor"] != 0 and \
        data["budgets"]["scene_000/edof.exr"]["total"]["terms"]["sensor"] == 0
    assert json.loads((out / "budget.json").read_text()) == data
    assert (out / "budget_scene_000_edof_50lux.png").stat().st_size > 0
    rc, text, _ = run_cli("budget", tiny_dataset, "--item", "edof_50lux")
    assert rc == 0 and text.startswith("scene_000/edof_50lux.exr") and "mismatch" in text


@pytest.mark.parametrize("args", [("{missing}",), ("{ds}", "--item", "edof_7lux"),
                                  ("{ds}", "--second-seed", "3")])
def test_budget_command_bad_input_is_one_line_exit_2(tiny_dataset, tmp_path, args):
    argv = [a.format(missing=tmp_path / "nothing", ds=tiny_dataset) for a in args]
    rc, stdout, stderr = run_cli("budget", *argv)
    assert rc == 2 and stdout == ""
    assert len(stderr.strip().splitlines()) == 1, stderr


def test_docs_page_describes_every_term_and_the_command():
    page = (ROOT / "docs" / "guide" / "budget.md").read_text()
    assert "mitsweep budget" in page
    for term in TERMS:
        assert f"`{term}`" in page, term
    index = (ROOT / "docs" / "index.md").read_text()
    assert "guide/budget" in index
