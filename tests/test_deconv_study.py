"""scripts/restoration_study.py: the derived fine-pitch setups and the tables it writes
from `mitsweep evaluate --json` results."""

import importlib.util
from pathlib import Path

import pytest

from mitsweep.config import load_setup

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def study():
    spec = importlib.util.spec_from_file_location("restoration_study",
                                                  ROOT / "scripts" / "restoration_study.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("setup", ["sphere", "paraboloid", "paraboloid_tilted"])
def test_a_fine_pitch_keeps_the_sensor_size(study, setup, tmp_path):
    demo = load_setup(ROOT / "scenes" / f"{setup}.toml")
    fine = load_setup(study.setup_file(setup, "0.0064", tmp_path))
    assert fine.sensor.pixel_pitch == 0.0064
    for n_demo, n_fine in zip(demo.sensor.resolution, fine.sensor.resolution):
        # rounded up to a multiple of 16 px: the sensor is at most 16 px wider
        size = n_demo * demo.sensor.pixel_pitch
        assert size <= n_fine * 0.0064 < size + 16 * 0.0064
    assert fine.mirror == demo.mirror and fine.sweep == demo.sweep
    assert study.setup_file(setup, "demo", tmp_path) == ROOT / "scenes" / f"{setup}.toml"


def _entry(psnr):
    return {"psnr": psnr, "ssim": psnr / 40, "per_radius": {"psnr": [psnr + 1, psnr - 1],
                                                           "ssim": [0.5, 0.4],
                                                           "radius_px": [10.0, 30.0]}}


def test_tables_compare_the_best_edof_with_f11_and_focused(study):
    scene = {"focused": _entry(15.0), "stopped": _entry(21.0), "sweep": _entry(17.0),
             "edof": _entry(19.0), "edof_tv": _entry(19.5),
             "stopped_0.5lux": _entry(14.0), "sweep_0.5lux": _entry(16.0),
             "edof_0.5lux": _entry(18.0), "edof_tv_0.5lux": _entry(18.25)}
    key = ("paraboloid", "demo")
    text, js = study.tables({key: {"scenes": {"scene_000": scene}}}, {key: ["wiener", "tv"]},
                            {key: (187.8, {"edof_tv": 25.0})})
    assert "| paraboloid | demo | none | 15.00 | 21.00 | 19.50 (tv) | -1.50 | +4.50 |" in text
    # the focused image has no noisy version: no comparison with it in dim light
    assert "| paraboloid | demo | 0.5 | – | 14.00 | 18.25 (tv) | +4.25 | – |" in text
    assert "| EDOF tv | none | 19.50 | 0.487 | 25.00 | 20.5 / 18.5 |" in text
    images = js["paraboloid@demo"]["images"]
    assert images["edof_tv"]["psnr_fov"] == 25.0 and images["edof"]["psnr_fov"] is None
    assert js["paraboloid@demo"]["fov_radius_px"] == 187.8
