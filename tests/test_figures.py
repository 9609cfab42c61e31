"""``mitsweep figures``: every named file of the paper's figures, the refusals at the CLI,
and the pieces the figures are made of (field points, inset regions, the builders)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from matplotlib.image import imread

from conftest import run_cli
from mitsweep import plots
from mitsweep.cli.main import main
from mitsweep.config import load_setup
from mitsweep.optics import optimal_sweep_range
from mitsweep.optics.reference import reference_geometry
from mitsweep.pipeline.figures import (PAPER_SETUPS, field_points, figure_files,
                                       inset_regions)
from mitsweep.tracer.metrics import cross_sections

from test_plots import _boxes_overlap, gaussian_kernel, png_size

PDF_SIGNATURE = b"%PDF-"


# -- the command --------------------------------------------------------------------------

@pytest.mark.slow
def test_quick_run_writes_every_named_file_and_refuses_a_second_run(tmp_path):
    """The default (the paper's three setups) with --quick: every PNG decodes at a
    figure's size, every PDF is a PDF; a second run without --force writes nothing."""
    out = tmp_path / "figs"
    rc, stdout, stderr = run_cli("figures", "--quick", "--out", out, timeout=1800)
    assert rc == 0, stderr
    setups = [load_setup(f"scenes/{name}.toml") for name in PAPER_SETUPS]
    expected = [name for s in setups for name in figure_files(s)]
    assert len(expected) == 3 * 7 * 2 + 2 * 4   # 7 figures each, Table 1 for 2 untilted
    for name in expected:
        path = out / name
        assert path.is_file() and path.stat().st_size > 0, name
        if name.endswith(".png"):
            width, height = png_size(path)
            # 120 dpi figures 5-13 inches wide: no empty canvas, no runaway legend
            assert 500 <= width <= 2000 and 400 <= height <= 2000, (name, width, height)
            assert imread(path).shape[:2] == (height, width)
        elif name.endswith(".pdf"):
            assert path.read_bytes()[:5] == PDF_SIGNATURE, name
    report = json.loads((out / "figures.json").read_text())
    assert report["quality"]["name"] == "quick"
    assert sorted(report["setups"]) == sorted(PAPER_SETUPS)
    table = json.loads((out / "table1_sphere.json").read_text())
    assert len(table["rows"]) == 4 and table["conventional"]["v_avg"] > 0
    assert f"{len(expected)} files" in stdout

    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    rc, _, stderr = run_cli("figures", "--quick", "--out", out)
    assert rc == 2
    assert stderr.count("\n") == 1 and "--force" in stderr and "exists" in stderr
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == before


def test_an_existing_figure_is_refused_without_force(tmp_path, capsys):
    out = tmp_path / "figs"
    out.mkdir()
    old = out / "fig6_sphere.png"
    old.write_bytes(b"an earlier run")
    assert main(["figures", "--quick", "--setup", "sphere", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mitsweep: error: ")
    assert str(old) in err and "--force" in err
    assert old.read_bytes() == b"an earlier run"
    assert sorted(p.name for p in out.iterdir()) == ["fig6_sphere.png"]


@pytest.mark.parametrize("argv, words", [
    (["--setup", "ellipsoid"], ["ellipsoid", *PAPER_SETUPS]),
    (["--setup", "missing.toml"], ["missing.toml", ".toml"]),
    (["--setup", "sphere", "--setup", "sphere"], ["sphere", "twice"]),
])
def test_bad_setup_is_refused_in_one_line(tmp_path, capsys, argv, words):
    out = tmp_path / "figs"
    assert main(["figures", "--quick", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("mitsweep: error: ")
    assert "Traceback" not in err
    for w in words:
        assert w in err
    assert not out.exists()


# -- the pieces ---------------------------------------------------------------------------

@pytest.mark.parametrize("name", PAPER_SETUPS)
def test_field_points_run_from_the_centre_across_the_field(scenes_dir, name):
    setup = load_setup(scenes_dir / f"{name}.toml")
    sweep = optimal_sweep_range(setup)
    ref = reference_geometry(setup, sweep=sweep).sensor_distance
    points = field_points(setup, sweep, ref)
    xs = [p.x for p in points]
    assert 0.0 in xs and xs == sorted(xs)
    assert max(abs(x) for x in xs) <= max(abs(sweep.rho_start), abs(sweep.rho_end))
    if setup.mirror.is_symmetric:
        # On the axis of a symmetric mirror the chief ray images the centre at (0, 0),
        # and the image radius grows along the +u half-axis.
        assert xs[0] == 0.0 and math.hypot(points[0].u, points[0].v) < 1e-9
        us = [p.u for p in points]
        assert all(abs(p.v) < 1e-9 for p in points) and us == sorted(us)


def test_inset_regions_lie_in_the_mask_in_their_zones_apart_and_on_detail():
    n = 200
    y, x = np.mgrid[:n, :n]
    r = np.hypot(y - 100, x - 100)
    mask = (r < 90).astype(np.float32)
    guide = np.full((n, n, 3), 0.5)
    # Detail (a checkerboard) in one spot of each zone; flat elsewhere.
    checker = ((y // 2 + x // 2) % 2).astype(float)[..., None]
    for cy, cx in ((100, 125), (100, 20)):   # 0.28 and 0.89 of the radius
        sl = (slice(cy - 10, cy + 10), slice(cx - 10, cx + 10))
        guide[sl] = checker[sl]
    regions = inset_regions(mask, guide)
    assert len(regions) == 2
    radius = math.sqrt(mask.sum() / math.pi)
    for (row, col, side), (lo, hi), (cy, cx) in zip(regions, ((0.15, 0.5), (0.75, 0.97)),
                                                      ((100, 125), (100, 20))):
        assert np.all(mask[row:row + side, col:col + side] > 0.5)
        d = math.hypot(row + side / 2 - 100, col + side / 2 - 100) / radius
        assert lo <= d <= hi
        assert row <= cy < row + side and col <= cx < col + side   # on the detail
    (r1, c1, s), (r2, c2, _) = regions
    assert abs(r1 - r2) >= 2 * s or abs(c1 - c2) >= 2 * s


def test_inset_regions_refuse_an_empty_mask():
    with pytest.raises(ValueError, match="mask is empty"):
        inset_regions(np.zeros((32, 32)), np.zeros((32, 32)))


@pytest.mark.slow   # 3 s; to keep the default run under 4 minutes on 2 cores
def test_psf_planes_share_one_colour_bar_and_window(tmp_path, drawn):
    kernels = np.stack([np.stack([gaussian_kernel(0.5 + 0.1 * i + 0.1 * j)
                                  for j in range(3)]) for i in range(2)])
    paths = plots.plot_psf_planes(kernels, [tmp_path / "f.png", tmp_path / "f.pdf"],
                                  pixel_pitch=0.018, focus_distances=[340.0, 360.0],
                                  sensor_distances=[58.6, 58.1], positions=["a", "b", "c"],
                                  title="t")
    assert [p.name for p in paths] == ["f.png", "f.pdf"]
    assert (tmp_path / "f.pdf").read_bytes()[:5] == PDF_SIGNATURE
    fig, renderer = drawn[0]
    thumbs = [ax for ax in fig.axes if ax.images]
    assert len(thumbs) == 6
    assert sum(ax.images[0].colorbar is not None for ax in thumbs) == 1
    # The window holds the widest kernel's energy, narrower than the whole kernel.
    lo, hi = thumbs[0].get_xlim()
    assert -lo == pytest.approx(hi) and hi < 15 / 2 * 18.0


@pytest.mark.slow   # 3 s; to keep the default run under 4 minutes on 2 cores
def test_sweep_ranges_key_clears_the_panels_and_depths_differ_in_style(tmp_path, drawn):
    depths = (500.0, 5000.0, 50000.0)
    per_depth = [cross_sections(gaussian_kernel(1.0 + 0.1 * d), 0.0) for d in range(3)]
    sections = [{"centre": per_depth, "periphery": per_depth} for _ in range(3)]
    ranges = [(339.0, 348.0), (339.0, 357.0), (339.0, 364.0)]
    plots.plot_sweep_ranges(sections, tmp_path / "f5.png", pixel_pitch=0.018, ranges=ranges,
                            depths=depths, title="t", optimal=(339.0, 364.0))
    fig, renderer = drawn[0]
    panels = [ax for ax in fig.axes if ax.lines]
    assert len(panels) == 6
    legend = fig.legends[0].get_window_extent(renderer)
    assert not any(_boxes_overlap(legend, ax.get_window_extent(renderer)) for ax in panels)
    styles = {(ln.get_linestyle(), ln.get_marker()) for ln in panels[0].lines}
    assert len(styles) == len(depths)
    assert sum("(optimal)" in ax.get_title() for ax in panels) == 2


def test_insets_frame_each_region_and_label_it(tmp_path, drawn):
    rng = np.random.default_rng(0)
    a, b = rng.random((64, 64, 3)), rng.random((64, 64, 3))
    plots.plot_insets([("left", a), ("right", b)], tmp_path / "f9.png",
                      regions=[(5, 5, 10), (40, 30, 10)], labels=["≈ 30 cm", "≈ 2.0 m"],
                      white=1.0, title="t")
    fig, renderer = drawn[0]
    titles = [ax.get_title() for ax in fig.axes]
    assert titles.count("1: ≈ 30 cm") == 2 and titles.count("2: ≈ 2.0 m") == 2
    mains = [ax for ax in fig.axes if ax.get_title() in ("left", "right")]
    assert all(len(ax.patches) == 2 for ax in mains)
    width, height = png_size(tmp_path / "f9.png")
    assert width > height > 0


def test_fig5_and_table1_draw_one_set_of_traced_banks(tmp_path, scenes_dir, monkeypatch):
    """Table 1's banks are traced once per setup and serve Fig. 5 too: its centre and
    periphery curves are those banks' first and last radii (no IPSF traced for Fig. 5)."""
    import mitsweep.plots
    import mitsweep.tracer.table1 as t1
    from mitsweep.pipeline.figures import QUICK, SetupFigures

    calls, drawn_sections = [], []
    traced = t1.table1_banks

    def counting(*args, **kw):
        calls.append(kw)
        return traced(*args, **kw)

    monkeypatch.setattr(t1, "table1_banks", counting)
    monkeypatch.setattr(mitsweep.plots, "plot_sweep_ranges",
                        lambda sections, path, **kw: drawn_sections.append((sections, kw)))
    monkeypatch.setattr(mitsweep.plots, "plot_table1", lambda result, path, **kw: None)
    tiny = dataclasses.replace(QUICK, table1_rays=2_000, table1_radii=2)
    figs = SetupFigures(load_setup(scenes_dir / "sphere.toml"), tiny, tmp_path, seed=0,
                        step=lambda msg: None)
    single, traced_single = figs.ipsf, []
    monkeypatch.setattr(figs, "ipsf", lambda *a, **kw: traced_single.append(a) or single(*a, **kw))
    figs.fig5()
    figs.table1()
    assert len(calls) == 1 and not traced_single
    (sections, kw), = drawn_sections
    banks = figs.table1_banks()
    lengths = [hi - lo for lo, hi in kw["ranges"]]
    assert lengths == sorted(lengths)   # columns by sweep length
    table = json.loads((tmp_path / "table1_sphere.json").read_text())
    for col, (lo, hi) in zip(sections, kw["ranges"]):
        (bank,) = [b for b in banks if np.allclose(
            (b.metadata["sweep_range"]["focus_min_mm"], b.metadata["sweep_range"]["focus_max_mm"]),
            (lo, hi))]
        x, rad, tan = col["periphery"][0]
        np.testing.assert_array_equal(rad, cross_sections(bank.kernels[0, -1], 0.0)[1])
    assert len(table["rows"]) == len(banks) and list(kw["depths"]) == table["depths_mm"]


def test_table1_chart_runs_from_the_shortest_sweep_and_marks_the_optimal(tmp_path, drawn):
    from test_plots import table1_result

    result = table1_result(3)
    result["rows"].append({**result["rows"][1], "focus_max_mm": 364.25})   # the optimal, last
    plots.plot_table1(result, tmp_path / "t1.png", optimal=(339.0, 364.25))
    (fig, _), = drawn
    labels = [t.get_text() for t in fig.axes[1].get_xticklabels()]
    ends = [float(t.split("–")[1].split()[0]) for t in labels]
    assert ends == sorted(ends) and len(ends) == 4
    assert [("optimal" in t) for t in labels] == [e == 364.0 for e in ends]


def test_pipeline_panels_read_in_the_order_of_the_steps(tmp_path, drawn):
    """Left to right, top to bottom, in the order given (the letters' order), polar
    panels included."""
    rng = np.random.default_rng(1)
    steps = [{"title": f"({c})", "image": rng.random((16, 16, 3))} for c in "bc"]
    polar = {"xlabel": "angle (degrees)", "ylabel": "radius (pixels)",
             "extent": (0.0, 360.0, 8.0, 0.0)}
    steps += [{"title": f"({c})", "image": rng.random((8, 36, 3)), **polar} for c in "de"]
    steps += [{"title": "(f)", "image": rng.random((16, 16, 3))}]
    plots.plot_pipeline(steps, tmp_path / "f8.png", bank_kernels=[gaussian_kernel(1.0)] * 2,
                        bank_positions=["r = 0", "r = 1"], pixel_pitch=0.018, white=1.0,
                        title="t")
    (fig, renderer), = drawn
    panels = [ax for ax in fig.axes if ax.get_title() in {f"({c})" for c in "bcdef"}]
    boxes = {ax.get_title(): ax.get_window_extent(renderer) for ax in panels}
    order = sorted(boxes, key=lambda t: (-round(boxes[t].y1), boxes[t].x0))
    assert order == ["(b)", "(c)", "(d)", "(e)", "(f)"]


def test_table1_refuses_banks_that_are_not_its_own(scenes_dir):
    """Banks passed to Table 1 are checked against its ranges, radii and depths: banks in
    the wrong order (another range's) or with other radii are refused, naming the range."""
    from mitsweep.tracer.table1 import default_ranges, table1, table1_banks

    setup = load_setup(scenes_dir / "sphere.toml")
    ranges = default_ranges(setup)[:2]
    banks = table1_banks(setup, ranges=ranges, n_radii=2, rays=2_000, kernel_size=15)
    kw = dict(ranges=ranges, n_radii=2, rays=2_000, kernel_size=15)
    assert len(table1(setup, banks=banks, **kw)["rows"]) == 2
    lo, hi = ranges[0]
    with pytest.raises(ValueError, match=rf"the bank for {lo:g}-{hi:g} mm is not Table 1's"):
        table1(setup, banks=banks[::-1], **kw)
    with pytest.raises(ValueError, match="not Table 1's"):
        table1(setup, banks=banks, **{**kw, "n_radii": 3})
    with pytest.raises(ValueError, match=r"one per sweep range \(2\), got 1"):
        table1(setup, banks=banks[:1], **kw)
