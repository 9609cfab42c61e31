"""The dataset's tasks, each declared once (:func:`plan`), and what they compute.

Per scene variation: the pinhole ground truth (with the depth and mirror-mask AOVs), the
``focused``, ``sweep`` and ``stopped`` renders, noisy versions at chosen light levels
(the paper's Fig. 10 settings: sweep F2.8 0.6 s ISO 100, stopped F11 0.6 s ISO 1600),
and EDOF images deconvolved from the sweeps with the IPSF bank, traced once for the
dataset. Every task function takes the :class:`~mitsweep.config.Setup` itself, the path
it writes and its inputs and parameters as keywords; what it returns (timings) goes to
the task's log, not into its file, so one task always writes the same bytes.

Diffraction: the renders are geometric; the thin-lens images (focused, sweep, stopped)
are convolved with the lens's pixel-integrated Airy PSF at 550 nm (``diffraction=True``),
which is what the paper holds against stopping down. The ground truth stays ideal.

Scenes (``DatasetOptions.family``): scene ``i`` is the built-in room with texture layout
``scene.texture_seed + i`` (``room``, today's datasets: their task parameters are what
they always were), procedural scene ``seed + i`` of :mod:`mitsweep.render.procedural`,
or the ``i``-th XML file of the user's directory. For the last two, each render task's
parameters hold ``scene_source`` (:func:`scene_source`): the family, seed and resolved
parameters, or the file's path, SHA-256 and unit, with the SHA-256 of every file it
includes or loads. They are in the manifest, so any item can be made again alone
(``render(setup, out, **params)``), and a changed XML file, include, texture or mesh
changes its scene's parameters, so a rerun redoes that scene. A room dataset whose
setup names its own ``[scene] file`` holds that scene's digests in its render
parameters the same way (``setup_scene``).

Weights: the restorations' Wiener NSR comes from the image's noise model and the bank's
mismatch profile (:data:`WEIGHT_RULE`), calibrated once per dataset on a scene outside
it (:data:`CALIBRATION_DIR`: the pinhole and noise-free sweep of scene variation
:data:`CALIBRATION_SCENE`, shared by every shard like the bank, then
:data:`MISMATCH`). That scene is no dataset scene: evaluation, budgets, the dataset reader
and the benches list ``scene_*`` folders only.

Radiometry: renders are linear radiance. Relative exposure 1.0 (the noise model's
reference level, reflectance ``SensorNoise.reflectance`` under the scene illuminance) is
the 99th percentile of the ground truth inside the mirror's image; all images of a scene
are divided by that same level before noise and metrics (data range 1).
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Setup
from ..io import read_exr, write_exr
from ..deconv.weights import MismatchProfile   # NumPy/SciPy only: no renderer to plan
from ..io.bank import IPSFBank
from ..io.exr import stack_channels
from ..render.api import MODE_SAMPLERS, MODES  # render imports Mitsuba only when rendering
from ..resources import FileTypeError
from ..io.scene_files import SceneFileError, changed_files, scene_digests
from .options import MAX_SCENES, MAX_SEED, DatasetOptions
from .runner import DatasetError, Task, sha256

__all__ = ["plan", "item_names", "white_level", "read_rgb", "render", "scene_source",
           "setup_scene_digests", "trace_bank",
           "add_noise", "restore", "edof_name", "NOISE_PIXEL_MM", "DECONV_PRIOR", "WEIGHT_RULE",
           "WHITE_PERCENTILE", "BANK", "CALIBRATION_DIR", "CALIBRATION_SCENE", "MISMATCH",
           "calibrate_weights", "calibration_profile", "is_scene_item", "read_mismatch",
           "WEIGHT_RULES"]

logger = logging.getLogger(__name__)

WHITE_PERCENTILE = 99.0
#: Pixel of the camera whose noise the noisy images carry, mm: a DSLR of the paper's
#: era (6.4 µm, whose ~60 000 e⁻ full well is the noise model's default). The renders
#: use larger synthetic pixels so that the mirror's image fits a small frame; each
#: rendered pixel gets the noise of one such camera pixel (not of an 18 µm pixel, which
#: would collect 8× the light and saturate the modelled full well).
NOISE_PIXEL_MM = 0.0064
#: Wiener prior of the EDOF images (see :func:`restore`).
DECONV_PRIOR = "natural"
#: The dataset's IPSF bank (one for every scene).
BANK = "bank.npz"

#: The calibration scene's folder: its pinhole and noise-free sweep renders and the
#: bank's mismatch profile (:data:`MISMATCH`), shared tasks (group None) as the bank.
CALIBRATION_DIR = "calibration"

#: The calibration scene's index: scene variation ``MAX_SCENES`` (texture layout
#: ``scene.texture_seed + MAX_SCENES``, procedural seed ``seed + MAX_SCENES``), which no
#: dataset scene has (indices run below :data:`~mitsweep.pipeline.options.MAX_SCENES`),
#: so the weight is calibrated held out however many scenes a dataset grows to. An XML
#: dataset calibrates on the setup's own scene (the room, or its ``[scene] file``).
CALIBRATION_SCENE = MAX_SCENES

#: The bank's mismatch profile (:class:`mitsweep.deconv.weights.MismatchProfile`, JSON).
MISMATCH = f"{CALIBRATION_DIR}/mismatch.json"
#: Run information the renderer puts in its metadata that differs between runs: it
#: goes to the task's log, not into the file.
_RENDER_TIMINGS = ("render_s", "load_and_render_s", "aov_s")


def scene_setup(setup: Setup, index: int) -> Setup:
    """Scene variation ``index`` of the room: the texture layout
    ``scene.texture_seed + index``.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup.
    index : int
        The scene's index in the dataset, >= 0.

    Returns
    -------
    mitsweep.config.Setup
        ``setup`` with that texture seed.
    """
    return replace(setup, scene=replace(setup.scene,
                                        texture_seed=setup.scene.texture_seed + index))


def read_rgb(path: str | Path) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, Any]]:
    """An EXR's RGB image, all its channels and its metadata.

    Parameters
    ----------
    path : str or Path
        An EXR file (a dataset's item).

    Returns
    -------
    (ndarray, dict, dict)
        The ``(H, W, 3)`` float32 image (its R, G, B channels), every channel by name
        (``R``, ``mask.Y``, ``depth.Z``...), the metadata.
    """
    chans, meta = read_exr(path)
    return stack_channels(chans), chans, meta


#: The ``units`` a noisy image's metadata records: the renders' (its values are the noisy
#: relative exposure times the recorded ``white_level``).
NOISY_UNITS = "render radiance (relative exposure times white_level)"


def white_level(pinhole: np.ndarray, mask: np.ndarray | None) -> float:
    """Relative exposure 1.0: a high percentile (:data:`WHITE_PERCENTILE`, the 99th) of
    the ground truth in the mirror's mask.

    Parameters
    ----------
    pinhole : (H, W[, C]) ndarray
        The ground truth, render radiance.
    mask : (H, W) ndarray or None
        The mirror's mask (inside where > 0); None, or an empty mask, takes every
        pixel.

    Returns
    -------
    float
        The level, render radiance, > 0.

    Raises
    ------
    DatasetError
        The ground truth is black there (the level is not > 0).
    """
    values = pinhole[mask > 0] if mask is not None and np.any(mask > 0) else pinhole
    level = float(np.percentile(values, WHITE_PERCENTILE))
    if not level > 0:
        raise DatasetError("the ground-truth image is black inside the mirror: nothing to "
                           "normalise by (check the scene's lighting)")
    return level


# -- the tasks --------------------------------------------------------------------------

def scene_source(opts: DatasetOptions, index: int) -> dict | None:
    """What scene ``index`` of a dataset is made of, for its render tasks' parameters.

    Parameters
    ----------
    opts : DatasetOptions
        The dataset's options (its ``family``).
    index : int
        The scene's index, in [0, ``opts.scenes``).

    Returns
    -------
    dict or None
        None for the room (its parameters predate the families); for the procedural
        family ``{"family", "seed": opts.seed + index, "params"}``; for XML files
        ``{"family": "xml", "file", "sha256", "unit"}`` (unit None: the setup's), with
        ``files`` (the SHA-256 of each file it loads) when it loads others.
    """
    if opts.family == "procedural":
        return {"family": "procedural", "seed": opts.seed + index,
                "params": dict(opts.family_params)}
    if opts.family == "xml":
        f = opts.scene_files[index]
        source = {"family": "xml", "file": f["path"], "sha256": f["sha256"],
                  "unit": opts.scene_unit}
        if "files" in f:   # what it includes and loads: a change there redoes the scene
            source["files"] = f["files"]
        return source
    return None


def setup_scene_digests(setup: Setup | None) -> dict | None:
    """The content identity of the setup's own ``[scene] file`` (None without one): the
    SHA-256 of every file it loads (:func:`mitsweep.io.scene_files.scene_digests`), for
    the room family's render parameters. A scene changed since its items were made
    changes them, so a rerun redoes those items; another spelling of its path does not.

    Parameters
    ----------
    setup : mitsweep.config.Setup or None
        The dataset's setup (None: no setup, no digests).

    Returns
    -------
    dict or None
        ``{file name: SHA-256}``, or None when the setup names no scene file.

    Raises
    ------
    DatasetError
        The scene file does not exist.
    mitsweep.render.user_scene.UserSceneError
        It, or a file it loads, cannot be read as a scene.
    """
    if setup is None or setup.scene.file is None:
        return None
    from ..render.user_scene import UserSceneError

    try:
        return scene_digests(setup.scene.file)
    except FileNotFoundError:
        raise DatasetError(f"{setup.scene.file}: no such scene file (the setup's [scene] "
                           f"file)") from None
    except (FileTypeError, SceneFileError) as exc:
        raise UserSceneError(str(exc)) from None


def _check_unchanged(path: str | Path, recorded: dict[str, str]) -> None:
    """Refuse to render a scene whose files are not those the task was planned with."""
    try:
        changed = changed_files(recorded, path)
    except FileNotFoundError:
        changed = [Path(path).name]
    if changed:
        more = f" (and {len(changed) - 1} more)" if len(changed) > 1 else ""
        raise DatasetError(f"{Path(path).parent / changed[0]}: changed since the dataset was "
                           f"planned{more} (its SHA-256 differs); rerun `mitsweep dataset` "
                           f"to plan it again")


def _user_scene(setup: Setup, source: dict):
    """``(scene, scene_unit, max_depth)`` of :func:`render_image` for a scene source."""
    if source["family"] == "procedural":
        from ..render.procedural import procedural_scene

        objects, params = procedural_scene(setup, source["seed"], **source["params"])
        return {"type": "scene", **objects}, None, params["max_depth"]
    path = Path(source["file"])
    try:
        digest = sha256(path)
    except FileNotFoundError:
        raise DatasetError(f"{path}: scene file missing (the dataset was planned from it)") \
            from None
    if digest != source["sha256"]:
        raise DatasetError(f"{path}: changed since the dataset was planned (its SHA-256 "
                           f"differs); rerun `mitsweep dataset --scenes-from` to plan it "
                           f"again")
    if "files" in source:
        _check_unchanged(path, source["files"])
    return str(path), source["unit"], None


def _motion(motion: dict | None):
    """The :class:`~mitsweep.optics.motion.MotionProfile` of a task's ``motion``
    parameter (:attr:`DatasetOptions.motion`), None for the setup's own sweep."""
    if motion is None:
        return None
    from ..optics.motion import MotionProfile

    return MotionProfile.tabulated(motion["times"], motion["positions_mm"])


def render(setup: Setup, out: Path, *, scene: int, mode: str, spp: int, seed: int,
           f_number: float | None, diffraction: bool, sampler: str,
           scene_source: dict | None = None, motion: dict | None = None,
           setup_scene: dict | None = None) -> dict:
    """Render scene variation ``scene`` in ``mode`` into the EXR ``out`` (the render
    task).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup.
    out : Path
        The EXR written (image, AOVs, metadata).
    scene : int
        The scene's index (:func:`scene_setup` for the room).
    mode : {"pinhole", "focused", "sweep", "stopped"}
        The camera; the pinhole render also holds the depth and mask AOVs.
    spp : int
        Samples per pixel.
    seed : int
        The Monte Carlo seed.
    f_number : float or None
        The stopped mode's F-number (None for the other modes: the lens's).
    diffraction : bool
        Convolve the image with the lens's pixel-integrated Airy PSF at 550 nm, at the
        mode's F-number.
    sampler : str
        Mitsuba's sampler (:data:`mitsweep.render.api.MODE_SAMPLERS`).
    scene_source : dict, optional
        The scene, if not the room (:func:`scene_source`); a procedural scene is built
        again, an XML file refused if it changed since the plan.
    motion : dict, optional
        The sweep's tabulated profile, if not the setup's
        (:attr:`DatasetOptions.motion`); every mode is rendered on its reference grid,
        mid-travel.
    setup_scene : dict, optional
        The digests of the setup's own ``[scene] file`` (:func:`setup_scene_digests`),
        refused if its files now differ.

    Returns
    -------
    dict
        The renderer's timings (seconds), for the task's log.

    Raises
    ------
    DatasetError
        A scene file changed or missing since the plan.
    """
    from ..optics.diffraction import add_diffraction
    from ..render import render_image, render_to_exr
    from ..render.api import DEFAULT_STOPPED_F_NUMBER

    if setup_scene is not None and scene_source is None:
        if setup.scene.file is None:
            raise DatasetError("render: the task records the digests of the setup's "
                               "[scene] file, and the setup names none")
        _check_unchanged(setup.scene.file, setup_scene)
    s = scene_setup(setup, scene)
    aovs = ("depth", "mask") if mode == "pinhole" else ()
    kw: dict[str, Any] = {}
    if scene_source is not None:
        kw["scene"], kw["scene_unit"], kw["max_depth"] = _user_scene(setup, scene_source)
    result = render_image(s, mode, spp=spp, seed=seed, aovs=aovs, f_number=f_number,
                          sampler=sampler, motion=_motion(motion), **kw)
    timings = {k: result.metadata.pop(k) for k in _RENDER_TIMINGS if k in result.metadata}
    result.metadata["scene_index"] = scene
    if scene_source is not None:
        result.metadata["scene_source"] = scene_source
    if diffraction:
        # the F-number the image was rendered at (render_image's rule)
        n = (f_number or DEFAULT_STOPPED_F_NUMBER) if mode == "stopped" else s.lens.f_number
        result.image = add_diffraction(result.image, n, s.sensor.pixel_pitch)
        result.metadata["diffraction"] = {"f_number": n, "wavelength_nm": 550.0,
                                          "model": "pixel-integrated Airy PSF"}
    render_to_exr(out, result)
    return timings


def trace_bank(setup: Setup, out: Path, *, depths: list, rays: int | None, grid: list,
               seed: int, motion: dict | None = None) -> dict:
    """Trace the dataset's IPSF bank into ``out`` (the bank task): radial for a
    rotationally symmetric setup, else a grid.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup; its pixel pitch sizes the kernels
        (:func:`mitsweep.io.bank.bank_kernel_size`).
    out : Path
        The bank file written (``.npz``, reproducible bytes).
    depths : list of float
        Depths of the sources from the mirror, mm.
    rays : int or None
        Rays per IPSF (None or 0: the tracer's default).
    grid : list of int
        The grid bank's (rows, cols) (:func:`bank_grid`); unused for a radial bank.
    seed : int
        The tracer's seed.
    motion : dict, optional
        The sweep's tabulated profile, if not the setup's.

    Returns
    -------
    dict
        ``trace_s``: the tracing time, seconds (for the task's log).
    """
    from ..io.bank import bank_kernel_size, save_bank
    from ..tracer import TraceSettings, ipsf_bank

    kind = "radial" if setup.mirror.is_symmetric else "grid"
    trace: dict[str, Any] = {"seed": seed, "kernel_size": bank_kernel_size(setup.sensor.pixel_pitch)}
    if rays:
        trace["rays"] = rays
    kw: dict[str, Any] = {"kind": kind, "depths": tuple(depths),
                          "settings": TraceSettings(**trace)}
    if kind == "grid":
        kw["grid"] = tuple(grid)
    if motion is not None:
        kw["motion"] = _motion(motion)
    bank = ipsf_bank(setup, **kw)
    seconds = bank.metadata.pop("seconds", None)
    save_bank(out, bank, reproducible=True)
    return {"trace_s": seconds}


def add_noise(setup: Setup, out: Path, *, ground_truth: Path, image: Path, lux: float,
              f_number: float, iso: float, exposure_s: float, pixel_pitch: float,
              seed: list) -> dict:
    """The sensor noise of ``lux`` with these camera settings on ``image``, in relative
    exposure (the ground truth's white level); stored in the renders' units (the noisy
    relative exposure times ``white_level``, as the metadata's ``units`` says).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup (the task's signature; the noise does not depend on it).
    out : Path
        The noisy EXR written; its metadata records the noise model, its seed and the
        white level.
    ground_truth : Path
        The scene's pinhole render (its white level, :func:`white_level`).
    image : Path
        The noise-free render to add noise to.
    lux : float
        Scene illuminance, lux.
    f_number : float
        The exposure's F-number.
    iso : float
        ISO sensitivity.
    exposure_s : float
        Exposure time, s.
    pixel_pitch : float
        The noise model's pixel pitch, mm (:data:`NOISE_PIXEL_MM`).
    seed : list of int
        The noise generator's seed (``[dataset seed, scene, level]``).

    Returns
    -------
    dict
        Empty (no run information).
    """
    from ..deconv import SensorNoise

    gt, chans, _ = read_rgb(ground_truth)
    level = white_level(gt, chans.get("mask.Y"))
    img, _, meta = read_rgb(image)
    noise = SensorNoise(illuminance_lux=lux, exposure_s=exposure_s, f_number=f_number,
                        pixel_pitch=pixel_pitch, iso=iso)
    info: dict = {}
    noisy = noise.apply(np.maximum(img / level, 0.0).astype(np.float32),
                        np.random.default_rng(list(seed)), info=info)
    meta = dict(meta, noise=noise.as_dict(), noise_seed=list(seed), white_level=level,
                units=NOISY_UNITS, nsr=noise.nsr(0.5), **info)
    write_exr(out, noisy * level, metadata=meta)
    return {}


#: The dataset's rule for the restorations' weights (a restore task's ``weights``):
#: ``"calibrated"``, Wiener's NSR of least expected error from the image's noise model
#: and the bank's mismatch profile calibrated on the calibration scene
#: (:func:`mitsweep.deconv.weights.model_nsr` with ``mismatch=``; within 0.07 dB of the
#: oracle held out on the bundled setups: docs/guide/weights.md). The rules of earlier
#: manifests, which a task may still name: ``"model"``, the same without a profile, the
#: whole frame's spectrum; ``"mirror"``, that with the mirror's spectrum
#: (``spectrum="mirror"``); and ``"estimated"``, the first rule (max of the model's NSR
#: at exposure 0.5 and the image's variance-based estimate), which manifests whose
#: tasks record no ``weights`` ran.
WEIGHT_RULE = "calibrated"

#: Every weight rule a restore task takes.
WEIGHT_RULES = ("calibrated", "model", "mirror", "estimated")


def is_scene_item(name: str) -> bool:
    """Whether an item (``scene_000/sweep.exr``) lies in a dataset scene's folder, not
    the bank or the calibration scene.

    Parameters
    ----------
    name : str
        The item's name in the manifest.

    Returns
    -------
    bool
        True for ``scene_NNN/...``.
    """
    parts = name.split("/")
    return len(parts) == 2 and parts[0].startswith("scene_") and parts[0][6:].isdigit()


def calibration_profile(truth: Path, sweep: Path, bank: IPSFBank) -> MismatchProfile:
    """The bank's mismatch profile on a scene's pinhole render and noise-free sweep,
    for the dataset's restoration (Wiener, :data:`DECONV_PRIOR`;
    :func:`mitsweep.deconv.weights.calibrate_mismatch`), both divided by the scene's
    white level.

    Parameters
    ----------
    truth : Path
        The pinhole render, with its ``mask.Y`` AOV.
    sweep : Path
        The noise-free sweep render of the same scene.
    bank : IPSFBank
        The bank the restorations use.

    Returns
    -------
    mitsweep.deconv.weights.MismatchProfile
        The profile.

    Raises
    ------
    DatasetError
        The pinhole render has no ``mask.Y`` channel.
    """
    from ..deconv import deconvolve
    from ..deconv.weights import calibrate_mismatch

    gt, chans, _ = read_rgb(truth)
    if "mask.Y" not in chans:
        raise DatasetError(f"{truth}: no mask.Y channel (the mirror mask AOV)")
    level = white_level(gt, chans["mask.Y"])
    img = read_rgb(sweep)[0]

    def restore(im: np.ndarray, w: float) -> np.ndarray:
        return deconvolve(im, bank, method="wiener", weight=w, prior=DECONV_PRIOR)

    return calibrate_mismatch(img / level, gt / level, bank, mask=chans["mask.Y"] > 0.5,
                              restore=restore)


def calibrate_weights(setup: Setup, out: Path, *, truth: Path, sweep: Path,
                      bank: Path) -> dict:
    """Write the bank's mismatch profile, calibrated on the calibration scene (the
    calibration task; :func:`calibration_profile`).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup (the task's signature; the renders and bank hold it).
    out : Path
        The JSON written (:meth:`~mitsweep.deconv.weights.MismatchProfile.to_dict`).
    truth, sweep : Path
        The calibration scene's pinhole and noise-free sweep renders.
    bank : Path
        The dataset's IPSF bank.

    Returns
    -------
    dict
        ``calibrate_s``: the calibration's time, seconds (for the task's log).
    """
    from ..io.bank import load_bank

    t0 = time.perf_counter()
    calibration_profile(truth, sweep, load_bank(bank)).write(out)
    return {"calibrate_s": time.perf_counter() - t0}


def read_mismatch(path: str | Path | None) -> MismatchProfile:
    """A mismatch profile written by :func:`calibrate_weights`.

    Parameters
    ----------
    path : path
        The JSON file.

    Returns
    -------
    mitsweep.deconv.weights.MismatchProfile
        The profile.

    Raises
    ------
    DatasetError
        The file is missing, not JSON, or not a profile.
    """
    try:
        return MismatchProfile.read(Path(str(path)))
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{path}: not a readable mismatch profile ({exc})") from None


def restore(setup: Setup, out: Path, *, image: Path, bank: Path, method: str,
            nsr: float | None = None, noise: dict | None = None,
            ground_truth: Path | None = None, weights: str = "estimated",
            mismatch: Path | None = None) -> dict:
    """Deconvolve ``image`` with ``method`` and the weight ``weights`` says.

    ``weights="calibrated"`` (every task :func:`plan` makes): Wiener's NSR (and the NSR
    of the priors' first Wiener step) is :func:`mitsweep.deconv.weights.model_nsr` with
    the bank's mismatch profile (``mismatch``, :func:`calibrate_weights`' JSON): the NSR
    of least expected error with the noise variance of the image's sensor model (as
    below) and the profile's share of the image's own spectrum, read over the mirror's
    image, as the model's mismatch.

    ``weights="model"`` (the tasks of earlier manifests): Wiener's NSR (and the NSR of
    the priors' first Wiener step) is :func:`mitsweep.deconv.weights.model_nsr`: the
    NSR of least expected error for this image, with the noise variance of the sensor
    model the image carries (``noise``, ``SensorNoise.as_dict()`` as :func:`add_noise`
    records it, in relative exposure: at the image's mean exposure over the mirror)
    and, where larger, what blur and prior leave unexplained in it (the render's Monte
    Carlo noise, the bank's mismatch: GCV), over the mirror's image (the ``mask.Y`` AOV
    of ``ground_truth``, the pinhole render; the spectrum is the whole frame's). Without a
    noise model (a noise-free sweep) that second part is all there is. The losses
    against the oracle NSR are measured in docs/guide/weights.md.

    ``weights="mirror"``: the same with the spectrum read over the mirror's image
    (``model_nsr(..., spectrum="mirror")``).

    ``weights="estimated"``: the rule before that, for older manifests' tasks: NSR = max(
    ``nsr``, the image's variance-based estimate).

    The prior-based methods (RL, TV, hyper-Laplacian) get the noise model itself too
    (their σ is then at least the model's); the model is in relative exposure, so they
    restore the image divided by its recorded white level and the result is scaled
    back. ``noise`` must be the noise the image's metadata records.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The dataset's setup (the task's signature; the bank holds the optics).
    out : Path
        The EDOF EXR written; its metadata adds ``deconvolved_from``, ``bank``,
        ``method``, ``nsr`` and the weight rule's record.
    image : Path
        The sweep image to restore.
    bank : Path
        The IPSF bank.
    method : {"wiener", "rl", "tv", "hyperlaplacian"}
        The restoration method (:func:`mitsweep.deconv.deconvolve`).
    nsr : float, optional
        ``weights="estimated"`` only: the least NSR (the noise model's).
    noise : dict, optional
        The image's noise model, ``SensorNoise.as_dict()`` (None: a noise-free sweep).
    ground_truth : Path, optional
        The scene's pinhole render, whose ``mask.Y`` bounds the NSR's estimate
        (``weights`` other than ``"estimated"``; required for ``"calibrated"``).
    weights : {"calibrated", "model", "mirror", "estimated"}
        The weight rule (above, :data:`WEIGHT_RULES`); ``"estimated"`` is the default of
        the tasks of older manifests, which do not record it.
    mismatch : Path, optional
        The bank's mismatch profile (``weights="calibrated"`` only, where it is
        required).

    Returns
    -------
    dict
        ``deconvolve_s``: the restoration's time, seconds (for the task's log).

    Raises
    ------
    ValueError
        An unknown weight rule, ``noise`` with Wiener under the first rule, or
        ``weights="calibrated"`` without ``mismatch`` and ``ground_truth``.
    DatasetError
        The image's metadata does not record ``noise``.
    """
    from ..deconv import SensorNoise, deconvolve, estimate_nsr
    from ..io.bank import load_bank

    if weights not in WEIGHT_RULES:
        raise ValueError(f"restore: weights must be one of {', '.join(WEIGHT_RULES)}, "
                         f"got {weights!r}")
    if weights == "calibrated" and (mismatch is None or ground_truth is None):
        raise ValueError("restore: weights 'calibrated' needs the mismatch profile and "
                         "the ground truth (its mirror mask)")
    img, _, meta = read_rgb(image)
    if noise is not None and method == "wiener" and weights == "estimated":
        raise ValueError("restore: method 'wiener' takes its noise as nsr, not noise=")
    if noise is not None and (meta.get("noise") != noise or "white_level" not in meta):
        raise DatasetError(f"{Path(image).name}: its metadata does not record the noise "
                           f"model this restoration was planned with ({noise}); recorded: "
                           f"{meta.get('noise')}, white level {meta.get('white_level')}")
    ipsf = load_bank(bank)
    model = SensorNoise.from_dict(noise) if noise is not None else None
    level = np.float32(meta["white_level"]) if noise is not None else np.float32(1.0)
    record: dict[str, Any] = {}
    if weights != "estimated":
        from ..deconv.weights import model_nsr

        mask = None
        if ground_truth is not None:
            chans = read_rgb(ground_truth)[1]
            mask = chans["mask.Y"] > 0.5 if "mask.Y" in chans else None
        details: dict = {}
        kw_rule: dict[str, Any] = {"spectrum": "mirror" if weights == "mirror" else "frame"}
        if weights == "calibrated":
            kw_rule["mismatch"] = read_mismatch(mismatch)
            if mask is None:
                raise DatasetError(f"{ground_truth}: no mask.Y channel (the mirror mask "
                                   f"AOV), which the calibrated weight reads over")
        used = model_nsr(img, ipsf, model, mask=mask, level=float(level), details=details,
                         **kw_rule)
        record = {"nsr_rule": weights, "noise_variance": details["noise_variance"]}
    else:
        estimated = estimate_nsr(img)
        used = max(estimated, nsr) if nsr is not None else estimated
        record = {"nsr_model": nsr, "nsr_estimated": estimated}
    kw: dict[str, Any] = {"nsr": used}
    if method == "wiener":
        kw["prior"] = DECONV_PRIOR
    x = img.astype(np.float32)
    if model is not None and method != "wiener":
        kw["noise"], x = model, x / level
    t0 = time.perf_counter()
    restored = deconvolve(x, ipsf, method=method, **kw)
    if model is not None and method != "wiener":
        restored = restored * level
    seconds = time.perf_counter() - t0
    meta = dict(meta, deconvolved_from=Path(image).name, bank=Path(bank).name,
                method=method, nsr=used, **record)
    write_exr(out, restored, metadata=meta)
    return {"deconvolve_s": seconds}


# -- the plan ---------------------------------------------------------------------------

def edof_name(method: str, suffix: str = "") -> str:
    """The EDOF image's stem.

    Parameters
    ----------
    method : str
        The restoration method.
    suffix : str
        Appended, e.g. ``_50lux`` for the restoration of a noisy image.

    Returns
    -------
    str
        ``edof`` for Wiener (its evaluation key since the first datasets),
        ``edof_<method>`` for another method, then ``suffix``.
    """
    return ("edof" if method == "wiener" else f"edof_{method}") + suffix


def bank_grid(opts: DatasetOptions, setup: Setup | None) -> list[int]:
    """The grid bank's (rows, cols): ``opts.grid``, refined for a mirror whose image
    covers only part of the frame (a tilted one) so that
    :func:`mitsweep.deconv.spatial.mirror_grid_shape` nodes lie across it: a 9x9 grid
    over the frame puts 5 across the tilted paraboloid's image and loses ~1 dB. Unused
    (and unchanged) for a rotationally symmetric mirror's radial bank.

    Parameters
    ----------
    opts : DatasetOptions
        The dataset's options (its ``grid``).
    setup : mitsweep.config.Setup or None
        The dataset's setup (None: ``opts.grid`` as it is).

    Returns
    -------
    list of int
        ``[rows, cols]``, each at least ``opts.grid``'s.
    """
    grid = [int(g) for g in opts.grid]
    if setup is None or setup.mirror.is_symmetric:
        return grid
    from ..deconv.spatial import grid_bank_shape

    return list(grid_bank_shape(setup, (grid[0], grid[1])))


def plan(opts: DatasetOptions, setup: Setup | None = None) -> list[Task]:
    """Every task of a dataset, inputs first.

    Parameters
    ----------
    opts : DatasetOptions
        What the dataset holds.
    setup : mitsweep.config.Setup, optional
        The dataset's setup: it sizes a tilted mirror's grid bank (:func:`bank_grid`)
        and gives a room dataset its own scene file's digests
        (:func:`setup_scene_digests`). None names the items only (their names do not
        depend on it).

    Returns
    -------
    list of Task
        The bank and the calibration scene's tasks (shared, group None), then per scene
        (its index the shard group) the renders, the EDOF images, the noisy images and
        their restorations. Task names are the items' paths in the directory.
    """
    from ..deconv import paper_fig10_settings

    bank: dict[str, Any] = {"depths": list(opts.bank_depths), "rays": opts.bank_rays,
                            "grid": bank_grid(opts, setup), "seed": opts.seed}
    if opts.motion is not None:   # in the parameters only when set: older manifests hold
        bank["motion"] = opts.motion
    tasks = [Task(BANK, trace_bank, bank), *_calibration_tasks(opts, setup)]
    settings = [paper_fig10_settings(NOISE_PIXEL_MM, lux) for lux in opts.light_levels_lux]
    own_scene = setup_scene_digests(setup) if opts.family == "room" else None
    for i in range(opts.scenes):
        d = f"scene_{i:03d}"

        def add(name: str, fn, params: dict, inputs: dict | None = None) -> None:
            # called within this iteration only: d and i are the current scene's
            tasks.append(Task(f"{d}/{name}", fn, params, inputs or {}, group=i))  # noqa: B023

        source = scene_source(opts, i)
        for mode in MODES:
            add(f"{mode}.exr", render, _render_params(opts, i, mode, source, own_scene))
        for m in opts.methods:
            add(f"{edof_name(m)}.exr", restore, {"method": m, "weights": WEIGHT_RULE},
                {"image": f"{d}/sweep.exr", "bank": BANK, "ground_truth": f"{d}/pinhole.exr",
                 "mismatch": MISMATCH})
        for j, lux in enumerate(opts.light_levels_lux):
            for mode in ("sweep", "stopped"):
                s = settings[j][mode]
                add(f"{mode}_{lux:g}lux.exr", add_noise,
                    {"lux": lux, "f_number": s.f_number, "iso": s.iso,
                     "exposure_s": s.exposure_s, "pixel_pitch": NOISE_PIXEL_MM,
                     "seed": [opts.seed, i, j]},
                    {"ground_truth": f"{d}/pinhole.exr", "image": f"{d}/{mode}.exr"})
            for m in opts.methods:
                # every method gets the noise model itself (Wiener's NSR comes from it);
                # in their parameters, so a dataset restored under another rule is redone
                params = {"method": m, "noise": settings[j]["sweep"].as_dict(),
                          "weights": WEIGHT_RULE}
                add(f"{edof_name(m, f'_{lux:g}lux')}.exr", restore, params,
                    {"image": f"{d}/sweep_{lux:g}lux.exr", "bank": BANK,
                     "ground_truth": f"{d}/pinhole.exr", "mismatch": MISMATCH})
    return tasks


def _render_params(opts: DatasetOptions, index: int, mode: str, source: dict | None,
                   own_scene: dict | None) -> dict:
    """A render task's parameters: scene ``index`` (made of ``source``,
    :func:`scene_source`) in ``mode``, Monte Carlo seed ``seed + index`` (32-bit)."""
    params = {"scene": index, "mode": mode, "spp": opts.spp[mode],
              "seed": (opts.seed + index) % (MAX_SEED + 1),
              "f_number": opts.stopped_f_number if mode == "stopped" else None,
              "diffraction": opts.diffraction and mode != "pinhole",
              "sampler": MODE_SAMPLERS[mode]}
    if source is not None:
        params["scene_source"] = source
    if opts.motion is not None:
        params["motion"] = opts.motion
    if source is None and own_scene is not None:
        params["setup_scene"] = own_scene
    return params


def _calibration_tasks(opts: DatasetOptions, setup: Setup | None) -> list[Task]:
    """The calibration scene's pinhole and noise-free sweep renders and the bank's
    mismatch profile on them (shared tasks, group None)."""
    index = CALIBRATION_SCENE
    source = scene_source(opts, index) if opts.family == "procedural" else None
    own_scene = setup_scene_digests(setup)
    renders = [Task(f"{CALIBRATION_DIR}/{mode}.exr", render,
                    _render_params(opts, index, mode, source, own_scene))
               for mode in ("pinhole", "sweep")]
    return renders + [Task(MISMATCH, calibrate_weights, {},
                           {"truth": renders[0].name, "sweep": renders[1].name, "bank": BANK})]


def item_names(opts: DatasetOptions) -> list[str]:
    """The items of a dataset.

    Parameters
    ----------
    opts : DatasetOptions
        What the dataset holds.

    Returns
    -------
    list of str
        The items' paths relative to the dataset directory, in the plan's order.
    """
    return [t.name for t in plan(opts)]
