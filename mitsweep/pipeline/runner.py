"""Synthetic datasets and their evaluation: the paper's pipeline end to end.

For a setup, :func:`build_dataset` renders per scene variation the pinhole ground truth
(with the depth and mirror-mask AOVs), the ``focused``, ``sweep`` and ``stopped``
images, traces the IPSF bank once, makes noisy versions at chosen light levels (the
paper's Fig. 10 settings: sweep F2.8 0.6 s ISO 100, stopped F11 0.6 s ISO 1600), and
deconvolves the sweep images into EDOF images. :func:`evaluate_dataset` scores EDOF,
focused and stopped images against the ground truth inside the mirror's image: PSNR and
SSIM overall, per radius and per depth band.

Files are written atomically; ``manifest.json`` records every finished item with its
parameters and SHA-256, so a rerun skips what is complete and valid and redoes the rest.
A run holds an advisory lock on its directory (``.mitsweep.lock``): a second run on the
same directory is refused, or waits. A manifest is validated whenever it is read
(:func:`validate_manifest`), by ``dataset`` and ``evaluate`` alike.
Independent tasks run through a pluggable executor (``serial`` or local ``process``es).

Diffraction: the renders are geometric; the thin-lens images (focused, sweep, stopped)
are convolved with the lens's pixel-integrated Airy PSF at 550 nm (``diffraction=True``),
which is what the paper holds against stopping down. The ground truth stays ideal.

Radiometry: renders are linear radiance. Relative exposure 1.0 (the noise model's
reference level, reflectance ``SensorNoise.reflectance`` under the scene illuminance) is
the 99th percentile of the ground truth inside the mirror's image; all images of a scene
are divided by that same level before noise and metrics (data range 1).
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import json
import logging
import math
import multiprocessing
import numbers
import time
from dataclasses import dataclass, field, fields
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any, Callable

import numpy as np

from .config import Setup, setup_from_dict, setup_to_dict
from .io import WriteError, read_exr, write_exr, write_text_atomic
from .io.exr import stack_channels
from .optics.pixels import optical_center_px
from .render.api import MODES  # the camera modes; render imports Mitsuba only when rendering

__all__ = ["DatasetOptions", "options_from_dict", "build_dataset", "evaluate_dataset",
           "load_manifest", "validate_manifest", "item_names", "dataset_inputs", "MANIFEST",
           "MAX_SCENES", "DatasetError"]

logger = logging.getLogger(__name__)

MANIFEST = "manifest.json"
FORMAT = "mitsweep-dataset/1"
WHITE_PERCENTILE = 99.0
#: Pixel of the camera whose noise the noisy images carry, mm: a DSLR of the paper's
#: era (6.4 µm, whose ~60 000 e⁻ full well is the noise model's default). The renders
#: use larger synthetic pixels so that the mirror's image fits a small frame; each
#: rendered pixel gets the noise of one such camera pixel (not of an 18 µm pixel, which
#: would collect 8× the light and saturate the modelled full well).
NOISE_PIXEL_MM = 0.0064
#: Wiener prior of the EDOF images (see :func:`_task_deconvolve`).
DECONV_PRIOR = "natural"


class DatasetError(ValueError):
    """A dataset directory is missing, inconsistent, or was made for another setup."""


#: Most scene variations a dataset may hold (``DatasetOptions.scenes``); a manifest that
#: claims more is refused before any work starts.
MAX_SCENES = 10_000
#: Most light levels and bank depths a dataset may hold.
MAX_LIGHT_LEVELS = 32
MAX_BANK_DEPTHS = 64
#: Mitsuba's sampler seeds are 32-bit: scene i renders with seed + i.
MAX_SEED = 2**32 - 1


def _is_int(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _is_real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool)


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise DatasetError(f"{key}: {message}")


def _positive_reals(values: Any, key: str, lo_count: int, hi_count: int) -> tuple[float, ...]:
    _require(isinstance(values, (list, tuple)) and lo_count <= len(values) <= hi_count, key,
             f"must be a list of {lo_count} to {hi_count} numbers, got {values!r}")
    for v in values:
        _require(_is_real(v) and math.isfinite(v) and v > 0, key,
                 f"every value must be a finite number > 0, got {v!r}")
    return tuple(float(v) for v in values)


@dataclass(frozen=True, kw_only=True)
class DatasetOptions:
    """What a dataset holds. Seeds: scene i renders with ``seed + i`` (texture layout
    ``scene.texture_seed + i``); noise of scene i at level j uses ``(seed, i, j)``.

    Every field is validated here, for the command line and for a manifest read back
    alike (:func:`options_from_dict`): ``scenes`` in [1, ``MAX_SCENES``], ``seed`` >= 0
    with ``seed + scenes - 1`` <= ``MAX_SEED``, ``spp`` a positive integer per mode,
    light levels (at most ``MAX_LIGHT_LEVELS``, distinct as file names) and bank depths
    (1 to ``MAX_BANK_DEPTHS``) finite and > 0.
    """

    scenes: int = 1
    seed: int = 0
    spp: dict = field(default_factory=lambda: {"pinhole": 16, "focused": 64, "sweep": 128,
                                               "stopped": 64})
    light_levels_lux: tuple[float, ...] = (50.0, 2.0, 0.5)
    bank_depths_mm: tuple[float, ...] = (500.0,)
    bank_rays: int | None = None
    grid: tuple[int, int] = (9, 9)
    stopped_f_number: float = 11.0
    diffraction: bool = True

    def __post_init__(self) -> None:
        _require(_is_int(self.scenes) and 1 <= self.scenes <= MAX_SCENES, "scenes",
                 f"must be an integer in [1, {MAX_SCENES}], got {self.scenes!r}")
        _require(_is_int(self.seed) and 0 <= self.seed <= MAX_SEED - (self.scenes - 1), "seed",
                 f"must be an integer in [0, {MAX_SEED - (self.scenes - 1)}] (scene i uses "
                 f"seed + i, a 32-bit seed), got {self.seed!r}")
        _require(isinstance(self.spp, dict) and set(self.spp) == set(MODES), "spp",
                 f"must give samples per pixel for exactly {', '.join(MODES)}, got "
                 f"{self.spp!r}")
        for mode in MODES:
            v = self.spp[mode]
            _require(_is_int(v) and v > 0, f"spp[{mode!r}]",
                     f"must be a positive integer, got {v!r}")
        lux = _positive_reals(self.light_levels_lux, "light_levels_lux", 0, MAX_LIGHT_LEVELS)
        names = [f"{x:g}" for x in lux]
        _require(len(set(names)) == len(names), "light_levels_lux",
                 f"levels must differ (as file names: {', '.join(names)})")
        depths = _positive_reals(self.bank_depths_mm, "bank_depths_mm", 1, MAX_BANK_DEPTHS)
        _require(self.bank_rays is None or (_is_int(self.bank_rays) and self.bank_rays > 0),
                 "bank_rays", f"must be a positive integer or null, got {self.bank_rays!r}")
        _require(isinstance(self.grid, (list, tuple)) and len(self.grid) == 2
                 and all(_is_int(g) and 1 <= g <= 256 for g in self.grid), "grid",
                 f"must be two integers in [1, 256], got {self.grid!r}")
        _require(_is_real(self.stopped_f_number) and math.isfinite(self.stopped_f_number)
                 and self.stopped_f_number > 0, "stopped_f_number",
                 f"must be a finite number > 0, got {self.stopped_f_number!r}")
        _require(isinstance(self.diffraction, bool), "diffraction",
                 f"must be true or false, got {self.diffraction!r}")
        object.__setattr__(self, "spp", {m: int(self.spp[m]) for m in MODES})
        object.__setattr__(self, "light_levels_lux", lux)
        object.__setattr__(self, "bank_depths_mm", depths)
        object.__setattr__(self, "grid", tuple(int(g) for g in self.grid))

    def as_dict(self) -> dict:
        return {"scenes": self.scenes, "seed": self.seed, "spp": dict(self.spp),
                "light_levels_lux": list(self.light_levels_lux),
                "bank_depths_mm": list(self.bank_depths_mm), "bank_rays": self.bank_rays,
                "grid": list(self.grid), "stopped_f_number": self.stopped_f_number,
                "diffraction": self.diffraction}


def options_from_dict(d: Any) -> DatasetOptions:
    """:class:`DatasetOptions` from a manifest's ``options`` (the keys of
    :meth:`DatasetOptions.as_dict`, all required, no others); raises
    :class:`DatasetError` naming the field."""
    names = [f.name for f in fields(DatasetOptions)]
    _require(isinstance(d, dict), "options", f"must be an object, got {type(d).__name__}")
    unknown = sorted(set(d) - set(names))
    missing = [k for k in names if k not in d]
    _require(not unknown, "options", f"unknown keys {unknown}")
    _require(not missing, "options", f"missing keys {missing}")
    try:
        return DatasetOptions(**d)
    except DatasetError as exc:
        raise DatasetError(f"options.{exc}") from None


# -- tasks (top-level functions: picklable for process executors) ---------------------

def _scene_setup(setup_dict: dict, index: int) -> Setup:
    from dataclasses import replace

    setup = setup_from_dict(setup_dict)
    return replace(setup, scene=replace(setup.scene,
                                        texture_seed=setup.scene.texture_seed + index))


def add_diffraction(image: np.ndarray, f_number: float, pixel_pitch: float) -> np.ndarray:
    """Convolve a geometric render (H, W[, C]) with the lens's pixel-integrated Airy PSF."""
    from scipy.signal import fftconvolve

    from .optics.diffraction import airy_kernel

    k = airy_kernel(f_number, pixel_pitch)
    if k.shape[0] == 1:
        return image
    img = np.asarray(image)
    chans = img[..., None] if img.ndim == 2 else img
    out = np.stack([fftconvolve(chans[..., c], k, mode="same") for c in range(chans.shape[2])],
                   axis=-1).astype(img.dtype)
    return out[..., 0] if img.ndim == 2 else out


def _task_render(setup_dict: dict, index: int, mode: str, spp: int, seed: int,
                 f_number: float, path: str, diffraction: bool = True) -> str:
    from .render import render_image, render_to_exr

    setup = _scene_setup(setup_dict, index)
    aovs = ("depth", "mask") if mode == "pinhole" else ()
    result = render_image(setup, mode, spp=spp, seed=seed, aovs=aovs,
                          f_number=f_number if mode == "stopped" else None)
    result.metadata["scene_index"] = index
    if diffraction and mode != "pinhole":  # the ground truth stays ideal
        n = f_number if mode == "stopped" else setup.lens.f_number
        result.image = add_diffraction(result.image, n, setup.sensor.pixel_pitch)
        result.metadata["diffraction"] = {"f_number": n, "wavelength_nm": 550.0,
                                          "model": "pixel-integrated Airy PSF"}
    render_to_exr(path, result)
    return path


def bank_kernel_size(pixel_pitch: float) -> int:
    """Kernel size (odd, px) holding the IPSFs of the paper's sweeps: 31 px at the demo's
    18 µm pixels (the largest peripheral IPSF spans ~0.5 mm on the sensor), scaled
    inversely with the pitch so finer pixels do not truncate the kernels."""
    half = int(math.ceil(15 * 0.018 / pixel_pitch))
    return 2 * max(half, 15) + 1


def _task_bank(setup_dict: dict, depths, rays, grid, seed: int, path: str) -> str:
    from .io.bank import save_bank
    from .tracer import ipsf_bank

    setup = setup_from_dict(setup_dict)
    kind = "radial" if setup.mirror.is_symmetric else "grid"
    kw: dict[str, Any] = {"kind": kind, "depths": tuple(depths), "seed": seed,
                          "kernel_size": bank_kernel_size(setup.sensor.pixel_pitch)}
    if rays:
        kw["rays"] = rays
    if kind == "grid":
        kw["grid"] = tuple(grid)
    save_bank(path, ipsf_bank(setup, **kw))
    return path


def _read_rgb(path) -> tuple[np.ndarray, dict, dict]:
    chans, meta = read_exr(path)
    return stack_channels(chans), chans, meta


def white_level(pinhole: np.ndarray, mask: np.ndarray) -> float:
    """Relative exposure 1.0: the 99th percentile of the ground truth in the mask."""
    values = pinhole[mask > 0] if mask is not None and np.any(mask > 0) else pinhole
    level = float(np.percentile(values, WHITE_PERCENTILE))
    if not level > 0:
        raise DatasetError("the ground-truth image is black inside the mirror: nothing to "
                           "normalise by (check the scene's lighting)")
    return level


def _task_noisy(pinhole_path: str, image_path: str, lux: float, f_number: float, iso: float,
                exposure_s: float, pixel_pitch: float, seed: tuple, path: str) -> str:
    from .deconv import SensorNoise

    gt, chans, _ = _read_rgb(pinhole_path)
    level = white_level(gt, chans.get("mask.Y"))
    img, _, meta = _read_rgb(image_path)
    noise = SensorNoise(illuminance_lux=lux, exposure_s=exposure_s, f_number=f_number,
                        pixel_pitch=pixel_pitch, iso=iso)
    info: dict = {}
    noisy = noise.apply(np.maximum(img / level, 0.0).astype(np.float32),
                        np.random.default_rng(list(seed)), info=info)
    meta = dict(meta, noise=noise.as_dict(), noise_seed=list(seed), white_level=level,
                units="relative exposure", nsr=noise.nsr(0.5), **info)
    write_exr(path, noisy * level, metadata=meta)  # stored in the renders' units
    return path


def _task_deconvolve(image_path: str, bank_path: str, nsr: float | None, path: str) -> str:
    """Deconvolve with NSR = max(the noise model's, the image's own estimate).

    The noise model's NSR (``nsr``) covers sensor noise only; Monte Carlo noise of the
    render and the residual mismatch between the bank and the image are not in it, and a
    Wiener filter regularised below them amplifies them without bound (measured: 50-lux
    EDOF at the model's NSR 5e-5 lost 9 dB against the un-deconvolved sweep). The image's
    estimate assumes a white signal spectrum, so it goes with the natural-image (1/f²)
    prior: on the demo's sphere that pair came within 0.1 dB of the best hand-tuned
    constant NSR at 50 and 2 lux and beat it at 0.5 and 0.1 lux (README).
    """
    from .deconv import deconvolve, estimate_nsr
    from .io.bank import load_bank

    img, _, meta = _read_rgb(image_path)
    bank = load_bank(bank_path)
    estimated = estimate_nsr(img)
    used = max(estimated, nsr) if nsr is not None else estimated
    t0 = time.perf_counter()
    out = deconvolve(img.astype(np.float32), bank, nsr=used, prior=DECONV_PRIOR)
    meta = dict(meta, deconvolved_from=Path(image_path).name, bank=Path(bank_path).name,
                nsr=used, nsr_model=nsr, nsr_estimated=estimated,
                deconvolve_s=time.perf_counter() - t0)
    write_exr(path, out, metadata=meta)
    return path


# -- manifest ---------------------------------------------------------------------------

def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_manifest(directory: str | Path) -> dict:
    """Read and validate ``directory/manifest.json`` (see :func:`validate_manifest`)."""
    p = Path(directory) / MANIFEST
    if not p.is_file():
        raise DatasetError(f"{directory}: no {MANIFEST} (not a mitsweep dataset)")
    try:
        manifest = json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{p}: corrupt manifest ({exc})") from None
    try:
        validate_manifest(manifest, directory)
    except DatasetError as exc:
        raise DatasetError(f"{p}: invalid manifest: {exc}") from None
    return manifest


def validate_manifest(manifest: Any, directory: str | Path) -> DatasetOptions:
    """Check a manifest's schema before anything trusts it; return its options.

    The top level is an object with ``format`` (``mitsweep-dataset/1``), ``setup`` (an
    object), ``options`` (validated as :class:`DatasetOptions`, the limits of the
    command line) and ``items``: an object whose keys are items of a dataset with those
    options (relative paths such as ``scene_000/sweep.exr``, never absolute, never with
    ``..``, never resolving outside ``directory`` through a symlink) and whose values
    hold ``params`` (object), ``sha256`` (64 hex digits), ``bytes`` (integer >= 0) and
    ``seconds`` (number >= 0). ``complete``, when present, is ``true`` and then every
    item of the dataset is listed. Raises :class:`DatasetError` naming the field.
    """
    _require(isinstance(manifest, dict), "top level",
             f"must be a JSON object, got {type(manifest).__name__}")
    _require(manifest.get("format") == FORMAT, "format",
             f"must be {FORMAT!r}, got {manifest.get('format')!r}")
    _require(isinstance(manifest.get("setup"), dict), "setup",
             f"must be an object, got {type(manifest.get('setup')).__name__}")
    opts = options_from_dict(manifest.get("options"))
    items = manifest.get("items")
    _require(isinstance(items, dict), "items", f"must be an object, got {type(items).__name__}")
    root = Path(directory).resolve()
    expected = set(item_names(opts))
    for name, item in items.items():
        key = f"items[{name!r}]"
        posix = PurePosixPath(name)
        _require(name != "" and not posix.is_absolute() and "\\" not in name
                 and not PureWindowsPath(name).drive, key, "must be a relative path")
        _require(".." not in posix.parts, key, "must stay inside the dataset directory")
        _require(name in expected, key, f"is not an item of a dataset with these options "
                                        f"({opts.scenes} scenes)")
        _require((root / name).resolve().is_relative_to(root), key,
                 "resolves outside the dataset directory (symlink)")
        _require(isinstance(item, dict), key, f"must be an object, got {type(item).__name__}")
        _require(isinstance(item.get("params"), dict), f"{key}.params", "must be an object")
        sha = item.get("sha256")
        _require(isinstance(sha, str) and len(sha) == 64
                 and all(c in "0123456789abcdef" for c in sha), f"{key}.sha256",
                 f"must be 64 lowercase hex digits, got {sha!r}")
        _require(_is_int(item.get("bytes")) and item["bytes"] >= 0, f"{key}.bytes",
                 f"must be an integer >= 0, got {item.get('bytes')!r}")
        _require(_is_real(item.get("seconds")) and math.isfinite(item["seconds"])
                 and item["seconds"] >= 0, f"{key}.seconds",
                 f"must be a finite number >= 0, got {item.get('seconds')!r}")
    if "complete" in manifest:
        _require(manifest["complete"] is True, "complete",
                 f"must be true when present, got {manifest['complete']!r}")
        missing = sorted(expected - set(items))
        if missing:
            more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
            raise DatasetError(f"items: a complete dataset lists every item; missing "
                               f"{missing[0]}{more}")
    return opts


def _versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for pkg in ("mitsweep", "mitsuba", "drjit", "numpy", "scipy", "scikit-image", "OpenEXR"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = None
    return out


@dataclass
class _Task:
    name: str            # relative output path
    fn: Callable
    args: tuple
    params: dict
    deps: tuple = ()


def _plan(sd: dict, opts: DatasetOptions, root: Path) -> list[_Task]:
    """Every task of a dataset of setup ``sd`` (a setup dict) with ``opts``, in
    dependency order; task names are the items' paths relative to ``root``."""
    from .deconv import paper_fig10_settings

    tasks = [_Task("bank.npz", _task_bank,
                   (sd, opts.bank_depths_mm, opts.bank_rays, opts.grid, opts.seed,
                    str(root / "bank.npz")),
                   {"depths": list(opts.bank_depths_mm), "rays": opts.bank_rays,
                    "grid": list(opts.grid), "seed": opts.seed})]
    pitch = NOISE_PIXEL_MM
    settings = [paper_fig10_settings(pitch, lux) for lux in opts.light_levels_lux]
    for i in range(opts.scenes):
        d = f"scene_{i:03d}"
        seed = opts.seed + i
        for mode in MODES:
            tasks.append(_Task(f"{d}/{mode}.exr", _task_render,
                               (sd, i, mode, opts.spp[mode], seed, opts.stopped_f_number,
                                str(root / d / f"{mode}.exr"), opts.diffraction),
                               {"mode": mode, "spp": opts.spp[mode], "seed": seed,
                                "f_number": opts.stopped_f_number if mode == "stopped" else None,
                                "diffraction": opts.diffraction and mode != "pinhole"}))
        tasks.append(_Task(f"{d}/edof.exr", _task_deconvolve,
                           (str(root / d / "sweep.exr"), str(root / "bank.npz"), None,
                            str(root / d / "edof.exr")),
                           {"nsr": None, "prior": DECONV_PRIOR},
                           deps=(f"{d}/sweep.exr", "bank.npz")))
        for j, lux in enumerate(opts.light_levels_lux):
            for mode in ("sweep", "stopped"):
                s = settings[j][mode]
                name = f"{d}/{mode}_{lux:g}lux.exr"
                tasks.append(_Task(name, _task_noisy,
                                   (str(root / d / "pinhole.exr"), str(root / d / f"{mode}.exr"),
                                    lux, s.f_number, s.iso, s.exposure_s, pitch, (opts.seed, i, j),
                                    str(root / name)),
                                   {"lux": lux, "f_number": s.f_number, "iso": s.iso,
                                    "exposure_s": s.exposure_s, "seed": [opts.seed, i, j]},
                                   deps=(f"{d}/pinhole.exr", f"{d}/{mode}.exr")))
            nsr = settings[j]["sweep"].nsr(0.5)
            tasks.append(_Task(f"{d}/edof_{lux:g}lux.exr", _task_deconvolve,
                               (str(root / d / f"sweep_{lux:g}lux.exr"), str(root / "bank.npz"),
                                nsr, str(root / d / f"edof_{lux:g}lux.exr")),
                               {"nsr": nsr, "prior": DECONV_PRIOR},
                               deps=(f"{d}/sweep_{lux:g}lux.exr", "bank.npz")))
    return tasks


def item_names(opts: DatasetOptions) -> list[str]:
    """The items (paths relative to the dataset directory) of a dataset with ``opts``."""
    return [t.name for t in _plan({}, opts, Path("."))]


def _run_task(fn: Callable, args: tuple, path: str) -> tuple[str, int]:
    """Run one task and checksum its output where it was written (in the worker): the
    SHA-256 and size recorded in the manifest are those of the file as written."""
    fn(*args)
    p = Path(path)
    return _sha256(p), p.stat().st_size


def build_dataset(setup: Setup, out_dir: str | Path, options: DatasetOptions | None = None, *,
                  executor: str = "serial", jobs: int = 2, progress: bool = True,
                  wait: float | None = None) -> dict:
    """Render, trace, add noise and deconvolve a synthetic dataset (resumable).

    Parameters
    ----------
    setup : Setup
    out_dir : path
        Created if needed. A directory holding a manifest for another setup is refused.
    options : DatasetOptions
    executor : {"serial", "process"}
        Run independent tasks in this process, or in ``jobs`` local processes.
    progress : bool
        A tqdm bar on stderr.
    wait : float or None
        The directory is locked for the run (:class:`~mitsweep.io.lock.DirectoryLock`):
        another run on it is refused at once (``None``) or after waiting this many
        seconds for it (``math.inf``: for ever).

    Returns
    -------
    dict
        The manifest (also written to ``out_dir/manifest.json``): ``complete`` only once
        every item's file matches the SHA-256 recorded when it was written.
    """
    from .io.lock import DirectoryLock

    if executor not in ("serial", "process"):
        raise DatasetError(f"executor: must be 'serial' or 'process', got {executor!r}")
    if not (isinstance(jobs, int) and jobs >= 1):
        raise DatasetError(f"jobs: must be a positive integer, got {jobs!r}")
    if wait is not None and not (wait >= 0):
        raise DatasetError(f"wait: must be >= 0 seconds, got {wait!r}")
    opts = options or DatasetOptions()
    root = Path(out_dir)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DatasetError(f"{root}: cannot create the dataset directory ({exc.strerror})") from None
    with DirectoryLock(root, wait=wait):  # before anything is written into the directory
        return _build_locked(setup, root, opts, executor, jobs, progress)


def _build_locked(setup: Setup, root: Path, opts: DatasetOptions, executor: str, jobs: int,
                  progress: bool) -> dict:
    sd = setup_to_dict(setup)
    tasks = _plan(sd, opts, root)
    by_name = {t.name: t for t in tasks}
    manifest = {"format": FORMAT, "setup": sd, "options": opts.as_dict(),
                "versions": _versions(), "items": {}}
    if (root / MANIFEST).is_file():
        old = load_manifest(root)
        if old["setup"] != sd:
            raise DatasetError(f"{root}: holds a dataset of another setup "
                               f"({old['setup'].get('name')!r}); use a new directory")
        # Items of other options (fewer scenes, other light levels) are not ours to keep.
        manifest["items"] = {k: v for k, v in old["items"].items() if k in by_name}
    for i in range(opts.scenes):
        scene_dir = root / f"scene_{i:03d}"
        try:
            scene_dir.mkdir(exist_ok=True)
        except OSError as exc:
            raise WriteError(exc.errno, exc.strerror, str(scene_dir)) from None

    def is_done(t: _Task) -> bool:
        item = manifest["items"].get(t.name)
        p = root / t.name
        return (item is not None and item.get("params") == _jsonable(t.params) and p.is_file()
                and item.get("sha256") == _sha256(p))

    todo = [t for t in tasks if not is_done(t)]
    skipped = len(tasks) - len(todo)
    if skipped:
        logger.info("resuming: %d of %d items already complete", skipped, len(tasks))
    for t in todo:  # invalid or stale entries must not survive a crash mid-run
        manifest["items"].pop(t.name, None)
    _write_manifest(root, manifest)

    bar = _progress(len(todo), progress)
    done_names = {t.name for t in tasks} - {t.name for t in todo}
    pending = list(todo)
    pool = None
    if executor == "process":
        pool = cf.ProcessPoolExecutor(max_workers=jobs,
                                      mp_context=multiprocessing.get_context("spawn"))
    try:
        while pending:
            ready = [t for t in pending if all(d in done_names for d in t.deps)]
            if not ready:
                raise DatasetError("dataset tasks have unmet dependencies: "
                                   + ", ".join(t.name for t in pending))
            t0 = time.perf_counter()
            if pool is None:
                for t in ready:
                    sha, size = _run_task(t.fn, t.args, str(root / t.name))
                    _record(root, manifest, t, sha, size, time.perf_counter() - t0)
                    bar.update(1)
                    done_names.add(t.name)
                    t0 = time.perf_counter()
            else:
                futures = {pool.submit(_run_task, t.fn, t.args, str(root / t.name)): t
                           for t in ready}
                for fut in cf.as_completed(futures):
                    t = futures[fut]
                    sha, size = fut.result()
                    _record(root, manifest, t, sha, size, time.perf_counter() - t0)
                    bar.update(1)
                    done_names.add(t.name)
            pending = [t for t in pending if t.name not in done_names]
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    _verify_items(root, manifest, tasks)
    manifest["complete"] = True
    _write_manifest(root, manifest)
    return manifest


def _verify_items(root: Path, manifest: dict, tasks: list[_Task]) -> None:
    """Every item's file still matches its recorded SHA-256, or the dataset is not
    complete: a mismatching item is dropped from the manifest (a rerun redoes it)."""
    bad = [t.name for t in tasks if not (root / t.name).is_file()
           or _sha256(root / t.name) != manifest["items"][t.name]["sha256"]]
    if bad:
        for name in bad:
            manifest["items"].pop(name, None)
        _write_manifest(root, manifest)
        raise DatasetError(f"{root / bad[0]}: changed after it was written (its SHA-256 no "
                           f"longer matches the manifest"
                           + (f"; {len(bad) - 1} more items too" if len(bad) > 1 else "")
                           + "); rerun `mitsweep dataset` to redo it")


def _jsonable(obj):
    return json.loads(json.dumps(obj, default=str))


def _record(root: Path, manifest: dict, task: _Task, sha256: str, size: int,
            seconds: float) -> None:
    manifest["items"][task.name] = {"params": _jsonable(task.params), "sha256": sha256,
                                    "bytes": size, "seconds": round(seconds, 3)}
    _write_manifest(root, manifest)


def _write_manifest(root: Path, manifest: dict) -> None:
    write_text_atomic(root / MANIFEST, json.dumps(manifest, indent=1, default=str) + "\n")


class _NoBar:
    def update(self, n=1):
        pass

    def close(self):
        pass


def _progress(total: int, enabled: bool):
    if not enabled or total == 0:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc="dataset", unit="item", leave=False)


# -- evaluation -------------------------------------------------------------------------

DEPTH_BANDS_MM = (0.0, 300.0, 1000.0, 3000.0, math.inf)


def _checked_items(root: Path, manifest: dict) -> dict[str, Path]:
    """The items of a complete dataset, each file present and unchanged since written."""
    if manifest.get("complete") is not True:
        raise DatasetError(f"{root}: incomplete dataset (rerun `mitsweep dataset` with the "
                           f"same options to finish it)")
    files = {}
    for name, item in sorted(manifest["items"].items()):
        p = root / name
        if not p.is_file():
            raise DatasetError(f"{p}: listed in the manifest but missing (rerun `mitsweep "
                               f"dataset` to redo it)")
        if p.stat().st_size != item["bytes"] or _sha256(p) != item["sha256"]:
            raise DatasetError(f"{p}: changed since it was written (size or SHA-256 differs "
                               f"from the manifest; rerun `mitsweep dataset` to redo it)")
        files[name] = p
    return files


def _read_finite(path: Path) -> tuple[np.ndarray, dict, dict]:
    img, chans, meta = _read_rgb(path)
    for name, arr in {"image": img, **chans}.items():
        if not np.all(np.isfinite(arr)):
            raise DatasetError(f"{path}: holds NaN or inf pixels (channel {name}); cannot "
                               f"score it (rerun `mitsweep dataset` to redo it)")
    return img, chans, meta


def dataset_inputs(directory: str | Path) -> list[Path]:
    """Every file of a dataset that evaluating it reads: the manifest and the items (for
    :func:`~mitsweep.cli.common.check_outputs`)."""
    root = Path(directory)
    manifest = load_manifest(root)
    return [root / MANIFEST] + [root / name for name in manifest["items"]]


def evaluate_dataset(directory: str | Path, *, n_radial_bins: int = 8) -> dict:
    """Score EDOF against focused and stopped images, on the ground truth.

    Returns per scene and averaged: PSNR (dB) and SSIM inside the mirror's image, per
    radial bin (pixels from the optical axis) and per depth band (mm), for ``edof``,
    ``focused``, ``stopped``, ``sweep`` (not deconvolved) and the noisy variants.

    The manifest is validated (:func:`load_manifest`); the dataset must be complete,
    with every item's file present and unchanged, and every image finite.
    """
    from .deconv import per_depth_band, per_radius, psnr, ssim

    root = Path(directory)
    manifest = load_manifest(root)
    files = _checked_items(root, manifest)
    n_scenes = manifest["options"]["scenes"]
    results: dict[str, Any] = {"dataset": str(root), "scenes": {}}
    for i in range(n_scenes):
        d = root / f"scene_{i:03d}"
        gt, chans, _ = _read_finite(d / "pinhole.exr")
        mask = chans.get("mask.Y")
        if mask is None:
            raise DatasetError(f"{d}/pinhole.exr: no mask.Y channel (mirror mask AOV)")
        m = mask > 0.5
        if not np.any(m):
            raise DatasetError(f"{d}/pinhole.exr: the mirror mask is empty (nothing to score)")
        depth = chans.get("depth.Z", np.full(mask.shape, np.nan, dtype=np.float32))
        depth = np.where(m & (depth > 0), depth, np.nan)
        level = white_level(gt, mask)
        ref = gt / level
        ys, xs = np.nonzero(m)
        cy, cx = optical_center_px(m.shape)
        r_max = float(np.max(np.hypot(ys - cy, xs - cx))) + 0.5
        edges = np.linspace(0.0, r_max, n_radial_bins + 1)
        scene_res: dict[str, Any] = {"white_level": level, "mirror_radius_px": r_max}
        for name, path in files.items():
            if not name.startswith(f"{d.name}/") or path.suffix != ".exr" \
                    or path.stem == "pinhole":
                continue
            img = _read_finite(path)[0] / level
            if img.shape != ref.shape:
                raise DatasetError(f"{path}: shape {img.shape} differs from the ground "
                                   f"truth's {ref.shape}")
            # An image leaves the mirror's disc alone outside the mask: score inside only.
            entry = {"psnr": psnr(img, ref, mask=m), "ssim": ssim(img, ref, mask=m),
                     "per_radius": _listify(per_radius(img, ref, edges, mask=m)),
                     "per_depth_band": _listify(per_depth_band(img, ref, depth,
                                                               list(DEPTH_BANDS_MM), mask=m))}
            scene_res[path.stem] = entry
        results["scenes"][d.name] = scene_res
    names = sorted({k for s in results["scenes"].values() for k, v in s.items()
                    if isinstance(v, dict)})
    results["mean"] = {n: {"psnr": float(np.nanmean([s[n]["psnr"] for s in results["scenes"].values() if n in s])),
                           "ssim": float(np.nanmean([s[n]["ssim"] for s in results["scenes"].values() if n in s]))}
                       for n in names}
    return results


def _listify(d: dict) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}
