"""Backend choice: CUDA when Dr.Jit has a usable device, else LLVM; MITSWEEP_BACKEND
overrides; the tracer's Dr.Jit module and Mitsuba's variant follow the choice.

The CUDA probe is forced here (no GPU on these machines); the ``gpu`` tests run only on
a machine with one (``scripts/gpu-check.sh``)."""

import json

import pytest

from mitsweep import backend


@pytest.fixture
def fresh(monkeypatch):
    """select_backend is cached per process: clear it around each test."""
    monkeypatch.delenv("MITSWEEP_BACKEND", raising=False)
    backend.select_backend.cache_clear()
    yield monkeypatch
    backend.select_backend.cache_clear()


def _probe(monkeypatch, usable: bool):
    monkeypatch.setattr(backend, "cuda_usable", lambda: usable)


def test_cuda_is_chosen_when_a_device_is_usable(fresh):
    _probe(fresh, True)
    assert backend.select_backend() == "cuda"
    assert backend.mitsuba_variant() == "cuda_ad_rgb"
    assert backend.mitsuba_variant("spectral") == "cuda_ad_spectral"
    # importing drjit.cuda compiles nothing and needs no device
    assert backend.drjit_module().__name__ == "drjit.cuda"


@pytest.mark.parametrize("usable", [True, False])
def test_llvm_can_be_forced_on_a_gpu_machine(fresh, usable):
    _probe(fresh, usable)
    fresh.setenv("MITSWEEP_BACKEND", "llvm")
    assert backend.select_backend() == "llvm"
    assert backend.mitsuba_variant() == "llvm_ad_rgb"
    assert backend.drjit_module().__name__ == "drjit.llvm"


def test_without_a_device_llvm_is_chosen_and_cuda_refused_if_asked(fresh):
    _probe(fresh, False)
    assert backend.select_backend() == "llvm"
    backend.select_backend.cache_clear()
    fresh.setenv("MITSWEEP_BACKEND", "cuda")
    with pytest.raises(backend.BackendError, match="no CUDA device is usable"):
        backend.select_backend()


def test_the_real_probe_agrees_with_the_driver():
    """No driver, no device (this machine); with nvidia-smi listing GPUs Dr.Jit should
    find one too, or the user is told nothing about a broken CUDA set-up."""
    if backend.cuda_devices():
        assert backend.cuda_usable()
    else:
        assert not backend.cuda_usable()


def test_an_automatic_cuda_variant_mitsuba_refuses_falls_back_to_llvm(fresh, caplog):
    import mitsuba as mi

    _probe(fresh, True)
    real_set = mi.set_variant

    def set_variant(name, *more):
        if name.startswith("cuda_"):
            raise ImportError("OptiX not found (injected)")
        return real_set(name, *more)

    fresh.setattr(mi, "set_variant", set_variant)
    before = mi.variant()
    try:
        assert backend.set_mitsuba_variant() == "llvm_ad_rgb"
        assert mi.variant() == "llvm_ad_rgb"
        assert "cannot be set" in caplog.text
        # asked for explicitly, the same refusal is an error
        backend.select_backend.cache_clear()
        fresh.setenv("MITSWEEP_BACKEND", "cuda")
        with pytest.raises(backend.BackendError, match="cuda_ad_rgb cannot be set"):
            backend.set_mitsuba_variant()
    finally:
        if before and mi.variant() != before:
            real_set(before)


def test_machine_description_is_json_and_names_the_choice():
    info = backend.describe_machine()
    json.dumps(info)
    assert info["backend"] in ("cuda", "llvm")
    assert info["variant"] == f"{info['backend']}_ad_rgb"
    assert info["llvm"].startswith("19.") or int(info["llvm"].split(".")[0]) >= 19
    assert info["cores_usable"] <= info["cores_logical"]
    assert isinstance(info["gpus"], list)
    if info["backend"] == "llvm":
        assert info["llvm_vector_width"] == backend.llvm_vector_width() >= \
            info["llvm_native_vector_width"] > 0
    else:
        assert info["llvm_vector_width"] is None


def test_a_cuda_choice_leaves_the_llvm_width_setting_unapplied(fresh):
    # MITSWEEP_LLVM_VECTOR_WIDTH is read only when LLVM is chosen: a bad value does not
    # stop a CUDA machine, and is refused as soon as LLVM is selected
    fresh.setenv("MITSWEEP_LLVM_VECTOR_WIDTH", "12")
    _probe(fresh, True)
    assert backend.select_backend() == "cuda"
    backend.select_backend.cache_clear()
    _probe(fresh, False)
    with pytest.raises(backend.BackendError, match="MITSWEEP_LLVM_VECTOR_WIDTH"):
        backend.select_backend()


# -- on a GPU machine only ------------------------------------------------------------

# skipped where nvidia-smi lists no GPU; scripts/gpu-check.sh checks for one first, so
# there they run (or fail)
gpu = [pytest.mark.gpu,
       pytest.mark.skipif(not backend.cuda_devices(), reason="no CUDA device (nvidia-smi)")]


@gpu[0]
@gpu[1]
def test_gpu_machine_selects_cuda_without_being_told(fresh):
    assert backend.cuda_devices(), "nvidia-smi lists no GPU"
    assert backend.select_backend() == "cuda"
    assert backend.describe_machine()["variant"] == "cuda_ad_rgb"


@gpu[0]
@gpu[1]
def test_gpu_drjit_cuda_computes():
    import drjit as dr

    m = backend.drjit_module("cuda")
    x = dr.arange(m.Float, 1 << 20)
    # sum of 0 .. n-1 = n (n - 1) / 2, exact in float64 and within float32 round-off
    n = float(1 << 20)
    assert abs(float(dr.sum(x)[0]) - n * (n - 1) / 2) < 1e-5 * n * n


@gpu[0]
@gpu[1]
def test_gpu_mitsuba_cuda_variant_renders():
    import numpy as np

    variant = backend.set_mitsuba_variant(prefer="cuda")
    import mitsuba as mi

    assert variant == "cuda_ad_rgb" and mi.variant() == variant
    scene = mi.load_dict(mi.cornell_box())
    img = np.asarray(mi.render(scene, spp=4))
    assert img.shape[-1] == 3 and np.isfinite(img).all() and img.mean() > 0
