"""Only regular files are read: the one check before mitsweep opens a user's path.

Opening a named pipe (FIFO) for reading blocks until a writer appears, a character
device may stream for ever, and a socket or a directory fails in a way that names
neither. Inside Mitsuba's XML parser such a block cannot even be interrupted (the
process ignores SIGTERM there). So every path mitsweep reads or hands to Mitsuba (setups,
scenes and every file they reference, photos, banks, motion files) passes
:func:`require_regular_file` first; :func:`os.stat` itself never blocks on any of them.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

__all__ = ["FileTypeError", "require_regular_file", "file_kind"]


class FileTypeError(ValueError):
    """A path names a named pipe, device, socket or directory where mitsweep reads a
    regular file (a user error: one line, exit status 2 at the command line)."""


_KINDS = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISDIR, "a directory"))


def file_kind(mode: int) -> str:
    """What an ``st_mode`` names, in words (``"a regular file"``, ``"a named pipe
    (FIFO)"``, ...)."""
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
