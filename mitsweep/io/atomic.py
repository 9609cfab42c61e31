"""Atomic file writes: write to a temporary file beside the target, then rename.

An interrupted write never leaves a half-written file at the target, and never removes
what was there before.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import threading
from pathlib import Path
from typing import Iterator

__all__ = ["atomic_path", "write_bytes_atomic", "write_text_atomic", "check_writable"]


def check_writable(path: str | Path) -> Path:
    """Raise ``OSError`` with a clear message unless ``path`` can be created."""
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise OSError(f"{p}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise OSError(f"{p}: directory {parent} is not writable")
    if p.is_dir():
        raise OSError(f"{p}: is a directory")
    return p


_UMASK_LOCK = threading.Lock()


def _default_file_mode() -> int:
    """0o666 less the process umask: the mode ``open()`` would have given the file
    (``mkstemp`` creates 0o600, which would hide results from other users)."""
    with _UMASK_LOCK:
        mask = os.umask(0)
        os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` atomically.

    The temporary keeps the target's suffix (some writers pick the format from it).
    """
    p = check_writable(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=suffix or "".join(p.suffixes[-1:]),
                               dir=p.parent if str(p.parent) else ".")
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, _default_file_mode())
        os.replace(tmp_path, p)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))
