"""Workflows: what each ``mitsweep`` command does, as documented library functions.

Each function takes plain Python values (paths, numbers, a :class:`~mitsweep.config.Setup`
or a setup's name), does the whole job a command does (reading, checking, computing,
writing the files asked for), and returns a :class:`WorkflowResult`: the product, its
provenance (inputs, setup, where each value came from, timings) and the summary the
command prints with ``--json``. The commands only parse their arguments, call one of
these and print.

Start here:

- :func:`run_demo`: the whole chain on the paper's sphere (``mitsweep demo``).
- :func:`restore_photo`: a focal-sweep photo → its EDOF image (``mitsweep deconvolve``).
- :func:`calibrate_camera`: the mirror's centre and rim on a photo, and a setup for its
  camera (``mitsweep calibrate``; :func:`find_mirror_circle` without a setup;
  :func:`calibrate_photo`, from :mod:`mitsweep.photo`, on an image array).
- :func:`unwarp_image`: a catadioptric image → its panorama (``mitsweep unwarp``).
- :func:`compute_sweep_range`: the optimal sweep range of a setup (``mitsweep sweep-range``).
- :func:`render_exr`: a render through the mirror with Mitsuba 3 (``mitsweep render``).
- :func:`run_benchmarks`: benchmarks against baselines, in one process (``mitsweep bench``).
- :func:`trace_ipsf`, :func:`trace_ipsf_bank`: IPSFs of a setup (``mitsweep ipsf``).
- :func:`build_dataset`, :func:`evaluate_dataset`: a synthetic dataset and its scores
  (``mitsweep dataset``, ``mitsweep evaluate``); :func:`error_budget`: where each EDOF
  image's error comes from (``mitsweep budget``).
- :func:`reproduce_table1`, :func:`make_paper_figures`: the paper's Table 1 and figures
  (``mitsweep table1``, ``mitsweep figures``).
- :func:`design_motion_profile`: an optimised sweep motion (``mitsweep design-sweep``).
- :func:`plan_rig_capture`, :func:`capture`: a capture on the rig (``mitsweep capture``).

Bad input raises :class:`InputError` (a :class:`ValueError`) or
:class:`mitsweep.config.SetupError` with one line naming what is wrong.
"""

from ..photo import calibrate_photo
from ._base import (WorkflowResult, json_text, progress_callback, read_motion_file,
                    resolve_setup)
from ._errors import InputError
from ._paths import check_output_name, check_outputs
from .bench import run_benchmarks
from .budget import error_budget
from .calibrate import calibrate_camera, find_mirror_circle
from .capture import capture, plan_rig_capture
from .dataset import build_dataset, evaluate_dataset
from .demo import run_demo
from .design_sweep import design_motion_profile
from .ipsf import trace_ipsf, trace_ipsf_bank
from .paper import make_paper_figures, reproduce_table1
from .render import render_exr
from .restore import restore_photo
from .sweep_range import compute_sweep_range
from .unwarp import unwarp_image

__all__ = ["WorkflowResult", "InputError", "resolve_setup", "read_motion_file", "json_text",
           "progress_callback",
           "check_output_name", "check_outputs", "restore_photo", "trace_ipsf",
           "trace_ipsf_bank", "build_dataset", "evaluate_dataset", "design_motion_profile",
           "unwarp_image", "calibrate_photo", "capture", "plan_rig_capture",
           "compute_sweep_range", "render_exr", "calibrate_camera", "find_mirror_circle",
           "run_demo", "run_benchmarks", "error_budget", "make_paper_figures",
           "reproduce_table1"]
