"""One run per dataset directory: the advisory lock, with real processes.

A second ``mitsweep dataset`` on a directory in use is refused naming the holder (or
waits with ``--wait``); a holder killed with SIGKILL leaves a record that the next run
takes over. The concurrent runs are made deterministic by stopping the first run
(SIGSTOP) once it holds the lock, so that it is certainly still running when the second
one starts.
"""

import hashlib
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT
from mitsweep import pipeline
from mitsweep.io.lock import LOCK_FILE, DirectoryLock, DirectoryLocked
from mitsweep.pipeline import item_names, load_manifest
from test_io_write_errors import tiny_setup_toml

TINY_ARGS = ["--spp", "1", "1", "1", "1", "--lux", "50"]


def test_second_lock_is_refused_naming_the_holder(tmp_path):
    with DirectoryLock(tmp_path, command="first run") as first:
        assert first.held
        record = json.loads((tmp_path / LOCK_FILE).read_text())
        assert record["pid"] == os.getpid() and record["command"] == "first run"
        # flock locks belong to open file descriptions: a second one conflicts even
        # within this process, as another process's would.
        with pytest.raises(DirectoryLocked) as info:
            DirectoryLock(tmp_path).acquire()
        msg = str(info.value)
        assert f"pid {os.getpid()} on {socket.gethostname()}, since {record['since']}" in msg
        assert "first run" in msg and "--wait" in msg
    assert not (tmp_path / LOCK_FILE).exists()  # released and removed
    with DirectoryLock(tmp_path) as again:
        assert again.taken_over is None


def test_wait_gives_up_after_its_timeout(tmp_path):
    with DirectoryLock(tmp_path):
        t0 = time.monotonic()
        with pytest.raises(DirectoryLocked, match="in use by another mitsweep run: .*; gave "
                                                  "up after waiting 0.5 s"):
            DirectoryLock(tmp_path, wait=0.5).acquire()
        assert time.monotonic() - t0 >= 0.5      # it waited the 0.5 s asked, not less


class _Messages(logging.Handler):
    """The messages one logger emits, whatever other tests in this process did to the
    loggers above it (their levels, handlers or propagation: caplog listens at the root,
    and a suite run once lost this warning there)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


def test_record_left_by_a_dead_holder_is_taken_over(tmp_path):
    # What a SIGKILLed run leaves: its record in a file nobody holds a flock on.
    dead = {"pid": 999999, "host": "elsewhere", "since": "2026-01-01T00:00:00+00:00",
            "command": "mitsweep dataset x"}
    (tmp_path / LOCK_FILE).write_text(json.dumps(dead))
    log = logging.getLogger("mitsweep.io.lock")
    heard, level = _Messages(), log.level
    log.addHandler(heard)
    log.setLevel(logging.WARNING)  # what it says at WARNING, whatever its parents' levels
    try:
        with DirectoryLock(tmp_path) as lock:
            assert lock.taken_over == dead
            assert json.loads((tmp_path / LOCK_FILE).read_text())["pid"] == os.getpid()
    finally:
        log.removeHandler(heard)
        log.setLevel(level)
    assert any("pid 999999 on elsewhere" in m and "without releasing" in m
               for m in heard.messages), heard.messages


def _start_dataset(setup: Path, root: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "mitsweep", "dataset", str(setup),
                             "--out", str(root), *TINY_ARGS, *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT)


def _wait_for_lock(proc: subprocess.Popen, root: Path, timeout: float = 120.0) -> dict:
    """The lock record of ``proc`` once it holds the directory's lock."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            record = json.loads((root / LOCK_FILE).read_text())
        except (FileNotFoundError, ValueError):  # not there yet, or being written
            record = {}
        if record.get("pid") == proc.pid:
            return record
        time.sleep(0.05)
    proc.kill()
    pytest.fail("the dataset run never took the lock")


def _assert_complete_and_verified(root: Path) -> None:
    manifest = load_manifest(root)
    assert manifest["complete"] is True
    assert set(manifest["items"]) == set(item_names(pipeline.options_from_dict(
        manifest["options"])))
    for name, item in manifest["items"].items():
        assert item["sha256"] == hashlib.sha256((root / name).read_bytes()).hexdigest(), name
    assert not (root / LOCK_FILE).exists()


def test_concurrent_dataset_runs_one_refused_one_completes(tmp_path):
    setup = tiny_setup_toml(tmp_path)
    root = tmp_path / "ds"
    first = _start_dataset(setup, root)
    try:
        record = _wait_for_lock(first, root)
        os.kill(first.pid, signal.SIGSTOP)  # certainly still holding the lock
        second = subprocess.run([sys.executable, "-m", "mitsweep", "dataset", str(setup),
                                 "--out", str(root), *TINY_ARGS],
                                capture_output=True, text=True, cwd=ROOT, timeout=300)
        waiter = _start_dataset(setup, root, "--wait", "300")
        waiting = waiter.stderr.readline()  # blocks until it reports that it waits
    finally:
        os.kill(first.pid, signal.SIGCONT)
    out, err = first.communicate(timeout=600)
    assert first.returncode == 0, err
    assert second.returncode == 2
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in second.stderr
    assert lines[0] == (f"mitsweep: error: {root} is in use by another mitsweep run: pid "
                        f"{first.pid} on {record['host']}, since {record['since']} "
                        f"({record['command']}); wait for it to finish or pass --wait")
    # The waiting run gets the lock after the first and finds everything done.
    assert f"is in use by pid {first.pid}" in waiting and "waiting up to 300 s" in waiting
    w_out, w_err = waiter.communicate(timeout=600)
    assert waiter.returncode == 0, waiting + w_err
    _assert_complete_and_verified(root)


@pytest.mark.slow   # 10 s; the concurrent runs' test above stays in the default run
def test_sigkilled_holder_is_taken_over_by_the_next_run(tmp_path):
    setup = tiny_setup_toml(tmp_path)
    root = tmp_path / "ds"
    victim = _start_dataset(setup, root)
    record = _wait_for_lock(victim, root)
    victim.kill()  # SIGKILL: no chance to release anything
    victim.communicate()
    assert victim.returncode == -signal.SIGKILL
    assert json.loads((root / LOCK_FILE).read_text()) == record  # the stale record
    proc = subprocess.run([sys.executable, "-m", "mitsweep", "dataset", str(setup),
                           "--out", str(root), *TINY_ARGS],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert (f"taking over the lock of pid {victim.pid} on {record['host']}, since "
            f"{record['since']}") in proc.stderr
    assert "killed or crashed" in proc.stderr
    _assert_complete_and_verified(root)
