r"""Where a restoration's error comes from: an error budget per radius and depth band.

:func:`error_budget` splits the squared error of a restored focal-sweep image against
its ground truth into terms, one per source of error, by a *sequential decomposition*:
a chain of inputs, each adding one source to the previous one, every input restored and
scored against the truth. A term is the increase of the mean squared error (MSE) from
one step to the next, so the terms add up, by construction, to the error of the last
step, which is the restoration the user got. The order:

===============  =====================================================================
term             the step's input (restored with the weight in brackets)
===============  =====================================================================
``information``  the bank's blur of the truth at the bank depth, no noise (oracle).
                 What no weight recovers from the exact model: the sweep's and the
                 method's information limit.
``depth``        each pixel of the truth blurred with the bank kernels of its own depth
                 (the depth AOV, nearest bank depth in 1/depth) instead of the one
                 bank depth (oracle). Only with a depth map and a bank of several depths.
``mismatch``     the render without sensor noise (oracle); with a second seed, the mean
                 of the two seeds' renders. Everything the bank's model misses: radial
                 and angular sampling of the bank, the field beyond the traced radii,
                 occlusion edges, diffraction, the render's Monte Carlo noise not
                 counted under ``monte_carlo``.
``monte_carlo``  one seed's render (oracle). Only with a second seed: this step goes
                 from the two-seed mean to one render, i.e. from half the Monte Carlo
                 variance to all of it. For a linear restoration the noise's share of
                 the MSE grows with its variance, so about as much Monte Carlo error
                 again is still inside ``mismatch``.
``sensor``       the image that was restored: the render with sensor noise (oracle).
                 Zero when that image is the noise-free render.
``weight``       the restoration that was made, with its chosen weight (or stopping):
                 what the weight choice costs against the oracle's.
===============  =====================================================================

Why sequential: the sources do not add in the error (a weight tuned for noise also
smooths the mismatch), so any split is a choice; a chain of real inputs, each restored
as well as it can be, makes every term an error one can measure and the terms add up
exactly. The order runs from what the model can explain to what the data add, and ends
with the one choice the pipeline makes. A term may be negative on a region (a source
may land, by chance, on the side of the truth; the oracle weight is tuned on the whole
image, not per region), rarely overall.

The *oracle* weight of a step is the scalar weight (Wiener's NSR, the prior weight λ of
TV / hyper-Laplacian) that minimises the MSE over the mask against the truth: a grid in
log weight, then a bounded Brent search (:func:`scipy.optimize.minimize_scalar`) between
the grid neighbours of its best point (:func:`oracle_weight`).

Errors are per pixel, averaged over the channels, in the truth's units (data range 1:
divide by the white level first), reported as MSE per region: the whole mask, radial
bins (pixels from the optical axis), depth bands (from the depth AOV), and two regions
of the mismatch's likely sources: ``beyond_fov`` (radii past the bank's outermost
traced point) and ``occlusion_edges`` (pixels near a depth discontinuity).
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass, field
from typing import Any
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

from ..deprecation import renamed_fields, renamed_keywords
from ..io.bank import IPSFBank
from ..optics.pixels import optical_center_px
from .kernels import PAPER_DECONV_DEPTH_MM
from .noise import SensorNoise

__all__ = ["error_budget", "oracle_weight", "layered_blur", "ErrorBudget", "TERMS",
           "TERM_INPUTS", "DEPTH_BANDS_MM", "WEIGHT_BOUNDS"]

logger = logging.getLogger(__name__)

#: Every term, in the order of the decomposition (a budget holds those it could measure).
TERMS = ("information", "depth", "mismatch", "monte_carlo", "sensor", "weight")
#: What each step restores (the table's and the docs' wording).
TERM_INPUTS = {
    "information": "bank's blur of the truth, no noise, oracle weight",
    "depth": "truth blurred with the bank depth of each pixel's depth AOV, oracle weight",
    "mismatch": "the render without sensor noise (two-seed mean if given), oracle weight",
    "monte_carlo": "one seed's render, oracle weight",
    "sensor": "the image that was restored (with sensor noise), oracle weight",
    "weight": "the restoration made, with its chosen weight",
}
#: Depth bands of the report, mm (those of :func:`mitsweep.pipeline.evaluate_dataset`).
DEPTH_BANDS_MM = (0.0, 300.0, 1000.0, 3000.0, math.inf)
#: Search range of the oracle weight per method (Wiener's NSR, the priors' λ).
WEIGHT_BOUNDS = {"wiener": (1e-10, 1.0), "tv": (1e-6, 1.0), "hyperlaplacian": (1e-6, 1.0)}
#: Relative depth jump between neighbouring pixels that marks an occlusion edge.
EDGE_DEPTH_RATIO = 1.25


def _mse_map(x: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(H, W) squared error averaged over the channels, float64."""
    d = np.asarray(x, dtype=np.float64) - np.asarray(truth, dtype=np.float64)
    d *= d
    return d if d.ndim == 2 else d.mean(axis=2)


def _digest(a: np.ndarray) -> str:
    a = np.ascontiguousarray(a)
    return hashlib.sha1(a.view(np.uint8).ravel().data).hexdigest() + str(a.dtype) + str(a.shape)


def oracle_weight(image: np.ndarray, truth: np.ndarray,
                  restore: Callable[[np.ndarray, float], np.ndarray], *,
                  mask: np.ndarray | None = None, bounds: tuple[float, float] = (1e-7, 1.0),
                  grid_points: int = 9, xatol: float = 0.02
                  ) -> tuple[float, np.ndarray, float]:
    """The scalar weight whose restoration of ``image`` is nearest ``truth`` (MSE in mask).

    Parameters
    ----------
    image, truth : (H, W) or (H, W, C) ndarray
    restore : callable
        ``restore(image, weight) -> restored`` (same shape).
    mask : (H, W) bool ndarray, optional
        Pixels scored (default all).
    bounds : (float, float)
        Search range of the weight (> 0): ``grid_points`` log-spaced weights, then a
        bounded Brent search in log weight between the best one's neighbours, to
        ``xatol`` in log10 (0.02: 5 % in weight).

    Returns
    -------
    weight, restored, mse
        The best weight tried (never worse than any grid point), its restoration and
        its MSE over the mask.
    """
    from scipy.optimize import minimize_scalar

    lo, hi = (math.log10(float(b)) for b in bounds)
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"bounds must be two increasing weights > 0, got {bounds!r}")
    m = np.ones(np.shape(truth)[:2], dtype=bool) if mask is None else np.asarray(mask, bool)
    tried: dict[float, float] = {}
    best: dict[str, Any] = {"mse": math.inf}

    def f(t: float) -> float:
        t = float(t)
        if t not in tried:
            x = restore(image, 10.0 ** t)
            e = float(_mse_map(x, truth)[m].mean())
            tried[t] = e if math.isfinite(e) else math.inf
            if tried[t] < best["mse"]:
                best.update(mse=tried[t], t=t, x=x)
        return tried[t]

    grid = np.linspace(lo, hi, max(3, int(grid_points)))
    vals = [f(t) for t in grid]
    i = int(np.argmin(vals))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    minimize_scalar(f, bounds=(a, b), method="bounded", options={"xatol": xatol})
    if not math.isfinite(best["mse"]):
        raise ValueError("no weight in the search range gives a finite restoration")
    logger.debug("oracle weight %.4g (MSE %.4g, %d restorations)", 10 ** best["t"],
                 best["mse"], len(tried))
    return 10.0 ** best["t"], best["x"], best["mse"]


def _per_channel(op: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    if x.ndim == 2:
        return op(x)
    return np.stack([op(x[..., c]) for c in range(x.shape[2])], axis=-1)


def _layer_index(depth: np.ndarray, bank_depths: np.ndarray, default: int) -> np.ndarray:
    """Per pixel the bank depth nearest its depth (in 1/depth); ``default`` where the
    depth is unknown (not finite, or <= 0: no hit)."""
    d = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(d) & (d > 0)
    with np.errstate(divide="ignore"):
        inv_bank = 1.0 / np.asarray(bank_depths, dtype=np.float64)
        inv = np.where(ok, 1.0 / np.where(ok, d, 1.0), 0.0)
    idx = np.argmin(np.abs(inv[..., None] - inv_bank), axis=-1)
    return np.where(ok, idx, default)


@renamed_keywords(depth_mm="deconvolution_depth")
def layered_blur(truth: np.ndarray, bank: IPSFBank, depth: np.ndarray, *,
                 deconvolution_depth: float | None = None,
                 dtype: DTypeLike = np.float64) -> np.ndarray:
    r"""The truth blurred layer by layer: :math:`\sum_d A_d (t \cdot 1[\text{layer}=d])`.

    Each pixel belongs to the bank depth nearest its depth (``depth``, mm, the depth
    AOV; in 1/depth); pixels of unknown depth to the bank depth that
    ``deconvolution_depth`` picks
    (the deconvolution's, default 500 mm). :math:`A_d` is the bank's blur at depth d
    (:func:`~mitsweep.deconv.restore.blur_operator`). Occlusion is not modelled: a near
    layer's blur spreads over the far one's pixels, as in a layered scene without
    visibility.

    Parameters
    ----------
    truth : (H, W) or (H, W, C) ndarray
        The sharp image.
    bank : IPSFBank
        The IPSF bank whose kernels at each of its depths blur the layers.
    depth : (H, W) ndarray
        Scene depth per pixel, mm; not finite or <= 0 where unknown (no hit).
    deconvolution_depth : float, optional
        Depth, mm, whose nearest bank depth takes the pixels of unknown depth (default
        :data:`~mitsweep.deconv.kernels.PAPER_DECONV_DEPTH_MM`, the deconvolution's).
        The former keyword ``depth_mm`` is still accepted, with a
        :class:`DeprecationWarning`.
    dtype : dtype
        Working and output precision (default float64).

    Returns
    -------
    ndarray
        The blurred image, the shape of ``truth``.
    """
    from .restore import blur_operator

    t = np.asarray(truth, dtype=dtype)
    depths = np.asarray(bank.depths, dtype=np.float64)
    default = int(_layer_index(np.array([PAPER_DECONV_DEPTH_MM if deconvolution_depth is None
                                         else float(deconvolution_depth)]), depths, 0)[0])
    layer = _layer_index(depth, depths, default)
    out = np.zeros_like(t)
    for k in np.unique(layer):
        op = blur_operator(bank, t.shape, depth=float(depths[k]), dtype=dtype)
        sel = (layer == k) if t.ndim == 2 else (layer == k)[..., None]
        part = t if bool(np.all(layer == k)) else np.where(sel, t, 0.0)
        out += _per_channel(op.forward, part)
    return out


def _occlusion_edges(depth: np.ndarray, width_px: int) -> np.ndarray:
    """Pixels within ``width_px`` of a jump of more than ``EDGE_DEPTH_RATIO`` in depth
    between 4-neighbours (or between a hit and a miss)."""
    from scipy.ndimage import binary_dilation

    d = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(d) & (d > 0)
    logd = np.log(np.where(ok, d, 1.0))
    edge = np.zeros(d.shape, dtype=bool)
    jump = math.log(EDGE_DEPTH_RATIO)
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        e = (np.abs(logd[tuple(a)] - logd[tuple(b)]) > jump) & ok[tuple(a)] & ok[tuple(b)]
        e |= ok[tuple(a)] != ok[tuple(b)]
        edge[tuple(a)] |= e
        edge[tuple(b)] |= e
    if width_px > 0 and edge.any():
        edge = binary_dilation(edge, iterations=int(width_px))
    return edge


def _psnr(mse: float) -> float:
    if not math.isfinite(mse):
        return math.nan
    return math.inf if mse <= 0 else -10.0 * math.log10(mse)


def _json_safe(o: Any) -> Any:
    """Plain JSON values: NaN → None, ±inf → "inf" / "-inf" (the CLI's ``json_text``
    convention), NumPy scalars and arrays → Python ones."""
    if isinstance(o, np.ndarray):
        return _json_safe(o.tolist())
    if isinstance(o, (np.floating, float)):
        v = float(o)
        return v if math.isfinite(v) else (None if math.isnan(v) else
                                           ("inf" if v > 0 else "-inf"))
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, dict):
        return {str(k): _json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_json_safe(v) for v in o]
    return o


@renamed_fields(depth_edges_mm="depth_edges")
@dataclass(frozen=True, kw_only=True)
class ErrorBudget:
    """A restoration's error split into terms (see the module docstring).

    Attributes
    ----------
    terms : tuple of str
        The terms measured, in the decomposition's order (a subset of :data:`TERMS`).
    weights : dict
        The weight each step's restoration used (the oracle's; ``weight``: the chosen
        one, None when unknown).
    regions : tuple of str
        Region names: ``"all"``, ``"r<i>"`` (radial bins), ``"d<i>"`` (depth bands),
        ``"beyond_fov"``, ``"occlusion_edges"`` (those present).
    pixels : (n_regions,) int ndarray
    mse : (n_terms, n_regions) ndarray
        Cumulative MSE after each step (data range 1); the last row is the measured
        error of the restoration.
    radius_edges_px : ndarray
        Edges of the radial bins, px.
    depth_edges : ndarray
        Edges of the depth bands, mm (``as_dict`` writes them under ``edges_mm``, as
        before). The former name ``depth_edges_mm`` is still accepted and readable,
        with a :class:`DeprecationWarning`.
    method : str
    info : dict
        Anything else worth recording (bank depth, the traced radius, the edge width).
    """

    terms: tuple[str, ...]
    weights: dict[str, float | None]
    regions: tuple[str, ...]
    pixels: np.ndarray
    mse: np.ndarray
    radius_edges_px: np.ndarray
    depth_edges: np.ndarray
    method: str
    info: dict = field(default_factory=dict)

    @property
    def term_mse(self) -> np.ndarray:
        """(n_terms, n_regions): each term's MSE (the first step's MSE, then the
        differences between consecutive steps). Sums to ``mse[-1]``."""
        return np.diff(self.mse, axis=0, prepend=np.zeros((1, self.mse.shape[1])))

    def _rows(self, prefix: str) -> list[int]:
        return [j for j, r in enumerate(self.regions) if r.startswith(prefix)
                and r[len(prefix):].isdigit()]

    def as_dict(self) -> dict:
        """Strict-JSON-ready dict: per region its pixels, each term's MSE, the MSE and
        PSNR (dB) after each step; NaN (an empty region) as None."""
        tm = self.term_mse

        def block(cols: list[int], scalar: bool = False) -> dict:
            def pick(a):
                return a[cols[0]] if scalar else [a[j] for j in cols]
            return {"pixels": pick(self.pixels.tolist()),
                    "terms": {t: pick(tm[k].tolist()) for k, t in enumerate(self.terms)},
                    "mse_after": {t: pick(self.mse[k].tolist())
                                  for k, t in enumerate(self.terms)},
                    "psnr_after": {t: pick([_psnr(v) for v in self.mse[k]])
                                   for k, t in enumerate(self.terms)}}

        out: dict[str, Any] = {
            "order": list(self.terms), "method": self.method,
            "inputs": {t: TERM_INPUTS[t] for t in self.terms},
            "weights": dict(self.weights),
            "total": block([self.regions.index("all")], True),
            "per_radius": {"edges_px": self.radius_edges_px, **block(self._rows("r"))},
            "per_depth_band": ({"edges_mm": self.depth_edges, **block(self._rows("d"))}
                               if self._rows("d") else None),
            "regions": {r: block([j], True) for j, r in enumerate(self.regions)
                        if r in ("beyond_fov", "occlusion_edges")},
            "info": dict(self.info),
        }
        return _json_safe(out)

    def table(self) -> str:
        """The budget as text: one row per region, each term's MSE × 10⁴ and the PSNR
        after the last step (the measured one)."""
        short = {"information": "info", "monte_carlo": "MC"}
        heads = [short.get(t, t) for t in self.terms]
        lines = [(f"terms: MSE x 1e4 (data range 1), in order {' -> '.join(self.terms)}; "
                  f"PSNR: the restoration's"),
                 f"{'region':<18s} {'pixels':>7s} " + " ".join(f"{h:>9s}" for h in heads)
                 + f" {'total':>9s} {'PSNR dB':>8s}"]
        tm = self.term_mse
        for j, r in enumerate(self.regions):
            label = self._label(r)
            vals = " ".join(f"{1e4 * v:9.3f}" if math.isfinite(v) else f"{'-':>9s}"
                            for v in tm[:, j])
            total = self.mse[-1, j]
            tot = f"{1e4 * total:9.3f}" if math.isfinite(total) else f"{'-':>9s}"
            p = _psnr(total)
            ps = f"{p:8.2f}" if math.isfinite(p) else f"{'-' if math.isnan(p) else 'inf':>8s}"
            lines.append(f"{label:<18s} {int(self.pixels[j]):7d} {vals} {tot} {ps}")
        return "\n".join(lines) + "\n"

    def _label(self, region: str) -> str:
        if region[0] in "rd" and region[1:].isdigit():
            i = int(region[1:])
            if region[0] == "r":
                e = self.radius_edges_px
                return f"r {e[i]:.0f}-{e[i + 1]:.0f} px"
            e = self.depth_edges
            hi = "inf" if not math.isfinite(e[i + 1]) else f"{e[i + 1] / 1000:g}"
            return f"depth {e[i] / 1000:g}-{hi} m"
        return region


@renamed_keywords(depth_mm="deconvolution_depth", depth_bands_mm="depth_bands")
def error_budget(truth: np.ndarray, observed: np.ndarray, bank: IPSFBank, *,
                 clean_observed: np.ndarray | None = None,
                 second_seed: np.ndarray | None = None,
                 restored: np.ndarray | None = None,
                 depth: np.ndarray | None = None, mask: np.ndarray | None = None,
                 method: str = "wiener", weight: float | None = None,
                 noise: SensorNoise | float | None = None,
                 deconvolution_depth: float | None = None,
                 radius_edges_px: ArrayLike | None = None, n_radial_bins: int = 8,
                 depth_bands: ArrayLike = DEPTH_BANDS_MM, edge_width_px: int = 2,
                 weight_bounds: tuple[float, float] | None = None,
                 **restore_kw: Any) -> ErrorBudget:
    r"""The error budget of a restoration of ``observed`` against ``truth``.

    Parameters
    ----------
    truth : (H, W) or (H, W, C) ndarray
        Ground truth on the bank's reference grid (the pinhole render), in the units of
        the data range 1 (divided by the white level).
    observed : ndarray, like ``truth``
        The image that was restored (a noisy render, or the noise-free one).
    bank : IPSFBank
    clean_observed : ndarray, optional
        The same render before sensor noise; None: ``observed`` has none (the
        ``sensor`` term is then 0).
    second_seed : ndarray, optional
        The clean render again with another Monte Carlo seed: adds ``monte_carlo``.
    restored : ndarray, optional
        The restoration that was made (e.g. a dataset's EDOF image); default: restored
        here from ``observed`` with ``method`` and ``weight``.
    depth : (H, W) ndarray, optional
        Depth AOV, mm: depth bands, occlusion edges, and the ``depth`` term when the
        bank holds several depths.
    mask : (H, W) bool ndarray, optional
        Pixels scored (the mirror's image); default all.
    method : {"wiener", "tv", "hyperlaplacian"}
        Restoration method (:func:`~mitsweep.deconv.restore.deconvolve`); RL's
        regularisation is its stopping rule, not a scalar weight, and is refused.
    weight : float, optional
        The chosen weight of ``restored`` (recorded), or of the restoration made here
        (None: the method's calibrated choice from ``noise`` and the image).
    noise : SensorNoise or float, optional
        The observed image's noise, for the methods' calibrated choices.
    deconvolution_depth : float, optional
        Bank depth deconvolved with, mm (default 500 mm, :func:`select_depth`); the
        former keyword ``depth_mm`` is still accepted, with a :class:`DeprecationWarning`.
    radius_edges_px : sequence of float, optional
        Radial bin edges, pixels from the optical axis; default ``n_radial_bins`` equal
        bins from 0 to the mask's farthest pixel + 0.5 (as the evaluation's).
    depth_bands : sequence of float
        Depth band edges, mm (default :data:`DEPTH_BANDS_MM`); the former keyword
        ``depth_bands_mm`` is still accepted, with a :class:`DeprecationWarning`.
    edge_width_px : int
        Half-width of the occlusion-edge region, pixels.
    weight_bounds : (float, float), optional
        Search range of the oracle weights (default :data:`WEIGHT_BOUNDS`).
    **restore_kw
        Passed to :func:`~mitsweep.deconv.restore.deconvolve` (``prior``, ``center``).

    Returns
    -------
    ErrorBudget
        Its ``mse[-1]`` is the measured error of the restoration; the terms
        (``term_mse``) add up to it per region, exactly up to round-off.
    """
    from .restore import blur_operator, deconvolve

    if method not in WEIGHT_BOUNDS:
        raise ValueError(f"error_budget: method {method!r} has no scalar weight to search "
                         f"(allowed: {', '.join(WEIGHT_BOUNDS)})")
    t = np.asarray(truth)
    shape = t.shape
    for name, a in (("observed", observed), ("clean_observed", clean_observed),
                    ("second_seed", second_seed), ("restored", restored)):
        if a is not None and np.shape(a) != shape:
            raise ValueError(f"error_budget: {name} has shape {np.shape(a)}, the truth "
                             f"{shape}")
        if a is not None and not np.all(np.isfinite(a)):
            raise ValueError(f"error_budget: {name} holds NaN or inf pixels")
    if t.ndim not in (2, 3):
        raise ValueError(f"error_budget: images must be (H, W) or (H, W, C), got {shape}")
    m = np.ones(shape[:2], dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if m.shape != shape[:2] or not m.any():
        raise ValueError("error_budget: the mask must be (H, W) and select some pixels")
    if depth is not None and np.shape(depth) != shape[:2]:
        raise ValueError(f"error_budget: depth must be {shape[:2]}, got {np.shape(depth)}")
    dt = np.float32 if np.asarray(observed).dtype == np.float32 else np.float64
    bounds = WEIGHT_BOUNDS[method] if weight_bounds is None else weight_bounds
    kw = dict(restore_kw, depth=deconvolution_depth)
    if method != "wiener":
        kw["noise"] = noise

    def restore(x: np.ndarray, w: float) -> np.ndarray:
        return deconvolve(x, bank, method=method, weight=w, **kw)

    cache: dict[str, tuple[float, np.ndarray]] = {}

    def best(x: np.ndarray) -> tuple[float, np.ndarray]:
        x = np.asarray(x, dtype=dt)
        key = _digest(x)
        if key not in cache:
            w, r, _ = oracle_weight(x, t, restore, mask=m, bounds=bounds)
            cache[key] = (w, r)
        return cache[key]

    # the chain of inputs
    op = blur_operator(bank, shape, depth=deconvolution_depth, dtype=dt)
    model = _per_channel(op.forward, t.astype(dt))
    clean = np.asarray(observed if clean_observed is None else clean_observed)
    steps: list[tuple[str, np.ndarray]] = [("information", model)]
    if depth is not None and len(np.asarray(bank.depths)) > 1:
        steps.append(("depth", layered_blur(t, bank, depth,
                                            deconvolution_depth=deconvolution_depth, dtype=dt)))
    if second_seed is not None:
        mean = 0.5 * (np.asarray(clean, dtype=np.float64) + np.asarray(second_seed, np.float64))
        steps += [("mismatch", mean), ("monte_carlo", clean)]
    else:
        steps.append(("mismatch", clean))
    steps.append(("sensor", np.asarray(observed)))

    weights: dict[str, float | None] = {}
    maps = []
    for name, x in steps:
        w, r = best(x)
        weights[name] = float(w)
        maps.append(_mse_map(r, t))
        logger.info("budget step %s: oracle weight %.3g, MSE %.4g", name, w,
                    float(maps[-1][m].mean()))
    if restored is None:
        wiener_kw: dict[str, Any] = {"noise": noise} if method == "wiener" else {}
        restored = deconvolve(np.asarray(observed, dtype=dt), bank, method=method,
                              weight=weight, **wiener_kw, **kw)
    weights["weight"] = None if weight is None else float(weight)
    maps.append(_mse_map(restored, t))
    names = tuple(n for n, _ in steps) + ("weight",)

    # the regions
    cy, cx = restore_kw.get("center") or optical_center_px(shape)
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    rr = np.hypot(yy - cy, xx - cx)
    if radius_edges_px is None:
        r_max = float(rr[m].max()) + 0.5
        redges = np.linspace(0.0, r_max, int(n_radial_bins) + 1)
    else:
        redges = np.asarray(radius_edges_px, dtype=np.float64)
    if redges.ndim != 1 or len(redges) < 2 or np.any(np.diff(redges) <= 0):
        raise ValueError("error_budget: radius_edges_px must be at least two increasing radii")
    dedges = np.asarray(depth_bands, dtype=np.float64)
    if dedges.ndim != 1 or len(dedges) < 2 or np.any(~(np.diff(dedges) > 0)):
        raise ValueError("error_budget: depth_bands must be at least two increasing depths")
    regions: list[tuple[str, np.ndarray]] = [("all", m)]
    for i in range(len(redges) - 1):
        regions.append((f"r{i}", m & (rr >= redges[i]) & (rr < redges[i + 1])))
    info: dict[str, Any] = {"bank_depths_mm": np.asarray(bank.depths, float).tolist(),
                            "deconvolution_depth_mm": deconvolution_depth,
                            "sensor_noise": clean_observed is not None,
                            "second_seed": second_seed is not None}
    if depth is not None:
        d = np.asarray(depth, dtype=np.float64)
        for i in range(len(dedges) - 1):
            regions.append((f"d{i}", m & np.isfinite(d) & (d >= dedges[i])
                            & (d < dedges[i + 1])))
    if bank.kind == "radial":
        from .kernels import radii_px

        traced = float(np.max(radii_px(bank)))
        info["traced_radius_px"] = traced
        # a bank traced to the mirror's rim records the design FOV's edge: the region
        # stays the same pixels whichever bank restores them
        fov_mm = (bank.metadata or {}).get("fov_radius_mm")
        fov = traced if fov_mm is None else float(fov_mm) / float(bank.pixel_pitch)
        info["fov_radius_px"] = fov
        regions.append(("beyond_fov", m & (rr > fov)))
    if depth is not None:
        regions.append(("occlusion_edges", m & _occlusion_edges(depth, edge_width_px)))
        info.update(edge_width_px=int(edge_width_px), edge_depth_ratio=EDGE_DEPTH_RATIO)
    pixels = np.array([int(s.sum()) for _, s in regions])
    mse = np.array([[float(e[s].mean()) if s.any() else math.nan for _, s in regions]
                    for e in maps])
    return ErrorBudget(terms=names, weights=weights, regions=tuple(r for r, _ in regions),
                       pixels=pixels, mse=mse, radius_edges_px=redges, depth_edges=dedges,
                       method=method, info=info)
