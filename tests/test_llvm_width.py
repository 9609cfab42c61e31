"""LLVM vector width: set through drjit-core's C API, checked, applied from
MITSWEEP_LLVM_VECTOR_WIDTH before any kernel; the tracer's kernels agree across widths
and Dr.Jit's kernel cache never reuses a kernel of one width at another."""

import json
import logging
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from mitsweep import backend
from mitsweep.config import DEFAULT_SETUP
from mitsweep.optics.reference import reference_geometry
from mitsweep.tracer.bank import field_radius
from mitsweep.tracer.ipsf import integrated_psf

pytestmark = pytest.mark.skipif(backend.select_backend() != "llvm",
                                reason="the vector width is an LLVM-backend setting")

NATIVE = backend.native_llvm_vector_width()
#: Tests that switch between two widths need a CPU whose register width leaves room for
#: a second one (AVX2: 8 and 16); on AVX-512 the native 16 is already the largest allowed.
two_widths = pytest.mark.skipif(
    NATIVE is None or 2 * NATIVE > backend.MAX_LLVM_VECTOR_WIDTH,
    reason=f"only one vector width is allowed on this CPU (native {NATIVE}, "
           f"at most {backend.MAX_LLVM_VECTOR_WIDTH})")


def _in_subprocess(code: str, width: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ, MITSWEEP_LLVM_VECTOR_WIDTH=width or "")
    env.pop("MITSWEEP_BACKEND", None)
    if width is None:
        del env["MITSWEEP_LLVM_VECTOR_WIDTH"]
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, timeout=120)


_REPORT = ("import json; from mitsweep import backend as b; b.select_backend(); "
           "api = b.llvm_target_api(); "
           "print(json.dumps([b.llvm_vector_width(), b.native_llvm_vector_width(), "
           "api['target_cpu']().decode(), api['target_features']().decode()]))")


@pytest.mark.parametrize("setting", ["2x", "native", "auto", "unset"])
def test_width_from_the_environment_is_applied_at_backend_selection(setting):
    # A fresh process: the setting is read once, when the backend is selected; unset
    # means auto (twice the register width, at most 16).
    auto = min(2 * NATIVE, backend.MAX_LLVM_VECTOR_WIDTH)
    assert backend.auto_llvm_vector_width() == max(auto, NATIVE)
    want = {"2x": min(2 * NATIVE, backend.MAX_LLVM_VECTOR_WIDTH), "native": NATIVE,
            "auto": max(auto, NATIVE), "unset": max(auto, NATIVE)}[setting]
    text = {"2x": str(want), "unset": None}.get(setting, setting)
    res = _in_subprocess(_REPORT, text)
    assert res.returncode == 0, res.stderr
    width, native, cpu, features = json.loads(res.stdout.splitlines()[-1])
    assert (width, native) == (want, NATIVE)
    # only the width changes: Dr.Jit's target CPU and features stay
    base = json.loads(_in_subprocess(_REPORT, "native").stdout.splitlines()[-1])
    assert (cpu, features) == (base[2], base[3])


@pytest.mark.parametrize("bad", ["12", str(NATIVE // 2), "32", "0", "wide", "8.0"])
def test_bad_width_settings_are_refused_with_the_allowed_values(bad, monkeypatch):
    monkeypatch.setenv("MITSWEEP_LLVM_VECTOR_WIDTH", bad)
    before = backend.llvm_vector_width()
    with pytest.raises(backend.BackendError, match="MITSWEEP_LLVM_VECTOR_WIDTH: must be"):
        backend.apply_llvm_vector_width_setting()
    assert backend.llvm_vector_width() == before
    with pytest.raises(backend.BackendError, match="power of two from|integer"):
        backend.set_llvm_vector_width(int(bad) if bad.isdigit() else bad)


def _other_width() -> int:
    """A valid width that is not the current one."""
    return NATIVE if backend.llvm_vector_width() != NATIVE else 2 * NATIVE


def test_non_llvm_backend_leaves_the_width_alone(monkeypatch, caplog):
    monkeypatch.setattr(backend, "select_backend", lambda prefer=None: "cuda")
    before = backend.llvm_vector_width()
    with caplog.at_level(logging.INFO, logger="mitsweep.backend"):
        assert backend.set_llvm_vector_width(_other_width()) is None
    assert backend.llvm_vector_width() == before and "not llvm" in caplog.text


def test_missing_symbols_leave_the_width_alone(monkeypatch):
    monkeypatch.setattr(backend, "llvm_target_api", lambda: None)
    assert backend.set_llvm_vector_width(2 * NATIVE) is None
    assert backend.set_llvm_vector_width("auto") is None
    assert backend.llvm_vector_width() is None
    assert backend.native_llvm_vector_width() is None


@two_widths
def test_scope_sets_and_restores_the_width():
    before, other = backend.llvm_vector_width(), _other_width()
    with backend.llvm_vector_width_scope(other) as now:
        assert now == backend.llvm_vector_width() == other
    assert backend.llvm_vector_width() == before


def test_describe_machine_records_the_width():
    info = backend.describe_machine()
    assert info["llvm_vector_width"] == backend.llvm_vector_width()
    assert info["llvm_native_vector_width"] == NATIVE


@two_widths
@pytest.mark.parametrize("method", ["continuous", "exact"])
def test_tracer_kernels_agree_across_widths_and_kernels_are_not_reused(method):
    """Same seed at widths N, 2N and N again, in one process.

    Every ray is computed lane by lane by the same float32 operations whatever the
    width (no operation crosses lanes), and the deposit sums in float64, whose
    summation order may change with the width (~1e-16 relative): far below float32's
    6e-8 on kernel values <= 1, so the kernels are equal to 1e-7 (measured: equal
    bit for bit at 2^18 rays) and the landed counts are equal. Dr.Jit's kernel cache
    keys a kernel by its IR, which names the width: the kernels launched at 2N share no
    hash with those launched at N, so no kernel compiled at one width ran at the other.
    """
    import drjit as dr

    setup = DEFAULT_SETUP
    geometry = reference_geometry(setup)
    u = 0.9 * field_radius(setup, geometry)
    runs = []
    for width in (NATIVE, 2 * NATIVE, NATIVE):
        dr.kernel_history()  # clears the history
        dr.set_flag(dr.JitFlag.KernelHistory, True)
        try:
            with backend.llvm_vector_width_scope(width) as now:
                assert now == width
                kernel, info = integrated_psf(setup, u, 0.0, 500.0, rays=1 << 16,
                                              sweep=geometry.sweep, seed=3, method=method)
        finally:
            dr.set_flag(dr.JitFlag.KernelHistory, False)
        hashes = {e["hash"] for e in dr.kernel_history() if e.get("hash")}
        runs.append((np.asarray(kernel), info["rays_landed"], hashes))
    (k8, n8, h8), (k16, n16, h16), (k8b, n8b, h8b) = runs
    assert n8 == n16 == n8b > 0
    assert math.isclose(k8.sum(), 1.0, abs_tol=1e-5)
    np.testing.assert_allclose(k16, k8, rtol=0, atol=1e-7)
    np.testing.assert_allclose(k8b, k8, rtol=0, atol=1e-7)
    assert h8 and h16 and not (h8 & h16)
    assert h8b <= h8  # back at N: the same kernels as the first time
