"""The rig tests' harness under pytest-xdist (scripts/test.sh runs the suite with -n):
the rig tests form one xdist group (one worker, one at a time, as serially), and the
busy-core load is refused under -n, where each worker would start its own spinners."""

from __future__ import annotations

import os
import subprocess
import sys

from conftest import BUSY_CORES_ENV, RIG_GROUP, ROOT


def test_rig_tests_run_in_one_xdist_group(request):
    marker = request.node.get_closest_marker("xdist_group")
    assert marker is not None and marker.args == (RIG_GROUP,)


def test_busy_cores_are_refused_under_xdist():
    proc = subprocess.run([sys.executable, "-m", "pytest", "-n", "2", "-q",
                           "tests/test_rig_imports.py"], cwd=ROOT, capture_output=True,
                          text=True, timeout=300,
                          env={**os.environ, BUSY_CORES_ENV: "1"})
    assert proc.returncode == 4, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert f"{BUSY_CORES_ENV} runs every test beside that many spinning processes" \
        in proc.stderr, proc.stderr[-2000:]
