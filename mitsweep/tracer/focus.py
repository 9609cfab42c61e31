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

from ..config import Setup, SetupError
from ..deprecation import renamed_fields
from ..optics import chief_ray, object_distance, optimal_sweep_range, placement_of
from ..optics.sweep import mirror_zone
from .kernel import trace_arrays
from .ipsf import fit_sampling_box
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
    "fov": "the FOV in 2-D: every mirror point within the rim whose world-bound reflected "
           "chief ray lies within FOV/2 of the FOV's central direction, which is the "
           "mirror axis when untilted (the disc of 'plane') and, tilted, the bisector of "
           "the tilt-plane fan of 'plane' (so the field meets the tilt plane in exactly "
           "the paper's zone); tilted, searched over the half y >= 0 in polar "
           "coordinates about the bisector's mirror point, its boundary included",
}

#: Convergence of the field search: local refinement stops when the bracket or simplex
#: is this small, in mm of mirror position and of focus distance: ten times finer than
#: the 1 µm to which the reported extremes are meant to be converged.
FIELD_TOL_MM = 1e-4


#: FocusResult's fields as :meth:`FocusResult.as_dict` writes them: the keys of earlier
#: versions (the fields were renamed to the unit rule, the files keep their keys).
_FOCUS_KEYS = {"radial_sensor": "radial_sensor_mm", "tangential_sensor": "tangential_sensor_mm",
               "line_foci_sensor": "line_foci_sensor_mm", "radial_focus": "radial_focus_mm",
               "tangential_focus": "tangential_focus_mm", "line_foci_focus": "line_foci_focus_mm"}


@renamed_fields(**{old: new for new, old in _FOCUS_KEYS.items()})
@dataclass(frozen=True)
class FocusResult:
    """Sensor distances (mm) of sharpest focus of one point source, and their focus
    distances (mm, object side: the axial distance of the focal image from the lens).

    ``line_foci_sensor`` is (nearer, farther) sensor distance of the two line foci;
    ``line_foci_focus`` their focus distances (nearer, farther) — the farther sensor
    distance focuses nearer. The former names (``radial_sensor_mm``, ...) read on with a
    DeprecationWarning, and :meth:`as_dict` keeps them as keys.

    Attributes
    ----------
    radial_sensor, tangential_sensor : float
        Sensor distance of least spread along / across the image radius, mm.
    line_foci_sensor : (float, float)
        Sensor distances of the two line foci, mm, nearer first.
    radial_focus, tangential_focus : float
        Focus distances of the radial and tangential foci, mm (inf where the sensor
        distance is not beyond the focal length).
    line_foci_focus : (float, float)
        Focus distances of the line foci, mm, nearer first.
    rays_landed : int
        Traced rays that reached the sensor.
    """

    radial_sensor: float
    tangential_sensor: float
    line_foci_sensor: tuple
    radial_focus: float
    tangential_focus: float
    line_foci_focus: tuple
    rays_landed: int

    def as_dict(self) -> dict:
        """The fields under the keys earlier versions wrote (``radial_sensor_mm``, ...)."""
        return {_FOCUS_KEYS.get(k, k): v for k, v in asdict(self).items()}


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


def numeric_focus(setup: Setup, source: PointSource, *, rays: int = 1 << 16, seed: int = 0,
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
    foc = lambda e: float(-(e @ c_ab @ e) / (e @ c_bb @ e))
    i_r, i_t = foc(e_r), foc(e_t)
    # Real for a pencil from a point (a normal congruence); where the two line foci
    # coincide (an axis point) rounding may leave a conjugate pair: its real part is it.
    lines = np.sort(np.linalg.eigvals(-c_ab @ np.linalg.inv(c_bb)).real)
    f = setup.lens.focal_length
    to_focus = lambda i: float(object_distance(f, i)) if i > f else math.inf
    return FocusResult(
        radial_sensor=i_r, tangential_sensor=i_t,
        line_foci_sensor=(float(lines[0]), float(lines[1])),
        radial_focus=to_focus(i_r), tangential_focus=to_focus(i_t),
        line_foci_focus=(to_focus(float(lines[1])), to_focus(float(lines[0]))),
        rays_landed=n)


@renamed_fields(focus_min_mm="focus_min", focus_max_mm="focus_max", depths_mm="depths",
                aperture_radius_mm="aperture_radius")
@dataclass(frozen=True)
class TracedSweepRange:
    """The sweep range found by tracing over one field (focus distances, mm, object side).

    Attributes
    ----------
    field : str
        A key of :data:`FIELDS`.
    focus_min, focus_max : float
        The nearest and the farthest line focus over the field and the two end depths,
        mm (named as in :class:`~mitsweep.optics.SweepRange`).
    min_at, max_at : dict
        Where they are reached: the mirror point ``x_mm``, ``y_mm`` (local frame),
        ``depth_mm``, ``on_boundary`` (of the field), ``on_rim``, and the chief-ray image
        ``image_uv_mm`` on a sensor at ``reference_sensor_mm`` (mid-sweep of the
        analytic range).
    convergence : dict
        ``{"min": [...], "max": [...]}``, the extreme after each stage of the search:
        ``stage`` ("grid", "refined"), ``evaluations`` (traced points so far), ``focus_mm``.
    points : int
        Point sources traced.
    depths : (float, float) or (float,)
        The end depths searched, mm, nearer first (one where they coincide).
    aperture_radius : float
        Radius of the traced pencils' aperture, mm.
    samples : list of dict
        Every traced point: the mirror point, depth and foci (keys ``x_mm``, ``y_mm``,
        ``depth_mm``, ``line_foci_focus_mm``, ``radial_focus_mm``,
        ``tangential_focus_mm``); not in :meth:`as_dict`.

    The former names ``focus_min_mm``, ``focus_max_mm``, ``depths_mm`` and
    ``aperture_radius_mm`` read on with a DeprecationWarning; :meth:`as_dict` keeps them
    as keys.
    """

    field: str
    focus_min: float
    focus_max: float
    min_at: dict
    max_at: dict
    convergence: dict
    points: int
    depths: tuple
    aperture_radius: float
    samples: list

    def as_dict(self) -> dict:
        """The fields but ``samples``, under the keys earlier versions wrote
        (``focus_min_mm``, ``focus_max_mm``, ``depths_mm``, ``aperture_radius_mm``)."""
        d = asdict(self)
        d.pop("samples")
        for name in ("focus_min", "focus_max", "depths", "aperture_radius"):
            d[f"{name}_mm"] = d.pop(name)
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

    def __call__(self, x: float, y: float, depth: float) -> tuple:
        key = (float(x), float(y), float(depth))
        if key not in self._memo:
            src = source_from_mirror(self.setup, key[0], key[1], key[2],
                                     reference_sensor_distance=self.ref)
            res = numeric_focus(self.setup, src, rays=self.rays,
                                aperture_radius=self.aperture_radius)
            self._memo[key] = (res.line_foci_focus, src.image_uv)
            self.samples.append({"x_mm": key[0], "y_mm": key[1], "depth_mm": key[2],
                                 "line_foci_focus_mm": res.line_foci_focus,
                                 "radial_focus_mm": res.radial_focus,
                                 "tangential_focus_mm": res.tangential_focus})
        return self._memo[key][0]

    @property
    def evaluations(self) -> int:
        return len(self._memo)

    def where(self, x, y, depth, *, on_boundary: bool) -> dict:
        uv = self._memo[(float(x), float(y), float(depth))][1]
        return {"x_mm": float(x), "y_mm": float(y), "depth_mm": float(depth),
                "on_boundary": bool(on_boundary),
                "on_rim": bool(math.hypot(x, y) >= self.rim * (1 - 1e-12)),
                "image_uv_mm": [float(uv[0]), float(uv[1])],
                "reference_sensor_mm": float(self.ref)}


def _search_segment(foci: _LineFoci, xs, depths, which: int, sign: float, *,
                    start_is_boundary: bool):
    """Extreme of line focus ``which`` (0 near, 1 far) along the tilt-plane points ``xs``
    (ends included; the last is the field's boundary, the first too unless it is the
    axis of an untilted mirror): the grid, then a bounded Brent search between the best
    point's neighbours (stops on a bracket of :data:`FIELD_TOL_MM`)."""
    from scipy.optimize import minimize_scalar  # imported here: a second of start-up
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
    on_boundary = x_best == float(xs[-1]) or (start_is_boundary and x_best == float(xs[0]))
    return sign * v, foci.where(x_best, 0.0, depth, on_boundary=on_boundary), history


class StarField:
    """A 2-D field of mirror points star-shaped about a centre ``p0`` on the tilt plane:
    ``(t, θ) ∈ [0, 1] × [0, π]`` maps to ``p0 + t s_b(θ) (cos θ, sin θ)``, with
    ``s_b(θ)`` the distance to the field's boundary, so ``t = 1`` is the boundary itself
    (the half ``y >= 0``: the setup is symmetric under ``y → −y``).

    Parameters
    ----------
    rim : float
        The mirror's rim radius, mm: the field never leaves the disc of this radius.
    p0 : (2,) array_like, optional
        The centre, local mirror (x, y), mm (default the vertex); it must lie inside
        the rim.
    angle : callable, optional
        ``angle(x, y)`` of local (x, y) arrays (mm), zero at ``p0``, increasing outwards;
        its level ``limit`` bounds the field inside the rim. Without it (default) the
        boundary is the rim.
    limit : float, optional
        The level of ``angle`` on the boundary (the unit of ``angle``: radians for the
        FOV field). Required with ``angle``.
    """

    def __init__(self, rim: float, p0=(0.0, 0.0), angle=None, limit: float | None = None):
        self.rim = rim
        self.p0 = np.asarray(p0, dtype=float)
        self.angle = angle
        self.limit = limit
        self._s: dict[float, float] = {}

    def _s_rim(self, u) -> float:
        b = float(self.p0 @ u)
        return -b + math.sqrt(max(b * b - (float(self.p0 @ self.p0) - self.rim ** 2), 0.0))

    def boundary_distance(self, theta: float) -> float:
        """The distance ``s_b(θ)`` from ``p0`` to the field's boundary along direction θ,
        mm: the rim, or the first crossing of ``angle = limit`` (root to 1e-12 mm) before
        it. Cached per θ.

        Parameters
        ----------
        theta : float
            Direction from ``p0`` in the mirror's (x, y) plane, radians (0: +x).

        Returns
        -------
        float
            ``s_b(θ)``, mm.
        """
        if theta not in self._s:
            u = np.array([math.cos(theta), math.sin(theta)])
            s_rim = self._s_rim(u)
            s_b = s_rim
            if self.angle is not None:
                ss = np.linspace(0.0, s_rim, 513)
                pts = self.p0 + ss[:, None] * u
                g = self.angle(pts[:, 0], pts[:, 1]) - self.limit
                out = np.nonzero(g > 0)[0]
                if out.size:
                    k = int(out[0])
                    h = lambda s: float(self.angle(*(self.p0 + s * u)) - self.limit)
                    from scipy.optimize import brentq

                    s_b = brentq(h, ss[k - 1], ss[k], xtol=1e-12)
            self._s[theta] = s_b
        return self._s[theta]

    def point(self, t: float, theta: float) -> tuple[float, float]:
        """The mirror point at field coordinates (t, θ).

        Parameters
        ----------
        t : float
            Fraction of the way from ``p0`` (0) to the boundary (1).
        theta : float
            Direction from ``p0``, radians, in [0, π] for the half ``y >= 0``.

        Returns
        -------
        tuple of float
            Local mirror (x, y), mm; a point rounded past the rim is pulled back onto it.
        """
        u = np.array([math.cos(theta), math.sin(theta)])
        x, y = self.p0 + t * self.boundary_distance(theta) * u
        h = math.hypot(x, y)
        scale = min(1.0, self.rim / h) if h > 0 else 1.0  # rounding at the rim
        return float(x * scale), float(y * scale)


def _polar_grid(n_rings: int):
    """(t, θ) of the half field: rings ``t = k / n_rings`` (the last is the boundary)
    with ``3k + 1`` angles from 0 to π on ring k; returns points and spacings."""
    pts = [(0.0, 0.0)]
    for k in range(1, n_rings + 1):
        pts += [(k / n_rings, math.pi * j / (3 * k)) for j in range(3 * k + 1)]
    return pts, 1.0 / n_rings, math.pi / (3 * n_rings)


def _search_disc(foci: _LineFoci, field: StarField, n_rings, depths, which: int,
                 sign: float):
    """Extreme of line focus ``which`` over a 2-D field: the polar grid of
    :func:`_polar_grid`, then refinements from its best point and from its best boundary
    point (an extreme of a smooth function on a region is inside or on the boundary):
    Nelder–Mead in (t, θ) inside, Brent along the boundary; both stop at
    :data:`FIELD_TOL_MM` (of focus, and of t, θ times the field's size)."""
    from scipy.optimize import minimize, minimize_scalar
    pts, dt, dth = _polar_grid(n_rings)
    f = lambda t, th, d: sign * foci(*field.point(t, th), d)[which]
    scored = [(f(t, th, d), t, th, d) for d in depths for t, th in pts]
    best = min(scored)
    best_edge = min(s for s in scored if s[1] == 1.0)
    history = [{"stage": "grid", "evaluations": foci.evaluations, "focus_mm": sign * best[0]}]
    found = [best, best_edge]
    xtol = FIELD_TOL_MM / field.rim
    for _v, t, th, d in {best, best_edge}:
        if t == 1.0:
            res = minimize_scalar(lambda a, d=d: f(1.0, a, d),
                                  bounds=(max(th - dth, 0.0), min(th + dth, math.pi)),
                                  method="bounded", options={"xatol": xtol})
            found.append((float(res.fun), 1.0, float(res.x), d))
        else:
            p0 = np.array([t, th])
            simplex = np.array([p0, p0 + [0.5 * dt, 0.0],
                                p0 + [0.0, 0.5 * dth if th + 0.5 * dth <= math.pi else -0.5 * dth]])
            res = minimize(lambda p, d=d: f(p[0], p[1], d), p0, method="Nelder-Mead",
                           bounds=[(0.0, 1.0), (0.0, math.pi)],
                           options={"initial_simplex": simplex, "xatol": xtol,
                                    "fatol": FIELD_TOL_MM, "maxiter": 400})
            found.append((float(res.fun), float(res.x[0]), float(res.x[1]), d))
    v, t, th, d = min(found)
    history.append({"stage": "refined", "evaluations": foci.evaluations, "focus_mm": sign * v})
    x, y = field.point(t, th)
    return sign * v, foci.where(x, y, d, on_boundary=t >= 1.0), history


def _check_visible(setup, field: str, x, y) -> None:
    """Raise SetupError unless the lens sees every mirror point (x, y) of ``field``."""
    pl = placement_of(setup.mirror)
    cos_i = chief_ray(pl, pl.surface(x, y)).cos_incidence
    if not np.all(cos_i > 0):
        j = np.unravel_index(np.argmin(cos_i), cos_i.shape)
        raise SetupError(
            f"field {field!r}: the lens does not see all of this field of the mirror: it "
            f"is hidden beyond grazing incidence, e.g. at local (x, y) = "
            f"({x[j]:.2f}, {y[j]:.2f}) mm (rim {setup.mirror.rim_radius:g} mm), and toward "
            f"grazing incidence the focal images run out toward the depth, so the field "
            f"has no bounded focus range; use field 'plane' (the FOV's zone; --field plane "
            f"at the command line)")


def _disc_samples(rim: float, p0=(0.0, 0.0), s_b=None):
    """Local (x, y) arrays over a star-shaped field, its boundary included (for checks)."""
    th = np.linspace(0.0, 2.0 * math.pi, 721)
    t = np.linspace(0.0, 1.0, 257)[:, None]
    s = np.full(th.shape, float(rim)) if s_b is None else np.array([s_b(a) for a in th])
    return p0[0] + t * s * np.cos(th), p0[1] + t * s * np.sin(th)


def fov_field(setup: Setup, fov_deg: float | None) -> tuple[StarField, float]:
    """The 2-D FOV field of a tilted mirror (see :data:`FIELDS`), and its half angle:
    the mirror points whose reflected chief ray lies within half the FOV of the ray at
    the tilt-plane zone's bisector, inside the rim.

    Parameters
    ----------
    setup : Setup
        The setup (its mirror, placement and rim).
    fov_deg : float or None
        The field of view, degrees; None for the setup's own
        (:func:`~mitsweep.optics.sweep.mirror_zone`).

    Returns
    -------
    field : StarField
        Centred on the bisector's mirror point (on the tilt plane), bounded by the
        chief-ray angle from the bisector reaching the half angle, or by the rim.
    half : float
        Half the FOV, radians.
    """
    from scipy.optimize import minimize_scalar
    pl = placement_of(setup.mirror)
    zone = mirror_zone(setup, fov_deg)
    xs = zone.grid()
    w = chief_ray(pl, pl.surface(xs, np.zeros_like(xs))).world_dir
    phi = np.unwrap(np.arctan2(w[:, 0], w[:, 2]))
    mid = 0.5 * (float(phi.min()) + float(phi.max()))
    centre = np.array([math.sin(mid), 0.0, math.cos(mid)])
    half = 0.5 * math.radians(zone.fov_deg)

    def angle(x, y):
        wd = chief_ray(pl, pl.surface(np.asarray(x, float), np.asarray(y, float))).world_dir
        return np.arccos(np.clip(wd @ centre, -1.0, 1.0))

    # The bisector's own mirror point (angle 0), on the zone: phi is monotonic there.
    j = int(np.argmin(np.abs(phi - mid)))
    lo, hi = xs[max(j - 1, 0)], xs[min(j + 1, len(xs) - 1)]
    x0 = minimize_scalar(lambda x: float(angle(x, 0.0)), bounds=(min(lo, hi), max(lo, hi)),
                         method="bounded", options={"xatol": 1e-10}).x
    return StarField(setup.mirror.rim_radius, (float(x0), 0.0), angle, half), half


def traced_sweep_range(setup: Setup, fov_deg: float | None = None,
                       depth_min: float | None = None, depth_max: float | None = None, *,
                       field: str = "plane", n_points: int = 41, n_rings: int = 6,
                       rays: int = 1 << 15,
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
    field : {"plane", "mirror", "fov"}
        See :data:`FIELDS`.
    n_points : int
        Grid points along a segment (the tilt-plane zone, or a radius when untilted).
    n_rings : int
        Rings of the polar grid over a tilted mirror's 2-D field ("mirror", "fov"),
        about its centre; the last ring is the field's boundary, and ring k carries
        3k + 1 angles over the half field.
    rays, aperture_radius :
        Per traced point; see :func:`numeric_focus`.

    Returns
    -------
    TracedSweepRange

    Raises
    ------
    ValueError
        For an unknown field; SetupError (a ValueError) for a 2-D field ("mirror",
        "fov") part of which faces away from the lens.
    """
    if field not in FIELDS:
        raise ValueError(f"field: must be one of {', '.join(FIELDS)}, got {field!r}")
    if int(n_points) < 3 or int(n_rings) < 1:
        raise ValueError(f"n_points must be >= 3 and n_rings >= 1, got {n_points}, {n_rings}")
    sr = optimal_sweep_range(setup, fov_deg=fov_deg, depth_min=depth_min, depth_max=depth_max)
    depths = tuple(sorted({sr.depth_min, sr.depth_max}))
    rim = setup.mirror.rim_radius
    tilted = not setup.mirror.is_symmetric
    zone = mirror_zone(setup, fov_deg)
    star = None
    if field == "plane" or (field == "fov" and not tilted):
        # Untilted, the FOV disc is searched along its radius (rotational symmetry).
        xs = np.linspace(zone.rho_start, zone.rho_end, int(n_points))
    elif field == "mirror":
        _check_visible(setup, field, *_disc_samples(rim))
        xs = np.linspace(0.0, rim, int(n_points))
        star = StarField(rim) if tilted else None
    else:  # "fov", tilted
        star, _ = fov_field(setup, fov_deg)
        _check_visible(setup, field, *_disc_samples(rim, star.p0, star.boundary_distance))
    foci = _LineFoci(setup, sr.reference_sensor_distance, rays=rays,
                     aperture_radius=aperture_radius)
    out = {}
    for key, which, sign in (("min", 0, 1.0), ("max", 1, -1.0)):
        if star is not None:
            out[key] = _search_disc(foci, star, int(n_rings), depths, which, sign)
        else:
            out[key] = _search_segment(foci, xs, depths, which, sign,
                                       start_is_boundary=tilted)
    logger.info("traced sweep range over field %s: %.4f .. %.4f mm (%d points)", field,
                out["min"][0], out["max"][0], foci.evaluations)
    return TracedSweepRange(
        field=field, focus_min=float(out["min"][0]), focus_max=float(out["max"][0]),
        min_at=out["min"][1], max_at=out["max"][1],
        convergence={"min": out["min"][2], "max": out["max"][2]},
        points=foci.evaluations, depths=depths,
        aperture_radius=float(setup.lens.aperture_radius if aperture_radius is None
                              else aperture_radius),
        samples=foci.samples)
