"""Field of view → mirror zone, and the optimal focal-sweep range (paper Eq. 8–9).

The mirror zone (docs/design.md):

- untilted: ρ from the axis out to where the world-bound reflected chief ray makes
  ``fov/2`` with the mirror axis pointing toward the camera;
- tilted: the contiguous range of tilt-plane points, starting at the rim nearest the
  camera, over which the reflected chief rays span ``fov`` within the tilt plane.

The optimal range is the min and max of D_m, D_s (Eq. 6–7) over that zone and the depth
range. D is monotonic in depth (d_m, d_s grow with l), so only the two end depths are
evaluated; over the zone a dense grid is refined by a bounded 1-D minimisation.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass

import numpy as np

from ..config import Setup, SetupError
from ..deprecation import renamed_fields
from .chief_ray import chief_ray
from .coddington import focal_image_axial_distances
from .placement import placement_of
from .solve import bounded_minimum, bracketed_root
from .thinlens import image_distance

__all__ = ["MirrorZone", "SweepRange", "mirror_zone", "optimal_sweep_range",
           "max_fov_deg"]

_GRID = 4097


@dataclass(frozen=True)
class MirrorZone:
    """The part of the mirror that serves the FOV, as signed tilt-plane coordinates.

    Attributes
    ----------
    rho_start : float
        Start of the zone, mm: 0 on the axis for an untilted mirror, the rim nearest the
        camera for a tilted one.
    rho_end : float
        End of the zone, mm (signed).
    fov_deg : float
        The field of view the zone serves, degrees.
    max_fov_deg : float
        The largest FOV this mirror reaches from this camera, degrees.
    """

    rho_start: float   # mm; 0 on the axis for untilted mirrors, the near rim for tilted
    rho_end: float     # mm; signed
    fov_deg: float
    max_fov_deg: float  # the largest FOV this mirror reaches from this camera

    @property
    def rho_max(self) -> float:
        return max(abs(self.rho_start), abs(self.rho_end))

    def grid(self, n: int = _GRID) -> np.ndarray:
        """``n`` evenly spaced tilt-plane coordinates from :attr:`rho_start` to
        :attr:`rho_end`, mm, both included.

        Parameters
        ----------
        n : int, optional
            Number of points (default 4097, the zone's search grid).
        """
        return np.linspace(self.rho_start, self.rho_end, n)


#: SweepRange lengths (mm) that were named ``<name>_mm`` before; JSON keeps that form.
_MM_FIELDS = ("focus_min", "focus_max", "sensor_start", "sensor_end", "translation",
              "rho_max", "rho_start", "rho_end", "depth_min", "depth_max")


@renamed_fields(**{f"{name}_mm": name for name in _MM_FIELDS})
@dataclass(frozen=True)
class SweepRange:
    """An optical sweep: focus distances (object side) and the sensor travel.

    Lengths are mm (unsuffixed, docs/design.md); ``exposure_s``, ``velocity_mm_s`` and
    the angles carry their units. ``sensor_start`` is the sensor distance focusing at
    ``focus_min`` (the larger distance), ``sensor_end`` the one focusing at
    ``focus_max``. The reference distance of IPSFs and ground truth is the mid-travel of
    the motion run over it (:func:`mitsweep.optics.reference.reference_geometry`); for
    the default motion that is :attr:`reference_sensor_distance`.

    The former ``*_mm`` names (``focus_min_mm``, ...) still read, and are still
    accepted by the constructor, with a :class:`DeprecationWarning`; :meth:`as_dict`
    keeps the ``*_mm`` keys.

    Attributes
    ----------
    focus_min, focus_max : float
        Nearest and farthest focus distances (object side) the sweep covers, mm.
    sensor_start, sensor_end : float
        Sensor distances focusing at ``focus_min`` and ``focus_max``, mm.
    translation : float
        Sensor travel ``|sensor_start − sensor_end|``, mm.
    exposure_s : float
        Exposure: the travel at ``velocity_mm_s``, s.
    velocity_mm_s : float
        Stage velocity, mm/s.
    rho_max : float
        Largest ``|ρ|`` of the mirror zone, mm.
    rho_start, rho_end : float
        The mirror zone, signed tilt-plane coordinates, mm (:class:`MirrorZone`).
    fov_deg, max_fov_deg : float
        The FOV served and the largest one the mirror reaches, degrees.
    depth_min, depth_max : float
        The depth range, mm (``depth_max`` may be ``inf``).
    source : str
        ``"optimal"`` (Eq. 8–9) or ``"setup"`` (the setup's given focus_min/max).
    min_at, max_at : dict
        Where each extreme is reached: ``surface``, ``rho_mm``, ``depth_mm``.
    """

    focus_min: float
    focus_max: float
    sensor_start: float
    sensor_end: float
    translation: float
    exposure_s: float
    velocity_mm_s: float
    rho_max: float
    rho_start: float
    rho_end: float
    fov_deg: float
    max_fov_deg: float
    depth_min: float
    depth_max: float
    source: str            # "optimal" (Eq. 8–9) or "setup" (given focus_min/max)
    min_at: dict           # where the minimum is reached: surface, rho_mm, depth_mm
    max_at: dict

    @property
    def reference_sensor_distance(self) -> float:
        """Mid-travel of the sensor, mm."""
        return 0.5 * (self.sensor_start + self.sensor_end)

    def as_dict(self) -> dict:
        """JSON provenance: lengths under their ``*_mm`` keys (unchanged for readers)."""
        d = {(f"{k}_mm" if k in _MM_FIELDS else k): v for k, v in asdict(self).items()}
        d["reference_sensor_distance_mm"] = self.reference_sensor_distance
        return d


def _reflected_angles(placement, xs):
    ray = chief_ray(placement, placement.surface(xs, np.zeros_like(xs)))
    w = ray.world_dir
    axis = placement.axis
    # Angle to the mirror axis (untilted), and the in-plane angle (tilted).
    ang_axis = np.arccos(np.clip(w @ axis, -1.0, 1.0))
    ang_plane = np.arctan2(w[..., 0], w[..., 2])
    return ray, ang_axis, ang_plane


def _visible_limit(placement, x_lo: float, x_hi: float) -> float:
    """The end of the visible (n·r̂ > 0) run that starts at x_lo, searching toward x_hi."""
    xs = np.linspace(x_lo, x_hi, _GRID)
    ray = chief_ray(placement, placement.surface(xs, np.zeros_like(xs)))
    vis = ray.cos_incidence > 0
    if not vis[0]:
        return x_lo
    if vis.all():
        return x_hi
    j = int(np.argmin(vis))  # first invisible
    f = lambda x: float(chief_ray(placement, placement.surface(np.array(x), np.array(0.0)))
                        .cos_incidence)
    return bracketed_root(f, xs[j - 1], xs[j], xtol=1e-12)


def max_fov_deg(setup: Setup) -> float:
    """The largest FOV (degrees) this mirror gives this camera.

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror and its placement in front of the lens.
    """
    return mirror_zone(setup, reach_only=True).max_fov_deg


def mirror_zone(setup: Setup, fov_deg: float | None = None, *, reach_only: bool = False
               ) -> MirrorZone:
    """The zone of the mirror that covers ``fov_deg`` (default: the setup's).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The mirror, lens and sweep.
    fov_deg : float, optional
        The field of view, degrees (default: ``setup.sweep.fov_deg``).
    reach_only : bool, optional
        Only find how far the mirror reaches (``max_fov_deg``), without refusing a FOV
        beyond it.

    Raises
    ------
    SetupError
        If the FOV exceeds what the mirror reaches (the message gives the largest), or
        the camera cannot see the mirror.
    """
    m = setup.mirror
    placement = placement_of(m)
    fov = setup.sweep.fov_deg if fov_deg is None else fov_deg
    rim = min(m.rim_radius, placement.profile.max_rho())
    if m.is_symmetric:
        start = 0.0
        end = _visible_limit(placement, 0.0, rim)
        if end <= 0.0:
            raise SetupError("mirror: the camera cannot see the mirror's front surface")
        xs = np.linspace(start, end, _GRID)
        _, ang, _ = _reflected_angles(placement, xs)
        # Contiguous run from the axis while the angle keeps growing.
        grows = np.concatenate([[True], np.diff(ang) > 0])
        stop = int(np.argmin(grows)) if not grows.all() else len(xs)
        xs, ang = xs[:stop], ang[:stop]
        reach = 2.0 * math.degrees(float(ang[-1]))
        if reach_only:
            return MirrorZone(start, float(xs[-1]), reach, reach)
        half = math.radians(fov) / 2.0
        if half > ang[-1]:
            raise SetupError(f"sweep.fov_deg: {fov:g}° is beyond this mirror's reach from the "
                             f"camera; the largest FOV it gives is {reach:.2f}°")
        j = int(np.searchsorted(ang, half))
        g = lambda x: float(_reflected_angles(placement, np.array([x]))[1][0]) - half
        end_fov = xs[0] if j == 0 else bracketed_root(g, xs[j - 1], xs[j], xtol=1e-12)
        return MirrorZone(start, float(end_fov), fov, reach)

    # Tilted: start at the rim nearest the camera, walk across the tilt plane.
    rims = np.array([-rim, rim])
    z_rims = placement.surface(rims, np.zeros(2)).position[:, 2]
    near = float(rims[int(np.argmax(z_rims))])
    far = -near
    # The near rim may be hidden: start at the first visible point from that side.
    xs_all = np.linspace(near, far, _GRID)
    vis = chief_ray(placement, placement.surface(xs_all, np.zeros_like(xs_all))).cos_incidence > 0
    if not vis.any():
        raise SetupError("mirror: the camera cannot see the mirror's front surface "
                         f"(tilt_deg = {m.tilt_deg:g})")
    first = int(np.argmax(vis))
    start = float(xs_all[first])
    end = _visible_limit(placement, start, far)
    xs = np.linspace(start, end, _GRID)
    _, _, phi = _reflected_angles(placement, xs)
    phi = np.unwrap(phi)
    extent = np.maximum.accumulate(phi) - np.minimum.accumulate(phi)
    reach = math.degrees(float(extent[-1]))
    if reach_only:
        return MirrorZone(start, float(xs[-1]), reach, reach)
    target = math.radians(fov)
    if target > extent[-1]:
        raise SetupError(f"sweep.fov_deg: {fov:g}° is beyond this mirror's reach in its tilt "
                         f"plane; the largest FOV it gives is {reach:.2f}°")
    j = int(np.searchsorted(extent, target))

    def h(x):
        xx = np.linspace(start, x, 257)
        p = np.unwrap(_reflected_angles(placement, xx)[2])
        return float(np.max(p) - np.min(p)) - target

    end_fov = xs[0] if j == 0 else bracketed_root(h, xs[j - 1], xs[j], xtol=1e-10)
    return MirrorZone(start, float(end_fov), fov, reach)


def _zone_and_extremes(setup: Setup, fov_deg: float | None, depths: tuple[float, ...]
                       ) -> tuple[MirrorZone, float, dict[str, object], float,
                                  dict[str, object]]:
    """The mirror zone and the nearest and farthest focal images (each with where it
    lies) of :func:`optimal_sweep_range`, remembered for the last
    :data:`_EXTREMES_CACHED` setups (a pure function of frozen values: a calibration
    or a bank asks for the same setup's range dozens of times, 60 ms each)."""
    try:
        return _zone_and_extremes_cached(setup, fov_deg, depths)
    except TypeError:   # a setup built with unhashable values (a list for a tuple)
        return _zone_and_extremes_cached.__wrapped__(setup, fov_deg, depths)


_EXTREMES_CACHED = 64


@functools.lru_cache(maxsize=_EXTREMES_CACHED)
def _zone_and_extremes_cached(setup, fov_deg, depths):
    zone = mirror_zone(setup, fov_deg)
    if setup.sweep.focus_min is not None and setup.sweep.focus_max is not None:
        # both or neither (mitsweep.config.Sweep checks it)
        given = {"surface": "given", "rho_mm": float("nan"), "depth_mm": float("nan")}
        return zone, setup.sweep.focus_min, given, setup.sweep.focus_max, dict(given)
    fmin, at_min = _extreme(setup, zone, depths, +1.0)
    fmax, at_max = _extreme(setup, zone, depths, -1.0)
    return zone, fmin, at_min, fmax, at_max


def _extreme(setup, zone: MirrorZone, depths, sign: float) -> tuple[float, dict[str, object]]:
    """Min (sign=+1) or max (sign=−1) of D_m, D_s over the zone and the end depths."""
    xs = zone.grid()
    best: tuple[float, dict[str, object]] | None = None
    for depth in depths:
        d_m, d_s = focal_image_axial_distances(setup, xs, depth)
        for name, dd in (("meridional", d_m), ("sagittal", d_s)):
            j = int(np.argmin(sign * dd))
            lo, hi = xs[max(j - 1, 0)], xs[min(j + 1, len(xs) - 1)]
            f = lambda x, depth=depth, k=(0 if name == "meridional" else 1): sign * float(
                focal_image_axial_distances(setup, np.array(x), depth)[k])
            x_best, v_best = float(xs[j]), float(sign * dd[j])
            if hi > lo:
                x_min, f_min = bounded_minimum(f, lo, hi, xatol=1e-10)
                if f_min < v_best:
                    x_best, v_best = x_min, f_min
            cand = (v_best, {"surface": name, "rho_mm": x_best, "depth_mm": float(depth)})
            if best is None or cand[0] < best[0]:
                best = cand
    if best is None:
        raise ValueError("_extreme: no depth to evaluate")
    return sign * best[0], best[1]


def optimal_sweep_range(setup: Setup, *, fov_deg: float | None = None,
                        depth_min: float | None = None,
                        depth_max: float | None = None) -> SweepRange:
    """The optimal focal-sweep range of a setup (paper Eq. 4–9) and its sensor travel.

    Parameters
    ----------
    setup : mitsweep.config.Setup
    fov_deg, depth_min, depth_max : float, optional
        Override the setup's FOV (degrees) and depth range (mm, ``inf`` allowed).

    Returns
    -------
    SweepRange
        ``focus_min``/``focus_max`` are D_min^opt and D_max^opt (Eq. 8–9), the
        sensor distances follow from the thin lens (Eq. 1), the exposure is the sensor
        translation over the stage velocity.

    Raises
    ------
    SetupError
        For a FOV beyond the mirror's reach, an inverted depth range, or focal images
        at or inside the lens focal length.
    """
    dmin = setup.sweep.depth_min if depth_min is None else float(depth_min)
    dmax = setup.sweep.depth_max if depth_max is None else float(depth_max)
    if not (dmin > 0) or math.isnan(dmax):
        raise SetupError(f"sweep.depth_min: must be > 0 mm, got {dmin:g}")
    if dmin > dmax:
        raise SetupError(f"sweep.depth_min: must be <= depth_max ({dmax:g} mm), got {dmin:g}")
    if fov_deg is not None and not (0 < fov_deg < 360):
        raise SetupError(f"sweep.fov_deg: must be in (0, 360), got {fov_deg:g}")
    depths = (dmin, dmax) if dmin != dmax else (dmin,)
    zone, fmin, at_min, fmax, at_max = _zone_and_extremes(setup, fov_deg, depths)
    at_min, at_max = dict(at_min), dict(at_max)   # the caller's own, not the cache's
    source = "setup" if setup.sweep.focus_min is not None \
        and setup.sweep.focus_max is not None else "optimal"
    f = setup.lens.focal_length
    if not fmin > f:
        raise SetupError(f"sweep: the nearest focal image lies at {fmin:.3f} mm from the lens, "
                         f"at or inside the lens focal length ({f:g} mm); move the mirror "
                         f"farther than {f:g} mm plus its depth")
    i_start = float(image_distance(f, fmin))
    i_end = float(image_distance(f, fmax))
    translation = abs(i_start - i_end)
    return SweepRange(
        focus_min=float(fmin), focus_max=float(fmax),
        sensor_start=float(i_start), sensor_end=float(i_end),
        translation=float(translation),
        exposure_s=float(translation / setup.sweep.velocity),
        velocity_mm_s=setup.sweep.velocity,
        rho_max=zone.rho_max, rho_start=zone.rho_start, rho_end=zone.rho_end,
        fov_deg=zone.fov_deg, max_fov_deg=zone.max_fov_deg,
        depth_min=float(dmin), depth_max=float(dmax),
        source=source, min_at=at_min, max_at=at_max)

