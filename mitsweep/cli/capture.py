"""``mitsweep capture``: run a focal-sweep capture on the rig over serial.

The sensor travel and exposure come from the setup's sweep range and velocity; the rig
section of the setup gives the stage limits, acceleration, settle distance, sensor
mapping and the board's watchdog. ``--dry-run`` prints the plan without opening a port.

``--motion PROFILE.json`` runs a motion-profile file (e.g. from ``mitsweep design-sweep``)
instead of the linear sweep, for the file's ``exposure_s`` (or, when it has none, the
linear sweep's exposure over the same span): the plan turns it into a step-rate table
(Arduino: ``TABLE``/``SEG``/``TSWEEP``; Zaber: a stored stream of ``line abs`` moves)
and refuses, before any port is opened, a profile the stage cannot follow, a span that
reaches the focal length, or a table that is empty or not monotonic. The record then
holds the planned and the measured motion (``measured.profile``).

``--out`` (default ``capture_<setup>_<UTC time>.json``) is never the setup file, and an
existing file is replaced only with ``--force``.

Stopping a capture: Ctrl-C (SIGINT), ``kill`` (SIGTERM) and a closed terminal (SIGHUP)
release the shutter and stop the stage, then write the record marked incomplete
(``status: "interrupted"``, ``signal``); a second signal does not cut that short. What
cannot be caught (SIGKILL, a crash) is left to the board's watchdog (``rig.watchdog_s``).

With a Zaber stage the host times the shutter; when it answers too late to do so within
the settle distance it abandons the attempt (shutter released) and tries again, and after
three it stops with status ``"host too slow"`` (exit 1): close other programs, or raise
``rig.settle_distance``.

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
import datetime as _dt
import os
import sys

from .common import UsageError, check_outputs, load_setup_arg, print_json

NAME = "capture"
HELP = ("drive the linear stage and the shutter over serial for one focal-sweep "
        "capture, and write its record")

#: Exit statuses (see the module docstring).
EXIT_COMPLETE = 0
EXIT_INCOMPLETE_SAFE = 1
EXIT_MAYBE_UNSAFE = 3


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


def _parse_stage(text: str) -> str | None:
    if text == "arduino":
        return None
    kind, sep, port = text.partition(":")
    if kind != "zaber" or not sep or not port:
        raise UsageError(f"--stage: expected 'arduino' or 'zaber:PORT', got {text!r}")
    return port


def _check_out(out: str, setup_path: str, force: bool) -> None:
    check_outputs([setup_path], {"--out": out})          # never the setup, even with --force
    if os.path.lexists(out) and not force:
        raise UsageError(f"--out {out} exists: pass --force to replace it, or choose "
                         f"another path")


def exit_status(exc: BaseException, safe: bool) -> int:
    """The exit status of an incomplete capture (table in the module docstring)."""
    if not safe:
        return EXIT_MAYBE_UNSAFE
    if isinstance(exc, KeyboardInterrupt):
        return 128 + getattr(exc, "signum", 2)   # SIGINT is 2
    return EXIT_INCOMPLETE_SAFE


def _report_incomplete(exc: BaseException, record, out: str) -> int:
    from ..rig import safety_summary
    from ..rig.capture import status_of

    safe, steps = safety_summary(record)
    if isinstance(exc, KeyboardInterrupt):
        head = f"capture incomplete (interrupted by {record.signal})"
    else:
        head = f"capture incomplete ({status_of(exc)}): {exc or type(exc).__name__}"
    tail = "" if safe else "; the rig may be unsafe: check the stage and the shutter"
    try:
        print(f"mitsweep: {head}; {steps}{tail}; record: {out}", file=sys.stderr)
    except OSError:   # SIGHUP: the terminal may be gone; the record and status remain
        pass
    return exit_status(exc, safe)


def run(args) -> int:
    from ..rig import RigError, RigPorts, plan_capture, run_capture

    from .motion import motion_file_from_args

    zaber_port = _parse_stage(args.stage)
    setup = load_setup_arg(args.setup)
    motion_file = motion_file_from_args(args, setup)
    stage = "zaber" if zaber_port else "arduino"
    if motion_file is None:
        plan = plan_capture(setup, stage=stage)
    else:
        plan = plan_capture(setup, stage=stage, motion=motion_file.profile,
                            exposure_s=motion_file.exposure_s)
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
    _check_out(out, args.setup, args.force)
    ports = RigPorts(arduino=args.port, zaber=zaber_port, checksums=args.checksums)
    try:
        record = run_capture(setup, ports, out=out, plan=plan, motion_file=motion_file)
    except (RigError, KeyboardInterrupt) as exc:
        record = getattr(exc, "capture_record", None)
        if record is None:      # not from the device phase: nothing was moved
            raise
        return _report_incomplete(exc, record, out)
    m = record.measurement()
    cmp = m.get("profile")
    if args.json:
        extra = {} if cmp is None else {
            "profile_max_deviation_steps": cmp["max_deviation_steps"],
            "profile_tolerance_steps": cmp["tolerance_steps"]}
        print_json({"setup": setup.name, "record": str(out), "complete": record.complete,
                    **m["exposure"], **extra})
    else:
        e = m["exposure"]
        sys.stdout.write("\n".join([
            f"record             {out} (complete)",
            f"exposure           {e['measured_exposure_s']:.6f} s measured, "
            f"{e['planned_exposure_s']:.6f} s planned",
            f"sensor distance    {e['open_sensor_distance_mm']:.4f} -> "
            f"{e['close_sensor_distance_mm']:.4f} mm",
        ] + ([] if cmp is None else [
            f"motion profile     measured within {cmp['max_deviation_steps']:.2f} steps of "
            f"the plan at {len(cmp['time_s'])} samples (allowed "
            f"{cmp['tolerance_steps']:.2f})"])) + "\n")
    return EXIT_COMPLETE
