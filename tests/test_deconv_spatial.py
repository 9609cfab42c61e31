"""Spatially varying blur and deconvolution (product-convolution over grid banks)."""

import math

import numpy as np
import pytest
from skimage import data, transform

from mitsweep.deconv import deconvolve
from mitsweep.deconv.kernels import (grid_bank_from_radial, interpolate_radial, rotate_kernel,
                                     select_depth)
from mitsweep.deconv.metrics import psnr
from mitsweep.deconv.spatial import (grid_axes_px, grid_kernel_field, grid_windows,
                                     hat_weights, scatter_blur,
                                     spatially_varying_blur, spatially_varying_deconvolve)
from mitsweep.deconv.synthetic import (synthetic_grid_bank, synthetic_kernel_field,
                                       synthetic_radial_bank)
from mitsweep.deconv.wiener import wiener_deconvolve
from mitsweep.io.bank import BankError, IPSFBank


@pytest.fixture(scope="module")
def camera128():
    return transform.resize(data.camera() / 255.0, (128, 128), anti_aliasing=True)


@pytest.mark.parametrize("nodes", [[0.0], [0.0, 10.0], [2.0, 5.0, 9.5, 20.0]])
def test_hat_weights_sum_to_one_and_interpolate(nodes):
    x = np.linspace(-5, 25, 301)
    w = hat_weights(x, nodes)
    np.testing.assert_allclose(w.sum(axis=0), 1.0, atol=1e-12)
    assert np.all(w >= 0)
    for j, n in enumerate(nodes):
        np.testing.assert_allclose(hat_weights(np.array([n]), nodes)[:, 0],
                                   np.eye(len(nodes))[j], atol=1e-12)


@pytest.mark.parametrize("shape,grid", [((64, 64), (1, 1)), ((64, 80), (3, 4)),
                                        ((96, 96), (5, 5))])
def test_product_convolution_equals_the_dense_operator(shape, grid):
    rng = np.random.default_rng(0)
    img = rng.random(shape)
    bank = synthetic_grid_bank(shape, grid, size=11)
    rows, cols = grid_axes_px(bank, shape)
    wy, wx = grid_windows(rows, cols, shape)
    k = select_depth(bank)
    fast = spatially_varying_blur(img, bank)
    dense = scatter_blur(img, grid_kernel_field(k, wy, wx))
    # two exact evaluations of the same sum: FFT round-off only (~1e-15)
    np.testing.assert_allclose(fast, dense, atol=1e-12)


def test_grid_axes_match_the_bank_points():
    bank = synthetic_grid_bank((90, 120), (4, 5), size=9)
    rows, cols = grid_axes_px(bank, (90, 120))
    np.testing.assert_allclose(rows, np.linspace(0, 89, 4), atol=1e-9)
    np.testing.assert_allclose(cols, np.linspace(0, 119, 5), atol=1e-9)


@pytest.mark.parametrize("grid,min_gain_db", [((9, 9), 9.0), ((17, 17), 12.0)])
def test_deconvolution_restores_the_true_blur(camera128, grid, min_gain_db):
    """The truth is the per-pixel analytic kernel field, not the grid model."""
    truth = scatter_blur(camera128, synthetic_kernel_field(camera128.shape, size=21))
    bank = synthetic_grid_bank(camera128.shape, grid, size=21)
    x = spatially_varying_deconvolve(truth, bank, nsr=1e-4)
    inner = (slice(16, -16), slice(16, -16))   # the truth loses light off the sensor edge
    # measured gains 11.1 dB (9x9) and 14.7 dB (17x17): the denser grid models the blur
    # better; the bars sit ~2.5 dB below
    assert psnr(x[inner], camera128[inner]) > psnr(truth[inner], camera128[inner]) + min_gain_db


def test_no_seams_identical_kernels_equal_one_global_wiener(camera128):
    """With one kernel everywhere the windows must blend to the global Wiener result."""
    base = synthetic_grid_bank(camera128.shape, (4, 4), size=11)
    k = np.repeat(base.kernels[:, 5:6], 16, axis=1)
    bank = IPSFBank(kernels=k, points_uv=base.points_uv, depths=base.depths,
                    pixel_pitch=base.pixel_pitch, reference_sensor_distance=30.0,
                    kind="grid", grid_shape=(4, 4), metadata=base.metadata)
    # the flat prior's inverse filter is compact, so 3 K of context captures it (the
    # natural prior's reaches farther: 1e-3 at 3 K, 2.5e-4 at 12 K)
    tiled = spatially_varying_deconvolve(camera128, bank, nsr=1e-4, prior="constant")
    whole = wiener_deconvolve(camera128, k[0, 0], nsr=1e-4, pad=3 * 11, prior="constant")
    # tiles see 3 K of context, the global filter the whole image: they differ only by
    # the inverse filter's tail beyond 3 K (measured max 2.8e-5, 1.5e-5 in the interior);
    # a seam (windows not summing to one, a misplaced tile) shows as >= 1e-2
    np.testing.assert_allclose(tiled, whole, atol=1e-4)


@pytest.mark.parametrize("value", [0.0, 1.0])
def test_constant_images_pass_unchanged(value):
    img = np.full((96, 96, 3), value, np.float32)
    out = spatially_varying_deconvolve(img, synthetic_grid_bank(img.shape, (4, 4), size=11),
                                       nsr=1e-4)
    assert out.dtype == np.float32 and out.shape == img.shape
    np.testing.assert_allclose(out, value, atol=1e-5)  # float32 FFT round-off


@pytest.mark.parametrize("theta_deg,where", [(90, (-1, 0)), (180, (0, -1)), (-90, (1, 0))])
def test_rotate_kernel_is_counter_clockwise_in_upright_coordinates(theta_deg, where):
    k = np.zeros((11, 11))
    k[5, 8] = 1.0                          # mass 3 px along +u (right)
    r = rotate_kernel(k, math.radians(theta_deg))
    row, col = np.unravel_index(np.argmax(r), r.shape)
    assert (np.sign(row - 5), np.sign(col - 5)) == where
    assert r.sum() == pytest.approx(1.0)


def test_radial_bank_rotated_to_a_grid_matches_the_analytic_kernels():
    shape = (64, 64)
    # kernels small enough not to be cut by the 21 px box at the corners (3 sigma < 10 px),
    # radii out to the corners
    kw = dict(size=21, radial=1.0, tangential=0.8)
    radial = synthetic_radial_bank(shape, n_radii=33, extent_px=46, **kw)
    grid = grid_bank_from_radial(radial, (3, 3), shape)
    direct = synthetic_grid_bank(shape, (3, 3), **kw)
    # rotation by cubic splines and linear interpolation between 33 radii: the kernels
    # agree to ~1 % of their peak (measured 0.6 %)
    peak = direct.kernels.max()
    assert np.abs(grid.kernels - direct.kernels).max() < 0.015 * peak


def test_interpolate_radial_is_linear_between_radii_and_clamped_outside():
    ks = np.stack([np.full((3, 3), 1.0), np.full((3, 3), 3.0)])
    np.testing.assert_allclose(interpolate_radial(ks, np.array([0.0, 10.0]), 2.5), 1.5)
    np.testing.assert_allclose(interpolate_radial(ks, np.array([0.0, 10.0]), 20.0), 3.0)


def test_deconvolve_dispatches_grid_banks(camera128):
    bank = synthetic_grid_bank(camera128.shape, (3, 3), size=11)
    np.testing.assert_array_equal(deconvolve(camera128, bank, nsr=1e-3),
                                  spatially_varying_deconvolve(camera128, bank, nsr=1e-3))


def test_radial_bank_is_refused_with_a_hint(camera128):
    with pytest.raises(BankError, match="grid_bank_from_radial"):
        spatially_varying_deconvolve(camera128, synthetic_radial_bank(camera128.shape, size=9))


def test_irregular_grid_is_refused():
    bank = synthetic_grid_bank((64, 64), (3, 3), size=9)
    pts = bank.points_uv.copy()
    pts[4, 0] += 0.05                                    # move the middle point sideways
    bad = IPSFBank(kernels=bank.kernels, points_uv=pts, depths=bank.depths,
                   pixel_pitch=bank.pixel_pitch, reference_sensor_distance=30.0, kind="grid",
                   grid_shape=(3, 3))
    with pytest.raises(BankError, match="regular"):
        spatially_varying_deconvolve(np.zeros((64, 64)), bad)


@pytest.mark.parametrize("resolution,pitch", [((200, 200), 0.06), ((262, 230), 0.06),
                                              ((512, 512), 0.02)])
def test_mirror_grid_puts_the_asked_nodes_across_the_tilted_mirrors_image(resolution, pitch):
    """The grid's node lines (cell centres over the sensor, as the tracer places them)
    that fall within the predicted outline's extent: at least ``nodes_across`` on each
    axis, where a 9x9 grid over the frame has 5 or 6 across this mirror."""
    from dataclasses import replace

    from mitsweep.config import Sensor, load_setup
    from mitsweep.deconv.spatial import MIRROR_GRID_NODES, mirror_grid_shape
    from mitsweep.optics.outline import predicted_outline
    from mitsweep.tracer.bank import grid_points

    from conftest import SCENES

    setup = replace(load_setup(SCENES / "paraboloid_tilted.toml"),
                    sensor=Sensor(resolution=resolution, pixel_pitch=pitch))
    uv = predicted_outline(setup).uv
    (u0, v0), (u1, v1) = uv.min(axis=0), uv.max(axis=0)

    def across(grid):
        pts = grid_points(setup, grid)
        us, vs = np.unique(pts[:, 0]), np.unique(pts[:, 1])
        return (int(np.sum((us >= u0) & (us <= u1))), int(np.sum((vs >= v0) & (vs <= v1))))

    rows, cols = mirror_grid_shape(setup)
    assert rows == cols and min(across((rows, cols))) >= MIRROR_GRID_NODES
    assert min(across((9, 9))) < MIRROR_GRID_NODES
    assert rows <= min(resolution) // 4
