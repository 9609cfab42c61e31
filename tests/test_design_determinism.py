"""A sweep design is a deterministic function of its inputs: the plane bank bit for bit
whatever Dr.Jit's thread count (per-ray hits binned by NumPy, no atomics), and the
optimiser's τ bit for bit whatever the BLAS thread count (SLSQP runs on one BLAS thread)."""

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from mitsweep.config import load_setup
from mitsweep.deconv import paper_fig10_settings
from mitsweep.design import StageLimits, certified_lower_bound, local_optimum, plane_bank, \
    wiener_model
from mitsweep.optics import optimal_sweep_range

PARABOLOID = Path(__file__).resolve().parents[1] / "scenes" / "paraboloid.toml"


@pytest.fixture(scope="module")
def problem():
    setup = load_setup(PARABOLOID)
    sweep = optimal_sweep_range(setup)
    edges = np.linspace(sweep.sensor_start, sweep.sensor_end, 65)
    i_ref = 0.5 * (sweep.sensor_start + sweep.sensor_end)
    args = dict(points_uv=[(0.0, 0.0), (3.5, 0.0)], depths=[300.0, 10000.0],
                edges=edges, reference_sensor_distance=i_ref, rays=1 << 13)
    limits = StageLimits(exposure_s=sweep.exposure_s, max_velocity=setup.rig.max_velocity,
                         acceleration=setup.rig.acceleration)
    return setup, args, limits


def test_plane_bank_traced_again_is_bitwise_equal_whatever_the_thread_count(problem):
    setup, args, _ = problem
    first = plane_bank(setup, **args).kernels
    threads = dr.thread_count()
    dr.set_thread_count(1)
    try:
        single = plane_bank(setup, **args).kernels
    finally:
        dr.set_thread_count(threads)
    again = plane_bank(setup, **args).kernels
    np.testing.assert_array_equal(first, again)
    np.testing.assert_array_equal(first, single)


@pytest.mark.parametrize("objective", ["worst", pytest.param("mean", marks=pytest.mark.slow)])
def test_design_is_bitwise_equal_whatever_the_blas_thread_count(problem, objective):
    """64 bins: SLSQP's products are large enough for OpenBLAS to split them over threads
    (without the one-thread limit, 1 and 2 threads gave τ 2e-13 apart on the sphere)."""
    setup, args, limits = problem
    bank = plane_bank(setup, **args)
    model = wiener_model(bank.kernels, paper_fig10_settings(0.0064, 2.0)["sweep"],
                         n_fft=32, n_px=512)
    results = []
    for threads in (1, 2, 2):
        with threadpool_limits(limits=threads, user_api="blas"):
            sol = local_optimum(model, bank.widths, limits, objective=objective)
            bound, _ = certified_lower_bound(model, bank.widths, limits,
                                             objective=objective)
        results.append((sol.tau, sol.value, sol.info["iterations"], bound))
    for tau, value, iterations, bound in results[1:]:
        np.testing.assert_array_equal(tau, results[0][0])
        assert (value, iterations, bound) == results[0][1:]
