"""Figures: every plot mitsweep draws, at the edge of the package.

Each function takes data (arrays, result dicts, a setup and its sweep range) and a
path, and writes one figure there atomically; the format follows the path's suffix
(PNG when it has none). Compute packages (optics, tracer, deconv, render, rig, io) never
import this module or matplotlib: their results are handed here by the CLI, which
imports this module lazily, only when a plot is asked for.

Figures are drawn on :class:`matplotlib.figure.Figure` objects without ``pyplot``: no
global backend is selected and no figure is left registered, so a program or notebook
importing this module keeps its own matplotlib state.

- :func:`plot_focal_surfaces` — meridional and sagittal focal surfaces (paper Fig. 6).
- :func:`plot_ipsf` — one IPSF: thumbnail and radial/tangential cross-sections (Fig. 3).
- :func:`plot_bank` — an IPSF bank across the field and over depths (Fig. 4–5).
- :func:`plot_table1` — the paper's Table 1 as bar charts.
- :func:`plot_per_radius` — PSNR per radius of an evaluated dataset.
- :func:`plot_error_budget` — an EDOF image's error budget per radius and depth band.

The paper's figures as ``mitsweep figures`` draws them (:mod:`mitsweep.pipeline.figures`
computes their data); each takes one path or a sequence of paths (one per format):

- :func:`plot_psf_planes` — PSFs across the mirror at several focal planes (Fig. 3).
- :func:`plot_ipsf_depths` — IPSFs across the mirror, cross-sections over depths (Fig. 4).
- :func:`plot_sweep_ranges` — cross-sections for several sweep ranges (Fig. 5).
- :func:`plot_pipeline` — the processing pipeline step by step (Fig. 8).
- :func:`plot_insets` — images side by side with magnified, labelled regions (Figs. 9, 10).
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Literal
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure, SubFigure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from numpy.typing import ArrayLike

from .config import Setup
from .deprecation import renamed_keywords
from .io.atomic import atomic_path
from .io.bank import IPSFBank
from .optics.sweep import SweepRange

if TYPE_CHECKING:
    from matplotlib.image import AxesImage
    from matplotlib.typing import HashableList, LineStyleType

__all__ = ["check_figure_path", "new_figure", "save_figure", "plot_focal_surfaces",
           "plot_ipsf", "plot_bank", "plot_table1", "plot_per_radius", "plot_psf_planes",
           "plot_ipsf_depths", "plot_sweep_ranges", "plot_pipeline", "plot_insets"]

logger = logging.getLogger(__name__)

#: Resolution of written raster figures, dots per inch.
DPI = 120
#: Colour map of kernel thumbnails (normalised to their maximum).
KERNEL_CMAP = "inferno"
#: Grid lines: a light grey rather than a transparent black, and legends opaque, so that
#: PostScript output (which has no transparency) looks the same and raises no warning.
GRID_COLOR = "0.88"
#: Formats whose files carry matplotlib's ``metadata`` (the maker and version).
_TAGGED = frozenset({"png", "pdf", "svg", "svgz", "ps", "eps"})

#: One output path, or one per format (:func:`plot_psf_planes` and the other paper figures).
PathOrPaths = str | Path | Sequence[str | Path]


def _format_of(path: Path) -> str:
    return path.suffix.lstrip(".").lower() or "png"


def check_figure_path(path: str | Path, flag: str | None = None) -> Path:
    """Refuse, before any long computation, a figure path whose format cannot be written.

    ``flag`` (e.g. ``"--plot"``) is named in the message.

    Parameters
    ----------
    path : str or Path
        The figure file.
    flag : str, optional
        The command-line option that gave it.

    Raises
    ------
    ValueError
        The suffix names no format matplotlib writes here (PGF needs a TeX system); the
        message lists those it does.
    """
    import shutil

    import matplotlib

    p = Path(path)
    formats = set(Figure().canvas.get_supported_filetypes())
    if shutil.which(matplotlib.rcParams["pgf.texsystem"]) is None:
        formats.discard("pgf")   # PGF output measures its text with LaTeX
    if _format_of(p) not in formats:
        raise ValueError(f"{flag + ' ' if flag else ''}{p}: a figure must end in one of "
                         f"{', '.join('.' + f for f in sorted(formats))} (or have no suffix, "
                         f"for PNG)")
    return p


def new_figure(*args: int, figsize: tuple[float, float] = (7.0, 4.5),
               layout: Literal["constrained", "compressed", "tight"] | None = "constrained",
               **kwargs: Any) -> tuple[Figure, Any]:
    """A new figure and its axes: ``Figure(figsize, layout).subplots(*args, **kwargs)``.

    Parameters
    ----------
    *args : int
        ``nrows, ncols`` for :meth:`matplotlib.figure.Figure.subplots`.
    figsize : tuple of float, optional
        Inches.
    layout : str, optional
        matplotlib's layout engine.
    **kwargs
        Passed to ``subplots``.
    """
    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(*args, **kwargs)


def save_figure(fig: Figure, path: str | Path, dpi: int = DPI) -> Path:
    """Write ``fig`` to ``path`` atomically (format from the suffix, PNG without one).

    PNG, PDF, SVG and PostScript files name their maker (``Creator: mitsweep <version>``)
    in their metadata; matplotlib has no metadata for the other formats.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or Path
        Where to write it.
    dpi : int, optional
        Resolution of raster formats.
    """
    from . import __version__

    p = Path(path)
    fmt = _format_of(p)
    extra: dict[str, Any] = ({"metadata": {"Creator": f"mitsweep {__version__}"}}
                             if fmt in _TAGGED else {})
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=fmt, **extra)
    logger.info("wrote %s", p)
    return p


def _subfigures(fig: Figure, nrows: int, ncols: int, **kwargs: Any) -> list[SubFigure]:
    """``fig.subfigures(nrows, ncols, **kwargs)`` as a flat list in row-major order, one
    subfigure included (matplotlib returns that one bare)."""
    found = fig.subfigures(nrows, ncols, squeeze=False, **kwargs)
    return [found] if isinstance(found, SubFigure) else list(found.flat)


def _legend_outside(ax) -> None:
    """The legend right of the axes, top-aligned: never over the data."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              framealpha=1.0)


def plot_focal_surfaces(setup: Setup, sweep: SweepRange, path: str | Path,
                        depths: Sequence[float] = (0.0, 20.0, math.inf)) -> Path:
    """Meridional and sagittal focal surfaces in the meridional plane (paper Fig. 6).

    Parameters
    ----------
    setup : mitsweep.config.Setup
    sweep : mitsweep.optics.SweepRange
        Its optimal sweep range (:func:`mitsweep.optics.optimal_sweep_range`).
    path : path
    depths : sequence of float
        Depths l, mm (0 is the mirror itself), drawn with the two ends of the sweep's
        depth range.
    """
    from .optics import chief_ray, placement_of
    from .optics.coddington import focal_distances

    placement = placement_of(setup.mirror)
    ds = sorted(set(depths) | {sweep.depth_min, sweep.depth_max})
    lo = -setup.mirror.rim_radius if not setup.mirror.is_symmetric else -sweep.rho_max
    xs = np.linspace(min(lo, sweep.rho_start), max(sweep.rho_end, sweep.rho_max), 801)
    ray = chief_ray(placement, placement.surface(xs, np.zeros_like(xs)))
    ok = ray.visible
    fig, ax = new_figure(figsize=(8.5, 6))
    p = ray.surface.position
    ax.plot(p[ok, 0], p[ok, 2], "k-", lw=2, label="mirror")
    colors = iter(["tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:red", "tab:gray",
                   "tab:pink", "tab:olive", "tab:cyan"])
    for d in ds:
        c = next(colors, "k")
        if d == 0:
            ax.plot(p[ok, 0], p[ok, 2], "-", color=c, lw=1, label="depth 0 (on the mirror)")
            continue
        dm, dsg = focal_distances(setup, xs[ok], d)
        for dist, style, nm in ((dm, "-", "meridional"), (dsg, "--", "sagittal")):
            q = p[ok] - dist[:, None] * ray.to_lens[ok]
            ax.plot(q[:, 0], q[:, 2], style, color=c, lw=1, label=f"{nm}, {_depth_label(d)}")
    vd = setup.mirror.vertex_distance
    for f, lab in ((sweep.focus_min, "focus min"), (sweep.focus_max, "focus max")):
        ax.axhline(vd - f, color="0.5", lw=0.6, ls=":")
        # Right of the axes, level with its line: inside, every place along the line
        # is near a curve (the sweep's ends touch the focal surfaces by definition).
        ax.annotate(f" {lab}\n {f:.1f} mm", (1.0, vd - f), xycoords=("axes fraction", "data"),
                    fontsize=7, va="center", ha="left", annotation_clip=False)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm), camera above")
    ax.set_aspect("equal")
    ax.set_title(f"{setup.name}: focal surfaces (FOV {sweep.fov_deg:g}°)")
    # Below the axes: inside, every corner holds a curve; the right holds the focus labels.
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncols=3,
              borderaxespad=0.0, framealpha=1.0)
    return _save_all(fig, path)


def _thumbnail(ax, kernel, pitch_um: float, title: str) -> AxesImage:
    """Draw a kernel normalised to its maximum on ``ax``, in µm about its centre pixel;
    return the image (for a colour bar, 0 to 1)."""
    k = np.asarray(kernel, dtype=np.float64)
    half = k.shape[0] / 2 * pitch_um
    im = ax.imshow(k / max(k.max(), 1e-30), cmap=KERNEL_CMAP, vmin=0.0, vmax=1.0,
                   extent=(-half, half, -half, half), interpolation="nearest")
    ax.set_title(title, fontsize=8)
    ax.set_xlabel("u (µm)", fontsize=7)
    ax.tick_params(labelsize=6)
    return im


def _sections_axes(ax, sections, pitch_um: float, labels=("radial", "tangential"),
                   colors=("tab:blue", "tab:red"), suffix: str = "", lw: float = 1.5) -> None:
    x, rad, tan = (np.asarray(a, dtype=np.float64) for a in sections)
    for values, name, color in zip((rad, tan), labels, colors):
        ax.plot(x * pitch_um, values, "-", color=color, lw=lw, label=name + suffix)


@renamed_keywords(pitch_mm="pixel_pitch")
def plot_ipsf(kernel: ArrayLike, path: str | Path, *, pixel_pitch: float,
              sections: tuple[np.ndarray, np.ndarray, np.ndarray],
              title: str = "IPSF") -> Path:
    """One IPSF: thumbnail (normalised to its maximum, with a colour bar) and its radial
    and tangential cross-sections (paper Fig. 3).

    Parameters
    ----------
    kernel : (K, K) array_like
        Unit-sum kernel, rows down the image, the chief-ray image at the centre.
    path : path
    pixel_pitch : float
        Pixel pitch, mm (formerly ``pitch_mm``, still accepted with a warning).
    sections : tuple of three (n,) arrays
        ``(x, radial, tangential)`` as :func:`mitsweep.tracer.metrics.cross_sections`
        returns them (``x`` in pixels).
    title : str
    """
    fig, (a0, a1) = new_figure(1, 2, figsize=(10, 4))
    pitch_um = pixel_pitch * 1e3
    im = _thumbnail(a0, kernel, pitch_um, title)
    a0.set_ylabel("v (µm)", fontsize=7)
    fig.colorbar(im, ax=a0, label="intensity / maximum", shrink=0.9)
    _sections_axes(a1, sections, pitch_um)
    a1.set_xlabel("position (µm)")
    a1.set_ylabel("IPSF (unit sum)")
    a1.grid(color=GRID_COLOR)
    a1.legend(framealpha=1.0)
    return save_figure(fig, path)


def plot_bank(bank: IPSFBank, path: str | Path, *,
              sections: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]],
              max_thumbs: int = 10) -> Path:
    """An IPSF bank: thumbnails across the field at its first depth, and cross-sections
    over its depths at chosen points (paper Fig. 4–5).

    Parameters
    ----------
    bank : mitsweep.io.bank.IPSFBank
        Reads ``kernels`` (n_depths, n_points, K, K), ``points_uv`` (n_points, 2) mm,
        ``depths`` (n_depths,) and ``pixel_pitch`` mm.
    path : path
    sections : mapping of str to a sequence of ``(x, radial, tangential)``
        Per panel (e.g. ``"centre"``, ``"periphery"``), the cross-sections of one point
        at each of the bank's depths, in the bank's depth order (radial in blue shades,
        tangential in red shades, brightest at the first depth, darker at each next).
    max_thumbs : int
        At most this many thumbnails, evenly spaced over the points.
    """
    kernels = np.asarray(bank.kernels)
    n_depths, n = kernels.shape[:2]
    for name, per_depth in sections.items():
        if len(per_depth) != n_depths:
            raise ValueError(f"sections[{name!r}]: need one per depth ({n_depths}), "
                             f"got {len(per_depth)}")
    idx = np.unique(np.linspace(0, n - 1, min(n, max_thumbs)).round().astype(int))
    cols = max(len(idx), 2)
    pitch_um = bank.pixel_pitch * 1e3
    # h_pad in inches: room between the rows' titles
    fig = Figure(figsize=(max(1.6 * cols + 1.2, 8.0), 6.4),
                 layout=ConstrainedLayoutEngine(h_pad=0.1))
    top, bottom = _subfigures(fig, 2, 1, height_ratios=(1.0, 1.35))
    thumbs = top.subplots(1, cols, sharex=True, sharey=True, squeeze=False)[0]
    images = [_thumbnail(thumbs[j], kernels[0, i], pitch_um,
                         "({:.2f}, {:.2f}) mm".format(*bank.points_uv[i]))
              for j, i in enumerate(idx)]
    for ax in thumbs[len(idx):]:
        ax.set_visible(False)
    thumbs[0].set_ylabel("v (µm)", fontsize=7)
    top.colorbar(images[-1], ax=list(thumbs), label="intensity / maximum", shrink=0.9)
    top.suptitle(f"IPSFs across the field, depth {_depth_text(bank.depths[0])}",
                 fontsize=9)
    panels = bottom.subplots(1, max(len(sections), 1), squeeze=False)[0]
    for ax, (name, per_depth) in zip(panels, sections.items()):
        for d, (depth, sec) in enumerate(zip(bank.depths, per_depth)):
            shade = 1.0 - 0.6 * d / max(n_depths - 1, 1)
            _sections_axes(ax, sec, pitch_um, colors=((0, 0, shade), (shade, 0, 0)),
                           suffix=f" {_depth_text(depth)}", lw=1.0)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("position (µm)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(color=GRID_COLOR)
        ax.legend(fontsize=6, framealpha=1.0)
    panels[0].set_ylabel("IPSF (unit sum)", fontsize=8)
    return save_figure(fig, path)


def _depth_text(depth: float) -> str:
    return "inf" if math.isinf(depth) else f"{depth / 1000:g} m"


#: Up to this many sweep ranges, Table 1's bar labels stand upright on two lines.
TABLE1_UPRIGHT_RANGES = 5


def plot_table1(result: dict, path: str | Path, *,
                optimal: tuple[float, float] | None = None) -> Path:
    """The paper's Table 1 as bar charts: V_avg per sweep range and the conventional
    camera (log scale), and the four mean kurtoses per sweep range, the ranges from the
    shortest sweep to the longest.

    Parameters
    ----------
    result : dict
        As :func:`mitsweep.tracer.table1.table1` returns it: ``rows`` (each with
        ``focus_min_mm``, ``focus_max_mm``, ``v_avg`` and ``kurtosis[where][direction]``
        for ``where`` in centre/periphery and ``direction`` in tangential/radial) and
        ``conventional["v_avg"]``.
    path : path
    optimal : (focus_min, focus_max), optional
        The optimal range (Eq. 8–9), marked "optimal" under its bars.
    """
    rows = sorted(result["rows"], key=lambda r: r["focus_max_mm"] - r["focus_min_mm"])
    # Side by side, one-line "339–364 mm" labels run into each other: two lines each for a
    # few ranges, vertical single lines for more (two lines no longer fit then either).
    vertical = len(rows) > TABLE1_UPRIGHT_RANGES
    br = "" if vertical else "\n"
    labels = [f"{r['focus_min_mm']:.0f}–{br}{r['focus_max_mm']:.0f} mm"
              + (f"{' ' if vertical else br}(optimal)" if optimal is not None and np.allclose(
                  (r["focus_min_mm"], r["focus_max_mm"]), optimal) else "") for r in rows]
    conventional = "conventional camera" if vertical else "conventional\ncamera"
    tick_style = dict(fontsize=8, rotation=90 if vertical else 0)
    fig, (a0, a1) = new_figure(1, 2, figsize=(11, 4.5))
    a0.bar(np.arange(len(rows) + 1), [r["v_avg"] for r in rows]
           + [result["conventional"]["v_avg"]],
           color=["tab:blue"] * len(rows) + ["tab:gray"])
    a0.set_xticks(np.arange(len(rows) + 1), labels + [conventional],
                  **tick_style)
    a0.set_yscale("log")
    a0.set_ylabel("V_avg (Eq. 3)")
    a0.set_xlabel("sweep range (focus distances)")
    keys = [("center", "tangential"), ("center", "radial"), ("periphery", "tangential"),
            ("periphery", "radial")]
    width = 0.8 / len(keys)
    for k, (where, dirn) in enumerate(keys):
        a1.bar(np.arange(len(rows)) + k * width, [r["kurtosis"][where][dirn] for r in rows],
               width, label=f"{'centre' if where == 'center' else where} {dirn}")
    a1.axhline(3.0, color="0.4", lw=0.8, ls=":")
    a1.set_xticks(np.arange(len(rows)) + (len(keys) - 1) * width / 2, labels,
                  **tick_style)
    a1.set_ylabel("kurtosis (Gaussian = 3, dotted)")
    a1.set_xlabel("sweep range (focus distances)")
    _legend_outside(a1)
    return _save_all(fig, path)


#: Colour of each image kind in :func:`plot_per_radius` (noisy versions share it).
IMAGE_COLORS = {"edof": "tab:red", "focused": "tab:blue", "stopped": "tab:green",
                "sweep": "0.45", "pinhole": "k"}
OTHER_IMAGE_COLOR = "tab:purple"
#: Entries per column of the per-radius key (more light levels: more columns).
LEGEND_ROWS = 20
#: Line style and marker of the noise-free images in :func:`plot_per_radius`.
CLEAN_STYLE: tuple[LineStyleType, str] = ("-", "o")
#: Line styles and markers of the light levels, brightest first: level k gets style
#: k mod 3 and marker k mod 11, so 33 levels (3 × 11, coprime) get distinct pairs, more
#: than a dataset holds (mitsweep.pipeline.MAX_LIGHT_LEVELS).
LIGHT_DASHES: tuple[LineStyleType, ...] = ("--", "-.", ":")
LIGHT_MARKERS = ("s", "^", "v", "D", "P", "X", "*", "p", "h", "<", ">")
_LUX_NAME = re.compile(r"(?P<base>.+)_(?P<lux>[0-9.e+-]+)lux")


def _image_kind(name: str) -> tuple[str, float | None]:
    """``"edof_50lux"`` → ``("edof", 50.0)``; ``"edof"`` → ``("edof", None)``."""
    m = _LUX_NAME.fullmatch(name)
    if m is None:
        return name, None
    try:
        return m["base"], float(m["lux"])
    except ValueError:
        return name, None


def plot_per_radius(results: dict, path: str | Path) -> Path:
    """PSNR per radius inside the mirror's image, for the first scene of an evaluation.

    One colour per image kind (``IMAGE_COLORS``), one line style and marker per light
    level: the noise-free image solid with circles (``CLEAN_STYLE``), then the light
    levels brightest to dimmest (``LIGHT_DASHES``, ``LIGHT_MARKERS``).

    Parameters
    ----------
    results : dict
        As :func:`mitsweep.pipeline.evaluate_dataset` returns it: ``scenes`` maps a scene
        to its images, each with ``per_radius = {"radius_px": [...], "psnr": [...]}``
        (entries that are not dicts are the scene's own values and are skipped).
    path : path
    """
    first = next(iter(results["scenes"].values()))
    entries = {name: e for name, e in first.items() if isinstance(e, dict)}
    levels = sorted({lux for lux in (_image_kind(n)[1] for n in entries) if lux is not None},
                    reverse=True)
    style_of: dict[float | None, tuple[LineStyleType, str]] = {None: CLEAN_STYLE}
    style_of.update({lux: (LIGHT_DASHES[k % len(LIGHT_DASHES)],
                           LIGHT_MARKERS[k % len(LIGHT_MARKERS)])
                     for k, lux in enumerate(levels)})
    from matplotlib.lines import Line2D

    fig, ax = new_figure(figsize=(8.5, 4.8))
    kinds: dict[str, str] = {}
    lights: dict[float | None, str] = {}
    for base, lux, entry in sorted(((*_image_kind(n), e) for n, e in entries.items()),
                                   key=lambda t: (t[0], -math.inf if t[1] is None else -t[1])):
        ls, marker = style_of[lux]
        color = kinds.setdefault(base, IMAGE_COLORS.get(base, OTHER_IMAGE_COLOR))
        r = entry["per_radius"]
        ax.plot(r["radius_px"], r["psnr"], linestyle=ls, marker=marker, ms=4, lw=1.2,
                color=color, label=base if lux is None else f"{base}, {lux:g} lux")
        lights[lux] = "noise-free" if lux is None else f"{lux:g} lux"
    ax.set_xlabel("distance from the optical axis (pixels)")
    ax.set_ylabel("PSNR (dB) against the pinhole ground truth")
    ax.set_title("per-radius PSNR inside the mirror's image")
    ax.grid(color=GRID_COLOR)
    # One key, not one entry per curve (kinds × light levels): a colour per image kind,
    # then a black line per light level.
    key = [Line2D([], [], color=c, lw=2, label=b) for b, c in kinds.items()]
    key += [Line2D([], [], color="k", lw=1.2, linestyle=style_of[lux][0],
                   marker=style_of[lux][1], ms=4, label=text)
            for lux, text in sorted(lights.items(),
                                    key=lambda kv: -math.inf if kv[0] is None else -kv[0])]
    ax.legend(handles=key, title="colour: image; line: light", title_fontsize=7, fontsize=7,
              ncols=math.ceil(len(key) / LEGEND_ROWS), loc="upper left",
              bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, framealpha=1.0)
    return save_figure(fig, path)


#: Colour of each error-budget term (:mod:`mitsweep.deconv.budget`), in its order.
BUDGET_COLORS = {"information": "tab:gray", "depth": "tab:brown", "mismatch": "tab:orange",
                 "monte_carlo": "tab:purple", "sensor": "tab:blue", "weight": "tab:red"}


def plot_error_budget(budget: dict, path: str | Path, *, title: str | None = None) -> Path:
    """An error budget as stacked bars: each term's MSE per radial bin (left) and per
    depth band and region (right), positive terms stacked up from 0 and negative ones
    down, the measured MSE of the restoration as a black tick and its PSNR above.

    Parameters
    ----------
    budget : dict
        :meth:`mitsweep.deconv.budget.ErrorBudget.as_dict` (``order``, ``per_radius``,
        ``per_depth_band``, ``regions``, ``total``).
    path : path
    title : str, optional
    """
    order = budget["order"]
    r = budget["per_radius"]
    edges = r["edges_px"]
    groups = [([f"{edges[i]:.0f}-{edges[i + 1]:.0f}" for i in range(len(edges) - 1)],
               r, "radius from the optical axis (px)")]
    right_labels, right = ["all"], [budget["total"]]
    d = budget.get("per_depth_band")
    if d:
        e = d["edges_mm"]
        n = len(e) - 1
        right_labels += [f"{e[i] / 1000:g}-{'inf' if e[i + 1] == 'inf' else f'{e[i + 1] / 1000:g}'} m"
                         for i in range(n)]
        right += [{"terms": {t: d["terms"][t][i] for t in order},
                   "mse_after": {t: d["mse_after"][t][i] for t in order}} for i in range(n)]
    for name, reg in budget.get("regions", {}).items():
        right_labels.append(name.replace("_", " "))
        right.append(reg)

    def columns(entries):
        return ([[e["terms"][t] for e in entries] for t in order],
                [e["mse_after"][order[-1]] for e in entries])

    fig, axes = new_figure(1, 2, figsize=(11.0, 4.6), width_ratios=[1.2, 1.0])
    left_terms = [[r["terms"][t][i] for i in range(len(edges) - 1)] for t in order]
    left_total = list(r["mse_after"][order[-1]])
    panels = [(axes[0], groups[0][0], left_terms, left_total, groups[0][2]),
              (axes[1], right_labels, *columns(right), "depth band and region")]
    for ax, labels, terms, totals, xlabel in panels:
        x = np.arange(len(labels))
        up, down = np.zeros(len(x)), np.zeros(len(x))
        for t, vals in zip(order, terms):
            v = 1e4 * np.array([np.nan if a is None else float(a) for a in vals])
            v = np.nan_to_num(v)
            pos, neg = np.clip(v, 0, None), np.clip(v, None, 0)
            ax.bar(x, pos, bottom=up, color=BUDGET_COLORS.get(t, "k"), width=0.7,
                   label=t.replace("_", " "))
            ax.bar(x, neg, bottom=down, color=BUDGET_COLORS.get(t, "k"), width=0.7)
            up += pos
            down += neg
        tot = 1e4 * np.array([np.nan if a is None else float(a) for a in totals])
        ax.plot(x, tot, linestyle="none", marker="_", ms=18, mew=2, color="k",
                label="measured")
        for xi, v in zip(x, tot):
            if np.isfinite(v) and v > 0:
                ax.annotate(f"{-10 * math.log10(v * 1e-4):.1f} dB", (xi, max(v, up[xi])),
                            xytext=(0, 3), textcoords="offset points", ha="center",
                            fontsize=6)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=7)
        ax.set_xlabel(xlabel)
        ax.grid(axis="y", color=GRID_COLOR)
        ax.set_axisbelow(True)
    axes[0].set_ylabel("MSE x 1e4 (data range 1)")
    _legend_outside(axes[1])
    fig.suptitle(title or "error budget", fontsize=10)
    return save_figure(fig, path)


# -- the paper's figures (mitsweep figures: mitsweep.pipeline.figures) ------------------

#: Line style and marker of each depth's cross-section in Figs. 4 and 5, nearest first.
DEPTH_STYLES: tuple[tuple[LineStyleType, str], ...] = (
    ("-", "o"), ("--", "s"), (":", "^"), ("-.", "D"), ((0, (5, 1, 1, 1)), "v"))
#: Colours of the radial and tangential cross-sections (the paper's blue and red).
DIRECTION_COLORS = {"radial": "tab:blue", "tangential": "tab:red"}
#: Colour of the rectangles marking the magnified regions of Figs. 9 and 10.
INSET_COLORS = ("#ffd400", "#00e5ff", "#ff3dd8", "#7CFC00")


def _paths(path) -> list[Path]:
    """One path or a sequence of them (one figure written in several formats)."""
    if isinstance(path, (str, Path)):
        return [Path(path)]
    return [Path(p) for p in path]


def _save_all(fig, path):
    """Write ``fig`` to each path; return the first (or the only) one."""
    paths = [save_figure(fig, p) for p in _paths(path)]
    return paths[0] if len(paths) == 1 else paths


def _depth_label(depth: float) -> str:
    if math.isinf(depth):
        return "depth ∞"
    return f"depth {depth / 10:g} cm" if depth < 1000 else f"depth {depth / 1000:g} m"


def _energy_half_extent(kernels, pitch_um: float, fraction: float = 0.995) -> float:
    """Half side (µm) of the centred square holding ``fraction`` of every kernel's
    energy, plus two pixels: the window the thumbnails and cross-sections show."""
    k = np.asarray(kernels, dtype=np.float64)
    k = k.reshape(-1, *k.shape[-2:])
    K = k.shape[-1]
    y, x = np.mgrid[:K, :K] - K // 2
    ring = np.maximum(np.abs(x), np.abs(y)).ravel()
    widest = 0
    for kk in k:
        total = kk.sum()
        if not total > 0:
            continue
        energy = np.cumsum(np.bincount(ring, kk.ravel(), minlength=K // 2 + 1)) / total
        widest = max(widest, int(np.searchsorted(energy, fraction)))
    return (min(widest + 2, K // 2) + 0.5) * pitch_um


def _set_window(axes, half_um: float) -> None:
    for ax in axes:
        ax.set_xlim(-half_um, half_um)
        ax.set_ylim(-half_um, half_um)


def _display(image, white: float) -> np.ndarray:
    """Linear radiance → 8-bit-ready sRGB in [0, 1], ``white`` mapped to 1."""
    from .io.png import linear_to_srgb

    return linear_to_srgb(np.clip(np.asarray(image, dtype=np.float64) / white, 0.0, 1.0))


def _kernel_grid(fig, kernels, pitch_um: float, col_titles, row_titles, *, suptitle: str,
                 half_extent_um: float | None = None):
    """Thumbnails (rows × cols), each normalised to its maximum, one shared colour bar."""
    n_rows, n_cols = kernels.shape[:2]
    axes = fig.subplots(n_rows, n_cols, sharex=True, sharey=True, squeeze=False)
    im = None
    for i in range(n_rows):
        for j in range(n_cols):
            ax = axes[i, j]
            im = _thumbnail(ax, kernels[i, j], pitch_um, col_titles[j] if i == 0 else "")
            if half_extent_um is not None:
                ax.set_xlim(-half_extent_um, half_extent_um)
                ax.set_ylim(-half_extent_um, half_extent_um)
            if i < n_rows - 1:
                ax.set_xlabel("")
            if j == 0:
                ax.set_ylabel(f"{row_titles[i]}\nv (µm)", fontsize=7)
    fig.colorbar(im, ax=axes.ravel().tolist(), label="PSF / its maximum", shrink=0.8,
                 aspect=30)
    fig.suptitle(suptitle, fontsize=10)
    return axes


@renamed_keywords(pitch_mm="pixel_pitch", focus_mm="focus_distances",
                  sensor_mm="sensor_distances")
def plot_psf_planes(kernels: ArrayLike, path: PathOrPaths, *, pixel_pitch: float,
                    focus_distances: Sequence[float], sensor_distances: Sequence[float],
                    positions: Sequence[str], title: str) -> Path:
    """PSFs across the mirror for several focal planes (paper Fig. 3).

    Parameters
    ----------
    kernels : (n_planes, n_points, K, K) array_like
        PSF of each image point (columns) with the sensor at each plane (rows).
    path : path or sequence of paths
        One file per format (e.g. ``fig3.png`` and ``fig3.pdf``).
    pixel_pitch : float
        Pixel pitch of the kernels, mm (formerly ``pitch_mm``, still accepted with a
        warning).
    focus_distances, sensor_distances : sequences of float
        Each plane's focus distance (object side) and sensor distance, mm (formerly
        ``focus_mm`` and ``sensor_mm``, as ``pixel_pitch``).
    positions : sequence of str
        Each point's position on the mirror (column titles).
    title : str
    """
    k = np.asarray(kernels, dtype=np.float64)
    n_rows, n_cols = k.shape[:2]
    fig = Figure(figsize=(1.5 * n_cols + 1.8, 1.4 * n_rows + 1.0), layout="constrained")
    rows = [f"focus {f:.0f} mm\n(sensor {s:.2f} mm)" for f, s in zip(focus_distances, sensor_distances)]
    _kernel_grid(fig, k, pixel_pitch * 1e3, list(positions), rows, suptitle=title,
                 half_extent_um=_energy_half_extent(k, pixel_pitch * 1e3))
    return _save_all(fig, path)


@renamed_keywords(pitch_mm="pixel_pitch", depths_mm="depths")
def plot_ipsf_depths(kernels: ArrayLike, path: PathOrPaths, *, pixel_pitch: float,
                     depths: Sequence[float], positions: Sequence[str],
                     sections: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]],
                     title: str) -> Path:
    """IPSFs across the mirror and their cross-sections over depths (paper Fig. 4).

    Parameters
    ----------
    kernels : (n_depths, n_points, K, K) array_like
        Unit-sum IPSFs; the thumbnails show the first depth.
    path : path or sequence of paths
    pixel_pitch : float
        Pixel pitch of the kernels, mm (formerly ``pitch_mm``, still accepted with a
        warning).
    depths : sequence of float
        The depths of ``kernels``' first axis, mm (formerly ``depths_mm``, as
        ``pixel_pitch``).
    positions : sequence of str
        Each point's position on the mirror (thumbnail titles).
    sections : mapping of str to a sequence of ``(x, radial, tangential)``
        Per panel title (e.g. ``"centre, ρ = 0 mm"``), one point's cross-sections at each
        depth (``x`` in pixels, as :func:`mitsweep.tracer.metrics.cross_sections`).
    title : str
    """
    k = np.asarray(kernels, dtype=np.float64)
    n_depths, n = k.shape[:2]
    for name, per_depth in sections.items():
        if len(per_depth) != n_depths:
            raise ValueError(f"sections[{name!r}]: need one per depth ({n_depths}), "
                             f"got {len(per_depth)}")
    pitch_um = pixel_pitch * 1e3
    fig = Figure(figsize=(max(1.7 * n + 1.4, 9.0), 7.0), layout="constrained")
    top, bottom = _subfigures(fig, 2, 1, height_ratios=(1.0, 1.5))
    thumbs = top.subplots(1, n, sharex=True, sharey=True, squeeze=False)[0]
    images = [_thumbnail(thumbs[j], k[0, j], pitch_um, positions[j]) for j in range(n)]
    half = _energy_half_extent(k, pitch_um)
    _set_window(thumbs, half)
    thumbs[0].set_ylabel("v (µm)", fontsize=7)
    top.colorbar(images[-1], ax=list(thumbs), label="IPSF / its maximum", shrink=0.9)
    top.suptitle(f"{title}: IPSFs across the mirror, {_depth_label(depths[0])}",
                 fontsize=10)
    _section_panels(bottom, sections, depths, pitch_um, half_um=half,
                    suptitle="cross-sections at each depth (unit-sum IPSFs)")
    return _save_all(fig, path)


#: Line widths of the two directions: the radial curve wider, drawn first, so that where
#: the two coincide (the centre of a symmetric mirror) it shows as a rim around the other.
DIRECTION_WIDTHS = {"radial": 2.4, "tangential": 1.1}


def _section_panels(fig, sections, depths, pitch_um: float, *, suptitle: str | None,
                    half_um: float | None = None, axes=None, legend: bool = True):
    """Radial (blue) and tangential (red) cross-sections, one line style and marker per
    depth; one key for the figure, below the panels."""
    from matplotlib.lines import Line2D

    if axes is None:
        axes = fig.subplots(1, max(len(sections), 1), squeeze=False)[0]
    for ax, (name, per_depth) in zip(axes, sections.items()):
        for d, sec in enumerate(per_depth):
            ls, marker = DEPTH_STYLES[d % len(DEPTH_STYLES)]
            x, rad, tan = (np.asarray(a, dtype=np.float64) for a in sec)
            every = max(len(x) // 8, 1)
            for values, direction in ((rad, "radial"), (tan, "tangential")):
                ax.plot(x * pitch_um, values, linestyle=ls, marker=marker, ms=3.5,
                        markevery=(d % every, every), lw=DIRECTION_WIDTHS[direction],
                        color=DIRECTION_COLORS[direction])
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("position along the direction (µm)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(color=GRID_COLOR)
        ax.set_ylim(bottom=0.0)
        if half_um is not None:
            ax.set_xlim(-half_um, half_um)
    axes[0].set_ylabel("IPSF (unit sum)", fontsize=8)
    if legend:
        key = [Line2D([], [], color=c, lw=DIRECTION_WIDTHS[d] + 0.8, label=f"{d} direction")
               for d, c in DIRECTION_COLORS.items()]
        key += [Line2D([], [], color="k", lw=1.1, linestyle=DEPTH_STYLES[d % len(DEPTH_STYLES)][0],
                       marker=DEPTH_STYLES[d % len(DEPTH_STYLES)][1], ms=3.5,
                       label=_depth_label(depth)) for d, depth in enumerate(depths)]
        fig.legend(handles=key, loc="outside lower center", ncols=len(key), fontsize=7,
                   framealpha=1.0)
    if suptitle:
        fig.suptitle(suptitle, fontsize=9)
    return axes


@renamed_keywords(pitch_mm="pixel_pitch", ranges_mm="ranges", depths_mm="depths")
def plot_sweep_ranges(sections: Sequence[Mapping[str, Sequence[tuple]]], path: PathOrPaths,
                      *, pixel_pitch: float, ranges: Sequence[tuple],
                      depths: Sequence[float], title: str,
                      optimal: tuple[float, float] | None = None) -> Path:
    """IPSF cross-sections at the mirror's centre and periphery for several sweep ranges
    and depths (paper Fig. 5).

    Parameters
    ----------
    sections : sequence (one per range) of mapping str → sequence of ``(x, rad, tan)``
        For each range, per place (e.g. ``"centre"``, ``"periphery"``: the rows), the
        cross-sections at each depth.
    path : path or sequence of paths
    pixel_pitch : float
        Pixel pitch of the cross-sections' ``x`` (pixels), mm (formerly ``pitch_mm``,
        still accepted with a warning).
    ranges : sequence of (focus_min, focus_max)
        Column titles, mm (formerly ``ranges_mm``, as ``pixel_pitch``).
    depths : sequence of float
        The depths of each place's cross-sections, mm (formerly ``depths_mm``, as
        ``pixel_pitch``).
    title : str
    optimal : (focus_min, focus_max), optional
        The optimal range (Eq. 8–9), marked "optimal" in its column's titles.
    """
    places = list(sections[0])
    n = len(ranges)
    x_half = max(float(np.max(np.abs(np.asarray(sec[0])[np.maximum(np.asarray(sec[1]),
                                                                  np.asarray(sec[2]))
                                                       > 1e-3 * max(np.max(sec[1]),
                                                                    np.max(sec[2]))])))
                 for col in sections for per_depth in col.values() for sec in per_depth)
    x_half = (x_half + 2.0) * pixel_pitch * 1e3
    fig = Figure(figsize=(2.7 * n + 1.2, 2.5 * len(places) + 1.2), layout="constrained")
    axes = fig.subplots(len(places), n, squeeze=False, sharey="row", sharex="row")
    for j, (lo, hi) in enumerate(ranges):
        col = {p: sections[j][p] for p in places}
        for i, p in enumerate(places):
            ax = axes[i, j]
            mark = " (optimal)" if optimal is not None and np.allclose((lo, hi), optimal) else ""
            _section_panels(fig, {f"{p}, sweep {lo:.0f}–{hi:.0f} mm{mark}": col[p]}, depths,
                            pixel_pitch * 1e3, suptitle=None, axes=[ax], half_um=x_half,
                            legend=(i == 0 and j == 0))
            if j > 0:
                ax.set_ylabel("")
    fig.suptitle(f"{title}: IPSF cross-sections for several sweep ranges (same exposure "
                 f"per range)", fontsize=10)
    return _save_all(fig, path)


@renamed_keywords(pitch_mm="pixel_pitch")
def plot_pipeline(steps: Sequence[dict], path: PathOrPaths, *,
                  bank_kernels: ArrayLike, bank_positions: Sequence[str],
                  pixel_pitch: float, white: float, title: str) -> Path:
    """The processing pipeline step by step (paper Fig. 8): the IPSF bank, then images.

    Parameters
    ----------
    steps : sequence of dict
        Each ``{"title", "image"}`` (linear RGB (H, W, 3), shown as sRGB with ``white``
        → 1) and optionally ``"extent"`` (left, right, bottom, top) with ``"xlabel"`` and
        ``"ylabel"`` (polar images: angle and radius, drawn to fill their panel), else
        pixel axes, with ``"window"`` (x, y, w, h) the part shown (the mirror's image).
        Drawn in order, left to right, at most three a row.
    path : path or sequence of paths
    bank_kernels : (n, K, K) array_like
        The IPSFs the deconvolution uses, shown in a row above the images.
    bank_positions : sequence of str
        Their positions (thumbnail titles).
    pixel_pitch : float
        Pixel pitch of the kernels, mm (formerly ``pitch_mm``, still accepted with a
        warning).
    white : float
        Linear value shown as white (the ground truth's white level).
    title : str
    """
    # In the steps' order (it is the reading order of their letters), at most three a
    # row, each row filling the width.
    rows = [list(steps[i:i + 3]) for i in range(0, len(steps), 3)]
    kernels = np.asarray(bank_kernels, dtype=np.float64)
    fig = Figure(figsize=(12.0, 1.9 + 3.9 * len(rows)), layout="constrained")
    top, bottom = _subfigures(fig, 2, 1, height_ratios=(1.6, 3.9 * len(rows)))
    thumbs = top.subplots(1, len(kernels), sharex=True, sharey=True, squeeze=False)[0]
    images = [_thumbnail(thumbs[j], k, pixel_pitch * 1e3, bank_positions[j])
              for j, k in enumerate(kernels)]
    _set_window(thumbs, _energy_half_extent(kernels, pixel_pitch * 1e3))
    thumbs[0].set_ylabel("v (µm)", fontsize=7)
    top.colorbar(images[-1], ax=list(thumbs), label="IPSF / its maximum", shrink=0.9)
    top.suptitle("(a) the IPSF bank the deconvolution uses (depth 50 cm)", fontsize=9)
    mosaic: list[HashableList[str]] = [
        [f"{r}:{j}" for j, _ in enumerate(row) for _ in range(6 // len(row))]
        for r, row in enumerate(rows)]
    axes = bottom.subplot_mosaic(mosaic)
    for r, row in enumerate(rows):
        for j, step in enumerate(row):
            ax = axes[f"{r}:{j}"]
            extent = step.get("extent")
            shown = _display(step["image"], white)
            if step.get("window") is not None:
                x0, y0, w, h = step["window"]
                shown = shown[y0:y0 + h, x0:x0 + w]
                extent = (x0 - 0.5, x0 + w - 0.5, y0 + h - 0.5, y0 - 0.5)
            ax.imshow(shown, extent=extent, origin="upper", interpolation="nearest",
                      aspect="auto" if step.get("extent") is not None else "equal")
            ax.set_title(step["title"], fontsize=9)
            ax.set_xlabel(step.get("xlabel", "x (pixels)"), fontsize=8)
            ax.set_ylabel(step.get("ylabel", "y (pixels)"), fontsize=8)
            ax.tick_params(labelsize=7)
    fig.suptitle(title, fontsize=11)
    return _save_all(fig, path)


def plot_insets(images: Sequence[tuple[str, np.ndarray]], path: PathOrPaths, *,
                regions: Sequence[tuple[int, int, int]], labels: Sequence[str], white: float,
                crop: tuple[int, int, int, int] | None = None, title: str) -> Path:
    """Images side by side, each with magnified regions below it (paper Figs. 9, 10).

    Parameters
    ----------
    images : sequence of (str, (H, W, 3) ndarray)
        Title and linear RGB image of each column.
    path : path or sequence of paths
    regions : sequence of (row, col, size)
        Top-left corner and side of each magnified square, pixels of the full image; the
        same regions in every image, each framed in its own colour.
    labels : sequence of str
        One per region (e.g. its distance from the mirror, "≈ 1.2 m").
    white : float
        Linear value shown as white.
    crop : (x, y, w, h), optional
        Show only this window of each image (the mirror's image).
    title : str
    """
    from matplotlib.patches import Rectangle
    from matplotlib.patheffects import withStroke

    n_img, n_reg = len(images), len(regions)
    fig = Figure(figsize=(5.0 * n_img, 5.0 + 5.0 / n_reg + 0.6), layout="constrained")
    cols = _subfigures(fig, 1, n_img, wspace=0.02)
    x0, y0, w, h = crop if crop is not None else (0, 0, images[0][1].shape[1],
                                                  images[0][1].shape[0])
    for sub, (name, image) in zip(cols, images):
        shown = _display(image, white)
        main_ax, *inset_axes = sub.subplot_mosaic([["main"] * n_reg, list(range(n_reg))],
                                                  height_ratios=(n_reg, 1.0)).values()
        main_ax.imshow(shown[y0:y0 + h, x0:x0 + w], extent=(x0 - 0.5, x0 + w - 0.5,
                                                            y0 + h - 0.5, y0 - 0.5),
                       interpolation="nearest")
        main_ax.set_title(name, fontsize=10)
        main_ax.set_xlabel("x (pixels)", fontsize=8)
        main_ax.set_ylabel("y (pixels)", fontsize=8)
        main_ax.tick_params(labelsize=7)
        for k, ((r, c, s), label, ax) in enumerate(zip(regions, labels, inset_axes)):
            color = INSET_COLORS[k % len(INSET_COLORS)]
            main_ax.add_patch(Rectangle((c - 0.5, r - 0.5), s, s, fill=False, lw=1.5,
                                        edgecolor=color))
            # The number just outside the frame's top-left corner, outlined so that it
            # reads on light and dark parts of the image alike.
            main_ax.annotate(str(k + 1), (c - 0.5, r - 0.5), xytext=(-2, 2),
                             textcoords="offset points", color=color, fontsize=11,
                             fontweight="bold", va="bottom", ha="right",
                             path_effects=[withStroke(linewidth=2.5, foreground="black")])
            ax.imshow(shown[r:r + s, c:c + s], interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            for spine in ax.spines.values():
                spine.set_edgecolor(color)
                spine.set_linewidth(2.0)
            ax.set_title(f"{k + 1}: {label}", fontsize=8)
    fig.suptitle(title, fontsize=11)
    return _save_all(fig, path)
