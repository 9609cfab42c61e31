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
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .config import Setup, setup_from_dict, setup_to_dict
from .io import read_exr, write_exr, write_text_atomic
from .io.exr import stack_channels

__all__ = ["DatasetOptions", "build_dataset", "evaluate_dataset", "load_manifest",
           "MANIFEST", "DatasetError"]

log = logging.getLogger(__name__)

MANIFEST = "manifest.json"
MODES = ("pinhole", "focused", "sweep", "stopped")
WHITE_PERCENTILE = 99.0
#: Pixel of the camera whose noise the noisy images carry, mm: a DSLR of the paper's
#: era (6.4 µm, whose ~40 000 e⁻ full well is the noise model's default). The renders
#: use larger synthetic pixels so that the mirror's image fits a small frame; each
#: rendered pixel gets the noise of one such camera pixel (not of an 18 µm pixel, which
#: would collect 8× the light and saturate the modelled full well).
NOISE_PIXEL_MM = 0.0064
#: Wiener prior of the EDOF images (see :func:`_task_deconvolve`).
DECONV_PRIOR = "natural"


class DatasetError(ValueError):
    """A dataset directory is missing, inconsistent, or was made for another setup."""


@dataclass(frozen=True, kw_only=True)
class DatasetOptions:
    """What a dataset holds. Seeds: scene i renders with ``seed + i`` (texture layout
    ``scene.texture_seed + i``); noise of scene i at level j uses ``(seed, i, j)``."""

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
        if not (isinstance(self.scenes, int) and 1 <= self.scenes <= 10000):
            raise DatasetError(f"scenes: must be an integer in [1, 10000], got {self.scenes!r}")
        for mode in MODES:
            v = self.spp.get(mode)
            if not (isinstance(v, int) and v > 0):
                raise DatasetError(f"spp[{mode!r}]: must be a positive integer, got {v!r}")
        for lux in self.light_levels_lux:
            if not (lux > 0 and math.isfinite(lux)):
                raise DatasetError(f"light level: must be > 0 lux, got {lux!r}")

    def as_dict(self) -> dict:
        return {"scenes": self.scenes, "seed": self.seed, "spp": dict(self.spp),
                "light_levels_lux": list(self.light_levels_lux),
                "bank_depths_mm": list(self.bank_depths_mm), "bank_rays": self.bank_rays,
                "grid": list(self.grid), "stopped_f_number": self.stopped_f_number,
                "diffraction": self.diffraction}


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
                        pixel_size_mm=pixel_pitch, iso=iso)
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
    p = Path(directory) / MANIFEST
    if not p.is_file():
        raise DatasetError(f"{directory}: no {MANIFEST} (not a mitsweep dataset)")
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{p}: corrupt manifest ({exc})") from None


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


def _plan(setup: Setup, opts: DatasetOptions, root: Path) -> list[_Task]:
    from .deconv import paper_fig10_settings

    sd = setup_to_dict(setup)
    tasks = [_Task("bank.npz", _task_bank,
                   (sd, opts.bank_depths_mm, opts.bank_rays, opts.grid, opts.seed,
                    str(root / "bank.npz")),
                   {"depths": list(opts.bank_depths_mm), "rays": opts.bank_rays,
                    "grid": list(opts.grid), "seed": opts.seed})]
    pitch = NOISE_PIXEL_MM
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
            settings = paper_fig10_settings(pitch, lux)
            for mode in ("sweep", "stopped"):
                s = settings[mode]
                name = f"{d}/{mode}_{lux:g}lux.exr"
                tasks.append(_Task(name, _task_noisy,
                                   (str(root / d / "pinhole.exr"), str(root / d / f"{mode}.exr"),
                                    lux, s.f_number, s.iso, s.exposure_s, pitch, (opts.seed, i, j),
                                    str(root / name)),
                                   {"lux": lux, "f_number": s.f_number, "iso": s.iso,
                                    "exposure_s": s.exposure_s, "seed": [opts.seed, i, j]},
                                   deps=(f"{d}/pinhole.exr", f"{d}/{mode}.exr")))
            nsr = settings["sweep"].nsr(0.5)
            tasks.append(_Task(f"{d}/edof_{lux:g}lux.exr", _task_deconvolve,
                               (str(root / d / f"sweep_{lux:g}lux.exr"), str(root / "bank.npz"),
                                nsr, str(root / d / f"edof_{lux:g}lux.exr")),
                               {"nsr": nsr, "prior": DECONV_PRIOR},
                               deps=(f"{d}/sweep_{lux:g}lux.exr", "bank.npz")))
    return tasks


def build_dataset(setup: Setup, out_dir: str | Path, options: DatasetOptions | None = None, *,
                  executor: str = "serial", jobs: int = 2, progress: bool = True) -> dict:
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

    Returns
    -------
    dict
        The manifest (also written to ``out_dir/manifest.json``).
    """
    if executor not in ("serial", "process"):
        raise DatasetError(f"executor: must be 'serial' or 'process', got {executor!r}")
    if not (isinstance(jobs, int) and jobs >= 1):
        raise DatasetError(f"jobs: must be a positive integer, got {jobs!r}")
    opts = options or DatasetOptions()
    root = Path(out_dir)
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DatasetError(f"{root}: cannot create the dataset directory ({exc.strerror})") from None
    sd = setup_to_dict(setup)
    manifest = {"format": "mitsweep-dataset/1", "setup": sd, "options": opts.as_dict(),
                "versions": _versions(), "items": {}}
    if (root / MANIFEST).is_file():
        old = load_manifest(root)
        if old.get("setup") != sd:
            raise DatasetError(f"{root}: holds a dataset of another setup "
                               f"({old.get('setup', {}).get('name')!r}); use a new directory")
        manifest["items"] = old.get("items", {})
    tasks = _plan(setup, opts, root)
    for i in range(opts.scenes):
        (root / f"scene_{i:03d}").mkdir(exist_ok=True)

    def is_done(t: _Task) -> bool:
        item = manifest["items"].get(t.name)
        p = root / t.name
        return (item is not None and item.get("params") == _jsonable(t.params) and p.is_file()
                and item.get("sha256") == _sha256(p))

    todo = [t for t in tasks if not is_done(t)]
    skipped = len(tasks) - len(todo)
    if skipped:
        log.info("resuming: %d of %d items already complete", skipped, len(tasks))
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
                results = []
                for t in ready:
                    t.fn(*t.args)
                    results.append(t)
                    _record(root, manifest, t, time.perf_counter() - t0)
                    bar.update(1)
                    done_names.add(t.name)
                    t0 = time.perf_counter()
            else:
                futures = {pool.submit(t.fn, *t.args): t for t in ready}
                for fut in cf.as_completed(futures):
                    t = futures[fut]
                    fut.result()
                    _record(root, manifest, t, time.perf_counter() - t0)
                    bar.update(1)
                    done_names.add(t.name)
            pending = [t for t in pending if t.name not in done_names]
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
    manifest["complete"] = True
    _write_manifest(root, manifest)
    return manifest


def _jsonable(obj):
    return json.loads(json.dumps(obj, default=str))


def _record(root: Path, manifest: dict, task: _Task, seconds: float) -> None:
    p = root / task.name
    manifest["items"][task.name] = {"params": _jsonable(task.params), "sha256": _sha256(p),
                                    "bytes": p.stat().st_size, "seconds": round(seconds, 3)}
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


def _scene_dirs(root: Path, manifest: dict) -> list[Path]:
    n = int(manifest.get("options", {}).get("scenes", 0))
    dirs = [root / f"scene_{i:03d}" for i in range(n)]
    missing = [d.name for d in dirs if not (d / "pinhole.exr").is_file()]
    if missing:
        raise DatasetError(f"{root}: incomplete dataset, no pinhole.exr in {missing[0]} "
                           f"(rerun `mitsweep dataset` to finish it)")
    return dirs


def evaluate_dataset(directory: str | Path, *, n_radial_bins: int = 8) -> dict:
    """Score EDOF against focused and stopped images, on the ground truth.

    Returns per scene and averaged: PSNR (dB) and SSIM inside the mirror's image, per
    radial bin (pixels from the optical axis) and per depth band (mm), for ``edof``,
    ``focused``, ``stopped``, ``sweep`` (not deconvolved) and the noisy variants.
    """
    from .deconv import per_depth_band, per_radius, psnr, ssim

    root = Path(directory)
    manifest = load_manifest(root)
    results: dict[str, Any] = {"dataset": str(root), "scenes": {}}
    for d in _scene_dirs(root, manifest):
        gt, chans, _ = _read_rgb(d / "pinhole.exr")
        mask = chans.get("mask.Y")
        if mask is None:
            raise DatasetError(f"{d}/pinhole.exr: no mask.Y channel (mirror mask AOV)")
        m = mask > 0.5
        depth = chans.get("depth.Z", np.full(mask.shape, np.nan, dtype=np.float32))
        depth = np.where(m & (depth > 0), depth, np.nan)
        level = white_level(gt, mask)
        ref = gt / level
        ys, xs = np.nonzero(m)
        H, W = m.shape
        cy, cx = (H - 1) / 2.0, (W - 1) / 2.0
        r_max = float(np.max(np.hypot(ys - cy, xs - cx))) + 0.5
        edges = np.linspace(0.0, r_max, n_radial_bins + 1)
        scene_res: dict[str, Any] = {"white_level": level, "mirror_radius_px": r_max}
        for path in sorted(d.glob("*.exr")):
            name = path.stem
            if name == "pinhole":
                continue
            img = _read_rgb(path)[0] / level
            # An image leaves the mirror's disc alone outside the mask: score inside only.
            entry = {"psnr": psnr(img, ref, mask=m), "ssim": ssim(img, ref, mask=m),
                     "per_radius": _listify(per_radius(img, ref, edges, mask=m)),
                     "per_depth_band": _listify(per_depth_band(img, ref, depth,
                                                               list(DEPTH_BANDS_MM), mask=m))}
            scene_res[name] = entry
        results["scenes"][d.name] = scene_res
    names = sorted({k for s in results["scenes"].values() for k, v in s.items()
                    if isinstance(v, dict)})
    results["mean"] = {n: {"psnr": float(np.nanmean([s[n]["psnr"] for s in results["scenes"].values() if n in s])),
                           "ssim": float(np.nanmean([s[n]["ssim"] for s in results["scenes"].values() if n in s]))}
                       for n in names}
    return results


def _listify(d: dict) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}
