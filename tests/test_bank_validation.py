"""Banks are validated whole: every array, and every archive member's declared size.

Each case is a bank made by mitsweep with one defect planted, run through ``deconvolve``
(the command that reads banks) and through :func:`mitsweep.io.bank.load_bank`: refused
in one line naming the file and the array, exit 2, nothing written. Before, NaN depths,
NaN points, NaN vignetting and reversed radii deconvolved with exit 0, string depths and
radii <= 0 ended in tracebacks, and a zip bomb was inflated whole.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from cli_contract import refused
from mitsweep.io.bank import BankError, load_bank, save_bank
from mitsweep.resources import MAX_MEMORY_ENV, ResourceError

SIZE = 32


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """A small image and a radial bank for it (with vignetting), which deconvolve."""
    from mitsweep.config import DEFAULT_SETUP, Sensor, setup_to_dict
    from mitsweep.deconv.synthetic import synthetic_radial_bank
    from mitsweep.io import write_exr
    from mitsweep.io.bank import optics_sections

    d = tmp_path_factory.mktemp("banks")
    setup = replace(DEFAULT_SETUP, sensor=Sensor(resolution=(SIZE, SIZE), pixel_pitch=0.018))
    sd = setup_to_dict(setup)
    write_exr(d / "image.exr", np.random.default_rng(0).random((SIZE, SIZE)).astype(np.float32),
              metadata={"pixel_pitch": 0.018, "setup": sd})
    bank = synthetic_radial_bank((SIZE, SIZE), n_radii=5, size=7)
    bank = replace(bank, optics=optics_sections(sd),
                   vignetted=np.zeros((bank.kernels.shape[0], bank.kernels.shape[1])))
    save_bank(d / "bank.npz", bank)
    return d


def _arrays(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _write(path: Path, arrays: dict) -> None:
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _set(key, fn):
    def edit(a):
        a[key] = fn(a[key].copy())
    return edit


def _nan_at(a, index=0):
    a.reshape(-1)[index] = np.nan
    return a


# (id, edit of the arrays, words the message must hold)
ARRAY_CASES = [
    ("depths-nan", _set("depths_mm", _nan_at), "depths_mm"),
    ("depths-negative", _set("depths_mm", lambda d: -d), "depths_mm"),
    ("depths-zero", _set("depths_mm", lambda d: d * 0), "depths_mm"),
    ("depths-strings", _set("depths_mm", lambda d: np.array(["far"] * d.size)), "depths_mm"),
    ("points-nan", _set("points_uv", _nan_at), "points_uv"),
    ("points-inf", _set("points_uv", lambda p: p + np.inf), "points_uv"),
    ("points-strings", _set("points_uv", lambda p: p.astype(str)), "points_uv"),
    ("vignetted-nan", _set("vignetted", _nan_at), "vignetted"),
    ("vignetted-above-1", _set("vignetted", lambda v: v + 2), "vignetted"),
    ("vignetted-shape", _set("vignetted", lambda v: v[:, :1]), "vignetted"),
    ("radii-reversed", _set("radii_mm", lambda r: r[::-1].copy()), "radii_mm"),
    ("radii-all-negative", _set("radii_mm", lambda r: -r[::-1] - 1), "radii_mm"),
    ("radii-nan", _set("radii_mm", _nan_at), "radii_mm"),
    ("radii-repeated", _set("radii_mm", lambda r: r * 0), "radii_mm"),
]


def _npz_bytes(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return buf.getvalue()


def _npy_header(shape, descr="<f8", version=(1, 0)) -> bytes:
    buf = io.BytesIO()
    header = {"descr": descr, "fortran_order": False, "shape": tuple(shape)}
    if version == (1, 0):
        np.lib.format.write_array_header_1_0(buf, header)
    else:
        np.lib.format.write_array_header_2_0(buf, header)
    return buf.getvalue()


_BOMBS: dict[bytes, bytes] = {}  # the archive per bank: deflating 1 GiB takes ~3 s


def _zip_bomb(path: Path, arrays: dict) -> None:
    """The bank plus a member that is not an array: 1 GiB of zeros deflated to ~1 MiB.

    Built once per bank and reused: the three tests that plant it read the same bytes.
    """
    key = hashlib.sha256(b"".join(k.encode() + _save(v) for k, v in sorted(arrays.items())))
    if key.digest() not in _BOMBS:
        _BOMBS[key.digest()] = _zip_bomb_bytes(arrays)
    path.write_bytes(_BOMBS[key.digest()])


def _zip_bomb_bytes(arrays: dict) -> bytes:
    blob = io.BytesIO()
    with zipfile.ZipFile(blob, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for k, v in arrays.items():
            with zf.open(f"{k}.npy", "w") as m:
                np.lib.format.write_array(m, v)
        with zf.open("padding", "w", force_zip64=True) as m:  # deflated by zipfile
            step = bytes(1 << 24)
            for _ in range(64):
                m.write(step)
    return blob.getvalue()


def _declares_huge(path: Path, arrays: dict) -> None:
    """The kernels' header declares 2 GiB of float64; the member holds a few bytes."""
    members = {}
    for k, v in arrays.items():
        b = io.BytesIO()
        np.lib.format.write_array(b, v)
        members[f"{k}.npy"] = b.getvalue()
    members["kernels.npy"] = _npy_header((1, 5, 16385, 16385)) + bytes(64)
    path.write_bytes(_npz_bytes(members))


def _object_member(path: Path, arrays: dict) -> None:
    members = {f"{k}.npy": _save(v) for k, v in arrays.items()}
    members["extra.npy"] = _npy_header((1,), descr="|O") + b"\x80\x04N."
    path.write_bytes(_npz_bytes(members))


def _npy_v3(path: Path, arrays: dict) -> None:
    members = {f"{k}.npy": _save(v) for k, v in arrays.items()}
    members["extra.npy"] = b"\x93NUMPY\x03\x00" + _npy_header((1,))[8:]
    path.write_bytes(_npz_bytes(members))


def _save(v) -> bytes:
    b = io.BytesIO()
    np.lib.format.write_array(b, np.asarray(v), allow_pickle=False)
    return b.getvalue()


# (id, writer of the file from the good arrays, words the message must hold)
FILE_CASES = [
    ("zip-bomb-member", _zip_bomb, "'padding' is not a .npy"),
    ("declares-2GiB", _declares_huge, "MITSWEEP_MAX_MEMORY_GB"),
    ("object-member", _object_member, "Python objects"),
    ("npy-format-3", _npy_v3, "format 3.0"),
]


def _case_bank(tmp: Path, good: Path, case) -> Path:
    arrays = _arrays(good / "bank.npz")
    bank = tmp / "bank.npz"
    if case in FILE_CASES:
        case[1](bank, arrays)
    else:
        case[1](arrays)
        _write(bank, arrays)
    return bank


ALL = ARRAY_CASES + FILE_CASES


@pytest.mark.parametrize("case", ALL, ids=[c[0] for c in ALL])
def test_corrupt_bank_is_refused_by_deconvolve(case, good, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, "1")
    bank = _case_bank(tmp_path, good, case)
    image = tmp_path / "image.exr"
    image.write_bytes((good / "image.exr").read_bytes())
    before = sorted(p.name for p in tmp_path.iterdir())
    line = refused(capsys, ["deconvolve", image, "--bank", bank, "--out", tmp_path / "o.exr"])
    assert str(bank) in line and case[2] in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == before


@pytest.mark.parametrize("case", ALL, ids=[c[0] for c in ALL])
def test_load_bank_names_the_array(case, good, tmp_path, monkeypatch):
    monkeypatch.setenv(MAX_MEMORY_ENV, "1")
    bank = _case_bank(tmp_path, good, case)
    with pytest.raises((BankError, ResourceError)) as info:
        load_bank(bank)
    assert str(info.value).startswith(f"{bank}: ") and case[2] in str(info.value)


def test_the_good_bank_loads_and_deconvolves(good, tmp_path, capsys):
    """The baseline every case differs from by one defect."""
    from mitsweep.cli.main import main

    bank = load_bank(good / "bank.npz")
    assert bank.vignetted.shape == bank.kernels.shape[:2]
    assert main(["deconvolve", str(good / "image.exr"), "--bank", str(good / "bank.npz"),
                 "--out", str(tmp_path / "o.exr")]) == 0
    capsys.readouterr()


def test_zip_bomb_peak_stays_small(good, tmp_path):
    """The 1 GiB member is refused by name before it is inflated (before: 1.6 GiB)."""
    from test_memory_gate import _MEASURED, _peak_of

    bank = tmp_path / "bank.npz"
    _zip_bomb(bank, _arrays(good / "bank.npz"))
    code = _MEASURED.replace("from mitsweep.cli.main import main", """
from mitsweep.io.bank import BankError, load_bank
def main(argv):
    try:
        load_bank(argv[0])
    except BankError:
        return 2
    return 0""")
    rc, peak, err = _peak_of([bank], code)
    assert rc == 2 and peak < 300 * 2**20, (rc, peak / 2**20, err)


def test_header_json_is_untouched_by_the_edits(good):
    """The cases edit arrays only: the JSON header still parses."""
    header = json.loads(str(_arrays(good / "bank.npz")["header"]))
    assert header["kind"] == "radial"
