#!/usr/bin/env python3
"""Run one focal-sweep capture on the rig: ``mitsweep capture`` with the same arguments.

    scripts/capture.py scenes/sphere.toml --port /dev/ttyACM0 --out capture.json
    scripts/capture.py scenes/sphere.toml --port /dev/ttyACM0 --stage zaber:/dev/ttyUSB0
    scripts/capture.py scenes/sphere.toml --dry-run
    scripts/capture.py scenes/sphere.toml --port /dev/ttyACM0 --motion profile.json
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mitsweep.cli.main import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["capture", *sys.argv[1:]]))
