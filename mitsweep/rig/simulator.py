"""Device simulators for the rig, served on a pseudo-terminal, with fault injection.

:class:`PtyDevice` opens a pty pair (``os.openpty``) and runs a device model in a thread
on the master side; the driver opens the slave path (``/dev/pts/N``) with pyserial
exactly like a real port. Closing the master mid-run is an unplugged cable: the driver's
next read or write fails like a vanished USB adapter.

Models:

- :class:`ArduinoModel`: the project's sweep controller (protocol in
  :mod:`mitsweep.rig.arduino`): stepper with trapezoidal motion, home switch, soft
  limits, the shutter opto, events with ``micros()`` timestamps (optionally started
  near the 32-bit wrap).
- :class:`ZaberModel`: one Zaber ASCII-protocol axis (replies, BUSY/IDLE, warning flags,
  ``WR`` until homed, device-side limits, checksums when the command carries one).

Timing: motion is analytic (constant acceleration ramps, constant cruise), and every
event's timestamp is computed from the motion at 1 µs resolution — not from when the
thread happens to emit it — so measured exposures are exact up to the 1 µs
quantisation of ``micros()``. Emission lags the timestamp by the loop's ~1 ms poll.

Faults (:class:`Fault`): ``no_reply`` (a command is swallowed), ``garbage`` (answered
with non-ASCII bytes), ``fault_flag`` (the stage stalls part-way through the next move:
Arduino ``EV FAULT``, Zaber ``FS``), ``unplug`` (the port vanishes part-way through the
next move), ``late_event`` (the end-of-exposure events arrive ``delay_s`` late),
``slow_reply`` (Arduino: a command acts at once but its reply comes ``delay_s`` late).

The Arduino model has the firmware's watchdog (``WATCHDOG <ms>``): while it moves or an
exposure is pending or open, a host silent for that long gets ``EV FAULT ... WATCHDOG``
after the shutter was released and the motor stopped. The Zaber model has none (see
:mod:`mitsweep.rig.capture`).

Run ``python -m mitsweep.rig.simulator arduino|zaber`` to serve one by hand.
"""

from __future__ import annotations

import fcntl
import logging
import math
import os
import re
import select
import struct
import termios
import threading
import time
import tty
from dataclasses import dataclass

from ..optics.kinematics import Trapezoid
from .arduino import (FIRMWARE_NAME, MAX_STEP_RATE, MAX_WATCHDOG_MS, POS_EVENT_PERIOD_US,
                      PROTOCOL_VERSION)
from .transport import XorChecksum, ZaberChecksum

__all__ = ["Fault", "FAULT_KINDS", "Move", "ArduinoModel", "ZaberModel", "PtyDevice"]

logger = logging.getLogger(__name__)

FAULT_KINDS = ("no_reply", "garbage", "fault_flag", "unplug", "late_event", "slow_reply")
FIRMWARE_VERSION = "1.1"


@dataclass(frozen=True)
class Fault:
    """One injected fault.

    kind : one of :data:`FAULT_KINDS`.
    command : for ``no_reply`` / ``garbage`` / ``slow_reply``: the command word it hits
        (``"SWEEP"``, ``"STATE"``, ``"move"``, ...); the first such command only.
    at_fraction : for ``fault_flag`` / ``unplug``: fraction of the next long move
        (SWEEP, or a Zaber ``move``) at which it happens.
    delay_s : for ``late_event``: how late the end-of-exposure events are; for
        ``slow_reply``: how late the reply is.
    """

    kind: str
    command: str | None = None
    at_fraction: float = 0.5
    delay_s: float = 5.0

    def __post_init__(self) -> None:
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"fault kind must be one of {', '.join(FAULT_KINDS)}, got {self.kind!r}")
        if self.kind in ("no_reply", "garbage", "slow_reply") and not self.command:
            raise ValueError(f"fault {self.kind!r} needs the command word it hits")
        if not 0.0 <= self.at_fraction <= 1.0:
            raise ValueError(f"fault at_fraction must be in [0, 1], got {self.at_fraction}")


class Move:
    """Trapezoidal (or triangular) point-to-point motion from ``x0`` to ``x1`` starting at
    ``t0``, in the caller's units (steps, steps/s, steps/s², s): a
    :class:`~mitsweep.optics.kinematics.Trapezoid` placed in position and time."""

    def __init__(self, x0: float, x1: float, v: float, a: float, t0: float) -> None:
        self.x0, self.x1, self.t0 = float(x0), float(x1), float(t0)
        self.sign = 1.0 if x1 >= x0 else -1.0
        self.profile = Trapezoid(abs(self.x1 - self.x0), v, a)
        self.length = self.profile.distance
        self.duration = self.profile.duration

    def distance(self, t: float) -> float:
        return self.profile.position_at(t - self.t0)

    def position(self, t: float) -> float:
        return self.x0 + self.sign * self.distance(t)

    def time_at(self, d: float) -> float:
        return self.t0 + self.profile.time_at(d)

    @property
    def end_time(self) -> float:
        return self.t0 + self.duration


class _Model:
    """Base of the device models: a scheduled-output queue and fault bookkeeping."""

    checksum_cls = XorChecksum

    def __init__(self, faults=()) -> None:
        self.faults = list(faults)
        self._scheduled: list[tuple[float, bytes, str]] = []
        self.unplug_at: float | None = None
        self.log: list[tuple[float, str, str]] = []   # (t, "rx"/"tx", text) seen by the device

    def schedule(self, t: float, data: bytes, tag: str = "") -> None:
        self._scheduled.append((t, data, tag))
        self._scheduled.sort(key=lambda x: x[0])

    def due(self, now: float) -> list[bytes]:
        out = []
        while self._scheduled and self._scheduled[0][0] <= now:
            out.append(self._scheduled.pop(0)[1])
        return out

    def next_due(self) -> float | None:
        times = [t for t, _, _ in self._scheduled[:1]]
        if self.unplug_at is not None:
            times.append(self.unplug_at)
        return min(times) if times else None

    def cancel_scheduled(self, tag: str | None = None) -> None:
        self._scheduled = [s for s in self._scheduled if tag is not None and s[2] != tag]

    def take_fault(self, kind: str, command: str | None = None) -> Fault | None:
        for f in self.faults:
            if f.kind == kind and (command is None or f.command == command):
                self.faults.remove(f)
                return f
        return None

    #: Whether opening the port resets the device (an Uno's auto-reset on DTR).
    reset_on_open = False

    def boot(self, now: float) -> list[bytes]:  # pragma: no cover - overridden
        return []

    def reset(self, now: float) -> None:
        """The host opened (and flushed) the port."""

    def handle(self, line: bytes, now: float) -> list[bytes]:  # pragma: no cover
        raise NotImplementedError

    def on_unplug(self, now: float) -> None:
        pass

    # -- motion bookkeeping shared by the stage models (``move``: the Move under way,
    # ``_pos``: the position at rest, in device units) ----------------------------------
    move: "Move | None" = None
    _pos: int = 0

    def moving(self, now: float) -> bool:
        return self.move is not None and now < self.move.end_time

    def _settle(self, now: float) -> None:
        if self.move is not None and now >= self.move.end_time:
            self._pos = int(round(self.move.x1))
            self.move = None


class ArduinoModel(_Model):
    """The sweep controller's firmware, in Python (see :mod:`mitsweep.rig.arduino`).

    Parameters
    ----------
    faults : iterable of Fault
    homed : bool
        Whether the board starts knowing its position (a real board never does).
    micros_start : int
        ``micros()`` at boot (set near 2**32 to exercise the wrap).
    home_time_s : float
        How long homing takes.
    """

    def __init__(self, faults=(), *, homed: bool = False, position: int = 0,
                 micros_start: int = 0, home_time_s: float = 0.05,
                 boot_time_s: float = 0.1) -> None:
        super().__init__(faults)
        self.homed = homed
        self._pos = int(position)
        self.limits: tuple[int, int] | None = None
        self.move: Move | None = None
        self.sweep_window: tuple[int, int] | None = None
        self.shutter_open = False
        self.shutter_history: list[tuple[str, float]] = []
        self.checksums = False
        self.micros_start = int(micros_start)
        self.home_time_s = home_time_s
        self.boot_time_s = boot_time_s
        self._boot_state = (homed, int(position))
        self.boot_t = 0.0
        self.stopped = False
        self._fault_at: float | None = None
        self.watchdog_s = 0.0                   # 0: off (the firmware's default)
        self.last_rx = 0.0                      # when the last line came from the host
        self.faults_seen: list[str] = []        # codes of the EV FAULTs sent

    # -- clock, position ----------------------------------------------------------------
    def micros(self, t: float) -> int:
        return (self.micros_start + int(round((t - self.boot_t) * 1e6))) % 2**32

    def position(self, now: float) -> int:
        if self.move is not None:
            d = self.move.distance(now)
            return int(round(self.move.x0 + self.move.sign * math.floor(d + 1e-9)))
        return self._pos


    # -- output -------------------------------------------------------------------------
    def _line(self, text: str) -> bytes:
        if self.checksums:
            text = XorChecksum().append(text)
        return text.encode("ascii") + b"\n"

    def _event(self, t: float, name: str, pos: int, detail: str = "") -> tuple[float, bytes]:
        text = f"EV {name} {self.micros(t)} {pos}" + (f" {detail}" if detail else "")
        return t, self._line(text)

    reset_on_open = True

    def boot(self, now: float) -> list[bytes]:
        # the bootloader runs first, then the sketch prints READY
        self.boot_t = now
        self.schedule(now + self.boot_time_s,
                      self._line(f"READY {FIRMWARE_NAME} {FIRMWARE_VERSION} {PROTOCOL_VERSION}"))
        return []

    def reset(self, now: float) -> None:
        """Opening the port pulses DTR, which resets an Uno: the sketch restarts with
        its constructor state (``homed=True`` thus models a board that keeps its
        reference across resets, which a real one does not), shutter released."""
        self.cancel_scheduled()
        self.homed, self._pos = self._boot_state
        self.limits = None
        self.move = None
        self._shutter_plan = None
        self.shutter_open = False
        self.checksums = False
        self._fault_at = None
        self.watchdog_s = 0.0
        self.boot(now)

    # -- input --------------------------------------------------------------------------
    def handle(self, line: bytes, now: float) -> list[bytes]:
        self._settle(now)
        self.last_rx = now      # any line feeds the watchdog
        try:
            text = line.decode("ascii")
        except UnicodeDecodeError:
            return [self._line("ERR SYNTAX non-ASCII")]
        if self.checksums:
            try:
                text = XorChecksum().strip(text)
            except Exception:
                return [self._line("ERR CHECKSUM")]
        parts = text.split()
        if not parts:
            return []
        word, args = parts[0], parts[1:]
        if self.take_fault("no_reply", word):
            return []
        if self.take_fault("garbage", word):
            return [b"\xfe\x81\x00garbage\xff\n"]
        try:
            nums = [int(a) for a in args]
        except ValueError:
            return [self._line(f"ERR SYNTAX {word}")]
        handler = getattr(self, f"_cmd_{word.lower()}", None) if word.isupper() else None
        if handler is None:
            return [self._line(f"ERR SYNTAX unknown command {word}")]
        replies = handler(nums, now)
        slow = self.take_fault("slow_reply", word)
        if slow:
            for data in replies:
                self.schedule(now + slow.delay_s, data)
            return []
        return replies

    def _nargs(self, nums, n, word):
        if len(nums) != n:
            return [self._line(f"ERR SYNTAX {word} takes {n} arguments")]
        return None

    def _cmd_id(self, nums, now):
        return self._nargs(nums, 0, "ID") or [
            self._line(f"OK ID {FIRMWARE_NAME} {FIRMWARE_VERSION} {PROTOCOL_VERSION}")]

    def _cmd_chk(self, nums, now):
        if err := self._nargs(nums, 1, "CHK"):
            return err
        self.checksums = bool(nums[0])
        return [self._line(f"OK CHK {int(self.checksums)}")]

    def _cmd_ping(self, nums, now):
        return self._nargs(nums, 0, "PING") or [self._line(f"OK PING {self.micros(now)}")]

    def _cmd_watchdog(self, nums, now):
        if err := self._nargs(nums, 1, "WATCHDOG"):
            return err
        if not 0 <= nums[0] <= MAX_WATCHDOG_MS:
            return [self._line("ERR RANGE watchdog ms")]
        self.watchdog_s = nums[0] * 1e-3
        return [self._line(f"OK WATCHDOG {nums[0]}")]

    def watchdog_armed(self, now: float) -> bool:
        """Motion, or an exposure pending or open: what the watchdog guards."""
        return (self.moving(now) or self._shutter_plan is not None or self.shutter_open
                or any(tag == "homing" for _, _, tag in self._scheduled))

    def _cmd_state(self, nums, now):
        return self._nargs(nums, 0, "STATE") or [self._line(
            f"OK STATE {self.micros(now)} {self.position(now)} {int(self.homed)} "
            f"{int(self.moving(now))} {int(self.shutter_open)}")]

    def _cmd_limits(self, nums, now):
        if err := self._nargs(nums, 2, "LIMITS"):
            return err
        lo, hi = nums
        if lo >= hi:
            return [self._line("ERR RANGE min must be < max")]
        self.limits = (lo, hi)
        return [self._line(f"OK LIMITS {lo} {hi}")]

    def _check_move(self, target, rate, accel, now):
        if self.moving(now):
            return [self._line("ERR BUSY moving")]
        if not self.homed:
            return [self._line("ERR HOME not homed")]
        if not (1 <= rate <= MAX_STEP_RATE) or accel < 1:
            return [self._line("ERR RANGE rate or accel")]
        if self.limits is None or not (self.limits[0] <= target <= self.limits[1]):
            return [self._line("ERR LIMIT target outside soft limits")]
        return None

    def _cmd_home(self, nums, now):
        if err := self._nargs(nums, 1, "HOME"):
            return err
        if self.moving(now):
            return [self._line("ERR BUSY moving")]
        self.homed, self._pos = True, 0
        self.schedule(*self._event(now + self.home_time_s, "HOMED", 0), "homing")
        return [self._line("OK HOME")]

    def _start_move(self, target, rate, accel, now):
        x0 = self.position(now)
        self.move = Move(x0, target, rate, accel, now)
        self.stopped = False
        return x0

    def _cmd_move(self, nums, now):
        if err := self._nargs(nums, 3, "MOVE"):
            return err
        target, rate, accel = nums
        if err := self._check_move(target, rate, accel, now):
            return err
        self._start_move(target, rate, accel, now)
        self.schedule(*self._event(self.move.end_time, "DONE", target))
        return [self._line("OK MOVE")]

    def _cmd_sweep(self, nums, now):
        if err := self._nargs(nums, 5, "SWEEP"):
            return err
        target, rate, accel, open_at, close_at = nums
        if err := self._check_move(target, rate, accel, now):
            return err
        x0 = self.position(now)
        mv = Move(x0, target, rate, accel, now)
        ramp = math.ceil(Trapezoid.reaching(rate, accel).ramp_distance)
        d_open, d_close = abs(open_at - x0), abs(close_at - x0)
        inside = lambda p: min(x0, target) <= p <= max(x0, target)  # noqa: E731
        if not (inside(open_at) and inside(close_at) and ramp <= d_open < d_close
                <= mv.length - ramp):
            return [self._line("ERR RANGE open/close outside the constant-velocity part")]
        self._start_move(target, rate, accel, now)
        self.sweep_window = (open_at, close_at)
        t_open, t_close = mv.time_at(d_open), mv.time_at(d_close)
        late = self.take_fault("late_event")
        delay = late.delay_s if late else 0.0
        self.schedule(*self._event(now, "START", x0))
        self.schedule(*self._event(t_open, "OPEN", open_at), "shutter")
        period = POS_EVENT_PERIOD_US * 1e-6
        k = 1
        while now + k * period < mv.end_time:
            t = now + k * period
            self.schedule(*self._event(t, "POS", self.position(t)))
            k += 1
        t_ev, line = self._event(t_close, "CLOSE", close_at)
        self.schedule(t_ev + delay, line, "shutter")
        t_ev, line = self._event(mv.end_time, "DONE", target)
        self.schedule(t_ev + delay, line)
        self._set_shutter_plan(t_open, t_close)
        self._arm_motion_faults(mv)
        return [self._line("OK SWEEP")]

    def _arm_motion_faults(self, mv: Move) -> None:
        f = self.take_fault("fault_flag")
        if f:
            self._fault_at = mv.t0 + f.at_fraction * mv.duration
        f = self.take_fault("unplug")
        if f:
            self.unplug_at = mv.t0 + f.at_fraction * mv.duration

    def _cmd_shutter(self, nums, now):
        if err := self._nargs(nums, 2, "SHUTTER"):
            return err
        delay_us, duration_us = nums
        if delay_us < 0 or duration_us < 1:
            return [self._line("ERR RANGE delay or duration")]
        t_open = now + delay_us * 1e-6
        t_close = t_open + duration_us * 1e-6
        late = self.take_fault("late_event")
        delay = late.delay_s if late else 0.0
        pos = self.position(now)
        self.schedule(*self._event(t_open, "OPEN", pos), "shutter")
        t_ev, line = self._event(t_close, "CLOSE", pos)
        self.schedule(t_ev + delay, line, "shutter")
        self._set_shutter_plan(t_open, t_close)
        return [self._line(f"OK SHUTTER {self.micros(now)}")]

    def _cmd_close(self, nums, now):
        self._close_now(now)
        return [self._line("OK CLOSE")]

    def _close_now(self, now):
        if self.shutter_open:
            self.shutter_history.append(("close", now))
        self.shutter_open = False
        self._shutter_plan = None
        self.cancel_scheduled("shutter")

    def _set_shutter_plan(self, t_open, t_close):
        self._shutter_plan = (t_open, t_close)
        self._opened = False

    def _cmd_stop(self, nums, now):
        self._close_now(now)
        self.cancel_scheduled()
        pos = self.position(now)
        self.move, self._pos, self.stopped = None, pos, True
        self._fault_at = None
        return [self._line(f"OK STOP {self.micros(now)} {pos}")]

    _shutter_plan: tuple[float, float] | None = None

    def tick(self, now: float) -> list[bytes]:
        """Advance the shutter and faults to ``now``; scheduled lines are emitted by the
        server."""
        out = []
        if self._shutter_plan is not None:
            t_open, t_close = self._shutter_plan
            if now >= t_open and not self._opened:
                self._opened = self.shutter_open = True
                self.shutter_history.append(("open", t_open))
            if now >= t_close:
                self.shutter_open = False
                self.shutter_history.append(("close", t_close))
                self._shutter_plan = None
        if self._fault_at is not None and now >= self._fault_at:
            out.append(self._fault(self._fault_at, "STALL"))
        expiry = self.last_rx + self.watchdog_s
        if self.watchdog_s and now >= expiry and self.watchdog_armed(expiry):
            out.append(self._fault(expiry, "WATCHDOG"))
        self._settle(now)
        return out

    def _fault(self, t: float, code: str) -> bytes:
        """Release the shutter, stop the motor (at time ``t``), then the ``EV FAULT``."""
        pos = self.position(t)
        self._close_now(t)
        self.cancel_scheduled()
        self.move, self._pos, self.stopped = None, pos, True
        self._fault_at = None
        self.faults_seen.append(code)
        return self._event(t, "FAULT", pos, code)[1]

    def on_unplug(self, now: float) -> None:
        # USB-powered board: power goes, the motor stops and the opto releases
        pos = self.position(now)
        if self.shutter_open:
            self.shutter_history.append(("close", now))
        self.shutter_open = False
        self._shutter_plan = None
        self.move, self._pos, self.stopped = None, pos, True


_ZABER_CMD_RE = re.compile(r"^/(\d{1,2})(?: (\d))?(?: (\d{1,2}))? ?(.*)$")


class ZaberModel(_Model):
    """One Zaber ASCII-protocol axis (device ``device``, axis 1).

    Parameters
    ----------
    faults : iterable of Fault
    device : int
        Address on the chain.
    device_id : int
        What ``get deviceid`` answers.
    homed : bool
        Start with a reference position (a real stage does not: flag ``WR``).
    position : int
        Start position, microsteps.
    max_position : int
        The stage's physical travel, microsteps (``limit.max`` default).
    """

    def __init__(self, faults=(), *, device: int = 1, device_id: int = 50081,
                 homed: bool = False, position: int = 0, max_position: int = 25 * 20997,
                 home_speed: int = 400_000) -> None:
        super().__init__(faults)
        self.device, self.device_id = device, device_id
        self.homed = homed
        self._pos = position
        self.settings = {"maxspeed": 153_600, "accel": 205, "limit.min": 0,
                         "limit.max": max_position}
        self.move: Move | None = None
        self.flags: set[str] = set()
        self.home_speed = home_speed
        self._fault_at: float | None = None
        self.stopped = False

    def position(self, now: float) -> int:
        if self.move is not None:
            return int(round(self.move.position(now)))
        return self._pos


    def tick(self, now: float) -> list[bytes]:
        if self._fault_at is not None and now >= self._fault_at:
            self._pos = self.position(self._fault_at)
            self.move = None
            self.flags.add("FS")
            self._fault_at = None
            self.stopped = True
        self._settle(now)
        return []

    def on_unplug(self, now: float) -> None:
        # a Zaber stage has its own supply: losing the serial link does not stop a move
        # already commanded; it ends at its target, inside the device-side limits
        self.link_lost_at = now

    def _flag(self) -> str:
        for f in sorted(self.flags):
            if f.startswith("F"):
                return f
        if not self.homed:
            return "WR"
        for f in sorted(self.flags):
            return f
        return "--"

    def _reply(self, axis, mid, ok, data, now, checksum) -> bytes:
        status = "BUSY" if self.moving(now) else "IDLE"
        head = f"@{self.device:02d} {axis}" + (f" {mid}" if mid is not None else "")
        text = f"{head} {'OK' if ok else 'RJ'} {status} {self._flag()} {data}"
        if checksum:
            text = ZaberChecksum().append(text)
        return text.encode("ascii") + b"\r\n"

    def handle(self, line: bytes, now: float) -> list[bytes]:
        self.tick(now)
        try:
            text = line.decode("ascii").strip()
        except UnicodeDecodeError:
            return []
        has_checksum = bool(re.search(r":[0-9A-Fa-f]{2}$", text))
        if has_checksum:
            body = text[:-3]
            if ZaberChecksum.value(body) != int(text[-2:], 16):
                return []  # a device drops a message whose checksum fails
            text = body
        m = _ZABER_CMD_RE.match(text)
        if not m:
            return []
        dev, axis, mid, cmd = m.groups()
        if int(dev) not in (0, self.device):
            return []
        axis = int(axis or 0)
        mid = int(mid) if mid is not None else None
        words = cmd.split()
        word = words[0] if words else ""
        if self.take_fault("no_reply", word):
            return []
        if self.take_fault("garbage", word):
            return [b"@\xff\xfe\x00\x13garbage\r\n"]
        reply = lambda ok, data: [self._reply(axis, mid, ok, data, now, has_checksum)]  # noqa: E731
        if axis not in (0, 1):
            return reply(False, "BADAXIS")
        if words[:1] == ["get"] and len(words) == 2:
            key = words[1]
            if key == "deviceid":
                return reply(True, str(self.device_id))
            if key == "pos":
                return reply(True, str(self.position(now)))
            if key in self.settings:
                return reply(True, str(self.settings[key]))
            return reply(False, "BADCOMMAND")
        if words[:1] == ["set"] and len(words) == 3 and words[1] in self.settings:
            try:
                value = int(words[2])
            except ValueError:
                return reply(False, "BADDATA")
            if words[1] in ("maxspeed", "accel") and value < 1:
                return reply(False, "BADDATA")
            self.settings[words[1]] = value
            return reply(True, "0")
        if words == ["home"]:
            if self.moving(now):
                self._pos = self.position(now)
            self.move = Move(self.position(now), 0, self.home_speed, 10 * self.home_speed, now)
            self.homed = True
            self.flags.discard("FS")
            return reply(True, "0")
        if words[:2] == ["move", "abs"] and len(words) == 3:
            try:
                target = int(words[2])
            except ValueError:
                return reply(False, "BADDATA")
            if not self.settings["limit.min"] <= target <= self.settings["limit.max"]:
                return reply(False, "BADDATA")
            if any(f.startswith("F") for f in self.flags):
                return reply(False, "BADDATA")
            x0 = self.position(now)
            self.move = Move(x0, target, self.settings["maxspeed"] / 1.6384,
                             self.settings["accel"] * 10 / 1.6384, now)
            self.stopped = False
            f = self.take_fault("fault_flag")
            if f:
                self._fault_at = now + f.at_fraction * self.move.duration
            f = self.take_fault("unplug")
            if f:
                self.unplug_at = now + f.at_fraction * self.move.duration
            return reply(True, "0")
        if words in (["stop"], ["estop"]):
            was_moving = self.moving(now)
            self._pos = self.position(now)
            self.move = None
            self.stopped = True
            self._fault_at = None
            if was_moving:
                self.flags.add("NI")
            return reply(True, "0")
        if words == ["warnings"] or words == ["warnings", "clear"]:
            flags = sorted(self.flags | (set() if self.homed else {"WR"}))
            data = f"{len(flags):02d}" + "".join(f" {f}" for f in flags)
            out = reply(True, data)
            if words[-1] == "clear":
                self.flags.clear()
            return out
        return reply(False, "BADCOMMAND")


class PtyDevice:
    """Serve a device model on a pseudo-terminal.

    Use as a context manager; :attr:`port` is the slave path to give the driver.

    Parameters
    ----------
    model : ArduinoModel or ZaberModel
    poll_s : float
        Loop period (s) when nothing is due; bounds the emission latency of events.
    """

    def __init__(self, model, *, poll_s: float = 0.001) -> None:
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

    def __enter__(self) -> "PtyDevice":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def start(self) -> None:
        with self._lock:
            for data in self.model.boot(time.monotonic()):
                os.write(self.master, data)
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

    def _close_fds(self) -> None:
        if not self.unplugged:
            self.unplugged = True
            for fd in (self.master, self.slave):
                try:
                    os.close(fd)
                except OSError:
                    pass

    def _run(self) -> None:
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
                        os.write(self.master, data)
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
                            os.write(self.master, data)


def _main(argv=None) -> int:  # pragma: no cover - manual use
    import argparse

    p = argparse.ArgumentParser(description="serve a simulated rig device on a pty")
    p.add_argument("device", choices=["arduino", "zaber"])
    p.add_argument("--homed", action="store_true")
    args = p.parse_args(argv)
    model = ArduinoModel(homed=args.homed) if args.device == "arduino" \
        else ZaberModel(homed=args.homed)
    with PtyDevice(model) as dev:
        print(dev.port, flush=True)
        try:
            while True:
                time.sleep(1)
        except KeyboardInterrupt:
            return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
