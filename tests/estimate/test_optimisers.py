"""Batched optimisers: known minima, real batching, seeds, budgets, GlobalSearch bookkeeping."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest

from estimation.search import optimisers as opt
from estimation.search.optimisers import Budget

RASTRIGIN_SHIFT = 1.3  # global minimum at x = 1.3 in [-5.12, 5.12]


class Counting:
    """Batched objective wrapper recording every call's batch size."""

    def __init__(self, fun):
        self.fun = fun
        self.batches: list[int] = []

    def __call__(self, U):
        assert U.ndim == 2 and np.all(U >= 0.0) and np.all(U <= 1.0)
        self.batches.append(U.shape[0])
        return self.fun(U)

    @property
    def nfev(self) -> int:
        return sum(self.batches)


def sphere(centre):
    centre = np.asarray(centre, float)
    return lambda U: np.sum((U - centre) ** 2, axis=1)


def rosenbrock(U):
    """Rosenbrock on [-2, 2]^n; minimum 0 at x = 1, i.e. u = 0.75."""
    X = 4.0 * U - 2.0
    return np.sum(100.0 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (1.0 - X[:, :-1]) ** 2, axis=1)


def rastrigin(U):
    """Shifted Rastrigin on [-5.12, 5.12]^n: global minimum 0 at x = 1.3, many local minima."""
    X = 10.24 * U - 5.12 - RASTRIGIN_SHIFT
    return 10.0 * X.shape[1] + np.sum(X**2 - 10.0 * np.cos(2.0 * np.pi * X), axis=1)


RASTRIGIN_U = (RASTRIGIN_SHIFT + 5.12) / 10.24
ROSEN_U = 0.75


def centre_for(n):
    return np.linspace(0.2, 0.8, n)


# --------------------------------------------------------------------------- #
# Known minima
# --------------------------------------------------------------------------- #


@pytest.mark.parametrize("method", ["L-BFGS-B", "trust-constr", "nelder-mead"])
@pytest.mark.parametrize("fd", ["forward", "central"])
@pytest.mark.parametrize("n", [2, 4, 6])
def test_local_finds_sphere_and_rosenbrock(method, fd, n):
    c = centre_for(n)
    res = opt.local(sphere(c), n, method=method, fd=fd, budget=Budget(max_evals=50_000))
    assert np.max(np.abs(res.x - c)) < 1e-4
    res = opt.local(rosenbrock, n, method=method, fd=fd, budget=Budget(max_evals=50_000))
    assert np.max(np.abs(res.x - ROSEN_U)) < 1e-4
    assert res.fun < 1e-8


def test_local_respects_bounds_at_a_face():
    # unconstrained minimum outside the cube: the bounded minimum is on the face u = 0
    res = opt.local(sphere(np.full(3, -0.3)), 3)
    assert np.allclose(res.x, 0.0, atol=1e-12)
    assert res.fun == pytest.approx(3 * 0.09)


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_pattern_search(n):
    c = centre_for(n)
    res = opt.pattern_search(sphere(c), n, budget=Budget(max_evals=20_000))
    assert np.max(np.abs(res.x - c)) < 1e-5
    assert "mesh" in res.message
    res = opt.pattern_search(rosenbrock, n, budget=Budget(max_evals=40_000))
    # coordinate polling crawls along Rosenbrock's curved valley: near, not at, the minimum
    assert np.max(np.abs(res.x - ROSEN_U)) < 0.04
    assert res.fun < 1e-2


@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_multistart(n):
    c = centre_for(n)
    options = {"n_trial": 300, "n_stage_one": 60}
    res = opt.multistart(sphere(c), n, seed=1, budget=Budget(max_evals=50_000), **options)
    assert np.max(np.abs(res.x - c)) < 1e-5
    res = opt.multistart(rosenbrock, n, seed=1, budget=Budget(max_evals=50_000), **options)
    assert np.max(np.abs(res.x - ROSEN_U)) < 1e-4


@pytest.mark.parametrize("method", ["genetic", "particle_swarm"])
@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_population_methods_on_sphere(method, n):
    c = centre_for(n)
    res = opt.minimize(sphere(c), n, method, seed=1, budget=Budget(max_evals=20_000), options={"f_tol": 0.0})
    assert np.max(np.abs(res.x - c)) < 0.05
    assert res.nfev <= 20_000 + 200


@pytest.mark.parametrize("method", ["genetic", "particle_swarm"])
@pytest.mark.parametrize("n", [2, 3])
def test_population_methods_on_rosenbrock(method, n):
    # run on the evaluation budget alone (no stall or iteration stop)
    options = {"max_stall": 10**6, "max_generations" if method == "genetic" else "max_iter": 10**6}
    res = opt.minimize(rosenbrock, n, method, seed=1, budget=Budget(max_evals=100_000), options=options)
    # metaheuristics alone creep along the curved valley (the hybrids below finish the job)
    assert np.max(np.abs(res.x - ROSEN_U)) < 0.05
    assert res.fun < 1e-2


@pytest.mark.parametrize("method", ["genetic+local", "pso+fmincon"])
@pytest.mark.parametrize("n", [2, 3, 4, 5, 6])
def test_hybrid_on_rosenbrock_best_of_five_seeds(method, n):
    # thesis 5.2.1: seeds 1..5, keep the best (for n >= 4 Rosenbrock has a local
    # minimum near x1 = -1 that a single seed can fall into)
    results = [opt.minimize(rosenbrock, n, method, seed=s, budget=Budget(max_evals=20_000)) for s in range(1, 6)]
    best = min(results, key=lambda r: r.fun)
    assert np.max(np.abs(best.x - ROSEN_U)) < 1e-4
    assert best.fun < 1e-8
    assert sum(np.max(np.abs(r.x - ROSEN_U)) < 1e-4 for r in results) >= 3


@pytest.mark.parametrize("method", ["genetic", "particle_swarm"])
def test_rastrigin_2d_global_basin(method):
    basin = 0.5 / 10.24  # half the spacing of Rastrigin's local minima, in unit-cube units
    res = opt.minimize(rastrigin, 2, method, seed=1)
    assert np.max(np.abs(res.x - RASTRIGIN_U)) < basin
    wins = [np.max(np.abs(opt.minimize(rastrigin, 2, method, seed=s).x - RASTRIGIN_U)) < basin for s in range(1, 11)]
    assert sum(wins) >= 8
    # a local solver started near the local minimum 2 away from the optimum stays there
    # (cost ~ 2 * 2**2): the landscape is not trivial
    x0 = np.full(2, (2.1 + 5.12 + RASTRIGIN_SHIFT) / 10.24)
    assert opt.local(rastrigin, 2, x0=x0).fun == pytest.approx(7.96, abs=0.05)


def test_nan_costs_are_treated_as_infeasible():
    c = centre_for(3)

    def holey(U):
        f = np.sum((U - c) ** 2, axis=1)
        f[U[:, 0] > 0.9] = np.nan
        return f

    for method in ("genetic", "particle_swarm", "pattern_search", "local"):
        res = opt.minimize(holey, 3, method, seed=2, budget=Budget(max_evals=5000))
        assert np.isfinite(res.fun) and res.x[0] <= 0.9


# --------------------------------------------------------------------------- #
# Batching
# --------------------------------------------------------------------------- #


@pytest.mark.parametrize("n", [2, 5])
def test_local_gradient_is_one_batch(n):
    for fd, size in (("forward", n + 1), ("central", 2 * n + 1)):
        f = Counting(rosenbrock)
        res = opt.local(f, n, fd=fd)
        assert res.ncalls == len(f.batches) and res.nfev == f.nfev
        assert set(f.batches) == {size}  # value and gradient come together, one call each time
        assert res.nfev >= 10 * size  # many iterations, yet one call per gradient


def test_trust_constr_and_nelder_mead_batches():
    n = 4
    f = Counting(rosenbrock)
    opt.local(f, n, method="trust-constr")
    assert set(f.batches) <= {1, n, n + 1}
    f = Counting(rosenbrock)
    opt.local(f, n, method="nelder-mead")
    assert f.batches[0] == n + 1 and set(f.batches[1:]) <= {4, n}  # speculative 4-point steps, shrinks


def test_population_batches():
    n = 3
    f = Counting(sphere(centre_for(n)))
    res = opt.genetic(f, n, seed=0, pop_size=40, elite_count=2)
    assert f.batches[0] == 40 and set(f.batches[1:]) == {38}  # elites are not re-evaluated
    assert res.ncalls == len(f.batches) == res.nit + 1
    f = Counting(sphere(centre_for(n)))
    res = opt.particle_swarm(f, n, seed=0, swarm_size=25)
    assert set(f.batches) == {25} and res.ncalls == res.nit + 1
    f = Counting(sphere(centre_for(n)))
    opt.pattern_search(f, n)
    assert max(f.batches[1:]) == 2 * n and len(f.batches) < f.nfev / 3
    f = Counting(sphere(centre_for(n)))
    opt.multistart(f, n, seed=0, n_trial=500, n_stage_one=100)
    assert 500 in f.batches  # every trial point scored in one call


# --------------------------------------------------------------------------- #
# Reproducibility
# --------------------------------------------------------------------------- #

ALL_METHODS = ["local", "pattern_search", "multistart", "genetic", "particle_swarm", "pso+local", "ga+local"]


def _same(a, b):
    return np.array_equal(a.x, b.x) and a.fun == b.fun and a.nfev == b.nfev and a.history == b.history


@pytest.mark.parametrize("method", ALL_METHODS)
def test_same_seed_same_result(method):
    options = {"n_trial": 200, "n_stage_one": 40} if method == "multistart" else {}
    run = lambda seed: opt.minimize(rastrigin, 3, method, seed=seed, budget=Budget(max_evals=4000), options=options)
    a, b = run(7), run(7)
    assert _same(a, b) and a.seed == 7
    if method in ("genetic", "particle_swarm", "multistart", "pso+local", "ga+local"):
        assert not _same(a, run(8))


def test_unseeded_run_records_its_seed():
    a = opt.particle_swarm(rastrigin, 2, budget=Budget(max_evals=2000))
    b = opt.particle_swarm(rastrigin, 2, seed=a.seed, budget=Budget(max_evals=2000))
    assert isinstance(a.seed, int) and _same(a, b)


# --------------------------------------------------------------------------- #
# Budgets, callback, history
# --------------------------------------------------------------------------- #


@pytest.mark.parametrize("method", ALL_METHODS)
@pytest.mark.parametrize("max_evals", [1, 37, 900])
def test_max_evals_exceeded_by_less_than_one_batch(method, max_evals):
    f = Counting(rastrigin)
    options = {"n_trial": 300, "n_stage_one": 50} if method == "multistart" else {}
    res = opt.minimize(f, 4, method, seed=3, budget=Budget(max_evals=max_evals), options=options)
    assert res.nfev == f.nfev
    assert res.nfev < max_evals + max(f.batches)
    assert res.nfev - f.batches[-1] < max_evals  # the last batch started below the limit


@pytest.mark.parametrize("method", ["local", "genetic", "particle_swarm", "pso+local", "multistart"])
def test_max_time(method):
    def slow(U):
        time.sleep(0.01)
        return rosenbrock(U)

    res = opt.minimize(slow, 6, method, seed=0, budget=Budget(max_time_s=0.25))
    assert res.message.endswith("max_time_s reached")
    assert res.wall_s < 0.25 + 0.2  # one batch (10 ms) plus generous scheduling slack


def test_target_stops_early():
    res = opt.particle_swarm(sphere(centre_for(3)), 3, seed=0, budget=Budget(target=1e-3))
    assert res.message == "target reached" and res.fun <= 1e-3
    full = opt.particle_swarm(sphere(centre_for(3)), 3, seed=0)
    assert res.nfev < full.nfev


def test_hybrid_splits_budget():
    res = opt.hybrid(rosenbrock, 4, global_method="ga", seed=1, budget=Budget(max_evals=5000), global_share=0.5)
    assert res.method == "genetic+local"
    assert 2500 <= res.info["global_nfev"] < 2500 + 200  # global phase stopped at its share
    assert res.fun < res.info["global_fun"]  # and the local phase improved on it
    assert res.nfev < 5000 + 9


def test_callback_progress_and_stop():
    seen = []

    def callback(p: opt.Progress):
        seen.append(p)
        return p.nit >= 5

    res = opt.genetic(rastrigin, 2, seed=0, callback=callback)
    assert res.message == "stopped by callback" and res.nit == 5 == len(seen)
    assert [p.nit for p in seen] == [1, 2, 3, 4, 5]
    assert all(a.fun >= b.fun for a, b in zip(seen, seen[1:]))


@pytest.mark.parametrize("method", ALL_METHODS)
def test_history_and_result_fields(method):
    f = Counting(rastrigin)
    options = {"n_trial": 200, "n_stage_one": 40} if method == "multistart" else {}
    res = opt.minimize(f, 3, method, seed=4, budget=Budget(max_evals=3000), options=options)
    nfevs, bests = zip(*res.history)
    assert list(nfevs) == sorted(nfevs) and nfevs[-1] == res.nfev
    assert all(a >= b for a, b in zip(bests, bests[1:])) and bests[-1] == res.fun
    assert res.fun == pytest.approx(float(rastrigin(res.x[None])[0]), abs=0)
    assert res.x.shape == (3,) and np.all((res.x >= 0) & (res.x <= 1))
    assert json.loads(json.dumps(res.to_dict()))["fun"] == res.fun


# --------------------------------------------------------------------------- #
# Multistart (GlobalSearch) bookkeeping
# --------------------------------------------------------------------------- #


class TrialSpy(Counting):
    """Also keeps the multistart trial points (the one large batch)."""

    def __call__(self, U):
        if U.shape[0] >= 100:
            self.trial = U.copy()
        return super().__call__(U)


def test_multistart_basin_rejection_counts():
    """With threshold raising disabled, the skipped starts are exactly those inside the basin."""
    n, c = 3, np.array([0.3, 0.6, 0.45])
    f = TrialSpy(sphere(c))
    n_trial, stage_one = 400, 80
    res = opt.multistart(f, n, seed=5, n_trial=n_trial, n_stage_one=stage_one, max_wait=10**6)
    info = res.info
    # only the two compulsory runs (x0 and best stage-one point); every later start was skipped
    assert info["local_runs"] == 2 and info["basins"] == 1
    assert info["rejected_basin"] + info["rejected_threshold"] == n_trial - stage_one
    # recompute the basin independently: radius = larger start-to-solution distance of the two runs
    trial = f.trial
    assert trial.shape == (n_trial, n)
    stage = trial[np.argmin(np.sum((trial[:stage_one] - c) ** 2, axis=1))]
    radius = max(np.linalg.norm(np.full(n, 0.5) - c), np.linalg.norm(stage - c))
    inside = np.linalg.norm(trial[stage_one:] - c, axis=1) <= 0.75 * radius
    assert info["rejected_basin"] == int(inside.sum()) > 0


def test_multistart_threshold_raising_lets_starts_run():
    n = 2
    res = opt.multistart(rastrigin, n, seed=0, n_trial=400, n_stage_one=50)
    info = res.info
    assert info["local_runs"] > 2  # threshold rises after max_wait rejections
    assert info["rejected_basin"] > 0 and info["rejected_threshold"] > 0
    assert info["local_runs"] - 2 + info["rejected_basin"] + info["rejected_threshold"] == 400 - 50
    assert np.max(np.abs(res.x - RASTRIGIN_U)) < 1e-5


def test_multistart_escapes_the_basin_of_x0():
    def two_wells(U):
        shallow = np.sum((U - 0.2) ** 2, axis=1)
        deep = np.sum((U - 0.8) ** 2, axis=1) - 0.05
        return np.minimum(shallow, deep)

    x0 = np.full(2, 0.25)
    assert opt.local(two_wells, 2, x0=x0).fun == pytest.approx(0.0, abs=1e-12)  # local stays in the shallow well
    res = opt.multistart(two_wells, 2, x0=x0, seed=0, n_trial=200, n_stage_one=20)
    assert res.fun == pytest.approx(-0.05, abs=1e-12)
    assert np.allclose(res.x, 0.8, atol=1e-5)


# --------------------------------------------------------------------------- #
# Validation
# --------------------------------------------------------------------------- #


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: opt.genetic(rosenbrock, 2, popsize=10), "genetic: unknown option 'popsize'"),
        (lambda: opt.genetic(rosenbrock, 2, pop_size=1), "option 'pop_size'"),
        (lambda: opt.genetic(rosenbrock, 2, crossover="uniform"), "option 'crossover'"),
        (lambda: opt.particle_swarm(rosenbrock, 2, inertia_range=(1.0, 0.5)), "option 'inertia_range'"),
        (lambda: opt.local(rosenbrock, 2, method="bfgs"), "option 'method'"),
        (lambda: opt.pattern_search(rosenbrock, 2, contraction=1.5), "option 'contraction'"),
        (lambda: opt.multistart(rosenbrock, 2, n_stage_one=10, n_trial=5), "n_stage_one"),
        (lambda: opt.multistart(rosenbrock, 2, local_options={"tol": 1}), "local: unknown option 'tol'"),
        (lambda: opt.minimize(rosenbrock, 2, "simplex"), "unknown method 'simplex'"),
        (lambda: opt.minimize(rosenbrock, 2, "pso+ga"), "second stage"),
        (lambda: opt.minimize(rosenbrock, 2, "hybrid", options={"swarm_size": 3}), "hybrid: unknown option"),
        (lambda: opt.hybrid(rosenbrock, 2, global_method="local"), "global_method"),
        (lambda: opt.local(rosenbrock, 0), "n "),
        (lambda: opt.local(rosenbrock, 2, x0=[0.5, 1.5]), "x0"),
        (lambda: opt.local(rosenbrock, 2, seed=-1), "seed"),
        (lambda: Budget(max_evals=0), "max_evals"),
        (lambda: Budget(max_time_s=-1.0), "max_time_s"),
        (lambda: opt.local(lambda U: np.zeros((U.shape[0], 1)), 2), r"objective returned shape"),
    ],
)
def test_bad_arguments_name_the_problem(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_aliases_and_dispatch():
    f = sphere(centre_for(2))
    assert opt.minimize(f, 2, "fmincon").method == "local"
    assert opt.minimize(f, 2, "patternsearch").method == "pattern_search"
    assert opt.minimize(f, 2, "GlobalSearch", seed=0, options={"n_trial": 50, "n_stage_one": 10}).method == "multistart"
    assert opt.minimize(f, 2, "ga", seed=0).method == "genetic"
    assert opt.minimize(f, 2, "particleswarm", seed=0).method == "particle_swarm"
    assert opt.minimize(f, 2, "pso+fmincon", seed=0).method == "particle_swarm+local"
    res = opt.minimize(f, 2, "hybrid", seed=0, options={"global_method": "ga", "local_options": {"fd": "central"}})
    assert res.method == "genetic+local"


def test_x0_is_used():
    c = centre_for(3)
    res = opt.genetic(sphere(c), 3, seed=0, x0=c, budget=Budget(max_evals=60))
    assert res.fun == 0.0 and np.array_equal(res.x, c)
    res = opt.particle_swarm(sphere(c), 3, seed=0, x0=c, budget=Budget(max_evals=30))
    assert res.fun == 0.0


# ------------------------------------------------------------------ CMA-ES
def test_cma_es_finds_the_rosenbrock_minimum_in_batches_and_repeats_with_its_seed():
    fun = Counting(rosenbrock)
    r = opt.minimize(fun, 4, method="cma", seed=3, budget=Budget(max_evals=6000))
    assert r.method == "cma_es" and r.fun < 1e-6
    np.testing.assert_allclose(r.x, 0.75, atol=1e-3)  # x = 1 in [-2, 2]
    assert r.nfev == fun.nfev <= 6000 and max(fun.batches) > 1  # one batch per generation
    again = opt.minimize(rosenbrock, 4, method="cmaes", seed=3, budget=Budget(max_evals=6000))
    np.testing.assert_array_equal(again.x, r.x)


def test_cma_es_hybrid_and_bad_options():
    r = opt.minimize(sphere([0.1, 0.9, 0.4]), 3, method="cma+local", seed=1, budget=Budget(max_evals=3000))
    assert r.method == "cma_es+local" and r.fun < 1e-10
    with pytest.raises(ValueError, match="sigma0"):
        opt.cma_es(sphere([0.5]), 1, sigma0=0.0)
    with pytest.raises(ValueError, match="restarts"):
        opt.minimize(sphere([0.5]), 1, method="cma", options={"restarts": -1})
