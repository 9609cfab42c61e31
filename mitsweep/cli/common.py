"""Shared CLI plumbing: user errors → one line on stderr and exit status 2.

The argument types live in :mod:`mitsweep.cli.args`; the output policy
(:func:`check_outputs`), the setup argument and strict JSON are the workflows'
(:mod:`mitsweep.workflows`), re-exported here.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Any, NoReturn

from ..config import Setup, SetupError
from ..workflows._base import json_text, resolve_setup
from ..workflows._errors import InputError
from ..workflows._paths import check_output_name, check_outputs, shown_path
from .args import (add_photo_arguments, depth_mm, illuminance_lux, number_type,
                   photo_options, positive_float, positive_int)

__all__ = ["depth_mm", "number_type", "UsageError", "USER_ERRORS", "ArgumentParser",
           "ArgumentParserError", "check_output_name", "check_outputs", "json_text",
           "load_setup_arg", "print_error_json", "print_json", "positive_float",
           "positive_int", "shown_path", "user_error_message", "illuminance_lux",
           "add_photo_arguments", "photo_options", "configure_logging"]

#: Bad command-line input: reported in one line, exit status 2 (the workflows' InputError).
UsageError = InputError


def _user_errors() -> tuple[type[BaseException], ...]:
    # OSError covers unwritable outputs, full disks and missing ports: the user's to fix.
    errors: list[type[BaseException]] = [UsageError, SetupError, OSError, ValueError]
    try:
        from ..backend import BackendError
        errors.append(BackendError)
    except ImportError:  # pragma: no cover
        pass
    return tuple(errors)


USER_ERRORS = _user_errors()


def user_error_message(exc: BaseException, *, prefix: bool = True) -> str:
    """The one line a user error prints: its message's first line, after
    ``mitsweep: error: `` unless ``prefix`` is false."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return f"mitsweep: error: {text}" if prefix else text


def print_error_json(message: str, command: str | None, exit_status: int) -> None:
    """A failed ``--json`` command's stdout: one object ``{"error": MESSAGE, "command":
    NAME, "exit_status": STATUS}``, so that a script parsing stdout sees the failure
    (the line on stderr and the exit status stay as without ``--json``)."""
    print_json({"error": message, "command": command, "exit_status": exit_status})


class ArgumentParserError(SystemExit):
    """A command line argparse refused; the line is on stderr, ``message`` keeps it
    without the ``PROG: error:`` prefix."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(code)
        self.message = message


class ArgumentParser(argparse.ArgumentParser):
    """argparse that exits with status 2 and one line (argparse's own convention)."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise ArgumentParserError(message, 2)


def load_setup_arg(path: str) -> Setup:
    """A ``SETUP`` argument: a setup TOML file, or a bundled setup's name
    (:func:`mitsweep.workflows.resolve_setup`, which refuses an FOV beyond the mirror's
    reach)."""
    return resolve_setup(path)


def print_json(obj: Any) -> None:
    """One JSON object on stdout (:func:`mitsweep.workflows.json_text`)."""
    sys.stdout.write(json_text(obj))


def configure_logging(verbose: int) -> None:
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
