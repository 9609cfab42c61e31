"""Shared CLI plumbing: user errors → one line on stderr and exit status 2."""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from typing import Any

from ..config import SetupError, load_setup

__all__ = ["UsageError", "USER_ERRORS", "ArgumentParser", "load_setup_arg", "print_json",
           "positive_float", "positive_int", "user_error_message"]


class UsageError(ValueError):
    """Bad command-line input: reported in one line, exit status 2."""


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


def user_error_message(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return f"mitsweep: error: {text}"


class ArgumentParser(argparse.ArgumentParser):
    """argparse that exits with status 2 and one line (argparse's own convention)."""

    def error(self, message: str):  # noqa: D401
        self.exit(2, f"{self.prog}: error: {message}\n")


def load_setup_arg(path: str):
    return load_setup(path)


def _finite_json(o: Any):
    if isinstance(o, float) and not math.isfinite(o):
        return None if math.isnan(o) else ("inf" if o > 0 else "-inf")
    if isinstance(o, dict):
        return {k: _finite_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite_json(v) for v in o]
    return o


def print_json(obj: Any) -> None:
    """One JSON object on stdout (non-finite floats become null / "inf")."""
    json.dump(_finite_json(obj), sys.stdout, indent=2, sort_keys=True)
    sys.stdout.write("\n")


def positive_float(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (x > 0) or math.isnan(x):
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return x


def positive_int(text: str) -> int:
    try:
        x = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if x <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return x


def configure_logging(verbose: int) -> None:
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
