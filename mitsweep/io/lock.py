"""An advisory lock on a directory, so that two runs never write one dataset at once.

The lock is ``fcntl.flock`` on ``DIR/.mitsweep.lock``; the file holds who has it (pid,
host, start time, command) as JSON, for the message that refuses a second run. The
kernel releases a flock when its holder dies, even by SIGKILL, so a lock can never be
stale: a file whose lock is free but which still names a holder was left by a run that
died, and the next run overwrites it (and says so). On a clean release the file is
removed while still locked; a waiter that then gets the lock on the removed file sees
that the path no longer names it and starts over on the new one.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import math
import os
import socket
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from .atomic import WriteError

__all__ = ["LOCK_FILE", "DirectoryLock", "DirectoryLocked"]

logger = logging.getLogger(__name__)

LOCK_FILE = ".mitsweep.lock"
#: Seconds between attempts while waiting for a held lock.
POLL_S = 0.2


class DirectoryLocked(OSError):
    """Another live process holds the directory's lock (errno EBUSY); the message names
    the holder."""

    def __str__(self) -> str:
        return str(self.strerror)


def _describe(holder: dict) -> str:
    pid = holder.get("pid", "?")
    host = holder.get("host", "?")
    since = holder.get("since", "?")
    command = holder.get("command")
    text = f"pid {pid} on {host}, since {since}"
    return text + (f" ({command})" if command else "")


class DirectoryLock:
    """Exclusive advisory lock on a directory, held for a run (a context manager).

    Parameters
    ----------
    directory : path
        Must exist; the lock file is created in it.
    wait : float or None
        ``None``: refuse at once if another process holds the lock; a number of seconds
        (``math.inf`` for ever) to wait for it first.
    command : str, optional
        Recorded for the message another run shows; default the process's argv.
    """

    def __init__(self, directory: str | Path, *, wait: float | None = None,
                 command: str | None = None) -> None:
        self.directory = Path(directory)
        self.path = self.directory / LOCK_FILE
        self.wait = wait
        self.command = command if command is not None else " ".join(
            ["mitsweep", *sys.argv[1:]] if sys.argv and "mitsweep" in sys.argv[0] else sys.argv)
        self._fd: int | None = None
        #: The holder record left by a run that died, when this lock took it over.
        self.taken_over: dict | None = None

    # -- acquiring ------------------------------------------------------------------
    def acquire(self) -> DirectoryLock:
        deadline = None if self.wait is None else time.monotonic() + self.wait
        told = False
        while True:
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = self._read(fd)
                os.close(fd)
                if deadline is None or time.monotonic() >= deadline:
                    raise self._busy(holder) from None
                if not told:
                    logger.warning("%s is in use by %s; waiting%s", self.directory,
                                   _describe(holder) if holder else "another process",
                                   "" if self.wait is None or math.isinf(self.wait)
                                   else f" up to {self.wait:g} s")
                    told = True
                time.sleep(POLL_S)
                continue
            except BaseException:
                os.close(fd)
                raise
            # The holder may have removed the file between our open and our flock: then
            # we hold a lock on a file nobody else will look at; start over.
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            self._fd = fd
            break
        try:
            left = self._read(fd)
            if left:
                self.taken_over = left
                logger.warning("%s: taking over the lock of %s, which ended without "
                               "releasing it (killed or crashed)", self.directory,
                               _describe(left))
            self._write(fd)
        except BaseException:
            self.release()
            raise
        return self

    def _open(self) -> int:
        try:
            return os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise WriteError(exc.errno, exc.strerror, str(self.path)) from None

    def _busy(self, holder: dict) -> DirectoryLocked:
        what = _describe(holder) if holder else "another process (no details recorded)"
        hint = (f"; gave up after waiting {self.wait:g} s" if self.wait
                else "; wait for it to finish or pass --wait")
        return DirectoryLocked(errno.EBUSY, f"{self.directory} is in use by another mitsweep "
                                            f"run: {what}{hint}")

    @staticmethod
    def _read(fd: int) -> dict:
        try:
            data = os.pread(fd, 1 << 16, 0)
        except OSError:
            return {}
        if not data.strip():
            return {}
        try:
            holder = json.loads(data.decode("utf-8", "replace"))
        except ValueError:
            return {"command": "unreadable lock record"}
        return holder if isinstance(holder, dict) else {}

    def _write(self, fd: int) -> None:
        record = {"pid": os.getpid(), "host": socket.gethostname(),
                  "since": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                  "command": self.command}
        data = (json.dumps(record) + "\n").encode()
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, data, 0)
        except OSError as exc:
            raise WriteError(exc.errno, exc.strerror, str(self.path)) from None

    # -- releasing ------------------------------------------------------------------
    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            try:
                if os.path.samestat(os.fstat(fd), os.stat(self.path)):
                    os.unlink(self.path)  # still ours: remove it while locked
            except OSError:  # gone, or a read-only directory: the next run takes it over
                pass
        finally:
            os.close(fd)  # closing releases the flock

    @property
    def held(self) -> bool:
        return self._fd is not None

    def __enter__(self) -> DirectoryLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
