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
``slow_reply`` (Arduino: a command acts at once but its reply comes ``delay_s`` late),
``brownout`` (Arduino: the board restarts part-way through the next move, shutter released,
position lost, and prints ``READY`` again).

The Arduino model has the firmware's watchdog (``WATCHDOG <ms>``): while it moves or an
exposure is pending or open, a host silent for that long gets ``EV FAULT ... WATCHDOG``
after the shutter was released and the motor stopped. The Zaber model has none (see
:mod:`mitsweep.rig.capture`).

Modules: :mod:`.base` (faults, motion, the command table), :mod:`.arduino`,
:mod:`.zaber` (the two models), :mod:`.pty` (the server). Run ``python -m
mitsweep.rig.simulator arduino|zaber`` to serve one by hand.
"""

from .arduino import FIRMWARE_VERSION, ArduinoModel
from .base import FAULT_KINDS, Fault, Model, Move, command
from .pty import PtyDevice
from .zaber import ZaberModel

__all__ = ["Fault", "FAULT_KINDS", "Move", "Model", "command", "ArduinoModel", "ZaberModel",
           "PtyDevice", "FIRMWARE_VERSION"]
