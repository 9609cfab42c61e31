"""Atomic file writes: write to a temporary file beside the target, then rename.

An interrupted or failed write never leaves a half-written file at the target, never
leaves the temporary behind, and never removes what was there before. Every failure to
write is a :class:`WriteError`: an ``OSError`` with the cause's errno whose message names
the target (``cannot write out.exr: No space left on device``), not the temporary.
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
import threading
from pathlib import Path
from collections.abc import Iterator

__all__ = ["WriteError", "atomic_path", "write_bytes_atomic", "write_text_atomic",
           "check_writable"]


class WriteError(OSError):
    """An output file could not be written.

    Constructed like ``OSError(errno, strerror, filename)`` (so it pickles across
    processes); its message is one line naming the file and the cause.
    """

    def __str__(self) -> str:
        return f"cannot write {self.filename}: {self.strerror}"


def _write_error(path: Path, exc: OSError) -> WriteError:
    if isinstance(exc, WriteError):
        return exc
    code = exc.errno if exc.errno is not None else errno.EIO
    cause = exc.strerror or str(exc) or os.strerror(code)
    return WriteError(code, cause, str(path))


def check_writable(path: str | Path) -> Path:
    """Raise :class:`WriteError` with a clear cause unless ``path`` can be created.

    Parameters
    ----------
    path : str or Path
        The file to be written: its folder must exist and be writable, and it must not
        be a directory itself (an existing file is fine: it will be replaced).

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.
    """
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise WriteError(errno.ENOENT, f"directory {parent} does not exist", str(p))
    if not os.access(parent, os.W_OK):
        if os.statvfs(parent).f_flag & os.ST_RDONLY:
            raise WriteError(errno.EROFS, f"directory {parent} is on a read-only file system",
                             str(p))
        raise WriteError(errno.EACCES, f"directory {parent} is not writable", str(p))
    if p.is_dir():
        raise WriteError(errno.EISDIR, "it is a directory", str(p))
    return p


_UMASK_LOCK = threading.Lock()


def _default_file_mode() -> int:
    """0o666 less the process umask: the mode ``open()`` would have given the file
    (``mkstemp`` creates 0o600, which would hide results from other users)."""
    with _UMASK_LOCK:
        mask = os.umask(0)
        os.umask(mask)
    return 0o666 & ~mask


def _fsync(path: Path) -> None:
    # Some file systems (delayed allocation, NFS, quotas) report a full disk only when
    # the data is flushed: flush before the rename so that the error is ours to report.
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path`` atomically.

    The temporary keeps the target's suffix (some writers pick the format from it). Any
    ``OSError`` raised while writing, flushing or renaming becomes a :class:`WriteError`
    naming ``path``; the temporary is removed.

    Parameters
    ----------
    path : str or Path
        The file to write.
    suffix : str, optional
        The temporary's suffix (default: ``path``'s own).
    """
    p = check_writable(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.",
                                   suffix=suffix or "".join(p.suffixes[-1:]),
                                   dir=p.parent if str(p.parent) else ".")
        os.close(fd)
    except OSError as exc:
        raise _write_error(p, exc) from exc
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _fsync(tmp_path)
        os.chmod(tmp_path, _default_file_mode())
        os.replace(tmp_path, p)
    except OSError as exc:
        raise _write_error(p, exc) from exc
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (through :func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
        The file to write.
    data : bytes
        Its whole content.

    Returns
    -------
    Path
        ``path``.
    """
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (through :func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
        The file to write.
    text : str
        Its whole content, written as UTF-8.

    Returns
    -------
    Path
        ``path``.
    """
    return write_bytes_atomic(path, text.encode("utf-8"))
