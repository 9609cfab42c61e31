"""The two small interfaces the capture relies on: a :class:`Stage` and a :class:`Shutter`.

A driver takes a :class:`~mitsweep.rig.transport.LineTransport` and does not care what
is behind it (a real port, a pty simulator, a scripted byte stream). Positions are stage
millimetres (the stage's own coordinates, 0 at home); velocities mm/s, accelerations
mm/s², times seconds.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

__all__ = ["StageState", "Stage", "Shutter"]


@dataclass(frozen=True)
class StageState:
    """What a stage reports about itself.

    ``position_mm`` is None when the stage does not know where it is (not homed).
    ``fault`` is a short device code (e.g. ``"FS"`` stall) or None.
    """

    position_mm: float | None
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
    def set_soft_limits(self, lo_mm: float, hi_mm: float) -> None:
        """Make the device itself refuse positions outside ``[lo_mm, hi_mm]``."""

    @abc.abstractmethod
    def home(self, *, velocity_mm_s: float, timeout_s: float) -> None:
        """Find the reference position; blocks until done."""

    @abc.abstractmethod
    def move_to(self, position_mm: float, *, velocity_mm_s: float, acceleration_mm_s2: float,
                timeout_s: float) -> float:
        """Move (shutter closed) and wait until idle; returns the final position, mm."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop now (safety path: must not raise because of the stage's state)."""


class Shutter(abc.ABC):
    """A camera shutter fired through the remote-release lines (bulb mode)."""

    name: str = "shutter"

    @abc.abstractmethod
    def close_shutter(self) -> None:
        """Release the shutter now (safety path)."""
