"""Every figure of the paper for its three setups, in one call (``mitsweep figures``).

Per setup (:data:`PAPER_SETUPS`, the ``scenes/*.toml`` of the paper's mirrors), what
each figure needs is computed once and shared:

- the optimal sweep range (Eq. 4–9) → Fig. 6 (focal surfaces);
- PSFs at five focal planes of the sweep for five points across the mirror → Fig. 3;
- IPSFs of those points at 50 cm, 5 m and 50 m over the optimal sweep → Fig. 4;
- Table 1's radial banks (one per sweep range, at its depths 0.5, 1, 5 and 10 m) → both
  Table 1 and Fig. 5, whose centre and periphery are those banks' first and last radii
  (a tilted mirror has no Table 1: its Fig. 5 IPSFs are traced for it);
- one synthetic dataset (:func:`mitsweep.pipeline.build_dataset`, the demo's
  machinery: renders, IPSF bank, 50-lux noise, Wiener EDOF images), kept under
  ``data/<setup>[_quick]/`` → Figs. 8, 9 and 10;
- Table 1 (:func:`mitsweep.tracer.table1.table1` of those banks, untilted mirrors only)
  → ``table1_*``.

Every figure is written as PNG and PDF (:data:`FORMATS`); ``figures.json`` records the
setups, the quality, the sweep ranges, the files and the timings.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..config import Setup
from ..deprecation import renamed_fields
from ..optics.sweep import SweepRange

__all__ = ["PAPER_SETUPS", "FORMATS", "FigureQuality", "QUICK", "FULL", "figure_files",
           "data_dir", "field_points", "make_figures"]

logger = logging.getLogger(__name__)

#: The paper's setups, by the stem of their ``scenes/*.toml``.
PAPER_SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")
#: Formats of every figure.
FORMATS = ("png", "pdf")
#: Depths of Fig. 4, mm (the paper's 50 cm, 5 m and 50 m; Fig. 5 draws Table 1's depths).
SECTION_DEPTHS_MM = (500.0, 5000.0, 50000.0)
#: Depth of the Fig. 3 PSFs, mm (the paper's world points 50 cm from the mirror).
PSF_DEPTH_MM = 500.0
#: Light level of Fig. 10, lux (the paper's "about 50 lux").
FIG10_LUX = 50.0
#: Points across the mirror (Figs. 3, 4) and focal planes (Fig. 3).
N_POINTS = 5
N_PLANES = 5
#: The outermost point sits this fraction of the way to the edge of the field of view
#: (at the very edge, part of its IPSF falls off the mirror).
EDGE_FRACTION = 0.94


@dataclass(frozen=True, kw_only=True)
class FigureQuality:
    """How much work each figure gets.

    Attributes
    ----------
    name : str
        The quality's name (``"quick"``, ``"full"``): the suffix of the dataset's
        folder under ``data/`` (none for :data:`FULL`).
    render_scale : int
        Renders at 1/scale of the setup's resolution with scale × its pixel pitch (the
        same field of view); an integer >= 1.
    spp : dict
        Samples per pixel of each render mode (``pinhole``, ``focused``, ``sweep``,
        ``stopped``).
    psf_rays, ipsf_rays : int
        Rays per PSF (Fig. 3) and per IPSF (Figs. 4, 5), >= 1.
    bank_rays : int or None
        Rays per IPSF of the deconvolution bank (None: the tracer's default).
    table1_rays, table1_radii : int
        Rays per IPSF and radii of Table 1's banks, >= 1.
    """

    name: str
    render_scale: int
    spp: dict = field(default_factory=dict)
    psf_rays: int
    ipsf_rays: int
    bank_rays: int | None
    table1_rays: int
    table1_radii: int

    def __post_init__(self):
        if not (isinstance(self.render_scale, int) and self.render_scale >= 1):
            raise ValueError(f"render_scale: must be an integer >= 1, got {self.render_scale!r}")
        for key in ("psf_rays", "ipsf_rays", "table1_rays", "table1_radii"):
            if not getattr(self, key) >= 1:
                raise ValueError(f"{key}: must be >= 1, got {getattr(self, key)!r}")


#: Minutes on a laptop: 256 px renders of the 512 px setups, few rays.
QUICK = FigureQuality(name="quick", render_scale=2,
                      spp={"pinhole": 16, "focused": 16, "sweep": 64, "stopped": 32},
                      psf_rays=30_000, ipsf_rays=30_000, bank_rays=30_000,
                      table1_rays=20_000, table1_radii=5)
#: The gallery: full-resolution renders at the demo's samples per pixel
#: (mitsweep.cli.demo.DEMO_SPP, chosen there), the tracer's default bank.
FULL = FigureQuality(name="full", render_scale=1,
                     spp={"pinhole": 64, "focused": 64, "sweep": 512, "stopped": 144},
                     psf_rays=1_000_000, ipsf_rays=1_000_000, bank_rays=None,
                     table1_rays=1_000_000, table1_radii=19)


def figure_files(setup: Setup) -> list[str]:
    """The files :func:`make_figures` writes for ``setup``.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        One of the setups drawn (its ``name`` is the files' suffix).

    Returns
    -------
    list of str
        Names relative to the output directory: ``fig{3,4,5,6,8,9,10}_<name>`` in each
        of :data:`FORMATS` and, for an untilted mirror, ``table1_<name>`` (chart as PNG
        and PDF, table as Markdown and JSON).
    """
    names = [f"{fig}_{setup.name}.{fmt}" for fig in ("fig3", "fig4", "fig5", "fig6", "fig8",
                                                      "fig9", "fig10") for fmt in FORMATS]
    if setup.mirror.is_symmetric:
        names += [f"table1_{setup.name}.{fmt}" for fmt in (*FORMATS, "md", "json")]
    return names


def data_dir(out: Path, setup: Setup, quality: FigureQuality) -> Path:
    """Where the dataset behind Figs. 8–10 lives (resumed by a rerun).

    Parameters
    ----------
    out : Path
        The figures' output directory.
    setup : mitsweep.config.Setup
        The setup drawn.
    quality : FigureQuality
        The run's quality; any but :data:`FULL` adds its name to the folder's.

    Returns
    -------
    Path
        ``out/data/<setup>`` (``out/data/<setup>_<quality>`` below full quality).
    """
    return Path(out) / "data" / (setup.name + ("" if quality is FULL else f"_{quality.name}"))


def _paths(out: Path, stem: str) -> list[Path]:
    return [out / f"{stem}.{fmt}" for fmt in FORMATS]


# -- geometry ---------------------------------------------------------------------------

@renamed_fields(x_mm="x")
@dataclass(frozen=True)
class FieldPoint:
    """A point of the mirror in its meridional plane and its chief-ray image at a sensor
    distance.

    Attributes
    ----------
    x : float
        The point's coordinate along the meridional plane, mm (0: the vertex, or the
        sphere's pole). Formerly ``x_mm`` (still accepted and readable, with a
        warning).
    u, v : float
        Its chief ray's image on the sensor, upright, mm.
    """

    x: float
    u: float
    v: float

    def label(self) -> str:
        """The point as a figure labels it: ``x = 12.3 mm``."""
        return f"x = {self.x:.1f} mm" if self.x else "x = 0 mm"


def field_points(setup: Setup, sweep: SweepRange, sensor_distance: float, n: int = N_POINTS,
                 xs: ArrayLike | None = None) -> list[FieldPoint]:
    """Points across the mirror in the meridional plane and their images.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror and camera.
    sweep : mitsweep.optics.sweep.SweepRange
        The sweep whose field of view the points span (its ``rho_start``,
        ``rho_end``).
    sensor_distance : float
        The sensor distance the points are imaged at, mm.
    n : int
        Points, when ``xs`` is None: from the mirror's centre to
        :data:`EDGE_FRACTION` of the way to the edge of the field of view (untilted),
        or from one edge through the vertex to the other (tilted).
    xs : array_like, optional
        Mirror coordinates of the points instead, mm.

    Returns
    -------
    list of FieldPoint
        In order of ``x``.
    """
    from ..optics import chief_ray, image_point, placement_of

    if xs is None:
        if setup.mirror.is_symmetric:
            xs = np.linspace(0.0, EDGE_FRACTION * sweep.rho_end, n)
        else:
            xs = np.linspace(EDGE_FRACTION * sweep.rho_start, EDGE_FRACTION * sweep.rho_end, n)
            xs[np.argmin(np.abs(xs))] = 0.0   # the vertex is one of them
            xs = np.sort(xs)
    xs = np.asarray(xs, dtype=float)
    placement = placement_of(setup.mirror)
    ray = chief_ray(placement, placement.surface(xs, np.zeros_like(xs)))
    u, v = image_point(ray, sensor_distance)
    return [FieldPoint(float(x), float(a), float(b)) for x, a, b in zip(xs, u, v)]


def _radial_angle(point: FieldPoint, centre: FieldPoint) -> float:
    """Polar angle (rad, upright u/v) of the radial direction at ``point``: away from the
    image of the mirror's centre."""
    du, dv = point.u - centre.u, point.v - centre.v
    return math.atan2(dv, du) if math.hypot(du, dv) > 1e-9 else 0.0


def _range_setup(setup: Setup, focus_min: float, focus_max: float):
    """The setup swept over ``focus_min``–``focus_max`` and that sweep range (as
    :func:`mitsweep.tracer.table1.table1` makes its rows)."""
    from ..optics import optimal_sweep_range

    s = dataclasses.replace(setup, sweep=dataclasses.replace(setup.sweep, focus_min=focus_min,
                                                             focus_max=focus_max))
    return s, optimal_sweep_range(s)


# -- the computations, each once --------------------------------------------------------

class SetupFigures:
    """What the figures of one setup need, computed on first use and then shared; each
    figure a method of its name (:data:`FIGURES`), as :func:`make_figures` draws them.

    Parameters
    ----------
    setup : Setup
        The mirror and camera.
    quality : FigureQuality
        How much work each figure gets.
    out : Path
        The folder the figures and their data are written to.
    seed : int
        Seed of every trace and render.
    step : callable
        ``step(message)`` is told each long step (progress).
    """

    def __init__(self, setup: Setup, quality: FigureQuality, out: Path, *, seed: int,
                 step: Callable[[str], object]):
        from ..io.bank import bank_kernel_size
        from ..optics import optimal_sweep_range
        from ..optics.reference import reference_geometry

        self.setup, self.quality, self.out, self.seed, self.step = setup, quality, out, seed, step
        self.sweep = optimal_sweep_range(setup)
        self.ref = reference_geometry(setup, sweep=self.sweep).sensor_distance
        self.points = field_points(setup, self.sweep, self.ref)
        self.centre = next(p for p in self.points if p.x == 0.0)
        self.periphery = max(self.points, key=lambda p: abs(p.x))
        self.kernel_size = bank_kernel_size(setup.sensor.pixel_pitch)
        self._ipsfs: dict = {}
        self._data: dict | None = None
        self._banks: list | None = None
        self.timings: dict[str, float] = {}

    def _timed(self, key: str, fn, *args, **kw):
        t0 = time.perf_counter()
        value = fn(*args, **kw)
        self.timings[key] = self.timings.get(key, 0.0) + time.perf_counter() - t0
        return value

    def ipsf(self, x: float, depth: float, focus: tuple[float, float] | None = None):
        """The IPSF of the mirror point ``x`` (mm) at ``depth`` over the sweep ``focus``
        (default the optimal range), traced once.

        Parameters
        ----------
        x : float
            The mirror point, mm from the centre in the meridional plane.
        depth : float
            The point source's depth, mm.
        focus : (float, float), optional
            The sweep's focus range (near, far), mm (default the optimal sweep range).

        Returns
        -------
        (K, K) ndarray
            The IPSF, ``K`` the setup's bank kernel size; the same array on each call.
        """
        from ..optics.reference import reference_geometry
        from ..tracer import TraceSettings, integrated_psf

        focus = focus or (self.sweep.focus_min, self.sweep.focus_max)
        key = (round(x, 9), float(depth), round(focus[0], 9), round(focus[1], 9))
        if key not in self._ipsfs:
            setup, sweep = _range_setup(self.setup, *focus)
            ref = reference_geometry(setup, sweep=sweep).sensor_distance
            (p,) = field_points(setup, sweep, ref, xs=[x])
            settings = TraceSettings(rays=self.quality.ipsf_rays, kernel_size=self.kernel_size,
                                     seed=self.seed)
            kernel, _ = self._timed("ipsf_s", integrated_psf, setup, p.u, p.v, depth,
                                    settings=settings, sweep=sweep)
            self._ipsfs[key] = kernel
        return self._ipsfs[key]

    def sections(self, point: FieldPoint, depths, focus=None):
        """Radial and tangential cross-sections of the IPSFs of ``point`` at ``depths``
        (:func:`~mitsweep.tracer.metrics.cross_sections`), radial meaning away from the
        image of the mirror's centre.

        Parameters
        ----------
        point : FieldPoint
            The mirror point and its image.
        depths : iterable of float
            Depths of the point source, mm.
        focus : (float, float), optional
            The sweep's focus range, mm (default the optimal sweep range).

        Returns
        -------
        list of (x, radial, tangential)
            One per depth.
        """
        from ..tracer.metrics import cross_sections

        angle = _radial_angle(point, self.centre)
        return [cross_sections(self.ipsf(point.x, d, focus), angle) for d in depths]

    # -- the figures --

    def fig3(self):
        from ..optics.thinlens import image_distance
        from ..plots import plot_psf_planes
        from ..tracer import psf

        s = self.setup
        focus = np.linspace(self.sweep.focus_min, self.sweep.focus_max, N_PLANES)
        sensor = [float(image_distance(s.lens.focal_length, f)) for f in focus]
        K = 2 * self.kernel_size - 1   # off the sweep's middle, PSFs outgrow the IPSFs
        kernels = np.zeros((N_PLANES, len(self.points), K, K), np.float32)
        for i, d in enumerate(sensor):
            for j, p in enumerate(field_points(s, self.sweep, d, xs=[q.x for q in self.points])):
                kernels[i, j] = self._timed("psf_s", psf, s, p.u, p.v, PSF_DEPTH_MM, d,
                                            rays=self.quality.psf_rays, kernel_size=K,
                                            seed=self.seed)[0]
        plot_psf_planes(kernels, _paths(self.out, f"fig3_{s.name}"),
                        pixel_pitch=s.sensor.pixel_pitch, focus_distances=focus,
                        sensor_distances=sensor,
                        positions=[p.label() for p in self.points],
                        title=f"{s.name}: PSFs across the mirror for focal planes through the "
                              f"sweep (point sources {PSF_DEPTH_MM / 10:g} cm from the mirror)")

    def fig4(self):
        from ..plots import plot_ipsf_depths

        s = self.setup
        kernels = np.stack([np.stack([self.ipsf(p.x, d) for p in self.points])
                            for d in SECTION_DEPTHS_MM])
        sections = {f"centre, {self.centre.label()}": self.sections(self.centre, SECTION_DEPTHS_MM),
                    f"periphery, {self.periphery.label()}":
                        self.sections(self.periphery, SECTION_DEPTHS_MM)}
        plot_ipsf_depths(kernels, _paths(self.out, f"fig4_{s.name}"),
                         pixel_pitch=s.sensor.pixel_pitch, depths=SECTION_DEPTHS_MM,
                         positions=[p.label() for p in self.points], sections=sections,
                         title=f"{s.name} (sweep {self.sweep.focus_min:.0f}–"
                               f"{self.sweep.focus_max:.0f} mm)")

    def table1_banks(self) -> list:
        """Table 1's radial banks, one per :func:`~mitsweep.tracer.table1.default_ranges`
        range (untilted mirrors), traced once: Table 1 measures them and Fig. 5 draws
        their centre and periphery."""
        if self._banks is None:
            from ..tracer.table1 import table1_banks

            q = self.quality
            self._banks = self._timed("table1_banks_s", table1_banks, self.setup,
                                      n_radii=q.table1_radii, rays=q.table1_rays,
                                      seed=self.seed)
        return self._banks

    def fig5(self):
        from ..plots import plot_sweep_ranges
        from ..tracer.metrics import cross_sections
        from ..tracer.table1 import PAPER_DEPTHS_MM, default_ranges

        s = self.setup
        ranges = default_ranges(s)
        if s.mirror.is_symmetric:
            # Table 1's IPSFs: the centre (radius 0) and periphery (the FOV's edge) of
            # each range's bank, cut along the +u axis (radial = u).
            banks = self.table1_banks()
            sections = [{place: [cross_sections(b.kernels[j, i], 0.0)
                                 for j in range(len(PAPER_DEPTHS_MM))]
                         for place, i in (("centre", 0), ("periphery", -1))} for b in banks]
            periphery = f"the field's edge, r = {banks[0].radii[-1]:.2f} mm on the sensor"
        else:
            sections = [{"centre": self.sections(self.centre, PAPER_DEPTHS_MM, r),
                         "periphery": self.sections(self.periphery, PAPER_DEPTHS_MM, r)}
                        for r in ranges]
            periphery = self.periphery.label()
        order = np.argsort([hi - lo for lo, hi in ranges], kind="stable")
        plot_sweep_ranges([sections[i] for i in order], _paths(self.out, f"fig5_{s.name}"),
                          pixel_pitch=s.sensor.pixel_pitch, ranges=[ranges[i] for i in order],
                          depths=PAPER_DEPTHS_MM,
                          optimal=(self.sweep.focus_min, self.sweep.focus_max),
                          title=f"{s.name} (periphery: {periphery})")

    def fig6(self):
        from ..plots import plot_focal_surfaces

        plot_focal_surfaces(self.setup, self.sweep, _paths(self.out, f"fig6_{self.setup.name}"))

    def table1(self):
        from ..io import write_text_atomic
        from ..plots import plot_table1
        from ..tracer.table1 import table1

        s = self.setup
        result = self._timed("table1_s", table1, s, n_radii=self.quality.table1_radii,
                             rays=self.quality.table1_rays, seed=self.seed,
                             banks=self.table1_banks())
        stem = f"table1_{s.name}"
        optimal = (self.sweep.focus_min, self.sweep.focus_max)
        plot_table1(result, _paths(self.out, stem), optimal=optimal)
        write_text_atomic(self.out / f"{stem}.json",
                          json.dumps(result, indent=2, default=str) + "\n")
        write_text_atomic(self.out / f"{stem}.md", _table1_md(result, optimal))

    # -- the renders (Figs. 8-10) --

    def dataset(self) -> dict:
        """Build (or resume) the dataset of Figs. 8–10; its images in memory."""
        if self._data is not None:
            return self._data
        from ..io.bank import load_bank
        from . import DatasetOptions, build_dataset
        from .tasks import read_rgb, white_level

        q = self.quality
        s = self.setup
        if q.render_scale > 1:
            w, h = s.sensor.resolution
            s = dataclasses.replace(s, sensor=dataclasses.replace(
                s.sensor, resolution=(w // q.render_scale, h // q.render_scale),
                pixel_pitch=s.sensor.pixel_pitch * q.render_scale))
        opts = DatasetOptions(scenes=1, seed=self.seed, spp=dict(q.spp),
                              light_levels_lux=(FIG10_LUX,), bank_rays=q.bank_rays)
        where = data_dir(self.out, self.setup, q)
        self.step(f"{self.setup.name}: renders, bank and EDOF images in {where}")
        self._timed("dataset_s", build_dataset, s, where, opts, progress=False)
        scene = where / "scene_000"
        data: dict[str, Any] = {"setup": s, "bank": load_bank(where / "bank.npz")}
        for name in ("pinhole", "focused", "sweep", "edof", f"stopped_{FIG10_LUX:g}lux",
                     f"edof_{FIG10_LUX:g}lux"):
            image, chans, _ = read_rgb(scene / f"{name}.exr")
            data[name] = image
            if name == "pinhole":
                data["mask"] = chans["mask.Y"]
                data["depth"] = chans["depth.Z"]
        data["white"] = white_level(data["pinhole"], data["mask"])
        self._data = data
        return data

    def fig8(self):
        from ..deconv import polar_grid, to_polar
        from ..plots import plot_pipeline
        from ..render import mirror_image_bbox

        d = self.dataset()
        s, bank = d["setup"], d["bank"]
        kernels, positions = _bank_row(bank)
        bbox = mirror_image_bbox(s, bank.reference_sensor_distance, margin_px=2)
        steps = [{"title": "(b) the scene (pinhole ground truth)", "image": d["pinhole"],
                  "window": bbox},
                 {"title": "(c) the focal-sweep image", "image": d["sweep"], "window": bbox},
                 {"title": "(f) the EDOF image (Wiener)", "image": d["edof"], "window": bbox}]
        if bank.kind == "radial":
            # The paper's steps (b)-(e): deconvolution in polar coordinates, each line
            # (radius) with its own IPSF.
            grid = polar_grid(d["sweep"].shape, r_max=0.5 * max(bbox[2], bbox[3]))
            step = grid.radial_step
            extent = (0.0, 360.0, (grid.n_radii - grid.n_inner) * step, -grid.n_inner * step)
            polar = {"xlabel": "angle (degrees)", "ylabel": "radius (pixels)", "extent": extent}
            steps.insert(2, {"title": "(d) the sweep image in polar coordinates",
                             "image": to_polar(d["sweep"], grid), **polar})
            steps.insert(3, {"title": "(e) deconvolved line by line (polar)",
                             "image": to_polar(d["edof"], grid), **polar})
            steps[-1]["title"] = "(f) back to Cartesian: the EDOF image"
        else:
            steps[-1]["title"] = "(d) the EDOF image (spatially varying Wiener)"
        plot_pipeline(steps, _paths(self.out, f"fig8_{self.setup.name}"), bank_kernels=kernels,
                      bank_positions=positions, pixel_pitch=bank.pixel_pitch, white=d["white"],
                      title=f"{self.setup.name}: the processing pipeline "
                            f"({s.sensor.resolution[0]}×{s.sensor.resolution[1]} px render)")

    def _insets(self, stem: str, images, title: str):
        from ..plots import plot_insets
        from ..render import mirror_image_bbox

        d = self.dataset()
        regions = inset_regions(d["mask"], d["pinhole"])
        labels = [_distance_label(d["depth"], d["mask"], r) for r in regions]
        crop = mirror_image_bbox(d["setup"], d["bank"].reference_sensor_distance, margin_px=2)
        plot_insets(images, _paths(self.out, stem), regions=regions, labels=labels,
                    white=d["white"], crop=crop, title=title)

    def fig9(self):
        d = self.dataset()
        self._insets(f"fig9_{self.setup.name}",
                     [("normal camera, focused at the mirror's centre", d["focused"]),
                      ("EDOF: focal sweep, deconvolved", d["edof"])],
                     f"{self.setup.name}: normal camera against EDOF (distances of the "
                     f"magnified regions from the mirror)")

    def fig10(self):
        from ..deconv import paper_fig10_settings
        from .tasks import NOISE_PIXEL_MM

        d = self.dataset()
        lux = f"{FIG10_LUX:g}lux"
        cam = {k: f"F{n.f_number:g}, {n.exposure_s:g} s, ISO {n.iso:g}"
               for k, n in paper_fig10_settings(NOISE_PIXEL_MM, FIG10_LUX).items()}
        self._insets(f"fig10_{self.setup.name}",
                     [(f"EDOF ({cam['sweep']})", d[f"edof_{lux}"]),
                      (f"stopped down ({cam['stopped']})", d[f"stopped_{lux}"])],
                     f"{self.setup.name}: EDOF against a stopped-down aperture at "
                     f"{FIG10_LUX:g} lux")


def _bank_row(bank, n: int = 7):
    """Up to ``n`` IPSFs of a bank at its first depth, evenly spaced over its points
    (a grid bank's valid ones), and their positions."""
    kernels = np.asarray(bank.kernels[0])
    valid = np.asarray(bank.metadata.get("valid", np.ones(len(kernels), bool)), bool)
    idx = np.flatnonzero(valid)
    if bank.kind == "grid":
        # The row of cells through the mirror's image centre reads like the radial bank.
        v = np.asarray(bank.points_uv)[idx, 1]
        idx = idx[np.abs(v - np.median(v)) <= np.ptp(v) / 8 + 1e-12] if len(idx) else idx
    pick = idx[np.unique(np.linspace(0, len(idx) - 1, min(n, len(idx))).round().astype(int))]
    if bank.kind == "radial":
        labels = [f"r = {bank.radii[i]:.2f} mm" for i in pick]
    else:
        labels = [f"({bank.points_uv[i][0]:.1f}, {bank.points_uv[i][1]:.1f}) mm" for i in pick]
    return kernels[pick], labels


def inset_regions(mask: np.ndarray, guide: np.ndarray, zones=((0.15, 0.5), (0.75, 0.97)),
                  size_fraction: float = 0.2) -> list[tuple[int, int, int]]:
    """Squares (row, col, side) inside the mirror's image to magnify, one per zone.

    A zone is a range of distances from the centre of the mirror's image, as fractions
    of its radius (the mask's equivalent-disc radius about its centroid); in each, the
    square wholly inside ``mask`` with the most detail in ``guide`` (mean gradient
    magnitude of its luminance smoothed over 1.5 px, e.g. the ground truth's), so that
    the insets show what blur removes rather than a flat wall.

    Parameters
    ----------
    mask : (H, W) ndarray
        The mirror's mask (inside where > 0.5).
    guide : (H, W) or (H, W, C) ndarray
        The image whose detail chooses the squares (its mean over channels).
    zones : sequence of (float, float)
        Per square, the range of its centre's distance from the mirror image's centre,
        as fractions of its radius; when no square fits in a zone, one anywhere inside
        the mask.
    size_fraction : float
        The squares' side as a fraction of the mirror image's radius (at least 8 px).

    Returns
    -------
    list of (int, int, int)
        Per zone, the square's top row, left column and side, px; no two squares
        within two sides of each other where the mask leaves room.

    Raises
    ------
    ValueError
        An empty mask, or one that holds no such square.
    """
    inside = mask > 0.5
    rows, cols = np.nonzero(inside)
    if len(rows) == 0:
        raise ValueError("the mirror's mask is empty: no region to magnify")
    cy, cx = rows.mean(), cols.mean()
    radius = math.sqrt(len(rows) / math.pi)
    side = max(int(round(size_fraction * radius)), 8)
    from scipy.ndimage import gaussian_filter

    g = np.asarray(guide, dtype=np.float64)
    lum = g.mean(axis=-1) if g.ndim == 3 else g
    # Structure, not pixel-scale texture or render noise: the gradient at 1.5 px scale.
    gy, gx = np.gradient(gaussian_filter(lum, 1.5))
    detail = np.hypot(gx, gy) * inside
    # Sums over every side × side square, from the integral images.
    def box_sums(a):
        c = np.pad(a, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
        return c[side:, side:] - c[:-side, side:] - c[side:, :-side] + c[:-side, :-side]
    full = box_sums(inside.astype(np.float64)) >= side * side - 0.5
    score = box_sums(detail)
    r0, c0 = np.mgrid[:score.shape[0], :score.shape[1]]
    dist = np.hypot(r0 + side / 2 - cy, c0 + side / 2 - cx) / radius
    out: list[tuple[int, int, int]] = []
    for lo, hi in zones:
        # Apart from the squares already chosen (else both may land on one chart).
        apart = np.ones_like(full)
        for r, c, _ in out:
            apart &= (np.abs(r0 - r) >= 2 * side) | (np.abs(c0 - c) >= 2 * side)
        ok = full & apart & (dist >= lo) & (dist <= hi)
        if not ok.any():
            ok = full & apart
        if not ok.any():
            ok = full
        if not ok.any():
            raise ValueError(f"the mirror's image holds no {side} px square to magnify")
        top, left = np.unravel_index(np.argmax(np.where(ok, score, -np.inf)), score.shape)
        out.append((int(top), int(left), side))
    return out


def _distance_label(depth: np.ndarray, mask: np.ndarray, region) -> str:
    r, c, s = region
    d = depth[r:r + s, c:c + s][mask[r:r + s, c:c + s] > 0.5]
    d = d[np.isfinite(d) & (d > 0)]
    if not len(d):
        return "distance unknown"
    m = float(np.median(d))
    return f"≈ {m / 10:.0f} cm from the mirror" if m < 1000 else f"≈ {m / 1000:.1f} m from the mirror"


def _table1_md(result: dict, optimal: tuple[float, float] | None = None) -> str:
    lines = [f"# Table 1 — {result['setup']}", "",
             f"V_avg (Eq. 3) and mean kurtosis (Gaussian = 3) over depths "
             f"{', '.join(f'{d / 1000:g}' for d in result['depths_mm'])} m; "
             f"{result['rays_per_ipsf']} rays per IPSF, {result['n_radii']} radii.", "",
             "| sweep range (mm) | V_avg | centre tangential | centre radial | "
             "periphery tangential | periphery radial |", "|---|---|---|---|---|---|"]
    for r in result["rows"]:
        k = r["kurtosis"]
        mark = (" (optimal)" if optimal is not None
                and np.allclose((r["focus_min_mm"], r["focus_max_mm"]), optimal) else "")
        lines.append(f"| {r['focus_min_mm']:.1f}–{r['focus_max_mm']:.1f}{mark} | "
                     f"{r['v_avg']:.3g} | "
                     f"{k['center']['tangential']:.2f} | {k['center']['radial']:.2f} | "
                     f"{k['periphery']['tangential']:.2f} | {k['periphery']['radial']:.2f} |")
    c = result["conventional"]
    lines += [f"| conventional camera (focused at {c['focus_distance_mm']:.0f} mm) | "
              f"{c['v_avg']:.3g} | | | | |", ""]
    return "\n".join(lines)


#: Figure order; each name is a method of :class:`SetupFigures`.
FIGURES = ("fig6", "fig3", "fig4", "fig5", "table1", "fig8", "fig9", "fig10")


def make_figures(setups: Sequence[Setup], out: str | Path, *, quality: FigureQuality = FULL,
                 seed: int = 0, step: Callable[[str], object] | None = None) -> dict:
    """Write every figure of the paper for each setup into ``out``.

    Parameters
    ----------
    setups : sequence of mitsweep.config.Setup
        Each with a distinct ``name`` (the files' suffix).
    out : path
        Created if needed. Existing files are overwritten (the caller decides whether
        that is allowed; the dataset under ``data/`` is resumed).
    quality : FigureQuality
        :data:`QUICK` or :data:`FULL` (default).
    seed : int
        Seed of the traces and renders.
    step : callable, optional
        Called with a line of progress before each figure.

    Returns
    -------
    dict
        The provenance written to ``figures.json``: files, sweep ranges, timings.
    """
    from .. import __version__
    from ..io import write_text_atomic

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = [s.name for s in setups]
    if len(set(names)) != len(names):
        raise ValueError(f"setups: each needs its own name (the files' suffix), got {names}")
    step = step or (lambda msg: logger.info("%s", msg))
    report: dict = {"version": __version__, "quality": dataclasses.asdict(quality),
                    "seed": seed, "setups": {}}
    t_all = time.perf_counter()
    for setup in setups:
        figs = SetupFigures(setup, quality, out, seed=seed, step=step)
        for name in FIGURES:
            if name == "table1" and not setup.mirror.is_symmetric:
                continue   # Table 1 measures a radial bank (tracer.table1)
            step(f"{setup.name}: {name}")
            t0 = time.perf_counter()
            getattr(figs, name)()
            figs.timings[f"{name}_s"] = time.perf_counter() - t0
        report["setups"][setup.name] = {"sweep_range": figs.sweep.as_dict(),
                                        "files": figure_files(setup),
                                        "timings": figs.timings}
    report["total_s"] = time.perf_counter() - t_all
    write_text_atomic(out / "figures.json", json.dumps(report, indent=2, default=str) + "\n")
    return report
