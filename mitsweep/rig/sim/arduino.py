"""The Arduino sweep controller's firmware, in Python (protocol in
:mod:`mitsweep.rig.arduino`): stepper with trapezoidal motion, home switch, soft limits,
the shutter opto, events with ``micros()`` timestamps (optionally started near the
32-bit wrap), step-rate tables (``TABLE``/``SEG``/``TSWEEP``: the table's segments
at constant rate, rate changes at once as the firmware's stepper makes them), and the
firmware's watchdog (``WATCHDOG <ms>``: while it moves or an
exposure is pending or open, a host silent for that long gets ``EV FAULT <t> <pos> WATCHDOG``
after the shutter was released and the motor stopped).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from ...optics.kinematics import Trapezoid
from ..arduino import (FIRMWARE_NAME, MAX_SEGMENT_STEPS, MAX_STEP_RATE, MAX_TABLE_SEGMENTS,
                       MAX_WATCHDOG_MS, POS_EVENT_PERIOD_US, PROTOCOL_VERSION)
from ..transport import XorChecksum
from .base import Fault, Model, Move, PathMove, command, table_pieces

__all__ = ["ArduinoModel", "FIRMWARE_VERSION"]

FIRMWARE_VERSION = "1.2"


class ArduinoModel(Model):
    """The sweep controller's firmware, in Python (see :mod:`mitsweep.rig.arduino`).

    Parameters
    ----------
    faults : iterable of Fault
        Faults to inject, each used once.
    homed : bool
        Whether the board starts knowing its position (a real board never does).
    position : int
        Start position, steps.
    micros_start : int
        ``micros()`` at boot (set near 2**32 to exercise the wrap).
    home_time_s : float
        How long homing takes, s.
    boot_time_s : float
        From a reset to the ``READY`` line, s (the bootloader's wait).
    """

    reset_on_open = True

    def __init__(self, faults: Iterable[Fault] = (), *, homed: bool = False, position: int = 0,
                 micros_start: int = 0, home_time_s: float = 0.05,
                 boot_time_s: float = 0.1) -> None:
        super().__init__(faults)
        self.homed = homed
        self._pos = int(position)
        self.limits: tuple[int, int] | None = None
        self.sweep_window: tuple[int, int] | None = None
        self.shutter_open = False
        self.shutter_history: list[tuple[str, float]] = []
        self.checksums = False
        self.micros_start = int(micros_start)
        self.home_time_s = home_time_s
        self.boot_time_s = boot_time_s
        self._boot_state = (homed, int(position))
        self.boot_t = 0.0
        self._shutter_plan: tuple[float, float] | None = None   # (open, close) times
        self._opened = False                    # the planned exposure has opened
        self.watchdog_s = 0.0                   # 0: off (the firmware's default)
        self.last_rx = 0.0                      # when the last line came from the host
        self.faults_seen: list[str] = []        # codes of the EV FAULTs sent
        self.table_size = 0                     # TABLE <n>: segments announced
        self.table: list[tuple[int, int]] = []  # (steps, us) received by SEG
        self._restart_at: float | None = None   # a brown-out fault's time

    # -- clock, position ----------------------------------------------------------------
    def micros(self, t: float) -> int:
        """The board's 32-bit ``micros()`` at server time ``t``.

        Parameters
        ----------
        t : float
            The server's time, s.
        """
        return (self.micros_start + int(round((t - self.boot_t) * 1e6))) % 2**32

    def position(self, now: float) -> int:
        """The stepper's position at ``now``, whole steps (the floor of the travel).

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        if self.move is not None:
            d = self.move.distance(now)
            return int(round(self.move.x0 + self.move.sign * math.floor(d + 1e-9)))
        return self._pos

    # -- output -------------------------------------------------------------------------
    def encode_line(self, text: str) -> bytes:
        """The bytes the board sends for one line of ``text``: its XOR checksum appended
        when the host turned checksums on (``CHK 1``), then the end of line. A subclass
        that answers a command its own way (another firmware version) builds its reply
        with it.

        Parameters
        ----------
        text : str
            The line, ASCII, without its end of line.

        Returns
        -------
        bytes
            What goes on the wire.
        """
        if self.checksums:
            text = XorChecksum().append(text)
        return text.encode("ascii") + b"\n"

    def _event(self, t: float, name: str, pos: int, detail: str = "") -> tuple[float, bytes]:
        text = f"EV {name} {self.micros(t)} {pos}" + (f" {detail}" if detail else "")
        return t, self.encode_line(text)

    def boot(self, now: float) -> list[bytes]:
        # the bootloader runs first, then the sketch prints READY
        self.boot_t = now
        self.schedule(now + self.boot_time_s,
                      self.encode_line(f"READY {FIRMWARE_NAME} {FIRMWARE_VERSION} {PROTOCOL_VERSION}"))
        return []

    def reset(self, now: float) -> None:
        """Opening the port pulses DTR, which resets an Uno: the sketch restarts with
        its constructor state (``homed=True`` thus models a board that keeps its
        reference across resets, which a real one does not), shutter released.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        self.cancel_scheduled()
        self.homed, self._pos = self._boot_state
        self.limits = None
        self.move = None
        self._shutter_plan = None
        self.shutter_open = False
        self.checksums = False
        self._fault_at = None
        self._restart_at = None
        self.watchdog_s = 0.0
        self.table_size, self.table = 0, []
        self.boot(now)

    # -- input --------------------------------------------------------------------------
    def handle(self, line: bytes, now: float) -> list[bytes]:
        self._settle(now)
        self.last_rx = now      # any line feeds the watchdog
        try:
            text = line.decode("ascii")
        except UnicodeDecodeError:
            return [self.encode_line("ERR SYNTAX non-ASCII")]
        if self.checksums:
            try:
                text = XorChecksum().strip(text)
            except Exception:
                return [self.encode_line("ERR CHECKSUM")]
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
            return [self.encode_line(f"ERR SYNTAX {word}")]
        handler, known_args = self.handler(parts)
        if handler is None:
            return [self.encode_line(f"ERR SYNTAX unknown command {word}")]
        if known_args is None:
            return [self.encode_line(f"ERR SYNTAX {word} takes {self.commands[(word,)][1]} "
                               f"arguments")]
        replies = handler(nums, now)
        slow = self.take_fault("slow_reply", word)
        if slow:
            for data in replies:
                self.schedule(now + slow.delay_s, data)
            return []
        return replies

    @command("ID", nargs=0)
    def _cmd_id(self, nums, now):
        return [
            self.encode_line(f"OK ID {FIRMWARE_NAME} {FIRMWARE_VERSION} {PROTOCOL_VERSION}")]

    @command("CHK", nargs=1)
    def _cmd_chk(self, nums, now):
        self.checksums = bool(nums[0])
        return [self.encode_line(f"OK CHK {int(self.checksums)}")]

    @command("PING", nargs=0)
    def _cmd_ping(self, nums, now):
        return [self.encode_line(f"OK PING {self.micros(now)}")]

    @command("WATCHDOG", nargs=1)
    def _cmd_watchdog(self, nums, now):
        if not 0 <= nums[0] <= MAX_WATCHDOG_MS:
            return [self.encode_line("ERR RANGE watchdog ms")]
        self.watchdog_s = nums[0] * 1e-3
        return [self.encode_line(f"OK WATCHDOG {nums[0]}")]

    @property
    def exposure_pending(self) -> bool:
        """Whether an exposure is planned (by ``SWEEP``, ``TSWEEP`` or ``SHUTTER``) and not
        yet over: the shutter is to open, or is open and to close at its planned time."""
        return self._shutter_plan is not None

    def watchdog_armed(self, now: float) -> bool:
        """Motion, or an exposure pending or open: what the watchdog guards.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        return (self.moving(now) or self._shutter_plan is not None or self.shutter_open
                or any(tag == "homing" for _, _, tag in self._scheduled))

    @command("STATE", nargs=0)
    def _cmd_state(self, nums, now):
        return [self.encode_line(
            f"OK STATE {self.micros(now)} {self.position(now)} {int(self.homed)} "
            f"{int(self.moving(now))} {int(self.shutter_open)}")]

    @command("LIMITS", nargs=2)
    def _cmd_limits(self, nums, now):
        lo, hi = nums
        if lo >= hi:
            return [self.encode_line("ERR RANGE min must be < max")]
        self.limits = (lo, hi)
        return [self.encode_line(f"OK LIMITS {lo} {hi}")]

    def _check_move(self, target, rate, accel, now):
        if self.moving(now):
            return [self.encode_line("ERR BUSY moving")]
        if not self.homed:
            return [self.encode_line("ERR HOME not homed")]
        if not (1 <= rate <= MAX_STEP_RATE) or accel < 1:
            return [self.encode_line("ERR RANGE rate or accel")]
        if self.limits is None or not (self.limits[0] <= target <= self.limits[1]):
            return [self.encode_line("ERR LIMIT target outside soft limits")]
        return None

    @command("HOME", nargs=1)
    def _cmd_home(self, nums, now):
        if self.moving(now):
            return [self.encode_line("ERR BUSY moving")]
        self.homed, self._pos = True, 0
        self.schedule(*self._event(now + self.home_time_s, "HOMED", 0), "homing")
        return [self.encode_line("OK HOME")]

    def _start_move(self, target, rate, accel, now):
        x0 = self.position(now)
        self.move = Move(x0, target, rate, accel, now)
        self.stopped = False
        return x0

    @command("MOVE", nargs=3)
    def _cmd_move(self, nums, now):
        target, rate, accel = nums
        if err := self._check_move(target, rate, accel, now):
            return err
        self._start_move(target, rate, accel, now)
        self.schedule(*self._event(self.move.end_time, "DONE", target))
        return [self.encode_line("OK MOVE")]

    @command("SWEEP", nargs=5)
    def _cmd_sweep(self, nums, now):
        target, rate, accel, open_at, close_at = nums
        if err := self._check_move(target, rate, accel, now):
            return err
        x0 = self.position(now)
        mv = Move(x0, target, rate, accel, now)
        ramp = math.ceil(Trapezoid.reaching(rate, accel).ramp_distance)
        d_open, d_close = abs(open_at - x0), abs(close_at - x0)
        inside = lambda p: min(x0, target) <= p <= max(x0, target)
        if not (inside(open_at) and inside(close_at) and ramp <= d_open < d_close
                <= mv.length - ramp):
            return [self.encode_line("ERR RANGE open/close outside the constant-velocity part")]
        self._start_move(target, rate, accel, now)
        self.sweep_window = (open_at, close_at)
        self._schedule_sweep(mv, x0, target, open_at, close_at, d_open, d_close, now)
        return [self.encode_line("OK SWEEP")]

    def _schedule_sweep(self, mv, x0, target, open_at, close_at, d_open, d_close, now):
        """The events of a sweep under way (``mv``): START, OPEN, POS every period,
        CLOSE, DONE, and the shutter's plan."""
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
        self.arm_motion_faults(mv)

    @command("TABLE", nargs=1)
    def _cmd_table(self, nums, now):
        if self.moving(now):
            return [self.encode_line("ERR BUSY moving")]
        if not 1 <= nums[0] <= MAX_TABLE_SEGMENTS:
            return [self.encode_line("ERR RANGE table size")]
        self.table_size, self.table = nums[0], []
        return [self.encode_line(f"OK TABLE {nums[0]}")]

    @command("SEG", nargs=3)
    def _cmd_seg(self, nums, now):
        i, steps, us = nums
        if self.moving(now):
            return [self.encode_line("ERR BUSY moving")]
        if i != len(self.table) or i >= self.table_size:
            return [self.encode_line("ERR RANGE segment order")]
        # at most MAX_STEP_RATE steps/s, in integers as the firmware checks
        if not (0 <= steps <= MAX_SEGMENT_STEPS and us >= 1
                and steps * (1_000_000 // MAX_STEP_RATE) <= us):
            return [self.encode_line("ERR RANGE segment steps or duration")]
        self.table.append((steps, us))
        total_steps = sum(k for k, _ in self.table)
        total_us = sum(u for _, u in self.table)
        return [self.encode_line(f"OK SEG {i} {total_steps} {total_us}")]

    @command("TSWEEP", nargs=4)
    def _cmd_tsweep(self, nums, now):
        target, accel, open_at, close_at = nums
        table = self.table
        if (not table or len(table) != self.table_size or table[0][0] == 0
                or table[-1][0] == 0):
            return [self.encode_line("ERR RANGE no complete table")]
        rate_in = table[0][0] * 1e6 / table[0][1]
        rate_out = table[-1][0] * 1e6 / table[-1][1]
        if err := self._check_move(target, math.ceil(rate_in), accel, now):
            return err
        x0 = self.position(now)
        sign = 1 if target >= x0 else -1
        ramp_in = math.ceil(rate_in * rate_in / (2 * accel) - 1e-6)
        ramp_out = math.ceil(rate_out * rate_out / (2 * accel) - 1e-6)
        d_open, d_close = sign * (open_at - x0), sign * (close_at - x0)
        length = abs(target - x0)
        if (d_open < ramp_in or d_close - d_open != sum(k for k, _ in table)
                or d_close > length - ramp_out):
            return [self.encode_line("ERR RANGE open/close do not fit the table and its ramps")]
        pieces = table_pieces(rate_in, rate_out, accel, d_open, length - d_close,
                              [(k, u * 1e-6) for k, u in table])
        mv = PathMove(x0, sign, now, pieces)
        self.move, self.stopped = mv, False
        self.sweep_window = (open_at, close_at)
        self._schedule_sweep(mv, x0, target, open_at, close_at, d_open, d_close, now)
        return [self.encode_line("OK TSWEEP")]

    @command("SHUTTER", nargs=2)
    def _cmd_shutter(self, nums, now):
        delay_us, duration_us = nums
        if delay_us < 0 or duration_us < 1:
            return [self.encode_line("ERR RANGE delay or duration")]
        t_open = now + delay_us * 1e-6
        t_close = t_open + duration_us * 1e-6
        late = self.take_fault("late_event")
        delay = late.delay_s if late else 0.0
        pos = self.position(now)
        self.schedule(*self._event(t_open, "OPEN", pos), "shutter")
        t_ev, line = self._event(t_close, "CLOSE", pos)
        self.schedule(t_ev + delay, line, "shutter")
        self._set_shutter_plan(t_open, t_close)
        return [self.encode_line(f"OK SHUTTER {self.micros(now)}")]

    @command("CLOSE", nargs=None)
    def _cmd_close(self, nums, now):
        self._close_now(now)
        return [self.encode_line("OK CLOSE")]

    def _close_now(self, now):
        if self.shutter_open:
            self.shutter_history.append(("close", now))
        self.shutter_open = False
        self._shutter_plan = None
        self.cancel_scheduled("shutter")

    def _set_shutter_plan(self, t_open, t_close):
        self._shutter_plan = (t_open, t_close)
        self._opened = False

    @command("STOP", nargs=None)
    def _cmd_stop(self, nums, now):
        self._close_now(now)
        self.cancel_scheduled()
        pos = self.position(now)
        self.move, self._pos, self.stopped = None, pos, True
        self._fault_at = None
        return [self.encode_line(f"OK STOP {self.micros(now)} {pos}")]

    def arm_motion_faults(self, mv: Move) -> None:
        super().arm_motion_faults(mv)
        f = self.take_fault("brownout")
        if f:
            self._restart_at = mv.t0 + f.at_fraction * mv.duration

    def tick(self, now: float) -> list[bytes]:
        """Advance the shutter and faults to ``now``; scheduled lines are emitted by the
        server.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        if self._restart_at is not None and now >= self._restart_at:
            # a brown-out: the sketch restarts where the motor stopped, its position lost
            t, self._restart_at = self._restart_at, None
            out = self.tick(t)
            pos = self.position(t)
            self._close_now(t)
            self.reset(t)
            self._pos, self.homed = pos, False
            return out + self.tick(now)
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
