"""The noise of a RAW file that does not state it, estimated from its own photosites.

A DNG may carry its noise model (the NoiseProfile tag:
:func:`mitsweep.io.camera.dng_noise_profile`); most RAW files (CR2, NEF, ARW, a DNG
without the tag) do not. Their photosites still show it, before demosaicking correlates
it: each CFA plane's noise is white, with the variance ``S x + O`` of the normalised raw
value ``x`` (shot noise and read noise, the DNG convention). :func:`estimate_raw_noise`
fits that line the way Foi et al. (2008, "Practical Poissonian-Gaussian noise modeling
and fitting for single-image raw-data") do, simplified:

1. each CFA plane (every second photosite in each direction, one colour) is normalised
   to [0, 1] between its black and the white level;
2. a high-pass residual with unit noise gain, ``(4 p - p_up - p_down - p_left -
   p_right) / sqrt(20)`` (variance ``v`` for white noise of variance ``v``), and the
   local mean over 5 x 5 plane samples;
3. the samples (clipped ones and their neighbours left out) are put into bins of equal
   count by local mean, and each bin's noise variance is the squared MAD of its
   residuals over 0.6745 (robust: edges and texture, a minority of a bin, leave it);
4. a straight line ``v = S x + O`` through the bins, weighted by each bin's count over its
   variance squared (the variance of a variance estimate), with ``S, O >= 0``.

Texture that fills a whole bin reads as noise (the estimate is then high, never low), and
a sensor's noise that is not white across photosites (pattern noise, a camera's own
denoising in the raw data) is not this model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import lru_cache

import numpy as np

__all__ = ["estimate_raw_noise", "RAW_NOISE_BINS", "BLOCK", "MIN_BIN_BLOCKS", "QUANTILE", "MAX_SCATTER"]

#: Bins of local mean the variance is measured in, at most.
RAW_NOISE_BINS = 16
#: Side of the blocks of plane samples whose residual variance is measured, samples.
BLOCK = 8
#: Fewest blocks a bin needs.
MIN_BIN_BLOCKS = 12
#: The quantile of a bin's block variances taken as its noise (the flattest blocks: a
#: textured block only adds variance), divided by the same quantile for pure white
#: noise (:func:`_quantile_bias`).
QUANTILE = 0.1
#: Largest RMS relative scatter of the bins about the fitted line for the estimate to be
#: used (:func:`mitsweep.io.camera.read_camera_image`): bins whose flattest blocks are
#: still texture scatter off a noise line (0.4-1.2 on synthetic DNGs of textured
#: photos at low noise, whose estimate read 1.6-12 times the true sigma; 0.05-0.23 where
#: it read 1.05-1.18 times).
MAX_SCATTER = 0.3


def _residual(plane: np.ndarray) -> np.ndarray:
    """The plane's high-pass residual with unit noise gain (variance v for white noise of
    variance v), one sample smaller on each side."""
    return (4.0 * plane[1:-1, 1:-1] - plane[:-2, 1:-1] - plane[2:, 1:-1]
            - plane[1:-1, :-2] - plane[1:-1, 2:]) / math.sqrt(20.0)


def _blocks(a: np.ndarray) -> np.ndarray:
    """``a`` cut into whole BLOCK x BLOCK tiles: (n, BLOCK * BLOCK)."""
    h, w = (a.shape[0] // BLOCK) * BLOCK, (a.shape[1] // BLOCK) * BLOCK
    t = a[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK).swapaxes(1, 2)
    return t.reshape(-1, BLOCK * BLOCK)


@lru_cache(maxsize=1)
def _quantile_bias() -> float:
    """:data:`QUANTILE` of the block variances of pure unit white noise through
    :func:`_residual` (simulated once, fixed seed): the ratio a noise-only bin's
    quantile reads of its variance (the residuals of a block are correlated, so no
    chi-squared law gives it)."""
    rng = np.random.default_rng(0)
    s2 = (_blocks(_residual(rng.standard_normal((802, 802)))) ** 2).mean(axis=1)
    return float(np.quantile(s2, QUANTILE))


def estimate_raw_noise(raw: np.ndarray, colours: np.ndarray, black: Sequence[float],
                       white: float) -> dict | None:
    """The noise line ``(S, O)`` of a RAW's visible photosites (see the module
    docstring), or None where too few unclipped blocks are left to fit it.

    Parameters
    ----------
    raw : (H, W) ndarray
        The visible photosites (LibRaw's ``raw_image_visible``), in raw units.
    colours : (H, W) int ndarray
        Each photosite's colour index (LibRaw's ``raw_colors_visible``).
    black : sequence of float
        The black level per colour index.
    white : float
        The white level.

    Returns
    -------
    dict or None
        ``profile``: ``[(S, O)]``, one pair for all planes (the variance of a value
        normalised to [0, 1]); ``bins``: the bins' ``(mean, variance, blocks)``;
        ``rms_rel``: the bins' RMS relative departure from the line.
    """
    colours = np.asarray(colours)
    blk = np.asarray(black, dtype=np.float64)
    means, variances = [], []
    # the four photosites of a 2 x 2 CFA cell, each a plane of one colour
    for dr in (0, 1):
        for dc in (0, 1):
            plane = np.asarray(raw[dr::2, dc::2], dtype=np.float64)
            if min(plane.shape) < BLOCK + 2:
                continue
            c = int(colours[dr, dc])
            b = float(blk[min(c, len(blk) - 1)])
            span = float(white) - b
            if not span > 0:
                continue
            x = (plane - b) / span
            valid = (plane > b) & (plane < float(white))
            # a residual is valid where its 3 x 3 neighbourhood is
            ok = valid[1:-1, 1:-1] & valid[:-2, 1:-1] & valid[2:, 1:-1] \
                & valid[1:-1, :-2] & valid[1:-1, 2:]
            keep = _blocks(ok).all(axis=1)
            means.append(_blocks(x[1:-1, 1:-1]).mean(axis=1)[keep])
            variances.append((_blocks(_residual(x)) ** 2).mean(axis=1)[keep])
    if not means:
        return None
    m, v = np.concatenate(means), np.concatenate(variances)
    n_bins = min(RAW_NOISE_BINS, len(m) // MIN_BIN_BLOCKS)
    if n_bins < 2:
        return None
    order = np.argsort(m, kind="stable")
    bias = _quantile_bias()
    bins = [(float(m[idx].mean()), float(np.quantile(v[idx], QUANTILE)) / bias, len(idx))
            for idx in np.array_split(order, n_bins)]
    bx, bv, bn = (np.asarray(a, dtype=np.float64) for a in zip(*bins))
    if not np.all(np.isfinite(bv)) or not np.any(bv > 0):
        return None
    S, O = _nonnegative_line(bx, bv, bn)
    fit = S * bx + O
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(fit > 0, bv / fit - 1.0, np.nan)
    return {"profile": [(S, O)],
            "bins": [(float(a), float(b), int(c)) for a, b, c in zip(bx, bv, bn)],
            "rms_rel": float(np.sqrt(np.nanmean(rel ** 2))) if np.isfinite(rel).any()
            else math.nan}


def _nonnegative_line(x: np.ndarray, v: np.ndarray, n: np.ndarray) -> tuple[float, float]:
    """``(S, O)``, both >= 0, of ``v ~ S x + O`` by least squares weighted by
    ``n / v**2``, refitted with the line's own variances once (a variance estimate's
    spread scales with the variance itself)."""
    level = np.maximum(v, 1e-30)
    best = (0.0, float(np.average(v, weights=n)))
    for _ in range(2):
        w = n / level ** 2
        candidates = []
        A = np.column_stack([x, np.ones_like(x)]) * np.sqrt(w)[:, None]
        sol, *_ = np.linalg.lstsq(A, v * np.sqrt(w), rcond=None)
        if sol[0] >= 0 and sol[1] >= 0:
            candidates.append((float(sol[0]), float(sol[1])))
        # on the boundary: S = 0 (read noise only) or O = 0 (shot noise only)
        candidates.append((0.0, float(np.sum(w * v) / np.sum(w))))
        sx = float(np.sum(w * x * x))
        if sx > 0:
            candidates.append((max(0.0, float(np.sum(w * x * v) / sx)), 0.0))
        best = min(candidates, key=lambda so: float(np.sum(w * (v - so[0] * x - so[1]) ** 2)))
        level = np.maximum(best[0] * x + best[1], 1e-30)
    return best
