"""Where mitsweep keeps what it can recompute: the user's cache directory.

``$MITSWEEP_CACHE_DIR``, else ``$MITSWEEP_CACHE`` (the name the mirror-mesh cache has
read since it was written), else ``$XDG_CACHE_HOME/mitsweep``, else
``~/.cache/mitsweep`` (the XDG Base Directory default). Each kind of entry has its own
subdirectory (``banks``, ``meshes``). ``MITSWEEP_CACHE=0`` (or ``off``, ``false``, ``no``)
turns the cache off: :func:`cache_enabled` is then False and nothing is written.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_root", "cache_enabled"]

#: Values of ``$MITSWEEP_CACHE`` that turn the cache off instead of naming a folder.
_OFF = ("0", "off", "false", "no")


def _switch() -> str:
    return os.environ.get("MITSWEEP_CACHE", "").strip().lower()


def cache_enabled() -> bool:
    """Whether mitsweep caches on disk: not where ``$MITSWEEP_CACHE`` is ``0``/``off``."""
    return _switch() not in _OFF


def cache_root() -> Path:
    """The cache directory (not created here)."""
    if os.environ.get("MITSWEEP_CACHE_DIR"):
        return Path(os.environ["MITSWEEP_CACHE_DIR"])
    if os.environ.get("MITSWEEP_CACHE") and _switch() not in _OFF:
        return Path(os.environ["MITSWEEP_CACHE"])
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"
    return base / "mitsweep"
