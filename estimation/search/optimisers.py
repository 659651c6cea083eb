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

The shared machinery (budget, result, options, evaluator) lives in
:mod:`estimation.search.core`, the local methods in
:mod:`estimation.search.local` and the population methods in
:mod:`estimation.search.population`; this module re-exports them.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from estimation.search.core import (Budget, GeneticOptions, LocalOptions, MultistartOptions, Objective, OptimResult,
    ParticleSwarmOptions, PatternSearchOptions, Progress, _centre_if_none, _drive, _Evaluator, _is_real,
    _parse_options, _run_phase)
from estimation.search.local import _local_solve, _pattern_body, local, pattern_search
from estimation.search.population import (CMAESOptions, _cma_body, _genetic_body, _multistart_body, _pso_body,
    cma_es, genetic, multistart, particle_swarm)

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
