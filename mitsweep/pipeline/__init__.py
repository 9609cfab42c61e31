"""Synthetic datasets and their evaluation: the paper's pipeline end to end.

For a setup, :func:`build_dataset` renders per scene variation the pinhole ground truth
(with the depth and mirror-mask AOVs), the ``focused``, ``sweep`` and ``stopped``
images, traces the IPSF bank once, makes noisy versions at chosen light levels, and
deconvolves the sweep images into EDOF images with each restoration method asked for
(:mod:`.tasks`). :func:`evaluate_dataset` scores them against the ground truth inside
the mirror's image: PSNR and SSIM overall, per radius and per depth band
(:mod:`.evaluation`).

The tasks run through a generic resumable runner (:mod:`.runner`): files written
atomically; ``manifest.json`` records every finished item with its parameters and
SHA-256, so a rerun skips what is complete and valid and redoes the rest; an advisory
lock on the directory (``.mitsweep.lock``) refuses a second run, or waits; per-task logs
in ``logs/``; the manifest is validated whenever it is read (:func:`validate_manifest`),
by ``dataset`` and ``evaluate`` alike. Tasks run here, in local processes, on Dask or on
any :class:`concurrent.futures.Executor` (:mod:`.executors`), and in shards ``K/N`` for
job arrays; the files are the same bytes whichever way they were made.
"""

from ..io.bank import bank_kernel_size
from ..optics.diffraction import add_diffraction
from .dataset import (FORMAT, build_dataset, dataset_inputs, load_manifest, read_manifest,
                      validate_manifest)
from .evaluation import DEPTH_BANDS_MM, evaluate_dataset
from .executors import EXECUTORS
from .options import (MAX_BANK_DEPTHS, MAX_LIGHT_LEVELS, MAX_SCENES, MAX_SEED,
                      DatasetOptions, options_from_dict)
from .runner import LOG_DIR, MANIFEST, SHARD_DIR, DatasetError, Shard
from .tasks import (DECONV_PRIOR, NOISE_PIXEL_MM, WHITE_PERCENTILE, edof_name, item_names,
                    white_level)

__all__ = ["DatasetOptions", "options_from_dict", "build_dataset", "evaluate_dataset",
           "load_manifest", "validate_manifest", "item_names", "dataset_inputs", "MANIFEST",
           "MAX_SCENES", "DatasetError", "Shard", "EXECUTORS", "white_level", "edof_name",
           "bank_kernel_size", "add_diffraction", "read_manifest"]
