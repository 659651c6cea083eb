"""Local searches shared by every estimation engine: the recorded optimiser run, the least-squares polish,
and the staged least squares with budgets that stop on progress.

- :class:`Recorder` wraps a batched objective and keeps every evaluated point;
- :func:`optimise` runs one optimiser of :mod:`estimation.search.optimisers` on an approach's ``cost_batch``;
- :func:`least_squares_polish` is a trust-region least squares on an approach's residuals (batched Jacobian);
- :func:`batched_least_squares` is a Levenberg-Marquardt from many starts at once (one batch per iteration);
- :func:`staged_least_squares` runs a trust-region least squares per stage of a continuation (any residual
  function, e.g. an FMU run per evaluation), each stage stopping when it converges, when its best cost stops
  falling (progress), or at a cap of evaluations; it reports the evaluations of every stage.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation.search.optimisers import Budget, OptimResult, minimize

__all__ = ["Recorder", "optimise", "least_squares_polish", "batched_least_squares", "PolishResult",
           "staged_least_squares", "profile_scan", "sloppy_parameters", "sloppiest_parameter", "STALL_FRACTION", "STALL_SPAN"]

#: A stage stops when its best cost fell by less than this fraction over its last ``STALL_SPAN (n + 1)`` evaluations.
STALL_FRACTION = 1e-4
STALL_SPAN = 4


class Recorder:
    """Wrap a batched objective and keep every evaluated point and cost (for minima analysis)."""

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray], keep: int = 200_000):
        self.fun = fun
        self.U: list[np.ndarray] = []
        self.f: list[np.ndarray] = []
        self.keep = keep
        self.count = 0

    def __call__(self, U: np.ndarray) -> np.ndarray:
        f = np.asarray(self.fun(U), float)
        if self.count < self.keep:
            self.U.append(np.array(U, float, copy=True))
            self.f.append(f.copy())
        self.count += len(f)
        return f

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.U:
            return np.zeros((0, 0)), np.zeros(0)
        return np.concatenate(self.U), np.concatenate(self.f)


def optimise(approach: Any, method: str, seed: int, budget: Budget, options: Mapping[str, Any] | None = None,
             x0: Any = None) -> tuple[OptimResult, Recorder]:
    """Run one optimiser on an approach's ``cost_batch`` with a recording wrapper."""
    rec = Recorder(approach.cost_batch)
    res = minimize(rec, approach.n, method=method, seed=seed, budget=budget, options=dict(options or {}), x0=x0)
    return res, rec


def least_squares_polish(approach: Any, x0: np.ndarray, max_nfev: int = 60, step: float = 1e-6,
                         max_time_s: float | None = None) -> dict[str, Any]:
    """Trust-region least squares on the approach's residuals from ``x0`` (Jacobian-scaled steps).

    The sum of squared log-magnitude errors (4.21) is a least-squares cost;
    a Gauss-Newton trust region with ``x_scale="jac"`` moves weakly
    sensitive parameters (the winding resistance) that a quasi-Newton
    method on the summed cost leaves where they are. The Jacobian is one
    batched forward-difference population per iteration.

    Returns
    -------
    dict
        ``x`` (unit cube), ``fun`` (sum of squares), ``nfev`` (points), ``message``.
    """
    from scipy.optimize import least_squares

    n = approach.n
    count = {"points": 0}
    t0 = time.perf_counter()

    def res(u: np.ndarray) -> np.ndarray:
        count["points"] += 1
        return approach.residuals(np.clip(u, 0, 1)[None])[0]

    def jac(u: np.ndarray) -> np.ndarray:
        h = np.where(u + step <= 1, step, -step)
        pts = np.clip(np.vstack([u, u + np.diag(h)]), 0, 1)
        r = approach.residuals(pts)
        count["points"] += n + 1
        if max_time_s is not None and time.perf_counter() - t0 > max_time_s:
            raise _Timeout
        return ((r[1:] - r[0]) / h[:, None]).T

    x = np.clip(np.asarray(x0, float), 0, 1)
    try:
        out = least_squares(res, x, jac=jac, bounds=(0, 1), x_scale="jac", method="trf", ftol=1e-15, xtol=1e-15,
                            gtol=1e-15, max_nfev=max_nfev)
        xb, msg = out.x, out.message
    except _Timeout:
        xb, msg = x, "time limit"
    r = approach.residuals(xb[None])[0]
    f = float(np.sum(r ** 2))
    r0 = approach.residuals(x[None])[0]
    if float(np.sum(r0 ** 2)) < f:
        xb, f = x, float(np.sum(r0 ** 2))
    return {"x": xb, "fun": f, "nfev": count["points"], "message": msg}


class _Timeout(Exception):
    pass


def sloppy_parameters(approach: Any, x: np.ndarray, count: int = 1, step: float = 1e-6) -> list[int]:
    """Indices of the ``count`` parameters the residuals determine worst at ``x`` (unit cube), worst first.

    Ranked by the diagonal of ``(J^T J)^-1``, ``J`` the residuals' Jacobian in the
    unit cube: the parameters that move furthest along the directions in which
    the cost changes least. Those are the ones a gradient method leaves on a
    plateau (a log-scaled value whose effect fades as it tends to zero, traded
    against others) and the ones :func:`profile_scan` should step.
    """
    u = np.clip(np.asarray(x, float), 0, 1)
    h = np.where(u + step <= 1, step, -step)
    r = approach.residuals(np.clip(np.vstack([u, u + np.diag(h)]), 0, 1))
    J = ((r[1:] - r[0]) / h[:, None]).T
    _, sv, vt = np.linalg.svd(J, full_matrices=False)
    sv = np.maximum(sv, 1e-12 * max(float(sv[0]), 1e-300))  # a null direction counts as nearly free, not as absent
    var = np.sum((vt.T / sv[None, :]) ** 2, axis=1)
    return [int(i) for i in np.argsort(-var)[: max(int(count), 1)]]


def sloppiest_parameter(approach: Any, x: np.ndarray, step: float = 1e-6) -> int:
    """The worst-determined parameter at ``x`` (:func:`sloppy_parameters` with ``count=1``)."""
    return sloppy_parameters(approach, x, 1, step)[0]


def profile_scan(approach: Any, x: np.ndarray, index: int, points: int = 13, max_nfev: int = 40
                 ) -> dict[str, Any]:
    """Profile of the cost along one parameter: that parameter stepped over its range, the others refitted.

    From ``x`` the parameter ``index`` is moved in ``points`` steps to each end of
    the unit interval; at each step the other parameters are refitted by trust-region
    least squares (warm-started from the previous step's fit). The lowest point of the
    profile is then polished with every parameter free (:func:`least_squares_polish`).
    This crosses plateaus and curved valleys that stop a local method (the profile
    likelihood of Raue et al., Bioinformatics 25 (2009) 1923).

    Returns
    -------
    dict
        ``x``, ``fun`` (sum of squares), ``nfev``, ``profile`` (list of (unit value, sum of squares)).
    """
    from scipy.optimize import least_squares

    u0 = np.clip(np.asarray(x, float), 0, 1)
    free = [j for j in range(approach.n) if j != index]
    count = {"points": 0}
    profile: list[tuple[float, float]] = []
    best = (float(np.sum(approach.residuals(u0[None])[0] ** 2)), u0)

    def fit(u: np.ndarray, value: float) -> np.ndarray:
        def res(z: np.ndarray) -> np.ndarray:
            v = u.copy()
            v[free], v[index] = z, value
            count["points"] += 1
            return approach.residuals(np.clip(v, 0, 1)[None])[0]

        out = least_squares(res, u[free], bounds=(0, 1), x_scale=1.0, diff_step=1e-6, max_nfev=max_nfev)
        v = u.copy()
        v[free], v[index] = out.x, value
        return v

    grid = np.linspace(0.0, 1.0, points + 2)[1:-1]
    for side in (grid[grid > u0[index]], grid[grid < u0[index]][::-1]):
        u = u0.copy()
        for value in side:
            u = fit(u, float(value))
            f = float(np.sum(approach.residuals(u[None])[0] ** 2))
            profile.append((float(value), f))
            if f < best[0]:
                best = (f, u.copy())
    pol = least_squares_polish(approach, best[1], max_nfev=max_nfev)
    fun, xb = (pol["fun"], np.asarray(pol["x"])) if pol["fun"] <= best[0] else best
    return {"x": xb, "fun": float(fun), "nfev": count["points"] + int(pol["nfev"]), "profile": sorted(profile)}


def batched_least_squares(residuals: Callable[[np.ndarray], np.ndarray], X0: np.ndarray, iterations: int = 30,
                          step: float = 1e-6, max_time_s: float | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Levenberg-Marquardt in the unit cube from many starts at once (one batch of residuals per step).

    Every iteration evaluates the residuals at each start and its ``n``
    forward-difference neighbours in one batch, solves each start's damped
    normal equations ``(J^T J + lambda diag J^T J) d = -J^T r`` (Marquardt's
    scaling), and keeps a step only where it lowers that start's sum of
    squares (``lambda`` falls by 3 after a kept step, rises by 4 after a
    rejected one). A cost with many narrow basins (the alias branches of a
    record's ringing modes) is explored this way at the price of one
    population per iteration, where one local solve per start would pay the
    call overhead per point.

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, m)`` for unit-cube points ``U`` ``(P, n)``; non-finite rows count as infinite cost.
    X0 : numpy.ndarray
        ``(S, n)`` starts in the unit cube.
    iterations : int
        Iterations of every start.
    step : float
        Forward-difference step (unit cube; taken inwards at the upper face).
    max_time_s : float, optional
        Wall-time limit, s.

    Returns
    -------
    X : numpy.ndarray
        ``(S, n)`` end points.
    cost : numpy.ndarray
        ``(S,)`` their sums of squares.
    nfev : int
        Points evaluated.
    """
    t0 = time.perf_counter()
    X = np.clip(np.asarray(X0, float), 0.0, 1.0)
    S, n = X.shape

    def sse(R: np.ndarray) -> np.ndarray:
        c = np.sum(R ** 2, axis=1)
        return np.where(np.isfinite(c), c, np.inf)

    R = np.asarray(residuals(X), float)
    cost = sse(R)
    nfev = S
    lam = np.full(S, 1e-3)
    eye = np.eye(n)
    for _ in range(int(iterations)):
        if max_time_s is not None and time.perf_counter() - t0 > max_time_s:
            break
        h = np.where(X + step <= 1.0, step, -step)  # (S, n)
        pts = X[:, None, :] + h[:, :, None] * eye[None]  # (S, n, n): start s, column j
        Rj = np.asarray(residuals(pts.reshape(S * n, n)), float).reshape(S, n, -1)
        nfev += S * n
        with np.errstate(all="ignore"):
            J = np.swapaxes((Rj - R[:, None, :]) / h[:, :, None], 1, 2)  # (S, m, n)
            ok = np.all(np.isfinite(J), axis=(1, 2)) & np.isfinite(cost)
            J = np.where(ok[:, None, None], J, 0.0)
            Rf = np.where(ok[:, None], R, 0.0)
            G = np.einsum("smi,smj->sij", J, J)
            g = np.einsum("smi,sm->si", J, Rf)
            # a value on a face that the descent would push outwards stays there (active set): the others move
            held = ((X <= 0.0) & (g > 0)) | ((X >= 1.0) & (g < 0))
            G = np.where(held[:, :, None] | held[:, None, :], 0.0, G)
            g = np.where(held, 0.0, g)
            d = np.where(held, 1.0, np.diagonal(G, axis1=1, axis2=2))
            M = G + lam[:, None, None] * (d[:, :, None] * eye[None] + 1e-12 * eye[None]) + held[:, :, None] * eye[None]
            try:
                D = -np.linalg.solve(M, g[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                D = -np.stack([np.linalg.lstsq(Mi, gi, rcond=None)[0] for Mi, gi in zip(M, g)])
        D = np.where(ok[:, None] & np.all(np.isfinite(D), axis=1)[:, None], D, 0.0)
        Xt = np.clip(X + D, 0.0, 1.0)
        Rt = np.asarray(residuals(Xt), float)
        nfev += S
        ct = sse(Rt)
        better = ct < cost
        X = np.where(better[:, None], Xt, X)
        R = np.where(better[:, None], Rt, R)
        cost = np.where(better, ct, cost)
        lam = np.clip(np.where(better, lam / 3.0, lam * 4.0), 1e-12, 1e12)
    return X, cost, nfev


@dataclass
class PolishResult:
    """Outcome of :func:`least_squares_polish` (the fields an :class:`OptimResult` row uses)."""

    x: np.ndarray
    fun: float
    nfev: int
    message: str
    wall_s: float = 0.0


class _Spent(Exception):
    pass


class _Stalled(Exception):
    pass


class _Settled(Exception):
    pass


def staged_least_squares(residual: Callable[[np.ndarray, Any], tuple[np.ndarray, float]], x0: np.ndarray,
                         stages: Sequence[Any], cap: int, counter: Callable[[], int],
                         label: Callable[[Any], str] = str, diff_step: float = 1e-5, finish: bool = True,
                         report: Callable[[str, int, float], None] | None = None,
                         settled: Callable[[Any, np.ndarray, float, float], bool] | None = None) -> dict[str, Any]:
    """Trust-region least squares in the unit cube, one per stage, each starting where the last ended.

    Every stage but the last (every stage when ``finish`` is false) also stops when its best cost fell by
    less than :data:`STALL_FRACTION` over its last ``STALL_SPAN (n + 1)`` evaluations; the last runs to the
    minimum (or the cap): near the noise its cost hardly falls while the values still move.

    Parameters
    ----------
    residual : callable
        ``residual(x, stage) -> (r, cost)``: residual vector and cost of a unit-cube point for a stage.
    x0 : numpy.ndarray
        ``(n,)`` start in the unit cube.
    stages : sequence
        The stages, passed to ``residual`` as they are.
    cap : int
        At most this many evaluations per stage (as counted by ``counter``).
    counter : callable
        The evaluations made so far (e.g. FMU runs).
    label : callable
        Text of a stage for the messages.
    diff_step : float
        Finite-difference step of the two-point Jacobian (unit cube).
    finish : bool
        Run the last stage to its minimum (no stop on progress).
    report : callable, optional
        ``report(stage text, runs of the stage, best cost)`` after every evaluation (progress lines).
    settled : callable, optional
        ``settled(stage, r_best, cost_then, cost_now) -> bool``: also stop a stage when this says that the fall
        of the best cost over the last ``STALL_SPAN (n + 1)`` evaluations is within the noise (e.g. less than
        one chi-square unit at a residual that is the record's noise).

    Returns
    -------
    dict
        ``x``, ``cost`` (the last stage's best), ``message`` (one clause per stage: converged, stopped on
        progress or at the cap), ``per_stage`` [{``stage``, ``runs``, ``cost``}].
    """
    from scipy.optimize import least_squares

    x = np.clip(np.asarray(x0, float), 0.0, 1.0)
    span = STALL_SPAN * (x.size + 1)
    messages, per_stage = [], []
    best: dict[str, Any] = {"x": x.tolist(), "cost": math.inf}
    for k, stage in enumerate(stages):
        stalls = k < len(stages) - 1 or not finish
        start = counter()
        best = {"x": [float(v) for v in x], "cost": math.inf, "r": None}
        trace: list[float] = []

        def fun(z: np.ndarray, stage: Any = stage, start: int = start, stalls: bool = stalls) -> np.ndarray:
            if counter() - start >= cap:
                raise _Spent
            if (stalls and len(trace) > span
                    and trace[-1] > trace[-1 - span] * (1.0 - STALL_FRACTION)):
                raise _Stalled
            if (settled is not None and len(trace) > span and best["r"] is not None
                    and settled(stage, best["r"], trace[-1 - span], trace[-1])):
                raise _Settled
            r, c = residual(z, stage)
            if c < best["cost"]:
                best["x"], best["cost"], best["r"] = [float(v) for v in z], float(c), r
            trace.append(best["cost"])
            if report is not None:
                report(label(stage), counter() - start, best["cost"])
            return r

        text = label(stage)
        try:
            sol = least_squares(fun, x, jac="2-point", bounds=(0.0, 1.0), method="trf", diff_step=diff_step,
                                x_scale="jac", ftol=1e-12, xtol=1e-10, gtol=1e-12, max_nfev=10 * cap)
            messages.append(f"{text}: {sol.message}")
        except _Spent:
            messages.append(f"{text}: stopped at the cap of {cap} runs")
        except _Stalled:
            messages.append(f"{text}: stopped on progress (cost fell < {STALL_FRACTION:g} over {span} runs)")
        except _Settled:
            messages.append(f"{text}: stopped at the noise (cost fell within it over {span} runs)")
        if not math.isfinite(best["cost"]):
            best["cost"] = float(residual(np.asarray(best["x"]), stage)[1])
        x = np.asarray(best["x"], float)
        per_stage.append({"stage": text, "runs": counter() - start, "cost": best["cost"]})
    return {"x": best["x"], "cost": best["cost"], "message": "; then ".join(messages), "per_stage": per_stage}
