"""Run a focal-sweep capture on the rig over serial (``mitsweep capture``).

The sensor travel and exposure come from the setup's sweep range and velocity; the rig
section of the setup gives the stage limits, acceleration, settle distance, sensor
mapping and the board's watchdog. :func:`plan_rig_capture` makes the plan without opening
a port.

A motion-profile file (e.g. from ``mitsweep design-sweep``) runs instead of the linear
sweep, for the file's ``exposure_s`` (or, when it has none, the linear sweep's exposure
over the same span): the plan turns it into a step-rate table (Arduino:
``TABLE``/``SEG``/``TSWEEP``; Zaber: a stored stream of ``line abs`` moves) and refuses,
before any port is opened, a profile the stage cannot follow, a span that reaches the
focal length, or a table that is empty or not monotonic. The record then holds the
planned and the measured motion (``measured.profile``).

The record (default ``capture_<setup>_<UTC time>.json``) is never the setup file, and an
existing file is replaced only with ``force``.

Stopping a capture: Ctrl-C (SIGINT), ``kill`` (SIGTERM) and a closed terminal (SIGHUP)
release the shutter and stop the stage, then write the record marked incomplete
(``status: "interrupted"``, ``signal``); a second signal does not cut that short. What
cannot be caught (SIGKILL, a crash) is left to the board's watchdog (``rig.watchdog_s``).

With a Zaber stage the host times the shutter; when it answers too late to do so within
the settle distance it abandons the attempt (shutter released) and tries again, and after
three it stops with status ``"host too slow"``: close other programs, or raise
``rig.settle_distance``.
"""

from __future__ import annotations

import datetime as _dt
import os
from typing import TYPE_CHECKING

from .. import __version__
from ..config import Setup
from ..optics.motion_file import MotionFile
from ._base import InputError, WorkflowResult, read_motion_file, resolve_setup
from ._paths import check_outputs

if TYPE_CHECKING:
    from ..rig import CapturePlan

__all__ = ["plan_rig_capture", "capture", "capture_failure", "exit_status",
           "EXIT_COMPLETE", "EXIT_INCOMPLETE_SAFE", "EXIT_MAYBE_UNSAFE"]

#: Exit statuses of ``mitsweep capture`` (its module docstring has the table).
EXIT_COMPLETE = 0
EXIT_INCOMPLETE_SAFE = 1
EXIT_MAYBE_UNSAFE = 3


def _parse_stage(text: str) -> str | None:
    if text == "arduino":
        return None
    kind, sep, port = text.partition(":")
    if kind != "zaber" or not sep or not port:
        raise InputError(f"--stage: expected 'arduino' or 'zaber:PORT', got {text!r}")
    return port


def _plan(setup: Setup | str | os.PathLike, stage: str, motion: str | os.PathLike | None
          ) -> tuple[Setup, CapturePlan, MotionFile | None, str | None]:
    """The setup resolved, the capture's plan, the motion file read and the Zaber port."""
    from ..rig import plan_capture

    zaber_port = _parse_stage(stage)
    resolved = resolve_setup(setup)
    motion_file = read_motion_file(motion, resolved)
    kind = "zaber" if zaber_port else "arduino"
    if motion_file is None:
        plan = plan_capture(resolved, stage=kind)
    else:
        plan = plan_capture(resolved, stage=kind, motion=motion_file.profile,
                            exposure_s=motion_file.exposure_s)
    return resolved, plan, motion_file, zaber_port


def plan_rig_capture(setup: Setup | str | os.PathLike, *, stage: str = "arduino",
                     motion: str | os.PathLike | None = None) -> WorkflowResult:
    """The plan of a capture, without opening a port (``mitsweep capture --dry-run``).

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup (its ``[sweep]`` and ``[rig]`` sections), its TOML file or a bundled name.
    stage : str
        What moves the stage: ``"arduino"`` (the sweep controller), or ``"zaber:PORT"`` (a
        Zaber ASCII-protocol stage on PORT, the Arduino only firing the shutter).
    motion : path-like, optional
        A motion-profile file to run instead of the linear sweep.

    Returns
    -------
    WorkflowResult
        ``value``: the :class:`mitsweep.rig.CapturePlan`. ``provenance``: ``setup`` (its
        name), ``stage``, ``motion`` (the file or None), ``version``. ``summary``: what
        ``mitsweep capture --dry-run --json`` prints.

    Raises
    ------
    InputError
        A bad ``stage``.
    mitsweep.config.SetupError
        A setup or motion file the rig cannot run (travel, velocity, acceleration).

    Examples
    --------
    >>> from mitsweep.workflows import plan_rig_capture
    >>> plan = plan_rig_capture("sphere").value      # doctest: +SKIP
    >>> print(plan.summary())                        # doctest: +SKIP
    """
    resolved, plan, _, _ = _plan(setup, stage, motion)
    provenance = {"workflow": "plan_rig_capture", "version": __version__,
                  "setup": resolved.name, "stage": stage,
                  "motion": None if motion is None else os.fspath(motion)}
    return WorkflowResult(plan, provenance,
                          {"setup": resolved.name, "dry_run": True, "plan": plan.as_dict()})


def capture(setup: Setup | str | os.PathLike, *, port: str | None,
            stage: str = "arduino", out: str | os.PathLike | None = None,
            force: bool = False, checksums: bool = False,
            motion: str | os.PathLike | None = None) -> WorkflowResult:
    """Drive the linear stage and the shutter over serial for one focal-sweep capture,
    and write its record (``mitsweep capture``).

    Everything is checked before any port is opened; the device phase is
    :func:`mitsweep.rig.run_capture`, with its safety behaviour: on any failure or signal
    the shutter is released and the stage stopped, and the record is written marked
    incomplete.

    Parameters
    ----------
    setup : Setup, path-like or str
        The setup (its ``[sweep]`` and ``[rig]`` sections), its TOML file or a bundled name.
    port : str
        Serial port of the Arduino sweep controller (e.g. ``/dev/ttyACM0``).
    stage : str
        ``"arduino"`` or ``"zaber:PORT"`` (:func:`plan_rig_capture`).
    out : path-like, optional
        The capture record (default ``capture_<setup>_<UTC time>.json``); never the setup
        file; an existing file only with ``force``.
    force : bool
        Replace an existing ``out``.
    checksums : bool
        Checksum every line on the serial links.
    motion : path-like, optional
        A motion-profile file to run instead of the linear sweep.

    Returns
    -------
    WorkflowResult
        ``value``: the complete :class:`mitsweep.rig.CaptureRecord`. ``provenance``:
        ``record`` (its path), ``setup`` (its name), ``stage``, ``port``, ``motion``,
        ``version``. ``summary``: what ``mitsweep capture --json`` prints (the measured
        exposure, and the measured motion's deviation from a profile's plan).

    Raises
    ------
    InputError
        No port, a bad stage, an existing record without ``force``, a record that is the
        setup file.
    mitsweep.rig.RigError, KeyboardInterrupt
        The capture did not complete; when the device phase had begun the exception holds
        the incomplete record as ``capture_record`` and its path as ``capture_out``
        (:func:`capture_failure` says what the user must know).

    Examples
    --------
    >>> from mitsweep.workflows import capture
    >>> r = capture("rig.toml", port="/dev/ttyACM0")  # doctest: +SKIP
    >>> r.summary["measured_exposure_s"]              # doctest: +SKIP
    0.6001
    """
    from ..rig import RigError, RigPorts, run_capture

    setup_path = None if isinstance(setup, Setup) else setup
    resolved, plan, motion_file, zaber_port = _plan(setup, stage, motion)
    if not port:
        raise InputError("--port is required (the Arduino's serial port) unless --dry-run")
    out = os.fspath(out) if out else (
        f"capture_{resolved.name}_{_dt.datetime.now(_dt.timezone.utc):%Y%m%dT%H%M%SZ}.json")
    check_outputs([setup_path], {"--out": out})          # never the setup, even with force
    if os.path.lexists(out) and not force:
        raise InputError(f"--out {out} exists: pass --force to replace it, or choose "
                         f"another path")
    ports = RigPorts(arduino=port, zaber=zaber_port, checksums=checksums)
    try:
        record = run_capture(resolved, ports, out=out, plan=plan, motion_file=motion_file)
    except (RigError, KeyboardInterrupt) as exc:
        exc.capture_out = out  # type: ignore[union-attr]  # the record's path, for capture_failure
        raise
    m = record.measurement(strict=True)  # a complete capture saw the whole shutter cycle
    assert m is not None  # strict: a missing measurement is raised as a RigError
    cmp = m.get("profile")
    extra = {} if cmp is None else {
        "profile_max_deviation_steps": cmp["max_deviation_steps"],
        "profile_tolerance_steps": cmp["tolerance_steps"]}
    summary = {"setup": resolved.name, "record": str(out), "complete": record.complete,
               **m["exposure"], **extra}
    provenance = {"workflow": "capture", "version": __version__, "record": str(out),
                  "setup": resolved.name, "stage": stage, "port": port,
                  "motion": None if motion is None else os.fspath(motion),
                  "measurement": m}
    return WorkflowResult(record, provenance, summary)


def exit_status(exc: BaseException, safe: bool) -> int:
    """The exit status of an incomplete capture (the table of ``mitsweep capture``).

    Parameters
    ----------
    exc : BaseException
        Why the capture stopped.
    safe : bool
        Whether the devices confirmed every safety step (shutter released, stage
        stopped).

    Returns
    -------
    int
        :data:`EXIT_MAYBE_UNSAFE` when not ``safe``; else 128 + the signal's number for
        an interruption (SIGINT when it has none), :data:`EXIT_INCOMPLETE_SAFE`
        otherwise.
    """
    if not safe:
        return EXIT_MAYBE_UNSAFE
    if isinstance(exc, KeyboardInterrupt):
        return 128 + getattr(exc, "signum", 2)   # SIGINT is 2
    return EXIT_INCOMPLETE_SAFE


def capture_failure(exc: BaseException) -> tuple[str, int]:
    """What an incomplete capture (an exception of :func:`capture` holding its record)
    means: the line for the user (which safety steps the devices confirmed, where the
    record is) and the exit status.

    Parameters
    ----------
    exc : BaseException
        The exception :func:`capture` raised, holding the incomplete record as
        ``capture_record`` (and its path as ``capture_out``).

    Returns
    -------
    (str, int)
        The line and the exit status (:func:`exit_status`).
    """
    from ..rig import safety_summary
    from ..rig.capture import status_of

    # run_capture puts the record on the exception (any type: the type cannot say so)
    record = exc.capture_record  # type: ignore[attr-defined]
    out = getattr(exc, "capture_out", None)
    safe, steps = safety_summary(record)
    if isinstance(exc, KeyboardInterrupt):
        head = f"capture incomplete (interrupted by {record.signal})"
    else:
        head = f"capture incomplete ({status_of(exc)}): {exc or type(exc).__name__}"
    tail = "" if safe else "; the rig may be unsafe: check the stage and the shutter"
    return f"mitsweep: {head}; {steps}{tail}; record: {out}", exit_status(exc, safe)
