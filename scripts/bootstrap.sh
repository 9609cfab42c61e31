#!/usr/bin/env bash
# Installs what mitsweep needs on a fresh machine, idempotently:
#   libLLVM >= 19 (Dr.Jit's CPU backend; the system LLVM 15 aborts the process),
#   a virtual environment in .venv and the package with its test extras.
# Run by scripts/main.sh and scripts/test.sh; safe to run again.
#   --test  also installs what the tests use beyond the package: the AVR toolchain
#           (gcc-avr avr-libc arduino-core-avr arduino-mk) that compiles the rig's
#           firmware for an Arduino Uno, and simavr that boots it (those tests skip,
#           with the reason, where these cannot be installed).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
want_test_tools=0
[ "${1:-}" = "--test" ] && want_test_tools=1

apt_updated=0
apt_install() {  # apt_install PKG...: as root, or through password-less sudo
    local sudo=""
    if [ "$(id -u)" != 0 ]; then
        command -v sudo >/dev/null && sudo -n true 2>/dev/null || return 1
        sudo="sudo"
    fi
    command -v apt-get >/dev/null || return 1
    if [ "$apt_updated" = 0 ]; then
        $sudo apt-get update -qq >/dev/null || return 1
        apt_updated=1
    fi
    $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

have_llvm19() {
    ldconfig -p 2>/dev/null | grep -Eq 'libLLVM(-|\.so\.)(19|2[0-9])' && return 0
    ls /usr/lib/*/libLLVM-{19,2?}*.so* /usr/lib/llvm-{19,2?}/lib/libLLVM*.so* >/dev/null 2>&1
}

if ! have_llvm19; then
    echo "bootstrap: installing libllvm19 through apt (Dr.Jit's CPU backend needs LLVM >= 19)" >&2
    apt_install libllvm19 || echo "bootstrap: libLLVM >= 19 is missing and could not be installed; install it (Debian/Ubuntu: apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH" >&2
fi

if [ "$want_test_tools" = 1 ]; then
    missing=()
    command -v avr-gcc >/dev/null || missing+=(gcc-avr avr-libc)
    [ -f /usr/share/arduino/Arduino.mk ] || missing+=(arduino-mk arduino-core-avr)
    command -v simavr >/dev/null || missing+=(simavr)
    if [ ${#missing[@]} -gt 0 ]; then
        echo "bootstrap: installing test tools through apt: ${missing[*]}" >&2
        apt_install "${missing[@]}" || echo "bootstrap: could not install ${missing[*]}; the firmware tests will be skipped" >&2
    fi
fi

py="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
    echo "bootstrap: creating .venv" >&2
    "$py" -m venv .venv
fi
stamp=".venv/.mitsweep-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ scripts/constraints.txt -nt "$stamp" ]; then
    echo "bootstrap: installing mitsweep and its dependencies into .venv (log: .venv/pip-install.log)" >&2
    # the versions the docs' figures were checked with (scripts/constraints.txt) where this
    # Python and platform have them; otherwise the newest that pyproject.toml allows
    if ! { .venv/bin/python -m pip install -q --upgrade pip &&
           .venv/bin/python -m pip install -q -c scripts/constraints.txt -e ".[dev,docs,test]"; } \
            >.venv/pip-install.log 2>&1; then
        echo "bootstrap: the checked versions (scripts/constraints.txt) do not install here;" \
             "installing the newest allowed (the docs' last digits may differ)" >&2
        if ! .venv/bin/python -m pip install -q -e ".[dev,docs,test]" >>.venv/pip-install.log 2>&1; then
            tail -n 30 .venv/pip-install.log >&2
            echo "bootstrap: pip install failed (full log: .venv/pip-install.log)" >&2
            exit 1
        fi
    fi
    touch "$stamp"
fi
