"""The ``mirrorview`` integrator and the stratified sampler of the renders."""

from __future__ import annotations


import numpy as np
import pytest

import mitsuba as mi  # noqa: E402

from mitsweep.config import load_setup  # noqa: E402
from mitsweep.render.api import (SAMPLERS, camera_dict, multijitter_count,  # noqa: E402
                                 mode_camera, pass_counts)
from mitsweep.render.ad_integrator import INTEGRATOR_NAME as LIT_NAME  # noqa: E402
from mitsweep.render.ad_integrator import MAX_DEPTH as LIT_MAX_DEPTH  # noqa: E402
from mitsweep.render.integrator import INTEGRATOR_NAME, integrator_dict  # noqa: E402
from mitsweep.render.scene import build_scene  # noqa: E402
from mitsweep.render.sensor import register  # noqa: E402

from test_render_api import SCENES, _mesh_cache, small as _small  # noqa: F401 (autouse fixture)


def small(name: str, n: int = 48, **scene):
    """test_render_api's reduced paper setup, at 48 px by default here."""
    return _small(name, n, **scene)


def _scene(setup, mode, spp, sampler="independent", integrator=None):
    kw, _ = mode_camera(setup, mode, None, None)
    d, info = build_scene(setup, camera_dict(setup, spp=spp, sampler=sampler, **kw))
    if integrator is not None:
        d["integrator"] = integrator
    return mi.load_dict(d), info


@pytest.mark.parametrize("name", ["sphere", pytest.param("paraboloid_tilted",
                                                         marks=pytest.mark.slow)])
@pytest.mark.parametrize("mode", ["pinhole", "focused", "sweep"])
def test_mirrorview_gives_the_path_integrators_image_bit_for_bit(name, mode):
    """Same sampler, same seed: the emissive scene's only paths are camera → emitter and
    camera → mirror → emitter, and the delta reflection draws no random numbers, so the
    two integrators must agree exactly, not just in expectation."""
    register()
    s = small(name)
    fast, info = _scene(s, mode, 8)
    assert info["integrator"] == INTEGRATOR_NAME
    slow, _ = _scene(s, mode, 8, integrator={"type": "path", "max_depth": 2,
                                              "hide_emitters": False})
    a = np.array(mi.render(fast, seed=5))
    b = np.array(mi.render(slow, seed=5))
    assert a.max() > 0
    np.testing.assert_array_equal(a, b)


def test_build_scene_uses_mirrorview_only_where_it_is_exact():
    """mirrorview for emissive scenes; lit ones (in the *_ad_* variant of the tests)
    mirrorpath, differentiable through the mirror, up to its depth limit; path beyond."""
    register()
    emissive, lit = small("sphere"), small("sphere", lighting="lit")
    cam = camera_dict(emissive, spp=1, sensor_distance=58.3)
    assert "_ad_" in mi.variant()
    assert build_scene(emissive, cam)[1]["integrator"] == INTEGRATOR_NAME
    assert build_scene(lit, cam)[1]["integrator"] == LIT_NAME
    assert build_scene(lit, cam, max_depth=LIT_MAX_DEPTH + 1)[1]["integrator"] == "path"
    assert build_scene(emissive, cam, max_depth=-1)[1]["integrator"] == "path"
    grey = {"type": "sphere", "radius": 1.0, "bsdf": {"type": "diffuse", "reflectance": 0.5}}
    assert build_scene(emissive, cam, extra={"ball": grey})[1]["integrator"] == LIT_NAME
    black = dict(grey, bsdf={"type": "diffuse", "reflectance": 0.0},
                 emitter={"type": "area", "radiance": 1.0})
    assert build_scene(emissive, cam, extra={"src": black})[1]["integrator"] == INTEGRATOR_NAME
    assert integrator_dict("emissive", 9)["type"] == "path"
    assert integrator_dict("lit", 3)["type"] == "path"       # not asked to be differentiable
    assert integrator_dict("lit", 3, differentiable=True)["type"] == LIT_NAME


@pytest.mark.parametrize("sampler", SAMPLERS)
@pytest.mark.parametrize("spp, per_pass", [(1, 73), (5, 73), (97, 73), (144, 73), (512, 73),
                                           (1000, 73), (300, 7), (64, 1)])
def test_pass_counts_sum_to_spp_and_fit_the_sampler(sampler, spp, per_pass):
    counts = pass_counts(spp, per_pass, sampler)
    assert sum(counts) == spp and max(counts) <= per_pass and min(counts) >= 1
    if sampler == "multijitter":
        register()
        for c in set(counts):
            # The count the sampler would render, asked of Mitsuba itself.
            assert mi.load_dict({"type": "multijitter", "sample_count": c}).sample_count() == c
        assert len(set(counts)) <= 2


def test_multijitter_count_is_mitsubas():
    register()
    level = mi.log_level()
    mi.set_log_level(mi.LogLevel.Error)   # it warns about every count it rounds up
    try:
        got = [mi.load_dict({"type": "multijitter", "sample_count": n}).sample_count()
               for n in range(1, 130)]
    finally:
        mi.set_log_level(level)
    assert got == [multijitter_count(n) for n in range(1, 130)]


def _mean_var(scene, seeds, spp):
    imgs = np.stack([np.array(mi.render(scene, seed=s, spp=spp))[..., 1] for s in seeds])
    return imgs.mean(axis=0), imgs.var(axis=0, ddof=1) / len(seeds)


def _window_scene(setup, mode, spp, sampler, crop):
    kw, _ = mode_camera(setup, mode, None, None)
    cam = camera_dict(setup, spp=spp, sampler=sampler, crop=crop, **kw)
    return mi.load_dict(build_scene(setup, cam)[0])


@pytest.mark.parametrize("mode", ["pinhole", "focused", "sweep"])
@pytest.mark.parametrize("crop", [(60, 236, 40, 40), (236, 236, 40, 40)],
                         ids=["periphery", "centre"])
def test_multijitter_renders_the_same_image_with_less_noise(mode, crop):
    """Stratification changes the noise, not the image: on 40×40 windows of the demo's
    sphere at its own pixel scale, the multijitter and independent means agree within
    their noise, and the ground truth's noise falls most. There the pixel-area integral
    over textures finer than a pixel is where independent samples waste their variance.
    """
    register()
    s = load_setup(SCENES / "sphere.toml")
    seeds, spp = range(8), 16
    m1, v1 = _mean_var(_window_scene(s, mode, spp, "independent", crop), seeds, spp)
    m2, v2 = _mean_var(_window_scene(s, mode, spp, "multijitter", crop),
                       [100 + k for k in seeds], spp)
    ok = (v1 + v2) > 1e-12
    assert ok.sum() > 0.9 * m1.size
    z2 = (m1 - m2)[ok] ** 2 / (v1 + v2)[ok]
    # E[z²] is 1.17 for equal variances (t with 14 dof) and 1.4 where the multijitter
    # variance is negligible (7 dof); measured 1.13-1.40. A bias of a tenth of a pixel
    # in the sample positions gives z² of several at the textured edges.
    assert 0.7 < z2.mean() < 1.8, z2.mean()
    if mode == "pinhole":
        # Measured variance ratios 0.068 (periphery) and 0.051 (centre); the lens modes
        # gain less (0.08-0.95): their noise is the aperture integral's.
        assert v2[ok].mean() < 0.3 * v1[ok].mean(), (v2[ok].mean(), v1[ok].mean())
