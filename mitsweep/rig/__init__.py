"""Rig control: drive the linear stage and the shutter of a focal-sweep camera over serial.

- :mod:`~mitsweep.rig.transport`: line-based serial transport (deadlines, strict parsing,
  checksums, timestamped log);
- :mod:`~mitsweep.rig.arduino`: the project's Arduino sweep controller (stepper + shutter,
  firmware in ``scripts/firmware/``);
- :mod:`~mitsweep.rig.zaber`: a Zaber ASCII-protocol stage;
- :mod:`~mitsweep.rig.simulator`: both devices on a pty, with fault injection;
- :mod:`~mitsweep.rig.plan`: sweep range → stage move (pure, checked before any motion);
- :mod:`~mitsweep.rig.capture`: the capture and its safety path;
- :mod:`~mitsweep.rig.record`: the capture record and its measured motion profile.

Depends only on :mod:`mitsweep.optics` and :mod:`mitsweep.config` (and pyserial).
"""

from .capture import RigPorts, capture, run_capture, safety_summary
from .errors import (CaptureInterrupted, DeviceError, DeviceFault, HostTooSlow, PlanError,
                     PortLost, PortUnavailable, ProtocolError, ReplyTimeout, RigError)
from .plan import CapturePlan, plan_capture
from .record import CaptureRecord, load_capture_record, measured_motion

__all__ = ["RigPorts", "capture", "run_capture", "safety_summary", "CaptureInterrupted", "CapturePlan",
           "plan_capture",
           "CaptureRecord", "load_capture_record", "measured_motion", "PlanError",
           "PortUnavailable", "RigError", "ProtocolError", "ReplyTimeout", "PortLost",
           "DeviceError", "DeviceFault", "HostTooSlow"]
