"""Numeric focus: where the traced PSF of a point is sharpest, and the traced sweep range.

Every traced ray lands at ``h(i) = A + B i`` on a sensor at distance ``i``. The
intensity-weighted spread of the spot along a unit image direction ``e`` is therefore a
quadratic in ``i``,

.. math:: σ_e^2(i) = e^T C_{AA} e + 2 i\\, e^T C_{AB} e + i^2 e^T C_{BB} e ,

(``C`` the weighted covariances of the ray hits), minimal at
``i_e = −e^T C_{AB} e / e^T C_{BB} e``: no search, no binning. The radial focus (``e``
along the image radius, sharp across the radius: the meridional focal image, D_m) and the
tangential focus (``e`` across it: the sagittal focal image, D_s) are compared with the
Coddington foci of :mod:`mitsweep.optics`; the two astigmatic line foci of an arbitrary
pencil (tilted mirrors off their tilt plane) are the extremes of ``i_e`` over ``e``, the
generalised eigenvalues of ``(−C_AB, C_BB)``.

With a small aperture (Coddington's infinitesimal pencil) the RMS foci converge to the
Coddington ones; :data:`PROBE_APERTURE_MM` is the default probe radius.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.linalg import eigh

from ..optics import object_distance, optimal_sweep_range
from ..optics.sweep import mirror_zone
from .kernel import trace_arrays
from .psf import fit_sampling_box
from .source import PointSource, source_from_mirror

__all__ = ["FocusResult", "numeric_focus", "TracedSweepRange", "traced_sweep_range",
           "PROBE_APERTURE_MM"]

log = logging.getLogger(__name__)

#: Aperture radius (mm) of the probe pencil used to locate focal images: small enough
#: that aberrations of the finite pencil shift the RMS focus by < 0.1 µm on the paper's
#: mirrors (measured in tests), large enough for float64 moments to be exact.
PROBE_APERTURE_MM = 0.1


@dataclass(frozen=True)
class FocusResult:
    """Sensor distances (mm) of sharpest focus of one point source, and their focus
    distances (mm, object side: the axial distance of the focal image from the lens)."""

    radial_sensor_mm: float
    tangential_sensor_mm: float
    line_foci_sensor_mm: tuple   # (min, max) over directions: the astigmatic line foci
    radial_focus_mm: float
    tangential_focus_mm: float
    line_foci_focus_mm: tuple
    rays_landed: int

    def as_dict(self) -> dict:
        return asdict(self)


def _moments(r: dict):
    ok = r["landed"]
    if ok.sum() < 16:
        raise ValueError("too few traced rays reach the sensor to locate the focus")
    w = r["weight"][ok]
    A = np.stack([r["Au"][ok], r["Av"][ok]], axis=1)
    B = np.stack([r["Bu"][ok], r["Bv"][ok]], axis=1)
    w = w / w.sum()
    A = A - w @ A
    B = B - w @ B
    c_ab = (A * w[:, None]).T @ B
    c_ab = 0.5 * (c_ab + c_ab.T)
    c_bb = (B * w[:, None]).T @ B
    return c_ab, c_bb, int(ok.sum())


def numeric_focus(setup, source: PointSource, *, rays: int = 1 << 16, seed: int = 0,
                  aperture_radius: float | None = PROBE_APERTURE_MM,
                  double: bool = True) -> FocusResult:
    """Traced foci of ``source`` (see the module docstring).

    Parameters
    ----------
    setup : mitsweep.config.Setup
    source : PointSource
        From :func:`mitsweep.tracer.source.source_from_image` or ``source_from_mirror``.
    rays : int
        Rays traced (float64 by default: the moments of a 0.1 mm pencil need it).
    aperture_radius : float or None
        Probe aperture radius, mm; None for the setup's lens aperture.
    """
    geom = source.geometry(setup, aperture_radius=aperture_radius)
    params, _ = fit_sampling_box(geom, seed=seed, double=double)
    r = trace_arrays(geom, params, int(rays), double=double)
    c_ab, c_bb, n = _moments(r)
    u, v = source.image_uv
    rad = math.hypot(u, v)
    e_r = np.array([u / rad, v / rad]) if rad > 1e-9 else np.array([1.0, 0.0])
    e_t = np.array([-e_r[1], e_r[0]])
    foc = lambda e: float(-(e @ c_ab @ e) / (e @ c_bb @ e))  # noqa: E731
    i_r, i_t = foc(e_r), foc(e_t)
    lines = eigh(-c_ab, c_bb, eigvals_only=True)
    f = setup.lens.focal_length
    to_focus = lambda i: float(object_distance(f, i)) if i > f else math.inf  # noqa: E731
    return FocusResult(
        radial_sensor_mm=i_r, tangential_sensor_mm=i_t,
        line_foci_sensor_mm=(float(lines.min()), float(lines.max())),
        radial_focus_mm=to_focus(i_r), tangential_focus_mm=to_focus(i_t),
        line_foci_focus_mm=(to_focus(float(lines.max())), to_focus(float(lines.min()))),
        rays_landed=n)


@dataclass(frozen=True)
class TracedSweepRange:
    """The sweep range found by tracing (focus distances, mm, object side).

    ``focus_min_mm``/``focus_max_mm`` cover the same field as the analytic range (the
    radius for untilted mirrors, the tilt plane for tilted ones); ``field_focus_*`` also
    cover the 2-D field of a tilted mirror (equal to the former when untilted).
    """

    focus_min_mm: float
    focus_max_mm: float
    field_focus_min_mm: float
    field_focus_max_mm: float
    points: int
    depths_mm: tuple
    aperture_radius_mm: float
    samples: list

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("samples")
        return d


def traced_sweep_range(setup, fov_deg: float | None = None, depth_min: float | None = None,
                       depth_max: float | None = None, *, n_points: int = 41,
                       n_field: int = 9, rays: int = 1 << 15,
                       aperture_radius: float | None = PROBE_APERTURE_MM) -> TracedSweepRange:
    """The optimal sweep range (paper Eq. 8–9) measured by tracing instead of Coddington.

    Point sources at ``n_points`` mirror points across the FOV's mirror zone (from
    :func:`mitsweep.optics.sweep.mirror_zone`, the same field definition as the analytic
    range) at the two end depths (the foci are monotonic in depth) are traced; the range
    is the min and max over them of the focus distances of the radial and tangential
    foci. For a tilted mirror the 2-D field (``n_field`` rows of mirror points off the
    tilt plane, within the rim and visible) is traced too, using the astigmatic line foci.

    Returns
    -------
    TracedSweepRange
    """
    sr = optimal_sweep_range(setup, fov_deg=fov_deg, depth_min=depth_min, depth_max=depth_max)
    zone = mirror_zone(setup, fov_deg)
    depths = tuple(sorted({sr.depth_min_mm, sr.depth_max_mm}))
    ref = sr.reference_sensor_distance
    # Stop short of the zone's far end by a hair: the Coddington range is evaluated there too.
    xs = np.linspace(zone.rho_start, zone.rho_end, int(n_points))
    samples = []
    lo = hi = None
    for depth in depths:
        for x in xs:
            src = source_from_mirror(setup, float(x), 0.0, depth, reference_sensor_distance=ref)
            res = numeric_focus(setup, src, rays=rays, aperture_radius=aperture_radius)
            vals = (res.radial_focus_mm, res.tangential_focus_mm)
            samples.append({"x_mm": float(x), "y_mm": 0.0, "depth_mm": depth,
                            "radial_focus_mm": vals[0], "tangential_focus_mm": vals[1]})
            lo = min(vals) if lo is None else min(lo, *vals)
            hi = max(vals) if hi is None else max(hi, *vals)
    f_lo, f_hi = lo, hi
    if not setup.mirror.is_symmetric and n_field > 1:
        rim = setup.mirror.rim_radius
        for depth in depths:
            for x in xs:
                ymax = math.sqrt(max(rim * rim - x * x, 0.0))
                for y in np.linspace(-ymax, ymax, int(n_field))[1:-1]:
                    try:
                        src = source_from_mirror(setup, float(x), float(y), depth,
                                                 reference_sensor_distance=ref)
                        res = numeric_focus(setup, src, rays=rays,
                                            aperture_radius=aperture_radius)
                    except ValueError:  # hidden or vignetted field point
                        continue
                    vals = res.line_foci_focus_mm
                    samples.append({"x_mm": float(x), "y_mm": float(y), "depth_mm": depth,
                                    "line_foci_focus_mm": vals})
                    f_lo, f_hi = min(f_lo, *vals), max(f_hi, *vals)
    return TracedSweepRange(
        focus_min_mm=float(lo), focus_max_mm=float(hi), field_focus_min_mm=float(f_lo),
        field_focus_max_mm=float(f_hi), points=len(samples), depths_mm=depths,
        aperture_radius_mm=float(setup.lens.aperture_radius if aperture_radius is None
                                 else aperture_radius),
        samples=samples)
