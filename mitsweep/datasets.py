"""A mitsweep dataset as training data: items as dicts of float32 arrays, splits by
scene, and random patches inside the mirror's image.

:func:`open_dataset` opens a directory made by ``mitsweep dataset``
(:func:`mitsweep.pipeline.build_dataset`) and gives a :class:`MitsweepDataset`: one item
per scene, ``len()`` and index access, each item a dict

- ``"input"``: (H, W, 3) float32, RGB, the image chosen as input (``sweep``,
  ``sweep_2lux``, ``focused``, ``edof_50lux``, ...);
- ``"target"``: (H, W, 3) float32, RGB, the image chosen as target (``pinhole``, the
  ground truth, by default);
- ``"mask"``: (H, W, 1) float32, 1 inside the mirror's image and 0 outside;
- ``"depth"``: (H, W, 1) float32, mm, the distance the ground truth's ray travelled
  from the mirror to the scene (0 where it hit nothing);
- ``"meta"``: scene, item names, white level, noise model (noisy inputs), provenance.

Images are in relative exposure, the dataset's own normalisation
(:func:`mitsweep.pipeline.white_level`): every image of a scene is divided by the 99th
percentile of its ground truth inside the mirror's image, so 1.0 is the noise model's
reference level and the data range of its metrics is 1. The EXR files store channels in
alphabetical order (B, G, R); items are always RGB.

The dataset and :class:`PatchSampler` follow the protocols of PyTorch and JAX input
pipelines without importing either: ``len()`` and ``[i]`` make them map-style
datasets for ``torch.utils.data.DataLoader``, and every value of an item is a NumPy
array, a number, a string or a dict of those (what PyTorch's default collation
accepts); :func:`stack_items` batches items for NumPy or JAX. Files are read when an
item is asked for, nothing is cached. The manifest is read and validated as
``mitsweep evaluate`` reads it (:func:`mitsweep.pipeline.load_manifest`,
:func:`mitsweep.pipeline.evaluation.checked_items`).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path, PurePosixPath
from typing import Any
from collections.abc import Iterator, Mapping, Sequence

import numpy as np

from .pipeline.dataset import FORMAT, load_manifest
from .pipeline.evaluation import checked_items, read_finite
from .pipeline.runner import DatasetError
from .pipeline.tasks import WHITE_PERCENTILE, white_level

__all__ = ["open_dataset", "MitsweepDataset", "PatchSampler", "stack_items", "split_scenes",
           "SPLITS", "AOVS", "GROUND_TRUTH"]

logger = logging.getLogger(__name__)

#: The splits of a dataset, in the order of ``splits=`` fractions.
SPLITS = ("train", "validation", "test")
#: The ground truth's AOVs an item may carry: EXR channel of each.
AOVS = {"mask": "mask.Y", "depth": "depth.Z"}
#: The ground truth's image name in every scene (its AOVs and white level come from it).
GROUND_TRUTH = "pinhole"
#: ``meta["units"]`` of normalised and raw items.
_UNITS = {True: f"relative exposure (1.0 = the {WHITE_PERCENTILE:g}th percentile of the "
                f"ground truth inside the mirror's image)",
          False: "render radiance"}


def split_scenes(scenes: Sequence[str], fractions: Sequence[float] = (0.8, 0.1, 0.1), *,
                 seed: int = 0) -> dict[str, tuple[str, ...]]:
    """Deal scenes into train, validation and test splits, deterministically.

    Parameters
    ----------
    scenes : sequence of str
        The scenes, in the dataset's order (``scene_000``, ``scene_001``, ...).
    fractions : (3,) sequence of float
        Shares of the train, validation and test splits: each >= 0, summing to 1.
    seed : int
        Seed of the shuffle; the same scenes, fractions and seed give the same splits.

    Returns
    -------
    dict of str to tuple of str
        ``{"train": ..., "validation": ..., "test": ...}``, disjoint, together every
        scene, each in the dataset's order.

    Notes
    -----
    The scenes are shuffled (``numpy.random.default_rng(seed).permutation``) and cut
    into runs of ``round(n * fraction)`` scenes by the largest-remainder rule, so the
    counts add up to ``n``; a split with a fraction > 0 gets at least one scene when
    there are enough (taken from the largest). A split depends on the number of scenes:
    a dataset grown with more scenes is dealt anew.
    """
    fr = [float(f) for f in fractions]
    if len(fr) != len(SPLITS) or not all(math.isfinite(f) and f >= 0 for f in fr) \
            or not math.isclose(sum(fr), 1.0, abs_tol=1e-9):
        raise DatasetError(f"splits: must be {len(SPLITS)} fractions >= 0 ({', '.join(SPLITS)}) "
                           f"summing to 1, got {tuple(fractions)!r}")
    n = len(scenes)
    exact = [n * f for f in fr]
    counts = [math.floor(x) for x in exact]
    for k in sorted(range(len(fr)), key=lambda k: exact[k] - counts[k], reverse=True):
        if sum(counts) == n:
            break
        counts[k] += 1
    for k in range(len(fr)):   # no empty split that was asked for, when scenes allow
        if fr[k] > 0 and counts[k] == 0 and max(counts) > 1:
            counts[int(np.argmax(counts))] -= 1
            counts[k] += 1
    order = np.random.default_rng(seed).permutation(n)
    out, start = {}, 0
    for name, c in zip(SPLITS, counts):
        out[name] = tuple(scenes[i] for i in sorted(order[start:start + c]))
        start += c
    return out


def _scene_index(scene: str) -> int:
    return int(scene.rsplit("_", 1)[1])


def _jsonable_numbers(d: Mapping[str, Any]) -> dict[str, Any]:
    """The entries of ``d`` that are numbers or strings (what a batch can collate)."""
    return {k: v for k, v in d.items()
            if isinstance(v, (int, float, str)) and not isinstance(v, bool)}


class MitsweepDataset:
    """The scenes of a mitsweep dataset (all, or one split) as training items.

    Made by :func:`open_dataset`; see the module's overview for what an item holds.

    Attributes
    ----------
    root : Path
        The dataset directory.
    input, target : str
        The images an item holds as ``"input"`` and ``"target"``.
    inputs : tuple of str
        Every image name each scene holds (``edof``, ``focused``, ``pinhole``,
        ``sweep``, ``sweep_2lux``, ...): the choices of ``input`` and ``target``.
    scenes : tuple of str
        The scenes of this dataset (or split), one item each, in order.
    split_name : str or None
        The split these scenes are, None for the whole dataset.
    aovs : tuple of str
        The AOVs each item holds (``mask``, ``depth``).
    normalise : bool
        Whether images are in relative exposure (True) or render radiance.
    manifest : dict
        The validated manifest.
    """

    def __init__(self, root: Path, manifest: dict, *, input: str, target: str,
                 scenes: Sequence[str], split_name: str | None,
                 fractions: Sequence[float], seed: int, aovs: Sequence[str],
                 normalise: bool) -> None:
        self.root = root
        self.manifest = manifest
        self._all_scenes, self.inputs = _catalogue(manifest)
        for role, name in (("input", input), ("target", target)):
            if name not in self.inputs:
                raise DatasetError(f"{role}: {name!r} is not an image of {root} (it holds "
                                   f"{', '.join(self.inputs)})")
        unknown = [a for a in aovs if a not in AOVS]
        if unknown:
            raise DatasetError(f"aovs: {unknown[0]!r} is not an AOV of a mitsweep dataset "
                               f"(one of {', '.join(AOVS)})")
        self.input, self.target = input, target
        self.scenes = tuple(scenes)
        self.split_name = split_name
        self.aovs = tuple(aovs)
        self.normalise = bool(normalise)
        self._fractions = tuple(float(f) for f in fractions)
        self._seed = int(seed)

    def __len__(self) -> int:
        return len(self.scenes)

    def __repr__(self) -> str:
        split = f", split={self.split_name!r}" if self.split_name else ""
        return (f"MitsweepDataset({str(self.root)!r}, input={self.input!r}, "
                f"target={self.target!r}{split}: {len(self)} scenes)")

    def _index(self, index: int) -> int:
        if not isinstance(index, (int, np.integer)) or isinstance(index, bool):
            raise TypeError(f"dataset indices are integers, got {type(index).__name__}")
        n = len(self.scenes)
        if not -n <= index < n:
            raise IndexError(f"item {index} of a dataset of {n} scenes")
        return int(index) % n

    def item_path(self, index: int, name: str) -> Path:
        """The file of an image of an item.

        Parameters
        ----------
        index : int
            The item (negative counts from the end).
        name : str
            The image, one of :attr:`inputs` (``sweep``, ``pinhole``...).

        Returns
        -------
        Path
            ``root/scene_NNN/name.exr``.

        Raises
        ------
        IndexError
            ``index`` out of range.
        TypeError
            ``index`` not an integer.
        """
        return self.root / self.scenes[self._index(index)] / f"{name}.exr"

    def __getitem__(self, index: int) -> dict[str, Any]:
        """Item ``index``: its images and AOVs, read from the files.

        Returns
        -------
        dict
            ``input``, ``target`` : (H, W, 3) float32 ndarray, RGB, in relative
            exposure (or render radiance with ``normalise=False``).
            ``mask`` : (H, W, 1) float32 ndarray, 1 inside the mirror's image.
            ``depth`` : (H, W, 1) float32 ndarray, mm, 0 where no surface was hit.
            ``meta`` : dict of ``scene`` (``scene_000``), ``scene_index``, ``input``
            and ``target`` (names), ``items`` (their files and the ground truth's,
            relative to the dataset), ``white_level`` (render radiance of relative
            exposure 1.0), ``units``, ``noise`` (the sensor noise model and light
            level of a noisy input: :meth:`mitsweep.deconv.SensorNoise.as_dict`),
            ``restoration`` (``method`` and ``nsr`` of an EDOF input) and
            ``provenance`` (dataset, format, setup name, mitsweep version, the
            input's and target's SHA-256). Only numbers, strings and dicts of them.
            (``mask``/``depth`` only as asked for by ``aovs``.)

        Raises
        ------
        IndexError
            Beyond the dataset's length (so ``for item in dataset`` ends).
        DatasetError
            A file with NaN or inf pixels, or a ground truth without its AOVs.
        """
        i = self._index(index)
        scene = self.scenes[i]
        gt_path = self.root / scene / f"{GROUND_TRUTH}.exr"
        gt, chans, _ = read_finite(gt_path)
        missing = [AOVS[a] for a in ("mask", *self.aovs) if AOVS[a] not in chans]
        if missing:
            raise DatasetError(f"{gt_path}: no {missing[0]} channel (the ground truth's "
                               f"{'mirror mask' if missing[0] == AOVS['mask'] else 'depth'} "
                               f"AOV)")
        level = white_level(gt, chans[AOVS["mask"]])
        scale = np.float32(1.0 / level) if self.normalise else np.float32(1.0)
        images, metas = {}, {}
        for role, name in (("input", self.input), ("target", self.target)):
            if name == GROUND_TRUTH:
                img, meta = gt, None
            else:
                img, _, meta = read_finite(self.root / scene / f"{name}.exr")
                if img.shape != gt.shape:
                    raise DatasetError(f"{self.root / scene / name}.exr: shape {img.shape} "
                                       f"differs from the ground truth's {gt.shape}")
            images[role] = np.ascontiguousarray(img * scale, dtype=np.float32)
            metas[role] = meta
        item: dict[str, Any] = dict(images)
        for a in self.aovs:
            item[a] = np.ascontiguousarray(chans[AOVS[a]][..., None], dtype=np.float32)
        item["meta"] = self._meta(scene, level, metas["input"])
        return item

    def _meta(self, scene: str, level: float, input_meta: Mapping[str, Any] | None) -> dict:
        items = self.manifest["items"]
        input_item = f"{scene}/{self.input}.exr"
        target_item = f"{scene}/{self.target}.exr"
        params = items[input_item]["params"]
        meta: dict[str, Any] = {
            "scene": scene, "scene_index": _scene_index(scene),
            "input": self.input, "target": self.target,
            "items": {"input": input_item, "target": target_item,
                      # a noisy image's manifest entry names the ground truth it was
                      # normalised by; every other image's is the scene's pinhole
                      "ground_truth": params.get("ground_truth",
                                                 f"{scene}/{GROUND_TRUTH}.exr")},
            "white_level": float(level), "units": _UNITS[self.normalise],
            "provenance": {"dataset": str(self.root), "format": FORMAT,
                           "setup": str(self.manifest["setup"].get("name", "")),
                           "mitsweep": str((self.manifest.get("versions") or {})
                                           .get("mitsweep") or ""),
                           "input_sha256": items[input_item]["sha256"],
                           "target_sha256": items[target_item]["sha256"]}}
        if input_meta is not None and isinstance(input_meta.get("noise"), dict):
            meta["noise"] = _jsonable_numbers(input_meta["noise"])
        if "method" in params:
            meta["restoration"] = {"method": str(params["method"]),
                                   "nsr": float((input_meta or {}).get("nsr", math.nan))}
        return meta

    def provenance(self, index: int) -> dict[str, Any]:
        """Everything recorded about an item.

        Parameters
        ----------
        index : int
            The item (negative counts from the end).

        Returns
        -------
        dict
            ``setup``, ``options`` and ``versions`` of the dataset, and per role
            (``input``, ``target``) the item's name, its manifest entry (parameters,
            SHA-256, size) and its EXR ``metadata``: nested, with lists and None (not
            for batching).

        Raises
        ------
        DatasetError
            An image holds NaN or inf pixels.
        """
        scene = self.scenes[self._index(index)]
        out: dict[str, Any] = {"setup": self.manifest["setup"],
                               "options": self.manifest["options"],
                               "versions": self.manifest.get("versions")}
        for role, name in (("input", self.input), ("target", self.target)):
            item = f"{scene}/{name}.exr"
            out[role] = {"item": item, **self.manifest["items"][item],
                         "metadata": read_finite(self.root / item)[2]}
        return out

    def split(self, name: str) -> MitsweepDataset:
        """One split of the whole dataset.

        Parameters
        ----------
        name : {"train", "validation", "test"}
            The split.

        Returns
        -------
        MitsweepDataset
            Its scenes, dealt by :func:`split_scenes` with this dataset's fractions and
            seed; the same input, target, AOVs and normalisation.

        Raises
        ------
        DatasetError
            An unknown split name.
        """
        if name not in SPLITS:
            raise DatasetError(f"split: {name!r} is not a split (one of {', '.join(SPLITS)})")
        scenes = split_scenes(self._all_scenes, self._fractions, seed=self._seed)[name]
        return MitsweepDataset(self.root, self.manifest, input=self.input, target=self.target,
                               scenes=scenes, split_name=name, fractions=self._fractions,
                               seed=self._seed, aovs=self.aovs, normalise=self.normalise)


def _catalogue(manifest: dict) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The scenes (``scene_000`` ...) of a manifest, by index, and the image names every
    one of them holds, sorted (the calibration scene is none of them)."""
    from .pipeline.tasks import is_scene_item

    per_scene: dict[str, set[str]] = {}
    for name in manifest["items"]:
        parts = PurePosixPath(name).parts
        if is_scene_item(name) and parts[1].endswith(".exr"):
            per_scene.setdefault(parts[0], set()).add(parts[1][:-len(".exr")])
    scenes = tuple(sorted(per_scene, key=_scene_index))
    names = set.intersection(*per_scene.values()) if per_scene else set()
    return scenes, tuple(sorted(names))


def open_dataset(path: str | Path, *, input: str = "sweep", target: str = GROUND_TRUTH,
                 split: str | None = None, splits: Sequence[float] = (0.8, 0.1, 0.1),
                 seed: int = 0, aovs: Sequence[str] = ("mask", "depth"),
                 normalise: bool = True, verify: bool = True) -> MitsweepDataset:
    """Open a dataset directory made by ``mitsweep dataset`` for training.

    Parameters
    ----------
    path : path
        The dataset directory (holding ``manifest.json``).
    input, target : str
        The images each item holds as ``"input"`` and ``"target"``: any image name
        of the dataset's scenes (:attr:`MitsweepDataset.inputs`: ``sweep``,
        ``sweep_50lux``, ``focused``, ``stopped_2lux``, ``edof``, ``pinhole``, ...).
    split : {"train", "validation", "test"}, optional
        Only that split's scenes (:meth:`MitsweepDataset.split`); None: every scene.
    splits : (3,) sequence of float
        Shares of the train, validation and test splits (:func:`split_scenes`).
    seed : int
        Seed of the split.
    aovs : sequence of {"mask", "depth"}
        The ground truth's AOVs each item holds, (H, W, 1) each.
    normalise : bool
        Divide every image by its scene's white level (relative exposure, the
        dataset's metrics' scale); False: render radiance as stored.
    verify : bool
        Check every file's SHA-256 against the manifest before trusting it, as
        ``mitsweep evaluate`` does (reads the whole dataset once); False checks that
        every file is present with its recorded size.

    Returns
    -------
    MitsweepDataset

    Raises
    ------
    DatasetError
        ``path`` is not a mitsweep dataset (no or an invalid manifest), the dataset is
        incomplete or a file missing or changed, or ``input``, ``target``, ``split``,
        ``splits`` or ``aovs`` names what the dataset does not hold (the message lists
        what it does).

    Examples
    --------
    >>> ds = open_dataset("data/small", input="sweep_2lux")      # doctest: +SKIP
    >>> item = ds[0]                                             # doctest: +SKIP
    >>> item["input"].shape, item["mask"].shape                  # doctest: +SKIP
    ((64, 64, 3), (64, 64, 1))
    """
    root = Path(path)
    if not root.is_dir():
        raise DatasetError(f"{path}: not a directory (a mitsweep dataset is the directory "
                           f"`mitsweep dataset --out` made)")
    manifest = load_manifest(root)
    checked_items(root, manifest, checksums=verify)
    scenes, _ = _catalogue(manifest)
    split_scenes((), splits)  # the fractions are checked before the first item is read
    ds = MitsweepDataset(root, manifest, input=input, target=target, scenes=scenes,
                         split_name=None, fractions=splits, seed=seed, aovs=aovs,
                         normalise=normalise)
    return ds if split is None else ds.split(split)


def stack_items(items: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """A batch of items or patches: each array stacked along a new first axis
    ((N, H, W, C) float32), ``meta`` a list of the items' metas. For NumPy and JAX
    pipelines (PyTorch's ``DataLoader`` collates by itself).

    Parameters
    ----------
    items : sequence of dict
        Items (``dataset[i]``) or patches (:class:`PatchSampler`), all of one shape.
    """
    if not items:
        raise ValueError("stack_items: no items to stack")
    out: dict[str, Any] = {}
    for key, value in items[0].items():
        if isinstance(value, np.ndarray):
            out[key] = np.stack([it[key] for it in items])
        else:
            out[key] = [it[key] for it in items]
    return out


class PatchSampler:
    """Random square patches of a dataset's items, each inside the mirror's image.

    Parameters
    ----------
    dataset : MitsweepDataset
        Its items must hold the ``mask`` AOV.
    size : int
        Patch side, pixels.
    per_item : int
        Patches drawn from each item per epoch.
    seed : int
        Seed of the patches and of the order of items; the same seed, epoch and
        dataset give the same patches.
    epoch : int
        Which epoch's patches (:meth:`with_epoch`): each epoch draws other positions
        and visits the items in another order.

    Notes
    -----
    A patch lies wholly inside the mirror's image (every pixel's mask > 0.5), its
    top-left corner uniform over the positions where it does; the positions of item
    ``i`` come from ``numpy.random.default_rng((seed, epoch, scene index))``, so they
    do not depend on the order items are read in. Iterating reads each item once, in a
    shuffled order, and yields its ``per_item`` patches; ``sampler[k]`` is patch
    ``k % per_item`` of item ``k // per_item`` (reading that item again), which makes
    the sampler a map-style dataset of ``len(dataset) * per_item`` patches as well.

    A patch is an item's dict cut to (size, size, C), with ``meta["patch"]`` its
    ``{"y", "x", "size"}`` in the full image (pixels).
    """

    def __init__(self, dataset: MitsweepDataset, size: int, *, per_item: int = 8,
                 seed: int = 0, epoch: int = 0) -> None:
        for key, value, low in (("size", size, 1), ("per_item", per_item, 1),
                                ("epoch", epoch, 0)):
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) \
                    or value < low:
                raise ValueError(f"PatchSampler: {key} must be an integer >= {low}, got "
                                 f"{value!r}")
        if "mask" not in dataset.aovs:
            raise ValueError("PatchSampler: the dataset's items need the mask AOV "
                             "(open_dataset(..., aovs=('mask', ...)))")
        self.dataset = dataset
        self.size = int(size)
        self.per_item = int(per_item)
        self.seed = int(seed)
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.dataset) * self.per_item

    def with_epoch(self, epoch: int) -> PatchSampler:
        """The same sampler for another epoch.

        Parameters
        ----------
        epoch : int
            The epoch, >= 0.

        Returns
        -------
        PatchSampler
            Same dataset, size, ``per_item`` and seed.
        """
        return PatchSampler(self.dataset, self.size, per_item=self.per_item, seed=self.seed,
                            epoch=epoch)

    def _windows(self, item: Mapping[str, Any]) -> list[tuple[int, int]]:
        """The ``per_item`` patch positions of an item."""
        inside = item["mask"][..., 0] > 0.5
        s = self.size
        h, w = inside.shape
        if s > min(h, w):
            raise ValueError(f"PatchSampler: patches of {s} px do not fit the "
                             f"{h}x{w} px images")
        # the patches at each position: their count of pixels inside, by an integral image
        c = np.pad(np.cumsum(np.cumsum(inside, axis=0, dtype=np.int64), axis=1), ((1, 0), (1, 0)))
        counts = c[s:, s:] - c[:-s, s:] - c[s:, :-s] + c[:-s, :-s]
        ys, xs = np.nonzero(counts == s * s)
        if ys.size == 0:
            scene = item["meta"]["scene"]
            raise DatasetError(f"{scene}: no {s} px patch fits inside the mirror's image "
                               f"({int(inside.sum())} px inside); use smaller patches")
        rng = np.random.default_rng((self.seed, self.epoch, item["meta"]["scene_index"]))
        pick = rng.integers(0, ys.size, size=self.per_item)
        return [(int(ys[k]), int(xs[k])) for k in pick]

    def _cut(self, item: Mapping[str, Any], win: tuple[int, int]) -> dict[str, Any]:
        s, (y, x) = self.size, win
        patch: dict[str, Any] = {k: np.ascontiguousarray(v[y:y + s, x:x + s])
                                 for k, v in item.items() if isinstance(v, np.ndarray)}
        patch["meta"] = {**item["meta"], "patch": {"y": y, "x": x, "size": s}}
        return patch

    def __iter__(self) -> Iterator[dict[str, Any]]:
        order = np.random.default_rng((self.seed, self.epoch)).permutation(len(self.dataset))
        for i in order:
            item = self.dataset[int(i)]
            for win in self._windows(item):
                yield self._cut(item, win)

    def __getitem__(self, index: int) -> dict[str, Any]:
        n = len(self)
        if not isinstance(index, (int, np.integer)) or isinstance(index, bool):
            raise TypeError(f"patch indices are integers, got {type(index).__name__}")
        if not -n <= index < n:
            raise IndexError(f"patch {index} of {n}")
        i, k = divmod(int(index) % n, self.per_item)
        item = self.dataset[i]
        return self._cut(item, self._windows(item)[k])
