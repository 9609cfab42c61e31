"""What every workflow shares: its result type, its input error, the setup argument,
progress reporting and strict JSON."""

from __future__ import annotations

import contextlib
import json
import math
import os
import sys
from dataclasses import dataclass, field
from typing import Any, overload
from collections.abc import Callable, Iterator

from ..config import Setup, SetupError, load_setup
from ..optics.motion_file import MotionFile
from ..resources import bundled_setup, bundled_setup_names
from ._errors import InputError
from ._paths import shown_path

__all__ = ["InputError", "WorkflowResult", "resolve_setup", "read_motion_file", "json_text",
           "progress_callback"]

Progress = Any  # None, True or a callable: see progress_callback


@dataclass(frozen=True)
class WorkflowResult:
    """What a workflow returns: its product, where it came from, and its summary.

    Attributes
    ----------
    value : object
        The product: an image (``(H, W[, C]) float32 ndarray``), an IPSF bank, a sweep
        range, a manifest... (each workflow's Returns section names it).
    provenance : dict
        How it was made, JSON-serialisable: at least ``workflow`` (its name) and
        ``version`` (mitsweep's), then the workflow's own keys (inputs, setup, where the
        pixel pitch and the centre came from, the bank's identity, timings...). Where the
        workflow writes a file, this is the metadata the file carries.
    summary : dict
        The JSON object the matching ``mitsweep`` command prints with ``--json``.
    """

    value: Any
    provenance: dict = field(default_factory=dict)
    summary: dict = field(default_factory=dict)


def resolve_setup(setup: Setup | str | os.PathLike) -> Setup:
    """A setup given as a :class:`~mitsweep.config.Setup`, a setup TOML file, or the name
    of a bundled setup (:func:`mitsweep.resources.bundled_setup_names`) when no such file
    exists.

    Besides the field checks of :func:`mitsweep.config.load_setup`, ``sweep.fov_deg``
    must lie within the mirror's reach from the camera (:func:`mitsweep.optics.mirror_zone`),
    so that a workflow refuses such a setup when it reads it, not halfway through.

    Parameters
    ----------
    setup : Setup, str or path-like
        The setup, its TOML file, or a bundled name (``"sphere"``).

    Returns
    -------
    mitsweep.config.Setup

    Raises
    ------
    mitsweep.config.SetupError
        One line: a path that is neither a file nor a bundled name (listing the bundled
        names), a bad key, or an FOV beyond the mirror's reach (naming ``sweep.fov_deg``
        and the largest FOV the mirror gives).

    Examples
    --------
    >>> from mitsweep.workflows import resolve_setup
    >>> resolve_setup("sphere").mirror.radius
    25.0
    """
    from ..optics.sweep import mirror_zone

    if isinstance(setup, Setup):
        result = setup
    elif os.path.lexists(setup):
        result = load_setup(os.fspath(setup))
    elif os.fspath(setup) in bundled_setup_names():
        result = load_setup(bundled_setup(os.fspath(setup)))
    else:
        raise SetupError(f"{shown_path(setup)}: no such setup file, nor a bundled setup name "
                         f"(bundled: {', '.join(bundled_setup_names())})")
    mirror_zone(result)
    return result


@overload
def read_motion_file(path: None, setup: Setup) -> None: ...


@overload
def read_motion_file(path: str | os.PathLike, setup: Setup) -> MotionFile: ...


def read_motion_file(path: str | os.PathLike | None, setup: Setup) -> MotionFile | None:
    """A motion-profile file (``--motion``: e.g. from ``mitsweep design-sweep``), read and
    checked against ``setup`` (:func:`mitsweep.optics.motion_file.check_motion_file`: the
    focal length, the rig's travel, velocity and acceleration) before any work; None when
    ``path`` is None.

    Parameters
    ----------
    path : path-like or None
        The motion-profile file (JSON), or None (no file: the setup's own sweep).
    setup : Setup
        The setup the file must suit.

    Returns
    -------
    mitsweep.optics.motion_file.MotionFile or None
        Its ``profile`` is what the tracer and the renderer run, its ``exposure_s`` what
        the rig does.

    Raises
    ------
    mitsweep.config.SetupError
        One line: the file breaks the format, or the setup cannot run it.
    OSError
        The file cannot be read.
    """
    if path is None:
        return None
    from ..optics.motion_file import check_motion_file, load_motion_file

    return check_motion_file(load_motion_file(path), setup)


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
    Python writes by default and strict parsers (jq, browsers) refuse.

    Parameters
    ----------
    obj : object
        JSON-serialisable values (dicts, lists, tuples, numbers, strings, None).

    Returns
    -------
    str
        Indented, keys sorted, ending in a newline.
    """
    return json.dumps(_finite_json(obj), indent=2, sort_keys=True, allow_nan=False) + "\n"


@contextlib.contextmanager
def progress_callback(progress: Progress, total: int | None, desc: str, unit: str
                      ) -> Iterator[Callable[..., object] | None]:
    """The callable a long loop reports to, for a workflow's ``progress`` argument: None
    (nothing), True (a tqdm bar on stderr, shown when stderr is a terminal) or the
    caller's own callable (called with the number of items done since the last call).

    Parameters
    ----------
    progress : None, bool or callable
        What to report to; False is as None.
    total : int or None
        Items in all (the bar's length; None: unknown).
    desc : str
        The bar's label.
    unit : str
        The bar's unit (``"ipsf"``, ``"item"``...).

    Yields
    ------
    callable or None
        ``step(n)``, to call with the items done since the last call; None reports
        nothing.
    """
    if progress is None or progress is False:
        yield None
    elif progress is True:
        from tqdm import tqdm

        with tqdm(total=total, desc=desc, unit=unit, file=sys.stderr,
                  disable=not sys.stderr.isatty()) as bar:
            yield bar.update
    else:
        yield progress
