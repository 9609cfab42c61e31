"""The generic runner on toy tasks (bytes derived from their parameters): the task
graph, shards and their merge, lost workers retried (real processes killed by PID, a
real Dask LocalCluster), failures, logs. Fast: no rendering.

The toy tasks live in this module so that worker processes (spawned pools, Dask
workers) import them by name, as they import the dataset's tasks.
"""

import concurrent.futures as cf
import hashlib
import json
import logging
import multiprocessing
import os
import re
import signal
import threading
import time
from pathlib import Path

import pytest

from mitsweep.io import write_bytes_atomic
from mitsweep.pipeline.runner import (LOG_DIR, MANIFEST, SHARD_DIR, DatasetError, Shard, Task,
                                      read_task_log, run_tasks, sha256)

logger = logging.getLogger("mitsweep.tests.toy")
HEADER = {"format": "toy/1", "setup": {"name": "toy"}}


def make_bytes(context, out: Path, *, value: int, delay_s: float = 0.0, **inputs) -> dict:
    """A file of the value, the context and the inputs' bytes (a deterministic item)."""
    time.sleep(delay_s)
    data = f"{context}:{value}:".encode() + b"".join(
        Path(p).read_bytes() for _, p in sorted(inputs.items()))
    # atomically, as the dataset's tasks write (Task's contract): two shards at once both
    # make the shared item, and one hashed the other's half-written file (a flaky CI run)
    write_bytes_atomic(out, hashlib.sha256(data).digest() * 64)
    return {"toy_s": delay_s}


def die_once(context, out: Path, *, value: int, marker: str) -> dict:
    """SIGKILL this worker the first time (as if the machine lost it), then work."""
    m = Path(marker)
    if not m.exists():
        m.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return make_bytes(context, out, value=value)


def always_die(context, out: Path, *, value: int) -> dict:
    os.kill(os.getpid(), signal.SIGKILL)


def fail(context, out: Path, *, value: int) -> dict:
    raise ValueError(f"toy failure {value}")


def warn(context, out: Path, *, value: int) -> dict:
    logger.warning("toy warning %d from pid %d", value, os.getpid())
    return make_bytes(context, out, value=value)


def announce_and_wait(context, out: Path, *, value: int, started_dir: str) -> dict:
    """Say which process runs it (a file named by its pid), then take a while."""
    (Path(started_dir) / f"{value}.{os.getpid()}").write_text("")
    return make_bytes(context, out, value=value, delay_s=1.5)


def toy_plan(groups: int = 3, fn=make_bytes, **extra) -> list[Task]:
    """A shared item, then per group: a, and b from a and the shared item."""
    tasks = [Task("shared.bin", make_bytes, {"value": 0})]
    for g in range(groups):
        tasks.append(Task(f"g{g}/a.bin", fn, {"value": 10 * g + 1, **extra}, group=g))
        tasks.append(Task(f"g{g}/b.bin", make_bytes, {"value": 10 * g + 2},
                          {"first": f"g{g}/a.bin", "shared": "shared.bin"}, group=g))
    return tasks


def read_toy(path: Path) -> dict:
    return json.loads(Path(path).read_text())


def same_setup_as(header):
    def check(manifest, path):
        if manifest["setup"] != header["setup"]:
            raise DatasetError(f"{path}: another setup")
    return check


def run(root, tasks, header=HEADER, **kw):
    kw.setdefault("progress", False)
    return run_tasks(root, tasks, "ctx", header, read_manifest=read_toy,
                     check_header=same_setup_as(header), **kw)


def files_of(root: Path) -> dict:
    """Every file but the logs, with its SHA-256."""
    return {p.relative_to(root).as_posix(): sha256(p) for p in sorted(root.rglob("*"))
            if p.is_file() and LOG_DIR not in p.relative_to(root).parts}


def spawn_pool(n=2):
    return cf.ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("spawn"))


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    root = tmp_path_factory.mktemp("serial")
    run(root, toy_plan())
    return files_of(root)


def test_serial_run_is_complete_with_checksums_and_no_run_values(tmp_path, serial):
    manifest = run(tmp_path, toy_plan())
    assert manifest["complete"] is True and list(manifest["items"]) == sorted(manifest["items"])
    entry = manifest["items"]["g1/b.bin"]
    # The task's parameters and its inputs' names are its entry: declared once.
    assert entry["params"] == {"value": 12, "first": "g1/a.bin", "shared": "shared.bin"}
    assert entry["sha256"] == sha256(tmp_path / "g1/b.bin") and entry["bytes"] == 2048
    assert "seconds" not in entry  # times, hosts and pids are in the logs only
    log = read_task_log(tmp_path, "g1/b.bin")
    assert log["status"] == "done" and log["pid"] == os.getpid() and log["attempt"] == 1
    assert log["sha256"] == entry["sha256"] and "toy_s" in log
    assert files_of(tmp_path) == serial


def test_changed_parameters_redo_only_their_items(tmp_path):
    run(tmp_path, toy_plan())
    before = read_toy(tmp_path / MANIFEST)["items"]
    changed = toy_plan()
    changed[1] = Task("g0/a.bin", make_bytes, {"value": 99}, group=0)
    after = run(tmp_path, changed)["items"]
    redone = {n for n in after if after[n]["sha256"] != before[n]["sha256"]}
    assert redone == {"g0/a.bin", "g0/b.bin"}  # b reads a: its bytes change too
    assert after["g0/a.bin"]["params"] == {"value": 99}


@pytest.mark.parametrize("count", [2, 3])
def test_shards_give_the_directory_of_one_run(tmp_path, serial, count):
    for k in range(1, count + 1):
        m = run(tmp_path, toy_plan(), shard=Shard(k, count))
        assert m.get("complete") is (True if k == count else None)
    assert files_of(tmp_path) == serial  # the manifest too; the shard manifests are gone
    assert not (tmp_path / SHARD_DIR).exists()


def test_a_shard_runs_its_groups_and_what_they_need(tmp_path):
    run(tmp_path, toy_plan(groups=4), shard=Shard(2, 3))
    shard_manifest = read_toy(tmp_path / SHARD_DIR / "2-of-3" / MANIFEST)
    assert set(shard_manifest["items"]) == {"shared.bin", "g1/a.bin", "g1/b.bin"}
    partial = read_toy(tmp_path / MANIFEST)
    assert "complete" not in partial and set(partial["items"]) == set(shard_manifest["items"])
    # A run without --shard adopts what the shard made and finishes the rest.
    calls = []
    tasks = [Task(t.name, t.fn, {**t.params}, t.inputs, t.group) for t in toy_plan(groups=4)]
    m = run(tmp_path, tasks, executor=_Recording(calls))
    assert m["complete"] is True
    assert sorted(calls) == sorted(n for n in m["items"] if n not in shard_manifest["items"])


class _Recording(cf.ThreadPoolExecutor):
    def __init__(self, calls):
        super().__init__(1)
        self.calls = calls

    def submit(self, fn, task, *args):
        self.calls.append(task.name)
        return super().submit(fn, task, *args)


def test_concurrent_shards_write_one_directory(tmp_path, serial):
    """Both shards at once (threads of this process, each with its own lock): the
    shared item is made by both with the same bytes, and the merge completes."""
    with cf.ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda k: run(tmp_path, toy_plan(), shard=Shard(k, 2)),
                                (1, 2)))
    assert any(r.get("complete") for r in results)
    assert files_of(tmp_path) == serial


@pytest.mark.parametrize("text", ["0/2", "3/2", "1", "a/b", "1/0", "-1/2", "1/2/3", ""])
def test_bad_shard_is_named(text):
    with pytest.raises(DatasetError, match=r"^shard: must be K/N with 1 <= K <= N"):
        Shard.parse(text)


def test_process_worker_killed_mid_task_is_retried(tmp_path, serial):
    marker = tmp_path / "killed"
    root = tmp_path / "ds"
    tasks = toy_plan()
    tasks[3] = Task("g1/a.bin", die_once, {"value": 11, "marker": str(marker)}, group=1)
    pool = _restarting()
    try:
        m = run(root, tasks, executor=pool)
    finally:
        pool.shutdown()
    assert marker.exists() and m["complete"] is True
    assert read_task_log(root, "g1/a.bin")["attempt"] >= 2
    # The marker parameter is the only difference from the serial tasks' entries.
    got = files_of(root)
    assert {k: v for k, v in got.items() if k != MANIFEST and k != "g1/a.bin"} == {
        k: v for k, v in serial.items() if k != MANIFEST and k != "g1/a.bin"}


def _restarting():
    from mitsweep.pipeline.executors import RestartingProcessPool

    return RestartingProcessPool(2, initializer=None)  # toy tasks need no renderer


def test_lost_worker_retries_are_bounded_and_a_rerun_resumes(tmp_path, serial):
    tasks = toy_plan()
    tasks[3] = Task("g1/a.bin", always_die, {"value": 11}, group=1)
    pool = _restarting()
    try:
        with pytest.raises(DatasetError) as info:
            run(tmp_path, tasks, executor=pool, retries=1)
    finally:
        pool.shutdown()
    # A dead process breaks the whole pool: the tasks running beside it are lost too
    # and count their attempts, so the first to run out may be one of them (on a loaded
    # machine even shared.bin, still running when the pool broke).
    msg = str(info.value)
    assert re.match(r"(g\d/[ab]|shared)\.bin: its worker was lost 2 times "
                    r"\(BrokenProcessPool", msg)
    assert "rerun the same command to resume" in msg
    partial = read_toy(tmp_path / MANIFEST)
    assert "complete" not in partial and "g1/a.bin" not in partial["items"]
    for name, item in partial["items"].items():  # what is listed is what is on disk
        assert item["sha256"] == sha256(tmp_path / name)
    run(tmp_path, toy_plan())
    assert files_of(tmp_path) == serial
    # Temporaries of the processes killed while writing are gone (the rerun's clean-up).
    assert not any(p.name.startswith(".") for p in tmp_path.rglob("*"))


def test_task_failure_stops_the_run_with_its_exception(tmp_path):
    tasks = toy_plan()
    tasks[3] = Task("g1/a.bin", fail, {"value": 11}, group=1)
    with spawn_pool() as pool:
        with pytest.raises(ValueError, match="toy failure 11"):
            run(tmp_path, tasks, executor=pool)
    assert read_task_log(tmp_path, "g1/a.bin")["status"] == "failed"
    assert "ValueError: toy failure 11" in (tmp_path / LOG_DIR / "g1/a.bin.log").read_text()
    assert "complete" not in read_toy(tmp_path / MANIFEST)


def test_worker_warnings_reach_the_coordinator(tmp_path, caplog):
    tasks = toy_plan(groups=1, fn=warn)
    with spawn_pool(1) as pool:
        with caplog.at_level(logging.WARNING):
            run(tmp_path, tasks, executor=pool)
    assert any(r.getMessage().startswith("g0/a.bin: toy warning 1 from pid ")
               and f"pid {os.getpid()}" not in r.getMessage() for r in caplog.records)
    assert "toy warning 1" in (tmp_path / LOG_DIR / "g0/a.bin.log").read_text()


def test_a_directory_of_another_setup_is_refused(tmp_path):
    run(tmp_path, toy_plan())
    before = files_of(tmp_path)
    with pytest.raises(DatasetError, match=f"{tmp_path / MANIFEST}: another setup"):
        run(tmp_path, toy_plan(), header=dict(HEADER, setup={"name": "other"}))
    assert files_of(tmp_path) == before


# -- Dask -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def dask_client():
    import distributed  # a core dependency: a missing one must fail, not skip
    from mitsweep.pipeline.cluster import local_cluster

    cluster = local_cluster(2)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def test_dask_executor_gives_the_same_directory(tmp_path, serial, dask_client):
    run(tmp_path, toy_plan(), executor=dask_client.get_executor(pure=False))
    assert files_of(tmp_path) == serial


@pytest.mark.slow   # 8 s; the process pool's killed worker stays in the default run
def test_dask_worker_killed_by_pid_mid_task_still_completes(tmp_path, serial, dask_client):
    """SIGKILL the worker process running a task while it runs: Dask reschedules it on
    the other worker (or the restarted one) and the directory is the serial one."""
    started = tmp_path / "started"
    started.mkdir()
    root = tmp_path / "ds"
    tasks = toy_plan(fn=announce_and_wait, started_dir=str(started))
    pids = set(dask_client.run(os.getpid).values())
    killed = []

    def killer():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            for f in started.iterdir():
                pid = int(f.suffix[1:])
                if pid in pids:
                    os.kill(pid, signal.SIGKILL)
                    killed.append((f.stem, pid))
                    return
            time.sleep(0.02)

    thread = threading.Thread(target=killer)
    thread.start()
    m = run(root, tasks, executor=dask_client.get_executor(pure=False))
    thread.join()
    assert killed, "no task started on a worker"
    value, pid = killed[0]
    # The killed task ran again elsewhere: it announced itself from another process.
    assert {int(f.suffix[1:]) for f in started.glob(f"{value}.*")} - {pid}
    assert m["complete"] is True
    expected = files_of(_serial_of(tmp_path, started))
    assert files_of(root) == expected
    dask_client.wait_for_workers(2, timeout=60)  # the nanny restarted the killed one


def _serial_of(tmp_path: Path, started: Path) -> Path:
    """The same tasks run here (the started_dir parameter is part of their entries)."""
    root = tmp_path / "serial"
    run(root, toy_plan(fn=announce_and_wait, started_dir=str(started)))
    return root
