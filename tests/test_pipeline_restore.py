"""The dataset's restoration task: the prior-based methods get the sensor noise model the
dataset applied to the image (Wiener gets it as its NSR), in the model's units."""

import json

import numpy as np
import pytest

from mitsweep import deconv
from mitsweep.deconv import SensorNoise, paper_fig10_settings
from mitsweep.deconv.synthetic import synthetic_radial_bank
from mitsweep.deconv.weights import MismatchProfile, model_nsr
from mitsweep.io import bank as bank_io
from mitsweep.io import read_exr, write_exr
from mitsweep.pipeline import DatasetError, DatasetOptions
from mitsweep.pipeline import tasks
from test_pipeline_dataset import TINY

LUX = 2.0
BANK = synthetic_radial_bank((32, 32), size=5)
WHITE = 0.37          # renders' units: far from 1, so that a lost white level shows
# the mirror's image: a disc (a calibrated weight is read over it)
MASK = np.hypot(*(np.mgrid[0:32, 0:32] - 15.5)) < 14
# a bank's mismatch profile (what calibrate_weights writes): a fifth of the spectrum
# unexplained beyond 0.1 cycles/px, counted at 0.8 of it
PROFILE = MismatchProfile(np.linspace(0.0, 0.5, 24),
                          np.where(np.linspace(0.0, 0.5, 24) > 0.1, 0.2, 0.01), 0.8, 1e-3)


@pytest.fixture
def noisy_sweep(tmp_path):
    """A noisy sweep made by the dataset's own add_noise task from a smooth synthetic
    render, and the noise model the plan gave it: (path, noise model)."""
    y, x = np.mgrid[0:32, 0:32] / 32.0
    render = (WHITE * (0.2 + 0.6 * np.stack([x, y, x * y], axis=-1))).astype(np.float32)
    write_exr(tmp_path / "pinhole.exr", render,
              channels={"mask.Y": MASK.astype(np.float32)})
    write_exr(tmp_path / "sweep.exr", render)
    (tmp_path / "mismatch.json").write_text(json.dumps(PROFILE.to_dict()))
    opts = DatasetOptions(scenes=1, light_levels_lux=(LUX,), methods=("wiener", "tv"))
    task = next(t for t in tasks.plan(opts) if t.name == f"scene_000/sweep_{LUX:g}lux.exr")
    tasks.add_noise(TINY, tmp_path / "noisy.exr", ground_truth=tmp_path / "pinhole.exr",
                    image=tmp_path / "sweep.exr", **task.params)
    return tmp_path / "noisy.exr", paper_fig10_settings(tasks.NOISE_PIXEL_MM, LUX)["sweep"]


@pytest.fixture
def calls(monkeypatch):
    """deconvolve replaced by a spy that returns its input: [(image, kwargs)]."""
    seen = []

    def spy(image, bank, **kw):
        seen.append((np.array(image), kw))
        return np.array(image)

    monkeypatch.setattr(deconv, "deconvolve", spy)
    monkeypatch.setattr(bank_io, "load_bank", lambda path: BANK)
    return seen


def restore_params(method: str) -> dict:
    opts = DatasetOptions(scenes=1, light_levels_lux=(LUX,), methods=(method,))
    name = f"scene_000/{tasks.edof_name(method, f'_{LUX:g}lux')}.exr"
    return next(t for t in tasks.plan(opts) if t.name == name).params


@pytest.mark.parametrize("method", ["rl", "tv", "hyperlaplacian"])
def test_prior_methods_get_the_noise_the_dataset_applied(noisy_sweep, calls, tmp_path,
                                                         method):
    path, model = noisy_sweep
    level = read_exr(path)[1]["white_level"]
    assert level != pytest.approx(1.0, rel=0.1)        # the units matter here
    tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                  ground_truth=tmp_path / "pinhole.exr", mismatch=tmp_path / "mismatch.json",
                  **restore_params(method))
    (seen, kw), = calls
    assert kw["noise"] == model
    assert isinstance(kw["noise"], SensorNoise)
    # the model is in relative exposure: the method sees the image divided by the level
    noisy = tasks.read_rgb(path)[0]
    np.testing.assert_allclose(seen, noisy / level, rtol=1e-6)   # float32 division
    # and its result is scaled back to the renders' units (the spy returns its input)
    np.testing.assert_allclose(tasks.read_rgb(tmp_path / "edof.exr")[0], noisy, rtol=1e-6)
    # their first Wiener step's NSR is the calibrated rule's (mitsweep.deconv.weights)
    assert kw["nsr"] == pytest.approx(model_nsr(noisy, BANK, model, level=level,
                                                mask=MASK,
                                                mismatch=PROFILE))


def test_wiener_takes_its_nsr_from_the_noise_model_and_the_profile(noisy_sweep, calls,
                                                                    tmp_path):
    path, model = noisy_sweep
    params = restore_params("wiener")
    assert params == {"method": "wiener", "noise": model.as_dict(), "weights": "calibrated"}
    tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                  ground_truth=tmp_path / "pinhole.exr", mismatch=tmp_path / "mismatch.json",
                  **params)
    (seen, kw), = calls
    assert "noise" not in kw and kw["prior"] == tasks.DECONV_PRIOR
    noisy, _, meta = tasks.read_rgb(path)
    expected = model_nsr(noisy, BANK, model, level=meta["white_level"],
                         mask=MASK, mismatch=PROFILE)
    assert kw["nsr"] == pytest.approx(expected)
    # the profile counts: without it (the former rule) the weight differs
    assert kw["nsr"] != pytest.approx(model_nsr(noisy, BANK, model, level=meta["white_level"],
                                                mask=MASK), rel=0.05)
    assert tasks.read_rgb(tmp_path / "edof.exr")[2]["nsr_rule"] == "calibrated"
    np.testing.assert_array_equal(seen, noisy)  # in the renders' units


def test_earlier_manifests_model_rule_still_runs(noisy_sweep, calls, tmp_path):
    """``weights="model"`` (the tasks of manifests before the calibrated rule)."""
    path, model = noisy_sweep
    params = dict(restore_params("wiener"), weights="model")
    tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                  ground_truth=tmp_path / "pinhole.exr", **params)
    (seen, kw), = calls
    noisy, _, meta = tasks.read_rgb(path)
    assert kw["nsr"] == pytest.approx(model_nsr(noisy, BANK, model, level=meta["white_level"],
                                                mask=MASK))
    assert tasks.read_rgb(tmp_path / "edof.exr")[2]["nsr_rule"] == "model"


@pytest.mark.parametrize("content,message", [
    (None, "not a readable mismatch profile"),
    ("{not json", "not a readable mismatch profile"),
    ('{"f": [0, 0.5], "share": [0.1, 0.1]}', "not a readable mismatch profile"),
])
def test_a_missing_or_broken_profile_is_refused_naming_it(noisy_sweep, calls, tmp_path,
                                                          content, message):
    path, _ = noisy_sweep
    bad = tmp_path / "bad.json"
    if content is not None:
        bad.write_text(content)
    with pytest.raises(DatasetError, match=message) as info:
        tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                      ground_truth=tmp_path / "pinhole.exr", mismatch=bad,
                      **restore_params("wiener"))
    assert str(bad) in str(info.value)
    assert calls == [] and not (tmp_path / "edof.exr").exists()


def test_the_calibrated_rule_needs_its_profile_and_mask(noisy_sweep, calls, tmp_path):
    path, _ = noisy_sweep
    with pytest.raises(ValueError, match="weights 'calibrated' needs the mismatch profile"):
        tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                      ground_truth=tmp_path / "pinhole.exr", **restore_params("wiener"))
    assert calls == []


def test_a_task_may_read_the_spectrum_over_the_mirror(noisy_sweep, calls, tmp_path):
    """``weights="mirror"``: model_nsr with the mirror's spectrum, and the image records
    the rule."""
    path, model = noisy_sweep
    params = dict(restore_params("wiener"), weights="mirror")
    tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                  ground_truth=tmp_path / "pinhole.exr", **params)
    (seen, kw), = calls
    noisy, _, meta = tasks.read_rgb(path)
    assert kw["nsr"] == pytest.approx(model_nsr(noisy, BANK, model, level=meta["white_level"],
                                                mask=MASK,
                                                spectrum="mirror"))
    assert tasks.read_rgb(tmp_path / "edof.exr")[2]["nsr_rule"] == "mirror"


def test_older_manifests_wiener_tasks_keep_their_rule(noisy_sweep, calls, tmp_path):
    """A task without ``weights`` (older manifests' params) keeps the former rule."""
    path, model = noisy_sweep
    tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                  method="wiener", nsr=model.nsr(0.5))
    (seen, kw), = calls
    assert kw["nsr"] >= model.nsr(0.5)


def test_noiseless_sweeps_are_restored_without_a_noise_model():
    opts = DatasetOptions(scenes=1, light_levels_lux=(LUX,), methods=("tv",))
    task = next(t for t in tasks.plan(opts) if t.name == "scene_000/edof_tv.exr")
    assert task.params == {"method": "tv", "weights": "calibrated"}
    assert task.inputs["mismatch"] == tasks.MISMATCH


def test_a_noise_model_the_image_does_not_carry_is_refused(noisy_sweep, calls, tmp_path):
    path, model = noisy_sweep
    params = restore_params("tv")
    params["noise"] = dict(params["noise"], iso=1600.0)
    with pytest.raises(DatasetError, match="noisy.exr: its metadata does not record the "
                                           "noise model"):
        tasks.restore(TINY, tmp_path / "edof.exr", image=path, bank=tmp_path / "bank.npz",
                      ground_truth=tmp_path / "pinhole.exr",
                      mismatch=tmp_path / "mismatch.json", **params)
    assert calls == [] and not (tmp_path / "edof.exr").exists()


def test_noisy_image_is_labelled_in_the_renders_units(noisy_sweep, tmp_path):
    """add_noise stores the noisy relative exposure times the white level: the renders'
    units, as its ``units`` says (it said "relative exposure"). In those units the noise
    is the model's, scaled by the level: the residual against the clean render divided by
    ``level · sqrt(variance(render / level))`` has unit spread, and the mean is the
    render's, not the relative exposure's (0.56 here, against 0.16)."""
    path, model = noisy_sweep
    noisy, _, meta = tasks.read_rgb(path)
    render = tasks.read_rgb(tmp_path / "sweep.exr")[0].astype(np.float64)
    level = meta["white_level"]
    assert meta["units"] == tasks.NOISY_UNITS
    residual = noisy - render
    # unbiased noise: the mean residual within 5 standard errors (3072 values)
    assert abs(residual.mean()) < 5 * residual.std() / np.sqrt(residual.size)
    z = residual / (level * np.sqrt(model.variance(render / level)))
    # the spread of 3072 unit normals is 1 within 5 / sqrt(2 · 3072) = 0.064
    assert z.std() == pytest.approx(1.0, abs=0.064)
