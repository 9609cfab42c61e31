"""``--motion PROFILE.json``: the one option through which commands run a designed motion.

A command adds the option with :func:`add_motion_argument` and passes its value to its
workflow, which reads it and checks it against the setup
(:func:`mitsweep.workflows.read_motion_file`: the focal length, the rig's travel, velocity
and acceleration) before any work, so a profile the stage cannot follow is one line and
exit status 2, before any motion.
"""

from __future__ import annotations

import argparse

__all__ = ["add_motion_argument"]


def add_motion_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--motion PROFILE.json`` (default: the setup's own sweep motion)."""
    parser.add_argument("--motion", metavar="PROFILE.json",
                        help="run this sensor-motion profile (a motion-profile file, e.g. "
                             "from `mitsweep design-sweep`) instead of the setup's sweep; "
                             "the reference grid is mid-travel of its span")
