"""Serve a device model on a pseudo-terminal (real serial I/O for the drivers).

:class:`PtyDevice` opens a pty pair (``os.openpty``) and runs a device model in a thread
on the master side; the driver opens the slave path (``/dev/pts/N``) with pyserial
exactly like a real port. Closing the master mid-run is an unplugged cable: the driver's
next read or write fails like a vanished USB adapter.

The device thread asks the OS for a raised scheduling priority (:data:`DEVICE_NICE`)
where it may (root or CAP_SYS_NICE; elsewhere it keeps the default): it stands in for
separate hardware, which the host's load cannot slow, so a loaded test machine (other
tests in parallel, CI's spinning processes) must starve the host under test, not the
simulated device answering it.
"""

from __future__ import annotations

import fcntl
import logging
import os
import select
import struct
import termios
import threading
import time
import tty

from .base import Model

__all__ = ["PtyDevice", "DEVICE_NICE", "raise_priority"]

#: Niceness asked for a simulated device's thread or process (lower runs first).
DEVICE_NICE = -10

logger = logging.getLogger(__name__)


def raise_priority(tid: int | None = None, nice: int = DEVICE_NICE) -> bool:
    """Set thread (or process) ``tid`` (default: the calling thread) to ``nice`` if the
    OS allows it; True if it did. Never raises: the priority is a help, not a need.

    Parameters
    ----------
    tid : int, optional
        A native thread id, or a process id (default: the calling thread).
    nice : int
        The niceness to set (negative: higher priority; needs the privilege).
    """
    try:
        tid = threading.get_native_id() if tid is None else tid
        os.setpriority(os.PRIO_PROCESS, tid, nice)
    except (AttributeError, OSError):
        return False
    return True


class PtyDevice:
    """Serve a device model on a pseudo-terminal.

    Use as a context manager; :attr:`port` is the slave path to give the driver.

    Parameters
    ----------
    model : ArduinoModel or ZaberModel
    poll_s : float
        Loop period (s) when nothing is due; bounds the emission latency of events.
    """

    def __init__(self, model: Model, *, poll_s: float = 0.001) -> None:
        self.model = model
        self.poll_s = poll_s
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.port = os.ttyname(self.slave)
        # packet mode: the master learns when the slave's input is flushed, which
        # pyserial does when it opens the port -- the moment a real Uno resets
        self.packet_mode = bool(getattr(model, "reset_on_open", False)) and hasattr(termios, "TIOCPKT")
        if self.packet_mode:
            fcntl.ioctl(self.master, termios.TIOCPKT, struct.pack("i", 1))
        self.unplugged = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"sim-{self.port}", daemon=True)
        self._lock = threading.Lock()

    def __enter__(self) -> PtyDevice:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        with self._lock:
            out = self.model.boot(time.monotonic())
            if self.packet_mode:
                # The host's open resets the board (a flush, seen below), so what the board
                # prints at power-on reaches no one. Not emitting it closes a race: a
                # power-on READY written after the host's flush but before this thread read
                # the flush would reach the host besides the READY of the reset, mid-session.
                self.model.cancel_scheduled()
                out = []
            for data in out:
                self._write_all(data)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        self._close_fds()

    def unplug(self) -> None:
        """Pull the cable now."""
        with self._lock:
            self.model.on_unplug(time.monotonic())
            self._close_fds()

    def _write_all(self, data: bytes) -> None:
        """Write every byte (a pty may take a write in parts; the rest must not be lost)."""
        view = memoryview(data)
        while view:
            view = view[os.write(self.master, view):]

    def _close_fds(self) -> None:
        if not self.unplugged:
            self.unplugged = True
            for fd in (self.master, self.slave):
                try:
                    os.close(fd)
                except OSError:
                    pass

    def _run(self) -> None:
        raise_priority()
        buf = bytearray()
        while not self._stop.is_set() and not self.unplugged:
            now = time.monotonic()
            with self._lock:
                if self.model.unplug_at is not None and now >= self.model.unplug_at:
                    self.model.on_unplug(self.model.unplug_at)
                    self._close_fds()
                    logger.info("simulator %s: unplugged", self.port)
                    return
                out = self.model.tick(now) + self.model.due(now)
                for data in out:
                    if data:
                        self._write_all(data)
            nxt = self.model.next_due()
            wait = self.poll_s if nxt is None else max(0.0, min(self.poll_s, nxt - now))
            try:
                ready, _, _ = select.select([self.master], [], [], wait)
            except (OSError, ValueError):
                return
            if not ready:
                continue
            try:
                chunk = os.read(self.master, 4096)
            except OSError:
                time.sleep(self.poll_s)
                continue
            if self.packet_mode:
                control, chunk = chunk[0], chunk[1:]
                if control & termios.TIOCPKT_FLUSHREAD:
                    with self._lock:
                        self.model.reset(time.monotonic())
                    buf.clear()
                if control:
                    continue
            buf += chunk
            while True:
                idx = [i for i in (buf.find(b"\n"), buf.find(b"\r")) if i >= 0]
                if not idx:
                    break
                i = min(idx)
                line = bytes(buf[:i])
                del buf[:i + 1]
                if not line:
                    continue
                with self._lock:
                    now = time.monotonic()
                    self.model.log.append((now, "rx", line.decode("ascii", "replace")))
                    for data in self.model.tick(now) + self.model.handle(line, now):
                        if data:
                            self._write_all(data)
