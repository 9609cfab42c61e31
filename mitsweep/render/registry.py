"""Registration of mitsweep's Mitsuba plugins for the current variant.

Each plugin is a class at module scope in its own module (:mod:`.focalsweep`,
:mod:`.integrator_base`, :mod:`.mirrorview`, :mod:`.mirrorpath`), built from the
variant set when the module runs and registered at the module's end, as Mitsuba's own
Python plugins are. :func:`register` imports those modules after selecting a variant;
after a change of variant it reloads them (the shared base first), as Mitsuba's
``set_variant`` reloads ``mitsuba.ad.integrators``: Mitsuba keeps plugins per variant.
"""

from __future__ import annotations

import importlib

from ..backend import set_mitsuba_variant

__all__ = ["register"]


def register() -> str:
    """Register mitsweep's plugins (``focalsweep``, ``mirrorview``, ``mirrorpath``) for
    the current Mitsuba variant; idempotent.

    When no variant is set yet, selects one through
    :func:`mitsweep.backend.set_mitsuba_variant`; call again after changing the variant.
    Returns the variant.
    """
    import mitsuba as mi

    variant = mi.variant() or set_mitsuba_variant()
    # Imported for the variant now set (a first import registers the plugin) ...
    from . import focalsweep, integrator_base, mirrorpath, mirrorview
    # ... or reloaded for it, the base before the integrators deriving from it.
    for module in (focalsweep, integrator_base, mirrorview, mirrorpath):
        if module.VARIANT != variant:
            importlib.reload(module)
    return variant
