"""A corpus of bad inputs across every subcommand: each is refused cleanly.

Every case runs the real CLI (``mitsweep.cli.main.main``) in a scratch directory and
asserts the contract of a user error: exit status 2, exactly one line on stderr that names
the problem, no traceback, no warning, nothing on stdout, and nothing written (the
directory tree, inputs included, is byte-for-byte as before).

The cases are grouped as the probes that found them: setups (TOML), flags, input files
(EXR, banks, motion tables), dataset manifests and output paths.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from mitsweep.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
SPHERE = (ROOT / "scenes" / "sphere.toml").read_text()

#: The sections of scenes/sphere.toml as a dict: cases patch one key at a time.
BASE = {
    "mirror": {"kind": "sphere", "radius": 25.0, "center_distance": 352.0, "rim_radius": 25.0},
    "lens": {"focal_length": 50.0, "f_number": 2.8},
    "sensor": {"resolution": [512, 512], "pixel_pitch": 0.018},
    "sweep": {"fov_deg": 237.0, "depth_min": 300.0, "depth_max": 10000.0, "velocity": 1.0},
}


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return str(v)


def toml_text(sections: dict) -> str:
    out = []
    for name, table in sections.items():
        out.append(f"[{name}]")
        out += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
        out.append("")
    return "\n".join(out)


_DROP = object()


def patched(section: str, key: str, value) -> str:
    """scenes/sphere.toml with one key set (or dropped, with ``_DROP``)."""
    sections = {s: dict(t) for s, t in BASE.items()}
    sections.setdefault(section, {})
    if value is _DROP:
        sections[section].pop(key, None)
    else:
        sections[section][key] = value
    return toml_text(sections)


@dataclass
class Case:
    """One bad input: ``make(tmp)`` writes the files and returns the argv; ``expect`` is
    a substring the error line must contain (case-insensitive)."""

    id: str
    make: Callable[[Path], list]
    expect: str = ""


CASES: list[Case] = []


def case(id: str, expect: str = ""):
    def deco(fn):
        CASES.append(Case(id, fn, expect))
        return fn
    return deco


def add(id: str, make: Callable[[Path], list], expect: str = "") -> None:
    CASES.append(Case(id, make, expect))


def write(tmp: Path, name: str, text: str) -> Path:
    p = tmp / name
    p.write_text(text)
    return p


# --------------------------------------------------------------------------------------
# Setups: one bad value at a time, each through the commands that load a setup
# --------------------------------------------------------------------------------------
BAD_SETUP_VALUES = [
    # (section, key, value, expected words in the error)
    ("mirror", "radius", "25.0", "mirror.radius"),
    ("mirror", "radius", True, "mirror.radius"),
    ("mirror", "radius", -25.0, "mirror.radius"),
    ("mirror", "radius", 0.0, "mirror.radius"),
    ("mirror", "radius", math.nan, "mirror.radius"),
    ("mirror", "radius", math.inf, "mirror.radius"),
    ("mirror", "radius", [25.0], "mirror.radius"),
    ("mirror", "radius", _DROP, "radius"),
    ("mirror", "kind", "cylinder", "mirror.kind"),
    ("mirror", "kind", 3, "mirror.kind"),
    ("mirror", "center_distance", "far", "center_distance"),
    ("mirror", "center_distance", 10.0, "vertex_distance"),
    ("mirror", "rim_radius", 40.0, "rim_radius"),
    ("mirror", "rim_radius", False, "rim_radius"),
    ("mirror", "tilt_deg", 90.0, "tilt_deg"),
    ("mirror", "tilt_deg", "10", "tilt_deg"),
    ("mirror", "colour", "silver", "colour"),
    ("lens", "focal_length", 0.0, "focal_length"),
    ("lens", "focal_length", "50", "focal_length"),
    ("lens", "f_number", True, "f_number"),
    ("lens", "f_number", -2.8, "f_number"),
    ("lens", "f_number", math.nan, "f_number"),
    ("lens", "zoom", 2.0, "zoom"),
    ("sensor", "resolution", [512], "resolution"),
    ("sensor", "resolution", [512.5, 512], "resolution"),
    ("sensor", "resolution", ["512", "512"], "resolution"),
    ("sensor", "resolution", [0, 512], "resolution"),
    ("sensor", "resolution", [-512, 512], "resolution"),
    ("sensor", "resolution", [65536, 65536], "resolution"),
    ("sensor", "resolution", [True, True], "resolution"),
    ("sensor", "pixel_pitch", 0.0, "pixel_pitch"),
    ("sensor", "pixel_pitch", "0.018", "pixel_pitch"),
    ("sweep", "fov_deg", 0.0, "fov"),
    ("sweep", "fov_deg", 400.0, "fov"),
    ("sweep", "fov_deg", "wide", "fov"),
    ("sweep", "depth_min", 20000.0, "depth"),
    ("sweep", "depth_min", -5.0, "depth_min"),
    ("sweep", "depth_max", "abc", "depth_max"),
    ("sweep", "depth_max", math.nan, "depth_max"),
    ("sweep", "velocity", 0.0, "velocity"),
    ("sweep", "velocity", True, "velocity"),
    ("sweep", "speed", 1.0, "speed"),
    ("scene", "texture_seed", -5, "texture_seed"),
    ("scene", "texture_seed", 1.5, "texture_seed"),
    ("scene", "texture_seed", "7", "texture_seed"),
    ("scene", "objects", 1000, "objects"),
    ("scene", "lighting", "sunny", "lighting"),
    ("scene", "room_size", [1.0, 2.0], "room_size"),
    ("rig", "travel", -1.0, "travel"),
    ("rig", "baudrate", 9600.5, "baudrate"),
    ("rig", "sensor_direction", 2, "sensor_direction"),
    ("rig", "steps_per_mm", "400", "steps_per_mm"),
]


def _setup_case(section, key, value, words, command):
    def make(tmp: Path) -> list:
        s = write(tmp, "setup.toml", patched(section, key, value))
        argv = {"sweep-range": ["sweep-range", s],
                "render": ["render", s, "--mode", "pinhole", "--out", tmp / "out.exr"],
                "capture": ["capture", s, "--dry-run"],
                "dataset": ["dataset", s, "--out", tmp / "ds"],
                "ipsf": ["ipsf", s, "--radius", "5", "-o", tmp / "k.npz"],
                "table1": ["table1", s]}[command]
        return argv
    return make


# every bad value through sweep-range (fast); a cross-section through the others
_OTHERS = ("render", "capture", "dataset", "ipsf", "table1")
for n, (section, key, value, words) in enumerate(BAD_SETUP_VALUES):
    vid = "drop" if value is _DROP else repr(value)[:24]
    add(f"setup-{section}.{key}={vid}-sweep-range",
        _setup_case(section, key, value, words, "sweep-range"), words)
    add(f"setup-{section}.{key}={vid}-{_OTHERS[n % len(_OTHERS)]}",
        _setup_case(section, key, value, words, _OTHERS[n % len(_OTHERS)]), words)


@case("setup-not-toml", "toml")
def _(tmp):
    return ["sweep-range", write(tmp, "setup.toml", "this is [not toml")]


@case("setup-empty", "mirror")
def _(tmp):
    return ["sweep-range", write(tmp, "setup.toml", "")]


@case("setup-binary", "")
def _(tmp):
    p = tmp / "setup.toml"
    p.write_bytes(bytes(range(256)) * 4)
    return ["sweep-range", p]


@case("setup-deep-nesting", "nest")
def _(tmp):
    return ["sweep-range", write(tmp, "setup.toml",
                                 SPHERE + "\n[extra]\nx = " + "[" * 5000 + "]" * 5000 + "\n")]


@case("setup-deep-nesting-value", "nest")
def _(tmp):
    text = patched("mirror", "radius", 25.0).replace("radius = 25.0",
                                                     "radius = " + "[" * 3000 + "]" * 3000)
    return ["sweep-range", write(tmp, "setup.toml", text)]


@case("setup-missing-file", "no such setup file")
def _(tmp):
    return ["sweep-range", tmp / "nope.toml"]


@case("setup-is-directory", "")
def _(tmp):
    (tmp / "dir.toml").mkdir()
    return ["sweep-range", tmp / "dir.toml"]


@case("setup-unknown-section", "section")
def _(tmp):
    return ["sweep-range", write(tmp, "setup.toml", SPHERE + "\n[camera]\niso = 100\n")]


@case("setup-section-not-table", "mirror")
def _(tmp):
    return ["sweep-range", write(tmp, "setup.toml", "mirror = 3\n" + SPHERE.split("[lens]")[1])]


# --------------------------------------------------------------------------------------
# Flags
# --------------------------------------------------------------------------------------
def _flags(command: str, extra: list, expect: str = "", *, setup_text: str = SPHERE):
    def make(tmp: Path) -> list:
        s = write(tmp, "setup.toml", setup_text)
        fixed = {"render": ["render", s, "--mode", "pinhole", "--out", tmp / "out.exr"],
                 "ipsf": ["ipsf", s, "-o", tmp / "k.npz"],
                 "table1": ["table1", s],
                 "dataset": ["dataset", s, "--out", tmp / "ds"],
                 "sweep-range": ["sweep-range", s],
                 "capture": ["capture", s],
                 "demo": ["demo", "--setup", s, "--out", tmp / "demo"]}[command]
        return [*fixed, *[a(tmp) if callable(a) else a for a in extra]]
    return make


FLAG_CASES = [
    ("render", ["--spp", "0"], "spp"),
    ("render", ["--spp", "-4"], "spp"),
    ("render", ["--spp", "many"], "spp"),
    ("render", ["--spp", "1e12"], "spp"),
    ("render", ["--seed", "-1"], "seed"),
    ("render", ["--seed", "x"], "seed"),
    ("render", ["--f-number", "0"], "f-number"),
    ("render", ["--f-number", "nan"], "f-number"),
    ("render", ["--f-number", "inf"], "f-number"),
    ("render", ["--preview-size", "0"], "preview-size"),
    ("render", ["--aov", "normals"], "aov"),
    ("render", ["--mode", "fisheye"], "mode"),
    ("render", ["--bogus"], "bogus"),
    ("ipsf", ["--point", "inf", "0"], "point"),
    ("ipsf", ["--point", "nan", "0"], "point"),
    ("ipsf", ["--point", "1e9", "0"], "point"),
    ("ipsf", ["--radius", "-1"], "radius"),
    ("ipsf", ["--radius", "nan"], "radius"),
    ("ipsf", ["--radius", "1e9"], "radius"),
    ("ipsf", ["--radius", "5", "--angle", "nan"], "angle"),
    ("ipsf", ["--radius", "5", "--depth", "0"], "depth"),
    ("ipsf", ["--radius", "5", "--depth", "-100"], "depth"),
    ("ipsf", ["--radius", "5", "--depth", "nan"], "depth"),
    ("ipsf", ["--radius", "5", "--sensor-distance", "0"], "sensor-distance"),
    ("ipsf", ["--radius", "5", "--sensor-distance", "nan"], "sensor-distance"),
    ("ipsf", ["--radius", "5", "--planes", "0"], "planes"),
    ("ipsf", ["--radius", "5", "--time-samples", "0"], "time-samples"),
    ("ipsf", ["--radius", "5", "--rays", "0"], "rays"),
    ("ipsf", ["--radius", "5", "--rays", "-5"], "rays"),
    ("ipsf", ["--radius", "5", "--rays", "1e30"], "rays"),
    ("ipsf", ["--radius", "5", "--kernel-size", "100001"], "kernel"),
    ("ipsf", ["--radius", "5", "--kernel-size", "0"], "kernel"),
    ("ipsf", ["--radius", "5", "--seed", "-1"], "seed"),
    ("ipsf", ["--bank", "grid", "--grid", "0", "5"], "grid"),
    ("ipsf", ["--bank", "grid", "--grid", "5000", "5000"], ""),
    ("ipsf", ["--bank", "radial", "--radii", "0"], "radii"),
    ("ipsf", ["--radius", "5", "--motion-table", lambda t: t / "none.csv"], "none.csv"),
    ("ipsf", ["--radius", "5", "--motion-table",
              lambda t: write(t, "m.csv", "t,pos\nzero,one\n")], "m.csv"),
    ("ipsf", ["--radius", "5", "--motion-table",
              lambda t: write(t, "m.csv", "0,360\n1,359\n0.5,361\n")], "m.csv"),
    ("ipsf", ["--radius", "5", "--motion-table",
              lambda t: write(t, "m.csv", "0,nan\n1,361\n")], "m.csv"),
    ("table1", ["--ranges", "5:3"], "range"),
    ("table1", ["--ranges", "abc"], "range"),
    ("table1", ["--rays", "0"], "rays"),
    ("table1", ["--radii", "0"], "radii"),
    ("table1", ["--kernel-size", "0"], "kernel"),
    ("table1", ["--kernel-size", "100001"], "kernel"),
    ("dataset", ["--scenes", "0"], "scenes"),
    ("dataset", ["--scenes", "-3"], "scenes"),
    ("dataset", ["--scenes", "100000000"], "scenes"),
    ("dataset", ["--seed", "-5"], "seed"),
    ("dataset", ["--spp", "0", "1", "1", "1"], "spp"),
    ("dataset", ["--spp", "1", "1", "1"], "spp"),
    ("dataset", ["--lux", "0"], "lux"),
    ("dataset", ["--lux", "-2"], "lux"),
    ("dataset", ["--lux", "nan"], "lux"),
    ("dataset", ["--lux", "inf"], "lux"),
    ("dataset", ["--jobs", "0"], "jobs"),
    ("dataset", ["--executor", "slurm"], "executor"),
    ("sweep-range", ["--fov", "0"], "fov"),
    ("sweep-range", ["--fov", "400"], "fov"),
    ("sweep-range", ["--fov", "nan"], "fov"),
    ("sweep-range", ["--depth", "5000", "300"], "depth"),
    ("sweep-range", ["--depth", "-1", "10"], "depth"),
    ("sweep-range", ["--depth", "nan", "100"], "depth"),
    ("sweep-range", ["--depth", "0", "100"], "depth"),
    ("sweep-range", ["--plot", lambda t: t / "missing" / "fig.png"], "missing"),
    ("sweep-range", ["--plot", lambda t: t / "setup.toml"], "setup.toml"),
    ("capture", [], "port"),
    ("capture", ["--stage", "zaber:"], "stage"),
    ("capture", ["--stage", "galil:/dev/x"], "stage"),
    ("capture", ["--port", lambda t: t / "no-such-port"], "no-such-port"),
    ("capture", ["--port", lambda t: t / "no-such-port", "--out",
                 lambda t: t / "setup.toml"], "setup.toml"),
    ("capture", ["--port", lambda t: t / "no-such-port", "--out",
                 lambda t: write(t, "old.json", "{}")], "old.json"),
    ("demo", ["--spp-scale", "0"], "spp-scale"),
    ("demo", ["--spp-scale", "nan"], "spp-scale"),
    ("demo", ["--scenes", "0"], "scenes"),
]
for n, (command, extra, expect) in enumerate(FLAG_CASES):
    label = " ".join(a if isinstance(a, str) else "PATH" for a in extra) or "none"
    add(f"flags-{command}-{n:02d}-{label}", _flags(command, extra), expect)

add("flags-demo-missing-setup",
    lambda t: ["demo", "--setup", t / "nope.toml", "--out", t / "demo"], "nope.toml")
add("flags-bench-unknown", lambda t: ["bench", "gpu"], "gpu")
add("flags-unknown-command", lambda t: ["frobnicate"], "frobnicate")
add("flags-no-command", lambda t: [], "")


# --------------------------------------------------------------------------------------
# Input files: images and banks for deconvolve
# --------------------------------------------------------------------------------------
SIZE = 64


@pytest.fixture(scope="module")
def deconv_files(tmp_path_factory):
    """A small image and banks made by the tool itself (with their provenance)."""
    from mitsweep.deconv.synthetic import synthetic_radial_bank
    from mitsweep.io import write_exr
    from mitsweep.io.bank import save_bank

    from mitsweep.config import DEFAULT_SETUP, Sensor, setup_to_dict
    from mitsweep.io.bank import optics_sections

    d = tmp_path_factory.mktemp("corpus_deconv")
    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(SIZE, SIZE), pixel_pitch=0.018))
    sd = setup_to_dict(setup)
    rng = np.random.default_rng(0)
    img = rng.random((SIZE, SIZE)).astype(np.float32)
    write_exr(d / "image.exr", img, metadata={"pixel_pitch": 0.018, "setup": sd})
    # a bank that claims this setup's optics, so that the unmodified command succeeds
    # (test_corpus_baselines_succeed) and each case differs from it by one defect
    bank = replace(synthetic_radial_bank((SIZE, SIZE), size=9), optics=optics_sections(sd))
    save_bank(d / "bank.npz", bank)
    return d


def _deconv(extra_fn):
    def make(tmp: Path) -> list:
        src = Path(_DECONV_DIR[0])
        shutil.copy(src / "image.exr", tmp / "image.exr")
        shutil.copy(src / "bank.npz", tmp / "bank.npz")
        argv = ["deconvolve", tmp / "image.exr", "--bank", tmp / "bank.npz",
                "--out", tmp / "out.exr"]
        return extra_fn(tmp, argv)
    return make


_DECONV_DIR: list = []


def _write_exr(path: Path, array) -> Path:
    """An image through mitsweep's writer, with the baseline image's provenance."""
    from mitsweep.io import write_exr
    from mitsweep.io.exr import read_exr_header

    meta = read_exr_header(Path(_DECONV_DIR[0]) / "image.exr")
    write_exr(path, np.asarray(array, dtype=np.float32), metadata=meta)
    return path


def _raw_exr(path: Path, channels: dict, metadata: dict | None = None) -> Path:
    """Write channels with OpenEXR itself: mitsweep's writer refuses NaN and inf, but a
    file from elsewhere may hold them. ``metadata`` default: the baseline image's."""
    import OpenEXR

    from mitsweep.io.exr import read_exr_header

    if metadata is None:
        metadata = read_exr_header(Path(_DECONV_DIR[0]) / "image.exr")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    header.update({f"mitsweep:{k}": json.dumps(v) for k, v in metadata.items()})
    chans = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    with OpenEXR.File(header, chans) as f:
        f.write(str(path))
    return path


def _image_with(value, at=(3, 4)):
    """The baseline image with one pixel set to a non-finite ``value``."""
    def f(t, argv):
        img = np.ones((SIZE, SIZE), np.float32)
        img[at] = value
        _raw_exr(t / "image.exr", {"Y": img})
        return argv
    return f


def _huge_image(t, argv):
    _write_exr(t / "image.exr", np.full((SIZE, SIZE), 3e38, np.float32))
    return argv


def _truncated(name):
    def f(t, argv):
        p = t / name
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
        return argv
    return f


def _replace_file(name, data: bytes):
    def f(t, argv):
        (t / name).write_bytes(data)
        return argv
    return f


def _bank_edit(edit):
    """Rewrite the bank NPZ with ``edit(dict_of_arrays)`` applied."""
    def f(t, argv):
        p = t / "bank.npz"
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        edit(arrays)
        with open(p, "wb") as fh:
            np.savez(fh, **arrays)
        return argv
    return f


def _header_edit(edit):
    """Edit the bank's JSON header (whichever array holds it)."""
    def e(arrays):
        for k, v in arrays.items():
            if v.dtype.kind in "US" and v.ndim == 0:
                try:
                    h = json.loads(str(v))
                except json.JSONDecodeError:
                    continue
                edit(h)
                arrays[k] = np.array(json.dumps(h))
                return
        raise AssertionError("no JSON header in the bank")
    return _bank_edit(e)


def _drop(key):
    def f(h):
        h.pop(key, None)
    return f


def _set(key, value):
    def f(h):
        h[key] = value
    return f


def _kernels_edit(edit):
    def e(arrays):
        name = max(arrays, key=lambda k: arrays[k].size)
        arrays[name] = edit(arrays[name].copy())
    return _bank_edit(e)


def _nan_kernels(k):
    k.reshape(-1)[0] = np.nan
    return k


DECONV_CASES = [
    ("image-missing", lambda t, a: (t / "image.exr").unlink() or a, "image.exr"),
    ("image-truncated", _truncated("image.exr"), "image.exr"),
    ("image-not-exr", _replace_file("image.exr", b"not an exr file at all"), "image.exr"),
    ("image-empty", _replace_file("image.exr", b""), "image.exr"),
    ("image-toml", lambda t, a: [a[0], write(t, "s.toml", SPHERE), *a[2:]], "s.toml"),
    ("image-directory", lambda t, a: [a[0], t, *a[2:]], ""),
    ("image-nan", _image_with(np.nan), "nan"),
    ("image-inf", _image_with(np.inf, at=(0, 0)), "inf"),
    ("image-huge", _huge_image, "1e+20"),
    ("image-size-mismatch",
     lambda t, a: _write_exr(t / "image.exr", np.ones((SIZE + 8, SIZE), np.float32)) and a,
     "64x72"),
    ("bank-missing", lambda t, a: (t / "bank.npz").unlink() or a, "bank.npz"),
    ("bank-truncated", _truncated("bank.npz"), "bank.npz"),
    ("bank-not-npz", _replace_file("bank.npz", b"PK\x03\x04 garbage"), "bank.npz"),
    ("bank-text", _replace_file("bank.npz", b"hello"), "bank.npz"),
    ("bank-no-kind", _header_edit(_drop("kind")), "kind"),
    ("bank-bad-kind", _header_edit(_set("kind", "spiral")), "kind"),
    ("bank-no-pitch", _header_edit(_drop("pixel_pitch")), "pitch"),
    ("bank-nan-kernels", _kernels_edit(_nan_kernels), "nan"),
    ("bank-empty-kernels", _kernels_edit(lambda k: k[:0]), "no kernels"),
    ("nsr-zero", lambda t, a: [*a, "--nsr", "0"], "nsr"),
    ("nsr-negative", lambda t, a: [*a, "--nsr", "-1"], "nsr"),
    ("nsr-nan", lambda t, a: [*a, "--nsr", "nan"], "nsr"),
    ("nsr-huge", lambda t, a: [*a, "--nsr", "1e300"], "nsr"),
    ("nsr-inf", lambda t, a: [*a, "--nsr", "inf"], "nsr"),
    ("grid-zero", lambda t, a: [*a, "--method", "grid", "--grid", "0"], "grid"),
    ("grid-huge", lambda t, a: [*a, "--method", "grid", "--grid", "5000"], "at most"),
    ("center-nan", lambda t, a: [*a, "--center", "nan", "3"], "center"),
    ("center-outside", lambda t, a: [*a, "--center", "1e9", "3"], "center"),
    ("pitch-zero", lambda t, a: [*a, "--pixel-pitch", "0"], "pixel-pitch"),
    ("depth-word", lambda t, a: [*a, "--depth", "far"], "depth"),
    ("depth-negative", lambda t, a: [*a, "--depth", "-5"], "depth"),
    ("out-is-image", lambda t, a: [*a[:-1], t / "image.exr"], "image.exr"),
    ("out-is-bank", lambda t, a: [*a[:-1], t / "bank.npz"], "bank.npz"),
    ("out-missing-dir", lambda t, a: [*a[:-1], t / "nodir" / "o.exr"], "nodir"),
    ("out-is-directory", lambda t, a: [*a[:-1], t], ""),
]
for name, fn, expect in DECONV_CASES:
    add(f"deconvolve-{name}", _deconv(fn), expect)


# --------------------------------------------------------------------------------------
# Dataset manifests (evaluate), on a copy of a real tiny dataset
# --------------------------------------------------------------------------------------
_DATASET_DIR: list = []


@pytest.fixture(scope="module")
def tiny_dataset_dir(tmp_path_factory):
    from mitsweep.config import DEFAULT_SETUP, Sensor
    from mitsweep.pipeline import DatasetOptions, build_dataset

    root = tmp_path_factory.mktemp("corpus_ds") / "ds"
    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(48, 48), pixel_pitch=0.18))
    opts = DatasetOptions(scenes=1, spp={"pinhole": 1, "focused": 1, "sweep": 1, "stopped": 1},
                          bank_rays=1 << 12, light_levels_lux=(50.0,))
    build_dataset(setup, root, opts, progress=False)
    return root


def _manifest(edit):
    def make(tmp: Path) -> list:
        d = tmp / "ds"
        shutil.copytree(_DATASET_DIR[0], d)
        p = d / "manifest.json"
        m = json.loads(p.read_text())
        m = edit(m, d)
        if m is not None:
            p.write_text(json.dumps(m) if not isinstance(m, str) else m)
        return ["evaluate", d]
    return make


def _opt(key, value):
    def e(m, d):
        m["options"][key] = value
        return m
    return e


def _nan_exr(m, d):
    p = d / "scene_000" / "sweep.exr"
    from mitsweep.io import read_exr

    chans, meta = read_exr(p)
    for v in chans.values():
        v[0, 0] = np.nan
    _raw_exr(p, chans, meta)
    return m


def _item_rename(new):
    def e(m, d):
        name, item = next(iter(m["items"].items()))
        m["items"] = {new: item, **{k: v for k, v in m["items"].items() if k != name}}
        return m
    return e


MANIFEST_CASES = [
    ("list", lambda m, d: [m], "manifest"),
    ("string", lambda m, d: json.dumps("hello"), "manifest"),
    ("not-json", lambda m, d: "{not json", "manifest"),
    ("empty-file", lambda m, d: " ", "manifest"),
    ("options-list", lambda m, d: {**m, "options": [1, 2]}, "options"),
    ("items-list", lambda m, d: {**m, "items": [1, 2]}, "items"),
    ("options-missing", lambda m, d: {k: v for k, v in m.items() if k != "options"},
     "options"),
    ("scenes-huge", _opt("scenes", 100_000_000), "scenes"),
    ("scenes-negative", _opt("scenes", -3), "scenes"),
    ("scenes-zero", _opt("scenes", 0), "scenes"),
    ("scenes-string", _opt("scenes", "1"), "scenes"),
    ("scenes-float", _opt("scenes", 1.5), "scenes"),
    ("scenes-bool", _opt("scenes", True), "scenes"),
    ("scenes-more-than-present", _opt("scenes", 2), "scene_001"),
    ("lux-negative", _opt("light_levels_lux", [-50.0]), "light_levels"),
    ("item-escapes", _item_rename("../outside.exr"), "items"),
    ("item-absolute", _item_rename("/etc/passwd"), "items"),
    ("item-file-missing", lambda m, d: (d / "scene_000" / "sweep.exr").unlink() or m,
     "sweep.exr"),
    ("nan-image", _nan_exr, "sweep.exr"),
    ("no-manifest", lambda m, d: (d / "manifest.json").unlink() or None, "manifest"),
]
for name, fn, expect in MANIFEST_CASES:
    add(f"manifest-{name}", _manifest(fn), expect)

add("evaluate-missing-dir", lambda t: ["evaluate", t / "nothing"], "nothing")
add("evaluate-file-not-dir", lambda t: ["evaluate", write(t, "x.txt", "x")], "x.txt")


def _eval_out_is_manifest(t):
    d = t / "ds"
    shutil.copytree(_DATASET_DIR[0], d)
    return ["evaluate", d, "--out", d / "manifest.json"]


add("evaluate-out-is-manifest", _eval_out_is_manifest, "manifest.json")


def _dataset_into_other_setup(t):
    d = t / "ds"
    shutil.copytree(_DATASET_DIR[0], d)
    return ["dataset", ROOT / "scenes" / "paraboloid.toml", "--out", d]


add("dataset-dir-of-other-setup", _dataset_into_other_setup, "another setup")


def _dataset_out_is_file(t):
    return ["dataset", write(t, "setup.toml", SPHERE), "--out", t / "setup.toml"]


add("dataset-out-is-setup-file", _dataset_out_is_file, "setup.toml")

# outputs equal to inputs, and unwritable outputs, for the remaining writers
add("render-out-is-setup",
    lambda t: ["render", write(t, "setup.toml", SPHERE), "--mode", "pinhole",
               "--out", t / "setup.toml"], "setup.toml")
add("render-preview-is-setup",
    lambda t: ["render", write(t, "setup.toml", SPHERE), "--mode", "pinhole",
               "--out", t / "o.exr", "--preview", t / "setup.toml"], "setup.toml")
add("render-out-missing-dir",
    lambda t: ["render", write(t, "setup.toml", SPHERE), "--mode", "pinhole",
               "--out", t / "nodir" / "o.exr"], "nodir")
add("ipsf-out-is-setup",
    lambda t: ["ipsf", write(t, "setup.toml", SPHERE), "--radius", "5",
               "-o", t / "setup.toml"], "setup.toml")
add("ipsf-plot-is-setup",
    lambda t: ["ipsf", write(t, "setup.toml", SPHERE), "--radius", "5",
               "--plot", t / "setup.toml"], "setup.toml")
add("table1-plot-is-setup",
    lambda t: ["table1", write(t, "setup.toml", SPHERE), "--plot", t / "setup.toml"],
    "setup.toml")


# --------------------------------------------------------------------------------------
# The contract
# --------------------------------------------------------------------------------------
def _tree(root: Path) -> dict:
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        elif p.is_dir():
            out[rel] = "dir"
    return out


def test_corpus_baselines_succeed(tmp_path, capsys, monkeypatch, deconv_files,
                                  tiny_dataset_dir):
    """Each family's unmodified input works, so a refusal is caused by the one defect a
    case plants, not by a broken baseline."""
    _DECONV_DIR[:] = [deconv_files]
    _DATASET_DIR[:] = [tiny_dataset_dir]
    monkeypatch.chdir(tmp_path)
    assert main(["sweep-range", str(write(tmp_path, "setup.toml", toml_text(BASE)))]) == 0
    assert main([str(a) for a in _deconv(lambda t, a: a)(tmp_path)]) == 0
    assert (tmp_path / "out.exr").is_file()
    assert main([str(a) for a in _manifest(lambda m, d: m)(tmp_path)]) == 0
    capsys.readouterr()


def test_corpus_is_large_enough():
    assert len(CASES) >= 150
    assert len({c.id for c in CASES}) == len(CASES), "case ids must be unique"


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_cleanly(case, tmp_path, capsys, monkeypatch,
                                      deconv_files, tiny_dataset_dir):
    _DECONV_DIR[:] = [deconv_files]
    _DATASET_DIR[:] = [tiny_dataset_dir]
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = [str(a) for a in case.make(work)]
    before = _tree(work)
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rc = main(argv)
        except SystemExit as exc:  # argparse
            rc = exc.code
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, f"exit status {rc}; stderr: {err!r}"
    assert len(lines) == 1, f"expected one line on stderr, got {lines!r}"
    assert "Traceback" not in err
    assert "error" in lines[0].lower()
    assert case.expect.lower() in lines[0].lower(), lines[0]
    assert not caught, [str(w.message) for w in caught]
    assert out == ""
    assert _tree(work) == before, "a refused command changed the files"
