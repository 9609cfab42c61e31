"""Resources: memory estimates checked before large arrays are made, and the bundled setups.

Every step that allocates in proportion to a user-given size (a render's film, an IPSF
bank, a kernel, a deconvolution's FFT grids) states what it needs and calls
:func:`check_allocation` first, so that a size that cannot fit is refused in one line
(``render film 30000x30000: needs 48.0 GiB, 21.3 GiB available``) instead of ending in
a ``MemoryError`` or a Dr.Jit abort halfway through.

The limit is the smaller of the memory available now (``MemAvailable`` in
``/proc/meminfo``, else physical pages × page size from :func:`os.sysconf`) and a hard
cap: ``$MITSWEEP_MAX_MEMORY_GB`` GiB, default :data:`DEFAULT_MAX_MEMORY_GB`.

The files bundled with the package are found here too: the paper's setups and the other
examples of the repository's ``scenes/`` folder (:func:`bundled_setup`,
:func:`bundled_scenes_dir`), which a wheel carries as ``mitsweep/scenes``
(``pyproject.toml`` maps the folder into the package), so ``mitsweep figures`` and any
``SETUP`` argument given as a bundled name (``mitsweep sweep-range sphere``) work from an
installed package as from the source tree.

Only regular files are read: opening a named pipe (FIFO) blocks until a writer appears,
a character device may stream for ever, and a socket or a directory fails in a way that
names neither; inside Mitsuba's XML parser such a block cannot even be interrupted (the
process ignores SIGTERM there). So every path mitsweep reads or hands to Mitsuba (setups,
scenes and every file they reference, photos, banks, motion files) passes
:func:`require_regular_file` first, here at the base so that every layer can call it;
:func:`os.stat` itself never blocks on any of them.
"""

from __future__ import annotations

import logging
import math
import os
import stat
from pathlib import Path

__all__ = ["ResourceError", "check_allocation", "available_memory_bytes", "memory_cap_bytes",
           "format_bytes", "DEFAULT_MAX_MEMORY_GB", "MAX_MEMORY_ENV", "MAX_MEMORY_GB_LIMIT",
           "bundled_scenes_dir",
           "bundled_setup_names", "bundled_setup", "FileTypeError", "require_regular_file",
           "file_kind"]

logger = logging.getLogger(__name__)

GIB = 1 << 30
#: Hard cap on one step's memory, GiB, unless ``$MITSWEEP_MAX_MEMORY_GB`` says otherwise.
DEFAULT_MAX_MEMORY_GB = 64.0
MAX_MEMORY_ENV = "MITSWEEP_MAX_MEMORY_GB"
#: Largest cap ``$MITSWEEP_MAX_MEMORY_GB`` may set, GiB (1 PiB): a larger number is a
#: typo, and ``1e300`` GiB in bytes overflows every integer type.
MAX_MEMORY_GB_LIMIT = float(1 << 20)


class ResourceError(ValueError):
    """A requested size needs more memory than is available or allowed."""


def format_bytes(nbytes: float) -> str:
    """``1.5 GiB``, ``12.0 MiB``: binary units, one decimal.

    Parameters
    ----------
    nbytes : float
        A size in bytes.
    """
    for unit, scale in (("TiB", GIB << 10), ("GiB", GIB), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{int(nbytes)} B"


def available_memory_bytes() -> int:
    """Memory the system can give now without swapping: MemAvailable (Linux), else the
    physical memory (``os.sysconf``), else 0 when neither can be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024  # reported in kB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):
        return 0


def memory_cap_bytes() -> int:
    """The hard cap, bytes: ``$MITSWEEP_MAX_MEMORY_GB`` (a number of GiB in
    (0, :data:`MAX_MEMORY_GB_LIMIT`]) or 64 GiB.

    Raises
    ------
    ResourceError
        If the environment variable is set to something else; the message names it and
        the allowed range.
    """
    text = os.environ.get(MAX_MEMORY_ENV)
    if text is None or text.strip() == "":
        return int(DEFAULT_MAX_MEMORY_GB * GIB)
    try:
        gb = float(text)
    except ValueError:
        gb = math.nan
    if not (math.isfinite(gb) and 0 < gb <= MAX_MEMORY_GB_LIMIT):
        raise ResourceError(f"${MAX_MEMORY_ENV}: expected a positive number of GiB, at most "
                            f"{MAX_MEMORY_GB_LIMIT:.0f}, got {text!r}")
    return max(1, int(gb * GIB))


def check_allocation(what: str, nbytes: float) -> None:
    """Refuse ``what`` if it needs more than ``nbytes`` allow: the available memory or the cap.

    Parameters
    ----------
    what : str
        What is being made, as the user would name it (``"IPSF bank 9x9 points x 2
        depths, 31x31 px kernels"``); the message starts with it.
    nbytes : float
        The estimated peak memory of that step, bytes (a float: products of user sizes
        can exceed any integer type NumPy would use).

    Raises
    ------
    ResourceError
        ``WHAT: needs 48.0 GiB, 21.3 GiB available`` (or ``..., over the 64.0 GiB cap
        ($MITSWEEP_MAX_MEMORY_GB)``).
    """
    need = float(nbytes)
    cap = memory_cap_bytes()
    if need > cap:
        raise ResourceError(f"{what}: needs {format_bytes(need)}, over the "
                            f"{format_bytes(cap)} cap (${MAX_MEMORY_ENV}); use smaller sizes")
    avail = available_memory_bytes()
    if avail and need > avail:
        raise ResourceError(f"{what}: needs {format_bytes(need)}, {format_bytes(avail)} "
                            f"available; use smaller sizes or free memory")
    logger.debug("%s: %s of %s available", what, format_bytes(need), format_bytes(avail))


# -- files bundled with the package ------------------------------------------------------

#: Where an installed package keeps the repository's ``scenes/`` (pyproject.toml maps it).
_INSTALLED_SCENES = Path(__file__).resolve().parent / "scenes"
#: The source tree's ``scenes/`` (a checkout, or an editable install of one).
_SOURCE_SCENES = Path(__file__).resolve().parents[1] / "scenes"


def bundled_scenes_dir() -> Path:
    """The folder of the bundled setups: the installed package's ``mitsweep/scenes``,
    else the source tree's ``scenes/``.

    Raises
    ------
    FileNotFoundError
        Neither holds a setup (a broken installation).
    """
    for d in (_INSTALLED_SCENES, _SOURCE_SCENES):
        if any(d.glob("*.toml")):
            return d
    raise FileNotFoundError(f"no bundled setups in {_INSTALLED_SCENES} nor {_SOURCE_SCENES}: "
                            f"reinstall mitsweep")


def bundled_setup_names() -> list[str]:
    """Names of the bundled setups (their files' stems), sorted: ``paraboloid``,
    ``sphere``, ..."""
    return sorted(p.stem for p in bundled_scenes_dir().glob("*.toml"))


def bundled_setup(name: str) -> Path:
    """The setup file of a bundled setup, by name (``"sphere"`` →
    ``.../scenes/sphere.toml``).

    Parameters
    ----------
    name : str
        A bundled setup's name, e.g. ``"sphere"``.

    Raises
    ------
    ValueError
        ``name`` is not one of :func:`bundled_setup_names`.
    """
    names = bundled_setup_names()
    if name not in names:
        raise ValueError(f"{name!r}: not a bundled setup (bundled: {', '.join(names)})")
    return bundled_scenes_dir() / f"{name}.toml"


class FileTypeError(ValueError):
    """A path names a named pipe, device, socket or directory where mitsweep reads a
    regular file (a user error: one line, exit status 2 at the command line)."""


_KINDS = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISDIR, "a directory"))


def file_kind(mode: int) -> str:
    """What an ``st_mode`` names, in words (``"a regular file"``, ``"a named pipe
    (FIFO)"``, ...).

    Parameters
    ----------
    mode : int
        An ``os.stat_result.st_mode``.
    """
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def require_regular_file(path: str | os.PathLike, what: str) -> Path:
    """``path`` as a :class:`~pathlib.Path`, once it is known not to block a reader.

    The path is followed through symlinks (:func:`os.stat`, which does not open it).

    Parameters
    ----------
    path : path-like
        The file about to be read.
    what : str
        What the file is, for the message (``"setup file"``, ``"texture of
        scene.xml"``, ...).

    Returns
    -------
    Path
        ``Path(path)``. A path that does not exist (or cannot be examined) is returned
        too: the reader's own open then reports it, each with its own message for a
        missing file.

    Raises
    ------
    FileTypeError
        The path names a named pipe, a device, a socket or a directory: one line naming
        the path, what it is and what was expected.
    """
    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except (OSError, ValueError):  # missing, dangling, unreadable folder, NUL byte
        return p
    if not stat.S_ISREG(mode):
        raise FileTypeError(f"{p}: {file_kind(mode)}, not a regular file; the {what} must be "
                            f"a regular file")
    return p
