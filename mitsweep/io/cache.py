"""Where mitsweep keeps what it can recompute: the user's cache directory.

``$MITSWEEP_CACHE_DIR``, else ``$MITSWEEP_CACHE`` (the name the mirror-mesh cache has
read since it was written), else ``$XDG_CACHE_HOME/mitsweep``, else
``~/.cache/mitsweep`` (the XDG Base Directory default). Each kind of entry has its own
subdirectory (``banks``, ``meshes``).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_root"]


def cache_root() -> Path:
    """The cache directory (not created here)."""
    for name in ("MITSWEEP_CACHE_DIR", "MITSWEEP_CACHE"):
        if os.environ.get(name):
            return Path(os.environ[name])
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and os.path.isabs(xdg) else Path.home() / ".cache"
    return base / "mitsweep"
