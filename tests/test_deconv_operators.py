"""The spatially varying blur as forward/adjoint operators: exact adjoints, agreement with
the dense per-pixel blur, pylops interface."""

import sys

import numpy as np
import pytest
import scipy.ndimage as ndi

from mitsweep.deconv import blur_operator
from mitsweep.deconv.kernels import select_depth
from mitsweep.deconv.metrics import disk_mask
from mitsweep.deconv.operators import (bilinear_matrix, dense_matrix, dot_product_error,
                                       polar_operator, product_convolution_operator)
from mitsweep.deconv.spatial import (grid_axes_px, grid_kernel_field, grid_windows,
                                     scatter_blur)
from mitsweep.deconv.synthetic import (synthetic_grid_bank, synthetic_kernel_field,
                                       synthetic_radial_bank)

SHAPE = (48, 48)
K = 9


def _polar():
    return polar_operator(synthetic_radial_bank(SHAPE, size=K, r_max_px=24, n_radii=13), SHAPE)


def _grid():
    return product_convolution_operator(synthetic_grid_bank(SHAPE, (5, 5), size=K,
                                                            r_max_px=24), SHAPE)


# float64: round-off of a few FFTs and sparse products (measured 7e-18); float32 inputs
# run the operator in float32 (measured 3e-10 relative, well inside float32's 6e-8)
@pytest.mark.parametrize("make", [_polar, _grid], ids=["polar", "product-convolution"])
@pytest.mark.parametrize("dtype,tol", [(np.float64, 1e-12), (np.float32, 1e-5)])
def test_adjoint_passes_the_dot_product_test(make, dtype, tol):
    assert dot_product_error(make(), rng=3, dtype=dtype) < tol


def test_polar_adjoint_is_the_transpose_of_the_dense_forward():
    shape = (20, 20)
    op = polar_operator(synthetic_radial_bank(shape, size=5, r_max_px=10, n_radii=7), shape)
    A = dense_matrix(op)
    At = dense_matrix(type(op)(shape=shape, forward=op.adjoint, adjoint=op.forward,
                               kind=op.kind))
    np.testing.assert_allclose(At, A.T, atol=1e-12)   # exact in exact arithmetic: round-off


def test_product_convolution_is_exactly_the_per_pixel_blur():
    bank = synthetic_grid_bank(SHAPE, (5, 5), size=K, r_max_px=24)
    wy, wx = grid_windows(*grid_axes_px(bank, SHAPE), SHAPE)
    field = grid_kernel_field(select_depth(bank), wy, wx)
    x = np.random.default_rng(1).random(SHAPE)
    # the same sums in another order: round-off on values ~1
    np.testing.assert_allclose(_grid()(x), scatter_blur(x, field), atol=1e-12)


def test_polar_operator_agrees_with_the_dense_blur_of_the_analytic_field():
    # the reference: every pixel spreads with the exact analytic IPSF at its own radius
    # and angle; the polar operator interpolates kernels between 13 radii and band
    # centres and resamples bilinearly twice. Measured 1.4 % relative error inside the
    # disk on a smooth image (the blur itself changes it by 6.9 %); 3 % is the bar.
    rng = np.random.default_rng(2)
    x = ndi.gaussian_filter(rng.random(SHAPE), 1.0)
    ref = scatter_blur(x, synthetic_kernel_field(SHAPE, K, 24))
    m = disk_mask(SHAPE, 20)
    err = np.linalg.norm((_polar()(x) - ref)[m]) / np.linalg.norm(ref[m])
    change = np.linalg.norm((x - ref)[m]) / np.linalg.norm(ref[m])
    assert err < 0.03
    assert err < change / 4


def test_product_convolution_sends_all_of_each_pixels_light_somewhere():
    # the scatter model conserves each pixel's light: Aᵀ 1 = Σ_s k_p[s] = 1 away from
    # the border (unit-sum kernels); A 1 need not be 1 where the kernels vary
    m = disk_mask(SHAPE, 16)
    np.testing.assert_allclose(_grid().adjoint(np.ones(SHAPE))[m], 1.0, atol=1e-12)


def test_polar_blur_conserves_the_light_of_a_disk_image():
    # bilinear sampling onto the polar grid and back is not exactly flux-preserving;
    # measured below 0.5 % on a smooth image inside the disk, 1 % is the bar
    x = ndi.gaussian_filter(np.random.default_rng(4).random(SHAPE), 2.0) * disk_mask(SHAPE, 14)
    assert abs(_polar()(x).sum() / x.sum() - 1) < 0.01


def test_bilinear_matrix_interpolates_and_its_transpose_spreads():
    img = np.arange(12.0).reshape(3, 4)
    S = bilinear_matrix([0.5, 1.0, 2.0], [0.25, 3.0, 3.5], img.shape, wrap_cols=True)
    # (0.5, 0.25): mean of rows 0-1 at col 0.25; (2.0, 3.5): half col 3, half col 0
    np.testing.assert_allclose(S @ img.ravel(), [4 * 0.5 + 0.25, 7.0, 0.5 * 11 + 0.5 * 8])
    np.testing.assert_allclose(np.asarray(S.sum(axis=1)).ravel(), 1.0)


def test_blur_operator_picks_the_operator_from_the_bank_kind():
    assert blur_operator(synthetic_radial_bank(SHAPE, size=K), SHAPE).kind == "polar"
    assert blur_operator(synthetic_grid_bank(SHAPE, (3, 3), size=K), SHAPE).kind == \
        "product-convolution"


def test_operator_refuses_an_image_of_another_shape():
    with pytest.raises(ValueError, match="48, 48"):
        _grid()(np.zeros((40, 48)))


def test_pylops_operator_passes_pylops_dottest():
    from pylops.utils import dottest  # the dev extra installs pylops: fail, not skip

    Op = _polar().as_pylops()
    assert Op.shape == (SHAPE[0] * SHAPE[1],) * 2
    assert dottest(Op, atol=1e-10)   # <Ax, y> = <x, A'y> to round-off of sums of 64² terms


def test_pylops_absent_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pylops", None)
    with pytest.raises(ImportError, match="pip install pylops"):
        _grid().as_pylops()
