"""Errors of the rig package.

Two families, because the command line treats them differently:

- :class:`PlanError` (a ``ValueError``): bad input found *before any motion* — a sweep
  longer than the travel, a velocity the stage cannot hold, an exposure outside the
  camera's range, a port that does not exist. The CLI prints one line, exit status 2.
- :class:`RigError` (a ``RuntimeError``): something went wrong while talking to the
  devices or during motion. The capture stops the stage, closes the shutter and writes
  its record marked incomplete before the error propagates.
"""

from __future__ import annotations

__all__ = ["PlanError", "PortUnavailable", "RigError", "ProtocolError", "ReplyTimeout",
           "PortLost", "DeviceError", "DeviceFault"]


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
