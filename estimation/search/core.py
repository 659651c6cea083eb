"""Machinery shared by the batched optimisers on the unit cube.

Holds the limits and results (:class:`Budget`, :class:`Progress`,
:class:`OptimResult`), the option containers of the built-in methods
(:class:`LocalOptions`, :class:`PatternSearchOptions`,
:class:`MultistartOptions`, :class:`GeneticOptions`,
:class:`ParticleSwarmOptions`) with their validation, the batched evaluator
that counts evaluations, keeps the best point and enforces the budget
(wall time in s), and :func:`_drive`, which runs one method's body and
builds its result. The methods are in :mod:`estimation.search.local`
and :mod:`estimation.search.population`; :mod:`estimation.search.optimisers`
is the public entry point.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

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
