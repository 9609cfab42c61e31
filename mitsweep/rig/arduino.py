"""Driver for the project's Arduino sweep controller (firmware in ``scripts/firmware/``).

The board drives a stepper (STEP/DIR/ENABLE to a stepper driver, a home switch) and an
optocoupler across the camera's remote-release lines, and speaks a line protocol at
115200 baud, 8N1, lines ending in ``\\n``. Positions are integer steps, rates steps/s,
accelerations steps/s², times the board's ``micros()`` (32-bit, wraps every ~71.6 min;
the driver unwraps them).

Protocol (version 3)
--------------------
On reset (opening the port resets an Uno) the board prints
``READY mitsweep-sweep <firmware-version> <protocol>``.

================================================  ==============================================
host → board                                      board → host
================================================  ==============================================
``ID``                                            ``OK ID mitsweep-sweep <fw> <protocol>``
``STATE``                                         ``OK STATE <t_us> <pos> <homed> <moving>
                                                  <shutter>`` (0/1 flags)
``CHK 1`` / ``CHK 0``                             ``OK CHK 1``: from then on every line both
                                                  ways ends in ``*HH`` (XOR of its bytes)
``LIMITS <min> <max>``                            ``OK LIMITS <min> <max>``: soft limits, steps
``HOME <rate>``                                   ``OK HOME``; later ``EV HOMED <t> 0``
``MOVE <target> <rate> <accel>``                  ``OK MOVE``; later ``EV DONE <t> <pos>``
``SWEEP <target> <rate> <accel> <open> <close>``  ``OK SWEEP``; events ``START``, ``OPEN``,
                                                  ``POS`` (every 50 ms), ``CLOSE``, ``DONE``
``TABLE <n>``                                     ``OK TABLE <n>``: a step-rate table of n
                                                  segments follows (1..64; replaces the last)
``SEG <i> <steps> <duration_us>``                 ``OK SEG <i> <total_steps> <total_us>``:
                                                  segment i (in order, from 0), steps >= 0,
                                                  duration >= 1 µs, at most 4000 steps/s;
                                                  the reply's running totals let the host
                                                  check the whole table
``TSWEEP <target> <accel> <open> <close>``        ``OK TSWEEP``; events as for ``SWEEP``
``SHUTTER <delay_us> <duration_us>``              ``OK SHUTTER <t_us>``; later ``EV OPEN``,
                                                  ``EV CLOSE``
``CLOSE``                                         ``OK CLOSE`` (shutter released now)
``STOP``                                          ``OK STOP <t_us> <pos>`` (shutter released
                                                  first, then the motor stopped)
``WATCHDOG <ms>``                                 ``OK WATCHDOG <ms>``: 0 (the default after a
                                                  reset) turns it off; at most 600000
``PING``                                          ``OK PING <t_us>`` (a heartbeat; any line
                                                  counts as one)
================================================  ==============================================

``SWEEP`` ramps at ``accel`` to ``rate`` and back to rest at ``target``; the shutter is
held open from the step that reaches ``open`` to the step that reaches ``close`` — both
must lie in the constant-velocity part (the board checks: ``ERR RANGE``). Errors are
``ERR <CODE> <text>`` with CODE in SYNTAX, RANGE, LIMIT, BUSY, HOME, CHECKSUM.

``TSWEEP`` (new in protocol 3) runs the loaded table: it ramps at ``accel`` from rest
to the first segment's rate, cruises to ``open`` (shutter opens on that step), then runs
segment after segment, each its steps evenly spread over its duration (timed from the
open step on the board's µs clock, whole microseconds, no drift), closes the shutter on
the table's last step (``close`` must be ``open`` ± the table's total steps), cruises at
the last segment's rate and ramps down to rest at ``target``. The board checks that
both ramps fit (``ERR RANGE``); what rate changes the stage can follow is the plan's
business (:mod:`mitsweep.rig.profile`). Linear sweeps (``SWEEP``) are unchanged, and
the driver still runs them on a protocol-2 board (firmware 1.1); a motion profile on one
is refused after ``ID``, before any motion (:meth:`ArduinoSweepController.require_tables`). Events are
``EV <NAME> <t_us> <pos> [<detail>]``; ``EV FAULT <t> <pos> <CODE>`` (e.g. HOME_SWITCH,
LIMIT) means the board has already released the shutter and stopped the motor.

Watchdog (new in protocol 2): with ``WATCHDOG <ms>`` set, while the stage moves (HOME,
MOVE, SWEEP) or a ``SHUTTER`` exposure is pending or open, the board releases the
shutter, stops the motor and sends ``EV FAULT <t> <pos> WATCHDOG`` when no line has come
from the host for ``<ms>`` milliseconds: a host that was killed, crashed or hung cannot
leave the rig moving with the shutter held. The driver enables it
(:meth:`ArduinoSweepController.set_watchdog`) and sends ``PING`` every quarter of the
timeout while it waits for events (:meth:`ArduinoSweepController.keep_alive`); ``OK
PING`` replies are skipped wherever they arrive.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from collections.abc import Callable, Iterable

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_keywords

from .errors import DeviceError, DeviceFault, ProtocolError, ReplyTimeout, RigError
from .interfaces import Shutter, Stage, StageState
from .transport import SAFETY_REPLY_TIMEOUT_S, LineTransport, XorChecksum

__all__ = ["ArduinoSweepController", "BoardEvent", "BoardClock", "FIRMWARE_NAME",
           "PROTOCOL_VERSION", "MAX_STEP_RATE", "step_rate", "step_accel", "EVENT_NAMES", "ERROR_CODES",
           "POS_EVENT_PERIOD_US", "MAX_WATCHDOG_MS", "HEARTBEATS_PER_TIMEOUT",
           "MAX_TABLE_SEGMENTS", "MAX_SEGMENT_STEPS", "SUPPORTED_PROTOCOLS", "TABLE_PROTOCOL"]

logger = logging.getLogger(__name__)

FIRMWARE_NAME = "mitsweep-sweep"
PROTOCOL_VERSION = 3
#: Protocols this driver speaks: 2 (linear sweeps, watchdog) and 3 (also step-rate tables).
#: Protocol 1 (no watchdog) is refused: a killed host could leave the rig moving.
SUPPORTED_PROTOCOLS = (2, 3)
#: The first protocol with step-rate tables.
TABLE_PROTOCOL = 3
#: Highest step rate the firmware generates reliably (steps/s), polling micros() on a 16 MHz Uno.
MAX_STEP_RATE = 4000
#: Segments a step-rate table holds (``TABLE <n>``): 6 bytes each of the Uno's 2 KiB SRAM
#: (64 leave the stack and serial buffers the 512 B the firmware test asks for).
MAX_TABLE_SEGMENTS = 64
#: Steps one segment moves at most (a 16-bit count on the board).
MAX_SEGMENT_STEPS = 65535


def step_rate(mm_s: float, steps_per_mm: float) -> int:
    """A velocity (mm/s) as the firmware's integer step rate (steps/s), unchecked.

    Parameters
    ----------
    mm_s : float
        Velocity, mm/s.
    steps_per_mm : float
        Stepper steps per stage millimetre.

    Returns
    -------
    int
        The nearest whole number of steps/s (not checked against :data:`MAX_STEP_RATE`).
    """
    return int(round(mm_s * steps_per_mm))


def step_accel(mm_s2: float, steps_per_mm: float) -> int:
    """An acceleration (mm/s²) as the firmware's integer steps/s² (at least 1).

    Parameters
    ----------
    mm_s2 : float
        Acceleration, mm/s².
    steps_per_mm : float
        Stepper steps per stage millimetre.

    Returns
    -------
    int
        The nearest whole number of steps/s², at least 1.
    """
    return max(1, int(round(mm_s2 * steps_per_mm)))
#: Period of ``EV POS`` samples during a SWEEP, µs.
POS_EVENT_PERIOD_US = 50_000
#: Longest watchdog timeout the firmware accepts, ms.
MAX_WATCHDOG_MS = 600_000
#: Heartbeats sent per watchdog timeout while waiting (a late one still leaves three).
HEARTBEATS_PER_TIMEOUT = 4
EVENT_NAMES = ("START", "OPEN", "POS", "CLOSE", "DONE", "HOMED", "FAULT")
ERROR_CODES = ("SYNTAX", "RANGE", "LIMIT", "BUSY", "HOME", "CHECKSUM")

_INT = r"-?\d+"
_EVENT_RE = re.compile(rf"^EV ({'|'.join(EVENT_NAMES)}) (\d+) ({_INT})(?: ([A-Z_]+))?$")
_ERR_RE = re.compile(rf"^ERR ({'|'.join(ERROR_CODES)})(?: (.*))?$")
_PING_RE = re.compile(r"^OK PING \d+$")


class BoardClock:
    """Unwraps the board's 32-bit ``micros()`` into a monotonic 64-bit count."""

    def __init__(self) -> None:
        self._last: int | None = None
        self._offset = 0

    def unwrap(self, raw: int) -> int:
        """The 64-bit board time of a raw ``micros()`` reading.

        Parameters
        ----------
        raw : int
            A time the board sent, µs, in ``0 .. 2**32 - 1``; readings are given in the
            order they arrived (a drop of more than half the range is a wrap).

        Returns
        -------
        int
            The unwrapped time, µs.

        Raises
        ------
        ProtocolError
            ``raw`` is outside the 32-bit range.
        """
        if not 0 <= raw < 2**32:
            raise ProtocolError(f"board time {raw} outside 32-bit micros() range")
        if self._last is not None and raw < self._last and self._last - raw > 2**31:
            self._offset += 2**32
        self._last = raw
        return raw + self._offset


@dataclass(frozen=True)
class BoardEvent:
    """An event from the board (``EV <NAME> <t_us> <pos> [<detail>]``).

    Attributes
    ----------
    name : str
        One of :data:`EVENT_NAMES` (``START``, ``OPEN``, ``POS``, ``CLOSE``, ...).
    t_us : int
        Board time, µs (unwrapped: :class:`BoardClock`).
    position : int
        Stage position, steps.
    detail : str
        The fault code of a ``FAULT`` event (e.g. ``WATCHDOG``), else ``""``.
    host_t_s : float
        When the line arrived, s on the command log's clock.
    """

    name: str
    t_us: int
    position: int
    detail: str
    host_t_s: float

    def as_dict(self) -> dict:
        return {"name": self.name, "t_us": self.t_us, "position_steps": self.position,
                "detail": self.detail, "host_t_s": round(self.host_t_s, 6)}


class ArduinoSweepController(Stage, Shutter):
    """The Arduino sweep controller: a stepper stage and a shutter on one board.

    Parameters
    ----------
    transport : LineTransport
        Line link to the board (``eol = b"\\n"``).
    steps_per_mm : float
        Stepper steps per stage millimetre.
    name : str
        Name in logs and messages.
    """

    name = "arduino"

    def __init__(self, transport: LineTransport, *, steps_per_mm: float) -> None:
        self.transport = transport
        self.steps_per_mm = float(steps_per_mm)
        self.clock = BoardClock()
        self.events: list[BoardEvent] = []   # every event received, in order
        self._unread: list[BoardEvent] = []  # events not yet consumed by wait_event
        self.ready_line: str | None = None
        self.shutter_open: bool | None = None   # as last reported by STATE
        self.stopped_at: int | None = None      # step position of the last STOP
        self.heartbeat_s: float | None = None   # PING period while waiting; None: off
        self.protocol: int | None = None        # as the board identified itself

    # -- link ---------------------------------------------------------------------------
    def wait_ready(self, timeout_s: float = 3.0) -> bool:
        """Wait for the ``READY`` line a board prints after its reset.

        Returns False (and logs) if none arrives: boards with auto-reset disabled print
        nothing; :meth:`identify` then checks the firmware anyway.

        Parameters
        ----------
        timeout_s : float
            How long to wait for the line, s.

        Raises
        ------
        ProtocolError
            A line other than ``READY``, or the ``READY`` line of another firmware.
        """
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                line = self.transport.read_line(deadline=deadline)
            except ReplyTimeout:
                logger.info("%s: no READY line within %.1f s", self.name, timeout_s)
                return False
            if line.startswith("READY "):
                parts = line.split()
                if len(parts) != 4 or parts[1] != FIRMWARE_NAME:
                    raise ProtocolError(f"{self.name}: unexpected firmware {line!r}; expected "
                                        f"'READY {FIRMWARE_NAME} <version> <protocol>'")
                self.ready_line = line
                return True
            raise ProtocolError(f"{self.name}: unexpected line before READY: {line!r}")

    def enable_checksums(self) -> None:
        """``CHK 1``: from now on every line both ways carries an XOR checksum."""
        self.transport.write_line("CHK 1")
        self.transport.checksum = XorChecksum()
        self._expect_ok("CHK", self.transport.read_line(), n_fields=1)

    # -- commands -----------------------------------------------------------------------
    def identify(self) -> str:
        fields = self._query("ID", n_fields=3)
        name, fw, proto = fields
        if name != FIRMWARE_NAME:
            raise ProtocolError(f"{self.name}: device is {name!r}, not {FIRMWARE_NAME!r}")
        if proto not in {str(v) for v in SUPPORTED_PROTOCOLS}:
            speaks = " or ".join(str(v) for v in SUPPORTED_PROTOCOLS)
            raise ProtocolError(f"{self.name}: protocol version {proto}, this driver speaks "
                                f"{speaks}; update the firmware or mitsweep")
        self.protocol = int(proto)
        return f"{name} {fw} (protocol {proto})"

    def require_tables(self) -> None:
        """Refuse a board whose firmware (protocol 2) has no step-rate tables."""
        if self.protocol is not None and self.protocol < TABLE_PROTOCOL:
            raise DeviceError(f"{self.name}: the firmware speaks protocol {self.protocol}, "
                              f"which has no step-rate tables (TABLE/SEG/TSWEEP, protocol "
                              f"{TABLE_PROTOCOL}): flash scripts/firmware/mitsweep_sweep to "
                              f"run a motion profile")

    def state(self) -> StageState:
        t, pos, homed, moving, shutter = self._ints(self._query("STATE", n_fields=5), "STATE")
        self.clock.unwrap(t)
        self.shutter_open = bool(shutter)
        return StageState(position=pos / self.steps_per_mm if homed else None,
                          homed=bool(homed), moving=bool(moving))

    @renamed_keywords(lo_mm="lo", hi_mm="hi")
    def set_soft_limits(self, lo: float, hi: float) -> None:
        lo_steps, hi_steps = self.steps(lo), self.steps(hi)
        got = self._ints(self._query(f"LIMITS {lo_steps} {hi_steps}", n_fields=2), "LIMITS")
        if got != [lo_steps, hi_steps]:
            raise ProtocolError(f"{self.name}: LIMITS echoed {got}, sent {[lo_steps, hi_steps]}")

    def home(self, *, velocity_mm_s: float, timeout_s: float) -> None:
        self._query(f"HOME {self.rate(velocity_mm_s)}", n_fields=0)
        self.wait_event("HOMED", timeout_s=timeout_s)

    @renamed_keywords(position_mm="position")
    def move_to(self, position: float, *, velocity_mm_s: float, acceleration_mm_s2: float,
                timeout_s: float) -> float:
        target = self.steps(position)
        self._query(f"MOVE {target} {self.rate(velocity_mm_s)} "
                    f"{self.accel(acceleration_mm_s2)}", n_fields=0)
        ev = self.wait_event("DONE", timeout_s=timeout_s)
        if ev.position != target:
            raise ProtocolError(f"{self.name}: move ended at step {ev.position}, not {target}")
        return ev.position / self.steps_per_mm

    def start_sweep(self, *, target: int, velocity_mm_s: float, acceleration_mm_s2: float,
                    open_at: int, close_at: int) -> None:
        """Send ``SWEEP`` to step ``target`` with the shutter open from step ``open_at``
        to ``close_at`` (exact step positions: the board triggers on them); velocity and
        acceleration are converted to the board's steps/s and steps/s². Events follow.

        Parameters
        ----------
        target : int
            Where the sweep ends at rest, steps.
        velocity_mm_s : float
            Sweep velocity, mm/s (1 .. :data:`MAX_STEP_RATE` steps/s).
        acceleration_mm_s2 : float
            Acceleration of the ramps, mm/s².
        open_at, close_at : int
            Steps at which the shutter opens and closes; both in the constant-velocity
            part of the move (else ``ERR RANGE``).
        """
        self._query(f"SWEEP {target} {self.rate(velocity_mm_s)} "
                    f"{self.accel(acceleration_mm_s2)} {open_at} {close_at}", n_fields=0)

    def load_table(self, steps: Iterable[int], durations_us: Iterable[int]) -> None:
        """Upload a step-rate table: ``TABLE <n>``, then ``SEG <i> <steps> <us>`` for each
        segment; the board acknowledges every segment with its running totals of steps
        and µs, which must be the host's (a lost, repeated or altered segment fails here,
        before any motion).

        Parameters
        ----------
        steps : iterable of int
            Steps of each segment (>= 0, at most :data:`MAX_SEGMENT_STEPS`);
            1 .. :data:`MAX_TABLE_SEGMENTS` segments.
        durations_us : iterable of int
            Duration of each segment, µs (>= 1), as many as ``steps``.

        Raises
        ------
        DeviceError
            A board without tables, a wrong number of segments, or a segment refused.
        ProtocolError
            An acknowledgement whose totals differ from the host's.
        """
        self.require_tables()
        steps, durations_us = list(steps), list(durations_us)
        n = len(steps)
        if not 1 <= n <= MAX_TABLE_SEGMENTS or len(durations_us) != n:
            raise DeviceError(f"{self.name}: a table has 1..{MAX_TABLE_SEGMENTS} segments "
                              f"of (steps, duration), got {n} and {len(durations_us)}")
        (got,) = self._ints(self._query(f"TABLE {n}", n_fields=1), "TABLE")
        if got != n:
            raise ProtocolError(f"{self.name}: TABLE echoed {got}, sent {n}")
        total_steps = total_us = 0
        for i, (k, us) in enumerate(zip(steps, durations_us)):
            total_steps += int(k)
            total_us += int(us)
            echo = self._ints(self._query(f"SEG {i} {int(k)} {int(us)}", n_fields=3), "SEG")
            if echo != [i, total_steps, total_us]:
                raise ProtocolError(f"{self.name}: SEG {i} acknowledged with totals "
                                    f"{echo[1:]}, the host has {[total_steps, total_us]}")

    def start_table_sweep(self, *, target: int, acceleration_mm_s2: float, open_at: int,
                          close_at: int) -> None:
        """``TSWEEP``: ramp to the loaded table's entry rate, run the table from step
        ``open_at`` (shutter opens) to ``close_at`` (shutter closes, its last step), then
        ramp down to rest at ``target``. Events as for :meth:`start_sweep`.

        Parameters
        ----------
        target : int
            Where the sweep ends at rest, steps.
        acceleration_mm_s2 : float
            Acceleration of the two ramps, mm/s².
        open_at, close_at : int
            Steps of the table's first and last step: ``close_at`` is ``open_at`` ± the
            table's total steps.
        """
        self._query(f"TSWEEP {target} {self.accel(acceleration_mm_s2)} {open_at} "
                    f"{close_at}", n_fields=0)

    def fire(self, *, delay_us: int, duration_us: int) -> int:
        """``SHUTTER``: open after ``delay_us`` for ``duration_us``; returns the board time
        (unwrapped µs) at which the board received the command.

        Parameters
        ----------
        delay_us : int
            Time from the command's arrival to the shutter's opening, µs.
        duration_us : int
            How long the shutter is held open, µs.
        """
        (t,) = self._ints(self._query(f"SHUTTER {int(delay_us)} {int(duration_us)}",
                                      n_fields=1), "SHUTTER")
        return self.clock.unwrap(t)

    def set_watchdog(self, timeout_s: float) -> None:
        """``WATCHDOG <ms>``: the board stops and releases the shutter when the host is
        silent for ``timeout_s`` during motion or an exposure (0 turns it off). From now
        on :meth:`wait_event` and :meth:`keep_alive` send heartbeats.

        Parameters
        ----------
        timeout_s : float
            The watchdog's timeout, s: 0 (off) or 0.1 .. ``MAX_WATCHDOG_MS / 1000``.
        """
        ms = int(round(timeout_s * 1000))
        if not 0 <= ms <= MAX_WATCHDOG_MS or (ms and timeout_s < 0.1):
            raise DeviceError(f"{self.name}: watchdog {timeout_s:g} s outside 0 (off) or "
                              f"0.1..{MAX_WATCHDOG_MS / 1000:g} s")
        (got,) = self._ints(self._query(f"WATCHDOG {ms}", n_fields=1), "WATCHDOG")
        if got != ms:
            raise ProtocolError(f"{self.name}: WATCHDOG echoed {got}, sent {ms}")
        self.heartbeat_s = timeout_s / HEARTBEATS_PER_TIMEOUT if ms else None

    def keep_alive(self) -> None:
        """Send ``PING`` if the watchdog is on and nothing was sent for a heartbeat
        period (the reply is skipped when it arrives)."""
        if (self.heartbeat_s is not None
                and time.monotonic() - self.transport.last_write_s >= self.heartbeat_s):
            self.transport.write_line("PING")

    def close_shutter(self) -> None:
        self._query("CLOSE", n_fields=0)

    def stop(self) -> None:
        t, pos = self._ints(self._query("STOP", n_fields=2), "STOP")
        self.clock.unwrap(t)
        self.stopped_at = pos

    # -- events -------------------------------------------------------------------------
    def wait_event(self, name: str, *, timeout_s: float | None = None,
                   deadline: float | None = None,
                   on_event: Callable[[BoardEvent], None] | None = None) -> BoardEvent:
        """Consume events until ``name`` arrives; ``EV FAULT`` raises :class:`DeviceFault`.

        Parameters
        ----------
        name : str
            The event awaited, one of :data:`EVENT_NAMES`.
        timeout_s : float, optional
            How long to wait, s (default 1 s); ignored when ``deadline`` is given.
        deadline : float, optional
            The :func:`time.monotonic` time to wait until.
        on_event : callable, optional
            Called with every event consumed, the awaited one included.

        Returns
        -------
        BoardEvent
            The awaited event.
        """
        if deadline is None:
            deadline = time.monotonic() + (timeout_s if timeout_s is not None else 1.0)
        while True:
            while self._unread:
                ev = self._unread.pop(0)
                if on_event is not None:
                    on_event(ev)
                if ev.name == "FAULT":
                    raise DeviceFault(f"{self.name}: board fault {ev.detail or '?'} at step "
                                      f"{ev.position}")
                if ev.name == name:
                    return ev
            try:
                line = self.transport.read_line(deadline=deadline,
                                                keepalive=self._keepalive())
            except ReplyTimeout:
                raise ReplyTimeout(f"{self.name}: no EV {name} before the deadline") from None
            if _PING_RE.match(line):
                continue
            if self.take_event(line) is None:
                raise self._unexpected(line, f"line while waiting for EV {name}")

    def poll_events(self) -> None:
        """Read whatever events are waiting, without blocking (consumed by
        :meth:`wait_event`)."""
        while self.transport.pending():
            line = self.transport.read_line(timeout_s=0.0)
            if not _PING_RE.match(line) and self.take_event(line) is None:
                raise self._unexpected(line, "line between events")

    def safe_stop(self, *, timeout_s: float = SAFETY_REPLY_TIMEOUT_S) -> int | None:
        """Safety path: ``STOP`` (the board releases the shutter first, then stops the
        motor), tolerant of stray lines from an interrupted exchange. Returns the step
        position the board stopped at.

        Parameters
        ----------
        timeout_s : float
            How long to wait for ``OK STOP``, s.

        Returns
        -------
        int or None
            The step position the board stopped at (None: no reply).
        """
        def stopped_at(line: str):
            # the reply may follow the remains of a line the interruption cut short
            i = line.find("OK STOP ")
            if i < 0:
                return None
            fields = line[i:].split()[2:]
            if len(fields) != 2:
                return None
            return self._ints(fields, "STOP")[1]

        def keep_event(line: str) -> None:
            if line.startswith("EV "):
                try:
                    self.take_event(line)
                except ProtocolError:
                    pass

        return self.transport.send_on_safety_path("STOP", stopped_at, timeout_s=timeout_s,
                                                  on_other=keep_event)

    # -- units --------------------------------------------------------------------------
    def steps(self, mm: float) -> int:
        """A position in whole steps.

        Parameters
        ----------
        mm : float
            Position, mm (stage coordinates).
        """
        return int(round(mm * self.steps_per_mm))

    def rate(self, mm_s: float) -> int:
        """A velocity as the board's step rate, checked against what it can run.

        Parameters
        ----------
        mm_s : float
            Velocity, mm/s.

        Raises
        ------
        DeviceError
            The rate is outside 1 .. :data:`MAX_STEP_RATE` steps/s.
        """
        r = step_rate(mm_s, self.steps_per_mm)
        if not 1 <= r <= MAX_STEP_RATE:
            raise DeviceError(f"{self.name}: {mm_s:g} mm/s is {r} steps/s, outside the "
                              f"firmware's 1..{MAX_STEP_RATE} steps/s")
        return r

    def accel(self, mm_s2: float) -> int:
        """An acceleration as the board's steps/s² (:func:`step_accel`).

        Parameters
        ----------
        mm_s2 : float
            Acceleration, mm/s².
        """
        return step_accel(mm_s2, self.steps_per_mm)

    # -- internals ----------------------------------------------------------------------
    def _keepalive(self):
        if self.heartbeat_s is None:
            return None
        return self.heartbeat_s, lambda: self.transport.write_line("PING")

    def take_event(self, line: str) -> BoardEvent | None:
        """Take ``line`` as an ``EV`` line from the board: the event, its time unwrapped
        (:class:`BoardClock`), recorded in :attr:`events` and queued for
        :meth:`wait_event`.

        Parameters
        ----------
        line : str
            A line read from the board (without its end of line).

        Returns
        -------
        BoardEvent or None
            The event; None (nothing recorded) when ``line`` is not an event line.
        """
        m = _EVENT_RE.match(line)
        if not m:
            return None
        ev = BoardEvent(m.group(1), self.clock.unwrap(int(m.group(2))), int(m.group(3)),
                        m.group(4) or "", self.transport.log.now())
        self.events.append(ev)
        self._unread.append(ev)
        return ev

    def _query(self, command: str, *, n_fields: int) -> list[str]:
        self.transport.write_line(command)
        word = command.split()[0]
        deadline = time.monotonic() + self.transport.timeout_s
        while True:
            try:
                line = self.transport.read_line(deadline=deadline)
            except ReplyTimeout:
                raise ReplyTimeout(f"{self.name}: no reply to {command!r}") from None
            if (line.startswith("EV ") and self.take_event(line) is not None) or _PING_RE.match(line):
                continue
            return self._expect_ok(word, line, n_fields=n_fields, command=command)

    def _expect_ok(self, word: str, line: str, *, n_fields: int,
                   command: str | None = None) -> list[str]:
        m = _ERR_RE.match(line)
        if m:
            raise DeviceError(f"{self.name}: {command or word!r} refused: {m.group(1)} "
                              f"{m.group(2) or ''}".rstrip())
        parts = line.split(" ")
        if len(parts) != 2 + n_fields or parts[0] != "OK" or parts[1] != word:
            raise self._unexpected(line, f"reply to {command or word!r}")
        return parts[2:]

    def _unexpected(self, line: str, what: str) -> RigError:
        """The error for a line the protocol does not allow here. A ``READY`` line means
        the board restarted mid-session (a brown-out when the motor starts, a USB glitch,
        another program opening its port): it has stopped, released the shutter and
        forgotten its limits, watchdog and (without a home switch) position."""
        if line.startswith("READY "):
            return DeviceFault(f"{self.name}: the board restarted mid-session (it sent "
                               f"{line!r}, expected: {what}); it stopped and forgot its "
                               f"settings: check its power supply and that no other "
                               f"program opens its port, then home it again")
        return ProtocolError(f"{self.name}: unexpected {what}: {line!r}")

    def _ints(self, fields: Iterable[str], what: str) -> list[int]:
        try:
            return [int(f) for f in fields]
        except ValueError:
            raise ProtocolError(f"{self.name}: non-integer field in {what} reply "
                                f"{' '.join(fields)!r}") from None
