"""Figures of IPSFs like the paper's Fig. 3–5: thumbnails and cross-sections."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..plots import new_figure, save_figure
from .metrics import cross_sections

__all__ = ["plot_ipsf", "plot_bank", "plot_table1"]


def _thumb(ax, kernel, pitch_um: float, title: str) -> None:
    k = np.asarray(kernel, dtype=float)
    K = k.shape[0]
    half = K / 2 * pitch_um
    ax.imshow(k / max(k.max(), 1e-30), cmap="inferno", extent=(-half, half, -half, half),
              interpolation="nearest")
    ax.set_title(title, fontsize=8)
    ax.set_xlabel("u [µm]", fontsize=7)
    ax.tick_params(labelsize=6)


def plot_ipsf(kernel, path: str | Path, *, pitch_mm: float, angle: float = 0.0,
              title: str = "IPSF") -> Path:
    """Thumbnail (normalised by its maximum) and radial/tangential cross-sections."""
    fig, (a0, a1) = new_figure(1, 2, figsize=(9, 4))
    _thumb(a0, kernel, pitch_mm * 1e3, title)
    x, rad, tan = cross_sections(kernel, angle)
    a1.plot(x * pitch_mm * 1e3, rad, "b-", label="radial")
    a1.plot(x * pitch_mm * 1e3, tan, "r-", label="tangential")
    a1.set_xlabel("position [µm]")
    a1.set_ylabel("IPSF (unit sum)")
    a1.legend()
    return save_figure(fig, path)


def plot_bank(bank, path: str | Path, *, max_thumbs: int = 10) -> Path:
    """Thumbnails across the field (first depth) and centre/periphery cross-sections
    over depths (radial in blue shades, tangential in red shades)."""
    n = bank.kernels.shape[1]
    idx = np.unique(np.linspace(0, n - 1, min(n, max_thumbs)).round().astype(int))
    cols = len(idx)
    fig, axes = new_figure(2, max(cols, 2), figsize=(1.6 * max(cols, 2), 4.2),
                           squeeze=False)
    pitch_um = bank.pixel_pitch * 1e3
    for j, i in enumerate(idx):
        u, v = bank.points_uv[i]
        _thumb(axes[0, j], bank.kernels[0, i], pitch_um, f"({u:.2f}, {v:.2f}) mm")
    for ax in axes[1]:
        ax.axis("off")
    for slot, (i, name) in enumerate(((0, "centre"), (n - 1, "periphery"))):
        ax = fig.add_subplot(2, 2, 3 + slot)
        u, v = bank.points_uv[i]
        ang = math.atan2(v, u) if (u or v) else 0.0
        for d, depth in enumerate(bank.depths_mm):
            x, rad, tan = cross_sections(bank.kernels[d, i], ang)
            shade = 0.35 + 0.65 * (d + 1) / len(bank.depths_mm)
            ax.plot(x * pitch_um, rad, color=(0, 0, shade), lw=1,
                    label=f"radial {depth / 1000:g} m")
            ax.plot(x * pitch_um, tan, color=(shade, 0, 0), lw=1,
                    label=f"tangential {depth / 1000:g} m")
        ax.set_title(name, fontsize=8)
        ax.set_xlabel("position [µm]", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=5)
    return save_figure(fig, path)


def plot_table1(result: dict, path: str | Path) -> Path:
    """Bar chart of Table 1: V_avg per range (log) and the four mean kurtoses."""
    rows = result["rows"]
    labels = [f"{r['focus_min_mm']:.0f}–{r['focus_max_mm']:.0f}" for r in rows]
    fig, (a0, a1) = new_figure(1, 2, figsize=(10, 4))
    a0.bar(labels + ["conventional"], [r["v_avg"] for r in rows] +
           [result["conventional"]["v_avg"]], color=["tab:blue"] * len(rows) + ["tab:gray"])
    a0.set_yscale("log")
    a0.set_ylabel("V_avg (Eq. 3)")
    keys = [("center", "tangential"), ("center", "radial"), ("periphery", "tangential"),
            ("periphery", "radial")]
    width = 0.8 / len(keys)
    for k, (where, dirn) in enumerate(keys):
        a1.bar(np.arange(len(rows)) + k * width, [r["kurtosis"][where][dirn] for r in rows],
               width, label=f"{where} {dirn}")
    a1.set_xticks(np.arange(len(rows)) + 0.4 - width / 2, labels)
    a1.set_ylabel("kurtosis (Gaussian = 3)")
    a1.legend(fontsize=7)
    return save_figure(fig, path)
