"""Shared machinery of the thesis's estimation studies: one run, its row, identifiability, the study driver.

A study is a list of :class:`estimation.search.executor.Task` objects, one per run
(case, approach, optimiser, cost function). Each task calls a top-level
``run_*`` function of the study module that builds the target and the
approach, runs the optimiser and returns one **row** (a JSON-ready dict):

``case``, ``approach``, ``optimiser``, ``cost_function``, ``engine``,
``errors_percent`` {parameter: signed % error (estimate - target) / target},
``estimate`` {parameter: value}, ``non_identifiable`` [names], ``cost``,
``wall_s``, ``nfev``, ``per_eval_s``, ``message`` and study-specific extras.

:func:`run_study` sends the tasks through :func:`estimation.search.executor.run_tasks`
(local processes, serial, or a Dask scheduler address), storing each run in
``<out>/runs/<id>.json`` and ``<out>/results.csv`` as it finishes; a rerun
skips stored runs (resume), and writes ``<out>/study.json``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimation.search.executor import ResultsStore, Task, atomic_write_text, run_tasks, to_jsonable
from estimation.search.local_search import PolishResult, Recorder, least_squares_polish, optimise
from estimation.search.optimisers import Budget, OptimResult, minimize
from estimation.parameters import ParameterSet, identifiability


__all__ = ["PolishResult", "Recorder", "least_squares_polish", "optimise"]  # re-exported from local_search


class StudyError(ValueError):
    """Bad study input (unknown study or case, bad option); one-line message."""


def say(text: str) -> None:
    """Progress line on stderr."""
    print(text, file=sys.stderr, flush=True)


def errors_percent(estimate: Mapping[str, float], target: Mapping[str, float]) -> dict[str, float]:
    """Signed percentage errors ``(estimate - target) / target * 100`` (thesis (4.23) without the abs)."""
    return {k: float((estimate[k] - target[k]) / target[k] * 100.0) for k in target if k in estimate}


# ====================================================================== identifiability
def equal_cost_minima(points: np.ndarray, costs: np.ndarray, params: ParameterSet, f_best: float, scale: float,
                      rel_tol: float = 1e-9, min_rel_diff: float = 0.05) -> tuple[list[dict[str, float]], list[str]]:
    """Distinct points whose cost equals the best cost, and the parameters that differ between them.

    Parameters
    ----------
    points : numpy.ndarray
        ``(M, n)`` unit-cube points (e.g. local-solver end points).
    costs : numpy.ndarray
        ``(M,)`` their costs.
    params : ParameterSet
    f_best : float
        Best cost found.
    scale : float
        Typical cost of the problem (e.g. the median cost of random points):
        costs within ``f_best + max(10 |f_best|, rel_tol * scale)`` count as equal.
    min_rel_diff : float
        Two minima are distinct, and a parameter differs between them, when
        the relative difference of a physical value exceeds this.

    Returns
    -------
    minima : list of dict
        Physical values of the distinct equal-cost minima.
    differing : list of str
        Names of the parameters that differ between them (not identifiable
        from this cost).
    """
    tol = max(10 * abs(f_best), rel_tol * max(scale, 1e-300)) + 1e-14
    sel = np.flatnonzero(np.isfinite(costs) & (costs <= f_best + tol))
    names = params.varying
    minima: list[dict[str, float]] = []
    for i in sel[np.argsort(costs[sel])]:
        vals = params.values(points[i])
        v = {k: float(vals[k]) for k in names}
        if all(max(abs(v[k] - m[k]) / max(abs(m[k]), 1e-300) for k in names) > min_rel_diff for m in minima):
            minima.append(v)
    differing = []
    if len(minima) > 1:
        for k in names:
            vals = np.array([m[k] for m in minima])
            if (vals.max() - vals.min()) / max(abs(vals).min(), 1e-300) > min_rel_diff:
                differing.append(k)
    return minima, differing


def swap_symmetries(cost_batch: Callable[[np.ndarray], np.ndarray], params: ParameterSet, x: np.ndarray,
                    f_best: float, scale: float, rel_tol: float = 1e-6,
                    min_rel_diff: float = 0.05) -> list[tuple[str, str, float]]:
    """Pairs of same-kind parameters whose values can be exchanged without changing the cost.

    The estimate's values of each pair (``L1``/``L2``, ...) are swapped (when
    both stay within bounds) and the cost is evaluated there: an equal cost
    means the data cannot tell the two parameters apart (thesis Fig. 4.9).

    Returns
    -------
    list of (name_a, name_b, cost_after_swap)
    """
    names = params.varying
    vals = params.values(x)
    cand, pairs = [], []
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            pa, pb = params[a], params[b]
            if not pa.kind or pa.kind != pb.kind or pa.kind == "K":
                continue
            va, vb = float(vals[a]), float(vals[b])
            if abs(va - vb) / max(abs(va), abs(vb)) <= min_rel_diff:
                continue
            slack = 1e-6  # an estimate on (or a rounding error beyond) a bound still counts
            if not (pa.min * (1 - slack) <= vb <= pa.max * (1 + slack) and pb.min * (1 - slack) <= va <= pb.max * (1 + slack)):
                continue
            new = {k: float(vals[k]) for k in names}
            new[a], new[b] = min(max(vb, pa.min), pa.max), min(max(va, pb.min), pb.max)
            cand.append(params.to_unit(new))
            pairs.append((a, b))
    if not cand:
        return []
    f = np.asarray(cost_batch(np.array(cand)), float)
    tol = max(10 * abs(f_best), rel_tol * max(scale, 1e-300)) + 1e-14
    return [(a, b, float(fi)) for (a, b), fi in zip(pairs, f) if fi <= f_best + tol]


def jacobian_identifiability(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet, x: np.ndarray,
                             rtol: float = 1e-9) -> dict[str, Any]:
    """Local identifiability from the residual Jacobian at the estimate (:func:`estimation.parameters.identifiability`)."""
    names = params.varying
    xi = np.clip(np.asarray(x, float), 1e-4, 1 - 1e-4)
    res = identifiability(lambda u: residuals(np.atleast_2d(u))[0], names, u0=xi, rtol=rtol, step=1e-5)
    s = res.singular_values
    return {"groups": [list(g) for g in res.groups], "insensitive": list(res.insensitive),
            "condition": float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf,
            "non_identifiable": sorted({n for g in res.groups for n in g} | set(res.insensitive))}


# ====================================================================== local probes
def local_probes(approach: Any, seed: int, count: int, budget_evals: int,
                 local_options: Mapping[str, Any] | None = None) -> list[OptimResult]:
    """``count`` extra local solves from seeded random starts (to find other equal-cost minima)."""
    rng = np.random.default_rng(seed + 7919)
    out = []
    for _ in range(count):
        x0 = rng.uniform(0.02, 0.98, approach.n)
        out.append(minimize(approach.cost_batch, approach.n, method="local", seed=seed, x0=x0,
                            budget=Budget(max_evals=budget_evals), options=dict(local_options or {})))
    return out


# ====================================================================== study driver
def run_study(study: str, tasks: Sequence[Task], out: str | Path | None, scheduler: str | None = None,
              workers: int | None = None, progress: bool = True) -> list[dict[str, Any]]:
    """Run (or resume) the tasks of a study and return their rows in task order.

    Parameters
    ----------
    study : str
        Name, for messages.
    tasks : sequence of Task
    out : path, optional
        Results directory (``runs/<id>.json``, ``results.csv``); None keeps nothing on disk.
    scheduler : str, optional
        ``None``/``"processes"`` (local processes), ``"serial"``, or a Dask
        scheduler address ``tcp://host:port``.
    workers : int, optional
        Local process count.
    progress : bool
        Progress lines on stderr.
    """
    store = ResultsStore(out) if out is not None else None
    if progress:
        say(f"study {study}: {len(tasks)} run(s)")
    results = run_tasks(tasks, executor=scheduler or "processes", store=store, progress=progress, workers=workers)
    return [dict(r) for r in results]


def write_summary(out: str | Path | None, summary: Mapping[str, Any]) -> Path | None:
    """Write ``study.json`` (the full JSON answer) into the results directory."""
    if out is None:
        return None
    path = Path(out) / "study.json"
    atomic_write_text(path, json.dumps(to_jsonable(summary), indent=1, allow_nan=False) + "\n")
    return path


def fmt(x: Any, width: int = 9) -> str:
    if x is None:
        return " " * (width - 1) + "-"
    if isinstance(x, str):
        return x.rjust(width)
    if not math.isfinite(x):
        return str(x).rjust(width)
    return f"{x:{width}.3g}" if abs(x) >= 1e-2 or x == 0 else f"{x:{width}.2e}"


def comparison_table(rows: Iterable[Mapping[str, Any]], thesis: Mapping[str, Mapping[str, Any]],
                     key: Callable[[Mapping[str, Any]], str], params: Sequence[str],
                     runtime_label: str = "thesis runtime") -> str:
    """Text table: our signed errors, cost and wall time beside the thesis's numbers, one row pair per run."""
    head = f"{'run':<28}" + "".join(f"{p:>10}" for p in params) + f"{'cost':>11}{'time':>11}  non-identifiable"
    lines = [head, "-" * len(head)]
    for r in rows:
        k = key(r)
        e = r.get("errors_percent", {})
        lines.append(f"{k:<28}" + "".join(fmt(e.get(p), 10) for p in params)
                     + fmt(r.get("cost"), 11) + f"{r.get('wall_s', float('nan')):9.1f} s  "
                     + ",".join(r.get("non_identifiable", [])))
        t = thesis.get(k)
        if t:
            te = t.get("errors_percent", {})
            lines.append(f"{'  thesis':<28}" + "".join(fmt(te.get(p), 10) for p in params)
                         + fmt(t.get("cost"), 11) + f"{fmt(t.get('runtime'), 9)} {t.get('runtime_unit', '')}")
    return "\n".join(lines)


def elapsed(t0: float) -> float:
    return time.perf_counter() - t0
