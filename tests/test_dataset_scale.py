"""A real tiny dataset made serially, by a process pool, by a two-worker Dask
LocalCluster and in two shards: the same bytes in every item and in the manifest. A Dask
worker killed by its PID mid-run, and the coordinator killed, still end in the serial
dataset. Slow: each run renders, traces and deconvolves for real (about 10-60 s each on
a loaded 2-core machine).
"""

import json
import os
import signal
import subprocess
import sys
import threading
import time
import pytest

from conftest import ROOT
from mitsweep.config import load_setup
from mitsweep.pipeline import (LOG_DIR, MANIFEST, SHARD_DIR, DatasetOptions, build_dataset,
                               item_names, load_manifest)
from mitsweep.pipeline.runner import read_task_log, sha256
from test_io_write_errors import tiny_setup_toml

pytestmark = pytest.mark.slow

OPTS = DatasetOptions(scenes=2, spp={"pinhole": 1, "focused": 1, "sweep": 2, "stopped": 1},
                      bank_rays=1 << 12, light_levels_lux=(50.0,))
#: The same options on the command line.
CLI_ARGS = ["--scenes", "2", "--spp", "1", "1", "2", "1", "--lux", "50", "--bank-rays", "4096"]


def files_of(root) -> dict:
    """Every file but the per-task logs (times, hosts, pids), with its SHA-256."""
    return {p.relative_to(root).as_posix(): sha256(p) for p in sorted(root.rglob("*"))
            if p.is_file() and LOG_DIR not in p.relative_to(root).parts}


@pytest.fixture(scope="module")
def setup_file(tmp_path_factory):
    """The paper sphere on a 48 px frame (the file, for the command line)."""
    return tiny_setup_toml(tmp_path_factory.mktemp("setup"))


@pytest.fixture(scope="module")
def tiny(setup_file):
    return load_setup(setup_file)


@pytest.fixture(scope="module")
def serial(tmp_path_factory, tiny):
    root = tmp_path_factory.mktemp("serial")
    build_dataset(tiny, root, OPTS, progress=False)
    files = files_of(root)
    assert set(files) == {MANIFEST, *item_names(OPTS)}
    return files


def test_process_pool_gives_the_same_bytes(tmp_path, serial, tiny):
    build_dataset(tiny, tmp_path, OPTS, executor="process", jobs=2, progress=False)
    assert files_of(tmp_path) == serial


def test_dask_local_cluster_gives_the_same_bytes(tmp_path, serial, tiny):
    build_dataset(tiny, tmp_path, OPTS, executor="dask", jobs=2, progress=False)
    assert files_of(tmp_path) == serial
    # The tasks ran on the workers, not here.
    pids = {read_task_log(tmp_path, n)["pid"] for n in item_names(OPTS)}
    assert os.getpid() not in pids and len(pids) >= 1


def test_two_shards_give_the_same_bytes(tmp_path, serial, tiny):
    first = build_dataset(tiny, tmp_path, OPTS, shard="1/2", progress=False)
    assert "complete" not in first
    assert (tmp_path / SHARD_DIR / "1-of-2" / MANIFEST).is_file()
    second = build_dataset(tiny, tmp_path, OPTS, shard="2/2", progress=False)
    assert second["complete"] is True
    assert files_of(tmp_path) == serial
    # Shard 1 made scene 0, shard 2 scene 1; each made the bank it needed.
    assert read_task_log(tmp_path, "scene_001/sweep.exr")["started"] > \
        read_task_log(tmp_path, "scene_000/sweep.exr")["started"]


def test_dask_worker_killed_by_pid_mid_run_still_gives_the_dataset(tmp_path, serial, tiny):
    from distributed import Client

    from mitsweep.pipeline.cluster import MitsweepWorkerPlugin, local_cluster

    cluster = local_cluster(2)
    client = Client(cluster)
    killed = []
    try:
        client.register_plugin(MitsweepWorkerPlugin(), name=MitsweepWorkerPlugin.name)
        pid_of = client.run(os.getpid)  # worker address -> pid

        def kill_a_busy_worker():
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline:
                for address, keys in client.processing().items():
                    if keys and address in pid_of:
                        os.kill(pid_of[address], signal.SIGKILL)
                        killed.append((address, keys))
                        return
                time.sleep(0.05)

        thread = threading.Thread(target=kill_a_busy_worker)
        thread.start()
        manifest = build_dataset(tiny, tmp_path, OPTS, progress=False,
                                 executor=client.get_executor(pure=False))
        thread.join()
    finally:
        client.close()
        cluster.close()
    assert killed, "no worker was ever busy"
    assert manifest["complete"] is True
    assert files_of(tmp_path) == serial


def test_killed_coordinator_is_resumed_by_a_rerun(tmp_path, serial, setup_file):
    setup = setup_file
    root = tmp_path / "ds"
    argv = [sys.executable, "-m", "mitsweep", "dataset", str(setup), "--out", str(root),
            *CLI_ARGS, "--executor", "dask", "--jobs", "2"]
    victim = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              cwd=ROOT, start_new_session=True)
    deadline = time.monotonic() + 600
    done = {}
    while time.monotonic() < deadline and len(done) < 3:
        assert victim.poll() is None, victim.communicate()
        try:
            done = json.loads((root / MANIFEST).read_text())["items"]
        except (OSError, ValueError):
            pass
        time.sleep(0.1)
    os.kill(victim.pid, signal.SIGKILL)  # the coordinator only: its workers see it go
    victim.communicate()
    kept = {n: read_task_log(root, n)["started"] for n in done}
    assert 3 <= len(kept) < len(item_names(OPTS))
    rerun = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=900)
    assert rerun.returncode == 0, rerun.stderr
    assert load_manifest(root)["complete"] is True
    assert files_of(root) == serial
    # What the killed run had recorded was not made again.
    assert {n: read_task_log(root, n)["started"] for n in kept} == kept
    try:  # the process group of the killed run (its cluster) is gone or going
        os.killpg(victim.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def test_cli_joins_a_running_scheduler_whose_workers_know_nothing(tmp_path, serial,
                                                                   setup_file):
    """``dask scheduler`` and ``dask worker`` started on their own (no mitsweep set-up):
    ``--scheduler`` registers the worker plugin, the renders find the focalsweep sensor,
    and the dataset is the serial one."""
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    info = tmp_path / "scheduler.json"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MITSWEEP_")}
    scheduler = subprocess.Popen([*dask, "--host", "127.0.0.1", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(info)],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                 cwd=tmp_path, env=env)
    worker = None
    try:
        deadline = time.monotonic() + 120
        while not info.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(info.read_text())["address"]
        worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker",
                                   address, "--nthreads", "1", "--nworkers", "2",
                                   "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  cwd=tmp_path, env=env)
        root = tmp_path / "ds"
        proc = subprocess.run([sys.executable, "-m", "mitsweep", "dataset", str(setup_file),
                               "--out", str(root), *CLI_ARGS, "--scheduler", address],
                              capture_output=True, text=True, cwd=ROOT, timeout=900)
        assert proc.returncode == 0, proc.stderr
        assert files_of(root) == serial
    finally:
        for p in (worker, scheduler):
            if p is not None:
                p.terminate()
                p.wait(timeout=60)
