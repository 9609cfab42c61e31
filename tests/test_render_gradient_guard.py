"""The "no silent zero gradient" guard in mitsweep's own entry point,
:func:`mitsweep.render.differentiable_render`: it reads the scene, its integrator and
the sensor's differentiated parameters (public state) before calling ``mi.render``.
``test_render_lit_grad.py`` checks the refusals and the gradients through it (its
``ad_derivative`` renders with it); here: what it passes through, and that a refusal
comes before any rendering."""

from __future__ import annotations

import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from mitsweep.render import NotDifferentiableError, differentiable_render, register
from mitsweep.render.integrator import register_integrator

from test_render_lit_grad import lit_mirror_scene
from test_render_sweep_grad import sweep_scene


@pytest.fixture(scope="module", autouse=True)
def _variant():
    variant = register()
    if "_ad_" not in variant:
        pytest.fail(f"these tests need an *_ad_* Mitsuba variant, got {variant}")
    register_integrator()


def test_without_a_gradient_it_is_mi_render_bit_for_bit():
    scene = lit_mirror_scene("path", spp=4)
    a = np.array(differentiable_render(scene, seed=3))
    b = np.array(mi.render(scene, seed=3))
    assert np.array_equal(a, b) and a.mean() > 0


@pytest.mark.parametrize("integrator", ["path", "prb"])
def test_a_refusal_comes_before_any_rendering(monkeypatch, integrator):
    scene = lit_mirror_scene(integrator, spp=4)
    params = mi.traverse(scene)
    dr.enable_grad(params["sensor.sensor_end"])
    params.update()
    rendered = []
    monkeypatch.setattr(mi, "render", lambda *a, **k: rendered.append(1))
    try:
        with pytest.raises(NotDifferentiableError, match=f"'{integrator}' integrator"):
            differentiable_render(scene, params, seed=1, seed_grad=2)
    finally:
        dr.disable_grad(params["sensor.sensor_end"])
    assert rendered == []


def test_the_sensor_reports_which_sweep_parameters_carry_a_gradient():
    scene = lit_mirror_scene(spp=4)
    sensor = scene.sensors()[0]
    params = mi.traverse(scene)
    assert sensor.differentiated_parameters() == ()
    dr.enable_grad(params["sensor.sensor_start"])
    params.update()
    try:
        assert sensor.differentiated_parameters() == ("sensor_start",)
    finally:
        dr.disable_grad(params["sensor.sensor_start"])


def test_mirrorpath_and_a_direct_view_with_path_pass_with_a_gradient():
    for scene in (lit_mirror_scene(spp=4), sweep_scene()):
        params = mi.traverse(scene)
        dr.enable_grad(params["sensor.sensor_end"])
        params.update()
        try:
            img = differentiable_render(scene, params, seed=1, seed_grad=2, spp=4)
            dr.forward(params["sensor.sensor_end"])
            g = dr.grad(img).numpy()
        finally:
            dr.disable_grad(params["sensor.sensor_end"])
        assert np.isfinite(g).all() and np.abs(g).max() > 0
