"""Local optimisers on the unit cube: the gradient-based and simplex solver and pattern search.

Holds :func:`local` (``fmincon``'s role: L-BFGS-B, trust-constr or
Nelder-Mead, with finite-difference gradients whose stencil is one batch)
and :func:`pattern_search` (``patternsearch``'s role), with their private
bodies, which :mod:`estimation.search.optimisers` also runs as the local phase of a
hybrid. Points are in the normalised cube ``[0, 1]^n``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import optimize as _spo

from estimation.search.core import (Budget, LocalOptions, Objective, OptimResult, PatternSearchOptions, Progress,
    _centre_if_none, _drive, _Evaluator, _parse_options)

# --------------------------------------------------------------------------- #
# Local solver (fmincon's role)
# --------------------------------------------------------------------------- #


class _FiniteDifference:
    """Value and finite-difference gradient, the stencil evaluated as one batch."""

    def __init__(self, ev: _Evaluator, scheme: str, step: float | None) -> None:
        self.ev = ev
        self.scheme = scheme
        eps = np.finfo(float).eps
        self.step = step if step is not None else (math.sqrt(eps) if scheme == "forward" else eps ** (1 / 3))
        self._x: np.ndarray | None = None
        self._f = math.nan

    def _cached(self, x: np.ndarray) -> bool:
        return self._x is not None and np.array_equal(self._x, x)

    def value(self, x: np.ndarray) -> float:
        """Cost at ``x`` (batch of one, cached)."""
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        if not self._cached(x):
            self._x, self._f = x.copy(), self.ev.one(x)
        return self._f

    def value_and_grad(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """Cost and gradient at ``x``; one batch of n+1 (forward) or 2n+1 (central) points."""
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        points, combine = self._stencil(x)
        with_centre = not self._cached(x)
        if with_centre:
            points = np.vstack([x[None, :], points])
        f = self.ev(points)
        if with_centre:
            self._x, self._f, f = x.copy(), float(f[0]), f[1:]
        return self._f, combine(self._f, f)

    def grad(self, x: np.ndarray) -> np.ndarray:
        """Gradient only (used by trust-constr)."""
        return self.value_and_grad(x)[1]

    def _signed_steps(self, x: np.ndarray, reach: float) -> np.ndarray:
        """Step per coordinate, pointing inwards where ``x + reach*h`` leaves the cube."""
        h = np.full_like(x, self.step)
        h[x + reach * h > 1.0] *= -1.0
        return (x + h) - x  # the step actually representable

    def _stencil(self, x: np.ndarray) -> tuple[np.ndarray, Callable[[float, np.ndarray], np.ndarray]]:
        n = x.size
        eye = np.eye(n)
        if self.scheme == "forward":
            h = self._signed_steps(x, 1.0)
            return x + eye * h, lambda f0, f: (f - f0) / h
        h = np.full(n, self.step)
        h = (x + h) - x
        inside = (x - h >= 0.0) & (x + h <= 1.0)
        hs = self._signed_steps(x, 2.0)
        first = np.where(inside, x + h, x + hs)[None, :] * eye + x * (1 - eye)
        second = np.where(inside, x - h, x + 2 * hs)[None, :] * eye + x * (1 - eye)

        def combine(f0: float, f: np.ndarray) -> np.ndarray:
            fa, fb = f[:n], f[n:]
            central = (fa - fb) / (2 * h)
            one_sided = (-3 * f0 + 4 * fa - fb) / (2 * hs)
            return np.where(inside, central, one_sided)

        return np.vstack([first, second]), combine


def _scipy_callback(ev: _Evaluator) -> Callable[..., None]:
    def callback(intermediate_result: Any) -> None:
        ev.end_iteration()

    return callback


def _local_lbfgsb(ev: _Evaluator, x0: np.ndarray, o: LocalOptions) -> tuple[np.ndarray, float, str]:
    fd = _FiniteDifference(ev, o.fd, o.fd_step)
    res = _spo.minimize(
        fd.value_and_grad,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=_spo.Bounds(np.zeros(ev.n), np.ones(ev.n)),
        callback=_scipy_callback(ev),
        options={"maxiter": o.max_iter, "maxfun": 10**9, "gtol": o.gtol, "ftol": o.ftol},
    )
    return np.clip(res.x, 0.0, 1.0), float(res.fun), f"L-BFGS-B: {res.message}"


def _local_trust_constr(ev: _Evaluator, x0: np.ndarray, o: LocalOptions) -> tuple[np.ndarray, float, str]:
    fd = _FiniteDifference(ev, o.fd, o.fd_step)
    margin = 1e-9
    start = np.clip(x0, margin, 1.0 - margin)  # the interior-point method needs a strictly feasible start
    with warnings.catch_warnings():
        # BFGS skips its update when two successive gradients coincide and says so; harmless here.
        warnings.filterwarnings("ignore", message="delta_grad == 0.0", category=UserWarning)
        res = _spo.minimize(
            fd.value,
            start,
            jac=fd.grad,
            hess=_spo.BFGS(),
            method="trust-constr",
            bounds=_spo.Bounds(np.zeros(ev.n), np.ones(ev.n), keep_feasible=True),
            callback=_scipy_callback(ev),
            options={
                "maxiter": o.max_iter,
                "gtol": o.gtol,
                "xtol": o.xtol,
                # scipy's default barrier start (0.1) stops far from interior minima; start lower.
                "initial_barrier_parameter": 1e-3,
                "barrier_tol": 1e-10,
            },
        )
    x = np.clip(res.x, 0.0, 1.0)
    return x, fd.value(x), f"trust-constr: {res.message}"


def _local_nelder_mead(ev: _Evaluator, x0: np.ndarray, o: LocalOptions) -> tuple[np.ndarray, float, str]:
    """Bounded Nelder-Mead; reflection, expansion and both contractions in one batch."""
    step = np.where(x0 + 0.05 <= 1.0, 0.05, -0.05)
    simplex = np.vstack([x0, x0 + np.diag(step)])
    fs = ev(simplex)
    coeffs = np.array([1.0, 2.0, 0.5, -0.5])  # reflect, expand, outside / inside contraction
    for _ in range(o.max_iter):
        order = np.argsort(fs, kind="stable")
        simplex, fs = simplex[order], fs[order]
        if np.max(np.abs(fs - fs[0])) <= o.ftol and np.max(np.abs(simplex - simplex[0])) <= o.xtol:
            return simplex[0], float(fs[0]), "nelder-mead: simplex converged"
        centroid = simplex[:-1].mean(axis=0)
        trial = np.clip(centroid + coeffs[:, None] * (centroid - simplex[-1]), 0.0, 1.0)
        fr, fe, foc, fic = ev(trial)
        pick = _nelder_mead_choice(fs, fr, fe, foc, fic)
        if pick is None:
            simplex[1:] = simplex[0] + 0.5 * (simplex[1:] - simplex[0])
            fs[1:] = ev(simplex[1:])
        else:
            simplex[-1], fs[-1] = trial[pick], (fr, fe, foc, fic)[pick]
        ev.end_iteration()
    best = int(np.argmin(fs))
    return simplex[best], float(fs[best]), f"nelder-mead: max_iter ({o.max_iter}) reached"


def _nelder_mead_choice(fs: np.ndarray, fr: float, fe: float, foc: float, fic: float) -> int | None:
    """Index of the accepted trial point (0..3) or None for a shrink (Lagarias et al.)."""
    if fr < fs[0]:
        return 1 if fe < fr else 0
    if fr < fs[-2]:
        return 0
    if fr < fs[-1]:
        return 2 if foc <= fr else None
    return 3 if fic < fs[-1] else None


_LOCAL_SOLVERS = {"L-BFGS-B": _local_lbfgsb, "trust-constr": _local_trust_constr, "nelder-mead": _local_nelder_mead}


def _local_solve(ev: _Evaluator, x0: np.ndarray, o: LocalOptions) -> tuple[np.ndarray, float, str]:
    """Run the configured local solver from ``x0``; return its end point, cost, message."""
    return _LOCAL_SOLVERS[o.method](ev, x0, o)


def local(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """Bounded local minimisation with batched finite-difference gradients (``fmincon``'s role).

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``, ``U`` of shape ``(P, n)`` in the
        unit cube, ``f`` of shape ``(P,)``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        Start point in ``[0, 1]^n``; default the cube centre.
    seed : int, optional
        Recorded only (the solver is deterministic).
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every iteration; returning True stops.
    **options
        See :class:`LocalOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(LocalOptions, "local", options)

    def body(ev: _Evaluator, rng: np.random.Generator, x: np.ndarray | None) -> str:
        start = _centre_if_none(x, ev.n)
        return _local_solve(ev, start, o)[2]

    return _drive("local", fun, n, seed, budget, x0, callback, body)


# --------------------------------------------------------------------------- #
# Pattern search (GPS, 2n positive basis)
# --------------------------------------------------------------------------- #


def _pattern_body(ev: _Evaluator, x0: np.ndarray, o: PatternSearchOptions) -> str:
    n = ev.n
    directions = np.vstack([np.eye(n), -np.eye(n)])
    x, fx = x0.copy(), ev.one(x0)
    mesh = o.initial_mesh
    max_iter = o.max_iter if o.max_iter is not None else 1000 * n
    for _ in range(max_iter):
        poll = np.clip(x + mesh * directions, 0.0, 1.0)
        poll = poll[np.any(poll != x, axis=1)]  # projection can fold a poll point back onto x
        improved = False
        if poll.shape[0]:
            fp = ev(poll)
            best = int(np.argmin(fp))
            if fp[best] < fx:
                x, fx, improved = poll[best], float(fp[best]), True
        mesh = min(mesh * o.expansion, o.max_mesh) if improved else mesh * o.contraction
        ev.end_iteration()
        if mesh < o.mesh_tol:
            return f"pattern_search: mesh size {mesh:.3g} below mesh_tol"
    return f"pattern_search: max_iter ({max_iter}) reached"


def pattern_search(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """Generalised pattern search with a complete 2n coordinate poll per batch (``patternsearch``).

    Each iteration polls ``x +/- mesh * e_i`` (projected onto the cube) as one
    batch; a poll that improves on ``x`` moves to its best point and doubles
    the mesh, otherwise the mesh is halved (thesis 2.4.2.2).

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        Start point; default the cube centre.
    seed : int, optional
        Recorded only (the search is deterministic).
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every poll; returning True stops.
    **options
        See :class:`PatternSearchOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(PatternSearchOptions, "pattern_search", options)

    def body(ev: _Evaluator, rng: np.random.Generator, x: np.ndarray | None) -> str:
        return _pattern_body(ev, _centre_if_none(x, ev.n), o)

    return _drive("pattern_search", fun, n, seed, budget, x0, callback, body)
