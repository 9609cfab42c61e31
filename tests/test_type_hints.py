"""The public API is annotated: every function, method and class ``__init__`` named in a
public module's ``__all__`` has an annotation for each parameter and for its return, and
the annotations resolve (``typing.get_type_hints``, what autodoc and type checkers do).

The modules not annotated yet are listed in :data:`NOT_YET`, so the remaining work stays
visible; a listed module that becomes complete fails the test until it leaves the list.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import typing

import pytest

import mitsweep

#: Modules whose public names are not annotated yet (others were editing them when the
#: rest of the API was annotated). Remove a module from here once it is done.
NOT_YET: set[str] = set()


def public_modules() -> list[str]:
    """Every module of the package except the entry point (``python -m mitsweep``)."""
    return sorted(m.name for m in pkgutil.walk_packages(mitsweep.__path__, "mitsweep.")
                  if not m.name.endswith("__main__"))


def _callables(module) -> list[tuple[str, typing.Callable]]:
    """(qualified name, function) for the functions of ``__all__`` defined in ``module``
    and the public methods (``__init__`` included) of its classes."""
    out = []
    for name in getattr(module, "__all__", []):
        obj = getattr(module, name)
        if getattr(obj, "__module__", None) != module.__name__:
            continue  # re-exported: checked where it is defined
        if inspect.isclass(obj):
            for attr, member in vars(obj).items():
                if attr.startswith("_") and attr != "__init__":
                    continue
                if isinstance(member, (staticmethod, classmethod)):
                    member = member.__func__
                elif isinstance(member, property):
                    member = member.fget
                if inspect.isfunction(member) and member.__module__ == module.__name__:
                    out.append((f"{name}.{attr}", member))
        elif inspect.isfunction(obj):
            out.append((name, obj))
    return out


def missing_annotations(module) -> list[str]:
    """``name(param, ...) -> ?`` for each public callable of ``module`` that lacks an
    annotation, ``name: error`` for one whose annotations do not resolve."""
    problems = []
    for qualname, fn in _callables(module):
        sig = inspect.signature(fn)
        bare = [p.name for p in sig.parameters.values()
                if p.annotation is inspect.Parameter.empty and p.name not in ("self", "cls")]
        no_return = sig.return_annotation is inspect.Signature.empty
        if bare or no_return:
            problems.append(f"{qualname}({', '.join(bare)})" + (" -> ?" if no_return else ""))
            continue
        try:
            typing.get_type_hints(fn)
        except Exception as exc:  # a NameError, or a bad expression in a string annotation
            problems.append(f"{qualname}: annotations do not resolve ({exc})")
    return problems


@pytest.mark.parametrize("name", [m for m in public_modules() if m not in NOT_YET])
def test_public_api_is_annotated(name):
    problems = missing_annotations(importlib.import_module(name))
    assert not problems, f"{name}: " + "; ".join(problems)


def test_not_yet_list_names_only_unfinished_modules():
    """The exemption list shrinks as modules are annotated: a complete one must leave it."""
    modules = set(public_modules())
    assert NOT_YET <= modules, f"not modules of mitsweep: {sorted(NOT_YET - modules)}"
    done = [m for m in sorted(NOT_YET) if not missing_annotations(importlib.import_module(m))]
    assert not done, f"annotated now, remove from NOT_YET: {done}"


def test_checker_sees_a_missing_annotation():
    """The check itself: a bare parameter, a missing return and an unresolvable name."""
    import types

    module = types.ModuleType("mitsweep_fake")

    def bare(x, y: int) -> int: ...

    def no_return(x: int): ...

    def unresolved(x: "NoSuchType") -> int: ...  # noqa: F821

    class Thing:
        def __init__(self, size): ...

    for obj in (bare, no_return, unresolved, Thing):
        obj.__module__ = module.__name__
        setattr(module, obj.__name__, obj)
    Thing.__init__.__module__ = module.__name__
    module.__all__ = ["bare", "no_return", "unresolved", "Thing"]
    problems = missing_annotations(module)
    assert problems[0] == "bare(x)"
    assert problems[1] == "no_return() -> ?"
    assert problems[2].startswith("unresolved: annotations do not resolve")
    assert problems[3] == "Thing.__init__(size) -> ?"
