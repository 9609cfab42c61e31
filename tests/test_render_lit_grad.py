"""``mirrorpath``: lit scenes through the mirror, their image and their sweep derivative.

Scene: the ``focalsweep`` camera of ``tests/test_render_sweep_grad.py`` (f/4, sweep
57.2 → 58.4 mm) looks at a convex spherical mirror (radius 200 mm, centre 420 mm ahead);
the mirror shows a large diffuse board behind the camera with a smooth (bilinear)
random texture, lit by a rectangular area light off to the side (not in the mirror's
view, and no shape between it and the part of the board the mirror shows). The primal
checks add an environment (constant or an ``envmap``), a point light and a glossy
(``roughplastic``) ball beside the board.

Primal: ``mirrorpath`` draws its random numbers as Mitsuba's ``path`` does, so with the
same seed the images agree to float rounding; over disjoint seeds their block means
agree within Monte Carlo error.

Derivative: as in ``test_render_sweep_grad.py`` (AD over seeds 1-10 against the
central difference with common random numbers over seeds 101-110, within ``Z``
standard errors; the same seed within 1 %), for ``sensor_start`` and ``sensor_end`` in
forward and reverse mode. The lighting is chosen so that the image has no visibility
edge that moves with the sweep except an area light's rim seen by BSDF samples (whose
MIS weight is small beside the light's own samples): under a constant environment the
mirror's silhouette, seen from the board, occludes the sky, and the few samples that
cross it within the step give single-seed finite differences of up to 15 times the
derivative, of either sign (measured), a boundary term plain AD leaves out (see
:mod:`mitsweep.render.ad_integrator`).
"""

from __future__ import annotations

import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

from mitsweep.render.ad_integrator import INTEGRATOR_NAME, register_integrator
from mitsweep.render.sensor import NotDifferentiableError, register

from test_render_sweep_grad import (BOARD, SEEDS_AD, SEEDS_FD, Z, _board_texture, _mean_se,
                                    ad_derivative, fd_derivative, sweep_scene)

W = 32
SPP = 32
#: AD and FD with the same seed: measured 4e-5 (sensor_end) and 1e-3 (sensor_start) at
#: seed 3, up to 8e-3 at other seeds (a BSDF sample crossing the light's rim in the step).
RTOL_CRN = 1e-2


@pytest.fixture(scope="module", autouse=True)
def _variant():
    variant = register()
    if "_ad_" not in variant:
        pytest.fail(f"these tests need an *_ad_* Mitsuba variant, got {variant}")
    register_integrator()


def lit_mirror_scene(integrator: str = INTEGRATOR_NAME, *, env: str = "none",
                     point: bool = False, ball: bool = False, max_depth: int = 3,
                     spp: int = SPP) -> "mi.Scene":
    """The module's scene (see the docstring); ``env`` in {"none", "constant",
    "envmap"}; ``point`` adds a point light, ``ball`` a glossy ball in the mirror's view."""
    T = mi.ScalarTransform4f
    integ = {"type": integrator}
    if not integrator.startswith("direct"):
        integ["max_depth"] = max_depth
    d = {"type": "scene", "integrator": integ,
         "sensor": sweep_scene(spp=spp, width=W).sensors()[0],
         "mirror": {"type": "sphere", "center": [0, 0, -BOARD], "radius": 200.0,
                    "bsdf": {"type": "conductor"}},
         "board": {"type": "rectangle",
                   "to_world": T().translate([0, 0, 300]).rotate([0, 1, 0], 180).scale(2000.0),
                   "bsdf": {"type": "diffuse", "reflectance": {
                       "type": "bitmap", "bitmap": mi.Bitmap(_board_texture()), "raw": True}}},
         "light": {"type": "rectangle",
                   "to_world": T().look_at(origin=[600, 0, 100], target=[0, 0, 300],
                                           up=[0, 1, 0]).scale(150.0),
                   "emitter": {"type": "area", "radiance": 20.0}}}
    if env == "constant":
        d["sky"] = {"type": "constant", "radiance": 1.0}
    elif env == "envmap":
        sky = 0.5 + np.random.default_rng(0).random((16, 32, 3))
        d["sky"] = {"type": "envmap", "bitmap": mi.Bitmap(sky.astype(np.float32))}
    if point:
        d["lamp"] = {"type": "point", "position": [-300, 100, 150], "intensity": 4e4}
    if ball:
        d["ball"] = {"type": "sphere", "center": [20, 10, 260], "radius": 15.0,
                     "bsdf": {"type": "roughplastic", "alpha": 0.2,
                              "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.3, 0.2]}}}
    return mi.load_dict(d)


PRIMAL_CASES = {
    "area light": dict(),
    "constant sky, area light": dict(env="constant"),
    "envmap, area and point light, glossy ball": dict(env="envmap", point=True, ball=True),
    "point light, glossy ball, depth 4": dict(point=True, ball=True, max_depth=4),
}


@pytest.mark.parametrize("case", list(PRIMAL_CASES))
def test_mirrorpath_gives_the_path_integrators_image_with_the_same_seed(case):
    """Same random numbers in the same order and masks as ``path`` (no Russian roulette
    below its rr_depth 5): the two estimates agree sample for sample. Measured: equal
    bit for bit; the tolerance leaves room for a different fusion of float operations."""
    kw = PRIMAL_CASES[case]
    ours = np.array(mi.render(lit_mirror_scene(**kw), seed=3))
    theirs = np.array(mi.render(lit_mirror_scene("path", **kw), seed=3))
    assert ours.mean() > 0.05
    np.testing.assert_allclose(ours, theirs, rtol=1e-5, atol=1e-6)


def _block_means(img: np.ndarray, n: int = 4) -> np.ndarray:
    """Means of the grey image over n × n blocks."""
    g = img[..., :3].mean(axis=-1)
    return g.reshape(n, g.shape[0] // n, n, g.shape[1] // n).mean(axis=(1, 3)).ravel()


def test_mirrorpath_agrees_with_path_within_monte_carlo_error():
    """Disjoint seeds (so not sample for sample): each of 16 block means agrees within
    ``Z`` standard errors (P(any |t| > 4.5) ≈ 0.5 % under H0 with 16 blocks), on the
    scene with every kind of light."""
    kw = PRIMAL_CASES["envmap, area and point light, glossy ball"]
    ours, theirs = lit_mirror_scene(**kw, spp=8), lit_mirror_scene("path", **kw, spp=8)
    a = np.array([_block_means(np.array(mi.render(ours, seed=s))) for s in SEEDS_AD])
    b = np.array([_block_means(np.array(mi.render(theirs, seed=s))) for s in SEEDS_FD])
    se = np.hypot(a.std(axis=0, ddof=1), b.std(axis=0, ddof=1)) / np.sqrt(len(a))
    z = (a.mean(axis=0) - b.mean(axis=0)) / se
    assert np.all(np.abs(z) < Z), z
    # Not vacuous: each block mean is resolved to 0.6-1.7 % (measured; max |z| 1.5), so
    # losing a light's emitter samples or the mirror's bounce fails above.
    assert np.all(Z * se < 0.1 * b.mean(axis=0)), se / b.mean(axis=0)


def forward_ad_weights(scene, key: str, spp: int = 64) -> np.ndarray:
    """The weight image ``w`` of ``J = Σ w·I``: the forward-mode derivative image at
    seed 999 (disjoint from the tested seeds), scaled to a largest magnitude of 1 (an FD
    image, as test_render_sweep_grad uses, is noisier here: see the module)."""
    params = mi.traverse(scene)
    value = params[key]
    dr.enable_grad(value)
    params.update()
    try:
        img = mi.render(scene, params, seed=998, seed_grad=999, spp=spp)
        dr.forward(value)
        g = dr.grad(img).numpy()
    finally:
        dr.disable_grad(value)
    return (g / np.abs(g).max()).astype(np.float32)


@pytest.fixture(scope="module")
def grad_cases():
    """key -> (scene, weights)."""
    out = {}
    for key in ("sensor.sensor_start", "sensor.sensor_end"):
        scene = lit_mirror_scene()
        out[key] = scene, forward_ad_weights(scene, key)
    return out


@pytest.mark.parametrize("key, mode", [
    # Forward and reverse mode agree to 1e-4 with the same seed (the CRN test below, for
    # both keys; measured |z| within 1e-5 of each other), so each key needs one here.
    ("sensor.sensor_start", "forward"), ("sensor.sensor_end", "reverse"),
    pytest.param("sensor.sensor_start", "reverse", marks=pytest.mark.slow),
    pytest.param("sensor.sensor_end", "forward", marks=pytest.mark.slow),
])
def test_lit_gradient_through_the_mirror_matches_finite_differences_statistically(
        grad_cases, key, mode):
    scene, w = grad_cases[key]

    def ad(seed):
        return float(ad_derivative(scene, key, seed, w, mode=mode, tangent=[1.0])[0])

    m_ad, se_ad = _mean_se([ad(s) for s in SEEDS_AD])
    m_fd, se_fd = _mean_se([fd_derivative(scene, key, s, w, [1.0]) for s in SEEDS_FD])
    sigma = np.hypot(se_ad, se_fd)
    assert abs(m_ad - m_fd) < Z * sigma, (m_ad, m_fd, sigma)
    # Not vacuous: σ is 1.3-1.7 % of the derivative (measured; |z| <= 0.31), so a zero
    # derivative (``path``'s here), or one off by more than ~8 %, fails above.
    assert Z * sigma < 0.1 * abs(m_fd), (m_fd, sigma)


@pytest.mark.parametrize("key", ["sensor.sensor_start", "sensor.sensor_end"])
def test_lit_gradient_equals_finite_differences_with_common_random_numbers(grad_cases, key):
    scene, w = grad_cases[key]
    fwd = float(ad_derivative(scene, key, 3, w, mode="forward", tangent=[1.0])[0])
    rev = float(ad_derivative(scene, key, 3, w, mode="reverse")[0])
    # forward and reverse mode: the same derivative summed in another order (float32);
    # measured: 0 (start) and 1.9e-7 (end) relative
    assert fwd == pytest.approx(rev, rel=1e-5)
    assert fwd == pytest.approx(fd_derivative(scene, key, 3, w, [1.0]), rel=RTOL_CRN)


@pytest.mark.parametrize("integrator", ["path", "direct", "prb"])
@pytest.mark.parametrize("mode", ["forward", "reverse"])
def test_an_integrator_that_drops_the_derivative_through_the_mirror_raises(integrator, mode):
    """Instead of Mitsuba's silent zero (``path``, ``direct``) or its error from inside
    the loop (``prb``): a NotDifferentiableError naming the integrator and the fix."""
    scene = lit_mirror_scene(integrator)
    w = np.ones((W, W, 3), np.float32)
    with pytest.raises(NotDifferentiableError, match=f"'{integrator}' integrator.*mirrorpath"):
        ad_derivative(scene, "sensor.sensor_end", 1, w, mode=mode, tangent=[1.0])


def test_path_stays_allowed_where_nothing_reflects_in_a_delta_lobe():
    """A direct view (no mirror): ``path`` differentiates what the camera sees, so the
    guard lets it through (test_render_sweep_grad checks its values)."""
    scene = sweep_scene()
    w = np.ones((W, W, 3), np.float32)
    g = ad_derivative(scene, "sensor.sensor_end", 1, w, mode="reverse")
    assert np.isfinite(g).all() and abs(float(g[0])) > 0


def test_the_lit_room_built_by_mitsweep_is_differentiable_through_the_mirror():
    """build_scene picks mirrorpath for the lit room: a sweep gradient of its image is
    finite and non-zero (with ``path`` it would be refused)."""
    from mitsweep.render.api import camera_dict, mode_camera
    from mitsweep.render.scene import build_scene

    from test_render_api import small

    setup = small("sphere", 16, lighting="lit")
    kw, _ = mode_camera(setup, "sweep", None, None)
    d, info = build_scene(setup, camera_dict(setup, spp=4, sampler="independent", **kw))
    assert info["integrator"] == INTEGRATOR_NAME
    scene = mi.load_dict(d)
    g = ad_derivative(scene, "sensor.sensor_end", 1, np.ones((16, 16, 3), np.float32),
                      mode="reverse")
    assert np.isfinite(g).all() and abs(float(g[0])) > 0


@pytest.mark.slow   # 4 s; the gradient checks above stay in the default run
def test_inverse_problem_recovers_a_perturbed_sweep_end_through_the_mirror_in_a_lit_scene():
    """examples/inverse_sweep.py --lit, reduced: a sweep end 240 µm (20 % of the span) off
    is found by Gauss-Newton steps on the forward-mode Jacobian image through the mirror.
    Measured over 4 target seeds at 32 px, 32 spp, 20 steps: 2.3-7.8 % of the initial
    error left (one step's estimate scatters by ±40 µm); a zero gradient (``path``'s)
    cannot step at all, a wrong one stays off or diverges."""
    from test_render_sweep_grad import _inverse_sweep_example

    example = _inverse_sweep_example()
    out = example.recover_sweep_end(method="gauss-newton", width=32, spp=32, steps=20,
                                    target_spp=4096, perturbation=0.2, lit=True)
    assert out["error_fraction_of_initial"] < 0.2, out["error_mm"]
