"""Where mitsweep keeps what it can recompute: the user's cache directory, optional.

The cache's folder is the first of

1. ``$MITSWEEP_CACHE_DIR`` (any non-empty value is a path);
2. ``$MITSWEEP_CACHE`` when it is a path: absolute, starting with ``~``, or holding a
   ``/`` (``./cache`` for a folder in the working directory);
3. ``$XDG_CACHE_HOME/mitsweep`` when ``$XDG_CACHE_HOME`` is absolute (the XDG Base
   Directory rule: a relative one is ignored);
4. ``~/.cache/mitsweep`` (the XDG default), where the home is ``$HOME`` when it is an
   absolute path, the account's home directory when ``$HOME`` is unset, and none when
   ``$HOME`` is set but empty or relative: a cache is never put at ``/.cache``.

``$MITSWEEP_CACHE`` also switches the cache: ``1``, ``on``, ``true`` or ``yes`` (any
case) turn it on at the default folder (steps 1, 3, 4; the same as leaving it unset),
``0``, ``off``, ``false`` or ``no`` turn it off (nothing is read or written). Any other
value that is not a path (``maybe``) is refused with :class:`CacheSettingError` when the
cache is first used: a bare word is more likely a mistyped switch than a folder.

The cache is optional. :func:`cache_dir` creates one kind's subdirectory (``banks``,
``meshes``) and checks that a file can be written there; where it cannot (no home, a
read-only or full disk, a file in the way) it logs one warning per folder and process
and returns None, and the caller works in memory.
"""

from __future__ import annotations

import logging
import os
import tempfile
from pathlib import Path

__all__ = ["CacheSettingError", "CacheUnavailable", "cache_root", "cache_enabled",
           "cache_dir", "warn_unusable", "forget_warnings", "CACHE_ON", "CACHE_OFF"]

logger = logging.getLogger(__name__)

#: Values of ``$MITSWEEP_CACHE`` (lower case) that turn the cache on at its default folder.
CACHE_ON = ("1", "on", "true", "yes")
#: Values of ``$MITSWEEP_CACHE`` (lower case) that turn the cache off.
CACHE_OFF = ("0", "off", "false", "no")

_warned: set[str] = set()


class CacheSettingError(ValueError):
    """``$MITSWEEP_CACHE`` is neither a switch nor a path (a user error: exit status 2)."""


class CacheUnavailable(OSError):
    """No cache folder can be named (``$HOME`` empty and nothing else set)."""


def _is_path(value: str) -> bool:
    return os.path.isabs(value) or value.startswith("~") or "/" in value or \
        (os.sep != "/" and os.sep in value)


def _setting() -> tuple[bool, Path | None]:
    """``(enabled, folder named by $MITSWEEP_CACHE or None)``."""
    raw = os.environ.get("MITSWEEP_CACHE", "").strip()
    word = raw.lower()
    if word in ("", *CACHE_ON):
        return True, None
    if word in CACHE_OFF:
        return False, None
    if _is_path(raw):
        return True, Path(raw).expanduser()
    raise CacheSettingError(
        f"MITSWEEP_CACHE: must be {'/'.join(CACHE_ON)} (cache on, default folder), "
        f"{'/'.join(CACHE_OFF)} (cache off) or a folder path (absolute, ~/..., or with a "
        f"/ such as ./{raw}), got {raw!r}")


def cache_enabled() -> bool:
    """Whether mitsweep caches on disk: not where ``$MITSWEEP_CACHE`` is ``0``/``off``/
    ``false``/``no``.

    Raises
    ------
    CacheSettingError
        If ``$MITSWEEP_CACHE`` is neither a switch nor a path.
    """
    return _setting()[0]


def _home() -> Path | None:
    home = os.environ.get("HOME")
    if home is None:
        try:
            return Path.home()  # the account's home (pwd)
        except (KeyError, RuntimeError):  # no entry for this uid
            return None
    return Path(home) if os.path.isabs(home) else None


def cache_root() -> Path:
    """The cache directory (not created here).

    Raises
    ------
    CacheSettingError
        If ``$MITSWEEP_CACHE`` is neither a switch nor a path.
    CacheUnavailable
        If no folder can be named: ``$HOME`` is empty or relative and neither
        ``$MITSWEEP_CACHE_DIR``, ``$MITSWEEP_CACHE`` nor ``$XDG_CACHE_HOME`` names one.
    """
    _, named = _setting()
    if os.environ.get("MITSWEEP_CACHE_DIR"):
        return Path(os.environ["MITSWEEP_CACHE_DIR"]).expanduser()
    if named is not None:
        return named
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and os.path.isabs(xdg):
        return Path(xdg) / "mitsweep"
    home = _home()
    if home is None:
        raise CacheUnavailable(f"HOME is {os.environ.get('HOME', '')!r}, not an absolute "
                               f"path, and neither MITSWEEP_CACHE_DIR nor XDG_CACHE_HOME "
                               f"names a folder")
    return home / ".cache" / "mitsweep"


def forget_warnings() -> None:
    """Forget which cache folders :func:`warn_unusable` has warned about, so that each
    warns once more (a process whose cache setting changed; a test that expects the
    warning).
    """
    _warned.clear()


def warn_unusable(folder: Path | str | None, exc: BaseException) -> None:
    """Log that the cache at ``folder`` is not used, once per folder and process.

    Parameters
    ----------
    folder : Path or str or None
        The cache folder that could not be used; None where no folder could even be
        chosen (the message then names no folder).
    exc : BaseException
        Why: its ``strerror`` (an :class:`OSError`'s) or its text goes in the message.
    """
    key = str(folder)
    if key in _warned:
        return
    _warned.add(key)
    reason = getattr(exc, "strerror", None) or str(exc)
    where = f"{folder}: " if folder is not None else ""
    logger.warning("%s%s; working without the cache (set MITSWEEP_CACHE_DIR to a "
                   "writable folder, or MITSWEEP_CACHE=0)", where, reason)


def cache_dir(kind: str) -> Path | None:
    """The cache's ``kind`` subdirectory, created and writable; None where the cache is
    off, or (after one warning) where no usable folder exists.

    Parameters
    ----------
    kind : str
        The subdirectory, e.g. ``"banks"`` or ``"meshes"``.

    Raises
    ------
    CacheSettingError
        If ``$MITSWEEP_CACHE`` is neither a switch nor a path.
    """
    if not cache_enabled():
        return None
    try:
        folder = cache_root() / kind
    except CacheUnavailable as exc:
        warn_unusable(None, exc)
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
        # a write, not os.access: root passes access checks on a read-only mount
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        warn_unusable(folder, exc)
        return None
    return folder
