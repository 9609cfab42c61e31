"""Figures (mitsweep.plots): each function writes a real PNG from tiny data, and the
defects users reported stay fixed (checked on the drawn figure's geometry)."""

from __future__ import annotations

import json
import logging
import math
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from mitsweep import plots
from mitsweep.cli.main import main
from mitsweep.config import load_setup
from mitsweep.io.bank import IPSFBank
from mitsweep.optics import optimal_sweep_range
from mitsweep.pipeline import MAX_LIGHT_LEVELS
from mitsweep.tracer.metrics import cross_sections

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
K = 15           # kernel size of the tiny kernels
PITCH_MM = 0.018


def png_size(path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk; asserts the file is a PNG."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def assert_real_png(path, figsize_in) -> None:
    """A PNG whose pixel size is about the figure's (tight bounding box: it may shrink
    by the margins, or grow by a legend placed outside the axes), with a drawing on it."""
    width, height = png_size(path)
    nominal_w, nominal_h = (s * plots.DPI for s in figsize_in)
    assert 0.6 * nominal_w <= width <= 1.6 * nominal_w, (width, nominal_w)
    assert 0.6 * nominal_h <= height <= 1.6 * nominal_h, (height, nominal_h)
    pixels = imread(path)
    assert pixels.shape[:2] == (height, width)
    # A figure, not a blank page: many distinct colours.
    assert len(np.unique(pixels.reshape(-1, pixels.shape[-1]), axis=0)) > 20
    assert not list(path.parent.glob(f".{path.name}.*")), "temporary left behind"


def gaussian_kernel(sigma_px: float, shift_px: float = 0.0) -> np.ndarray:
    y, x = np.mgrid[:K, :K] - K // 2
    k = np.exp(-((x - shift_px) ** 2 + y ** 2) / (2 * sigma_px ** 2))
    return (k / k.sum()).astype(np.float32)


def tiny_bank(n_points: int = 3, depths=(500.0, math.inf)) -> IPSFBank:
    kernels = np.stack([np.stack([gaussian_kernel(1.0 + 0.5 * i + 0.2 * d, 0.5 * i)
                                  for i in range(n_points)]) for d in range(len(depths))])
    radii = np.linspace(0.0, 2.0, n_points)
    return IPSFBank(kernels=kernels, points_uv=np.column_stack([radii, np.zeros(n_points)]),
                    depths=np.array(depths), pixel_pitch=PITCH_MM,
                    reference_sensor_distance=50.0, kind="radial", radii=radii,
                    metadata={"synthetic": True})


def bank_sections(bank):
    return {name: [cross_sections(k, 0.0) for k in bank.kernels[:, i]]
            for name, i in (("centre", 0), ("periphery", bank.kernels.shape[1] - 1))}


def table1_result(n_rows: int = 4) -> dict:
    rows = [{"focus_min_mm": 339.0, "focus_max_mm": hi, "v_avg": 600.0 / (j + 1),
             "kurtosis": {"center": {"tangential": 5.0 + j, "radial": 5.1 + j},
                          "periphery": {"tangential": 2.0 + j / 3, "radial": 4.0 - j / 3}}}
            for j, hi in enumerate(np.linspace(348.0, 374.0, n_rows))]
    return {"rows": rows, "conventional": {"v_avg": 3e6}}


LIGHT_LEVELS = (50.0, 2.0, 0.5)


def evaluation_results(light_levels=LIGHT_LEVELS) -> dict:
    radius = np.linspace(10.0, 200.0, 6)
    scene = {"white_level": 1.0, "mirror_radius_px": 200.0}
    for base, psnr in (("edof", 34.0), ("focused", 28.0), ("stopped", 26.0), ("sweep", 24.0)):
        names = [(base, psnr)]
        if base != "focused":
            names += [(f"{base}_{lux:g}lux", psnr - 3 * (j + 1))
                      for j, lux in enumerate(light_levels)]
        for name, p in names:
            scene[name] = {"psnr": p, "ssim": 0.9,
                           "per_radius": {"radius_px": radius.tolist(),
                                          "psnr": (p - radius / 100).tolist()}}
    return {"scenes": {"scene_000": scene}}


def _boxes_overlap(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def test_focal_surfaces_png_with_the_legend_off_the_curves(scenes_dir, tmp_path, drawn):
    setup = load_setup(scenes_dir / "sphere.toml")
    path = plots.plot_focal_surfaces(setup, optimal_sweep_range(setup), tmp_path / "fig6.png")
    assert_real_png(path, (8.5, 6))
    (fig, renderer), = drawn
    ax = fig.axes[0]
    legend = ax.get_legend().get_window_extent(renderer)
    assert not _boxes_overlap(legend, ax.get_window_extent(renderer))
    labels = {t.get_text().split()[1] for t in ax.texts}
    assert labels == {"min", "max"}   # both focus lines labelled, neither hidden
    # The focus labels sit outside the axes (inside, they ran over the curves) and off
    # the legend.
    for t in ax.texts:
        box = t.get_window_extent(renderer)
        assert not _boxes_overlap(box, ax.get_window_extent(renderer)), t.get_text()
        assert not _boxes_overlap(box, legend), t.get_text()


def test_ipsf_png_has_a_colour_bar_and_unclashing_labels(tmp_path, drawn):
    kernel = gaussian_kernel(1.5, 1.0)
    path = plots.plot_ipsf(kernel, tmp_path / "ipsf.png", pixel_pitch=PITCH_MM,
                           sections=cross_sections(kernel, 0.0), title="IPSF")
    assert_real_png(path, (10, 4))
    (fig, renderer), = drawn
    thumb, sections = fig.axes[0], fig.axes[1]
    assert thumb.images[0].colorbar is not None
    colorbar_ax = thumb.images[0].colorbar.ax
    # The cross-section panel's y label clears the thumbnail and its colour bar.
    ylabel = sections.yaxis.label.get_window_extent(renderer)
    for other in (thumb, colorbar_ax):
        assert not _boxes_overlap(ylabel, other.get_tightbbox(renderer))


@pytest.mark.slow   # 4 s; to keep the default run under 4 minutes on 2 cores
def test_bank_png_thumbnails_share_a_colour_bar_without_overlap(tmp_path, drawn):
    bank = tiny_bank()
    path = plots.plot_bank(bank, tmp_path / "bank.png", sections=bank_sections(bank))
    assert_real_png(path, (8.0, 6.4))
    (fig, renderer), = drawn
    images = [ax for ax in fig.axes if ax.images]
    assert len(images) == bank.kernels.shape[1]
    # One colour bar for all: every thumbnail on the same 0..1 scale (of its maximum).
    assert sum(ax.images[0].colorbar is not None for ax in images) == 1
    assert all(ax.images[0].get_clim() == (0.0, 1.0) for ax in images)
    boxes = [ax.get_tightbbox(renderer) for ax in images]
    assert not any(_boxes_overlap(a, b) for j, a in enumerate(boxes) for b in boxes[j + 1:])
    panels = [ax for ax in fig.axes if ax.get_title() in ("centre", "periphery")]
    assert len(panels) == 2
    assert all(len(ax.lines) == 2 * len(bank.depths) for ax in panels)


def test_bank_refuses_sections_not_matching_its_depths(tmp_path):
    bank = tiny_bank()
    sections = bank_sections(bank)
    sections["periphery"] = sections["periphery"][:1]
    with pytest.raises(ValueError, match=r"sections\['periphery'\]: need one per depth \(2\)"):
        plots.plot_bank(bank, tmp_path / "bank.png", sections=sections)
    assert not (tmp_path / "bank.png").exists()


@pytest.mark.parametrize("n_rows", [pytest.param(n, marks=pytest.mark.slow) for n in (1, 5, 6)]
                         + [12])   # the crowded table by default; the rest in CI
def test_table1_png_tick_labels_do_not_overlap(tmp_path, drawn, n_rows):
    path = plots.plot_table1(table1_result(n_rows), tmp_path / "table1.png")
    assert_real_png(path, (11, 4.5))
    (fig, renderer), = drawn
    for ax in fig.axes:
        boxes = [t.get_window_extent(renderer) for t in ax.get_xticklabels() if t.get_text()]
        assert len(boxes) == n_rows + (1 if ax is fig.axes[0] else 0)
        assert not any(_boxes_overlap(a, b) for j, a in enumerate(boxes) for b in boxes[j + 1:])
    legend = fig.axes[1].get_legend().get_window_extent(renderer)
    assert not _boxes_overlap(legend, fig.axes[1].get_window_extent(renderer))


@pytest.mark.parametrize("levels", [LIGHT_LEVELS,
                                    pytest.param(tuple(100.0 / 2 ** np.arange(MAX_LIGHT_LEVELS)),
                                                 marks=pytest.mark.slow)],
                         ids=["paper", "most"])
def test_per_radius_png_gives_each_light_level_its_own_style(tmp_path, drawn, levels):
    results = evaluation_results(levels)
    path = plots.plot_per_radius(results, tmp_path / "psnr_per_radius.png")
    assert_real_png(path, (8.5, 4.8))
    (fig, renderer), = drawn
    lines = {line.get_label(): line for line in fig.axes[0].lines}
    assert len(lines) == len([v for v in results["scenes"]["scene_000"].values()
                              if isinstance(v, dict)])
    for base in ("edof", "stopped", "sweep"):
        group = [lines[base]] + [lines[f"{base}, {lux:g} lux"] for lux in levels]
        styles = {(line.get_linestyle(), line.get_marker()) for line in group}
        assert len(styles) == len(group), (base, styles)
        assert len({line.get_color() for line in group}) == 1   # colour = image kind
    legend = fig.axes[0].get_legend().get_window_extent(renderer)
    assert not _boxes_overlap(legend, fig.axes[0].get_window_extent(renderer))


def test_plotting_leaves_pyplot_and_the_backend_alone(tmp_path):
    """Figures are drawn without pyplot: no backend chosen, no figure left registered."""
    code = ("import sys, matplotlib\n"
            "from mitsweep import plots\n"
            "from test_plots import table1_result\n"
            f"plots.plot_table1(table1_result(), {str(tmp_path / 't.png')!r})\n"
            "print('pyplot' if 'matplotlib.pyplot' in sys.modules else 'no pyplot')\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=Path(__file__).parent, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "no pyplot"
    assert png_size(tmp_path / "t.png")[0] > 0


@pytest.mark.parametrize("name,head,tagged", [
    ("fig.png", PNG_SIGNATURE, True), ("fig.PNG", PNG_SIGNATURE, True),
    ("fig", PNG_SIGNATURE, True), ("fig.svg", b"<?xml", True), ("fig.pdf", b"%PDF", True),
    ("fig.eps", b"%!PS-Adobe", True), ("fig.jpg", b"\xff\xd8\xff", False)])
def test_the_suffix_picks_the_format_and_the_file_names_its_maker(tmp_path, caplog, name,
                                                                  head, tagged):
    from mitsweep import __version__

    with caplog.at_level(logging.INFO, logger="matplotlib"):
        path = plots.plot_per_radius(evaluation_results(), tmp_path / name)
    data = path.read_bytes()
    assert data.startswith(head)
    assert (f"mitsweep {__version__}".encode() in data) is tagged
    # No transparency for PostScript to complain about, nothing else said either.
    assert [r.getMessage() for r in caplog.records if r.name.startswith("matplotlib")] == []


def test_unknown_figure_format_is_refused_naming_the_flag(tmp_path):
    with pytest.raises(ValueError, match=r"--plot .*fig\.txt: a figure must end in one of "
                                         r"\..*\.png"):
        plots.check_figure_path(tmp_path / "fig.txt", "--plot")
    assert plots.check_figure_path(tmp_path / "fig.png") == tmp_path / "fig.png"


def test_pgf_is_refused_without_a_tex_system(tmp_path, monkeypatch):
    """PGF output needs LaTeX to measure text: without it the plot would fail after the
    computation, so the format is refused up front."""
    import matplotlib

    monkeypatch.setitem(matplotlib.rcParams, "pgf.texsystem", "xelatex")
    monkeypatch.setenv("PATH", str(tmp_path))   # no xelatex on it
    with pytest.raises(ValueError, match=r"fig\.pgf: a figure must end in one of"):
        plots.check_figure_path(tmp_path / "fig.pgf")


@pytest.mark.parametrize("command", [["table1"], ["ipsf", "--bank", "radial"],
                                     ["sweep-range", "--verify"]], ids=lambda c: c[0])
def test_cli_refuses_a_bad_plot_format_before_tracing(scenes_dir, tmp_path, capsys, command):
    """Refused before any trace (after them, these runs would take minutes)."""
    rc = main([command[0], str(scenes_dir / "sphere.toml"), *command[1:],
               "--plot", str(tmp_path / "t.txt")])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith("mitsweep: error: --plot ") and "t.txt" in err and ".png" in err
    assert "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "t.txt").exists()


def test_ipsf_bank_cli_writes_its_plot(scenes_dir, tmp_path, capsys):
    png = tmp_path / "bank.png"
    rc = main(["ipsf", str(scenes_dir / "sphere.toml"), "--bank", "radial", "--radii", "3",
               "--depth", "500", "inf", "--rays", "20000", "--plot", str(png), "--json"])
    assert rc == 0
    assert json.loads(capsys.readouterr().out)["plot"] == str(png)
    width, height = png_size(png)
    assert width > 0 and height > 0
