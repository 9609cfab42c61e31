#!/usr/bin/env bash
# The test suite. Installs what is missing first (scripts/bootstrap.sh).
# Extra arguments go to pytest (e.g. -m slow, or -m "slow or not slow" for everything;
# a file or a test id runs just that).
#
# Runs in parallel (pytest-xdist): one worker per core plus one, at most 8, because one
# worker spends most of its time in the rig tests' real-time waits (tests/conftest.py keeps
# those tests together in one worker, in order, as a serial run has them, and every other
# module's tests together, so that its fixtures are built once). Set
# MITSWEEP_TEST_WORKERS=N for N workers (0: serially, in this process), or pass -n /
# -p no:xdist yourself. MITSWEEP_TEST_BUSY_CORES (see tests/conftest.py) runs serially.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh" --test
cd "$root"
# Byte-compile the package and the tests' helpers (only what changed since the last run,
# a fraction of a second): where PYTHONDONTWRITEBYTECODE is set (CI images often set it)
# nothing else would, and each of the suite's hundreds of processes would compile every
# module it imports from source again (0.1 s a `mitsweep` command).
.venv/bin/python -m compileall -q mitsweep tests scripts examples >/dev/null || true

workers="${MITSWEEP_TEST_WORKERS:-}"
if [ -z "$workers" ]; then
    cores="$(nproc 2>/dev/null || getconf _NPROCESSORS_ONLN 2>/dev/null || echo 1)"
    workers=$((cores + 1 > 8 ? 8 : cores + 1))
fi
case "$workers" in
    ''|*[!0-9]*) echo "test.sh: MITSWEEP_TEST_WORKERS must be a whole number of workers (0: serial), got '$workers'" >&2
                 exit 2 ;;
esac
busy="${MITSWEEP_TEST_BUSY_CORES:-0}"
[ "${busy//[[:space:]]/}" != "" ] && [ "${busy//[[:space:]]/}" != 0 ] && workers=0
for arg in "$@"; do   # the caller chose (-n N, -p no:xdist, --dist), or a debugger needs one process
    case "$arg" in
        -n|-n[0-9]*|-nauto|--numprocesses|--numprocesses=*|no:xdist|-pno:xdist|--dist|--dist=*|--pdb|--trace) workers=0 ;;
    esac
done
parallel=()
[ "$workers" -gt 0 ] && parallel=(-n "$workers" --dist loadgroup)
exec .venv/bin/python -m pytest "${parallel[@]}" "$@"
