"""Per-cell statistics of the estimation studies: measurement noise, convergence traces, seeds, Fisher information.

A *cell* is one approach x optimiser x cost function (x noise level) of a
study; a *run* is one cell with one seed. These helpers add what one run per
cell cannot say:

- :func:`add_noise` puts white Gaussian measurement noise at a given SNR on
  target waveforms;
- :func:`convergence_trace` turns the recorded costs of a run into the best
  cost against the number of evaluations;
- :func:`aggregate` folds the runs of a cell over seeds into one row
  (success rate, median and range of the errors, evaluations, speed);
- :func:`fisher_information` computes the Fisher information of the
  parameters from the residual Jacobian (the Cramer-Rao bound on each
  parameter's relative standard deviation at a stated noise level).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from estimation.verdict import fisher_information  # noqa: F401  (the studies' Fisher information)

#: A run succeeds when every parameter is within this many percent of the target.
SUCCESS_PERCENT = 5.0


def add_noise(waveforms: Mapping[str, np.ndarray], snr_db: float | None, seed: int,
              names: Sequence[str] = ("v_in", "i_in"), averages: int = 1) -> dict[str, np.ndarray]:
    """Copy of ``waveforms`` with white Gaussian noise on ``names`` at ``snr_db``.

    With ``averages`` above 1 the copy is the mean of that many acquisitions of
    the same waveforms, each with its own noise at ``snr_db`` (a triggered,
    averaged record: the noise's standard deviation falls by ``sqrt(averages)``).

    Parameters
    ----------
    waveforms : mapping
        Name to ``(K,)`` samples (V, A).
    snr_db : float or None
        Signal-to-noise ratio, dB: the noise standard deviation is the
        waveform's RMS (about its mean) times ``10 ** (-snr_db / 20)``. None:
        no noise (the waveforms are copied).
    seed : int
        Seed of the noise generator.
    names : sequence of str
        Waveforms that receive noise (others are copied unchanged).
    averages : int, optional
        Acquisitions averaged (default 1: one noisy record).

    Returns
    -------
    dict
    """
    out = {k: np.array(v, float, copy=True) for k, v in waveforms.items()}
    if snr_db is None:
        return out
    rng = np.random.default_rng(seed)
    for k in names:
        if k in out:
            x = out[k]
            sigma = float(np.std(x)) * 10.0 ** (-float(snr_db) / 20.0)
            out[k] = x + sigma * rng.standard_normal((max(int(averages), 1),) + x.shape).mean(axis=0)
    return out


def convergence_trace(costs: np.ndarray, extra: Sequence[tuple[int, float]] = (), points: int = 60
                      ) -> list[list[float]]:
    """Best cost so far against evaluations, thinned to about ``points`` log-spaced entries.

    Parameters
    ----------
    costs : numpy.ndarray
        ``(M,)`` costs in evaluation order.
    extra : sequence of (evaluations, cost)
        Later points (e.g. after a polish), appended in order.

    Returns
    -------
    list of [evaluations, best cost]
    """
    c = np.asarray(costs, float)
    trace: list[list[float]] = []
    if c.size:
        best = np.minimum.accumulate(np.where(np.isfinite(c), c, np.inf))
        idx = np.unique(np.clip(np.round(np.geomspace(1, c.size, points)).astype(int) - 1, 0, c.size - 1))
        trace = [[float(i + 1), float(best[i])] for i in idx if math.isfinite(best[i])]
    last = trace[-1][1] if trace else math.inf
    for n, f in extra:
        last = min(last, float(f))
        if math.isfinite(last):
            trace.append([float(n), last])
    return trace


def success(errors: Mapping[str, float], limit: float = SUCCESS_PERCENT) -> bool:
    """Every parameter within ``limit`` percent."""
    return all(math.isfinite(e) and abs(e) <= limit for e in errors.values())


def aggregate(runs: Sequence[Mapping[str, Any]], key: Callable[[Mapping[str, Any]], Any]) -> list[dict[str, Any]]:
    """One row per cell from its runs over seeds.

    Each row is the run with the lowest cost (its ``errors_percent``,
    ``estimate``, ``cost``), plus ``seeds``, ``success_rate`` (fraction of
    seeds with every parameter within :data:`SUCCESS_PERCENT`),
    ``errors_percent_median`` and ``errors_percent_range`` ([min, max] of the
    signed errors over seeds), ``abs_error_percent_max_median`` (median over
    seeds of the worst parameter's error), ``evaluations`` (median per run),
    ``evals_per_s`` (all evaluations over all wall time), ``wall_s`` (median)
    and ``wall_s_total``; with a Cramer-Rao bound on the runs (``bound_percent``)
    also ``efficiency`` (median ``|error|`` over seeds / bound, per parameter),
    ``efficiency_median`` and ``efficiency_max`` (over the parameters);
    ``failures`` counts the missed seeds by kind (``"cost"``: the approach's
    cost is no higher at the estimate than at the truth; ``"search"``: it is
    higher) and ``cpu_s_total`` sums the runs' processor time.
    """
    cells: dict[Any, list[Mapping[str, Any]]] = {}
    for r in runs:
        cells.setdefault(key(r), []).append(r)
    rows = []
    for group in cells.values():
        best = min(group, key=lambda r: r["cost"] if math.isfinite(r["cost"]) else math.inf)
        names = list(best["errors_percent"])
        E = np.array([[r["errors_percent"][k] for k in names] for r in group], float)
        evals = np.array([r["evaluations"] for r in group], float)
        walls = np.array([r["wall_s"] for r in group], float)
        row = dict(best)
        row.update({
            "seeds": [r["settings"]["seed"] for r in group],
            "success_rate": float(np.mean([bool(r.get("success", success(r["errors_percent"]))) for r in group])),
            "success_rate_5pct": float(np.mean([success(r["errors_percent"]) for r in group])),
            "errors_percent_median": dict(zip(names, np.median(E, axis=0).tolist())),
            "errors_percent_range": {k: [float(E[:, i].min()), float(E[:, i].max())] for i, k in enumerate(names)},
            "abs_error_percent_max_median": float(np.median(np.max(np.abs(E), axis=1))),
            "evaluations": int(np.median(evals)),
            "evals_per_s": float(evals.sum() / max(walls.sum(), 1e-9)),
            "wall_s": float(np.median(walls)),
            "wall_s_total": float(walls.sum()),
            "cost_median": float(np.median([r["cost"] for r in group])),
            "failures": {kind: sum(r.get("failure") == kind for r in group) for kind in ("cost", "search")
                         if any(r.get("failure") == kind for r in group)},
            "cpu_s_total": float(sum(r.get("cpu_s", 0.0) for r in group)),
            "traces": [r.get("trace", []) for r in group],
        })
        row.pop("trace", None)
        bound = best.get("bound_percent")
        if bound:
            eff = {k: float(np.median(np.abs(E[:, i]))) / bound[k] if bound.get(k, 0) > 0 else math.nan
                   for i, k in enumerate(names)}
            finite = [v for v in eff.values() if math.isfinite(v)]
            row.update({"efficiency": eff,
                        "efficiency_median": float(np.median(finite)) if finite else math.nan,
                        "efficiency_max": float(max(finite)) if finite else math.nan})
        rows.append(row)
    return rows
