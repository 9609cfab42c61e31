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
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .io.atomic import atomic_path

__all__ = ["check_figure_path", "new_figure", "save_figure", "plot_focal_surfaces",
           "plot_ipsf", "plot_bank", "plot_table1", "plot_per_radius"]

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


def _format_of(path: Path) -> str:
    return path.suffix.lstrip(".").lower() or "png"


def check_figure_path(path: str | Path, flag: str | None = None) -> Path:
    """Refuse, before any long computation, a figure path whose format cannot be written.

    ``flag`` (e.g. ``"--plot"``) is named in the message.

    Raises
    ------
    ValueError
        The suffix names no format matplotlib writes here (PGF needs a TeX system); the
        message lists those it does.
    """
    import shutil

    import matplotlib
    from matplotlib.figure import Figure

    p = Path(path)
    formats = set(Figure().canvas.get_supported_filetypes())
    if shutil.which(matplotlib.rcParams["pgf.texsystem"]) is None:
        formats.discard("pgf")   # PGF output measures its text with LaTeX
    if _format_of(p) not in formats:
        raise ValueError(f"{flag + ' ' if flag else ''}{p}: a figure must end in one of "
                         f"{', '.join('.' + f for f in sorted(formats))} (or have no suffix, "
                         f"for PNG)")
    return p


def new_figure(*args, figsize=(7.0, 4.5), layout: str | None = "constrained", **kwargs):
    """A new figure and its axes: ``Figure(figsize, layout).subplots(*args, **kwargs)``."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout=layout)
    return fig, fig.subplots(*args, **kwargs)


def save_figure(fig, path: str | Path, dpi: int = DPI) -> Path:
    """Write ``fig`` to ``path`` atomically (format from the suffix, PNG without one).

    PNG, PDF, SVG and PostScript files name their maker (``Creator: mitsweep <version>``)
    in their metadata; matplotlib has no metadata for the other formats.
    """
    from . import __version__

    p = Path(path)
    fmt = _format_of(p)
    extra = {"metadata": {"Creator": f"mitsweep {__version__}"}} if fmt in _TAGGED else {}
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=fmt, **extra)
    logger.info("wrote %s", p)
    return p


def _legend_outside(ax) -> None:
    """The legend right of the axes, top-aligned: never over the data."""
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              framealpha=1.0)


def plot_focal_surfaces(setup, sweep, path: str | Path,
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
            ax.plot(p[ok, 0], p[ok, 2], "-", color=c, lw=1, label="depth 0 mm")
            continue
        dm, dsg = focal_distances(setup, xs[ok], d)
        for dist, style, nm in ((dm, "-", "meridional"), (dsg, "--", "sagittal")):
            q = p[ok] - dist[:, None] * ray.to_lens[ok]
            ax.plot(q[:, 0], q[:, 2], style, color=c, lw=1, label=f"{nm}, depth {d:g} mm")
    vd = setup.mirror.vertex_distance
    for f, lab in ((sweep.focus_min, "focus min"), (sweep.focus_max, "focus max")):
        ax.axhline(vd - f, color="0.5", lw=0.6, ls=":")
        ax.text(xs[0], vd - f, f" {lab} {f:.1f} mm", fontsize=7, va="bottom")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm), camera above")
    ax.set_aspect("equal")
    ax.set_title(f"{setup.name}: focal surfaces (FOV {sweep.fov_deg:g}°)")
    # Outside the axes: inside, every corner holds a curve or a focus label.
    _legend_outside(ax)
    return save_figure(fig, path)


def _thumbnail(ax, kernel, pitch_um: float, title: str):
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


def plot_ipsf(kernel, path: str | Path, *, pitch_mm: float,
              sections: tuple[np.ndarray, np.ndarray, np.ndarray],
              title: str = "IPSF") -> Path:
    """One IPSF: thumbnail (normalised to its maximum, with a colour bar) and its radial
    and tangential cross-sections (paper Fig. 3).

    Parameters
    ----------
    kernel : (K, K) array_like
        Unit-sum kernel, rows down the image, the chief-ray image at the centre.
    path : path
    pitch_mm : float
        Pixel pitch, mm.
    sections : tuple of three (n,) arrays
        ``(x, radial, tangential)`` as :func:`mitsweep.tracer.metrics.cross_sections`
        returns them (``x`` in pixels).
    title : str
    """
    fig, (a0, a1) = new_figure(1, 2, figsize=(10, 4))
    pitch_um = pitch_mm * 1e3
    im = _thumbnail(a0, kernel, pitch_um, title)
    a0.set_ylabel("v (µm)", fontsize=7)
    fig.colorbar(im, ax=a0, label="intensity / maximum", shrink=0.9)
    _sections_axes(a1, sections, pitch_um)
    a1.set_xlabel("position (µm)")
    a1.set_ylabel("IPSF (unit sum)")
    a1.grid(color=GRID_COLOR)
    a1.legend(framealpha=1.0)
    return save_figure(fig, path)


def plot_bank(bank, path: str | Path, *,
              sections: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]]],
              max_thumbs: int = 10) -> Path:
    """An IPSF bank: thumbnails across the field at its first depth, and cross-sections
    over its depths at chosen points (paper Fig. 4–5).

    Parameters
    ----------
    bank : mitsweep.io.bank.IPSFBank
        Reads ``kernels`` (n_depths, n_points, K, K), ``points_uv`` (n_points, 2) mm,
        ``depths_mm`` (n_depths,) and ``pixel_pitch`` mm.
    path : path
    sections : mapping of str to a sequence of ``(x, radial, tangential)``
        Per panel (e.g. ``"centre"``, ``"periphery"``), the cross-sections of one point
        at each of the bank's depths, in the bank's depth order (radial in blue shades,
        tangential in red shades, brightest at the first depth, darker at each next).
    max_thumbs : int
        At most this many thumbnails, evenly spaced over the points.
    """
    from matplotlib.figure import Figure

    kernels = np.asarray(bank.kernels)
    n_depths, n = kernels.shape[:2]
    for name, per_depth in sections.items():
        if len(per_depth) != n_depths:
            raise ValueError(f"sections[{name!r}]: need one per depth ({n_depths}), "
                             f"got {len(per_depth)}")
    idx = np.unique(np.linspace(0, n - 1, min(n, max_thumbs)).round().astype(int))
    cols = max(len(idx), 2)
    pitch_um = bank.pixel_pitch * 1e3
    fig = Figure(figsize=(max(1.6 * cols + 1.2, 8.0), 6.4), layout="constrained")
    fig.get_layout_engine().set(h_pad=0.1)   # inches; room between the rows' titles
    top, bottom = fig.subfigures(2, 1, height_ratios=(1.0, 1.35))
    thumbs = top.subplots(1, cols, sharex=True, sharey=True, squeeze=False)[0]
    im = None
    for j, i in enumerate(idx):
        u, v = bank.points_uv[i]
        im = _thumbnail(thumbs[j], kernels[0, i], pitch_um, f"({u:.2f}, {v:.2f}) mm")
    for ax in thumbs[len(idx):]:
        ax.set_visible(False)
    thumbs[0].set_ylabel("v (µm)", fontsize=7)
    top.colorbar(im, ax=list(thumbs), label="intensity / maximum", shrink=0.9)
    top.suptitle(f"IPSFs across the field, depth {_depth_text(bank.depths_mm[0])}",
                 fontsize=9)
    panels = bottom.subplots(1, max(len(sections), 1), squeeze=False)[0]
    for ax, (name, per_depth) in zip(panels, sections.items()):
        for d, (depth, sec) in enumerate(zip(bank.depths_mm, per_depth)):
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


def _depth_text(depth_mm: float) -> str:
    return "inf" if math.isinf(depth_mm) else f"{depth_mm / 1000:g} m"


#: Up to this many sweep ranges, Table 1's bar labels stand upright on two lines.
TABLE1_UPRIGHT_RANGES = 5


def plot_table1(result: dict, path: str | Path) -> Path:
    """The paper's Table 1 as bar charts: V_avg per sweep range and the conventional
    camera (log scale), and the four mean kurtoses per sweep range.

    Parameters
    ----------
    result : dict
        As :func:`mitsweep.tracer.table1.table1` returns it: ``rows`` (each with
        ``focus_min_mm``, ``focus_max_mm``, ``v_avg`` and ``kurtosis[where][direction]``
        for ``where`` in centre/periphery and ``direction`` in tangential/radial) and
        ``conventional["v_avg"]``.
    path : path
    """
    rows = result["rows"]
    # Side by side, one-line "339–364 mm" labels run into each other: two lines each for a
    # few ranges, vertical single lines for more (two lines no longer fit then either).
    vertical = len(rows) > TABLE1_UPRIGHT_RANGES
    br = "" if vertical else "\n"
    labels = [f"{r['focus_min_mm']:.0f}–{br}{r['focus_max_mm']:.0f} mm" for r in rows]
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
    return save_figure(fig, path)


#: Colour of each image kind in :func:`plot_per_radius` (noisy versions share it).
IMAGE_COLORS = {"edof": "tab:red", "focused": "tab:blue", "stopped": "tab:green",
                "sweep": "0.45", "pinhole": "k"}
OTHER_IMAGE_COLOR = "tab:purple"
#: Entries per column of the per-radius key (more light levels: more columns).
LEGEND_ROWS = 20
#: Line style and marker of the noise-free images in :func:`plot_per_radius`.
CLEAN_STYLE = ("-", "o")
#: Line styles and markers of the light levels, brightest first: level k gets style
#: k mod 3 and marker k mod 11, so 33 levels (3 × 11, coprime) get distinct pairs, more
#: than a dataset holds (mitsweep.pipeline.MAX_LIGHT_LEVELS).
LIGHT_DASHES = ("--", "-.", ":")
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
    style_of = {None: CLEAN_STYLE}
    style_of.update({lux: (LIGHT_DASHES[k % len(LIGHT_DASHES)],
                           LIGHT_MARKERS[k % len(LIGHT_MARKERS)])
                     for k, lux in enumerate(levels)})
    from matplotlib.lines import Line2D

    fig, ax = new_figure(figsize=(8.5, 4.8))
    kinds, lights = {}, {}
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
