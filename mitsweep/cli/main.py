"""``mitsweep``: one program, one subcommand per job.

Each subcommand module exposes ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> int``; adding a command is adding its module name to ``COMMANDS``.
"""

from __future__ import annotations

import contextlib
import importlib
import logging
import signal
import sys
import threading

from .common import (USER_ERRORS, ArgumentParser, ArgumentParserError, configure_logging,
                     print_error_json, user_error_message)

# Module names under mitsweep.cli, in the order shown by --help.
COMMANDS = [
    "demo",
    "sweep_range",
    "render",
    "ipsf",
    "design_sweep",
    "table1",
    "figures",
    "dataset",
    "deconvolve",
    "evaluate",
    "budget",
    "bench",
    "capture",
    "unwarp",
    "calibrate",
]


def build_parser() -> ArgumentParser:
    """The ``mitsweep`` parser: ``--version``, ``-v``, and one subparser per module of
    :data:`COMMANDS`, each with its ``run`` as the ``_run`` default."""
    from .. import __version__

    parser = ArgumentParser(prog="mitsweep", description="Focal-sweep EDOF catadioptric "
                            "imaging: design, IPSFs, rendering, deconvolution, capture.")
    parser.add_argument("--version", action="version", version=f"mitsweep {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="more log output on stderr (-vv for debug)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=ArgumentParser)
    sub.required = True
    for name in COMMANDS:
        mod = importlib.import_module(f"mitsweep.cli.{name}")
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.HELP)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one ``mitsweep`` command line.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program's name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status: the command's (0 on success), 2 for a user error (one line on
        stderr; with ``--json`` also an error object on stdout), 130 when interrupted.

    Raises
    ------
    SystemExit
        A command line argparse refused (status 2, after its line on stderr),
        ``--help`` and ``--version`` (status 0), or SIGTERM during the command (status
        143, once temporaries are removed and locks released).
    """
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = parser.parse_args(argv)
    except ArgumentParserError as exc:  # the line is on stderr already
        if _wants_json(argv):
            # the code SystemExit holds: an int here (ArgumentParser.error gives 2)
            status = exc.code if isinstance(exc.code, int) else 2
            print_error_json(exc.message, _command_name(argv), status)
        raise
    configure_logging(args.verbose)
    try:
        with _terminate_cleanly():
            return int(args._run(args) or 0)
    except BrokenPipeError:  # output piped into head & co.
        return 0
    except KeyboardInterrupt:
        print("mitsweep: interrupted", file=sys.stderr)
        return 130
    except USER_ERRORS as exc:
        # ValueError is broad: keep the traceback one `-vv` away for bug reports.
        logging.getLogger("mitsweep").debug("user error", exc_info=True)
        print(user_error_message(exc), file=sys.stderr)
        if getattr(args, "json", False):
            print_error_json(user_error_message(exc, prefix=False), args.command, 2)
        return 2


def _wants_json(argv: list[str]) -> bool:
    """Whether ``--json`` is among the options (before a ``--``)."""
    options = argv[:argv.index("--")] if "--" in argv else argv
    return "--json" in options


def _command_name(argv: list[str]) -> str | None:
    """The subcommand named on a command line that failed to parse, if any."""
    names = {name.replace("_", "-") for name in COMMANDS}
    return next((a for a in argv if a in names), None)


@contextlib.contextmanager
def _terminate_cleanly():
    """SIGTERM unwinds like an exception (exit status 143), so that temporaries are
    removed and locks released on the way out instead of being left by a hard stop."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise SystemExit(128 + signum)

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def entry() -> None:
    """The ``mitsweep`` console script: :func:`main` on ``sys.argv``, its status the
    process's exit status."""
    sys.exit(main())
