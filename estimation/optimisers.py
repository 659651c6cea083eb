"""Batched optimisers on the unit cube: local, pattern search, multistart, GA, PSO, hybrids.

The thesis (section 2.4.2) estimated winding parameters with MATLAB's
``fmincon``, ``patternsearch``, ``GlobalSearch``, ``ga`` and ``particleswarm``
(sections 4.1.3, 4.2.4 and 5.2.1 describe how: GA/PSO populations of 50 to
1000, PSO followed by an ``fmincon`` refinement, seeds 1 to 5). This module
provides the same family of searches with one difference that drives the
design: **the objective is evaluated for a whole batch of points at once**.

Every optimiser works in the normalised unit cube ``[0, 1]^n`` (the parameter
layer maps it to physical values) and calls the objective as::

    fun(U) -> f        # U: (P, n) array of points, f: (P,) array of costs

A population, a pattern-search poll or a finite-difference gradient stencil is
one call. ``NaN`` costs are treated as ``+inf`` (infeasible point).

Public API
----------
- :class:`Budget`, :class:`OptimResult`, :class:`Progress`
- :func:`local` (``fmincon``), :func:`pattern_search` (``patternsearch``),
  :func:`multistart` (``GlobalSearch``), :func:`genetic` (``ga``),
  :func:`particle_swarm` (``particleswarm``), :func:`cma_es` (CMA-ES, the
  ``cma`` package), :func:`hybrid` (global then
  local), and the dispatcher :func:`minimize`.
- Option containers :class:`LocalOptions`, :class:`PatternSearchOptions`,
  :class:`MultistartOptions`, :class:`GeneticOptions`,
  :class:`ParticleSwarmOptions` (their fields are the accepted ``**options``).

Every stochastic choice comes from one :class:`numpy.random.Generator` made
from ``seed``: the same seed, objective and budget (without ``max_time_s``)
give an identical result.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from scipy import optimize as _spo

__all__ = [
    "Budget",
    "OptimResult",
    "Progress",
    "LocalOptions",
    "PatternSearchOptions",
    "MultistartOptions",
    "GeneticOptions",
    "ParticleSwarmOptions",
    "CMAESOptions",
    "METHODS",
    "ALIASES",
    "local",
    "pattern_search",
    "multistart",
    "genetic",
    "particle_swarm",
    "cma_es",
    "hybrid",
    "minimize",
]

Objective = Callable[[np.ndarray], np.ndarray]


# --------------------------------------------------------------------------- #
# Budget, result, progress
# --------------------------------------------------------------------------- #


@dataclass(frozen=True)
class Budget:
    """Limits shared by every optimiser; any one reached stops the search.

    Limits are checked before each batch, so ``max_evals`` is exceeded by less
    than one batch and ``max_time_s`` by less than one batch's duration. The
    first batch is always evaluated.

    Parameters
    ----------
    max_evals : int, optional
        Maximum number of objective evaluations (points, not calls).
    max_time_s : float, optional
        Wall-clock limit, s.
    target : float, optional
        Stop as soon as a cost ``<= target`` has been seen (MATLAB's
        ``ObjectiveLimit`` / ``FitnessLimit``).
    """

    max_evals: int | None = None
    max_time_s: float | None = None
    target: float | None = None

    def __post_init__(self) -> None:
        if self.max_evals is not None and (not _is_int(self.max_evals) or self.max_evals < 1):
            raise ValueError(f"Budget: max_evals must be an integer >= 1, got {self.max_evals!r}")
        if self.max_time_s is not None and not (_is_real(self.max_time_s) and self.max_time_s > 0):
            raise ValueError(f"Budget: max_time_s must be a positive finite number, got {self.max_time_s!r}")
        if self.target is not None and not (_is_real(self.target) and not math.isnan(self.target)):
            raise ValueError(f"Budget: target must be a number, got {self.target!r}")


@dataclass(frozen=True)
class Progress:
    """State handed to a ``callback`` after every iteration.

    Attributes
    ----------
    nit : int
        Iterations completed (generations, polls, local-solver iterations).
    nfev : int
        Objective evaluations so far.
    x : numpy.ndarray
        Best point so far, ``(n,)``, unit cube (a copy).
    fun : float
        Best cost so far.
    wall_s : float
        Elapsed time, s.
    """

    nit: int
    nfev: int
    x: np.ndarray
    fun: float
    wall_s: float


@dataclass
class OptimResult:
    """Outcome of one optimisation.

    Attributes
    ----------
    x : numpy.ndarray
        Best point evaluated, ``(n,)``, in the unit cube.
    fun : float
        Cost at ``x``.
    nfev : int
        Objective evaluations (points).
    nit : int
        Iterations (generations, polls, local-solver iterations; summed over
        phases for :func:`multistart` and :func:`hybrid`).
    wall_s : float
        Elapsed time, s.
    method : str
        Canonical method name (``"particle_swarm+local"`` for a hybrid).
    seed : int
        Seed actually used (drawn from OS entropy when none was given), so
        any run can be repeated.
    history : list of (int, float)
        ``(nfev, best cost)`` each time the best cost improved, and at the end.
    message : str
        Why the search stopped.
    ncalls : int
        Batched calls of the objective (``nfev / ncalls`` is the mean batch).
    info : dict
        Method-specific counters (e.g. multistart ``local_runs``,
        ``rejected_basin``, ``rejected_threshold``).
    """

    x: np.ndarray
    fun: float
    nfev: int
    nit: int
    wall_s: float
    method: str
    seed: int
    history: list[tuple[int, float]]
    message: str
    ncalls: int = 0
    info: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (lists and Python scalars only)."""
        return {
            "x": [float(v) for v in self.x],
            "fun": float(self.fun),
            "nfev": int(self.nfev),
            "nit": int(self.nit),
            "wall_s": float(self.wall_s),
            "method": self.method,
            "seed": int(self.seed),
            "history": [[int(k), float(v)] for k, v in self.history],
            "message": self.message,
            "ncalls": int(self.ncalls),
            "info": _plain(self.info),
        }


def _plain(value: Any) -> Any:
    """Convert numpy scalars/arrays inside containers to Python objects."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


# --------------------------------------------------------------------------- #
# Option containers and validation helpers
# --------------------------------------------------------------------------- #


def _is_int(value: Any) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _is_real(value: Any) -> bool:
    numeric = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
    return numeric and math.isfinite(value)


def _need_int(method: str, name: str, value: Any, minimum: int, optional: bool = False) -> None:
    if value is None and optional:
        return
    if not _is_int(value) or value < minimum:
        raise ValueError(f"{method}: option {name!r} must be an integer >= {minimum}, got {value!r}")


def _need_real(
    method: str, name: str, value: Any, low: float | None = None, high: float | None = None, open_low: bool = False
) -> None:
    ok = _is_real(value)
    if ok and low is not None:
        ok = value > low if open_low else value >= low
    if ok and high is not None:
        ok = value <= high
    if not ok:
        lo = "" if low is None else (f" > {low}" if open_low else f" >= {low}")
        hi = "" if high is None else f" and <= {high}"
        raise ValueError(f"{method}: option {name!r} must be a finite number{lo}{hi}, got {value!r}")


def _need_choice(method: str, name: str, value: Any, choices: tuple[str, ...]) -> None:
    if value not in choices:
        raise ValueError(f"{method}: option {name!r} must be one of {', '.join(map(repr, choices))}, got {value!r}")


def _parse_options(cls: type, method: str, options: Mapping[str, Any] | None) -> Any:
    """Build option container ``cls`` from a mapping, naming unknown keys."""
    options = dict(options or {})
    valid = [f.name for f in fields(cls)]
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ValueError(f"{method}: unknown option {unknown[0]!r} (valid options: {', '.join(sorted(valid))})")
    return cls(**options)


@dataclass(frozen=True)
class LocalOptions:
    """Options of :func:`local` (MATLAB ``fmincon``'s role).

    Attributes
    ----------
    method : {"L-BFGS-B", "trust-constr", "nelder-mead"}
        Bounded quasi-Newton (default), trust-region interior point with BFGS
        Hessian, or a bounded Nelder-Mead simplex.
    fd : {"forward", "central"}
        Finite-difference gradient: ``n + 1`` or ``2n + 1`` points, one batch.
    fd_step : float, optional
        Difference step in unit-cube units; default ``sqrt(eps)`` (forward)
        or ``eps**(1/3)`` (central), as MATLAB's ``FiniteDifferenceStepSize``.
    max_iter : int
        Iteration limit of the local solver.
    gtol : float
        Projected-gradient tolerance (L-BFGS-B, trust-constr).
    ftol : float
        Relative cost-decrease tolerance (L-BFGS-B); cost spread (Nelder-Mead).
    xtol : float
        Step tolerance (trust-constr, Nelder-Mead simplex size).
    """

    method: str = "L-BFGS-B"
    fd: str = "forward"
    fd_step: float | None = None
    max_iter: int = 1000
    gtol: float = 1e-6
    ftol: float = 1e-12
    xtol: float = 1e-10

    def __post_init__(self) -> None:
        m = "local"
        _need_choice(m, "method", self.method, ("L-BFGS-B", "trust-constr", "nelder-mead"))
        _need_choice(m, "fd", self.fd, ("forward", "central"))
        if self.fd_step is not None:
            _need_real(m, "fd_step", self.fd_step, 0.0, 0.1, open_low=True)
        _need_int(m, "max_iter", self.max_iter, 1)
        for name in ("gtol", "ftol", "xtol"):
            _need_real(m, name, getattr(self, name), 0.0)


@dataclass(frozen=True)
class PatternSearchOptions:
    """Options of :func:`pattern_search` (MATLAB ``patternsearch``, GPS 2N).

    Attributes
    ----------
    initial_mesh : float
        First mesh size, unit-cube units.
    expansion : float
        Mesh factor after a successful poll (MATLAB ``MeshExpansionFactor``).
    contraction : float
        Mesh factor after an unsuccessful poll (``MeshContractionFactor``).
    mesh_tol : float
        Stop when the mesh is smaller (``MeshTolerance``).
    max_mesh : float
        Upper limit of the mesh size.
    max_iter : int, optional
        Poll limit; default ``1000 * n``.
    """

    initial_mesh: float = 0.25
    expansion: float = 2.0
    contraction: float = 0.5
    mesh_tol: float = 1e-6
    max_mesh: float = 1.0
    max_iter: int | None = None

    def __post_init__(self) -> None:
        m = "pattern_search"
        _need_real(m, "initial_mesh", self.initial_mesh, 0.0, 1.0, open_low=True)
        _need_real(m, "expansion", self.expansion, 1.0)
        _need_real(m, "contraction", self.contraction, 0.0, 1.0, open_low=True)
        if self.contraction >= 1.0:
            raise ValueError(f"pattern_search: option 'contraction' must be < 1, got {self.contraction!r}")
        _need_real(m, "mesh_tol", self.mesh_tol, 0.0, open_low=True)
        _need_real(m, "max_mesh", self.max_mesh, 0.0, open_low=True)
        _need_int(m, "max_iter", self.max_iter, 1, optional=True)


@dataclass(frozen=True)
class MultistartOptions:
    """Options of :func:`multistart` (MATLAB ``GlobalSearch``; defaults as MATLAB).

    Attributes
    ----------
    n_trial : int
        Trial start points (Latin hypercube), evaluated as one batch
        (``NumTrialPoints``).
    n_stage_one : int
        The best of the first ``n_stage_one`` trial points is always run
        (``NumStageOnePoints``).
    distance_factor : float
        A point within ``distance_factor * radius`` of a basin centre is in
        that basin (``DistanceThresholdFactor``).
    radius_factor : float
        After ``max_wait`` consecutive points fall in a basin its radius is
        multiplied by ``1 - radius_factor`` (``BasinRadiusFactor``).
    penalty_factor : float
        After ``max_wait`` consecutive points score at or above the threshold
        it rises by ``penalty_factor * (1 + |threshold|)``
        (``PenaltyThresholdFactor``).
    max_wait : int
        ``MaxWaitCycle``.
    max_local_runs : int, optional
        Stop after this many local runs.
    same_minimum_tol : float
        Local solutions closer than this (unit cube) share a basin.
    local_options : dict
        Options for the local solver (see :class:`LocalOptions`).
    """

    n_trial: int = 1000
    n_stage_one: int = 200
    distance_factor: float = 0.75
    radius_factor: float = 0.2
    penalty_factor: float = 0.2
    max_wait: int = 20
    max_local_runs: int | None = None
    same_minimum_tol: float = 1e-4
    local_options: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = "multistart"
        _need_int(m, "n_trial", self.n_trial, 1)
        _need_int(m, "n_stage_one", self.n_stage_one, 1)
        if self.n_stage_one > self.n_trial:
            raise ValueError(
                f"multistart: option 'n_stage_one' ({self.n_stage_one}) exceeds 'n_trial' ({self.n_trial})"
            )
        _need_real(m, "distance_factor", self.distance_factor, 0.0)
        _need_real(m, "radius_factor", self.radius_factor, 0.0, 1.0)
        _need_real(m, "penalty_factor", self.penalty_factor, 0.0)
        _need_int(m, "max_wait", self.max_wait, 1)
        _need_int(m, "max_local_runs", self.max_local_runs, 1, optional=True)
        _need_real(m, "same_minimum_tol", self.same_minimum_tol, 0.0)
        if not isinstance(self.local_options, Mapping):
            raise ValueError(f"multistart: option 'local_options' must be a mapping, got {self.local_options!r}")
        _parse_options(LocalOptions, "local", self.local_options)


@dataclass(frozen=True)
class GeneticOptions:
    """Options of :func:`genetic` (MATLAB ``ga``).

    Attributes
    ----------
    pop_size : int, optional
        Population; default 50 for ``n <= 5`` else 200 (MATLAB).
    elite_count : int, optional
        Elite children; default ``ceil(0.05 * pop_size)`` (MATLAB).
    crossover_fraction : float
        Fraction of non-elite children made by crossover (0.8).
    crossover : {"scattered", "heuristic", "intermediate"}
        Scattered: each gene from either parent; heuristic: a point beyond
        the better parent, ``worse + ratio * (better - worse)``; intermediate:
        a random weighting of the two parents.
    heuristic_ratio : float
        ``ratio`` of heuristic crossover (1.2).
    tournament_size : int
        Individuals per selection tournament (4).
    mutation_scale : float
        Standard deviation of the Gaussian mutation at generation 0, as a
        fraction of the (unit) range (0.1; MATLAB's ``mutationgaussian``
        uses 1.0, which leaves the GA unable to refine in a bounded cube).
    mutation_shrink : float
        The standard deviation falls linearly by this fraction over the
        planned generations (1.0: to zero at the end).
    max_generations : int, optional
        Default ``100 * n``.
    max_stall : int
        Stall generations (50).
    f_tol : float
        Stop when the best cost's average relative change over ``max_stall``
        generations is below this (1e-6).
    """

    pop_size: int | None = None
    elite_count: int | None = None
    crossover_fraction: float = 0.8
    crossover: str = "scattered"
    heuristic_ratio: float = 1.2
    tournament_size: int = 4
    mutation_scale: float = 0.1
    mutation_shrink: float = 1.0
    max_generations: int | None = None
    max_stall: int = 50
    f_tol: float = 1e-6

    def __post_init__(self) -> None:
        m = "genetic"
        _need_int(m, "pop_size", self.pop_size, 4, optional=True)
        _need_int(m, "elite_count", self.elite_count, 0, optional=True)
        if self.pop_size is not None and self.elite_count is not None and self.elite_count >= self.pop_size:
            raise ValueError(
                f"genetic: option 'elite_count' ({self.elite_count}) must be < 'pop_size' ({self.pop_size})"
            )
        _need_real(m, "crossover_fraction", self.crossover_fraction, 0.0, 1.0)
        _need_choice(m, "crossover", self.crossover, ("scattered", "heuristic", "intermediate"))
        _need_real(m, "heuristic_ratio", self.heuristic_ratio, 0.0, open_low=True)
        _need_int(m, "tournament_size", self.tournament_size, 1)
        _need_real(m, "mutation_scale", self.mutation_scale, 0.0)
        _need_real(m, "mutation_shrink", self.mutation_shrink, 0.0, 1.0)
        _need_int(m, "max_generations", self.max_generations, 1, optional=True)
        _need_int(m, "max_stall", self.max_stall, 1)
        _need_real(m, "f_tol", self.f_tol, 0.0)


@dataclass(frozen=True)
class ParticleSwarmOptions:
    """Options of :func:`particle_swarm` (MATLAB ``particleswarm``; defaults as MATLAB).

    Attributes
    ----------
    swarm_size : int, optional
        Default ``min(100, 10 * n)``.
    inertia_range : tuple of float
        Adaptive inertia limits (0.1, 1.1).
    self_weight : float
        Self (cognitive) adjustment weight (1.49).
    social_weight : float
        Social adjustment weight (1.49).
    min_neighbors_fraction : float
        Minimum neighbourhood as a fraction of the swarm (0.25).
    max_iter : int, optional
        Default ``200 * n``.
    max_stall : int
        Stall iterations (20).
    f_tol : float
        Stop when the best cost's relative change over ``max_stall``
        iterations is below this (1e-6).
    """

    swarm_size: int | None = None
    inertia_range: tuple[float, float] = (0.1, 1.1)
    self_weight: float = 1.49
    social_weight: float = 1.49
    min_neighbors_fraction: float = 0.25
    max_iter: int | None = None
    max_stall: int = 20
    f_tol: float = 1e-6

    def __post_init__(self) -> None:
        m = "particle_swarm"
        _need_int(m, "swarm_size", self.swarm_size, 2, optional=True)
        ir = self.inertia_range
        pair = isinstance(ir, (tuple, list)) and len(ir) == 2 and all(_is_real(v) for v in ir)
        if not (pair and 0 <= ir[0] <= ir[1]):
            raise ValueError(
                f"particle_swarm: option 'inertia_range' must be (low, high) with 0 <= low <= high, got {ir!r}"
            )
        _need_real(m, "self_weight", self.self_weight, 0.0)
        _need_real(m, "social_weight", self.social_weight, 0.0)
        _need_real(m, "min_neighbors_fraction", self.min_neighbors_fraction, 0.0, 1.0)
        _need_int(m, "max_iter", self.max_iter, 1, optional=True)
        _need_int(m, "max_stall", self.max_stall, 1)
        _need_real(m, "f_tol", self.f_tol, 0.0)


# --------------------------------------------------------------------------- #
# Batched evaluator with budget, history and callback
# --------------------------------------------------------------------------- #


_ROOT = object()


class _Stop(Exception):
    """Internal: a limit was reached; ``token`` names the phase it belongs to."""

    def __init__(self, reason: str, token: object) -> None:
        super().__init__(reason)
        self.reason = reason
        self.token = token


@dataclass
class _Limit:
    token: object
    max_nfev: int | None
    deadline: float | None


class _Evaluator:
    """Counts evaluations, keeps the best point, enforces budgets, calls back."""

    def __init__(self, fun: Objective, n: int, budget: Budget, callback: Callable[[Progress], Any] | None) -> None:
        self.fun = fun
        self.n = n
        self.budget = budget
        self.callback = callback
        self.t0 = time.perf_counter()
        self.nfev = 0
        self.ncalls = 0
        self.nit = 0
        self.best_x: np.ndarray | None = None
        self.best_f = math.inf
        self.history: list[tuple[int, float]] = []
        self.info: dict[str, Any] = {}
        deadline = None if budget.max_time_s is None else self.t0 + budget.max_time_s
        self._limits = [_Limit(_ROOT, budget.max_evals, deadline)]

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def remaining_evals(self) -> int | None:
        """Evaluations left under the tightest active limit (None: unlimited)."""
        caps = [limit.max_nfev for limit in self._limits if limit.max_nfev is not None]
        return None if not caps else max(0, min(caps) - self.nfev)

    def _check_limits(self) -> None:
        if self.nfev == 0:
            return
        now = time.perf_counter()
        for limit in self._limits:
            if limit.max_nfev is not None and self.nfev >= limit.max_nfev:
                raise _Stop("max_evals reached", limit.token)
            if limit.deadline is not None and now >= limit.deadline:
                raise _Stop("max_time_s reached", limit.token)

    def __call__(self, U: np.ndarray) -> np.ndarray:
        """Evaluate a batch ``(P, n)``; returns ``(P,)`` costs (NaN -> inf)."""
        self._check_limits()
        U = np.clip(np.asarray(U, dtype=float), 0.0, 1.0)
        f = np.asarray(self.fun(U), dtype=float)
        if f.shape != (U.shape[0],):
            raise ValueError(
                f"objective returned shape {f.shape} for a batch of {U.shape[0]} points; expected ({U.shape[0]},)"
            )
        f = np.where(np.isnan(f), np.inf, f)
        self.nfev += U.shape[0]
        self.ncalls += 1
        i = int(np.argmin(f))
        if f[i] < self.best_f or self.best_x is None:
            self.best_f = float(f[i])
            self.best_x = U[i].copy()
            self.history.append((self.nfev, self.best_f))
        if self.budget.target is not None and self.best_f <= self.budget.target:
            raise _Stop("target reached", _ROOT)
        return f

    def one(self, x: np.ndarray) -> float:
        """Evaluate a single point as a batch of one."""
        return float(self(x[None, :])[0])

    def end_iteration(self) -> None:
        """Count an iteration and run the user callback (True stops)."""
        self.nit += 1
        if self.callback is not None and self.best_x is not None:
            progress = Progress(self.nit, self.nfev, self.best_x.copy(), self.best_f, self.elapsed())
            if self.callback(progress):
                raise _Stop("stopped by callback", _ROOT)

    @contextmanager
    def phase(self, share: float | None) -> Iterator[object]:
        """Limit a phase to ``share`` of the remaining evaluation/time budget."""
        token = object()
        root = self._limits[0]
        max_nfev = deadline = None
        if share is not None and root.max_nfev is not None:
            max_nfev = self.nfev + max(1, int(share * (root.max_nfev - self.nfev)))
        if share is not None and root.deadline is not None:
            now = time.perf_counter()
            deadline = now + share * max(0.0, root.deadline - now)
        limit = _Limit(token, max_nfev, deadline)
        self._limits.append(limit)
        try:
            yield token
        finally:
            self._limits.remove(limit)

    def result(self, method: str, seed: int, message: str) -> OptimResult:
        history = list(self.history)
        if history and history[-1][0] != self.nfev:
            history.append((self.nfev, self.best_f))
        assert self.best_x is not None
        return OptimResult(
            x=self.best_x.copy(),
            fun=self.best_f,
            nfev=self.nfev,
            nit=self.nit,
            wall_s=self.elapsed(),
            method=method,
            seed=seed,
            history=history,
            message=message,
            ncalls=self.ncalls,
            info=dict(self.info),
        )


def _run_phase(ev: _Evaluator, share: float | None, body: Callable[[], str]) -> str:
    """Run ``body`` under a sub-budget; return its message or the limit reached."""
    with ev.phase(share) as token:
        try:
            return body()
        except _Stop as stop:
            if stop.token is not token:
                raise
            return stop.reason


# --------------------------------------------------------------------------- #
# Driver shared by the public functions
# --------------------------------------------------------------------------- #


def _check_n(n: Any) -> int:
    if not _is_int(n) or n < 1:
        raise ValueError(f"n (number of parameters) must be an integer >= 1, got {n!r}")
    return int(n)


def _check_x0(x0: Any, n: int) -> np.ndarray | None:
    if x0 is None:
        return None
    x = np.asarray(x0, dtype=float)
    if x.shape != (n,):
        raise ValueError(f"x0 must have shape ({n},), got {x.shape}")
    if not np.all(np.isfinite(x)) or np.any(x < 0.0) or np.any(x > 1.0):
        raise ValueError("x0 must lie in the unit cube [0, 1]^n (normalised parameters)")
    return x.copy()


def _make_rng(seed: Any) -> tuple[int, np.random.Generator]:
    if seed is None:
        seed = int(np.random.SeedSequence().entropy)
    elif not _is_int(seed) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer or None, got {seed!r}")
    seed = int(seed)
    return seed, np.random.default_rng(seed)


def _centre_if_none(x: np.ndarray | None, n: int) -> np.ndarray:
    return np.full(n, 0.5) if x is None else x


def _drive(
    method: str,
    fun: Objective,
    n: int,
    seed: int | None,
    budget: Budget | None,
    x0: Any,
    callback: Callable[[Progress], Any] | None,
    body: Callable[[_Evaluator, np.random.Generator, np.ndarray | None], str],
) -> OptimResult:
    """Validate common arguments, run ``body`` and assemble the result."""
    if not callable(fun):
        raise ValueError(f"fun must be callable, got {fun!r}")
    n = _check_n(n)
    if budget is None:
        budget = Budget()
    elif not isinstance(budget, Budget):
        raise ValueError(f"budget must be a Budget, got {budget!r}")
    x0 = _check_x0(x0, n)
    seed, rng = _make_rng(seed)
    ev = _Evaluator(fun, n, budget, callback)
    try:
        message = body(ev, rng, x0)
    except _Stop as stop:
        message = stop.reason
    return ev.result(method, seed, message)


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


# --------------------------------------------------------------------------- #
# Multistart (GlobalSearch)
# --------------------------------------------------------------------------- #


def _latin_hypercube(rng: np.random.Generator, count: int, n: int) -> np.ndarray:
    """``count`` points, one in each of ``count`` equal slices of every axis."""
    slices = np.argsort(rng.random((n, count)), axis=1).T  # (count, n) permutations
    return (slices + rng.random((count, n))) / count


@dataclass
class _Basin:
    centre: np.ndarray
    radius: float
    fun: float
    waits: int = 0


class _GlobalSearch:
    """Bookkeeping of MATLAB GlobalSearch: basins, threshold and their counters."""

    def __init__(self, ev: _Evaluator, o: MultistartOptions) -> None:
        self.ev = ev
        self.o = o
        self.local_opts = _parse_options(LocalOptions, "local", o.local_options)
        self.basins: list[_Basin] = []
        self.threshold = math.inf
        self.threshold_waits = 0
        ev.info.update(local_runs=0, rejected_basin=0, rejected_threshold=0, basins=0)

    def run_local(self, start: np.ndarray) -> float:
        """Local solve from ``start``; record its basin; return the solution cost."""
        self.ev.info["local_runs"] += 1
        x, f, _ = _local_solve(self.ev, start, self.local_opts)
        radius = float(np.linalg.norm(start - x))
        for basin in self.basins:
            if np.linalg.norm(basin.centre - x) <= self.o.same_minimum_tol:
                basin.radius = max(basin.radius, radius)
                break
        else:
            self.basins.append(_Basin(x, radius, f))
            self.ev.info["basins"] = len(self.basins)
        for basin in self.basins:
            basin.waits = 0
        self.threshold_waits = 0
        return f

    def consider(self, point: np.ndarray, score: float) -> bool:
        """Run the local solver from ``point`` unless rejected; True if it ran."""
        inside = [np.linalg.norm(point - b.centre) <= self.o.distance_factor * b.radius for b in self.basins]
        if not any(inside) and score < self.threshold:
            self.run_local(point)
            self.threshold = score
            return True
        self.ev.info["rejected_basin" if any(inside) else "rejected_threshold"] += 1
        self._wait(inside, score)
        return False

    def _wait(self, inside: list[bool], score: float) -> None:
        for basin, hit in zip(self.basins, inside):
            basin.waits = basin.waits + 1 if hit else 0
            if basin.waits >= self.o.max_wait:
                basin.radius *= 1.0 - self.o.radius_factor
                basin.waits = 0
        self.threshold_waits = self.threshold_waits + 1 if score >= self.threshold else 0
        if self.threshold_waits >= self.o.max_wait:
            self.threshold += self.o.penalty_factor * (1.0 + abs(self.threshold))
            self.threshold_waits = 0


def _multistart_body(ev: _Evaluator, rng: np.random.Generator, x0: np.ndarray, o: MultistartOptions) -> str:
    search = _GlobalSearch(ev, o)
    f_first = search.run_local(x0)
    trial = _latin_hypercube(rng, o.n_trial, ev.n)
    scores = ev(trial)
    stage_one = int(np.argmin(scores[: o.n_stage_one]))
    f_second = search.run_local(trial[stage_one])
    search.threshold = min(f_first, f_second)
    for k in range(o.n_stage_one, o.n_trial):
        if o.max_local_runs is not None and ev.info["local_runs"] >= o.max_local_runs:
            return f"multistart: max_local_runs ({o.max_local_runs}) reached"
        search.consider(trial[k], float(scores[k]))
    return f"multistart: all {o.n_trial} trial points examined"


def multistart(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """Local solves from scattered starts with basin-of-attraction rejection (``GlobalSearch``).

    The local solver runs from ``x0`` and from the best of the first
    ``n_stage_one`` Latin-hypercube trial points (all trial points are
    evaluated as one batch). Each later trial point starts a local run only if
    it lies outside every basin (``distance_factor * radius`` of a previous
    solution, radius = start-to-solution distance) and scores below the
    threshold; otherwise it is skipped, with MATLAB's counters shrinking basins
    and raising the threshold after ``max_wait`` consecutive rejections
    (thesis 2.4.2.3). ``info`` counts ``local_runs``, ``rejected_basin``,
    ``rejected_threshold`` and distinct ``basins``.

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        First start point; default the cube centre.
    seed : int, optional
        Seed of the trial points.
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every local-solver iteration.
    **options
        See :class:`MultistartOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(MultistartOptions, "multistart", options)

    def body(ev: _Evaluator, rng: np.random.Generator, x: np.ndarray | None) -> str:
        return _multistart_body(ev, rng, _centre_if_none(x, ev.n), o)

    return _drive("multistart", fun, n, seed, budget, x0, callback, body)


# --------------------------------------------------------------------------- #
# Genetic algorithm
# --------------------------------------------------------------------------- #


def _reflect(U: np.ndarray) -> np.ndarray:
    """Fold points back into the unit cube by mirror reflection at the faces."""
    V = np.mod(U, 2.0)
    return np.where(V > 1.0, 2.0 - V, V)


def _tournament(rng: np.random.Generator, f: np.ndarray, count: int, size: int) -> np.ndarray:
    """Indices of ``count`` winners of tournaments of ``size`` random entrants."""
    entrants = rng.integers(0, f.size, size=(count, size))
    return entrants[np.arange(count), np.argmin(f[entrants], axis=1)]


def _crossover(
    rng: np.random.Generator, a: np.ndarray, b: np.ndarray, fa: np.ndarray, fb: np.ndarray, o: GeneticOptions
) -> np.ndarray:
    """Children of parent pairs (rows of ``a`` and ``b``)."""
    if o.crossover == "scattered":
        return np.where(rng.random(a.shape) < 0.5, a, b)
    if o.crossover == "intermediate":
        return a + rng.random(a.shape) * (b - a)
    a_better = (fa <= fb)[:, None]
    better, worse = np.where(a_better, a, b), np.where(a_better, b, a)
    return _reflect(worse + o.heuristic_ratio * (better - worse))


def _planned_generations(ev: _Evaluator, o: GeneticOptions, pop: int, elite: int) -> int:
    """Generations the mutation shrink is spread over (limited by ``max_evals``)."""
    planned = o.max_generations if o.max_generations is not None else 100 * ev.n
    remaining = ev.remaining_evals()
    if remaining is not None:
        planned = min(planned, max(1, (remaining - pop) // max(1, pop - elite)))
    return planned


def _stalled(best: list[float], window: int, f_tol: float, average: bool) -> bool:
    """Relative change of the best cost over ``window`` iterations below ``f_tol``."""
    if len(best) <= window:
        return False
    old, new = best[-1 - window], best[-1]
    change = (old - new) / max(1.0, abs(new)) if math.isfinite(old) else math.inf
    return (change / window if average else change) <= f_tol


def _genetic_body(ev: _Evaluator, rng: np.random.Generator, x0: np.ndarray | None, o: GeneticOptions) -> str:
    n = ev.n
    pop = o.pop_size if o.pop_size is not None else (50 if n <= 5 else 200)
    elite = o.elite_count if o.elite_count is not None else math.ceil(0.05 * pop)
    if elite >= pop:
        raise ValueError(f"genetic: option 'elite_count' ({elite}) must be < the population ({pop})")
    n_cross = int(round(o.crossover_fraction * (pop - elite)))
    n_mut = pop - elite - n_cross
    max_gen = o.max_generations if o.max_generations is not None else 100 * n
    planned = _planned_generations(ev, o, pop, elite)
    X = rng.random((pop, n))
    if x0 is not None:
        X[0] = x0
    F = ev(X)
    best = [float(F.min())]
    for gen in range(1, max_gen + 1):
        order = np.argsort(F, kind="stable")
        parents = _tournament(rng, F, 2 * n_cross + n_mut, o.tournament_size)
        a, b = parents[:n_cross], parents[n_cross : 2 * n_cross]
        crossed = _crossover(rng, X[a], X[b], F[a], F[b], o)
        sigma = o.mutation_scale * max(0.0, 1.0 - o.mutation_shrink * gen / planned)
        mutants = _reflect(X[parents[2 * n_cross :]] + sigma * rng.standard_normal((n_mut, n)))
        children = np.vstack([crossed, mutants])
        Fc = ev(children)
        X = np.vstack([X[order[:elite]], children])
        F = np.concatenate([F[order[:elite]], Fc])
        best.append(float(F.min()))
        ev.end_iteration()
        if _stalled(best, o.max_stall, o.f_tol, average=True):
            return f"genetic: stalled for {o.max_stall} generations (f_tol {o.f_tol:g})"
    return f"genetic: max_generations ({max_gen}) reached"


def genetic(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """Genetic algorithm with elitism, crossover and shrinking Gaussian mutation (``ga``).

    Each generation keeps ``elite_count`` best individuals, makes
    ``crossover_fraction`` of the rest by crossover of tournament-selected
    parents and the remainder by Gaussian mutation, and evaluates all new
    children as one batch (thesis 2.4.2.4).

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        Seeded into the initial population.
    seed : int, optional
        Seed of the generator; default drawn from OS entropy and recorded.
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every generation; returning True stops.
    **options
        See :class:`GeneticOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(GeneticOptions, "genetic", options)
    return _drive("genetic", fun, n, seed, budget, x0, callback, lambda ev, rng, x: _genetic_body(ev, rng, x, o))


# --------------------------------------------------------------------------- #
# Particle swarm
# --------------------------------------------------------------------------- #


def _neighbour_best(rng: np.random.Generator, P: np.ndarray, PF: np.ndarray, size: int) -> np.ndarray:
    """Best personal-best position among ``size`` random other particles, per particle."""
    S = PF.size
    if size >= S - 1:
        return np.broadcast_to(P[int(np.argmin(PF))], P.shape)
    idx = rng.integers(0, S - 1, size=(S, size))
    idx += idx >= np.arange(S)[:, None]  # skip the particle itself
    winner = idx[np.arange(S), np.argmin(PF[idx], axis=1)]
    return P[winner]


@dataclass
class _SwarmState:
    """Adaptive parameters of MATLAB particleswarm: inertia, neighbourhood, stall counter."""

    inertia: float
    neighbours: int
    min_neighbours: int
    size: int
    stall: int = 0

    def update(self, improved: bool, inertia_range: tuple[float, float]) -> None:
        """Adapt after an iteration; ``improved``: the swarm's best cost went down."""
        if improved:
            self.stall = max(0, self.stall - 1)
            self.neighbours = self.min_neighbours
        else:
            self.stall += 1
            self.neighbours = min(self.neighbours + self.min_neighbours, self.size)
        # Thesis 2.4.2.5: inertia rises while the best improves and falls after
        # several iterations without improvement, so this runs in both cases.
        if self.stall < 2:
            self.inertia *= 2.0
        elif self.stall > 5:
            self.inertia /= 2.0
        self.inertia = min(max(self.inertia, inertia_range[0]), inertia_range[1])


def _pso_body(ev: _Evaluator, rng: np.random.Generator, x0: np.ndarray | None, o: ParticleSwarmOptions) -> str:
    n = ev.n
    S = o.swarm_size if o.swarm_size is not None else min(100, 10 * n)
    max_iter = o.max_iter if o.max_iter is not None else 200 * n
    X = rng.random((S, n))
    if x0 is not None:
        X[0] = x0
    V = rng.uniform(-1.0, 1.0, size=(S, n))
    F = ev(X)
    P, PF = X.copy(), F.copy()
    min_nb = max(2, int(S * o.min_neighbors_fraction))
    state = _SwarmState(inertia=max(o.inertia_range), neighbours=min_nb, min_neighbours=min_nb, size=S)
    best = [float(PF.min())]
    for _ in range(max_iter):
        G = _neighbour_best(rng, P, PF, state.neighbours)
        u1, u2 = rng.random((2, S, n))
        V = state.inertia * V + o.self_weight * u1 * (P - X) + o.social_weight * u2 * (G - X)
        X = X + V
        outside = (X < 0.0) | (X > 1.0)
        X = np.clip(X, 0.0, 1.0)
        V[outside] = 0.0
        F = ev(X)
        better = F < PF
        P[better], PF[better] = X[better], F[better]
        best.append(float(PF.min()))
        state.update(best[-1] < best[-2], o.inertia_range)
        ev.end_iteration()
        if _stalled(best, o.max_stall, o.f_tol, average=False):
            return f"particle_swarm: stalled for {o.max_stall} iterations (f_tol {o.f_tol:g})"
    return f"particle_swarm: max_iter ({max_iter}) reached"


def particle_swarm(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """Particle swarm with adaptive inertia and neighbourhood (``particleswarm``).

    Velocities follow ``v = W v + c1 u1 (p - x) + c2 u2 (g - x)`` with ``g`` the
    best personal best among a random neighbourhood; a component leaving the
    cube is clamped to the face and its velocity zeroed. An improving
    iteration resets the neighbourhood to its minimum and adapts the inertia
    ``W`` from the stall counter; a stalled one widens the neighbourhood
    (thesis 2.4.2.5). The swarm is evaluated as one batch per iteration.

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        Seeded into the initial swarm.
    seed : int, optional
        Seed of the generator (thesis 5.2.1 used seeds 1 to 5).
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every iteration; returning True stops.
    **options
        See :class:`ParticleSwarmOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(ParticleSwarmOptions, "particle_swarm", options)
    return _drive("particle_swarm", fun, n, seed, budget, x0, callback, lambda ev, rng, x: _pso_body(ev, rng, x, o))


@dataclass(frozen=True)
class CMAESOptions:
    """Options of :func:`cma_es` (covariance matrix adaptation, the ``cma`` package).

    Attributes
    ----------
    popsize : int, optional
        Offspring per generation; default ``4 + floor(3 ln n)`` (``cma``'s).
    sigma0 : float
        Initial step size in the unit cube (0.3).
    restarts : int
        Restarts after a stop, each with twice the population (IPOP; 4).
    max_iter : int, optional
        Generations per run; default ``cma``'s.
    tol_fun : float
        Stop a run when the best costs of recent generations differ by less (1e-12).
    """

    popsize: int | None = None
    sigma0: float = 0.3
    restarts: int = 4
    max_iter: int | None = None
    tol_fun: float = 1e-12

    def __post_init__(self) -> None:
        m = "cma_es"
        _need_int(m, "popsize", self.popsize, 2, optional=True)
        _need_real(m, "sigma0", self.sigma0, 1e-9, 1.0)
        _need_int(m, "restarts", self.restarts, 0)
        _need_int(m, "max_iter", self.max_iter, 1, optional=True)
        _need_real(m, "tol_fun", self.tol_fun, 0.0)


def _cma_body(ev: _Evaluator, rng: np.random.Generator, x0: np.ndarray | None, o: CMAESOptions) -> str:
    import cma

    popsize = o.popsize if o.popsize is not None else 4 + int(3 * math.log(ev.n))
    start = rng.random(ev.n) if x0 is None else x0
    message = "cma_es: no run"
    for k in range(o.restarts + 1):
        opts: dict[str, Any] = {"bounds": [0.0, 1.0], "popsize": popsize * 2 ** k, "verbose": -9,
                                "seed": int(rng.integers(1, 2 ** 31 - 1)), "tolfun": o.tol_fun,
                                "tolflatfitness": 10}
        if o.max_iter is not None:
            opts["maxiter"] = o.max_iter
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            es = cma.CMAEvolutionStrategy(np.clip(start, 0.0, 1.0).tolist(), o.sigma0, opts)
            while not es.stop():
                X = np.clip(np.asarray(es.ask(), float), 0.0, 1.0)
                left = ev.remaining_evals()
                if left is not None and left < len(X):  # the budget ends inside this generation
                    if left > 0:
                        ev(X[:left])
                    return "cma_es: max_evals reached"
                F = ev(X)
                finite = np.isfinite(F)
                worst = float(F[finite].max()) if finite.any() else 1e300
                es.tell(list(X), np.where(finite, F, 10.0 * abs(worst) + 1.0).tolist())
                ev.end_iteration()
        message = f"cma_es: run {k + 1} stopped ({', '.join(sorted(es.stop()))})"
        start = rng.random(ev.n)
    return message


def cma_es(
    fun: Objective,
    n: int,
    *,
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    **options: Any,
) -> OptimResult:
    """CMA-ES with IPOP restarts (Hansen's ``cma`` package), one batch per generation.

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    x0 : array_like, optional
        Mean of the first run (default: a random point of the cube).
    seed : int, optional
        Seed; every run's ``cma`` seed is drawn from it.
    budget : Budget, optional
        Evaluation/time/target limits.
    callback : callable, optional
        ``callback(Progress)`` after every generation; returning True stops.
    **options
        See :class:`CMAESOptions`.

    Returns
    -------
    OptimResult
    """
    o = _parse_options(CMAESOptions, "cma_es", options)
    return _drive("cma_es", fun, n, seed, budget, x0, callback, lambda ev, rng, x: _cma_body(ev, rng, x, o))


# --------------------------------------------------------------------------- #
# Hybrid and dispatcher
# --------------------------------------------------------------------------- #


#: Global phases a hybrid can start with: options class and body ``(ev, rng, x0, options) -> message``.
_GLOBAL_BODIES: dict[str, tuple[type, Callable[..., str]]] = {
    "pattern_search": (PatternSearchOptions, lambda ev, rng, x, o: _pattern_body(ev, _centre_if_none(x, ev.n), o)),
    "multistart": (MultistartOptions, lambda ev, rng, x, o: _multistart_body(ev, rng, _centre_if_none(x, ev.n), o)),
    "genetic": (GeneticOptions, _genetic_body),
    "particle_swarm": (ParticleSwarmOptions, _pso_body),
    "cma_es": (CMAESOptions, _cma_body),
}


def hybrid(
    fun: Objective,
    n: int,
    *,
    global_method: str = "particle_swarm",
    x0: Any = None,
    seed: int | None = None,
    budget: Budget | None = None,
    callback: Callable[[Progress], Any] | None = None,
    global_options: Mapping[str, Any] | None = None,
    local_options: Mapping[str, Any] | None = None,
    global_share: float = 0.8,
) -> OptimResult:
    """Global search, then the local solver from its best point (MATLAB ``HybridFcn``).

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``.
    n : int
        Number of parameters.
    global_method : str
        ``"particle_swarm"`` (thesis 5.2.1), ``"genetic"``, ``"pattern_search"``
        or ``"multistart"`` (aliases accepted).
    x0 : array_like, optional
        Passed to the global method.
    seed : int, optional
        Seed of the global method.
    budget : Budget, optional
        Shared limits. The global phase may use ``global_share`` of
        ``max_evals`` and ``max_time_s``; the local phase gets the rest.
    callback : callable, optional
        ``callback(Progress)`` after every iteration of either phase.
    global_options, local_options : dict, optional
        Options of the two phases.
    global_share : float
        Fraction of the budget reserved for the global phase (0 < share <= 1).

    Returns
    -------
    OptimResult
        ``method`` is ``"<global_method>+local"``; ``info`` holds the global
        phase's counters and ``global_fun`` / ``global_nfev`` at the hand-over.
    """
    name = _canonical(global_method)
    if name not in _GLOBAL_BODIES:
        valid = ", ".join(sorted(_GLOBAL_BODIES))
        raise ValueError(f"hybrid: global_method must be one of {valid}, got {global_method!r}")
    if not (_is_real(global_share) and 0.0 < global_share <= 1.0):
        raise ValueError(f"hybrid: global_share must be in (0, 1], got {global_share!r}")
    options_cls, global_body = _GLOBAL_BODIES[name]
    go = _parse_options(options_cls, name, global_options)
    lo = _parse_options(LocalOptions, "local", local_options)

    def body(ev: _Evaluator, rng: np.random.Generator, x: np.ndarray | None) -> str:
        first = _run_phase(ev, global_share, lambda: global_body(ev, rng, x, go))
        ev.info.update(global_fun=ev.best_f, global_nfev=ev.nfev)
        assert ev.best_x is not None
        second = _run_phase(ev, None, lambda: _local_solve(ev, ev.best_x.copy(), lo)[2])
        return f"{first}; then {second}"

    return _drive(f"{name}+local", fun, n, seed, budget, x0, callback, body)


#: Canonical method names accepted by :func:`minimize`.
METHODS: tuple[str, ...] = ("local", "pattern_search", "multistart", "genetic", "particle_swarm", "cma_es", "hybrid")

#: MATLAB-style aliases.
ALIASES: dict[str, str] = {
    "fmincon": "local",
    "patternsearch": "pattern_search",
    "globalsearch": "multistart",
    "ga": "genetic",
    "pso": "particle_swarm",
    "particleswarm": "particle_swarm",
    "cma": "cma_es",
    "cmaes": "cma_es",
}


def _canonical(method: str) -> str:
    if not isinstance(method, str):
        raise ValueError(f"method must be a string, got {method!r}")
    key = method.strip().lower().replace("-", "_")
    key = ALIASES.get(key, key)
    if key not in METHODS:
        valid = ", ".join(list(METHODS) + sorted(ALIASES))
        raise ValueError(f"unknown method {method!r} (valid: {valid}, or '<global>+local')")
    return key


def minimize(
    fun: Objective,
    n: int,
    method: str = "particle_swarm",
    seed: int | None = None,
    budget: Budget | None = None,
    options: Mapping[str, Any] | None = None,
    x0: Any = None,
    callback: Callable[[Progress], Any] | None = None,
) -> OptimResult:
    """Minimise a batched objective over the unit cube with the named method.

    Parameters
    ----------
    fun : callable
        Batched objective ``fun(U) -> f``, ``U`` ``(P, n)``, ``f`` ``(P,)``.
    n : int
        Number of parameters.
    method : str
        One of :data:`METHODS`, a MATLAB alias (``fmincon``, ``patternsearch``,
        ``globalsearch``, ``ga``, ``pso``, ``particleswarm``) or
        ``"<global>+<local>"`` such as ``"pso+fmincon"`` for :func:`hybrid`.
    seed : int, optional
        Seed; the same seed gives the same result.
    budget : Budget, optional
        Evaluation/time/target limits.
    options : dict, optional
        Method options (for hybrids: ``global_options``, ``local_options``,
        ``global_share``, and ``global_method`` when ``method="hybrid"``).
    x0 : array_like, optional
        Start point / seeded individual in ``[0, 1]^n``.
    callback : callable, optional
        ``callback(Progress)`` after every iteration; returning True stops.

    Returns
    -------
    OptimResult
    """
    options = dict(options or {})
    common = {"x0": x0, "seed": seed, "budget": budget, "callback": callback}
    if isinstance(method, str) and "+" in method:
        first, second = method.split("+", 1)
        if _canonical(second) != "local":
            raise ValueError(f"hybrid method {method!r}: the second stage must be the local solver (local/fmincon)")
        if "global_method" in options:
            raise ValueError(f"hybrid method {method!r} already names the global method; drop option 'global_method'")
        return _call_hybrid(fun, n, _canonical(first), options, common)
    name = _canonical(method)
    if name == "hybrid":
        return _call_hybrid(fun, n, options.pop("global_method", "particle_swarm"), options, common)
    single = {"local": local, "pattern_search": pattern_search, "multistart": multistart,
              "genetic": genetic, "particle_swarm": particle_swarm, "cma_es": cma_es}[name]
    return single(fun, n, **common, **options)


def _call_hybrid(
    fun: Objective, n: int, global_method: str, options: dict[str, Any], common: dict[str, Any]
) -> OptimResult:
    valid = {"global_options", "local_options", "global_share"}
    unknown = sorted(set(options) - valid)
    if unknown:
        raise ValueError(f"hybrid: unknown option {unknown[0]!r} (valid options: {', '.join(sorted(valid))})")
    return hybrid(fun, n, global_method=global_method, **common, **options)
