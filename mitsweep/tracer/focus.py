"""Numeric focus: where the traced pencil of a point focuses, and the traced sweep range.

Every traced ray lands at ``h(i) = A + B i`` on a sensor at distance ``i``. The
intensity-weighted spread of the spot along a unit image direction ``e`` is therefore a
quadratic in ``i``,

.. math:: σ_e^2(i) = e^T C_{AA} e + 2 i\\, e^T C_{AB} e + i^2 e^T C_{BB} e ,

(``C`` the weighted covariances of the ray hits, ``C_AB = E[A Bᵀ]``), minimal at
``i_e = −e^T C_{AB} e / e^T C_{BB} e``: no search, no binning. The radial focus (``e``
along the image radius, sharp across the radius: the meridional focal image, D_m) and the
tangential focus (``e`` across it: the sagittal focal image, D_s) are compared with the
Coddington foci of :mod:`mitsweep.optics`.

The two astigmatic *line foci* of an arbitrary pencil (tilted mirrors off their tilt
plane) are the sensor distances where the spot collapses to a line. To first order in the
ray's aperture coordinates ``a``, ``A = P a`` and ``B = Q a``, so the spot has rank one
where ``det(P + Q i) = 0``: at the eigenvalues of ``−Q⁻¹P``, which equal those of
``−C_AB C_BB⁻¹`` whatever the covariance of the sampled ``a`` (``C_AB`` not symmetrised).
They are *not* the extremes of ``i_e`` over ``e``: off a plane of symmetry the two focal
lines are not perpendicular on the sensor, and those extremes then depend on how the
pencil is sampled (measured on the tilted paraboloid's rim at (0, 28.25) mm, 10 m:
line foci 380.002 and 414.257 mm of focus distance for every seed; the extremes of
``i_e``, 378.13–378.22 and 416.45–416.56 mm, moved with the seed).

With a small aperture (Coddington's infinitesimal pencil) the foci converge to the
Coddington ones; :data:`PROBE_APERTURE_MM` is the default probe radius.

The traced sweep range (:func:`traced_sweep_range`) is searched over one of the fields of
:data:`FIELDS`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from ..config import SetupError
from ..optics import chief_ray, object_distance, optimal_sweep_range, placement_of
from ..optics.sweep import mirror_zone
from .kernel import trace_arrays
from .psf import fit_sampling_box
from .source import PointSource, source_from_mirror

__all__ = ["FocusResult", "numeric_focus", "TracedSweepRange", "traced_sweep_range",
           "PROBE_APERTURE_MM", "FIELDS", "FIELD_TOL_MM"]

logger = logging.getLogger(__name__)

#: Aperture radius (mm) of the probe pencil used to locate focal images: small enough
#: that aberrations of the finite pencil shift the RMS focus by < 0.1 µm on the paper's
#: mirrors (measured in tests), large enough for float64 moments to be exact.
PROBE_APERTURE_MM = 0.1

#: The fields a traced sweep range can cover (``traced_sweep_range(field=...)``,
#: ``mitsweep sweep-range --verify --field``). Mirror points are in the mirror's local
#: frame (x in the tilt plane, toward the far rim; y across it), mm.
FIELDS = {
    "plane": "the paper's field, the FOV's mirror zone of mitsweep.optics.sweep.mirror_zone: "
             "untilted, the disc from the axis out to where the reflected chief ray makes "
             "FOV/2 with the mirror axis (searched along a radius, by symmetry); tilted, "
             "the tilt-plane segment from the rim nearest the camera over which the "
             "reflected chief rays span the FOV",
    "mirror": "the whole mirror the lens sees, out to its rim: every local point with "
              "x^2 + y^2 <= rim_radius^2 (rim included), all of which must face the lens "
              "(n.r > 0); untilted, searched along a radius by symmetry; tilted, over the "
              "disc (the half y >= 0: the setup is symmetric under y -> -y)",
}

#: Convergence of the field search: local refinement stops when the bracket or simplex
#: is this small, in mm of mirror position and of focus distance (1 µm is the brief's
#: bound; the refinement goes ten times finer so that the bound is met with margin).
FIELD_TOL_MM = 1e-4


@dataclass(frozen=True)
class FocusResult:
    """Sensor distances (mm) of sharpest focus of one point source, and their focus
    distances (mm, object side: the axial distance of the focal image from the lens).

    ``line_foci_sensor_mm`` is (nearer, farther) sensor distance of the two line foci;
    ``line_foci_focus_mm`` their focus distances (nearer, farther) — the farther sensor
    distance focuses nearer.
    """

    radial_sensor_mm: float
    tangential_sensor_mm: float
    line_foci_sensor_mm: tuple
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
    c_ab = (A * w[:, None]).T @ B  # E[A Bᵀ]; the line foci need it unsymmetrised
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
    # Real for a pencil from a point (a normal congruence); where the two line foci
    # coincide (an axis point) rounding may leave a conjugate pair: its real part is it.
    lines = np.sort(np.linalg.eigvals(-c_ab @ np.linalg.inv(c_bb)).real)
    f = setup.lens.focal_length
    to_focus = lambda i: float(object_distance(f, i)) if i > f else math.inf  # noqa: E731
    return FocusResult(
        radial_sensor_mm=i_r, tangential_sensor_mm=i_t,
        line_foci_sensor_mm=(float(lines[0]), float(lines[1])),
        radial_focus_mm=to_focus(i_r), tangential_focus_mm=to_focus(i_t),
        line_foci_focus_mm=(to_focus(float(lines[1])), to_focus(float(lines[0]))),
        rays_landed=n)


@dataclass(frozen=True)
class TracedSweepRange:
    """The sweep range found by tracing over one field (focus distances, mm, object side).

    Attributes
    ----------
    field : str
        A key of :data:`FIELDS`.
    focus_min_mm, focus_max_mm : float
        The nearest and the farthest line focus over the field and the two end depths.
    min_at, max_at : dict
        Where they are reached: the mirror point ``x_mm``, ``y_mm`` (local frame),
        ``depth_mm``, ``on_rim``, and the chief-ray image ``image_uv_mm`` on a sensor at
        ``reference_sensor_mm`` (mid-sweep of the analytic range).
    convergence : dict
        ``{"min": [...], "max": [...]}``, the extreme after each stage of the search:
        ``stage`` ("grid", "refined"), ``evaluations`` (traced points so far), ``focus_mm``.
    points : int
        Point sources traced.
    """

    field: str
    focus_min_mm: float
    focus_max_mm: float
    min_at: dict
    max_at: dict
    convergence: dict
    points: int
    depths_mm: tuple
    aperture_radius_mm: float
    samples: list

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("samples")
        return d


class _LineFoci:
    """Line-focus distances (near, far), mm, of mirror points: memoised, since the
    refinements revisit points, and recorded as ``samples``."""

    def __init__(self, setup, reference_sensor_distance, *, rays, aperture_radius):
        self.setup = setup
        self.ref = reference_sensor_distance
        self.rays = rays
        self.aperture_radius = aperture_radius
        self.rim = setup.mirror.rim_radius
        self._memo = {}
        self.samples = []

    def point(self, r, theta):
        """Local (x, y) at polar (r, θ), kept within the rim despite rounding."""
        x, y = r * math.cos(theta), r * math.sin(theta)
        h = math.hypot(x, y)
        scale = min(1.0, self.rim / h) if h > 0 else 1.0
        return x * scale, y * scale

    def __call__(self, x: float, y: float, depth: float) -> tuple:
        key = (float(x), float(y), float(depth))
        if key not in self._memo:
            src = source_from_mirror(self.setup, key[0], key[1], key[2],
                                     reference_sensor_distance=self.ref)
            res = numeric_focus(self.setup, src, rays=self.rays,
                                aperture_radius=self.aperture_radius)
            self._memo[key] = (res.line_foci_focus_mm, src.image_uv)
            self.samples.append({"x_mm": key[0], "y_mm": key[1], "depth_mm": key[2],
                                 "line_foci_focus_mm": res.line_foci_focus_mm,
                                 "radial_focus_mm": res.radial_focus_mm,
                                 "tangential_focus_mm": res.tangential_focus_mm})
        return self._memo[key][0]

    @property
    def evaluations(self) -> int:
        return len(self._memo)

    def where(self, x, y, depth) -> dict:
        uv = self._memo[(float(x), float(y), float(depth))][1]
        return {"x_mm": float(x), "y_mm": float(y), "depth_mm": float(depth),
                "on_rim": bool(math.hypot(x, y) >= self.rim * (1 - 1e-12)),
                "image_uv_mm": [float(uv[0]), float(uv[1])],
                "reference_sensor_mm": float(self.ref)}


def _search_segment(foci: _LineFoci, xs, depths, which: int, sign: float):
    """Extreme of line focus ``which`` (0 near, 1 far) along the tilt-plane points ``xs``
    (ends included): the grid, then a bounded Brent search between the best point's
    neighbours (stops on a bracket of :data:`FIELD_TOL_MM`)."""
    best = min((sign * foci(x, 0.0, d)[which], j, d) for d in depths for j, x in enumerate(xs))
    v, j, depth = best
    history = [{"stage": "grid", "evaluations": foci.evaluations, "focus_mm": sign * v}]
    x_best = float(xs[j])
    lo, hi = float(xs[max(j - 1, 0)]), float(xs[min(j + 1, len(xs) - 1)])
    res = minimize_scalar(lambda x: sign * foci(x, 0.0, depth)[which],
                          bounds=(min(lo, hi), max(lo, hi)), method="bounded",
                          options={"xatol": FIELD_TOL_MM})
    if res.fun < v:
        x_best, v = float(res.x), float(res.fun)
    history.append({"stage": "refined", "evaluations": foci.evaluations, "focus_mm": sign * v})
    return sign * v, foci.where(x_best, 0.0, depth), history


def _polar_grid(rim: float, n_rings: int):
    """(r, θ) of the half disc y >= 0: rings ``r = rim k / n_rings`` (the last is the rim
    itself) with ``3k + 1`` angles from 0 to π on ring k; returns points and spacings."""
    pts = [(0.0, 0.0)]
    for k in range(1, n_rings + 1):
        r = rim * k / n_rings
        pts += [(r, math.pi * j / (3 * k)) for j in range(3 * k + 1)]
    return pts, rim / n_rings, math.pi / (3 * n_rings)


def _search_disc(foci: _LineFoci, rim, n_rings, depths, which: int, sign: float):
    """Extreme of line focus ``which`` over the half disc: the polar grid of
    :func:`_polar_grid`, then refinements from its best point and from its best rim point
    (an extreme of a smooth function on a disc is inside or on the rim): Nelder–Mead in
    (r, θ) inside, Brent along the rim; both stop at :data:`FIELD_TOL_MM`."""
    pts, dr, dth = _polar_grid(rim, n_rings)
    f = lambda r, th, d: sign * foci(*foci.point(r, th), d)[which]  # noqa: E731
    scored = [(f(r, th, d), r, th, d) for d in depths for r, th in pts]
    best = min(scored)
    best_rim = min(s for s in scored if s[1] == rim)
    history = [{"stage": "grid", "evaluations": foci.evaluations, "focus_mm": sign * best[0]}]
    found = [best, best_rim]
    for v, r, th, d in {best, best_rim}:
        if r == rim:
            res = minimize_scalar(lambda t, d=d: f(rim, t, d),
                                  bounds=(max(th - dth, 0.0), min(th + dth, math.pi)),
                                  method="bounded", options={"xatol": FIELD_TOL_MM / rim})
            found.append((float(res.fun), rim, float(res.x), d))
        else:
            p0 = np.array([r, th])
            simplex = np.array([p0, p0 + [0.5 * dr, 0.0],
                                p0 + [0.0, 0.5 * dth if th + 0.5 * dth <= math.pi else -0.5 * dth]])
            res = minimize(lambda p, d=d: f(p[0], p[1], d), p0, method="Nelder-Mead",
                           bounds=[(0.0, rim), (0.0, math.pi)],
                           options={"initial_simplex": simplex, "xatol": FIELD_TOL_MM,
                                    "fatol": FIELD_TOL_MM, "maxiter": 400})
            found.append((float(res.fun), float(res.x[0]), float(res.x[1]), d))
    v, r, th, d = min(found)
    history.append({"stage": "refined", "evaluations": foci.evaluations, "focus_mm": sign * v})
    x, y = foci.point(r, th)
    return sign * v, foci.where(x, y, d), history


def _check_whole_mirror_visible(setup) -> None:
    """Raise SetupError unless the lens sees every point of the mirror within the rim."""
    pl = placement_of(setup.mirror)
    rim = setup.mirror.rim_radius
    r = np.linspace(0.0, rim, 257)[:, None]
    th = np.linspace(0.0, 2.0 * math.pi, 721)[None, :]
    x, y = r * np.cos(th), r * np.sin(th)
    cos_i = chief_ray(pl, pl.surface(x, y)).cos_incidence
    if not np.all(cos_i > 0):
        j = np.unravel_index(np.argmin(cos_i), cos_i.shape)
        raise SetupError(
            f"field 'mirror': the lens does not see this mirror out to its rim "
            f"({rim:g} mm): it is hidden beyond grazing incidence, e.g. at local "
            f"(x, y) = ({x[j]:.2f}, {y[j]:.2f}) mm, and toward grazing incidence the "
            f"focal images run out toward the depth, so the field has no bounded focus "
            f"range; use field 'plane' (the FOV's zone; --field plane at the command line)")


def traced_sweep_range(setup, fov_deg: float | None = None, depth_min: float | None = None,
                       depth_max: float | None = None, *, field: str = "plane",
                       n_points: int = 41, n_rings: int = 6, rays: int = 1 << 15,
                       aperture_radius: float | None = PROBE_APERTURE_MM) -> TracedSweepRange:
    """The optimal sweep range (paper Eq. 8–9) measured by tracing instead of Coddington.

    Point sources at mirror points of ``field`` (a key of :data:`FIELDS`) at the two end
    depths (the foci are monotonic in depth) are traced; the range is the min and max
    over them of the two line foci (in a plane of symmetry: the radial and tangential
    foci, D_m and D_s). The search is deterministic: a grid that contains the field's
    boundary exactly, then a local refinement around the best grid points that stops at
    :data:`FIELD_TOL_MM`; ``convergence`` records both stages.

    Parameters
    ----------
    field : {"plane", "mirror"}
        See :data:`FIELDS`.
    n_points : int
        Grid points along a segment (the tilt-plane zone, or a radius when untilted).
    n_rings : int
        Rings of the polar grid over a tilted mirror's disc (field "mirror"); the last
        ring is the rim, and ring k carries 3k + 1 angles over the half disc.
    rays, aperture_radius :
        Per traced point; see :func:`numeric_focus`.

    Returns
    -------
    TracedSweepRange

    Raises
    ------
    ValueError
        For an unknown field; SetupError (a ValueError) for field "mirror" when part of
        the mirror within its rim faces away from the lens.
    """
    if field not in FIELDS:
        raise ValueError(f"field: must be one of {', '.join(FIELDS)}, got {field!r}")
    sr = optimal_sweep_range(setup, fov_deg=fov_deg, depth_min=depth_min, depth_max=depth_max)
    depths = tuple(sorted({sr.depth_min_mm, sr.depth_max_mm}))
    rim = setup.mirror.rim_radius
    tilted = not setup.mirror.is_symmetric
    if field == "mirror":
        _check_whole_mirror_visible(setup)
    foci = _LineFoci(setup, sr.reference_sensor_distance, rays=rays,
                     aperture_radius=aperture_radius)
    out = {}
    for key, which, sign in (("min", 0, 1.0), ("max", 1, -1.0)):
        if field == "mirror" and tilted:
            out[key] = _search_disc(foci, rim, int(n_rings), depths, which, sign)
        else:
            if field == "plane":
                zone = mirror_zone(setup, fov_deg)
                xs = np.linspace(zone.rho_start, zone.rho_end, int(n_points))
            else:
                xs = np.linspace(0.0, rim, int(n_points))
            out[key] = _search_segment(foci, xs, depths, which, sign)
    logger.info("traced sweep range over field %s: %.4f .. %.4f mm (%d points)", field,
                out["min"][0], out["max"][0], foci.evaluations)
    return TracedSweepRange(
        field=field, focus_min_mm=float(out["min"][0]), focus_max_mm=float(out["max"][0]),
        min_at=out["min"][1], max_at=out["max"][1],
        convergence={"min": out["min"][2], "max": out["max"][2]},
        points=foci.evaluations, depths_mm=depths,
        aperture_radius_mm=float(setup.lens.aperture_radius if aperture_radius is None
                                 else aperture_radius),
        samples=foci.samples)
