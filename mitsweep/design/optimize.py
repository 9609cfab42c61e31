"""Choosing the exposure fractions τ: a local optimiser, a certified bound, brute force.

The problem (docs in :mod:`mitsweep.design`): over bins of widths ``Δi_k`` (mm), find
``τ`` minimising ``max_j MSE_j(τ)`` (``objective="worst"``) or the weighted mean
``Σ_j w_j MSE_j(τ)`` (``"mean"``; ``w`` in the simplex, uniform unless given: the design
weighs each field point by the image area it stands for) subject to

- the exposure: ``Σ_k τ_k = 1`` (the exposure ``T`` is fixed);
- the stage's velocity: ``v_k = Δi_k / (τ_k T) <= v_max``, i.e. ``τ_k >= Δi_k / (v_max T)``
  (linear);
- its acceleration: ``|v_{k+1} − v_k| <= a_max min(τ_k, τ_{k+1}) T`` at every inner knot,
  the velocity change made within the shorter of the two bins (as
  :func:`mitsweep.optics.motion_file.stage_kinematics` and the rig's plan measure it),
  imposed as the two smooth constraints ``|v_{k+1} − v_k| <= a_max τ_j T``, j = k, k+1.
  This is not linearised: it is imposed as it stands, non-convex, by the local
  optimiser; the convex bound drops it (a relaxation, so the bound stays a bound).

Local optimiser: SLSQP (deterministic: run on one BLAS thread) on ``x = τ / τ_lin`` (``x = 1`` is the uniform
sweep), the worst case in epigraph form (``min t`` s.t. ``MSE_j / MSE_0 <= t``), with
exact gradients, from a fixed set of starts (uniform, the relaxed problem's minimiser,
and two cosine-shaped ones); the best feasible result is kept and every start's value is
reported.

Certificate (:func:`certified_lower_bound`): the relaxed problem ``min max_j L_j(τ)``
(``L_j`` the convex bound of :mod:`mitsweep.design.objective`, acceleration dropped) is
solved, and its optimum bounded from below without trusting that solve: for any
weights ``λ`` in the simplex and any ``τ̄``, convexity gives
``min_Ω max_j L_j >= Σ_j λ_j L_j(τ̄) + min_{s ∈ Ω} Σ_j λ_j ∇L_j(τ̄)·(s − τ̄)``, and the
minimum of a linear function over ``Ω = {τ >= τ_min, Σ τ = 1}`` is at one of its N
vertices; the best ``λ`` is a small linear programme (HiGHS). The true optimum lies in
``[bound, optimised value]``. :func:`brute_force` checks the local optimiser against
exhaustive search on a small problem (the bank coarsened to a few bins).
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import linprog, minimize
from threadpoolctl import threadpool_limits

from .objective import WienerModel

__all__ = ["StageLimits", "Solution", "local_optimum", "certified_lower_bound", "brute_force",
           "OBJECTIVES", "stage_feasible"]

logger = logging.getLogger(__name__)

OBJECTIVES = ("worst", "mean")
#: The optimiser keeps this relative margin below the acceleration limit, so that its
#: active constraints pass :func:`mitsweep.optics.motion_file.check_motion_file`.
_MARGIN = 1e-7


@dataclass(frozen=True)
class StageLimits:
    """Exposure (s) and the stage's limits (mm/s, mm/s²).

    Attributes
    ----------
    exposure_s : float
        The fixed exposure T, s.
    max_velocity : float
        The stage's largest velocity, mm/s.
    acceleration : float
        The stage's acceleration, mm/s².
    """

    exposure_s: float
    max_velocity: float
    acceleration: float

    def tau_min(self, widths: np.ndarray) -> np.ndarray:
        """Smallest exposure fraction per bin: the bin crossed at ``max_velocity`` (a bound
        that SLSQP holds exactly, so it needs no margin).

        Parameters
        ----------
        widths : (N,) ndarray
            Widths ``Δi_k`` of the sweep's bins, mm.

        Returns
        -------
        (N,) ndarray
            ``Δi_k / (v_max T)``, a fraction of the exposure per bin.
        """
        return widths / (self.max_velocity * self.exposure_s)


@dataclass(frozen=True)
class Solution:
    """A τ and what it achieves.

    Attributes
    ----------
    tau : (N,) ndarray
        Exposure fraction per bin, summing to 1.
    value : float
        The objective reached: the largest (``"worst"``) or mean (``"mean"``) predicted
        MSE over field points × depths.
    mse : (J,) ndarray
        The predicted MSE at each of the model's J (depth, point) pairs.
    info : dict
        How it was found (:func:`local_optimum`: ``starts``, ``best_start``,
        ``iterations``, ``seconds``).
    """

    tau: np.ndarray
    value: float
    mse: np.ndarray
    info: dict


def _reduce(mse: np.ndarray, objective: str, weights: np.ndarray | None = None) -> float:
    if objective == "worst":
        return float(mse.max())
    return float(mse.mean() if weights is None else mse @ weights)


def _checked_weights(weights: ArrayLike | None, n_kernels: int) -> np.ndarray | None:
    """The mean objective's weights, normalised to sum to 1 (None: uniform)."""
    if weights is None:
        return None
    w = np.asarray(weights, dtype=float).ravel()
    if w.size != n_kernels or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights: must be {n_kernels} finite values >= 0, not all 0")
    return w / w.sum()


def _velocity_accel(tau, widths, limits: StageLimits):
    T = limits.exposure_s
    v = widths / (tau * T)
    a = np.diff(v) / (np.minimum(tau[:-1], tau[1:]) * T)
    return v, a


def stage_feasible(tau: ArrayLike, widths: ArrayLike, limits: StageLimits, *, rtol: float = 1e-6,
                   acceleration: bool = True) -> bool:
    """Whether τ sums to 1 and the stage can follow it (velocity, and acceleration
    unless ``acceleration`` is False).

    Parameters
    ----------
    tau : array_like
        (N,) exposure fraction per bin; every one must be > 0 and they must sum to 1
        (within 1e-9).
    widths : array_like
        (N,) widths of the sweep's bins, mm.
    limits : StageLimits
        The exposure and the stage's limits.
    rtol : float, optional
        Relative tolerance on the velocity and acceleration limits (default 1e-6).
    acceleration : bool, optional
        Check the acceleration limit too (default True); False checks the velocity only.

    Returns
    -------
    bool
        True when the stage can follow ``tau``.
    """
    tau = np.asarray(tau, dtype=float)
    if np.any(tau <= 0) or abs(tau.sum() - 1.0) > 1e-9:
        return False
    v, a = _velocity_accel(tau, widths, limits)
    return bool(v.max() <= limits.max_velocity * (1 + rtol)
                and (not acceleration or a.size == 0
                     or np.abs(a).max() <= limits.acceleration * (1 + rtol)))


def _accel_constraints(tau_lin, widths, limits: StageLimits):
    """SLSQP inequalities ``1 ∓ Δv_k / (a_max τ_j T) >= 0`` for j = k and k + 1 (the
    min-interval rule as smooth constraints) in x = τ/τ_lin, with their Jacobian."""
    T, A = limits.exposure_s, limits.acceleration * (1 - _MARGIN)
    n = tau_lin.size
    m = n - 1
    k = np.arange(m)

    def parts(z):
        x = z[:n]                                         # z may carry the epigraph t
        tau = tau_lin * x
        v = widths / (tau * T)
        dv = np.diff(v)
        dv_d0, dv_d1 = v[:-1] / x[:-1], -v[1:] / x[1:]    # ∂Δv_k/∂x_k, ∂Δv_k/∂x_{k+1}
        rows = []
        for j, own in ((k, 0), (k + 1, 1)):               # the interval dividing Δv_k
            c = A * T * tau[j]
            q = dv / c
            d0, d1 = dv_d0 / c, dv_d1 / c
            if own == 0:
                d0 = d0 - q / x[j]
            else:
                d1 = d1 - q / x[j]
            rows.append((q, d0, d1))
        return rows

    def fun(z):
        rows = parts(z)
        return np.concatenate([f(q) for q, _, _ in rows for f in (lambda q: 1 - q,
                                                                  lambda q: 1 + q)])

    def jac(z):
        J = np.zeros((4 * m, z.size))
        for r, (_, d0, d1) in enumerate(parts(z)):
            for sign, off in ((-1.0, (2 * r) * m), (1.0, (2 * r + 1) * m)):
                J[off + k, k] = sign * d0
                J[off + k, k + 1] = sign * d1
        return J

    return {"type": "ineq", "fun": fun, "jac": jac}


def _solve(value_grad, tau_lin, widths, limits, objective, x0, *, accel: bool,
           maxiter: int = 400, weights: np.ndarray | None = None):
    """SLSQP from ``x0``; returns (x, result). ``value_grad(tau) -> (J,), (J, N)``."""
    n = tau_lin.size
    x_lo = limits.tau_min(widths) / tau_lin
    memo: dict = {}

    def memo_value_grad(tau):  # SLSQP asks for a constraint and its Jacobian at the same point
        key = tau.tobytes()
        if memo.get("key") != key:
            memo["key"], memo["value"] = key, value_grad(tau)
        return memo["value"]

    v0, _ = memo_value_grad(tau_lin)
    scale = _reduce(v0, objective, weights)
    cons = [{"type": "eq", "fun": lambda z: np.array([tau_lin @ z[:n] - 1.0]),
             "jac": lambda z: np.concatenate([tau_lin, np.zeros(z.size - n)])[None, :]}]
    if accel and n > 1:
        cons.append(_accel_constraints(tau_lin, widths, limits))
    if objective == "worst":
        def f(z):
            return z[n]

        def fj(z):
            g = np.zeros(z.size)
            g[n] = 1.0
            return g

        def c(z):
            val, _ = memo_value_grad(tau_lin * z[:n])
            return z[n] - val / scale

        def cj(z):
            _, grad = memo_value_grad(tau_lin * z[:n])
            J = np.zeros((grad.shape[0], z.size))
            J[:, :n] = -grad * tau_lin / scale
            J[:, n] = 1.0
            return J

        cons.append({"type": "ineq", "fun": c, "jac": cj})
        z0 = np.concatenate([x0, [_reduce(memo_value_grad(tau_lin * x0)[0], "worst") / scale]])
        bounds = [(lo, None) for lo in x_lo] + [(None, None)]
    else:
        def f(z):
            val, _ = memo_value_grad(tau_lin * z)
            return _reduce(val, "mean", weights) / scale

        def fj(z):
            _, grad = memo_value_grad(tau_lin * z)
            g = grad.mean(axis=0) if weights is None else weights @ grad
            return g * tau_lin / scale

        z0 = np.asarray(x0, dtype=float)
        bounds = [(lo, None) for lo in x_lo]
    # SLSQP's linear algebra runs in the BLAS, whose threads split its products: with
    # OPENBLAS_NUM_THREADS 1 and 2 the same problem took 227 and 165 iterations to points
    # 2e-13 apart, and a start's end point can change (0.024535 / 0.024468 on the sphere at
    # 2 lux). One BLAS thread makes the result independent of the thread count and load.
    with threadpool_limits(limits=1, user_api="blas"):
        res = minimize(f, z0, jac=fj, bounds=bounds, constraints=cons, method="SLSQP",
                       options={"maxiter": maxiter, "ftol": 1e-12})
    x = np.maximum(res.x[:n], x_lo)
    x = x / (tau_lin @ x)
    return x, res


def _starts(n: int, x_lo: float) -> dict[str, np.ndarray]:
    k = (np.arange(n) + 0.5) / n
    out = {"uniform": np.ones(n)}
    for name, shape in (("ends", 1 + 0.5 * np.cos(2 * np.pi * k)),
                        ("middle", 1 - 0.5 * np.cos(2 * np.pi * k))):
        out[name] = np.maximum(shape, x_lo * 1.01)
    return out


def local_optimum(model: WienerModel, widths: ArrayLike, limits: StageLimits, *,
                  objective: str = "worst", extra_starts: dict | None = None,
                  acceleration: bool = True, weights: ArrayLike | None = None) -> Solution:
    """The best τ SLSQP finds from the fixed starts (module docstring), stage-feasible.

    ``acceleration=False`` drops the acceleration limit (a diagnostic: how much of the
    certificate's gap that constraint accounts for).

    Parameters
    ----------
    model : WienerModel
        The predicted MSE of every field point and depth as a function of τ.
    widths : array_like
        Widths of the sweep's bins, mm.
    limits : StageLimits
        The exposure and the stage's limits.
    objective : {"worst", "mean"}, optional
        Minimise the largest or the mean MSE over points × depths.
    extra_starts : dict, optional
        More starting points, name → τ.
    acceleration : bool, optional
        Enforce the acceleration limit.
    weights : array_like, optional
        The mean objective's weight of each of the model's J (depth, point) pairs
        (normalised; default uniform).

    Returns
    -------
    Solution
        ``info``: ``starts`` (start → objective value reached, None when infeasible),
        ``best_start``, ``iterations``, ``seconds``.
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective: must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    widths = np.asarray(widths, dtype=float)
    tau_lin = widths / widths.sum()
    w = _checked_weights(weights, model.n_kernels)
    t0 = time.perf_counter()
    x_lo = float((limits.tau_min(widths) / tau_lin).max())
    starts = _starts(widths.size, x_lo)
    for name, tau in (extra_starts or {}).items():
        starts[name] = np.maximum(np.asarray(tau, dtype=float) / tau_lin, x_lo * 1.01)
    best = None
    reached: dict = {}
    iterations = 0
    for name, x0 in starts.items():
        x, res = _solve(model.mse_and_grad, tau_lin, widths, limits, objective, x0,
                        accel=acceleration, weights=w)
        iterations += int(res.nit)
        tau = tau_lin * x
        ok = stage_feasible(tau, widths, limits, acceleration=acceleration)
        value = _reduce(model.mse(tau), objective, w)
        reached[name] = value if ok else None
        logger.debug("start %s: %s, value %.6g, feasible %s", name, res.message, value, ok)
        if ok and (best is None or value < best[1]):
            best = (tau, value, name)
    if best is None:  # the uniform sweep is feasible whenever the stage can run it
        raise RuntimeError("no start led to a stage-feasible profile")
    tau, value, name = best
    return Solution(tau=tau, value=value, mse=model.mse(tau),
                    info={"starts": reached, "best_start": name, "iterations": iterations,
                          "seconds": time.perf_counter() - t0})


def certified_lower_bound(model: WienerModel, widths: ArrayLike, limits: StageLimits, *,
                          objective: str = "worst", weights: ArrayLike | None = None
                          ) -> tuple[float, dict]:
    """A lower bound on ``min_τ objective(MSE(τ))`` over the feasible set (docstring).

    Parameters
    ----------
    model : WienerModel
        The predicted MSE of every field point and depth as a function of τ.
    widths : array_like
        Widths of the sweep's bins, mm.
    limits : StageLimits
        The exposure and the stage's limits.
    objective : {"worst", "mean"}, optional
        Minimise the largest or the mean MSE over points × depths.
    weights : array_like, optional
        The mean objective's weights, as :func:`local_optimum`'s.

    Returns
    -------
    bound : float
    info : dict
        ``relaxed_value`` (the relaxed problem's value at the solve's τ̄, an upper bound
        on the relaxed optimum), ``relaxed_tau``, ``seconds``.
    """
    widths = np.asarray(widths, dtype=float)
    tau_lin = widths / widths.sum()
    w = _checked_weights(weights, model.n_kernels)
    t0 = time.perf_counter()
    x, _ = _solve(model.bound_and_grad, tau_lin, widths, limits, objective,
                  np.ones(widths.size), accel=False, weights=w)
    tau_bar = tau_lin * x
    L, G = model.bound_and_grad(tau_bar)           # (J,), (J, N)
    tmin = limits.tau_min(widths)
    free = 1.0 - tmin.sum()
    # D[j, m] = ∇L_j(τ̄)·(s_m − τ̄), s_m = τ_min + free e_m: the Ω's vertices
    D = free * G + (G @ (tmin - tau_bar))[:, None]
    if objective == "mean":
        wm = np.full(L.size, 1.0 / L.size) if w is None else w
        bound = float(L @ wm + (wm @ D).min())
    else:
        J, N = D.shape
        # variables (λ_1..λ_J, z): maximise L·λ + z, z <= D[:, m]·λ for every m
        c = -np.concatenate([L, [1.0]])
        A_ub = np.hstack([-D.T, np.ones((N, 1))])
        res = linprog(c, A_ub=A_ub, b_ub=np.zeros(N),
                      A_eq=np.concatenate([np.ones(J), [0.0]])[None, :], b_eq=[1.0],
                      bounds=[(0, None)] * J + [(None, None)], method="highs")
        if not res.success:
            raise RuntimeError(f"certificate LP failed: {res.message}")
        lam = np.clip(res.x[:J], 0, None)
        lam /= lam.sum()
        # re-evaluate the bound at the LP's λ (not its reported value)
        bound = float(L @ lam + (lam @ D).min())
    return bound, {"relaxed_value": _reduce(L, objective, w), "relaxed_tau": tau_bar,
                   "seconds": time.perf_counter() - t0}


def _compositions(total: int, parts: int):
    """All tuples of ``parts`` non-negative integers summing to ``total``."""
    for bars in itertools.combinations(range(total + parts - 1), parts - 1):
        prev = -1
        out = []
        for b in bars:
            out.append(b - prev - 1)
            prev = b
        out.append(total + parts - 2 - prev)
        yield out


def brute_force(model: WienerModel, widths: ArrayLike, limits: StageLimits, *,
                objective: str = "worst", steps: int = 16, batch: int = 64,
                weights: ArrayLike | None = None) -> dict:
    """Exhaustive search on a lattice against the local optimiser, on a small problem.

    The lattice: ``τ = τ_min + (1 − Σ τ_min) q``, ``q`` every point of the simplex with
    coordinates in multiples of ``1/steps`` (C(steps + N − 1, N − 1) points), the
    stage-infeasible ones dropped. The local optimiser is run on the same problem from
    its usual starts and from the best lattice point.

    Parameters
    ----------
    model : WienerModel
        The predicted MSE of every field point and depth as a function of τ.
    widths : array_like
        Widths of the sweep's bins, mm.
    limits : StageLimits
        The exposure and the stage's limits.
    objective : {"worst", "mean"}, optional
        Minimise the largest or the mean MSE over points × depths.
    steps : int, optional
        Lattice resolution: coordinates in multiples of ``1/steps``.
    batch : int, optional
        Lattice points evaluated per vectorised batch.
    weights : array_like, optional
        The mean objective's weights, as :func:`local_optimum`'s.

    Returns
    -------
    dict
        ``lattice_points``, ``feasible_points``, ``lattice_best`` (value), ``lattice_best_tau``,
        ``local_value``, ``local_from_lattice_value``, ``lower_bound``, ``agrees``
        (``local_value <= lattice_best`` within 1e-9 relative: the optimiser did at least
        as well as exhaustive search), ``same_optimum`` (started from the best lattice
        point, the optimiser reaches the value it reaches from its own starts, within
        1e-6 relative), ``seconds``.
    """
    widths = np.asarray(widths, dtype=float)
    n = widths.size
    w = _checked_weights(weights, model.n_kernels)
    t0 = time.perf_counter()
    tmin = limits.tau_min(widths)
    free = 1.0 - tmin.sum()
    q = np.array(list(_compositions(int(steps), n)), dtype=float) / steps
    taus = tmin + free * q
    ok = np.array([stage_feasible(t, widths, limits) for t in taus])
    feas = taus[ok]
    values = np.empty(len(feas))
    for b in range(0, len(feas), batch):
        mse = model.mse(feas[b:b + batch])        # (B, J)
        values[b:b + batch] = mse.max(axis=1) if objective == "worst" else (
            mse.mean(axis=1) if w is None else mse @ w)
    k = int(np.argmin(values))
    local = local_optimum(model, widths, limits, objective=objective, weights=w)
    from_lattice = local_optimum(model, widths, limits, objective=objective,
                                 extra_starts={"lattice": feas[k]}, weights=w)
    bound, _ = certified_lower_bound(model, widths, limits, objective=objective, weights=w)
    best = float(values[k])
    refined = from_lattice.info["starts"].get("lattice")
    return {"bins": n, "steps": int(steps), "lattice_points": int(len(taus)),
            "feasible_points": int(len(feas)), "lattice_best": best,
            "lattice_best_tau": feas[k].tolist(), "local_value": local.value,
            "local_from_lattice_value": refined,
            "lower_bound": bound,
            "agrees": bool(local.value <= best * (1 + 1e-9)),
            "same_optimum": bool(refined is not None
                                 and abs(refined - local.value) <= 1e-6 * local.value),
            "seconds": time.perf_counter() - t0}
