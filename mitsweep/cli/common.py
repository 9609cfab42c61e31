"""Shared CLI plumbing: user errors → one line on stderr and exit status 2."""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, NoReturn, TypeVar, Union

from ..config import Setup, SetupError, load_setup
from ..deconv.noise import ILLUMINANCE_RANGE_LUX
from ..optics.sweep import mirror_zone
from ..resources import bundled_setup, bundled_setup_names

__all__ = ["depth_mm", "number_type", "UsageError", "USER_ERRORS", "ArgumentParser",
           "ArgumentParserError", "check_output_name", "check_outputs", "json_text",
           "load_setup_arg", "print_error_json", "print_json", "positive_float",
           "positive_int", "shown_path", "user_error_message"]


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

    def error(self, message: str) -> NoReturn:  # noqa: D401
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise ArgumentParserError(message, 2)


PathArg = Union[str, os.PathLike, None]


def _same_path(a: Path, b: Path) -> bool:
    """Whether two paths name one file: equal once resolved (symlinks, ``..``), or the
    same inode (hard links, case-insensitive file systems)."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet): not the same file
        return False


def shown_path(path: PathArg) -> str:
    """``path`` as a message shows it: its file-system bytes as UTF-8, with any byte that is
    not UTF-8 written ``\\xNN`` (never a lone surrogate that a terminal cannot print)."""
    text = os.fspath(path) if path is not None else ""
    try:
        data = os.fsencode(text)
    except UnicodeEncodeError:
        data = text.encode("utf-8", "backslashreplace")
    return data.decode("utf-8", "backslashreplace")


def check_output_name(path: PathArg, option: str = "output") -> None:
    """Refuse an output path that cannot be written under the name the user gave.

    Two encodings meet in one output name: the file system's (:func:`os.fsencode`: what
    Python's ``open``, ``os.replace`` and Pillow use) and UTF-8 (what OpenEXR's binding
    passes to C++, what the manifests and provenance hold). A name must round-trip
    through both and give the same bytes, so that OpenEXR writes the file that the atomic
    rename then moves. Refused, before any work:

    - a name holding bytes that are not UTF-8 (``$'\\xff.exr'``: Python's argv carries
      them as surrogates, which OpenEXR refuses with ``use write(path: str)``);
    - under an ASCII or other non-UTF-8 file-system encoding (``LC_ALL=C`` with
      ``PYTHONUTF8=0``, a Latin-1 locale), a non-ASCII name: its file-system bytes differ
      from the UTF-8 bytes OpenEXR would write (or it has none).

    Raises
    ------
    UsageError
        One line naming ``option`` and the path (non-UTF-8 bytes shown as ``\\xNN``).
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    try:
        native = os.fsencode(text)
    except UnicodeEncodeError:
        raise UsageError(f"{option} {shown_path(text)}: the name cannot be encoded in the "
                         f"file system encoding ({sys.getfilesystemencoding()}); use an "
                         f"ASCII name, or run under a UTF-8 locale") from None
    try:
        native.decode("utf-8")
    except UnicodeDecodeError:
        raise UsageError(f"{option} {shown_path(text)}: the name is not valid UTF-8; "
                         f"rename it with UTF-8 characters only") from None
    try:
        utf8 = text.encode("utf-8")   # what OpenEXR's binding asks of a str
    except UnicodeEncodeError:        # surrogates: bytes the file-system encoding lacked
        utf8 = None
    if utf8 != native:
        raise UsageError(f"{option} {shown_path(text)}: a non-ASCII name under the "
                         f"{sys.getfilesystemencoding()} file system encoding; use an ASCII "
                         f"name, or run under a UTF-8 locale (LC_ALL=C.UTF-8)")


def check_outputs(inputs: Iterable[PathArg],
                  outputs: Iterable[PathArg] | Mapping[str, PathArg | Iterable[PathArg]],
                  ) -> None:
    """Refuse a command line whose outputs cannot be written as named, or would
    overwrite one of its inputs.

    The one output policy of every command, checked before any work:

    - each output name can be written under its own name (:func:`check_output_name`:
      file-system encoding and UTF-8 agree), so no rendering ends in an encoding error;
    - an output never names the same file as an input (``render setup.toml --out
      setup.toml``, ``deconvolve IMG --out IMG``, a plot path equal to the setup), nor
      the same file as another output. Paths compare once resolved and by inode
      (``os.path.samefile``), so symlinks and hard links are caught.

    Overwriting an existing output of an earlier run stays allowed (writes are atomic).

    Parameters
    ----------
    inputs : iterable of path-like or None
        Every file the command reads; ``None`` entries (an option not given) are skipped.
    outputs : mapping of str to path-like, None or list; or iterable of path-like or None
        Every file (or folder) the command will write, keyed by the option that names it
        (``{"--out": args.out, "--preview": args.preview}``; the files written under one
        option's folder as a list) so that a refusal names the option; ``None`` entries
        are skipped.

    Raises
    ------
    UsageError
        One line naming the option (or both paths).
    """
    if isinstance(outputs, Mapping):
        named = [(opt, p) for opt, given in outputs.items()
                 for p in (given if isinstance(given, (list, tuple)) else [given])]
    else:
        named = [("output", p) for p in outputs]
    named = [(opt, p) for opt, p in named if p is not None and str(p) != ""]
    for opt, p in named:
        check_output_name(p, opt)
    ins = [Path(p) for p in inputs if p is not None and str(p) != ""]
    outs = [Path(p) for _, p in named]
    for k, out in enumerate(outs):
        for inp in ins:
            if _same_path(out, inp):
                raise UsageError(f"output {out} is the input {inp}: refusing to overwrite an "
                                 f"input; choose another output path")
        for other in outs[:k]:
            if _same_path(out, other):
                raise UsageError(f"output {out} and output {other} are the same file: give "
                                 f"each output its own path")


def load_setup_arg(path: str) -> Setup:
    """A ``SETUP`` argument: a setup TOML file, or the name of a bundled setup
    (:func:`mitsweep.resources.bundled_setup_names`) when no such file exists.

    Besides the field checks of :func:`mitsweep.config.load_setup`, the setup's
    ``sweep.fov_deg`` must lie within the mirror's reach from the camera
    (:func:`mitsweep.optics.mirror_zone`, the check :func:`mitsweep.optics.optimal_sweep_range`
    makes): every command refuses such a setup when it reads it, not halfway through.

    Raises
    ------
    SetupError
        One line: a path that is neither a file nor a bundled name (listing the bundled
        names), a bad key, or an FOV beyond the mirror's reach (naming ``sweep.fov_deg``
        and the largest FOV the mirror gives).
    """
    if os.path.lexists(path):
        setup = load_setup(path)
    elif path in bundled_setup_names():
        setup = load_setup(bundled_setup(path))
    else:
        raise SetupError(f"{shown_path(path)}: no such setup file, nor a bundled setup name "
                         f"(bundled: {', '.join(bundled_setup_names())})")
    # The reach needs the optics, which config (the base layer) may not import.
    mirror_zone(setup)
    return setup


def _finite_json(o: Any):
    if isinstance(o, float) and not math.isfinite(o):
        return None if math.isnan(o) else ("inf" if o > 0 else "-inf")
    if isinstance(o, dict):
        return {k: _finite_json(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite_json(v) for v in o]
    return o


def json_text(obj: Any) -> str:
    """``obj`` as strict JSON text (what ``--json`` prints and ``--out`` files hold):
    non-finite floats become null (NaN) or "inf" / "-inf", never the ``Infinity`` that
    Python writes by default and strict parsers (jq, browsers) refuse."""
    return json.dumps(_finite_json(obj), indent=2, sort_keys=True, allow_nan=False) + "\n"


def print_json(obj: Any) -> None:
    """One JSON object on stdout (:func:`json_text`)."""
    sys.stdout.write(json_text(obj))


N = TypeVar("N", int, float)


def number_type(convert: Callable[[str], N], ok: Callable[[N], bool], expected: str,
                allowed: str, name: str) -> Callable[[str], N]:
    """An argparse ``type``: ``convert(text)``, refused unless ``ok`` of it.

    Messages: ``expected <expected>, got 'text'`` (not a number) and ``must be <allowed>,
    got text`` (out of range); argparse prefixes the option. ``ok`` must be False for NaN
    where NaN is not allowed (``x > 0`` is).
    """
    def parse(text: str) -> N:
        try:
            x = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not ok(x):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text}")
        return x

    parse.__name__ = parse.__qualname__ = name
    return parse


#: A number > 0.
positive_float = number_type(float, lambda x: x > 0, "a number", "> 0", "positive_float")
#: A scene illuminance of a noise model, lux, in
#: :data:`mitsweep.deconv.noise.ILLUMINANCE_RANGE_LUX`.
illuminance_lux = number_type(
    float, lambda x: ILLUMINANCE_RANGE_LUX[0] <= x <= ILLUMINANCE_RANGE_LUX[1],
    "an illuminance in lux",
    f"an illuminance in [{ILLUMINANCE_RANGE_LUX[0]:g}, {ILLUMINANCE_RANGE_LUX[1]:g}] lux",
    "illuminance_lux")
#: An object depth in mm: a number > 0, ``inf`` allowed.
depth_mm = number_type(float, lambda x: x > 0, "a depth in mm (or inf)",
                       "> 0 mm (inf allowed)", "depth_mm")
#: An integer > 0.
positive_int = number_type(int, lambda x: x > 0, "an integer", "> 0", "positive_int")


def add_photo_arguments(p: argparse.ArgumentParser) -> None:
    """The options of every command that reads a camera file
    (:func:`mitsweep.io.camera.read_camera_image`): ``--pixel-pitch``,
    ``--white-balance`` (RAW) and ``--transfer`` (TIFF, PNG, JPEG); pass them on with
    :func:`photo_options`."""
    from ..io.camera import TRANSFERS, WHITE_BALANCES

    p.add_argument("--pixel-pitch", type=positive_float, metavar="MM",
                   help="the photo's pixel pitch, mm, when its metadata has none "
                        "(default: the file's, else the setup's sensor.pixel_pitch)")
    p.add_argument("--white-balance", choices=WHITE_BALANCES, default="camera",
                   help="RAW files: white balance of the decoding (default: camera, the "
                        "as-shot multipliers)")
    p.add_argument("--transfer", choices=TRANSFERS, default=None,
                   help="force the transfer function of a TIFF, PNG or JPEG (default: "
                        "from its metadata; see the README)")


def photo_options(args) -> dict:
    """``read_camera_image`` keyword arguments from :func:`add_photo_arguments`'s options."""
    return {"pixel_pitch": args.pixel_pitch, "white_balance": args.white_balance,
            "transfer": args.transfer}


def configure_logging(verbose: int) -> None:
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)
