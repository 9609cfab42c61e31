r"""The optical stages of the ray kernel: aim-plane sample → ray → mirror → lens → sensor.

Each stage is a function of Dr.Jit arrays, generic over the float type (``Float`` or
``Float64``); :func:`trace_lanes` chains them for the lanes of one launch
(:class:`mitsweep.tracer.sampling.Lanes`). Scalars that change from call to call arrive
as opaque Dr.Jit values, so that the fused kernel compiles once per process. ``a·b + c``
is written ``dr.fma(a, b, c)`` throughout: LLVM contracts nothing by itself, and a fused
multiply-add is one instruction instead of two and one rounding instead of two (measured
on the sphere's periphery: 323 instead of 380 operations per lane in the deposit kernel,
6 % fewer CPU seconds per ray, kernels within 1.4e-5 in L1).

Stages
------
*sample* (:func:`aim_box`, :func:`aim_ellipse`, :func:`source_rays`)
    The point source sits at ``S = p_r + l w`` (mirror point ``p_r``, world-bound chief
    direction ``w``, depth ``l``). Rays are parametrised by their crossing ``Q = p_r +
    a e₁ + b e₂`` of the *aim plane* through ``p_r`` perpendicular to ``w``; the
    direction is :math:`\hat d \propto -w + (a/l)\,e_1 + (b/l)\,e_2`, exact in float32
    for ``l → ∞``, with solid-angle weight ``(1 + (a² + b²)/l²)^{-3/2}``; the ray starts
    on the true line from ``S``, at most ``margin`` mm before ``Q``.
*intersect* (:func:`intersect_conic`, :func:`intersect_asphere`)
    In the mirror's local frame the conic is ``F(p) = x² + y² + (1+k) z² + 2 R z = 0``,
    the mirror on the branch ``R + (1+k) z ≥ 0``. Along ``p = o + t d`` the quadratic
    ``α t² + β t + γ = 0`` is solved without cancellation (``q = −(β + sign(β) √Δ)/2``,
    roots ``q/α`` and ``γ/q``; the second stays finite when ``α → 0``); the hit is the
    nearest positive root on the mirror's branch, polished by one Newton step on ``F``
    unless the ray grazes (``|∇F·d| < 10⁻³ |∇F|``). Even-asphere terms are added by
    Newton steps on ``z + s(ρ) = 0`` from the conic root.
*reflect* (:func:`surface_normal`, :func:`reflect`)
    About the unnormalised normal: ``d − 2 (d·m) m / |m|²`` (no square root).
*lens* (:func:`rotate`, :func:`thin_lens`)
    A reflected ray reaching the lens plane at ``L`` (``|L| ≤`` aperture radius) with
    direction ``r`` lands, on a sensor at distance ``i``, at ``L (1 − i/f) + i
    r_xy/r_z``, affine in ``i``: in upright image coordinates ``h(i) = A + B i`` with
    ``A = −L_xy`` and ``B = L_xy/f − r_xy/r_z``.

The *deposit* stage is :mod:`mitsweep.tracer.deposit`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .geometry import Geometry
from .sampling import R2, R3, Lanes, array_types, lattice_coordinates

__all__ = ["aim_box", "aim_ellipse", "source_rays", "intersect_conic", "intersect_asphere",
           "surface_normal", "reflect", "rotate", "thin_lens", "trace_lanes"]

#: A Dr.Jit array of the selected backend: ``Any`` in annotations, so that importing this
#: module does not import drjit.
DrJitArray = Any


def aim_box(ua: DrJitArray, ub: DrJitArray, a0: DrJitArray, a1: DrJitArray,
            b0: DrJitArray, b1: DrJitArray) -> tuple[DrJitArray, DrJitArray]:
    """Aim-plane point ``(a, b)`` uniform in the box ``[a0, a1] × [b0, b1]`` (mm) from
    unit-square coordinates ``(ua, ub)`` (stage *sample*).

    Parameters
    ----------
    ua, ub : Float
        Unit-square coordinates in [0, 1).
    a0, a1, b0, b1 : Float
        The box's bounds along ``e1`` and ``e2``, mm.

    Returns
    -------
    a, b : Float
        Aim-plane coordinates, mm.
    """
    import drjit as dr

    return dr.fma(a1 - a0, ua, a0), dr.fma(b1 - b0, ub, b0)


def aim_ellipse(ua: DrJitArray, ub: DrJitArray, centre: Sequence[DrJitArray],
                matrix: Sequence[DrJitArray]) -> tuple[DrJitArray, DrJitArray]:
    """Aim-plane point ``(a, b) = c + M x`` uniform in an ellipse (stage *sample*).

    ``x = √ua (cos 2π ub, sin 2π ub)`` is the area-preserving polar map of the unit
    square onto the unit disc; ``centre = (ca, cb)`` and ``matrix = (m00, m01, m10,
    m11)`` (row-major) in mm.

    Parameters
    ----------
    ua, ub : Float
        Unit-square coordinates in [0, 1).
    centre : (Float, Float)
        The ellipse's centre ``(ca, cb)``, mm.
    matrix : sequence of 4 Float
        ``M`` row-major, mm.

    Returns
    -------
    a, b : Float
        Aim-plane coordinates, mm.
    """
    import drjit as dr

    ca, cb = centre
    m00, m01, m10, m11 = matrix
    rad = dr.sqrt(ua)  # uniform on the unit disc
    sin_p, cos_p = dr.sincos((2.0 * math.pi) * ub)
    xd, yd = rad * cos_p, rad * sin_p
    return (dr.fma(m01, yd, dr.fma(m00, xd, ca)),
            dr.fma(m11, yd, dr.fma(m10, xd, cb)))


def source_rays(a: DrJitArray, b: DrJitArray, w: DrJitArray, e1: DrJitArray, e2: DrJitArray,
                pr: DrJitArray, inv_l: DrJitArray, margin: DrJitArray,
                depth: DrJitArray | None = None
                ) -> tuple[DrJitArray, DrJitArray, DrJitArray]:
    """Rays from the point source through the aim-plane points ``(a, b)`` (stage *sample*).

    Parameters
    ----------
    a, b : Float
        Aim-plane coordinates along ``e1``, ``e2``, mm.
    w, e1, e2, pr : Array3
        Local-frame chief direction (world-bound), aim-plane axes (``(w, e1, e2)``
        orthonormal) and mirror point ``p_r``.
    inv_l : Float
        1 / depth (0 for a source at infinity).
    margin : Float
        Upper bound of the distance from ``p_r`` to any mirror point, mm.
    depth : Float, optional
        The depth ``l``; None for a source at infinity (the start is then ``margin``
        before the aim plane).

    Returns
    -------
    origin, direction : Array3
        Start ``Q − back · d`` (``back = min(margin, |S − Q|)``) and unit direction.
    weight : Float
        Solid-angle weight ``(1 + (a² + b²)/l²)^{-3/2}``.
    """
    import drjit as dr

    fma = dr.fma
    al, bl = a * inv_l, b * inv_l
    # (w, e1, e2) is orthonormal, so |−w + al e1 + bl e2| = sqrt(1 + al² + bl²): one
    # square root serves the direction, the solid-angle weight and the start distance.
    root = dr.sqrt(fma(al, al, fma(bl, bl, 1.0)))
    inv_root = 1.0 / root
    d = fma(e1, al, fma(e2, bl, -w)) * inv_root
    weight = inv_root * inv_root * inv_root
    q_pt = fma(e1, a, fma(e2, b, pr))
    # Distance from S to Q is l·sqrt(1 + (a² + b²)/l²); start no farther back than the margin.
    back = margin if depth is None else dr.minimum(margin, depth * root)
    return fma(d, -back, q_pt), d, weight


def _conic_form(ok: DrJitArray, p: DrJitArray, q: DrJitArray) -> DrJitArray:
    """x_p x_q + y_p y_q + (1+k) z_p z_q (the conic's quadratic form)."""
    import drjit as dr

    return dr.fma(p.x, q.x, dr.fma(p.y, q.y, (ok * p.z) * q.z))


def intersect_conic(o: DrJitArray, d: DrJitArray, R: DrJitArray, ok: DrJitArray
                    ) -> tuple[DrJitArray, DrJitArray]:
    """Distance along ``o + t d`` to the conic mirror (stage *intersect*).

    Parameters
    ----------
    o, d : Array3
        Ray origin and unit direction, mirror's local frame (vertex at the origin).
    R, ok : Float
        Vertex radius R (mm) and ``1 + k``.

    Returns
    -------
    t : Float
        Nearest positive root on the mirror's branch (``R + (1+k) z ≥ −10⁻⁶ R``),
        polished by one Newton step on ``F`` except at grazing incidence; 0 where the
        ray misses.
    hit : Bool
        The ray meets the branch.
    """
    import drjit as dr

    fma = dr.fma
    Float = type(d.x)
    alpha = _conic_form(ok, d, d)
    beta = 2.0 * fma(R, d.z, _conic_form(ok, o, d))
    gamma = fma(2.0 * R, o.z, _conic_form(ok, o, o))
    disc = fma(beta, beta, -4.0 * alpha * gamma)
    has = disc >= 0.0
    sq = dr.sqrt(dr.maximum(disc, 0.0))
    qq = -0.5 * (beta + dr.copysign(sq, beta))
    t1 = qq / alpha
    t2 = gamma / qq
    inf = Float(math.inf)

    def valid(t):
        z = fma(t, d.z, o.z)
        return has & dr.isfinite(t) & (t > 0.0) & (fma(ok, z, R) >= -1e-6 * R)

    t1v, t2v = valid(t1), valid(t2)
    t = dr.minimum(dr.select(t1v, t1, inf), dr.select(t2v, t2, inf))
    hit = t1v | t2v
    t = dr.select(hit, t, 0.0)
    # Newton polish on F along the ray, skipped at grazing incidence.
    p = fma(d, t, o)
    grad = type(d)(p.x, p.y, fma(ok, p.z, R))
    g_dot_d = dr.dot(grad, d)
    f_val = fma(2.0 * R, p.z, _conic_form(ok, p, p))
    polish = g_dot_d * g_dot_d > 1e-6 * dr.squared_norm(grad)  # |∇F·d| > 1e-3 |∇F|
    t = dr.select(polish, fma(-0.5, f_val / dr.select(polish, g_dot_d, 1.0), t), t)
    return t, hit


def _asphere_terms(r2: DrJitArray, coeffs: Sequence[float]) -> tuple[DrJitArray, DrJitArray]:
    """Even-asphere sag Σ c_j ρ^(2j+4) and its s'/ρ, Σ (2j+4) c_j ρ^(2j+2)."""
    Float = type(r2)
    sag_p, slope_p = Float(0.0), Float(0.0)
    for j, c in enumerate(coeffs):
        sag_p = sag_p + c * r2 ** (j + 2)
        slope_p = slope_p + (2 * j + 4) * c * r2 ** (j + 1)
    return sag_p, slope_p


def intersect_asphere(o: DrJitArray, d: DrJitArray, t: DrJitArray, R: DrJitArray,
                      ok: DrJitArray, coeffs: Sequence[float]) -> DrJitArray:
    """Refine the conic root ``t`` onto the even asphere (stage *intersect*).

    Four Newton steps on ``G(t) = z + s(ρ)`` with ``s(ρ) = ρ²/(R + √(R² − (1+k) ρ²)) +
    Σ c_j ρ^(2j+4)`` (``coeffs`` = a4, a6, ...); ``t`` unchanged when every coefficient
    is 0.

    Parameters
    ----------
    o, d : Array3
        Ray origin and unit direction, mirror's local frame.
    t : Float
        The conic root (:func:`intersect_conic`).
    R, ok : Float
        Vertex radius R (mm) and ``1 + k``.
    coeffs : sequence of float
        Aspheric coefficients a4, a6, ... (mm^-3, mm^-5, ...).

    Returns
    -------
    Float
        The distance along the ray to the asphere.
    """
    import drjit as dr

    if not any(coeffs):
        return t
    for _ in range(4):  # Newton on G(t) = z + s(ρ) from the conic root
        p = dr.fma(d, t, o)
        r2 = p.x * p.x + p.y * p.y
        qc = dr.sqrt(dr.maximum(R * R - ok * r2, 0.0))
        sag_p, slope_p = _asphere_terms(r2, coeffs)
        g_over = 1.0 / dr.maximum(qc, 1e-12) + slope_p  # s'/ρ
        dg = d.z + g_over * (p.x * d.x + p.y * d.y)
        t = t - (p.z + r2 / (R + qc) + sag_p) / dg
    return t


def surface_normal(p: DrJitArray, r2: DrJitArray, R: DrJitArray, ok: DrJitArray,
                   coeffs: Sequence[float]) -> DrJitArray:
    """Unnormalised outward normal of the mirror at ``p`` (``r2 = x² + y²``; stage
    *reflect*).

    Conic: ``∇F/2 = (x, y, (1+k) z + R)``. Even asphere: ``(x (1 + q P), y (1 + q P),
    q)`` with ``q = √(R² − (1+k) ρ²)`` and ``P = s_asph'/ρ``, finite on the axis and at
    ``q = 0``.

    Parameters
    ----------
    p : Array3
        Point on the mirror, local frame, mm.
    r2 : Float
        ``x² + y²`` of ``p``, mm².
    R, ok : Float
        Vertex radius R (mm) and ``1 + k``.
    coeffs : sequence of float
        Aspheric coefficients a4, a6, ... (none or all zero: the conic).

    Returns
    -------
    Array3
        The normal, not normalised.
    """
    import drjit as dr

    Array3 = type(p)
    if any(coeffs):
        qc = dr.sqrt(dr.maximum(R * R - ok * r2, 0.0))
        h = 1.0 + qc * _asphere_terms(r2, coeffs)[1]
        return Array3(p.x * h, p.y * h, qc)
    return Array3(p.x, p.y, dr.fma(ok, p.z, R))


def reflect(d: DrJitArray, n: DrJitArray) -> tuple[DrJitArray, DrJitArray]:
    """Mirror reflection of ``d`` about the unnormalised normal ``n`` (stage *reflect*):
    ``(d − 2 (d·n) n / |n|², d·n)``.

    Parameters
    ----------
    d : Array3
        Incident direction.
    n : Array3
        Surface normal, any length.

    Returns
    -------
    reflected : Array3
    d_dot_n : Float
        ``d·n`` (negative on the side ``n`` points to).
    """
    import drjit as dr

    d_dot_n = dr.dot(d, n)
    return dr.fma(n, -2.0 * d_dot_n / dr.squared_norm(n), d), d_dot_n


def rotate(v: DrJitArray, rotation: np.ndarray, Float: type) -> DrJitArray:
    """``rotation @ v`` for a local-frame Array3 ``v`` (stage *lens*: local → world).

    Zero entries (an untilted mirror: the identity; a tilt about one axis: four) are
    left out and unit ones multiply nothing: the same values, fewer operations. Other
    entries are opaque ``Float`` values (one kernel for every tilt).

    Parameters
    ----------
    v : Array3
        A local-frame vector (or point).
    rotation : (3, 3) ndarray
        Local-to-world rotation.
    Float : type
        The Dr.Jit float type of the launch.

    Returns
    -------
    Array3
        ``v`` in the world frame.
    """
    import drjit as dr

    rot = np.asarray(rotation, dtype=float)
    comps = (v.x, v.y, v.z)

    def row(i):
        terms = [(1.0 if rot[i, j] == 1.0 else dr.opaque(Float, float(rot[i, j])), comps[j])
                 for j in range(3) if rot[i, j] != 0.0]
        scale, comp = terms[0]
        total = comp if isinstance(scale, float) else scale * comp
        for scale, comp in terms[1:]:
            total = total + comp if isinstance(scale, float) else dr.fma(scale, comp, total)
        return total

    return type(v)(row(0), row(1), row(2))


def thin_lens(p: DrJitArray, r: DrJitArray, vertex_distance: DrJitArray, inv_f: DrJitArray,
              aperture_radius2: DrJitArray) -> dict[str, DrJitArray]:
    """Through the thin lens onto the sensor (stage *lens*), world frame.

    Parameters
    ----------
    p, r : Array3
        Mirror point and reflected direction, world frame.
    vertex_distance, inv_f, aperture_radius2 : Float
        Lens plane ``z``, 1/f and the squared aperture radius (mm, 1/mm, mm²).

    Returns
    -------
    dict
        ``passes`` (travels toward the lens and meets its aperture) and the sensor hit
        ``h(i) = A + B i`` in upright image mm: ``Au, Av, Bu, Bv``.
    """
    import drjit as dr

    fma = dr.fma
    toward = r.z > 0.0
    inv_rz = 1.0 / dr.select(toward, r.z, 1.0)
    tl = (vertex_distance - p.z) * inv_rz
    lx, ly = fma(r.x, tl, p.x), fma(r.y, tl, p.y)
    in_ap = fma(lx, lx, ly * ly) <= aperture_radius2
    return {"passes": toward & in_ap, "Au": -lx, "Av": -ly,
            "Bu": fma(lx, inv_f, -r.x * inv_rz), "Bv": fma(ly, inv_f, -r.y * inv_rz)}


def _aim_points(lanes: Lanes, ua: DrJitArray, ub: DrJitArray) -> tuple[DrJitArray, DrJitArray]:
    """The lanes' aim-plane points: box, ellipse, or per lane for a mixed batch."""
    import drjit as dr

    val = lanes.value

    def in_box():
        return aim_box(ua, ub, val("a0"), val("a1"), val("b0"), val("b1"))

    def in_ellipse():
        return aim_ellipse(ua, ub, (val("ca"), val("cb")),
                           (val("m00"), val("m01"), val("m10"), val("m11")))

    if lanes.ellipse is None:  # a batch of both kinds
        (a_box, b_box), (a_ell, b_ell) = in_box(), in_ellipse()
        return (dr.select(lanes.is_ellipse, a_ell, a_box),
                dr.select(lanes.is_ellipse, b_ell, b_box))
    return in_ellipse() if lanes.ellipse else in_box()


def trace_lanes(geom: Geometry, lanes: Lanes, double: bool, time_dim: bool = False
                ) -> dict[str, DrJitArray]:
    """Trace the rays of ``lanes`` through every stage but the deposit.

    ``geom`` gives what every source shares (mirror, lens, rim); the chief ray, depth,
    margin and sampling domain are the lanes' own. Returns a dict of Dr.Jit arrays:
    ``landed`` (reaches the sensor through the rim and the aperture), ``landed_free``
    (would, without the rim), ``weight``, ``Au, Av, Bu, Bv`` (sensor hit ``A + B i``,
    upright image mm), ``a, b`` (aim-plane sample) and, with ``time_dim``, ``xi_t`` (a
    third low-discrepancy coordinate in [0, 1) for time: the samples are then R3's, else
    R2's).

    Parameters
    ----------
    geom : Geometry
        The optics (the first source's geometry, for a batch).
    lanes : Lanes
        The samples and their sources' values.
    double : bool
        Trace in float64.
    time_dim : bool, optional
        Draw the time coordinate ``xi_t`` too (default False: ``xi_t`` is None).

    Returns
    -------
    dict of str to Dr.Jit array
    """
    import drjit as dr

    _, Float, Array3 = array_types(double)
    coords = lattice_coordinates(lanes.index, lanes.shifts, R3 if time_dim else R2, Float)
    a, b = _aim_points(lanes, coords[0], coords[1])
    val = lanes.value
    o, d, weight = source_rays(
        a, b, Array3(val("w0"), val("w1"), val("w2")),
        Array3(val("e10"), val("e11"), val("e12")), Array3(val("e20"), val("e21"), val("e22")),
        Array3(val("p0"), val("p1"), val("p2")), val("inv_l"), val("margin"),
        None if lanes.infinite_depth else val("depth"))

    def op(x):  # compile once, update values
        return dr.opaque(Float, float(x))

    R, ok = op(geom.radius), op(1.0 + geom.conic)
    coeffs = [float(c) for c in geom.aspheric]
    t, hit = intersect_conic(o, d, R, ok)
    t = intersect_asphere(o, d, t, R, ok, coeffs)
    p = dr.fma(d, t, o)
    r2 = dr.fma(p.x, p.x, p.y * p.y)
    refl, d_dot_n = reflect(d, surface_normal(p, r2, R, ok, coeffs))
    front = hit & (d_dot_n < 0.0)
    inside = r2 <= op(geom.rim_radius ** 2 if math.isfinite(geom.rim_radius) else 3.0e38)
    lens = thin_lens(rotate(p, geom.rotation, Float), rotate(refl, geom.rotation, Float),
                     op(geom.vertex_distance), op(1.0 / geom.focal_length),
                     op(geom.aperture_radius ** 2))
    landed_free = front & lens.pop("passes")
    return {"landed": landed_free & inside, "landed_free": landed_free, "weight": weight,
            **lens, "a": a, "b": b, "xi_t": coords[2] if time_dim else None}
