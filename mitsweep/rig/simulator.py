"""Device simulators for the rig on a pseudo-terminal: the names of
:mod:`mitsweep.rig.sim`, and ``python -m mitsweep.rig.simulator arduino|zaber`` to serve
one by hand (it prints the port to open)."""

from __future__ import annotations

import signal
import threading

from .sim import (FAULT_KINDS, FIRMWARE_VERSION, ArduinoModel, Fault, Model, Move, PtyDevice,
                  ZaberModel)

__all__ = ["Fault", "FAULT_KINDS", "Move", "Model", "ArduinoModel", "ZaberModel", "PtyDevice",
           "FIRMWARE_VERSION"]


def _main(argv=None) -> int:  # pragma: no cover - manual use
    import argparse

    p = argparse.ArgumentParser(description="serve a simulated rig device on a pty")
    p.add_argument("device", choices=["arduino", "zaber"])
    p.add_argument("--homed", action="store_true")
    args = p.parse_args(argv)
    model = ArduinoModel(homed=args.homed) if args.device == "arduino" \
        else ZaberModel(homed=args.homed)
    # Ctrl-C, SIGTERM and SIGHUP end the server cleanly. A handler that only sets an
    # event (rather than raising KeyboardInterrupt wherever the main thread happens to
    # be) cannot cut the start-up or the shutdown short on a busy machine.
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, lambda *_: stop.set())
    with PtyDevice(model) as dev:
        print(dev.port, flush=True)
        while not stop.wait(1.0):
            pass
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(_main())
