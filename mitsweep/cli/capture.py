"""``mitsweep capture``: run a focal-sweep capture on the rig over serial.

A thin wrapper over :func:`mitsweep.workflows.capture` (``--dry-run``:
:func:`mitsweep.workflows.plan_rig_capture`), whose module documents the plan, the motion
profiles, the record and how a capture stops (Ctrl-C, SIGTERM and SIGHUP release the
shutter and stop the stage, then write the record marked incomplete; what cannot be
caught is left to the board's watchdog, ``rig.watchdog_s``).

Exit status
-----------
===  =========================================================================
0    capture complete
1    incomplete (fault, timeout, lost link, host too slow, ...); every safety
     step confirmed
2    bad input, refused before any motion
3    incomplete and some safety step NOT confirmed: the rig may be unsafe
130  interrupted by SIGINT, every safety step confirmed (143: SIGTERM,
     129: SIGHUP; 128 + the signal's number, as a shell reports it)
===  =========================================================================

Status 3 takes precedence over the signal's status. stderr says which safety steps the
devices confirmed, e.g. ``shutter released: confirmed; stage stopped: NOT confirmed
(port lost)``.
"""

from __future__ import annotations

import argparse
import sys

from ..workflows.capture import (  # noqa: F401  (names the tests import from the command)
    EXIT_COMPLETE,
    EXIT_INCOMPLETE_SAFE,
    EXIT_MAYBE_UNSAFE,
    capture,
    capture_failure,
    exit_status,
    plan_rig_capture,
)
from .common import print_json

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
                   help="capture record (default: capture_<setup>_<UTC time>.json); an "
                        "existing file only with --force, never the setup file")
    p.add_argument("--force", action="store_true",
                   help="replace an existing --out file")
    p.add_argument("--checksums", action="store_true",
                   help="checksum every line on the serial links")
    p.add_argument("--dry-run", action="store_true",
                   help="print the plan and exit; opens no port")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    from .motion import add_motion_argument

    add_motion_argument(p)


def run(args) -> int:
    from ..rig import RigError

    if args.dry_run:
        plan = plan_rig_capture(args.setup, stage=args.stage, motion=args.motion)
        if args.json:
            print_json(plan.summary)
        else:
            sys.stdout.write(plan.value.summary() + "\n")
        return 0
    try:
        result = capture(args.setup, port=args.port, stage=args.stage, out=args.out,
                         force=args.force, checksums=args.checksums, motion=args.motion)
    except (RigError, KeyboardInterrupt) as exc:
        if getattr(exc, "capture_record", None) is None:  # nothing was moved
            raise
        line, status = capture_failure(exc)
        try:
            print(line, file=sys.stderr)
        except OSError:   # SIGHUP: the terminal may be gone; the record and status remain
            pass
        return status
    s = result.summary
    if args.json:
        print_json(s)
        return EXIT_COMPLETE
    cmp = result.provenance["measurement"].get("profile")
    sys.stdout.write("\n".join([
        f"record             {s['record']} (complete)",
        f"exposure           {s['measured_exposure_s']:.6f} s measured, "
        f"{s['planned_exposure_s']:.6f} s planned",
        f"sensor distance    {s['open_sensor_distance_mm']:.4f} -> "
        f"{s['close_sensor_distance_mm']:.4f} mm",
    ] + ([] if cmp is None else [
        f"motion profile     measured within {cmp['max_deviation_steps']:.2f} steps of "
        f"the plan at {len(cmp['time_s'])} samples (allowed "
        f"{cmp['tolerance_steps']:.2f})"])) + "\n")
    return EXIT_COMPLETE
