"""One vocabulary, checked by machine (issue 26): the unit rule on public names.

The rule (``mitsweep.deprecation``, ``docs/design.md``): a length in millimetres carries no
unit suffix; every other unit says its unit. So no public parameter, dataclass field or
property ends in ``_mm`` (ratios such as ``steps_per_mm`` name a unit *per* length and are
kept), and the pixel pitch is called ``pixel_pitch`` everywhere (not ``pitch``,
``pitch_mm`` or ``pixel_size_mm``). A former name kept for one release through
``mitsweep.deprecation`` is an alias, not an offence.

*Enforced* for the whole package (``ENFORCED``); ``pytest tests/test_vocabulary.py -s``
prints any offence per package.
"""

import dataclasses
import importlib
import inspect
import pkgutil
import re
from collections import Counter

import pytest

from mitsweep.deprecation import RENAMED

#: Packages whose public names keep the rule: all of mitsweep since every package was
#: converted (143 names against the rule when the check was written, 0 now).
ENFORCED = ("mitsweep",)

AGAINST = re.compile(r"(?<!_per)_mm$|^pitch$|^pitch_mm$|^pixel_size_mm$")


def _modules():
    root = importlib.import_module("mitsweep")
    for info in pkgutil.walk_packages(root.__path__, "mitsweep."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts[1:]) or parts[1] == "cli":
            continue
        try:
            yield importlib.import_module(info.name)
        except ImportError:
            continue


def _parameters(obj):
    try:
        return list(inspect.signature(obj).parameters)
    except (TypeError, ValueError):
        return []


def _names(module):
    """(qualified place, name) of each public parameter, field and property defined in
    ``module``."""
    for name, obj in vars(module).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
            continue
        if inspect.isfunction(obj):
            for p in _parameters(obj):
                yield f"{module.__name__}.{name}({p})", p
        elif inspect.isclass(obj):
            yield from _class_names(module.__name__, obj)


def _class_names(modname, cls):
    where = f"{modname}.{cls.__qualname__}"
    if dataclasses.is_dataclass(cls):
        for f in dataclasses.fields(cls):
            if not f.name.startswith("_"):
                yield f"{where}.{f.name}", f.name
    for p in _parameters(cls):
        yield f"{where}({p})", p
    for attr, member in vars(cls).items():
        if attr.startswith("_"):
            continue
        if isinstance(member, property):
            yield f"{where}.{attr}", attr
        elif inspect.isfunction(member) or isinstance(member, (classmethod, staticmethod)):
            func = getattr(member, "__func__", member)
            for p in _parameters(func):
                yield f"{where}.{attr}({p})", p


def _is_alias(place: str, name: str) -> bool:
    """A former attribute name kept by ``renamed_fields`` (a former keyword never shows:
    ``renamed_keywords`` keeps the function's new signature)."""
    return place in RENAMED


def offences(prefix: str = "mitsweep") -> list[str]:
    """Public names under ``prefix`` against the unit rule (deprecated aliases excepted).

    Parameters
    ----------
    prefix : str
        A package or module name; its submodules are included.
    """
    out = set()
    for mod in _modules():
        if mod.__name__ != prefix and not mod.__name__.startswith(prefix + "."):
            continue
        for place, name in _names(mod):
            if AGAINST.search(name) and not _is_alias(place, name):
                out.add(place)
    return sorted(out)


@pytest.mark.parametrize("package", ENFORCED)
def test_enforced_packages_keep_the_unit_rule(package):
    assert offences(package) == []


def test_report_names_against_the_rule():
    found = offences()
    by_package = Counter(".".join(p.split(".")[:2]) for p in found)
    print(f"\npublic names against the unit rule: {len(found)}")
    for pkg, n in by_package.most_common():
        print(f"  {pkg}: {n}")
    for place in found:
        print(f"    {place}")


def test_the_checker_finds_a_planted_offence_and_passes_an_alias():
    import types

    from mitsweep.deprecation import renamed_keywords

    mod = types.ModuleType("mitsweep._planted")

    def f(depth_mm=1.0, steps_per_mm=2.0):
        return depth_mm

    @renamed_keywords(depth_mm="depth")
    def g(depth=1.0):
        return depth

    f.__module__ = g.__module__ = mod.__name__
    mod.f, mod.g = f, g
    names = dict(_names(mod))
    flagged = [p for p, n in names.items() if AGAINST.search(n) and not _is_alias(p, n)]
    assert flagged == ["mitsweep._planted.f(depth_mm)"]
