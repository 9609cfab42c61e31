"""Errors of the rig package.

Two families, because the command line treats them differently:

- :class:`PlanError` (a ``ValueError``): bad input found *before any motion* — a sweep
  longer than the travel, a velocity the stage cannot hold, an exposure outside the
  camera's range, a port that does not exist. The CLI prints one line, exit status 2.
- :class:`RigError` (a ``RuntimeError``): something went wrong while talking to the
  devices or during motion. The capture stops the stage, closes the shutter and writes
  its record marked incomplete before the error propagates.

A third, :class:`CaptureInterrupted` (a ``KeyboardInterrupt``), is a signal (SIGINT,
SIGTERM, SIGHUP) that stopped a capture: it runs the same safety path.
"""

from __future__ import annotations

__all__ = ["PlanError", "PortUnavailable", "RigError", "ProtocolError", "ReplyTimeout",
           "PortLost", "DeviceError", "DeviceFault", "HostTooSlow", "CaptureInterrupted"]


class PlanError(ValueError):
    """The requested capture cannot be run on this rig (raised before any motion)."""


class PortUnavailable(PlanError):
    """A serial port does not exist or cannot be opened."""


class RigError(RuntimeError):
    """A failure while talking to the rig's devices."""


class ProtocolError(RigError):
    """A reply that is not a whole, well-formed, expected line (garbage, partial line,
    bad checksum, unknown reply)."""


class ReplyTimeout(RigError):
    """No reply (or no expected event) before the deadline."""


class PortLost(RigError):
    """The serial port went away (unplugged, closed)."""


class DeviceError(RigError):
    """The device refused a command (Arduino ``ERR``, Zaber ``RJ``)."""


class DeviceFault(RigError):
    """The device reported a fault (Arduino ``EV FAULT``, Zaber ``F*`` warning flag)."""


class HostTooSlow(RigError):
    """The host answered too late to time something the plan needs it to time (in
    ``zaber`` mode: the shutter, opened by the host relative to the stage's move), on
    every attempt. Nothing is wrong with the devices; a less loaded host, or a longer
    ``rig.settle_distance`` (more time for the host's lateness), lets the capture run."""


class CaptureInterrupted(KeyboardInterrupt):
    """A signal stopped the capture: ``signal_name`` (``"SIGINT"``, ``"SIGTERM"``,
    ``"SIGHUP"``) and ``signum``. A ``KeyboardInterrupt``, so that code which handles
    Ctrl-C handles the other two alike.

    Parameters
    ----------
    signum : int
        The signal's number.
    signal_name : str
        Its name, e.g. ``"SIGTERM"``.
    """

    def __init__(self, signum: int, signal_name: str) -> None:
        super().__init__(f"interrupted by {signal_name}")
        self.signum = signum
        self.signal_name = signal_name
