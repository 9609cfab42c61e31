"""scripts/gpu-check.sh refuses clearly (one line, exit 2) where there is no usable GPU,
before running anything; on a GPU machine it is the check itself."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "gpu-check.sh"


def _run(tmp_path, path_dirs):
    env = dict(os.environ, PATH=os.pathsep.join(path_dirs))
    return subprocess.run(["bash", str(SCRIPT), str(tmp_path / "out")], env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(shutil.which("nvidia-smi") is not None, reason="this machine has a driver")
def test_without_a_driver_it_stops_with_one_line(tmp_path):
    r = _run(tmp_path, ["/usr/bin", "/bin"])
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("gpu-check: no nvidia-smi")
    assert not (tmp_path / "out").exists()          # nothing ran


def test_a_driver_without_a_device_dr_jit_can_use_is_refused(tmp_path):
    """nvidia-smi answers (a script standing in for a driver whose GPU Dr.Jit cannot
    open); Dr.Jit's own probe decides, and says why."""
    if shutil.which("nvidia-smi") is not None:
        pytest.skip("a real driver is present")
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "nvidia-smi").write_text("#!/bin/sh\necho 'Some GPU, 1000, 1.0'\n")
    (fake / "nvidia-smi").chmod(0o755)
    r = _run(tmp_path, [str(fake), "/usr/bin", "/bin"])
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "gpu-check: CUDA not usable: Dr.Jit chose 'llvm': its CUDA backend found no usable "
        "device"]
