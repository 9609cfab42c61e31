"""Line-based serial transport: deadlines on every read, strict framing, a timestamped log.

A :class:`LineTransport` wraps any pyserial-like object (``write``, ``read``,
``in_waiting``, ``timeout``, ``close``): a real port opened with :func:`open_port`, a pty
served by :mod:`mitsweep.rig.simulator`, or a scripted byte stream in protocol tests
(:mod:`mitsweep.rig.testing`). Drivers only see lines of text.

Rules (so that a confused link never passes silently):

- every read has a deadline; nothing at the deadline raises :class:`ReplyTimeout`, a
  *partial* line at the deadline raises :class:`ProtocolError` (the device said
  something, but not a whole line);
- bytes outside printable ASCII in a line raise :class:`ProtocolError`;
- an optional :class:`Checksum` is appended to every line sent and verified (and
  stripped) on every line received;
- a port that disappears (unplugged USB adapter, closed pty) raises :class:`PortLost`;
- every line sent and received is appended to a :class:`CommandLog` with a monotonic
  timestamp (seconds since the log was created) and the device's name.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar
from collections.abc import Callable

# re-exported: the errors' home before errors.py (callers import them from here)
from .errors import PortLost, PortUnavailable, ProtocolError, ReplyTimeout  # noqa: F401

__all__ = ["LogEntry", "CommandLog", "Checksum", "XorChecksum", "ZaberChecksum",
           "LineTransport", "open_port", "SAFETY_REPLY_TIMEOUT_S"]

logger = logging.getLogger(__name__)

#: What an awaited reply is parsed into (:meth:`LineTransport.send_on_safety_path`).
T = TypeVar("T")

#: Deadline of a stop command's reply on the safety path, s. Generous: a device that
#: answers at all answers within milliseconds, but a host whose cores are busy may read
#: the reply late, and a stop reported "not confirmed" because of the host's own load
#: would be a false alarm (seen at 1.0 s with two busy processes on two cores).
SAFETY_REPLY_TIMEOUT_S = 3.0
#: Times a stop command is sent on the safety path before it counts as unconfirmed.
SAFETY_ATTEMPTS = 3

try:
    import termios as _termios

    _PORT_ERRORS: tuple[type[BaseException], ...] = (OSError, _termios.error)
except ImportError:  # pragma: no cover - Windows
    _PORT_ERRORS = (OSError,)


@dataclass(frozen=True)
class LogEntry:
    """One line on a link.

    Attributes
    ----------
    t_s : float
        Seconds since the log started (monotonic clock).
    device : str
        The link's device name (e.g. ``"arduino"``).
    direction : str
        ``"tx"`` host → device, ``"rx"`` device → host.
    text : str
        The line without its terminator, with any checksum as it went over the wire.
    """

    t_s: float
    device: str
    direction: str
    text: str

    def as_dict(self) -> dict:
        return {"t_s": round(self.t_s, 6), "device": self.device, "dir": self.direction,
                "text": self.text}


@dataclass
class CommandLog:
    """Thread-safe, append-only log of every line exchanged on one or more links.

    Attributes
    ----------
    t0 : float
        The :func:`time.monotonic` origin of the entries' ``t_s`` (default: now).
    wall_t0 : float
        The matching UNIX time, s, for provenance.
    entries : list of LogEntry
        The lines, in the order they were added.
    """

    t0: float = field(default_factory=time.monotonic)
    wall_t0: float = field(default_factory=time.time)
    entries: list[LogEntry] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def now(self) -> float:
        """Seconds since the log's origin (monotonic clock)."""
        return time.monotonic() - self.t0

    def add(self, device: str, direction: str, text: str, t_s: float | None = None) -> LogEntry:
        """Append one line and return its entry.

        Parameters
        ----------
        device : str
            The link's device name.
        direction : str
            ``"tx"`` (sent) or ``"rx"`` (received).
        text : str
            The line, without its terminator.
        t_s : float, optional
            Its time, s since the log's origin (default: now).
        """
        entry = LogEntry(self.now() if t_s is None else t_s, device, direction, text)
        with self._lock:
            self.entries.append(entry)
        logger.debug("%s %s %s", device, "<-" if direction == "tx" else "->", text)
        return entry

    def as_list(self) -> list[dict]:
        with self._lock:
            return [e.as_dict() for e in self.entries]


class Checksum(Protocol):
    """A line checksum: ``append(text) -> text_with_checksum``, ``strip(text) -> text``
    (raises :class:`ProtocolError` when the checksum is missing or wrong).

    Parameters
    ----------
    text : str
        The argument of both methods: a line without its terminator (with its checksum,
        for :meth:`strip`).
    """

    def append(self, text: str) -> str:
        """The line with its checksum appended.

        Parameters
        ----------
        text : str
            A line without its terminator.
        """
        ...

    def strip(self, text: str) -> str:
        """The line without its checksum, once checked.

        Parameters
        ----------
        text : str
            A line as received, without its terminator.

        Raises
        ------
        ProtocolError
            The checksum is missing, malformed or wrong.
        """
        ...


class _HexSuffixChecksum:
    """A checksum sent as ``BODY<separator>HH`` (two upper-case hex digits); subclasses
    give the separator and ``value(body)``."""

    separator = "*"
    form = "TEXT*HH"

    @staticmethod
    def value(text: str) -> int:  # pragma: no cover - overridden
        raise NotImplementedError

    def append(self, text: str) -> str:
        return f"{text}{self.separator}{self.value(text):02X}"

    def strip(self, text: str) -> str:
        body, sep, tail = text.rpartition(self.separator)
        if not sep or len(tail) != 2:
            raise ProtocolError(f"missing checksum in {text!r} (expected {self.form})")
        try:
            got = int(tail, 16)
        except ValueError:
            raise ProtocolError(f"malformed checksum in {text!r}") from None
        if got != self.value(body):
            raise ProtocolError(f"bad checksum in {text!r}: expected {self.value(body):02X}")
        return body


class XorChecksum(_HexSuffixChecksum):
    """NMEA-style checksum: ``TEXT*HH``, HH = XOR of every byte of TEXT, two upper-case
    hex digits. Used by the project's Arduino sweep controller (``CHK 1``)."""

    separator = "*"
    form = "TEXT*HH"

    @staticmethod
    def value(text: str) -> int:
        """The checksum of a line: the XOR of its bytes (0..255).

        Parameters
        ----------
        text : str
            The line's ASCII text, without terminator or checksum.
        """
        x = 0
        for b in text.encode("ascii"):
            x ^= b
        return x


class ZaberChecksum(_HexSuffixChecksum):
    """Zaber ASCII message checksum: ``/1 1 move abs 10000:HH``.

    HH (two upper-case hex digits) is the 8-bit two's complement of the sum of the
    message's bytes after the leading type character (``/``, ``@``, ``#`` or ``!``) and
    before the colon, so that the bytes and the checksum sum to 0 modulo 256. The
    algorithm agrees with zproto's LRC (a Zaber client library); the byte range is
    the protocol's as publicly documented, not checked on a device.
    """

    separator = ":"
    form = "MESSAGE:HH"

    @staticmethod
    def value(text: str) -> int:
        """The checksum of a message: minus the sum of its bytes after the first, mod 256.

        Parameters
        ----------
        text : str
            The message's ASCII text, type character included, without terminator or
            checksum.
        """
        return (-sum(text[1:].encode("ascii"))) & 0xFF


def open_port(port: str, *, baudrate: int = 115200, name: str | None = None) -> Any:
    """Open a serial port with pyserial (8N1, no flow control), non-blocking reads.

    Parameters
    ----------
    port : str
        A device (``/dev/ttyACM0``, ``COM3``) or a pyserial URL (``loop://``).
    baudrate : int
        Line speed, baud.
    name : str, optional
        What the port is, for the error message (default ``"serial port"``).

    Returns
    -------
    serial.Serial
        The open port (exclusive access, 1 s write timeout).

    Raises
    ------
    PortUnavailable
        The port does not exist or cannot be opened (busy, permissions): the message
        names it. Raised before anything is sent.
    """
    import serial

    try:
        ser = serial.serial_for_url(port, baudrate=baudrate, timeout=0, write_timeout=1.0,
                                    exclusive=True)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise PortUnavailable(f"{name or 'serial port'} {port!r}: cannot open ({exc})") from None
    return ser


class LineTransport:
    """Lines of ASCII text over a byte stream, with deadlines and a log.

    Parameters
    ----------
    serial : pyserial-like
        Owned by the transport from now on (closed by :meth:`close`).
    name : str
        Device name in the log and in error messages (e.g. ``"arduino"``).
    log : CommandLog, optional
        Shared log (one per capture); a new one by default.
    eol : bytes
        Terminator appended to every line sent.
    checksum : Checksum, optional
        Appended to every line sent, verified on every line received. Can be set later
        (:attr:`checksum`), e.g. after the device has been told to use one.
    timeout_s : float
        Default deadline of :meth:`read_line`, seconds.
    """

    def __init__(self, serial: Any, *, name: str = "device", log: CommandLog | None = None,
                 eol: bytes = b"\n", checksum: Checksum | None = None,
                 timeout_s: float = 1.0) -> None:
        self.serial = serial
        self.name = name
        self.log = log if log is not None else CommandLog()
        self.eol = eol
        self.checksum = checksum
        self.timeout_s = float(timeout_s)
        self._buffer = bytearray()
        self._lost: str | None = None
        #: ``time.monotonic()`` of the last line sent (a device's watchdog counts from it).
        self.last_write_s = time.monotonic()

    # -- output -------------------------------------------------------------------------
    def write_line(self, text: str) -> None:
        """Send ``text`` (+ checksum) + eol. Raises :class:`PortLost` on a dead port.

        Parameters
        ----------
        text : str
            The line, printable ASCII, without terminator or checksum.
        """
        wire = self.checksum.append(text) if self.checksum is not None else text
        data = wire.encode("ascii") + self.eol
        self._check_alive()
        try:
            self.serial.write(data)
            flush = getattr(self.serial, "flush", None)
            if flush is not None:
                flush()
        except _PORT_ERRORS as exc:  # SerialException and SerialTimeoutException are OSErrors
            self._mark_lost(exc)
        self.last_write_s = time.monotonic()
        self.log.add(self.name, "tx", wire)

    # -- input --------------------------------------------------------------------------
    def read_line(self, timeout_s: float | None = None, *, deadline: float | None = None,
                  keepalive: tuple[float, Callable[[], None]] | None = None) -> str:
        """The next whole line (terminator and checksum stripped), waiting at most
        ``timeout_s`` (default :attr:`timeout_s`) or until the monotonic ``deadline``.

        Accepts ``\\n``, ``\\r\\n`` and ``\\r`` line ends (Zaber devices send CR LF).
        ``keepalive = (period_s, send)``: while waiting, call ``send()`` (which writes a
        line) whenever nothing was sent for ``period_s`` — a heartbeat for a device's
        watchdog.

        Parameters
        ----------
        timeout_s : float, optional
            How long to wait, s (default :attr:`timeout_s`); ignored with ``deadline``.
        deadline : float, optional
            The :func:`time.monotonic` time to wait until.
        keepalive : (float, callable), optional
            ``(period_s, send)``: the heartbeat while waiting (None: none).

        Raises
        ------
        ReplyTimeout
            Nothing arrived by the deadline.
        ProtocolError
            A partial line at the deadline, garbage, or a bad checksum.
        PortLost
            The port disappeared.
        """
        if deadline is None:
            deadline = time.monotonic() + (self.timeout_s if timeout_s is None else timeout_s)
        while True:
            line = self._pop_line()
            if line is not None:
                return self._accept(line)
            if keepalive is not None and time.monotonic() - self.last_write_s >= keepalive[0]:
                keepalive[1]()
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                # what arrived while this host was not scheduled arrived in time: read
                # it before calling the deadline missed
                self.fill(0.0)
                line = self._pop_line()
                if line is not None:
                    return self._accept(line)
                if self._buffer:
                    partial = bytes(self._buffer)
                    self._buffer.clear()
                    self.log.add(self.name, "rx", partial.decode("ascii", "replace") + " <partial>")
                    raise ProtocolError(f"{self.name}: partial line {partial!r} at the deadline "
                                        f"(no line terminator)")
                raise ReplyTimeout(f"{self.name}: no reply within the deadline")
            self.fill(min(remaining, 0.05))

    def pending(self) -> bool:
        """True if a whole line is already buffered or waiting on the port."""
        self.fill(0.0)
        return self._has_line()

    def send_on_safety_path(self, line: str, until: Callable[[str], T | None], *, timeout_s: float,
                            on_other: Callable[[str], object] | None = None,
                            attempts: int = SAFETY_ATTEMPTS) -> T:
        """Send ``line`` after discarding whatever is buffered, then read until
        ``until(reply)`` returns something other than None, and return that.

        For stop commands after an interrupted exchange: garbage and stray lines in the
        buffer must not block the stop, so unparseable lines are skipped and other lines
        go to ``on_other`` (e.g. to keep the board's events). A partial line left in the
        buffer by the interruption (a signal can land between a read and its use) is
        discarded before sending, so it cannot prefix the reply. Without the awaited
        reply within ``timeout_s`` the line is sent again (stop commands are idempotent),
        ``attempts`` times in all; then ``ReplyTimeout``.

        Parameters
        ----------
        line : str
            The command to send (idempotent: it may be sent ``attempts`` times).
        until : callable
            ``until(reply)``: the parsed awaited reply, or None for any other line.
        timeout_s : float
            How long each attempt waits for the reply, s.
        on_other : callable, optional
            Called with each line that is not the awaited reply.
        attempts : int
            How many times the line is sent at most.
        """
        for attempt in range(1, attempts + 1):
            try:
                self.drain()
            except Exception:  # noqa: BLE001 - garbage in the buffer must not block the stop
                logger.debug("%s: drain before %r failed", self.name, line, exc_info=True)
            if self._buffer:
                self.log.add(self.name, "rx", bytes(self._buffer).decode("ascii", "replace")
                             + " <partial, discarded>")
                self._buffer.clear()
            self.write_line(line)
            deadline = time.monotonic() + timeout_s
            while True:
                try:
                    reply = self.read_line(deadline=deadline)
                except ProtocolError:
                    continue
                except ReplyTimeout:
                    logger.warning("%s: no reply to %r within %.1f s (attempt %d of %d)",
                                   self.name, line, timeout_s, attempt, attempts)
                    break
                result = until(reply)
                if result is not None:
                    return result
                if on_other is not None:
                    on_other(reply)
        raise ReplyTimeout(f"{self.name}: no reply to {line!r} in {attempts} attempts of "
                           f"{timeout_s:g} s")

    def drain(self) -> list[str]:
        """Read and log whatever is waiting now (used after a reset); returns raw texts."""
        out = []
        self.fill(0.0)
        while (line := self._pop_line()) is not None:
            text = line.decode("ascii", "replace")
            self.log.add(self.name, "rx", text + " <drained>")
            out.append(text)
        return out

    @property
    def unread(self) -> bytes:
        """Bytes received but not yet returned as a line."""
        return bytes(self._buffer)

    def close(self) -> None:
        try:
            self.serial.close()
        except Exception:  # closing a dead port must not raise during cleanup
            logger.debug("%s: error while closing", self.name, exc_info=True)

    # -- internals ----------------------------------------------------------------------
    def _check_alive(self) -> None:
        if self._lost is not None:
            raise PortLost(f"{self.name}: port lost ({self._lost})")

    def _mark_lost(self, exc: BaseException) -> None:
        self._lost = str(exc) or type(exc).__name__
        self.log.add(self.name, "rx", f"<port lost: {self._lost}>")
        raise PortLost(f"{self.name}: port lost ({self._lost})") from None

    def _has_line(self) -> bool:
        return b"\n" in self._buffer or b"\r" in self._buffer

    def _pop_line(self) -> bytes | None:
        # skip empty lines produced by CR LF pairs
        while True:
            idx = [i for i in (self._buffer.find(b"\n"), self._buffer.find(b"\r")) if i >= 0]
            if not idx:
                return None
            i = min(idx)
            line = bytes(self._buffer[:i])
            end = i + 2 if self._buffer[i:i + 2] == b"\r\n" else i + 1
            del self._buffer[:end]
            if line:
                return line

    def fill(self, wait_s: float) -> None:
        """Move what the port has received into the line buffer (:attr:`unread`),
        returning no line: all bytes waiting now, else those that arrive within
        ``wait_s``. A lost port is marked lost (the next read raises).

        Parameters
        ----------
        wait_s : float
            How long to wait for a first byte when none is waiting, s; 0 or less: do
            not wait.
        """
        self._check_alive()
        try:
            waiting = self.serial.in_waiting
            if waiting:
                self._buffer += self.serial.read(waiting)
                return
            if wait_s <= 0:
                return
            self.serial.timeout = wait_s
            try:
                chunk = self.serial.read(1)
            finally:
                self.serial.timeout = 0
            if chunk:
                self._buffer += chunk
                waiting = self.serial.in_waiting
                if waiting:
                    self._buffer += self.serial.read(waiting)
        except _PORT_ERRORS as exc:
            self._mark_lost(exc)

    def _accept(self, raw: bytes) -> str:
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            text = None
        if text is None or not text.isprintable():
            shown = raw.decode("ascii", "replace")
            self.log.add(self.name, "rx", shown + " <garbage>")
            raise ProtocolError(f"{self.name}: garbage on the line: {raw[:40]!r}")
        self.log.add(self.name, "rx", text)
        if self.checksum is not None:
            text = self.checksum.strip(text)
        return text

