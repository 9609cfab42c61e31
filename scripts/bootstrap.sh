#!/usr/bin/env bash
# Installs what mitsweep needs on a fresh machine, idempotently:
#   libLLVM >= 19 (Dr.Jit's CPU backend; the system LLVM 15 aborts the process),
#   a virtual environment in .venv and the package with its test extras.
# Sourced by scripts/main.sh and scripts/test.sh; safe to run again.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

have_llvm19() {
    ldconfig -p 2>/dev/null | grep -Eq 'libLLVM(-|\.so\.)(19|2[0-9])' && return 0
    ls /usr/lib/*/libLLVM-{19,2?}*.so* /usr/lib/llvm-{19,2?}/lib/libLLVM*.so* >/dev/null 2>&1
}

if ! have_llvm19; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        echo "bootstrap: installing libllvm19 through apt (Dr.Jit's CPU backend needs LLVM >= 19)" >&2
        apt-get update -qq >/dev/null
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19 >/dev/null
    elif command -v sudo >/dev/null && command -v apt-get >/dev/null; then
        sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libllvm19
    else
        echo "bootstrap: libLLVM >= 19 is missing; install it (Debian/Ubuntu: apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH" >&2
    fi
fi

py="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
    echo "bootstrap: creating .venv" >&2
    "$py" -m venv .venv
fi
stamp=".venv/.mitsweep-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "bootstrap: installing mitsweep and its dependencies into .venv" >&2
    .venv/bin/python -m pip install -q --upgrade pip >/dev/null
    .venv/bin/python -m pip install -q -e ".[dev]"
    touch "$stamp"
fi
