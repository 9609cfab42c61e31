"""``mitsweep.datasets``: a real dataset, made once by the command of
docs/guide/train.md, read as training items; and that page's Python blocks, run in
order, whose learned filter must beat the raw input on the validation scenes.

The independent references: the EXR files read with OpenEXR directly (channels as
stored, B, G, R, reordered by hand), the white level recomputed with NumPy, and the
manifest's own records.
"""

import contextlib
import importlib.util
import io
import math
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitsweep.cli.main import main
from mitsweep.datasets import (SPLITS, MitsweepDataset, PatchSampler, open_dataset,
                               split_scenes, stack_items)
from mitsweep.pipeline import DatasetError, load_manifest

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "train.md"
#: The guide's dataset: 8 scenes, one light level (2 lux), 64 px.
SCENES, LUX, SIDE = 8, "2", 64


def _blocks(language: str) -> list[str]:
    """The guide's fenced code blocks in ``language``, in order."""
    return re.findall(rf"^```{language}\n(.*?)^```", GUIDE.read_text(), re.M | re.S)


@pytest.fixture(scope="module")
def guide_dir(tmp_path_factory):
    """A directory holding the guide's ``small.toml`` and ``data/small``, made by the
    guide's own ``mitsweep dataset`` command (about 8 s)."""
    root = tmp_path_factory.mktemp("guide")
    (toml,) = _blocks("toml")
    (command,) = [line for b in _blocks("bash") for line in b.splitlines()
                  if "mitsweep dataset" in line]
    args = shlex.split(command)[2:]           # after `.venv/bin/mitsweep dataset`
    (root / args[0]).write_text(toml)
    out = args.index("--out") + 1
    args[0], args[out] = str(root / args[0]), str(root / args[out])
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["dataset", *args]) == 0
    return root


@pytest.fixture(scope="module")
def root(guide_dir):
    return guide_dir / "data" / "small"


def _exr_as_stored(path: Path) -> tuple[list[str], dict[str, np.ndarray], dict]:
    """Channel names in the file's order, the channels and the header, by OpenEXR."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        chans = {name: np.array(c.pixels) for name, c in f.channels().items()}
        header = dict(f.header())
    return list(chans), chans, header


def test_items_are_rgb_float32_arrays_with_mask_depth_and_meta(root):
    ds = open_dataset(root, input="sweep_2lux")
    assert len(ds) == SCENES and ds.scenes[0] == "scene_000"
    assert {"pinhole", "sweep", "sweep_2lux", "focused", "stopped", "stopped_2lux", "edof",
            "edof_2lux"} == set(ds.inputs)
    item = ds[3]
    assert set(item) == {"input", "target", "mask", "depth", "meta"}
    for key, channels in (("input", 3), ("target", 3), ("mask", 1), ("depth", 1)):
        assert item[key].shape == (SIDE, SIDE, channels) and item[key].dtype == np.float32
        assert item[key].flags.c_contiguous
    assert item["meta"]["scene"] == "scene_003" and item["meta"]["scene_index"] == 3
    assert ds[-1]["meta"]["scene"] == f"scene_{SCENES - 1:03d}"
    with pytest.raises(IndexError):
        ds[SCENES]
    assert [it["meta"]["scene"] for it in ds] == list(ds.scenes)  # iteration stops


def test_channels_are_rgb_whatever_order_the_file_stores(root):
    """The EXR stores B, G, R (alphabetical); reversed by hand they are the item's."""
    ds = open_dataset(root, input="sweep", target="pinhole", normalise=False)
    item = ds[1]
    for role, name in (("input", "sweep"), ("target", "pinhole")):
        order, chans, _ = _exr_as_stored(root / "scene_001" / f"{name}.exr")
        assert order[:3] == ["B", "G", "R"]
        stored = np.stack([chans[c] for c in order[:3]], axis=-1)
        np.testing.assert_array_equal(item[role], stored[..., ::-1])
    # the scene is not grey: swapped channels would differ
    assert np.abs(item["target"][..., 0] - item["target"][..., 2]).max() > 1e-3


def test_images_are_in_relative_exposure_of_the_ground_truth(root):
    """Every image of a scene over the 99th percentile of its ground truth inside the
    mirror; the white level a noisy image recorded is the same number."""
    raw = open_dataset(root, input="sweep_2lux", normalise=False)
    norm = open_dataset(root, input="sweep_2lux")
    for i in (0, 5):
        r, n = raw[i], norm[i]
        _, chans, _ = _exr_as_stored(root / r["meta"]["scene"] / "pinhole.exr")
        inside = chans["mask.Y"] > 0.5
        rgb = np.stack([chans[c] for c in "RGB"], axis=-1)
        level = float(np.percentile(rgb[inside], 99.0))
        assert n["meta"]["white_level"] == pytest.approx(level, rel=1e-6)
        # float32 division against float32 division: one rounding apart at most
        np.testing.assert_allclose(n["input"], r["input"] / np.float32(level), rtol=1e-6)
        np.testing.assert_allclose(n["target"], r["target"] / np.float32(level), rtol=1e-6)
        assert np.percentile(n["target"][n["mask"][..., 0] > 0.5], 99.0) == pytest.approx(1.0)
        # the noisy image's own record (float32 in its EXR header)
        recorded = open_dataset(root, input="sweep_2lux").provenance(i)["input"]["metadata"]
        assert recorded["white_level"] == pytest.approx(level, rel=1e-6)
        assert "relative exposure" in n["meta"]["units"] and r["meta"]["units"] == "render radiance"


def test_mask_and_depth_are_the_ground_truths_aovs(root):
    ds = open_dataset(root)
    item = ds[2]
    _, chans, _ = _exr_as_stored(root / "scene_002" / "pinhole.exr")
    np.testing.assert_array_equal(item["mask"][..., 0], chans["mask.Y"])
    np.testing.assert_array_equal(item["depth"][..., 0], chans["depth.Z"])
    assert set(np.unique(item["mask"])) == {0.0, 1.0}
    inside = item["mask"][..., 0] > 0.5
    assert 0.2 < inside.mean() < 0.9            # the mirror's disc inside the frame
    assert item["depth"].min() >= 0 and np.median(item["depth"][inside]) > 300  # mm
    assert set(open_dataset(root, aovs=()).__getitem__(0)) == {"input", "target", "meta"}
    assert set(open_dataset(root, aovs=("depth",))[0]) == {"input", "target", "depth", "meta"}


def _collatable(value) -> bool:
    """Only numbers, strings and dicts of them (PyTorch's default collation)."""
    if isinstance(value, dict):
        return all(isinstance(k, str) and _collatable(v) for k, v in value.items())
    return isinstance(value, (int, float, str)) and not isinstance(value, bool)


@pytest.mark.parametrize("name", ["sweep_2lux", "edof_2lux", "focused"])
def test_meta_names_the_items_noise_and_provenance(root, name):
    ds = open_dataset(root, input=name)
    manifest = load_manifest(root)
    meta = ds[4]["meta"]
    item = f"scene_004/{name}.exr"
    assert meta["items"] == {"input": item, "target": "scene_004/pinhole.exr",
                             "ground_truth": "scene_004/pinhole.exr"}
    assert meta["provenance"]["input_sha256"] == manifest["items"][item]["sha256"]
    assert meta["provenance"]["setup"] == "small" and meta["provenance"]["dataset"] == str(root)
    assert _collatable(meta), meta
    if name == "sweep_2lux":   # the noisy item's manifest names its ground truth
        assert manifest["items"][item]["params"]["ground_truth"] == meta["items"]["ground_truth"]
    _, _, header = _exr_as_stored(root / item)
    if name == "focused":
        assert "noise" not in meta and "restoration" not in meta
    else:
        import json

        assert meta["noise"] == json.loads(header["mitsweep:noise"])
        assert meta["noise"]["illuminance_lux"] == float(LUX)
    if name == "edof_2lux":
        assert meta["restoration"]["method"] == "wiener" and meta["restoration"]["nsr"] > 0


def test_splits_are_disjoint_by_scene_and_deterministic(root):
    ds = open_dataset(root, splits=(0.5, 0.25, 0.25), seed=3)
    parts = {name: ds.split(name).scenes for name in SPLITS}
    assert [len(parts[n]) for n in SPLITS] == [4, 2, 2]
    assert sorted(sum(parts.values(), ())) == list(ds.scenes)
    again = open_dataset(root, splits=(0.5, 0.25, 0.25), seed=3, split="validation")
    assert again.scenes == parts["validation"] and again.split_name == "validation"
    # a split of a split is still the whole dataset's
    assert ds.split("train").split("test").scenes == parts["test"]
    others = {open_dataset(root, splits=(0.5, 0.25, 0.25), seed=s).split("test").scenes
              for s in range(4)}
    assert len(others) > 1     # the seed deals them
    assert [len(open_dataset(root).split(n)) for n in SPLITS] == [6, 1, 1]


@pytest.mark.parametrize("n,fractions,counts", [
    (10, (0.8, 0.1, 0.1), (8, 1, 1)),
    (3, (0.8, 0.1, 0.1), (1, 1, 1)),       # every asked-for split gets a scene
    (7, (0.5, 0.5, 0.0), (4, 3, 0)),
    (1000, (0.7, 0.2, 0.1), (700, 200, 100)),
])
def test_split_counts_follow_the_fractions(n, fractions, counts):
    scenes = [f"scene_{i:03d}" for i in range(n)]
    parts = split_scenes(scenes, fractions, seed=1)
    assert tuple(len(parts[s]) for s in SPLITS) == counts
    assert sorted(sum(parts.values(), ())) == scenes
    assert parts == split_scenes(scenes, fractions, seed=1)


def test_patches_lie_inside_the_mirror_and_repeat_with_the_seed(root):
    train = open_dataset(root, input="sweep_2lux", splits=(0.5, 0.25, 0.25)).split("train")
    sampler = PatchSampler(train, 16, per_item=5, seed=7)
    patches = list(sampler)
    assert len(patches) == len(sampler) == 5 * len(train)
    positions = [(p["meta"]["scene"], p["meta"]["patch"]["y"], p["meta"]["patch"]["x"])
                 for p in patches]
    again = [(p["meta"]["scene"], p["meta"]["patch"]["y"], p["meta"]["patch"]["x"])
             for p in PatchSampler(train, 16, per_item=5, seed=7)]
    assert positions == again
    items = {it["meta"]["scene"]: it for it in train}
    for p in patches:
        assert p["input"].shape == (16, 16, 3) and p["mask"].shape == (16, 16, 1)
        assert np.all(p["mask"] == 1.0)
        y, x = p["meta"]["patch"]["y"], p["meta"]["patch"]["x"]
        full = items[p["meta"]["scene"]]
        np.testing.assert_array_equal(p["input"], full["input"][y:y + 16, x:x + 16])
        np.testing.assert_array_equal(p["target"], full["target"][y:y + 16, x:x + 16])
    # random access holds the same patches; another epoch or seed draws others
    assert sorted(positions) == sorted(
        (q["meta"]["scene"], q["meta"]["patch"]["y"], q["meta"]["patch"]["x"])
        for q in (sampler[k] for k in range(len(sampler))))
    for other in (sampler.with_epoch(1), PatchSampler(train, 16, per_item=5, seed=8)):
        assert sorted(positions) != sorted(
            (q["meta"]["scene"], q["meta"]["patch"]["y"], q["meta"]["patch"]["x"]) for q in other)
    batch = stack_items(patches[:4])
    assert batch["input"].shape == (4, 16, 16, 3) and len(batch["meta"]) == 4


def test_refusals_name_what_exists(root, tmp_path):
    with pytest.raises(DatasetError, match="not a directory"):
        open_dataset(tmp_path / "nope")
    with pytest.raises(DatasetError, match=r"no manifest.json \(not a mitsweep dataset\)"):
        open_dataset(tmp_path)
    with pytest.raises(DatasetError, match=r"input: 'sweep_9lux' is not an image of .* "
                                           r"\(it holds edof, edof_2lux, focused, pinhole"):
        open_dataset(root, input="sweep_9lux")
    with pytest.raises(DatasetError, match="target: 'depth' is not an image"):
        open_dataset(root, target="depth")
    with pytest.raises(DatasetError, match="'val' is not a split .*train, validation, test"):
        open_dataset(root, split="val")
    with pytest.raises(DatasetError, match="splits: must be 3 fractions"):
        open_dataset(root, splits=(0.8, 0.3, 0.1))
    with pytest.raises(DatasetError, match="aovs: 'normals' is not an AOV .*mask, depth"):
        open_dataset(root, aovs=("normals",))
    with pytest.raises(DatasetError, match="no 64 px patch fits inside the mirror"):
        list(PatchSampler(open_dataset(root), 64, per_item=1))
    with pytest.raises(ValueError, match="need the mask AOV"):
        PatchSampler(open_dataset(root, aovs=("depth",)), 8)


def test_a_changed_file_is_refused_unless_unverified(root, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(root, copy)
    victim = copy / "scene_006" / "sweep.exr"
    data = bytearray(victim.read_bytes())
    data[-1] ^= 0xFF                     # same size, other bytes
    victim.write_bytes(bytes(data))
    with pytest.raises(DatasetError, match=r"scene_006/sweep.exr: changed since it was "
                                           r"written"):
        open_dataset(copy)
    assert len(open_dataset(copy, verify=False)) == SCENES   # sizes only
    victim.write_bytes(bytes(data[:-1]))
    with pytest.raises(DatasetError, match="changed since it was written"):
        open_dataset(copy, verify=False)
    (copy / "scene_003" / "edof.exr").unlink()
    with pytest.raises(DatasetError, match="scene_003/edof.exr: listed in the manifest but "
                                           "missing"):
        open_dataset(copy, verify=False)


def test_reading_imports_neither_mitsuba_nor_a_learning_framework(root):
    code = ("import sys\nfrom mitsweep.datasets import open_dataset, PatchSampler\n"
            f"ds = open_dataset({str(root)!r})\nlist(PatchSampler(ds, 8, per_item=1))\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'mitsuba', 'drjit', 'torch', 'jax', 'tensorflow'}))\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


#: Packages a block of the guide may need that the test environment need not have.
OPTIONAL = ("torch", "jax")


def test_the_guides_training_loop_improves_validation_psnr(guide_dir, monkeypatch):
    """Every Python block of docs/guide/train.md, in order, in one namespace, in the
    directory the guide's command made its dataset in; a block that imports PyTorch or
    JAX runs only where it is installed. The loop's filter must beat the raw input on
    the validation scenes: by at least 0.5 dB (it gains 1.0 dB on this dataset; its
    least-squares fit is deterministic, so the margin is against a change of
    behaviour, not against noise)."""
    monkeypatch.chdir(guide_dir)
    namespace: dict = {"__name__": "train_guide"}
    out = io.StringIO()
    ran = 0
    for block in _blocks("python"):
        needs = set(re.findall(rf"^\s*(?:import|from)\s+({'|'.join(OPTIONAL)})\b", block, re.M))
        if any(importlib.util.find_spec(n) is None for n in needs):
            continue
        with contextlib.redirect_stdout(out):
            exec(compile(block, str(GUIDE), "exec"), namespace)
        ran += 1
    assert ran >= 6
    assert isinstance(namespace["ds"], MitsweepDataset)
    printed = out.getvalue()
    m = re.search(r"validation PSNR: input ([\d.]+) dB, learned filter ([\d.]+) dB "
                  r"\((\d+) scenes\)", printed)
    assert m, printed
    before, after = float(m[1]), float(m[2])
    assert int(m[3]) == 2 and math.isfinite(before)
    assert after > before + 0.5, printed
    # the figures the guide quotes are the ones its loop prints (within 0.3 dB: another
    # CPU's renders may differ in their last bits)
    quoted = re.search(r"On this dataset: input ([\d.]+) dB, learned filter ([\d.]+) dB",
                       GUIDE.read_text())
    assert quoted, "the guide no longer quotes its loop's figures"
    assert (float(quoted[1]), float(quoted[2])) == pytest.approx((before, after), abs=0.3)
