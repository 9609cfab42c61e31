"""``mitsweep capture``: run a focal-sweep capture on the rig over serial.

The sensor travel and exposure come from the setup's sweep range and velocity; the rig
section of the setup gives the stage limits, acceleration, settle distance and sensor
mapping. ``--dry-run`` prints the plan without opening a port.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import sys

from .common import UsageError, load_setup_arg, print_json

NAME = "capture"
HELP = ("drive the linear stage and the shutter over serial for one focal-sweep "
        "capture, and write its record")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("setup", help="setup TOML file (its [sweep] and [rig] sections)")
    p.add_argument("--port", metavar="PORT",
                   help="serial port of the Arduino sweep controller (e.g. /dev/ttyACM0)")
    p.add_argument("--stage", default="arduino", metavar="arduino|zaber:PORT",
                   help="what moves the stage: the Arduino on --port (default), or a Zaber "
                        "ASCII-protocol stage on PORT with the Arduino only firing the shutter")
    p.add_argument("--out", metavar="RECORD.json",
                   help="capture record (default: capture_<setup>_<UTC time>.json)")
    p.add_argument("--checksums", action="store_true",
                   help="checksum every line on the serial links")
    p.add_argument("--dry-run", action="store_true",
                   help="print the plan and exit; opens no port")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _parse_stage(text: str) -> str | None:
    if text == "arduino":
        return None
    kind, sep, port = text.partition(":")
    if kind != "zaber" or not sep or not port:
        raise UsageError(f"--stage: expected 'arduino' or 'zaber:PORT', got {text!r}")
    return port


def run(args) -> int:
    from ..rig import RigError, RigPorts, plan_capture, run_capture
    from ..rig.capture import status_of

    zaber_port = _parse_stage(args.stage)
    setup = load_setup_arg(args.setup)
    plan = plan_capture(setup, stage="zaber" if zaber_port else "arduino")
    if args.dry_run:
        if args.json:
            print_json({"setup": setup.name, "dry_run": True, "plan": plan.as_dict()})
        else:
            sys.stdout.write(plan.summary() + "\n")
        return 0
    if not args.port:
        raise UsageError("--port is required (the Arduino's serial port) unless --dry-run")
    out = args.out or (f"capture_{setup.name}_"
                       f"{_dt.datetime.now(_dt.timezone.utc):%Y%m%dT%H%M%SZ}.json")
    ports = RigPorts(arduino=args.port, zaber=zaber_port, checksums=args.checksums)
    try:
        record = run_capture(setup, ports, out=out, plan=plan)
    except RigError as exc:
        print(f"mitsweep: capture incomplete ({status_of(exc)}): {exc}; stage stopped, shutter "
              f"released; record: {out}", file=sys.stderr)
        return 1
    m = record.measurement()
    if args.json:
        print_json({"setup": setup.name, "record": str(out), "complete": record.complete,
                    **m["exposure"]})
    else:
        e = m["exposure"]
        sys.stdout.write("\n".join([
            f"record             {out} (complete)",
            f"exposure           {e['measured_exposure_s']:.6f} s measured, "
            f"{e['planned_exposure_s']:.6f} s planned",
            f"sensor distance    {e['open_sensor_distance_mm']:.4f} -> "
            f"{e['close_sensor_distance_mm']:.4f} mm",
        ]) + "\n")
    return 0

