import contextlib
import os
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


@pytest.fixture
def scenes_dir() -> Path:
    return SCENES


def run_cli(*args, env=None, timeout=600):
    """Run ``python -m mitsweep ARGS`` in a subprocess: (returncode, stdout, stderr)."""
    import subprocess

    full_env = dict(os.environ)
    if env:
        full_env.update(env)
    proc = subprocess.run([sys.executable, "-m", "mitsweep", *map(str, args)],
                          capture_output=True, text=True, env=full_env, timeout=timeout,
                          cwd=ROOT)
    return proc.returncode, proc.stdout, proc.stderr



#: Set (e.g. ``MITSWEEP_TEST_BUSY_CORES=2``) to run every test with that many busy
#: processes beside it: CI runs the rig tests so (.ci/run), because their deadlines on the
#: safety path must hold on a loaded machine, not only on an idle one.
BUSY_CORES_ENV = "MITSWEEP_TEST_BUSY_CORES"


@contextlib.contextmanager
def busy_processes(n: int):
    """``n`` processes spinning in a pure-Python loop, killed on exit; yields their pids."""
    import subprocess

    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield [p.pid for p in procs]
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


@pytest.fixture
def busy_cores():
    """Keep every CPU busy (``os.cpu_count()`` spinning processes) while the test runs."""
    with busy_processes(os.cpu_count() or 2) as pids:
        yield pids


def _busy_cores_wanted() -> int:
    text = os.environ.get(BUSY_CORES_ENV, "").strip() or "0"
    if not text.isdigit():
        raise pytest.UsageError(f"{BUSY_CORES_ENV} must be a whole number of processes, "
                                f"got {text!r}")
    return int(text)


#: The xdist group of the tests that drive the simulated rig over ptys against real-time
#: deadlines (tests/test_rig_*.py): under ``--dist loadgroup`` (scripts/test.sh) they run
#: in one worker, one at a time and in file order, as in a serial run, while the other
#: workers keep the CPUs busy, the load CI's serial busy-core pass checks them under.
#: A module with fixtures wider than a test (module, class, package or session scope
#: declared in the module) is one group, so that its fixtures are built once (one test
#: per unit built them once per worker: 107 s against 85 s serially and 71 s by module,
#: for test_calibrate, test_unwarp, test_bank_validation, test_tracer_focus); the tests
#: of every other module are handed out one by one, which balances the workers (one
#: module of long tests, such as the doc snippets, would otherwise end the run alone).
RIG_GROUP = "rig"
SHARED_FIXTURE = ('scope="module"', 'scope="class"', 'scope="package"', 'scope="session"')

#: The slowest groups first (wall seconds of a serial run on the 2-core machine under
#: load; only the order matters): xdist hands groups out in collection order, so the
#: longest start first and the short ones fill in at the end.
SLOWEST_FIRST = ("rig", "test_calibrate_real", "test_doc_snippets", "test_calibrate_limb",
                 "test_cli_sweep_range", "test_calibrate", "test_architecture",
                 "test_pipeline_dataset", "test_memory_gate", "test_dataset_runner",
                 "test_datasets_reader", "test_error_budget", "test_plots",
                 "test_pipeline_lock", "test_cache_optional", "test_examples")


def pytest_configure(config):
    if _busy_cores_wanted() and getattr(config.option, "numprocesses", None):
        # each worker would start its own n spinners: not the load the variable names
        raise pytest.UsageError(f"{BUSY_CORES_ENV} runs every test beside that many "
                                f"spinning processes: run serially (-p no:xdist), not "
                                f"under -n")
    if os.environ.get("PYTEST_XDIST_WORKER"):
        # One BLAS thread per worker: scripts/test.sh starts a worker per core (plus one),
        # and a second BLAS thread in each would only take turns on the same cores (the
        # calibration's least-squares fits took twice the CPU time on two). A runtime limit, not
        # OPENBLAS_NUM_THREADS, so that a test may still raise it
        # (test_design_determinism runs on 1 and 2 threads).
        from threadpoolctl import threadpool_limits

        config.stash[_BLAS_LIMIT] = threadpool_limits(limits=1, user_api="blas")


_BLAS_LIMIT = pytest.StashKey[object]()


def _shares_fixtures(path: Path, seen: dict) -> bool:
    if path not in seen:
        text = path.read_text(errors="replace")
        seen[path] = any(s in text for s in SHARED_FIXTURE)
    return seen[path]


@pytest.hookimpl(tryfirst=True)   # before xdist's own hook, which reads the groups
def pytest_collection_modifyitems(config, items):
    seen: dict = {}
    for item in items:
        if item.path.name.startswith("test_rig_"):
            item.add_marker(pytest.mark.xdist_group(RIG_GROUP))
        elif _shares_fixtures(item.path, seen):
            item.add_marker(pytest.mark.xdist_group(item.path.stem))
    if getattr(config.option, "numprocesses", None):
        rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
        last = len(SLOWEST_FIRST)
        items.sort(key=lambda it: rank.get("rig" if it.path.name.startswith("test_rig_")
                                           else it.path.stem, last))


@pytest.fixture(autouse=True)
def _busy_cores_from_env():
    """``$MITSWEEP_TEST_BUSY_CORES`` = n > 0: every test runs beside n spinning processes."""
    n = _busy_cores_wanted()
    if n == 0:
        yield
        return
    with busy_processes(n):
        yield


@pytest.fixture(scope="session")
def host_firmware(tmp_path_factory):
    """The rig's Arduino sketch built for this machine (scripts/firmware/host): a program
    that serves the board on a pty (tests/test_rig_firmware.py's HostBoard). Compiled
    once per session (per worker under xdist), for every rig test module that runs it."""
    import shutil
    import subprocess

    cxx = shutil.which("g++")
    if cxx is None:
        if os.environ.get("CI"):
            pytest.fail("no C++ compiler (g++) for the host build of the sketch")
        pytest.skip("no C++ compiler (g++) for the host build of the sketch")
    sketch_dir = ROOT / "scripts" / "firmware" / "mitsweep_sweep"
    host_dir = sketch_dir.parent / "host"
    out = tmp_path_factory.mktemp("fwhost") / "mitsweep_sweep_host"
    proc = subprocess.run([cxx, "-O2", "-std=c++11", "-Wall", "-Wextra", "-Werror",
                           "-I", str(host_dir), "-x", "c++",
                           str(sketch_dir / "mitsweep_sweep.ino"), "-x", "none",
                           str(host_dir / "host_main.cpp"), "-o", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


@pytest.fixture
def drawn(monkeypatch):
    """The figures ``mitsweep.plots.save_figure`` writes, drawn on an Agg canvas:
    [(fig, renderer)] (for layout checks: overlaps, legends, colour bars)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from mitsweep import plots

    figures = []
    original = plots.save_figure

    def capture(fig, path, dpi=plots.DPI):
        out = original(fig, path, dpi)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        figures.append((fig, canvas.get_renderer()))
        return out

    monkeypatch.setattr(plots, "save_figure", capture)
    return figures
