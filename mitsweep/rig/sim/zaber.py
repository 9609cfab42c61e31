"""One Zaber ASCII-protocol axis, in Python (protocol in :mod:`mitsweep.rig.zaber`):
replies, BUSY/IDLE, warning flags, ``WR`` until homed, device-side limits, checksums
when the command carries one, and the subset of streams the driver uses: one stream
buffer stored (``stream 1 setup store 1 1``: ``set maxspeed``, ``set tanaccel``, ``line
abs``) and run in a live stream (``stream 1 setup live 1``, ``stream 1 call 1``). It
has no watchdog (see :mod:`mitsweep.rig.capture`).

A stream runs its lines from rest: the first ramps at ``tanaccel`` to its ``maxspeed``,
each following line runs at its own ``maxspeed`` (the change made at once at the
line's start: the simulator does not model the device's blending of speed changes at
``tanaccel``, which :mod:`mitsweep.rig.profile` bounds), and the last decelerates at
``tanaccel`` to rest on its target.

Speeds and accelerations are held as the protocol's data values (``maxspeed``,
``accel``) and converted with the driver's units (:data:`~mitsweep.rig.zaber.SPEED_UNIT`,
:data:`~mitsweep.rig.zaber.ACCEL_UNIT`); positions are microsteps.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from ..transport import ZaberChecksum
from ..zaber import ACCEL_UNIT, SPEED_UNIT
from .base import Fault, Model, Move, PathMove, command

__all__ = ["ZaberModel"]

_ZABER_CMD_RE = re.compile(r"^/(\d{1,2})(?: (\d))?(?: (\d{1,2}))? ?(.*)$")


class ZaberModel(Model):
    """One Zaber ASCII-protocol axis (device ``device``, axis 1).

    Parameters
    ----------
    faults : iterable of Fault
        Faults to inject, each used once (no ``brownout``: an Arduino fault).
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
    home_speed : int
        Homing speed, microsteps/s (homing accelerates at ten times that per second).
    """

    def __init__(self, faults: Iterable[Fault] = (), *, device: int = 1, device_id: int = 50081,
                 homed: bool = False, position: int = 0, max_position: int = 25 * 20997,
                 home_speed: int = 400_000) -> None:
        faults = list(faults)
        if any(f.kind == "brownout" for f in faults):
            # a fault that could never fire would let a test pass without testing it
            raise ValueError("fault 'brownout' is an Arduino fault; the Zaber model has none")
        super().__init__(faults)
        self.device, self.device_id = device, device_id
        self.homed = homed
        self._pos = position
        self.settings = {"maxspeed": 153_600, "accel": 205, "limit.min": 0,
                         "limit.max": max_position}
        self.flags: set[str] = set()
        self.home_speed = home_speed
        self.link_lost_at: float | None = None
        # streams: buffer number -> stored (command, value) list; the mode of stream 1
        self.buffers: dict[int, list[tuple[str, int]]] = {}
        self.stream_mode: tuple[str, int | None] = ("disabled", None)

    def position(self, now: float) -> int:
        """The axis's position at ``now``, microsteps.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
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

    # -- replies ------------------------------------------------------------------------
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
        if axis not in (0, 1):
            ok, data = False, "BADAXIS"
        else:
            handler, args = self.handler(words)
            ok, data = (False, "BADCOMMAND") if handler is None or args is None \
                else handler(args, now)
        return [self._reply(axis, mid, ok, data, now, has_checksum)]

    # -- commands: each returns (ok, data) ------------------------------------------------
    @command("get", nargs=1)
    def _get(self, args, now):
        key = args[0]
        if key == "deviceid":
            return True, str(self.device_id)
        if key == "pos":
            return True, str(self.position(now))
        if key in self.settings:
            return True, str(self.settings[key])
        return False, "BADCOMMAND"

    @command("set", nargs=2)
    def _set(self, args, now):
        key, text = args
        if key not in self.settings:
            return False, "BADCOMMAND"
        try:
            value = int(text)
        except ValueError:
            return False, "BADDATA"
        if key in ("maxspeed", "accel") and value < 1:
            return False, "BADDATA"
        self.settings[key] = value
        return True, "0"

    @command("home", nargs=0)
    def _home(self, args, now):
        if self.moving(now):
            self._pos = self.position(now)
        self.move = Move(self.position(now), 0, self.home_speed, 10 * self.home_speed, now)
        self.homed = True
        self.flags.discard("FS")
        return True, "0"

    @command("move", "abs", nargs=1)
    def _move_abs(self, args, now):
        try:
            target = int(args[0])
        except ValueError:
            return False, "BADDATA"
        if not self.settings["limit.min"] <= target <= self.settings["limit.max"]:
            return False, "BADDATA"
        if any(f.startswith("F") for f in self.flags):
            return False, "BADDATA"
        self.move = Move(self.position(now), target, self.settings["maxspeed"] / SPEED_UNIT,
                         self.settings["accel"] / ACCEL_UNIT, now)
        self.stopped = False
        self.arm_motion_faults(self.move)
        return True, "0"

    @command("stream", nargs=None)
    def _stream(self, args, now):
        """``stream buffer 1 erase`` and ``stream 1 ...``: setup store/live/disable, set maxspeed/tanaccel,
        line abs, call."""
        if args[:1] == ["buffer"] and len(args) == 3 and args[2] == "erase":
            # ``stream buffer <b> erase``: a device-scope command, no stream number
            try:
                self.buffers.pop(int(args[1]), None)
            except ValueError:
                return False, "BADDATA"
            return True, "0"
        try:
            words = [args[0], *args[1:]]
            if int(words[0]) != 1:
                return False, "BADDATA"
        except (ValueError, IndexError):
            return False, "BADCOMMAND"
        rest = words[1:]
        mode, buffer = self.stream_mode
        try:
            if rest[:2] == ["setup", "store"] and len(rest) == 4 and rest[3] == "1":
                self.stream_mode = ("store", int(rest[2]))
                self.buffers[int(rest[2])] = []
                return True, "0"
            if rest[:2] == ["setup", "live"] and rest[2:] == ["1"]:
                self.stream_mode = ("live", None)
                return True, "0"
            if rest == ["setup", "disable"]:
                self.stream_mode = ("disabled", None)
                return True, "0"
            if (rest[:1] == ["set"] and len(rest) == 3 and rest[1] in ("maxspeed", "tanaccel")
                    or rest[:2] == ["line", "abs"] and len(rest) == 3):
                key = rest[1] if rest[0] == "set" else "line"
                value = int(rest[2])
                if key != "line" and value < 1:
                    return False, "BADDATA"
                if key == "line" and not (self.settings["limit.min"] <= value
                                          <= self.settings["limit.max"]):
                    return False, "BADDATA"
                if mode != "store":
                    return False, "STATUSBUSY" if mode == "live" else "BADCOMMAND"
                self.buffers[buffer].append((key, value))
                return True, "0"
            if rest[:1] == ["call"] and len(rest) == 2:
                if mode != "live" or int(rest[1]) not in self.buffers:
                    return False, "BADDATA"
                return self._run_stream(self.buffers[int(rest[1])], now)
        except ValueError:
            return False, "BADDATA"
        return False, "BADCOMMAND"

    def _run_stream(self, stored, now):
        if self.moving(now) or any(f.startswith("F") for f in self.flags):
            return False, "BADDATA"
        speed, accel = self.settings["maxspeed"], self.settings["accel"]
        lines = []
        for key, value in stored:
            if key == "maxspeed":
                speed = value
            elif key == "tanaccel":
                accel = value
            else:
                lines.append((value, speed / SPEED_UNIT))
        if not lines:
            return False, "BADDATA"
        x0 = self.position(now)
        sign = 1.0 if lines[-1][0] >= x0 else -1.0
        a = accel / ACCEL_UNIT
        pieces, here = [], x0
        for i, (target, v) in enumerate(lines):
            length = sign * (target - here)
            if length < 0:
                return False, "BADDATA"          # a stream that turns back: not modelled
            cruise = length
            if i == 0:
                pieces.append((v / a, 0.0, a))
                cruise -= v * v / (2 * a)
            if i == len(lines) - 1:
                cruise -= v * v / (2 * a)
            if cruise < -1e-9:
                return False, "BADDATA"          # no room for the ramp at tanaccel
            pieces.append((max(cruise, 0.0) / v, v, 0.0))
            if i == len(lines) - 1:
                pieces.append((v / a, v, -a))
            here = target
        self.move = PathMove(x0, sign, now, pieces)
        self.stopped = False
        self.arm_motion_faults(self.move)
        return True, "0"

    @command("stop", nargs=0)
    def _stop(self, args, now):
        was_moving = self.moving(now)
        self._pos = self.position(now)
        self.move = None
        self.stopped = True
        self._fault_at = None
        if was_moving:
            self.flags.add("NI")
        return True, "0"

    @command("estop", nargs=0)
    def _estop(self, args, now):
        return self._stop(args, now)      # no brake modelled: the same stop

    @command("warnings", nargs=None)
    def _warnings(self, args, now):
        if args not in ([], ["clear"]):
            return False, "BADCOMMAND"
        flags = sorted(self.flags | (set() if self.homed else {"WR"}))
        data = f"{len(flags):02d}" + "".join(f" {f}" for f in flags)
        if args == ["clear"]:
            self.flags.clear()
        return True, data
