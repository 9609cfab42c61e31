"""Driver for a Zaber linear stage speaking the Zaber ASCII protocol.

Messages (Zaber ASCII protocol manual): commands ``/<device> <axis> [<id>] <command>
[<data>][:<checksum>]`` end in ``\\n``; replies ``@<dd> <a> [<id>] <OK|RJ> <IDLE|BUSY>
<warning flag> <data>[:<checksum>]`` end in ``\\r\\n``. Info lines start with ``#`` and
alerts with ``!``. The warning flag is ``--`` when nothing is pending, otherwise the
highest-priority flag: ``F*`` are faults (``FS`` stalled and stopped, ``FD`` driver
disabled, ``FQ`` encoder error, ``FF`` critical system error, ...), ``W*`` warnings
(``WR`` no reference position: the stage must be homed), ``N*`` notes (``NI`` a
movement was interrupted by a new command, ``NC`` manual control). A rejected command
(``RJ``) carries the reason as data (``BADDATA``, ``BADCOMMAND``, ``BADAXIS``, ...).

Units: positions in microsteps; ``maxspeed`` in microsteps/s × 1.6384; ``accel`` in
microsteps/s² × 1.6384 / 10 (the protocol's native data units). ``steps_per_mm`` is the
stage's microsteps per millimetre (1 / microstep size).

Only one stage is driven; the Arduino only fires the shutter in this configuration.

A motion profile runs as a stored stream (:meth:`ZaberStage.load_stream`): a chain of
``line abs`` moves, each at its own ``maxspeed``, stored in a stream buffer before any
motion and started by one command (``stream 1 call 1``), so the host times the shutter
from one exchange as for a plain ``move abs``.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from collections.abc import Iterable

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_keywords

from .errors import DeviceError, DeviceFault, ProtocolError, ReplyTimeout
from .interfaces import Stage, StageState
from .transport import SAFETY_REPLY_TIMEOUT_S, LineTransport, ZaberChecksum

__all__ = ["ZaberStage", "ZaberReply", "SPEED_UNIT", "ACCEL_UNIT", "FAULT_FLAGS",
           "parse_reply", "speed_data", "accel_data", "speed_mm_s", "accel_mm_s2"]

logger = logging.getLogger(__name__)

#: maxspeed data value per microstep/s (Zaber ASCII protocol).
SPEED_UNIT = 1.6384
#: accel data value per microstep/s².
ACCEL_UNIT = 1.6384 / 10.0
#: The stream and the stream buffer a motion profile runs in.
STREAM_ID = 1
STREAM_BUFFER = 1
FAULT_FLAGS = {"FF": "critical system error", "FD": "driver disabled", "FQ": "encoder error",
               "FS": "stalled and stopped", "FT": "excessive twist", "FB": "stream bounds error",
               "FP": "interpolated path deviation", "FE": "limit error",
               "FM": "unexpected limit trigger", "FO": "overdrive limit exceeded",
               "FH": "hardware emergency stop"}
_NOT_HOMED = ("WR", "WH")

_REPLY_RE = re.compile(r"^@(\d{2}) (\d+) (?:(\d{1,2}) )?(OK|RJ) (IDLE|BUSY) ([A-Z-]{2}) (\S.*)$")


def speed_data(mm_s: float, steps_per_mm: float) -> int:
    """A velocity (mm/s) as a ``maxspeed`` data value.

    Parameters
    ----------
    mm_s : float
        Velocity, mm/s.
    steps_per_mm : float
        The stage's microsteps per mm.

    Returns
    -------
    int
        The nearest data value (microsteps/s × :data:`SPEED_UNIT`).
    """
    return int(round(mm_s * steps_per_mm * SPEED_UNIT))


def accel_data(mm_s2: float, steps_per_mm: float) -> int:
    """An acceleration (mm/s²) as an ``accel`` data value.

    Parameters
    ----------
    mm_s2 : float
        Acceleration, mm/s².
    steps_per_mm : float
        The stage's microsteps per mm.

    Returns
    -------
    int
        The nearest data value (microsteps/s² × :data:`ACCEL_UNIT`).
    """
    return int(round(mm_s2 * steps_per_mm * ACCEL_UNIT))


def speed_mm_s(data: int, steps_per_mm: float) -> float:
    """A ``maxspeed`` data value as a velocity (mm/s): the inverse of :func:`speed_data`.

    Parameters
    ----------
    data : int
        A ``maxspeed`` data value.
    steps_per_mm : float
        The stage's microsteps per mm.
    """
    return data / SPEED_UNIT / steps_per_mm


def accel_mm_s2(data: int, steps_per_mm: float) -> float:
    """An ``accel`` data value as an acceleration (mm/s²): the inverse of
    :func:`accel_data`.

    Parameters
    ----------
    data : int
        An ``accel`` data value.
    steps_per_mm : float
        The stage's microsteps per mm.
    """
    return data / ACCEL_UNIT / steps_per_mm


@dataclass(frozen=True)
class ZaberReply:
    """A reply line, parsed (:func:`parse_reply`).

    Attributes
    ----------
    device : int
        Device address on the chain (1..99).
    axis : int
        Axis number (0: the device as a whole).
    message_id : int or None
        The message id echoed (None: commands sent without ids).
    ok : bool
        ``OK`` (True) or ``RJ``, rejected (False).
    busy : bool
        ``BUSY`` (True) or ``IDLE``.
    flag : str
        The warning flag: ``--`` or the highest-priority one (``FS``, ``WR``, ``NI``, ...).
    data : str
        The reply's data (a value, or the reason of a rejection).
    """

    device: int
    axis: int
    message_id: int | None
    ok: bool
    busy: bool
    flag: str
    data: str


def parse_reply(line: str) -> ZaberReply:
    """Parse a reply line (checksum already stripped); :class:`ProtocolError` if it is
    not one.

    Parameters
    ----------
    line : str
        One line from the stage, without its end of line and checksum, e.g.
        ``"@01 1 OK IDLE -- 0"``.
    """
    m = _REPLY_RE.match(line)
    if not m:
        raise ProtocolError(f"zaber: not a reply: {line!r}")
    dev, axis, mid, flag_ok, status, warn, data = m.groups()
    return ZaberReply(int(dev), int(axis), int(mid) if mid is not None else None,
                      flag_ok == "OK", status == "BUSY", warn, data)


class ZaberStage(Stage):
    """A Zaber stage (one axis) on an ASCII-protocol link.

    Parameters
    ----------
    transport : LineTransport
        Link to the daisy chain (``eol = b"\\n"``; replies end in CR LF).
    steps_per_mm : float
        Microsteps per millimetre of this stage.
    device, axis : int
        Address on the chain (1..99) and axis (1..9).
    message_ids : bool
        Tag every command with a message id (0..99) and require it in the reply.
    """

    name = "zaber"

    def __init__(self, transport: LineTransport, *, steps_per_mm: float, device: int = 1,
                 axis: int = 1, message_ids: bool = False) -> None:
        self.transport = transport
        self.steps_per_mm = float(steps_per_mm)
        self.device = int(device)
        self.axis = int(axis)
        self.message_ids = message_ids
        self._next_id = 0
        self.alerts: list[str] = []
        # position polls: (host log time s, microsteps, ± s). The device reads its
        # position somewhere between the poll's send and its reply: the sample is placed
        # at the midpoint, uncertain by half the round trip (long on a loaded host).
        self.samples: list[tuple[float, int, float]] = []

    def enable_checksums(self) -> None:
        """Append and require Zaber checksums on every message from now on."""
        self.transport.checksum = ZaberChecksum()

    # -- commands -----------------------------------------------------------------------
    def command(self, text: str, *, axis: int | None = None, allow_rejection: bool = False,
                check_faults: bool = True) -> ZaberReply:
        """Send one command and return its reply.

        Parameters
        ----------
        text : str
            The command and its data, e.g. ``"move abs 1000"``.
        axis : int, optional
            Axis to address (default: this stage's; 0: the whole device).
        allow_rejection : bool
            Return an ``RJ`` reply instead of raising.
        check_faults : bool
            Raise on a fault flag (``F*``) in the reply.

        Returns
        -------
        ZaberReply
            The reply to this command (alerts and info lines read meanwhile are kept in
            :attr:`alerts`).

        Raises
        ------
        DeviceError
            ``RJ`` (unless ``allow_rejection``).
        DeviceFault
            A fault (``F*``) warning flag, unless ``check_faults`` is False.
        """
        ax = self.axis if axis is None else axis
        mid = None
        if self.message_ids:
            mid = self._next_id
            self._next_id = (self._next_id + 1) % 100
            wire = f"/{self.device} {ax} {mid} {text}"
        else:
            wire = f"/{self.device} {ax} {text}"
        self.transport.write_line(wire)
        deadline = time.monotonic() + self.transport.timeout_s
        while True:
            try:
                line = self.transport.read_line(deadline=deadline)
            except ReplyTimeout:
                raise ReplyTimeout(f"{self.name}: no reply to {wire!r}") from None
            if line.startswith("!") or line.startswith("#"):
                self.alerts.append(line)   # alerts and info lines are logged, not replies
                continue
            reply = parse_reply(line)
            if (reply.device, reply.axis) != (self.device, ax) or reply.message_id != mid:
                raise ProtocolError(f"{self.name}: reply {line!r} does not answer {wire!r}")
            if not reply.ok and not allow_rejection:
                raise DeviceError(f"{self.name}: {text!r} rejected ({reply.data})")
            if check_faults and reply.flag in FAULT_FLAGS:
                raise DeviceFault(f"{self.name}: fault {reply.flag} "
                                  f"({FAULT_FLAGS[reply.flag]}) after {text!r}")
            return reply

    def identify(self) -> str:
        reply = self.command("get deviceid", axis=0)
        if not reply.data.isdigit():
            raise ProtocolError(f"{self.name}: device id {reply.data!r} is not a number")
        return f"zaber device id {reply.data} at address {self.device}"

    def get_position(self) -> tuple[int, ZaberReply]:
        t_tx = self.transport.log.now()
        reply = self.command("get pos")
        t_rx = self.transport.log.now()
        try:
            pos = int(reply.data)
        except ValueError:
            raise ProtocolError(f"{self.name}: position {reply.data!r} is not an integer") from None
        self.samples.append((0.5 * (t_tx + t_rx), pos, 0.5 * (t_rx - t_tx)))
        return pos, reply

    def state(self) -> StageState:
        pos, reply = self.get_position()
        homed = reply.flag not in _NOT_HOMED
        return StageState(position=pos / self.steps_per_mm if homed else None, homed=homed,
                          moving=reply.busy, fault=reply.flag if reply.flag in FAULT_FLAGS else None)

    @renamed_keywords(lo_mm="lo", hi_mm="hi")
    def set_soft_limits(self, lo: float, hi: float) -> None:
        self.command(f"set limit.min {self.steps(lo)}")
        self.command(f"set limit.max {self.steps(hi)}")

    def set_motion(self, velocity_mm_s: float, acceleration_mm_s2: float) -> None:
        """Set ``maxspeed`` and ``accel`` for the next moves.

        Parameters
        ----------
        velocity_mm_s : float
            Cruise velocity, mm/s.
        acceleration_mm_s2 : float
            Acceleration, mm/s².

        Raises
        ------
        DeviceError
            Either is below one data unit at this stage's resolution.
        """
        v = speed_data(velocity_mm_s, self.steps_per_mm)
        a = accel_data(acceleration_mm_s2, self.steps_per_mm)
        if v < 1 or a < 1:
            raise DeviceError(f"{self.name}: {velocity_mm_s:g} mm/s or {acceleration_mm_s2:g} "
                              f"mm/s² is below the stage's resolution")
        self.command(f"set maxspeed {v}")
        self.command(f"set accel {a}")

    def home(self, *, velocity_mm_s: float, timeout_s: float) -> None:
        self.command("home")
        self.wait_idle(timeout_s=timeout_s)

    @renamed_keywords(position_mm="position")
    def start_move(self, position: float) -> int:
        """``move abs``: start a move at the set motion, without waiting for it.

        Parameters
        ----------
        position : float
            Target position, mm (stage coordinates).

        Returns
        -------
        int
            The target, microsteps.
        """
        target = self.steps(position)
        self.command(f"move abs {target}")
        return target

    def load_stream(self, lines: Iterable[tuple[int, int]], *, accel: int) -> None:
        """Store a sequence of moves in stream buffer :data:`STREAM_BUFFER` and set up a
        live stream on this axis, ready for :meth:`start_stream`.

        ``lines`` are ``(target microsteps, maxspeed data value)``: each becomes ``stream
        1 set maxspeed <v>`` and ``stream 1 line abs <target>``; ``accel`` (an ``accel``
        data value) is the stream's ``tanaccel``. Sent as (Zaber ASCII protocol, streams)::

            /1 0 stream buffer 1 erase
            /1 0 stream 1 setup store 1 1
            /1 0 stream 1 set tanaccel <accel>
            /1 0 stream 1 set maxspeed <v>      (each line)
            /1 0 stream 1 line abs <target>
            /1 0 stream 1 setup disable
            /1 0 stream 1 setup live 1

        Parameters
        ----------
        lines : iterable of (int, int)
            ``(target microsteps, maxspeed data value)`` of each line, in order.
        accel : int
            The stream's ``tanaccel``, an ``accel`` data value (:func:`accel_data`).
        """
        s, b = STREAM_ID, STREAM_BUFFER
        # a stream left live (or in error) by an earlier capture: disable it first
        self.command(f"stream {s} setup disable", axis=0, allow_rejection=True)
        self.command(f"stream buffer {b} erase", axis=0)
        self.command(f"stream {s} setup store {b} 1", axis=0)
        self.command(f"stream {s} set tanaccel {int(accel)}", axis=0)
        for target, speed in lines:
            self.command(f"stream {s} set maxspeed {int(speed)}", axis=0)
            self.command(f"stream {s} line abs {int(target)}", axis=0)
        self.command(f"stream {s} setup disable", axis=0)
        self.command(f"stream {s} setup live {self.axis}", axis=0)

    def start_stream(self) -> None:
        """``stream 1 call 1``: run the stored sequence now (the stage goes BUSY)."""
        self.command(f"stream {STREAM_ID} call {STREAM_BUFFER}", axis=0)

    @renamed_keywords(position_mm="position")
    def move_to(self, position: float, *, velocity_mm_s: float, acceleration_mm_s2: float,
                timeout_s: float) -> float:
        self.set_motion(velocity_mm_s, acceleration_mm_s2)
        target = self.start_move(position)
        pos = self.wait_idle(timeout_s=timeout_s)
        if pos != target:
            raise ProtocolError(f"{self.name}: move ended at {pos}, not {target} microsteps")
        return pos / self.steps_per_mm

    def wait_idle(self, *, timeout_s: float, poll_s: float = 0.0) -> int:
        """Poll ``get pos`` until IDLE; returns the final position (microsteps). Every poll
        is kept in :attr:`samples` (the measured motion).

        Parameters
        ----------
        timeout_s : float
            How long the stage may stay busy, s (judged at each poll's send time).
        poll_s : float
            Pause between polls, s (0: poll back to back).
        """
        deadline = time.monotonic() + timeout_s
        while True:
            t_poll = time.monotonic()
            pos, reply = self.get_position()
            if not reply.busy:
                return pos
            # the poll's send time, not now: a host starved after a poll is no late stage
            if t_poll > deadline:
                raise ReplyTimeout(f"{self.name}: still moving after {timeout_s:.1f} s")
            if poll_s:
                time.sleep(poll_s)

    def stop(self) -> None:
        # the safety path: a fault flag must not prevent the stop from being sent
        self.command("stop", check_faults=False, allow_rejection=True)

    def safe_stop(self, *, timeout_s: float = SAFETY_REPLY_TIMEOUT_S) -> None:
        """Safety path: ``stop``, tolerant of stray lines from an interrupted exchange.

        Parameters
        ----------
        timeout_s : float
            How long to wait for the stage's reply, s.
        """
        prefix = f"@{self.device:02d} {self.axis} "
        self.transport.send_on_safety_path(
            f"/{self.device} {self.axis} stop", lambda line: True if prefix in line else None,
            timeout_s=timeout_s)

    def warnings(self) -> list[str]:
        """Active warning flags (``warnings`` command)."""
        reply = self.command("warnings", check_faults=False)
        parts = reply.data.split()
        try:
            n = int(parts[0])
        except (ValueError, IndexError):
            raise ProtocolError(f"{self.name}: bad warnings reply {reply.data!r}") from None
        if len(parts) != n + 1:
            raise ProtocolError(f"{self.name}: warnings reply {reply.data!r} lists "
                                f"{len(parts) - 1} flags, says {n}")
        return parts[1:]

    def steps(self, mm: float) -> int:
        """A position in whole microsteps.

        Parameters
        ----------
        mm : float
            Position, mm (stage coordinates).
        """
        return int(round(mm * self.steps_per_mm))
