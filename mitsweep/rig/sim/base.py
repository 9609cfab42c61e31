"""What both simulated devices share: injected faults, the motion under way, the
scheduled output queue and the command table.

A model's commands are declared with :func:`command` (the command word and how many
arguments it takes); :class:`Model` collects them into the class's ``commands`` table,
which :meth:`Model.handler` looks up by name, so a subclass may override one command's
method (tests do, to act in the middle of a sweep).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any, TypeVar
from collections.abc import Callable, Iterable

from ...optics.kinematics import Trapezoid

__all__ = ["Fault", "FAULT_KINDS", "Move", "PathMove", "table_pieces", "Model", "command"]

#: A model's command method (its replies' form is the model's own).
Handler = TypeVar("Handler", bound=Callable[..., Any])

FAULT_KINDS = ("no_reply", "garbage", "fault_flag", "unplug", "late_event", "slow_reply",
               "brownout")


@dataclass(frozen=True)
class Fault:
    """One injected fault.

    Attributes
    ----------
    kind : str
        One of :data:`FAULT_KINDS`.
    command : str, optional
        For ``no_reply`` / ``garbage`` / ``slow_reply``: the command word it hits
        (``"SWEEP"``, ``"STATE"``, ``"move"``, ...); the first such command only.
    at_fraction : float
        For ``fault_flag`` / ``unplug`` / ``brownout``: fraction of the next long move
        (SWEEP, or a Zaber ``move``) at which it happens. ``brownout`` (Arduino only):
        the board restarts, as when the motor's current sags its supply.
    delay_s : float
        For ``late_event``: how late the end-of-exposure events are; for
        ``slow_reply``: how late the reply is, s.
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
    :class:`~mitsweep.optics.kinematics.Trapezoid` placed in position and time.

    Parameters
    ----------
    x0, x1 : float
        Start and end positions.
    v : float
        Cruise velocity (reached unless the move is too short: then triangular).
    a : float
        Acceleration and deceleration.
    t0 : float
        Start time, s.
    """

    def __init__(self, x0: float, x1: float, v: float, a: float, t0: float) -> None:
        self.x0, self.x1, self.t0 = float(x0), float(x1), float(t0)
        self.sign = 1.0 if x1 >= x0 else -1.0
        self.profile = Trapezoid(abs(self.x1 - self.x0), v, a)
        self.length = self.profile.distance
        self.duration = self.profile.duration

    def distance(self, t: float) -> float:
        """Distance covered from ``x0`` at time ``t`` (0 before the start, the whole
        length after the end).

        Parameters
        ----------
        t : float
            Time, s (the clock of ``t0``).
        """
        return float(self.profile.position_at(t - self.t0))

    def position(self, t: float) -> float:
        """Position at time ``t``.

        Parameters
        ----------
        t : float
            Time, s (the clock of ``t0``).
        """
        return self.x0 + self.sign * self.distance(t)

    def time_at(self, d: float) -> float:
        """When the move has covered distance ``d`` from ``x0``.

        Parameters
        ----------
        d : float
            Distance from the start, 0 .. the move's length.
        """
        return self.t0 + float(self.profile.time_at(d))

    @property
    def end_time(self) -> float:
        return self.t0 + self.duration


class PathMove:
    """Motion from rest at ``x0`` along ``sign`` through pieces of constant acceleration
    ``(duration, start velocity, acceleration)`` starting at ``t0``: a table sweep (ramp,
    cruise, constant-rate segments, cruise, ramp), with the interface of :class:`Move`.

    Velocity changes between pieces are as given: a constant-rate segment follows the
    last at its own rate at once (a stepper's rate jump; the plan bounds them).

    Parameters
    ----------
    x0 : float
        Start position.
    sign : float
        Direction of motion, +1 or -1.
    t0 : float
        Start time, s.
    pieces : iterable of (float, float, float)
        ``(duration s, start velocity, acceleration)`` of each piece, in order
        (:func:`table_pieces`).
    """

    def __init__(self, x0: float, sign: float, t0: float,
                 pieces: Iterable[tuple[float, float, float]]) -> None:
        self.x0, self.sign, self.t0 = float(x0), float(sign), float(t0)
        self.pieces = [(float(d), float(v), float(a)) for d, v, a in pieces]
        self.starts_t = [0.0]
        self.starts_d = [0.0]
        for d, v, a in self.pieces:
            self.starts_t.append(self.starts_t[-1] + d)
            self.starts_d.append(self.starts_d[-1] + v * d + 0.5 * a * d * d)
        self.length = self.starts_d[-1]
        self.duration = self.starts_t[-1]
        self.x1 = self.x0 + self.sign * round(self.length)

    def _piece(self, i: int, tau: float) -> float:
        d, v, a = self.pieces[i]
        return self.starts_d[i] + v * tau + 0.5 * a * tau * tau

    def distance(self, t: float) -> float:
        """Distance covered from ``x0`` at time ``t`` (clamped to the path's span).

        Parameters
        ----------
        t : float
            Time, s (the clock of ``t0``).
        """
        tau = min(max(t - self.t0, 0.0), self.duration)
        i = min(max(bisect.bisect_right(self.starts_t, tau) - 1, 0), len(self.pieces) - 1)
        return self._piece(i, tau - self.starts_t[i])

    def position(self, t: float) -> float:
        """Position at time ``t``.

        Parameters
        ----------
        t : float
            Time, s (the clock of ``t0``).
        """
        return self.x0 + self.sign * self.distance(t)

    def time_at(self, dist: float) -> float:
        """When the path has covered distance ``dist`` from ``x0`` (clamped to its length).

        Parameters
        ----------
        dist : float
            Distance from the start.
        """
        dist = min(max(dist, 0.0), self.length)
        i = min(max(bisect.bisect_right(self.starts_d, dist) - 1, 0), len(self.pieces) - 1)
        d, v, a = self.pieces[i]
        rest = dist - self.starts_d[i]
        if a == 0.0:
            tau = rest / v if v > 0 else 0.0
        else:   # v tau + a tau²/2 = rest, the root within the piece
            tau = (-v + math.sqrt(max(v * v + 2.0 * a * rest, 0.0))) / a
        return self.t0 + self.starts_t[i] + min(max(tau, 0.0), d)

    @property
    def end_time(self) -> float:
        return self.t0 + self.duration


def table_pieces(rate_in: float, rate_out: float, accel: float, d_open: float,
                 d_after: float,
                 segments: Iterable[tuple[float, float]]) -> list[tuple[float, float, float]]:
    """Pieces of a table sweep: ramp from rest to ``rate_in`` at ``accel``, cruise to
    ``d_open``, the ``(steps, seconds)`` segments, cruise at ``rate_out`` and ramp down
    to rest ``d_after`` past the table's end.

    Parameters
    ----------
    rate_in, rate_out : float
        The table's entry and exit rates, steps/s.
    accel : float
        The ramps' acceleration, steps/s².
    d_open : float
        Steps from rest to the table's first step (ramp and cruise).
    d_after : float
        Steps from the table's last step to rest (cruise and ramp).
    segments : iterable of (float, float)
        ``(steps, seconds)`` of each table segment.

    Returns
    -------
    list of (float, float, float)
        ``(duration s, start velocity, acceleration)`` pieces for :class:`PathMove`.
    """
    ramp_in, ramp_out = rate_in ** 2 / (2 * accel), rate_out ** 2 / (2 * accel)
    pieces = [(rate_in / accel, 0.0, accel), ((d_open - ramp_in) / rate_in, rate_in, 0.0)]
    pieces += [(dur, steps / dur, 0.0) for steps, dur in segments]
    pieces += [((d_after - ramp_out) / rate_out, rate_out, 0.0),
               (rate_out / accel, rate_out, -accel)]
    return pieces


def command(*words: str, nargs: int | None = None) -> Callable[[Handler], Handler]:
    """Declare a model method as the handler of the command ``words`` (the leading
    words that name it) taking ``nargs`` further arguments (None: any number).

    Parameters
    ----------
    *words : str
        The command's leading words, e.g. ``"SWEEP"`` or ``"stream", "setup"``.
    nargs : int, optional
        How many arguments follow them (None: any number).
    """
    def declare(method):
        method.sim_command = (tuple(words), nargs)
        return method
    return declare


class Model:
    """Base of the device models: faults, the scheduled-output queue, the motion under
    way (``move``; ``_pos``, the position at rest, in device units) and the command
    table.

    Parameters
    ----------
    faults : iterable of Fault
        Faults to inject, each used once.
    """

    #: ``words -> (method name, nargs)``, collected from the :func:`command` methods.
    commands: dict[tuple[str, ...], tuple[str, int | None]] = {}
    #: Whether opening the port resets the device (an Uno's auto-reset on DTR).
    reset_on_open = False

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        table = dict(cls.commands)
        for name, member in vars(cls).items():
            declared = getattr(member, "sim_command", None)
            if declared is not None:
                words, nargs = declared
                table[words] = (name, nargs)
        cls.commands = table

    def __init__(self, faults: Iterable[Fault] = ()) -> None:
        self.faults = list(faults)
        self._scheduled: list[tuple[float, bytes, str]] = []
        self.unplug_at: float | None = None
        self.log: list[tuple[float, str, str]] = []   # (t, "rx"/"tx", text) seen by the device
        self.move: Move | None = None
        self._pos = 0
        self.stopped = False
        self._fault_at: float | None = None     # when an armed fault_flag fault strikes

    # -- commands -----------------------------------------------------------------------
    def handler(self, words: list[str]) -> tuple[Callable[..., Any] | None, list[str] | None]:
        """``(bound method, arguments)`` of the command that ``words`` start with (the
        longest declared match), or ``(None, None)``; arguments is None when their
        number is not the declared one.

        Parameters
        ----------
        words : list of str
            A received line, split into words.
        """
        for n in range(len(words), 0, -1):
            entry = self.commands.get(tuple(words[:n]))
            if entry is not None:
                name, nargs = entry
                args = words[n:]
                return getattr(self, name), (args if nargs is None or len(args) == nargs
                                             else None)
        return None, None

    # -- scheduled output ---------------------------------------------------------------
    def schedule(self, t: float, data: bytes, tag: str = "") -> None:
        """Queue output to be sent at time ``t``.

        Parameters
        ----------
        t : float
            When to send it, s (the server's clock).
        data : bytes
            The bytes, line ending included.
        tag : str
            A name to cancel it by (:meth:`cancel_scheduled`).
        """
        self._scheduled.append((t, data, tag))
        self._scheduled.sort(key=lambda x: x[0])

    def due(self, now: float) -> list[bytes]:
        """Take the queued output due by ``now``, in time order.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
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
        """Drop queued output.

        Parameters
        ----------
        tag : str, optional
            Drop only the output of this tag (None: all of it).
        """
        self._scheduled = [s for s in self._scheduled if tag is not None and s[2] != tag]

    # -- faults -------------------------------------------------------------------------
    def take_fault(self, kind: str, command: str | None = None) -> Fault | None:
        """Remove and return the first pending fault of ``kind`` (None: none).

        Parameters
        ----------
        kind : str
            One of :data:`FAULT_KINDS`.
        command : str, optional
            Only a fault that hits this command word.
        """
        for f in self.faults:
            if f.kind == kind and (command is None or f.command == command):
                self.faults.remove(f)
                return f
        return None

    def arm_motion_faults(self, mv: Move) -> None:
        """A pending ``fault_flag`` or ``unplug`` fault strikes part-way through ``mv``.

        Parameters
        ----------
        mv : Move
            The long move just started.
        """
        f = self.take_fault("fault_flag")
        if f:
            self._fault_at = mv.t0 + f.at_fraction * mv.duration
        f = self.take_fault("unplug")
        if f:
            self.unplug_at = mv.t0 + f.at_fraction * mv.duration

    # -- the device's life --------------------------------------------------------------
    def boot(self, now: float) -> list[bytes]:  # pragma: no cover - overridden
        """The device powers up: what it sends at once (later lines it schedules).

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        return []

    def reset(self, now: float) -> None:
        """The host opened (and flushed) the port.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """

    def handle(self, line: bytes, now: float) -> list[bytes]:  # pragma: no cover
        """Answer one line from the host: the replies to send at once.

        Parameters
        ----------
        line : bytes
            The line received, without its terminator.
        now : float
            The server's present time, s.
        """
        raise NotImplementedError

    def tick(self, now: float) -> list[bytes]:  # pragma: no cover - overridden
        """Advance the device to ``now``: what it sends because time passed.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        return []

    def on_unplug(self, now: float) -> None:
        """The link was cut (an injected ``unplug``): what the device does then.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """

    # -- motion -------------------------------------------------------------------------
    def moving(self, now: float) -> bool:
        """Whether a move is under way at ``now``.

        Parameters
        ----------
        now : float
            The server's present time, s.
        """
        return self.move is not None and now < self.move.end_time

    def _settle(self, now: float) -> None:
        if self.move is not None and now >= self.move.end_time:
            self._pos = int(round(self.move.x1))
            self.move = None
