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
