"""Renamed names that keep working for one release, with a :class:`DeprecationWarning`.

The vocabulary rule (``docs/design.md``): a length in millimetres carries no unit suffix
(``depth``, ``pixel_pitch``, ``focus_min``); every other unit says its unit (``pitch_um``,
``exposure_s``, ``radius_px``, ``tilt_deg``). A name renamed to keep the rule stays
accepted under its former name for one release through the two helpers here, so that a
user's script warns instead of breaking:

- :func:`renamed_keywords` for a function's or method's keyword arguments;
- :func:`renamed_fields` for a (data)class: the former field name as a constructor keyword
  and as a read-only attribute.

Files written by earlier versions (JSON manifests, bank files, cache keys, TOML) keep their
keys: what is renamed here is the Python name only.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["renamed_keywords", "renamed_fields", "RENAMED"]

F = TypeVar("F", bound=Callable[..., Any])
C = TypeVar("C", bound=type)

#: Every rename made through this module: ``"qualified.name(old)" -> "new"``. The
#: vocabulary test reads it to tell a deprecated alias from a name against the rule.
RENAMED: dict[str, str] = {}


def _take_old(owner: str, kwargs: dict, old: str, new: str, stacklevel: int) -> None:
    if old not in kwargs:
        return
    warnings.warn(f"{owner}({old}=...) is deprecated: use {new}=", DeprecationWarning,
                  stacklevel=stacklevel)
    if new in kwargs:
        raise TypeError(f"{owner}: give {new} or its deprecated name {old}, not both")
    kwargs[new] = kwargs.pop(old)


def renamed_keywords(**old_to_new: str) -> Callable[[F], F]:
    """Decorate a function so that its former keyword names still work, with a warning.

    Parameters
    ----------
    **old_to_new : str
        Each former keyword name, mapped to the parameter's present name.

    Returns
    -------
    callable
        A decorator. The wrapped function takes ``old=value`` as ``new=value`` after a
        :class:`DeprecationWarning`; giving both is a :class:`TypeError`.

    Examples
    --------
    >>> @renamed_keywords(depth_mm="depth")
    ... def blur(depth=500.0):
    ...     return depth
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     blur(depth_mm=250.0)
    250.0
    """
    def decorate(func: F) -> F:
        owner = func.__qualname__
        for old, new in old_to_new.items():
            RENAMED[f"{func.__module__}.{owner}({old})"] = new

        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            for old, new in old_to_new.items():
                _take_old(owner, kwargs, old, new, stacklevel=3)
            return func(*args, **kwargs)

        return wrapper  # type: ignore[return-value]  # same signature as func

    return decorate


def renamed_fields(**old_to_new: str) -> Callable[[C], C]:
    """Decorate a class (a dataclass, typically) whose fields or attributes were renamed.

    The former name stays accepted as a constructor keyword and readable as an attribute
    (read-only: it is not a field, so :func:`dataclasses.replace` and ``asdict`` never see
    it), each with a :class:`DeprecationWarning`.

    Parameters
    ----------
    **old_to_new : str
        Each former attribute name, mapped to its present name.

    Returns
    -------
    callable
        A class decorator; it returns the same class, amended.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @renamed_fields(depth_mm="depth")
    ... @dataclass
    ... class Plane:
    ...     depth: float
    >>> import warnings
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     Plane(depth_mm=3.0).depth_mm
    3.0
    """
    def decorate(cls: C) -> C:
        init = cls.__init__  # type: ignore[misc]  # mypy forbids reading __init__ off a class
        owner = cls.__qualname__

        @functools.wraps(init)
        def accepting_old(self, *args, **kwargs):
            for old, new in old_to_new.items():
                _take_old(owner, kwargs, old, new, stacklevel=3)
            init(self, *args, **kwargs)

        cls.__init__ = accepting_old  # type: ignore[misc]  # and assigning it: the point here
        for old, new in old_to_new.items():
            RENAMED[f"{cls.__module__}.{owner}.{old}"] = new
            setattr(cls, old, _alias(owner, old, new))
        return cls

    return decorate


def _alias(owner: str, old: str, new: str) -> property:
    def read(self):
        warnings.warn(f"{owner}.{old} is deprecated: use {owner}.{new}", DeprecationWarning,
                      stacklevel=2)
        return getattr(self, new)

    return property(read, doc=f"Deprecated alias of :attr:`{new}` (read-only).")
