"""Workflows: what each ``mitsweep`` command does, as documented library functions.

Each function takes plain Python values (paths, numbers, a :class:`~mitsweep.config.Setup`
or a setup's name), does the whole job a command does (reading, checking, computing,
writing the files asked for), and returns a :class:`WorkflowResult`: the product, its
provenance (inputs, setup, where each value came from, timings) and the summary the
command prints with ``--json``. The commands only parse their arguments, call one of
these and print.

Start here:

- :func:`restore_photo`: a focal-sweep photo → its EDOF image (``mitsweep deconvolve``).

Bad input raises :class:`InputError` (a :class:`ValueError`) or
:class:`mitsweep.config.SetupError` with one line naming what is wrong.
"""

from ._base import WorkflowResult, json_text, progress_callback, resolve_setup
from ._errors import InputError
from ._paths import check_output_name, check_outputs
from .restore import restore_photo

__all__ = ["WorkflowResult", "InputError", "resolve_setup", "json_text", "progress_callback",
           "check_output_name", "check_outputs", "restore_photo"]
