"""Designing the sweep, not only its range: the sensor's time profile as a design variable.

The IPSF is linear in the time density ``w(i)`` of the sensor over its distances,
``IPSF(ρ, l) = ∫ PSF(ρ, l, i) w(i) di`` with ``w >= 0`` and ``∫ w di = 1`` (normalised
exposure), so the predicted restoration error at every field point and depth is a
known function of ``w``; :func:`design_sweep` chooses it.

The objective, exactly
----------------------
The span (default: the optimal sweep range, paper Eq. 8–9) is cut into N equal bins of
sensor distance; ``τ_k`` is the fraction of the exposure ``T`` (fixed: the setup's sweep
exposure over the optimal range) spent in bin k, at constant velocity there. For every
field point ``p`` (radii 0 .. the FOV's edge; for a tilted mirror, grid points over the
sensor that see the mirror, and under the deployed restoration the nodes of the grid bank
that restores the image and its cell centres, :func:`~mitsweep.design.sweep.blended_grid_points`)
and depth ``l`` (the setup's depth range's ends and the
paper's V_avg depths 0.5, 1, 5, 10 m within it) the predicted error is the per-pixel
Wiener MSE of a natural image (power spectrum ``∝ 1/|f|²``, variance ``σ_s² = 0.5²``,
mean 0.5, relative exposure, white = 1) under the sensor noise at the given light level
(``σ² =`` :meth:`mitsweep.deconv.SensorNoise.variance` at 0.5),

.. math:: \\mathrm{MSE}_{p,l}(τ) = \\frac{σ^2}{n^2} \\sum_{f \\ne 0}
          \\frac{1}{\\big|\\sum_k τ_k \\hat P_{p,l,k}(f)\\big|^2 + R(f)},
          \\qquad R(f) = \\frac{σ^2}{σ_s^2}\\, 2π \\ln\\frac{n_{px}}{2}\\, |f|^2,

``P̂_{p,l,k}`` the transfer function of the PSF averaged over bin k (traced,
:mod:`mitsweep.design.planes`) on an n × n DFT grid, ``n_px`` the sensor's size in
pixels. ``objective="worst"`` minimises ``max_{p,l} MSE_{p,l}``, ``"mean"`` the mean
over the image, ``Σ_p w_p mean_l MSE_{p,l}`` (``w_p`` the share of the image point ``p``
stands for, :func:`image_area_weights`; an untilted mirror's radii then reach the rim's
image beyond the FOV), subject to ``Σ τ_k = 1``, the stage's velocity (``Δi_k / (τ_k T) <= rig.max_velocity``)
and acceleration (``|v_{k+1} − v_k| <= rig.acceleration · min(τ_k, τ_{k+1}) T``, the
velocity change made within the shorter of the two bins, as the rig's plan requires;
imposed as it stands, not linearised). The uniform sweep (τ_k = 1/N) is the paper's linear sweep.

The optimiser is local (SLSQP, deterministic); its certificate is a lower bound on the
optimum from a convex relaxation (:mod:`mitsweep.design.optimize`) and exhaustive search
on the problem coarsened to 6 bins.
"""

from .objective import WienerModel, wiener_model
from .optimize import StageLimits, brute_force, certified_lower_bound, local_optimum
from .planes import PlaneBank, plane_bank, plane_psfs
from .sweep import SweepDesign, design_depths, design_points, design_sweep, image_area_weights

__all__ = ["design_sweep", "SweepDesign", "design_depths", "design_points",
           "image_area_weights", "PlaneBank", "plane_bank", "plane_psfs", "WienerModel",
           "wiener_model", "StageLimits", "local_optimum", "certified_lower_bound",
           "brute_force"]
