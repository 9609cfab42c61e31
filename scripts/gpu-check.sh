#!/usr/bin/env bash
# GPU check: on a machine with an NVIDIA GPU, run the CUDA test subset and the quick
# benchmarks on the CUDA backend, in under 5 minutes (each step has a time limit:
# 60 + 90 + 150 s). Without a usable GPU it stops at
# once with a one-line reason and exit status 2.
#
#   scripts/gpu-check.sh [OUT_DIR]     (default: gpu-check-out/)
#
# What it runs, all with MITSWEEP_BACKEND=cuda (so nothing falls back to the CPU
# silently):
#   1. pytest -m gpu             the CUDA selection, a Dr.Jit CUDA kernel, a Mitsuba
#                                cuda_ad_rgb render (tests/test_backend_selection.py)
#   2. render and tracer tests   the thin-lens sweep sensor against Mitsuba's thinlens,
#                                the tracer's PSFs against their references, and the
#                                polar resampling's kernels against scipy, on CUDA
#   3. mitsweep bench all --quick --json   -> OUT_DIR/bench-all-quick.json
# Logs go to OUT_DIR; the machine's description is in the JSON ("machine").
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:-$root/gpu-check-out}"
py="$root/.venv/bin/python"
fail() { echo "gpu-check: $*" >&2; exit 2; }

[ -x "$py" ] || fail "no virtual environment at $root/.venv (run scripts/bootstrap.sh first)"
command -v nvidia-smi >/dev/null 2>&1 || fail "no nvidia-smi: this machine has no NVIDIA driver, so no GPU to check (CUDA untested here)"
gpus="$(nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader 2>/dev/null || true)"
[ -n "$gpus" ] || fail "nvidia-smi lists no GPU"
# Dr.Jit must see the device too, and Mitsuba must accept the CUDA variant
probe="$(cd "$root" && MITSWEEP_BACKEND= "$py" - <<'EOF' 2>&1
from mitsweep.backend import select_backend, set_mitsuba_variant
b = select_backend()
if b != "cuda":
    raise SystemExit(f"Dr.Jit chose {b!r}: its CUDA backend found no usable device")
print(set_mitsuba_variant(prefer="cuda"))
EOF
)" || fail "CUDA not usable: $(echo "$probe" | tail -n 1)"
mkdir -p "$out"
echo "gpu-check: GPU(s): $gpus"
echo "gpu-check: Mitsuba variant $probe; logs in $out"

export MITSWEEP_BACKEND=cuda
cd "$root"
start=$SECONDS
status=0
step() {  # name, command...: run, log, remember a failure, go on with the others
    local name="$1"; shift
    local t0=$SECONDS
    if "$@" >"$out/$name.log" 2>&1; then
        echo "gpu-check: $name passed ($((SECONDS - t0)) s)"
    else
        echo "gpu-check: $name FAILED ($((SECONDS - t0)) s): see $out/$name.log" >&2
        tail -n 20 "$out/$name.log" >&2
        status=1
    fi
}
step gpu-tests timeout 60 "$py" -m pytest -m gpu -q -p no:cacheprovider \
    tests/test_backend_selection.py
step render-tracer-tests timeout 90 "$py" -m pytest -q -p no:cacheprovider \
    tests/test_render_sensor.py tests/test_tracer_psf.py tests/test_tracer_independence.py \
    tests/test_jit_spline.py
step bench-all-quick bash -c "timeout 150 '$py' -m mitsweep bench all --quick --json \
    >'$out/bench-all-quick.json'"
echo "gpu-check: done in $((SECONDS - start)) s, status $status"
exit $status
