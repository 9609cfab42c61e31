"""The paper's claims on full renders of its three setups (slow: ~3 min per setup).

Settings are the demo's (``mitsweep.cli.demo.DEMO_SPP``): at those sample counts two
ground-truth renders with different seeds agree to 42 dB on the sphere, so the
differences asserted here (2–10 dB, docs/reference/datasets.md, "Measured on the paper's three setups") are not Monte
Carlo noise.
"""

import numpy as np
import pytest

from mitsweep.cli.demo import DEMO_SPP
from mitsweep.config import load_setup
from mitsweep.pipeline import DatasetOptions, build_dataset, evaluate_dataset

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module", params=["sphere", "paraboloid", "paraboloid_tilted"])
def evaluated(request, tmp_path_factory, scenes_dir_module):
    setup = load_setup(scenes_dir_module / f"{request.param}.toml")
    root = tmp_path_factory.mktemp(request.param)
    build_dataset(setup, root, DatasetOptions(spp=dict(DEMO_SPP),
                                              light_levels_lux=(0.5,)), progress=False)
    return request.param, evaluate_dataset(root)["scenes"]["scene_000"]


@pytest.fixture(scope="module")
def scenes_dir_module():
    from conftest import SCENES

    return SCENES


def test_edof_is_closer_to_ground_truth_than_focused(evaluated):
    name, scene = evaluated
    assert scene["edof"]["psnr"] > scene["focused"]["psnr"], name
    assert scene["edof"]["ssim"] > scene["focused"]["ssim"], name


def test_edof_gain_is_largest_in_the_periphery(evaluated):
    """Per radius: in the periphery (the outer third of the mirror's image: bins centred
    beyond 2/3 of its radius) EDOF beats the focused camera in every bin, and gains more
    there than over the whole image (the focused camera is sharp at the centre, paper
    Fig. 9). Nearer the centre the focused camera wins: on the sphere, every bin out to
    47 % of the radius (docs/reference/datasets.md)."""
    name, scene = evaluated
    r = np.array(scene["edof"]["per_radius"]["radius_px"])
    edof = np.array(scene["edof"]["per_radius"]["psnr"])
    focused = np.array(scene["focused"]["per_radius"]["psnr"])
    outer = r > (2.0 / 3.0) * r.max()
    assert np.all(edof[outer] > focused[outer]), (name, r[outer], edof[outer], focused[outer])
    gain_outer = float(np.mean(edof[outer] - focused[outer]))
    gain_all = scene["edof"]["psnr"] - scene["focused"]["psnr"]
    assert gain_outer > gain_all, (name, gain_outer, gain_all)


def test_edof_beats_stopped_down_in_low_light(evaluated):
    """At 0.5 lux (paper Fig. 10 exposures) the F11 ISO 1600 image is noise-limited and
    the deconvolved F2.8 sweep is closer to the ground truth. (At 50 lux it is not in
    these renders: see docs/reference/datasets.md, "Focal sweep against stopping down".)"""
    name, scene = evaluated
    assert scene["edof_0.5lux"]["psnr"] > scene["stopped_0.5lux"]["psnr"], name
