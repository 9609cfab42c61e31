"""``--motion PROFILE.json``: the one option through which commands run a designed motion.

A command adds the option with :func:`add_motion_argument` and reads it with
:func:`motion_from_args` (the profile, for the tracer and the renderer) or
:func:`motion_file_from_args` (the whole file, with its exposure, for the rig). The file
is read and checked against the setup (:func:`mitsweep.optics.motion_file.check_motion_file`:
the focal length, the rig's travel, velocity and acceleration) before any work, so a
profile the stage cannot follow is one line and exit status 2, before any motion.
"""

from __future__ import annotations

import argparse

from ..config import Setup
from ..optics.motion import MotionProfile
from ..optics.motion_file import MotionFile

__all__ = ["add_motion_argument", "motion_from_args", "motion_file_from_args"]


def add_motion_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--motion PROFILE.json`` (default: the setup's own sweep motion)."""
    parser.add_argument("--motion", metavar="PROFILE.json",
                        help="run this sensor-motion profile (a motion-profile file, e.g. "
                             "from `mitsweep design-sweep`) instead of the setup's sweep; "
                             "the reference grid is mid-travel of its span")


def motion_file_from_args(args: argparse.Namespace, setup: Setup) -> MotionFile | None:
    """The ``--motion`` file, read and checked against ``setup``; None when not given.

    Returns
    -------
    mitsweep.optics.motion_file.MotionFile or None

    Raises
    ------
    mitsweep.config.SetupError
        One line: the file breaks the format, or the setup cannot run it.
    OSError
        The file cannot be read.
    """
    path = getattr(args, "motion", None)
    if path is None:
        return None
    from ..optics.motion_file import check_motion_file, load_motion_file

    return check_motion_file(load_motion_file(path), setup)


def motion_from_args(args: argparse.Namespace, setup: Setup) -> MotionProfile | None:
    """The ``--motion`` profile (a tabulated :class:`~mitsweep.optics.motion.MotionProfile`)
    checked against ``setup``; None when the option was not given."""
    mf = motion_file_from_args(args, setup)
    return None if mf is None else mf.profile
