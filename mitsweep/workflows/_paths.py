"""The output policy of every workflow: names that can be written as given, outputs that
never overwrite an input or each other."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from collections.abc import Iterable, Mapping
from typing import cast

from ._errors import InputError

__all__ = ["check_output_name", "check_outputs", "shown_path"]


PathArg = str | os.PathLike | None


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
    not UTF-8 written ``\\xNN`` (never a lone surrogate that a terminal cannot print).

    Parameters
    ----------
    path : str, path-like or None
        The path (None shows as the empty string).

    Returns
    -------
    str
    """
    text = os.fspath(path) if path is not None else ""
    try:
        data = os.fsencode(text)
    except UnicodeEncodeError:
        data = text.encode("utf-8", "backslashreplace")
    return data.decode("utf-8", "backslashreplace")


def check_output_name(path: str | os.PathLike, option: str = "output") -> None:
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

    Parameters
    ----------
    path : str or path-like
        The output's name as given.
    option : str
        The option that names it, for the message (``"--out"``).

    Raises
    ------
    InputError
        One line naming ``option`` and the path (non-UTF-8 bytes shown as ``\\xNN``).
    """
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    try:
        native = os.fsencode(text)
    except UnicodeEncodeError:
        raise InputError(f"{option} {shown_path(text)}: the name cannot be encoded in the "
                         f"file system encoding ({sys.getfilesystemencoding()}); use an "
                         f"ASCII name, or run under a UTF-8 locale") from None
    try:
        native.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{option} {shown_path(text)}: the name is not valid UTF-8; "
                         f"rename it with UTF-8 characters only") from None
    try:
        utf8 = text.encode("utf-8")   # what OpenEXR's binding asks of a str
    except UnicodeEncodeError:        # surrogates: bytes the file-system encoding lacked
        utf8 = None
    if utf8 != native:
        raise InputError(f"{option} {shown_path(text)}: a non-ASCII name under the "
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
    InputError
        One line naming the option (or both paths).
    """
    listed: list[tuple[str, PathArg]] = []
    if isinstance(outputs, Mapping):
        for opt, given in outputs.items():
            if isinstance(given, (list, tuple)):
                listed += [(opt, p) for p in given]
            else:  # one path (a str is a path, not an iterable of them)
                listed.append((opt, cast(PathArg, given)))
    else:
        listed = [("output", p) for p in outputs]
    named = [(opt, p) for opt, p in listed if p is not None and str(p) != ""]
    for opt, p in named:
        check_output_name(p, opt)
    ins = [Path(p) for p in inputs if p is not None and str(p) != ""]
    outs = [Path(p) for _, p in named]
    for k, out in enumerate(outs):
        for inp in ins:
            if _same_path(out, inp):
                raise InputError(f"output {out} is the input {inp}: refusing to overwrite an "
                                 f"input; choose another output path")
        for other in outs[:k]:
            if _same_path(out, other):
                raise InputError(f"output {out} and output {other} are the same file: give "
                                 f"each output its own path")
