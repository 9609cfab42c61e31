#!/usr/bin/env bash
# The main job on the embedded default setup (the paper's spherical mirror).
# Installs what is missing first (scripts/bootstrap.sh). Extra arguments go to `mitsweep demo`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh"
cd "$root"
exec .venv/bin/mitsweep demo "$@"
