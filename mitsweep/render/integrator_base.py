"""What mitsweep's Python integrators share: :class:`DepthLimitedIntegrator`.

A plugin module, bound to the Mitsuba variant set when it runs (:data:`VARIANT`), as
Mitsuba's ``mitsuba/python/ad/integrators/common.py``: :func:`mitsweep.render.register`
imports it before the integrators that derive from it, and reloads it first after a
change of variant (see :mod:`mitsweep.render.focalsweep`).
"""

from __future__ import annotations

from typing import cast

import mitsuba as mi

from ..backend import set_mitsuba_variant

__all__ = ["DepthLimitedIntegrator", "VARIANT"]

#: The Mitsuba variant this module's class was built for (mitsweep's, set here, when
#: the module is imported with none set: for its documentation or types).
VARIANT: str = mi.variant() or set_mitsuba_variant()


class DepthLimitedIntegrator(mi.SamplingIntegrator):
    """A ``mi.SamplingIntegrator`` that reads the plugin parameter ``max_depth``
    (default :attr:`DEFAULT_DEPTH`) and refuses one outside ``1..MAX_DEPTH`` with a
    ValueError naming plugin :attr:`NAME`; no AOVs; printed as ``ClassName[max_depth=N]``.
    A subclass sets the three class attributes and defines ``sample``.

    Parameters
    ----------
    props : mi.Properties
        The plugin's properties, as Mitsuba passes them to the constructor; read:
        ``max_depth`` (int, the longest path in segments, as ``path`` counts them).
    """

    #: Plugin name, for error messages.
    NAME: str = ""
    #: Deepest path the integrator unrolls.
    MAX_DEPTH: int = 1
    #: ``max_depth`` when the scene gives none.
    DEFAULT_DEPTH: int = 1

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        # Properties.get is typed ``object``: its type is the stored value's
        depth = int(cast(int, props.get("max_depth", self.DEFAULT_DEPTH)))
        if not 1 <= depth <= self.MAX_DEPTH:
            raise ValueError(f"{self.NAME}: max_depth must be in 1..{self.MAX_DEPTH}, "
                             f"got {depth}")
        self.max_depth = depth

    def aov_names(self) -> list[str]:
        return []

    def to_string(self) -> str:
        return f"{type(self).__name__}[max_depth={self.max_depth}]"
