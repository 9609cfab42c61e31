"""Polar resampling and polar-domain deconvolution of rotationally symmetric blur."""

import math

import numpy as np
import pytest
import scipy.fft as sfft
from skimage import data, transform

from mitsweep.deconv import deconvolve
from mitsweep.deconv.metrics import disk_mask, psnr
from mitsweep.deconv.polar import from_polar, polar_deconvolve, polar_grid, to_polar
from mitsweep.deconv.spatial import scatter_blur
from mitsweep.deconv.synthetic import (synthetic_grid_bank, synthetic_kernel_field,
                                       synthetic_radial_bank)
from mitsweep.io.bank import BankError, IPSFBank


def _gray(name, size=None):
    img = getattr(data, name)()
    img = (img[..., 1] if img.ndim == 3 else img) / 255.0
    return transform.resize(img, (size, size), anti_aliasing=True) if size else img


@pytest.mark.parametrize("name", ["camera", "astronaut"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_polar_round_trip_above_50_db_inside_the_disk(name, dtype):
    img = _gray(name).astype(dtype)            # 512 x 512, sharp to the pixel
    grid = polar_grid(img.shape, r_max=250)
    back = from_polar(to_polar(img, grid), grid, img.shape)
    assert back.dtype == dtype
    # measured 54.0 (camera) and 56.7 dB (astronaut) with the default sampling (1.5
    # rows/px, 1.25 angles/px at the rim, no angular upsampling on the way back)
    assert psnr(back, img, mask=disk_mask(img.shape, 248)) > 50


def test_polar_grid_has_enough_angles_at_a_fast_length():
    g = polar_grid((300, 400), r_max=140)
    assert g.n_angles >= 2 * math.pi * 140
    assert sfft.next_fast_len(g.n_angles) == g.n_angles
    assert g.radii[0] < 0 and g.radii[-1] > 140    # continues through the centre and past r_max
    assert g.center == (149.5, 199.5)


@pytest.mark.parametrize("theta_deg,offset_rc", [(0, (0, 40)), (90, (-40, 0)),
                                                 (180, (0, -40)), (270, (40, 0))])
def test_polar_angle_is_counter_clockwise_from_plus_u(theta_deg, offset_rc):
    img = np.zeros((128, 128))
    cy, cx = 63.5, 63.5
    img[int(cy + 0.5) + offset_rc[0] - 1:int(cy + 0.5) + offset_rc[0] + 1,
        int(cx + 0.5) + offset_rc[1] - 1:int(cx + 0.5) + offset_rc[1] + 1] = 1.0
    g = polar_grid(img.shape, r_max=60)
    pol = to_polar(img, g)
    j = np.argmin(np.abs(g.radii - 40.5))
    k = int(np.argmax(pol[j]))
    ang = math.degrees(g.angles[k])
    assert min(abs(ang - theta_deg), 360 - abs(ang - theta_deg)) < 3


def test_to_polar_samples_a_smooth_function_exactly():
    yy, xx = np.mgrid[0:96, 0:96].astype(float)
    img = 0.3 + 0.002 * xx - 0.001 * yy          # linear: reproduced by cubic splines
    g = polar_grid(img.shape, r_max=40)
    pol = to_polar(img, g)
    r, th = g.radii[:, None], g.angles[None, :]
    ok = (g.radii > -40)[:, None] & (g.radii < 40)[:, None]
    expect = 0.3 + 0.002 * (47.5 + r * np.cos(th)) - 0.001 * (47.5 - r * np.sin(th))
    np.testing.assert_allclose(np.broadcast_to(pol, expect.shape)[ok[:, 0]],
                               expect[ok[:, 0]], atol=1e-9)


@pytest.fixture(scope="module")
def blurred_scene():
    """A 192² image blurred by the exact per-pixel synthetic IPSF field (the truth)."""
    img = _gray("camera", 192)
    K, rmax = 17, 96.0
    y = scatter_blur(img, synthetic_kernel_field(img.shape, size=K, r_max_px=rmax))
    bank = synthetic_radial_bank(img.shape, size=K, r_max_px=rmax, n_radii=19)
    return img, y, bank


def test_polar_deconvolution_restores_the_true_spatially_varying_blur(blurred_scene):
    img, y, bank = blurred_scene
    x = polar_deconvolve(y, bank, nsr=1e-4)
    rr = np.hypot(*(np.mgrid[0:192, 0:192] - 95.5))
    # measured: blurred 27-28 dB in every ring, restored 38-43 dB. A wrong rotation
    # direction or angular scale (harmonic m at m/r instead of m/(2 pi r)) drops the
    # outer rings below 32 dB; 8 dB per ring is the bar.
    for r0, r1 in [(0, 12), (12, 30), (30, 60), (60, 88)]:
        ring = (rr >= r0) & (rr < r1)
        assert psnr(x, img, mask=ring) > psnr(y, img, mask=ring) + 8, (r0, r1)


def test_deconvolve_dispatches_radial_banks_to_polar(blurred_scene):
    img, y, bank = blurred_scene
    np.testing.assert_array_equal(deconvolve(y, bank, nsr=1e-3),
                                  polar_deconvolve(y, bank, nsr=1e-3))


def _delta_bank(shape, K=9):
    k = np.zeros((1, 5, K, K), np.float32)
    k[..., K // 2, K // 2] = 1
    radii = np.linspace(0, 0.018 * shape[0] / 2, 5)
    return IPSFBank(kernels=k, points_uv=np.stack([radii, 0 * radii], 1),
                    depths=np.array([500.]),
                    pixel_pitch=0.018, reference_sensor_distance=30.0, kind="radial",
                    radii=radii)


def test_delta_bank_polar_deconvolution_is_the_round_trip():
    img = _gray("astronaut", 256)
    x = polar_deconvolve(img, _delta_bank(img.shape), nsr=1e-9, r_max=120)
    # resampling only: the same > 50 dB as the plain round trip
    assert psnr(x, img, mask=disk_mask(img.shape, 118)) > 50
    outside = ~disk_mask(img.shape, 121)
    np.testing.assert_array_equal(x[outside], img[outside])   # beyond r_max: unchanged


@pytest.mark.parametrize("scene", ["black", "saturated"])
@pytest.mark.parametrize("prior", ["constant", "natural"])
def test_constant_images_pass_unchanged(scene, prior):
    val = 0.0 if scene == "black" else 1.0
    img = np.full((128, 128), val, np.float32)
    bank = synthetic_radial_bank(img.shape, size=15)
    x = polar_deconvolve(img, bank, nsr=1e-4, prior=prior)
    assert x.dtype == np.float32
    # DC passes each band exactly and the windows sum to one; float32 splines ~1e-6
    np.testing.assert_allclose(x, val, atol=1e-5)


@pytest.mark.parametrize("nsr", [1e-6, 1e-2])
def test_stable_with_spectral_zeros_and_noise(nsr):
    rng = np.random.default_rng(0)
    img = rng.random((128, 128))
    K = 15
    k = np.zeros((1, 4, K, K), np.float32)
    k[..., K // 2, K // 2 - 3] = k[..., K // 2, K // 2 + 3] = 0.5   # exact spectral zeros
    radii = np.linspace(0, 1.2, 4)
    bank = IPSFBank(kernels=k, points_uv=np.stack([radii, 0 * radii], 1),
                    depths=np.array([500.]), pixel_pitch=0.018,
                    reference_sensor_distance=30.0, kind="radial", radii=radii)
    x = polar_deconvolve(img, bank, nsr=nsr)
    assert np.all(np.isfinite(x))
    # Wiener gain <= 1/(2 sqrt(nsr)); allow that times the input's range
    assert np.abs(x).max() < max(1.0, 1 / (2 * np.sqrt(nsr))) * 1.5


def test_colour_images_are_restored_per_channel(blurred_scene):
    _, y, bank = blurred_scene
    rgb = np.stack([y, 0.5 * y, y ** 2], axis=-1)
    out = polar_deconvolve(rgb, bank, nsr=1e-3)
    np.testing.assert_allclose(out[..., 1], polar_deconvolve(0.5 * y, bank, nsr=1e-3),
                               atol=1e-9)


def test_grid_bank_is_refused_by_polar():
    img = np.zeros((64, 64))
    with pytest.raises(BankError, match="radial"):
        polar_deconvolve(img, synthetic_grid_bank(img.shape, (3, 3), size=9), nsr=1e-3)


def test_bank_for_another_sensor_is_refused():
    bank = synthetic_radial_bank((128, 128), size=9)
    with pytest.raises(BankError, match="128x128"):
        polar_deconvolve(np.zeros((96, 128)), bank, nsr=1e-3)


@pytest.mark.parametrize("lux", [None, 50.0, 5.0, 0.5, 0.05])
@pytest.mark.parametrize("method", ["polar", "grid"])
def test_no_blow_up_from_no_noise_to_very_low_light(blurred_scene, lux, method):
    from mitsweep.deconv.noise import SensorNoise
    from mitsweep.deconv.spatial import spatially_varying_deconvolve

    img, y, bank = blurred_scene
    nsr = None
    if lux is not None:
        noise = SensorNoise(illuminance_lux=lux, exposure_s=0.6, f_number=2.8,
                            pixel_pitch=0.0064)
        y = noise.apply(y, rng=0)
        nsr = noise.nsr(mean_level=float(img.mean()), signal_std=float(img.std()))
    if method == "polar":
        x = polar_deconvolve(y, bank, nsr=nsr)
    else:
        x = spatially_varying_deconvolve(y, synthetic_grid_bank(img.shape, (9, 9), size=17,
                                                                r_max_px=96.0), nsr=nsr)
    m = disk_mask(img.shape, 90)
    assert np.all(np.isfinite(x))
    assert np.abs(x[m]).max() < 2.0          # the scene is in [0, 1]; measured <= 1.5
    # measured gains with the noise model's NSR and the natural prior: +11 dB without
    # noise, +3 dB at 50 lux, +0.3 dB at 0.5 lux, +8.6 dB at 0.05 lux (where the noise
    # itself dominates the error); a ringing blow-up loses many dB
    assert psnr(x, img, mask=m) > psnr(y, img, mask=m) - 1.0


# -- the sparse resampling ------------------------------------------------------------

@pytest.mark.parametrize("periodic", [False, True])
def test_spline_sampling_matrix_matches_map_coordinates(periodic):
    import scipy.ndimage as ndi

    from mitsweep.deconv.polar import spline_sampling_matrix

    rng = np.random.default_rng(1)
    coef = rng.standard_normal((23, 31))
    # points inside, on the edges and beyond them (mirrored or wrapped taps)
    rows = rng.uniform(-3, 25, 500)
    cols = rng.uniform(-3, 33, 500)
    M = spline_sampling_matrix(rows, cols, coef.shape, periodic_cols=periodic)
    if periodic:   # scipy's reference: the columns tiled three times
        ref = ndi.map_coordinates(np.tile(coef, (1, 3)), [rows, cols + 31], order=3,
                                  mode="mirror", prefilter=False)
    else:
        ref = ndi.map_coordinates(coef, [rows, cols], order=3, mode="mirror",
                                  prefilter=False)
    # same arithmetic in another order: float64 round-off
    np.testing.assert_allclose(M @ coef.ravel(), ref, rtol=0, atol=1e-12)


@pytest.fixture(params=["jit", "ndimage"])
def resampler(request, monkeypatch):
    """The polar resampling's two evaluators: the Dr.Jit kernels (where a backend
    works: here always) and their scipy.ndimage reference (the fallback elsewhere)."""
    from mitsweep.deconv import polar

    if request.param == "ndimage":
        monkeypatch.setattr(polar.spline, "jit_kernels", lambda: None)
    else:
        assert polar.spline.jit_kernels() is not None
    return request.param


@pytest.mark.parametrize("rows,center", [(128, None), (120, None), (120, (60.25, 70.8)),
                                         (128, (3.5, 125.0))])
def test_polar_resampling_matrices_are_to_polar_and_from_polar(rows, center, resampler):
    """The public matrices (16 taps a point, written by NumPy) agree with to_polar and
    from_polar (Dr.Jit kernels or scipy.ndimage) to float64 round-off, on square and
    other images, for poles at the centre, off it and near a corner (whose grid reaches
    far beyond the image: mirrored coefficients)."""
    import scipy.ndimage as ndi

    from mitsweep.deconv.polar import polar_resampling, polar_spline_coefficients

    img = _gray("camera", 128)[:rows]
    g = polar_grid(img.shape, center=center, r_max=55)
    T, B = polar_resampling(g, img.shape)
    assert T.shape == (g.n_radii * g.n_angles, img.size) and B.shape == T.shape[::-1]
    coef = ndi.spline_filter(img, order=3, mode="mirror")
    pol = to_polar(img, g)
    np.testing.assert_allclose((T @ coef.ravel()).reshape(pol.shape), pol, atol=1e-12)
    back = from_polar(pol, g, img.shape)
    via_b = (B @ polar_spline_coefficients(pol).ravel()).reshape(img.shape)
    # from_polar rebuilds the rows near the pole at fewer angles: compare where it
    # reads the full grid (2π (r + 8) 0.75 >= n/4 - 8 harmonics)
    cy, cx = g.center
    rr = np.hypot(*np.mgrid[0:rows, 0:128] - np.array([cy, cx])[:, None, None])
    full = (rr <= g.r_max) & (2 * np.pi * (rr + 8) * 0.75 >= g.n_angles / 4 - 8)
    assert full.sum() > 0.3 * (rr <= g.r_max).sum()
    np.testing.assert_allclose(back[full], via_b[full], atol=1e-12)
    assert np.all(via_b[rr > g.r_max] == 0) and np.all(back[rr > g.r_max] == 0)


@pytest.mark.parametrize("dtype,tol,spec_tol", [(np.float32, 5e-7, 1e-8),
                                                (np.float64, 2e-13, 1e-16)])
def test_dr_jit_resampling_matches_its_ndimage_reference(dtype, tol, spec_tol, monkeypatch):
    """Both resamplings, Dr.Jit against scipy.ndimage, on a 3-channel off-centre image
    with all three angle levels: the same spline, summed in another order. Tolerances:
    about 3x what was measured (pixels 1.8e-7 in float32, 5.1e-14 in float64, for values
    of order 1; the angle spectrum's largest difference over its largest value and
    sqrt(n_angles) 3.0e-9 and 1.6e-17)."""
    from mitsweep.deconv import polar

    img = np.stack([_gray(n, 160) for n in ("camera", "astronaut", "coins")], -1)
    img = img[:150].astype(dtype)
    g = polar_grid(img.shape, center=(70.3, 84.9))
    assert len({n for _, n in polar.grid.polar_levels(g, True)}) == 3
    spec_jit = polar.resample.angle_spectrum(img, g, np.complex128)
    out_jit = polar.resample.from_angle_spectrum(spec_jit, g, img.shape[:2], upsample=1.0,
                                                 outside=img, dtype=dtype)
    monkeypatch.setattr(polar.spline, "jit_kernels", lambda: None)
    spec_ref = polar.resample.angle_spectrum(img, g, np.complex128)
    out_ref = polar.resample.from_angle_spectrum(spec_jit, g, img.shape[:2], upsample=1.0,
                                                 outside=img, dtype=dtype)
    scale = np.abs(spec_ref).max()
    assert np.abs(spec_jit - spec_ref).max() <= spec_tol * scale * g.n_angles ** 0.5
    assert out_jit.dtype == out_ref.dtype == dtype
    np.testing.assert_allclose(out_jit, out_ref, rtol=0, atol=tol)


def test_polar_deconvolution_without_dr_jit_gives_the_same_image(blurred_scene, monkeypatch):
    """Where no Dr.Jit backend works the resamplings fall back to scipy.ndimage: the
    restored image is the same to round-off (float64 here: measured 3.6e-14, the
    resamplings' 1e-15 amplified by the Wiener filter's gain; the bound is 3x that)."""
    from mitsweep.deconv import polar

    _, y, bank = blurred_scene
    fast = polar_deconvolve(y, bank, nsr=1e-3)
    monkeypatch.setattr(polar.spline, "jit_kernels", lambda: None)
    ref = polar_deconvolve(y, bank, nsr=1e-3)
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1.1e-13)


def test_polar_deconvolution_does_not_depend_on_threads_or_calls(blurred_scene, monkeypatch):
    from mitsweep.deconv import polar

    _, y, bank = blurred_scene
    outs = []
    for n in (1, 3):
        monkeypatch.setattr(polar.spline, "threads", lambda n=n: n)
        outs.append(polar_deconvolve(y, bank, nsr=1e-3))
        outs.append(polar_deconvolve(y, bank, nsr=1e-3))
    for o in outs[1:]:
        np.testing.assert_array_equal(o, outs[0])


def test_concurrent_calls_from_threads_give_the_serial_results():
    """A user's thread pool (or a threaded executor) may call the polar deconvolution
    at once from several threads: the Dr.Jit kernels and the band threads must not mix
    their data."""
    from concurrent.futures import ThreadPoolExecutor

    imgs = [_gray(n, 128).astype(np.float32) for n in ("camera", "astronaut", "coins")]
    bank = synthetic_radial_bank((128, 128), size=11, r_max_px=60.0, n_radii=9)
    serial = [polar_deconvolve(x, bank, nsr=1e-3) for x in imgs]
    with ThreadPoolExecutor(3) as pool:
        par = list(pool.map(lambda x: polar_deconvolve(x, bank, nsr=1e-3), imgs * 2))
    for a, b in zip(serial * 2, par):
        np.testing.assert_array_equal(a, b)


def test_memory_estimate_bounds_the_measured_peak():
    """polar_memory_bytes (what the allocation check is given) is at least the peak
    NumPy and Dr.Jit allocate in a call, and not wildly more."""
    from memory_peak import traced_peak

    from mitsweep.deconv import polar

    img = _gray("astronaut", 384).astype(np.float32)
    bank = synthetic_radial_bank(img.shape, size=15, r_max_px=180.0, n_radii=19)
    peak = traced_peak(lambda: polar_deconvolve(img, bank, nsr=1e-3))
    K = 15
    rad = polar.radii_px(bank)
    g = polar_grid(img.shape, r_max=min(float(rad.max()) + K, polar_grid(img.shape).r_max),
                   inner_px=8, outer_px=8)
    est = polar.polar_memory_bytes(g, img.shape, np.float32)
    assert peak <= est <= 3 * peak, (peak, est)


@pytest.mark.parametrize("dtype,tol", [(np.float32, 3e-6), (np.float64, 1e-13)])
@pytest.mark.parametrize("shape", [(2048, 40), (300, 257), (40, 7), (3, 5)])
def test_spline_prefilter_matches_ndimage(shape, dtype, tol):
    import scipy.ndimage as ndi

    from mitsweep.deconv.polar.spline import spline_filter

    a = (np.random.default_rng(3).random(shape) * 4 - 1).astype(dtype)  # values in [-1, 3]
    for axes in [(0,), (0, 1)]:
        ref = a
        for ax in axes:
            ref = ndi.spline_filter1d(ref, order=3, axis=ax, output=dtype, mode="mirror")
        got = spline_filter(a, axes, dtype)
        assert got.dtype == dtype
        # rows filtered by recursions in the array's precision (ndimage: float64 lines);
        # float32 differs by a few ulp of coefficients up to ~5
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol)


def _band_transfer_by_fft(k, r, step, L, M, cdt):
    """Reference: pixel kernel zero-padded to L step px, FFT, rows clipped to Nyquist."""
    K0, K1 = k.shape
    t = -(np.arange(K0) - K0 // 2)
    T = np.einsum("ts,tm->sm", k, np.exp(-1j * np.outer(t, np.arange(M)) / r))
    L_px = int(round(L * step))
    big = np.zeros((L_px, M), complex)
    big[np.arange(K1) - K1 // 2] = T
    H = np.fft.fft(big, axis=0)
    p = np.rint(np.fft.fftfreq(L) * L).astype(int)
    return (H[np.clip(p, -(L_px // 2), (L_px - 1) // 2) % L_px] / k.sum()).astype(cdt)


@pytest.mark.parametrize("L,step", [(45, 2 / 3), (300, 2 / 3), (64, 1.0), (90, 0.5)])
@pytest.mark.parametrize("cdt,tol", [(np.complex64, 2e-6), (np.complex128, 1e-12)])
@pytest.mark.parametrize("rows", [9, 8])     # odd: the even/odd split of the kernel
def test_band_transfer_and_filter_match_their_definitions(L, step, cdt, tol, rows):
    from mitsweep.deconv.polar.bands import band_transfer, band_wiener
    from mitsweep.deconv.wiener import regulariser, wiener_filter

    k = np.random.default_rng(4).random((rows, 13))
    H = band_transfer(k, 40.0, step, L, 70, cdt)
    assert H.dtype == cdt
    np.testing.assert_allclose(H, _band_transfer_by_fft(k, 40.0, step, L, 70, cdt),
                               rtol=0, atol=tol)
    nu = np.fft.fftfreq(L, d=step)
    ft = np.arange(70) / (2 * math.pi * 40.0)
    for prior in ("natural", "constant"):
        for nsr in (1e-3, 0.0):
            R = regulariser(H.shape, nsr, prior, dtype=H.real.dtype,
                            freqs=(nu[:, None], ft[None, :]), n_px=256.0)
            ref = wiener_filter(H.copy(), R)
            got = band_wiener(H.copy(), nu, ft, nsr, prior, 256.0)
            np.testing.assert_allclose(got, ref, rtol=20 * tol, atol=20 * tol)
            assert got[0, 0] == pytest.approx(1.0)       # DC passes: R = 0 there
