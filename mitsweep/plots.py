"""Figures (matplotlib, Agg backend; written atomically)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .io.atomic import atomic_path

__all__ = ["new_figure", "save_figure", "plot_focal_surfaces"]

log = logging.getLogger(__name__)


def new_figure(*args, **kwargs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kwargs)


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    import matplotlib.pyplot as plt

    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format=p.suffix.lstrip(".") or "png")
    plt.close(fig)
    log.info("wrote %s", p)
    return p


def plot_focal_surfaces(setup, sweep, path, depths=(0.0, 20.0, np.inf)) -> Path:
    """Meridional and sagittal focal surfaces in the meridional plane (paper Fig. 6).

    Drawn for ``depths`` (mm; 0 is the mirror itself) plus the two ends of the sweep's
    depth range.
    """
    from .optics import chief_ray, placement_of
    from .optics.coddington import focal_distances

    placement = placement_of(setup.mirror)
    ds = sorted(set(depths) | {sweep.depth_min_mm, sweep.depth_max_mm})
    lo = -setup.mirror.rim_radius if not setup.mirror.is_symmetric else -sweep.rho_max_mm
    xs = np.linspace(min(lo, sweep.rho_start_mm), max(sweep.rho_end_mm, sweep.rho_max_mm), 801)
    ray = chief_ray(placement, placement.surface(xs, np.zeros_like(xs)))
    ok = ray.visible
    fig, ax = new_figure(figsize=(7, 6))
    p = ray.surface.position
    ax.plot(p[ok, 0], p[ok, 2], "k-", lw=2, label="mirror")
    colors = iter(["tab:green", "tab:orange", "tab:purple", "tab:brown", "tab:red", "tab:gray"])
    for d in ds:
        c = next(colors)
        if d == 0:
            ax.plot(p[ok, 0], p[ok, 2], "-", color=c, lw=1, label="depth 0 mm")
            continue
        dm, dsg = focal_distances(setup, xs[ok], d)
        for dist, style, nm in ((dm, "-", "meridional"), (dsg, "--", "sagittal")):
            q = p[ok] - dist[:, None] * ray.to_lens[ok]
            ax.plot(q[:, 0], q[:, 2], style, color=c, lw=1, label=f"{nm}, depth {d:g} mm")
    vd = setup.mirror.vertex_distance
    for f, lab in ((sweep.focus_min_mm, "focus min"), (sweep.focus_max_mm, "focus max")):
        ax.axhline(vd - f, color="0.5", lw=0.6, ls=":")
        ax.text(xs[0], vd - f, f" {lab} {f:.1f} mm", fontsize=7, va="bottom")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm), camera above")
    ax.set_aspect("equal")
    ax.set_title(f"{setup.name}: focal surfaces (FOV {sweep.fov_deg:g}°)")
    ax.legend(fontsize=6, loc="lower left")
    return save_figure(fig, path)
