"""What mitsweep's two Python integrators share (``integrator.depth_limited_integrator``):
the ``max_depth`` parameter, its default and range, no AOVs, and how they print."""

from __future__ import annotations

import pytest

import mitsuba as mi

from mitsweep.render import ad_integrator, integrator
from mitsweep.render.sensor import register

#: (module, default max_depth, class name): emissive scenes need camera → mirror →
#: emitter (2), lit ones add the light connection (3).
PLUGINS = [pytest.param(integrator, 2, "MirrorViewIntegrator", id="mirrorview"),
           pytest.param(ad_integrator, 3, "MirrorPathIntegrator", id="mirrorpath")]


@pytest.fixture(scope="module", autouse=True)
def registered():
    register()
    integrator.register_integrator()
    ad_integrator.register_integrator()


@pytest.mark.parametrize("module, default, cls", PLUGINS)
def test_python_integrators_take_a_depth_in_their_range(module, default, cls):
    name, deepest = module.INTEGRATOR_NAME, module.MAX_DEPTH
    plain = mi.load_dict({"type": name})
    assert str(plain) == f"{cls}[max_depth={default}]"
    assert plain.aov_names() == []
    for depth in (1, deepest):
        assert str(mi.load_dict({"type": name, "max_depth": depth})) == \
            f"{cls}[max_depth={depth}]"


@pytest.mark.parametrize("module, default, cls", PLUGINS)
@pytest.mark.parametrize("case", ["zero", "above", "unlimited"])
def test_python_integrators_refuse_a_depth_outside_their_range(module, default, cls, case):
    name, deepest = module.INTEGRATOR_NAME, module.MAX_DEPTH
    depth = {"zero": 0, "above": deepest + 1, "unlimited": -1}[case]
    # Mitsuba wraps the plugin's ValueError in its RuntimeError, message kept
    with pytest.raises(RuntimeError, match=rf"{name}: max_depth must be in 1\.\.{deepest}, "
                                           rf"got {depth}"):
        mi.load_dict({"type": name, "max_depth": depth})
