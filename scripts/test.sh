#!/usr/bin/env bash
# The test suite. Installs what is missing first (scripts/bootstrap.sh).
# Extra arguments go to pytest (e.g. -m slow, or -m "slow or not slow" for everything).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh" --test
cd "$root"
exec .venv/bin/python -m pytest "$@"
