"""The pixel-integrated Airy PSF."""

import numpy as np
import pytest
from scipy.special import j0, j1

from mitsweep.optics.diffraction import airy_kernel


@pytest.mark.slow   # one of the longest default tests (15-40 s on 2 cores): in CI's slow run
def test_encircled_energy_in_the_first_ring():
    """Rayleigh's classic: 83.8 % of the energy lies inside r = 1.22 λN (exactly
    1 − J0(x)² − J1(x)² at the first zero). Fine pixels (λN/8) make the pixel
    integration negligible; 1 % allows for the kernel's square pixels on the ring."""
    lam, n = 550e-6, 11.0
    pitch = lam * n / 8
    k = airy_kernel(n, pitch, rings=40)
    half = k.shape[0] // 2
    yy, xx = np.mgrid[-half:half + 1, -half:half + 1]
    r = np.hypot(xx, yy) * pitch
    x1 = 3.8317059702075125  # first zero of J1
    expected = 1 - j0(x1) ** 2 - j1(x1) ** 2
    inside = k[r <= 1.22 * lam * n].sum()
    # Truncation at 40 λN leaves ~0.5 % of the energy outside, renormalised in.
    assert inside == pytest.approx(expected, rel=0.015)


def test_kernel_is_unit_sum_symmetric_and_wider_when_stopped_down():
    k28 = airy_kernel(2.8, 0.018)
    k11 = airy_kernel(11.0, 0.018)
    for k in (k28, k11):
        assert k.sum() == pytest.approx(1.0) and np.allclose(k, k.T) and np.allclose(k, k[::-1])
    assert k11.shape[0] > k28.shape[0] and k11.max() < k28.max()


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan")])
def test_bad_f_number_is_refused(bad):
    with pytest.raises(ValueError, match="f_number"):
        airy_kernel(bad, 0.01)
