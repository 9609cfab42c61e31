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


@pytest.fixture(autouse=True)
def _busy_cores_from_env():
    """``$MITSWEEP_TEST_BUSY_CORES`` = n > 0: every test runs beside n spinning processes."""
    text = os.environ.get(BUSY_CORES_ENV, "").strip() or "0"
    if not text.isdigit():
        raise pytest.UsageError(f"{BUSY_CORES_ENV} must be a whole number of processes, "
                                f"got {text!r}")
    if int(text) == 0:
        yield
        return
    with busy_processes(int(text)):
        yield


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
