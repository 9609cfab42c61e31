"""The two small interfaces the capture relies on: a :class:`Stage` and a :class:`Shutter`.

A driver takes a :class:`~mitsweep.rig.transport.LineTransport` and does not care what
is behind it (a real port, a pty simulator, a scripted byte stream). Positions are stage
millimetres (the stage's own coordinates, 0 at home); velocities mm/s, accelerations
mm/s², times seconds.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_fields

__all__ = ["StageState", "Stage", "Shutter"]


@renamed_fields(position_mm="position")
@dataclass(frozen=True)
class StageState:
    """What a stage reports about itself.

    Attributes
    ----------
    position : float or None
        Position in stage coordinates, mm; None when the stage does not know where it is
        (not homed).
    homed : bool
        Whether the stage has a reference position.
    moving : bool
        Whether a motion is under way.
    fault : str or None
        A short device code (e.g. ``"FS"`` stall), or None.
    """

    position: float | None
    homed: bool
    moving: bool
    fault: str | None = None


class Stage(abc.ABC):
    """A linear stage that moves, reports its state and stops."""

    name: str = "stage"

    @abc.abstractmethod
    def identify(self) -> str:
        """A one-line identity of the device (checked before any motion)."""

    @abc.abstractmethod
    def state(self) -> StageState:
        """Current position, homed, moving, fault."""

    @abc.abstractmethod
    def set_soft_limits(self, lo: float, hi: float) -> None:
        """Make the device itself refuse positions outside ``[lo, hi]``.

        Parameters
        ----------
        lo, hi : float
            The lowest and highest position allowed, mm (stage coordinates).
        """

    @abc.abstractmethod
    def home(self, *, velocity_mm_s: float, timeout_s: float) -> None:
        """Find the reference position; blocks until done.

        Parameters
        ----------
        velocity_mm_s : float
            Homing velocity, mm/s (a stage that homes at its own speed ignores it).
        timeout_s : float
            How long homing may take before :class:`~mitsweep.rig.errors.ReplyTimeout`, s.
        """

    @abc.abstractmethod
    def move_to(self, position: float, *, velocity_mm_s: float, acceleration_mm_s2: float,
                timeout_s: float) -> float:
        """Move (shutter closed) and wait until idle; returns the final position, mm.

        Parameters
        ----------
        position : float
            Target position, mm (stage coordinates).
        velocity_mm_s : float
            Cruise velocity, mm/s.
        acceleration_mm_s2 : float
            Acceleration and deceleration, mm/s².
        timeout_s : float
            How long the move may take before :class:`~mitsweep.rig.errors.ReplyTimeout`, s.

        Returns
        -------
        float
            The position the stage reports at the end, mm (the target, to a step).
        """

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop now (safety path: must not raise because of the stage's state)."""


class Shutter(abc.ABC):
    """A camera shutter fired through the remote-release lines (bulb mode)."""

    name: str = "shutter"

    @abc.abstractmethod
    def close_shutter(self) -> None:
        """Release the shutter now (safety path)."""
