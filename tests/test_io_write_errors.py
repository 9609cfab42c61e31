"""Failed writes: one line naming the file and the cause, nothing half-written.

Two ways to fill the disk: a real 4-64 KiB tmpfs mounted by the test (needs root and
CAP_SYS_ADMIN; skipped with the reason otherwise) and an injected ENOSPC (monkeypatch),
which runs everywhere. OpenEXR reports a full disk as a RuntimeError quoting strerror;
PNG and JSON writes raise OSError.
"""

import errno
import hashlib
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from conftest import SCENES, run_cli
from mitsweep import pipeline
from mitsweep.cli.main import main
from mitsweep.io import WriteError, read_exr, write_exr, write_text_atomic
from mitsweep.io.png import write_png
from mitsweep.pipeline import build_dataset, load_manifest
from test_pipeline_dataset import TINY, TINY_OPTS

ENOSPC_TEXT = os.strerror(errno.ENOSPC)


def tiny_setup_toml(directory: Path) -> Path:
    """The paper sphere on a 48 px frame of 0.18 mm pixels (renders in about a second)."""
    text = (SCENES / "sphere.toml").read_text()
    text = text.replace("resolution = [512, 512]", "resolution = [48, 48]")
    text = text.replace("pixel_pitch = 0.018", "pixel_pitch = 0.18")
    assert "[48, 48]" in text and "0.18\n" in text
    path = directory / "tiny.toml"
    path.write_text(text)
    return path


@pytest.fixture
def tmpfs(tmp_path):
    """Mount a tmpfs of the requested size (KiB) under tmp_path; unmounted afterwards."""
    mounted = []

    def mount(size_kib: int, *options: str) -> Path:
        if os.geteuid() != 0:
            pytest.skip("mounting a small tmpfs needs root")
        d = tmp_path / f"tmpfs{len(mounted)}"
        d.mkdir()
        opts = ",".join((f"size={size_kib}k", *options))
        proc = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(d)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here: {proc.stderr.strip()}")
        mounted.append(d)
        return d

    yield mount
    for d in reversed(mounted):
        subprocess.run(["umount", str(d)], check=True)


def _noise(shape) -> np.ndarray:
    # Incompressible pixels: the ZIP-compressed EXR stays about as large as the data.
    return np.random.default_rng(0).random(shape).astype(np.float32)


WRITERS = {
    "exr": lambda p: write_exr(p, _noise((128, 128, 3))),          # ~190 KiB
    "png": lambda p: write_png(p, _noise((256, 256, 3)), white=1.0),  # ~190 KiB
    "json": lambda p: write_text_atomic(p, json.dumps(_noise(20000).tolist())),  # ~400 KiB
}


def _no_temporaries(directory: Path) -> bool:
    return not any(p.name.startswith(".") for p in directory.rglob("*"))


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_full_tmpfs_gives_enospc_naming_the_target(tmpfs, kind):
    d = tmpfs(64)
    target = d / f"out.{kind}"
    with pytest.raises(WriteError) as info:
        WRITERS[kind](target)
    assert info.value.errno == errno.ENOSPC
    assert str(info.value) == f"cannot write {target}: {ENOSPC_TEXT}"
    assert list(d.iterdir()) == []  # neither the target nor the temporary


@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_read_only_file_system_is_named(tmpfs, kind):
    d = tmpfs(64, "ro")
    target = d / f"out.{kind}"
    with pytest.raises(WriteError) as info:
        WRITERS[kind](target)
    assert info.value.errno == errno.EROFS
    assert str(info.value).startswith(f"cannot write {target}: ")
    assert "read-only file system" in str(info.value).lower()


def _fail_exr_writes(monkeypatch, message: str, after: int = 0):
    """OpenEXR.File.write raises ``message`` (as OpenEXR does) from its ``after``-th call,
    having written a partial file first, as a real full disk leaves one."""
    real = OpenEXR.File.write
    calls = []

    def write(self, filename):
        calls.append(filename)
        if len(calls) <= after:
            return real(self, filename)
        Path(filename).write_bytes(b"v/1\x01partial")
        raise RuntimeError(message.format(filename=filename))

    monkeypatch.setattr(OpenEXR.File, "write", write)
    return calls


def test_injected_exr_enospc_keeps_the_previous_file(tmp_path, monkeypatch):
    target = tmp_path / "out.exr"
    write_exr(target, np.ones((4, 4), np.float32), metadata={"run": 1})
    _fail_exr_writes(monkeypatch, 'Failed to write pixel data to image file "{filename}". '
                                  'No space left on device.')
    with pytest.raises(WriteError) as info:
        write_exr(target, np.zeros((4, 4), np.float32), metadata={"run": 2})
    assert info.value.errno == errno.ENOSPC
    assert str(info.value) == f"cannot write {target}: {ENOSPC_TEXT}"
    assert read_exr(target)[1] == {"run": 1}  # the earlier file, whole
    assert _no_temporaries(tmp_path)


def test_unrecognised_exr_failure_is_an_io_error(tmp_path, monkeypatch):
    _fail_exr_writes(monkeypatch, "Cannot write image file {filename}: something odd.")
    with pytest.raises(WriteError) as info:
        write_exr(tmp_path / "x.exr", np.zeros((4, 4), np.float32))
    # The directory has room: the cause cannot be told, so it is a generic I/O error.
    assert info.value.errno == errno.EIO
    assert _no_temporaries(tmp_path)


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EIO])
@pytest.mark.parametrize("kind", sorted(WRITERS))
def test_injected_error_at_flush_keeps_the_previous_file(tmp_path, monkeypatch, kind, code):
    """Delayed-allocation file systems, quotas and failing disks report the error when the
    data is flushed."""
    target = tmp_path / f"out.{kind}"
    target.write_bytes(b"previous")

    def fail(fd):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(os, "fsync", fail)   # the flush the writer asks of the system
    with pytest.raises(WriteError) as info:
        WRITERS[kind](target)
    assert info.value.errno == code
    assert str(info.value) == f"cannot write {target}: {os.strerror(code)}"
    assert target.read_bytes() == b"previous"
    assert _no_temporaries(tmp_path)


def test_permission_denied_names_the_target(tmp_path, monkeypatch):
    """EACCES where the temporary is created (root bypasses directory modes, so the
    refusal is injected: an ACL or a security module would give the same)."""
    import tempfile

    def denied(*args, **kwargs):
        raise PermissionError(errno.EACCES, os.strerror(errno.EACCES))

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(WriteError) as info:
        write_text_atomic(tmp_path / "x.json", "{}")
    assert str(info.value) == f"cannot write {tmp_path / 'x.json'}: Permission denied"


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_unwritable_directory_is_named(tmp_path):
    d = tmp_path / "ro"
    d.mkdir(mode=0o555)
    with pytest.raises(WriteError, match=f"cannot write {d / 'x.json'}: directory .* is not "
                                         f"writable"):
        write_text_atomic(d / "x.json", "{}")


def test_write_error_pickles_for_process_executors():
    import pickle

    exc = pickle.loads(pickle.dumps(WriteError(errno.ENOSPC, ENOSPC_TEXT, "a/b.exr")))
    assert isinstance(exc, WriteError) and exc.errno == errno.ENOSPC
    assert str(exc) == f"cannot write a/b.exr: {ENOSPC_TEXT}"


# -- commands ---------------------------------------------------------------------------

def test_render_to_a_full_tmpfs_is_one_line(tmpfs, tmp_path):
    d = tmpfs(4)  # one page: a 48 px render with texture noise does not fit
    setup = tiny_setup_toml(tmp_path)
    rc, _, err = run_cli("render", setup, "--mode", "pinhole", "--spp", "1",
                         "--out", d / "x.exr")
    assert rc == 2, err
    assert err.strip() == f"mitsweep: error: cannot write {d / 'x.exr'}: {ENOSPC_TEXT}"
    assert list(d.iterdir()) == []


def test_render_with_injected_enospc_is_one_line(tmp_path, monkeypatch, capsys):
    setup = tiny_setup_toml(tmp_path)
    out = tmp_path / "x.exr"
    _fail_exr_writes(monkeypatch, 'Failed to write pixel data to image file "{filename}". '
                                  'No space left on device.')
    rc = main(["render", str(setup), "--mode", "pinhole", "--spp", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.strip() == f"mitsweep: error: cannot write {out}: {ENOSPC_TEXT}"
    assert not out.exists() and _no_temporaries(tmp_path)


def _assert_consistent_partial_dataset(root: Path) -> dict:
    manifest = load_manifest(root)  # valid against the schema
    assert "complete" not in manifest
    for name, item in manifest["items"].items():
        assert item["sha256"] == hashlib.sha256((root / name).read_bytes()).hexdigest(), name
    assert _no_temporaries(root)  # no temporaries and no lock left behind
    return manifest


def test_dataset_with_injected_enospc_leaves_a_consistent_manifest(tmp_path, monkeypatch,
                                                                   capsys):
    root = tmp_path / "ds"
    setup = tiny_setup_toml(tmp_path)
    # The first four EXRs (the calibration scene's pinhole and sweep, the scene's pinhole
    # and focused) are written, the fifth fails.
    _fail_exr_writes(monkeypatch, 'Failed to write pixel data to image file "{filename}". '
                                  'No space left on device.', after=4)
    rc = main(["dataset", str(setup), "--out", str(root), "--spp", "1", "1", "1", "1",
               "--lux", "50"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert err[-1] == (f"mitsweep: error: cannot write {root / 'scene_000' / 'sweep.exr'}: "
                       f"{ENOSPC_TEXT}")
    manifest = _assert_consistent_partial_dataset(root)
    assert set(manifest["items"]) == {"bank.npz", "calibration/pinhole.exr",
                                      "calibration/sweep.exr", "calibration/mismatch.json",
                                      "scene_000/pinhole.exr", "scene_000/focused.exr"}
    assert not (root / "scene_000" / "sweep.exr").exists()


def test_dataset_on_a_full_tmpfs_leaves_a_consistent_manifest(tmpfs):
    root = tmpfs(96)  # the tiny dataset needs ~230 KiB
    with pytest.raises(WriteError) as info:
        build_dataset(TINY, root, TINY_OPTS, progress=False)
    assert info.value.errno == errno.ENOSPC
    assert Path(info.value.filename).parent in (root, root / "calibration",
                                                root / "scene_000")
    manifest = _assert_consistent_partial_dataset(root)
    assert 1 <= len(manifest["items"]) < len(pipeline.item_names(TINY_OPTS))
