"""Population and multi-start optimisers on the unit cube.

Holds :func:`multistart` (``GlobalSearch``'s role: scatter, basins, local
runs), :func:`genetic` (``ga``), :func:`particle_swarm` (``particleswarm``)
and :func:`cma_es` (CMA-ES through the ``cma`` package, with
:class:`CMAESOptions`), with their private bodies, which
:mod:`estimation.search.optimisers` also runs as the global phase of a hybrid.
Every population is evaluated as one batch in the normalised cube
``[0, 1]^n``.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from estimation.search.core import (Budget, GeneticOptions, LocalOptions, MultistartOptions, Objective, OptimResult,
    ParticleSwarmOptions, Progress, _centre_if_none, _drive, _Evaluator, _need_int, _need_real, _parse_options)
from estimation.search.local import _local_solve

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
