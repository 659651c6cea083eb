"""Three-section winding study, thesis 4.2.2-4.2.6 (Tables 4.7-4.10, Figs. 4.19-4.22).

Target: the three-section winding of Table 4.7 (``Rs = 0.083 Ohm``,
``Cs = 970 pF``, ``Cg = 1.6 nF``, ``Ls = 181 uH``, ``k12 = 0.8792``,
``k13 = 0.8729``, ``k23 = 0.8564``), perturbed at its terminal by the PRIS
source of 4.2.2: 100 V, f_clk = 100 kHz, series RLC 150 Ohm / 4 mH / 1 uF.

Estimated vector (4.27) ``[Rs, Cs, Cg, Ls, k12, k13, k23]`` with the scales
(4.28) ``[1e-3, 1e-12, 1e-9, 1e-6, 1e-2, 1e-2, 1e-2]`` and the bounds of
Table 4.8 (scaled: 1..1000 for R, L, C; 85..95 for the couplings). The
optimisers work on the unit cube (log10 for R, L, C; linear for k) and are
followed by the local solver (the thesis refines with ``fmincon``).

Approaches (4.2.4-4.2.5), each with an RMSE-type and a correlation cost:

``frequency``
    Input impedance of the estimate from a simulated PRIS perturbation
    (PRBS12, one period of 40.95 ms, sampled at 2.5 MHz; the batched exact
    engine), Welch H1 with Hann, 62.5 % overlap, half-record segments;
    ``C^z_rmse`` (4.29) / ``C^z_rho`` (4.31) on the bins nearest to 200
    log-spaced frequencies from 2 kHz to 1 MHz.
``time``
    PRBS6 (630 us), the target's current sampled at 11 MHz injected into the
    estimate (4.2.3); ``C^v_rmse`` (4.32) / ``C^v_rho`` (4.34) against the
    target's terminal voltage from the PRIS arrangement (so even the true
    parameters leave the discretisation discrepancy of Fig. 4.14).
``emd`` / ``iemd``
    The same voltages through EMD: ``C^m_nrmse`` (4.39) / ``C^m_rho``
    (4.42), and the inferred IMFs ``C^i_nrmse`` (4.45) / ``C^i_rho`` (4.46).

Optimisers: GA and PSO, then the local solver. The thesis used populations
of 1000 and 250 iterations; the full study here uses 200 and 100 (the
budgets are in :func:`optimiser_settings`), ``--quick`` much less (a
quick run shows the same ranking, not the same digits).

Search spaces (Figs. 4.19-4.22): the cost of every approach and metric as
Rs, Cs, Cg, Ls move one at a time from the target (steps of 0.2 % in the
full study), written as ``search_space_<approach>.png``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from pris_cosim import timedomain as td
from pris_cosim.arrangement import SourceSettings
from pris_cosim.models import get_model

from .. import approaches as ap
from ..executor import Task
from ..optimisers import Budget
from ..parameters import ParameterSet
from . import common

NAME = "three-section"
PORT = "n1"
NAMES = ["Rs", "Cs", "Cg", "Ls", "k12", "k13", "k23"]
TARGET = {"Rs": 0.083, "Cs": 970e-12, "Cg": 1.6e-9, "Ls": 181e-6, "k12": 0.8792, "k13": 0.8729, "k23": 0.8564}
#: Scales (4.28).
SCALES = {"Rs": 1e-3, "Cs": 1e-12, "Cg": 1e-9, "Ls": 1e-6, "k12": 1e-2, "k13": 1e-2, "k23": 1e-2}
#: Table 4.8 (scaled bounds).
SCALED_BOUNDS = {"Rs": (1, 1000), "Cs": (1, 1000), "Cg": (1, 1000), "Ls": (1, 1000),
                 "k12": (85, 95), "k13": (85, 95), "k23": (85, 95)}
SOURCE_FRF = SourceSettings(vdc=100.0, prbs_order=12, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
SOURCE_TIME = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
FS_FRF = 2.5e6
FS_TIME = 11e6
F_MIN, F_MAX, N_POINTS = 2e3, 1e6, 200
APPROACHES = ["frequency", "time", "emd", "iemd"]
OPTIMISERS = ["ga", "pso"]
METRICS = ["rmse", "correlation"]
SHOWN = ["Rs", "Cs", "Cg", "Ls"]


def _thesis(errors: Sequence[float], cost: float, runtime: float) -> dict[str, Any]:
    return {"errors_percent": dict(zip(NAMES, errors)), "cost": cost, "runtime": runtime,
            "runtime_unit": "(unit not stated)"}


#: Thesis Table 4.9 (RMSE-type costs) and Table 4.10 (correlation costs, C given x 1e-3 there).
THESIS: dict[str, dict[str, Any]] = {
    "frequency/ga/rmse": _thesis([-299.2, -2.69, -3.61, 5.68, -8.83, 0.04, -4.70], 2.6098, 15.71),
    "frequency/pso/rmse": _thesis([-242.5, -3.09, 0.67, 2.55, -8.83, 0.03, -5.29], 2.5917, 29.89),
    "time/ga/rmse": _thesis([91.85, 95.31, -1512, 94.61, -5.06, -4.92, -6.45], 32.543, 4.51),
    "time/pso/rmse": _thesis([1.14, -1.91, -0.59, 1.73, -4.78, -3.15, 0.53], 1.0859, 12.33),
    "emd/ga/rmse": _thesis([-977.6, 66.44, -519.1, 77.94, -4.82, 2.15, -2.01], 1.0854, 3.26),
    "emd/pso/rmse": _thesis([36.90, -3.03, -59.55, 33.47, -5.03, 2.50, -0.50], 0.5516, 5.92),
    "iemd/ga/rmse": _thesis([34.56, 38.53, -761.1, 89.68, -8.79, -8.83, -1.52], 49.695, 6.42),
    "iemd/pso/rmse": _thesis([1.14, -1.91, -0.59, 1.73, -4.78, -3.15, 0.53], 0.5067, 8.33),
    "frequency/ga/correlation": _thesis([93.36, 36.21, -6890, -321.1, -0.824, -6.534, -6.758], 14.94e-3, 13.87),
    "frequency/pso/correlation": _thesis([45.23, -0.50, 37.50, -40.25, -3.73, -8.80, -6.70], 0.452e-3, 11.81),
    "time/ga/correlation": _thesis([-14.26, 12.30, -66.13, 36.26, -1.298, -6.792, -2.9295], 0.426e-3, 0.714),
    "time/pso/correlation": _thesis([83.13, 47.17, -723.1, 86.26, -4.85, -5.45, -8.03], 0.422e-3, 4.31),
    "emd/ga/correlation": _thesis([-543.24, 74.29, -155.5, 58.679, -8.605, -3.876, -4.442], 629e-3, 2.46),
    "emd/pso/correlation": _thesis([-941.4, 25.25, 37.50, -51.22, 0.42, -3.10, -0.41], 38.41e-3, 1.76),
    "iemd/ga/correlation": _thesis([98.79, 43.58, -46257, -452.49, -2.957, -6.1796, -10.935], 6016e-3, 2.43),
    "iemd/pso/correlation": _thesis([-84.61, 21.58, -3.74, -0.91, 0.67, 1.88, 0.74], 390e-3, 8.87),
}


def make_params() -> ParameterSet:
    """[Rs, Cs, Cg, Ls, k12, k13, k23] with the scales (4.28) and the bounds of Table 4.8."""
    model = get_model(NAME)
    bounds = {k: (SCALED_BOUNDS[k][0] * SCALES[k], SCALED_BOUNDS[k][1] * SCALES[k]) for k in NAMES}
    ps = ParameterSet.from_model(model, names=NAMES, bounds=bounds, passivity="repair")
    for k in NAMES:
        ps.set(k, theta_scale=SCALES[k], scale="log" if not k.startswith("k") else "linear")
    return ps


def frequency_target() -> tuple[dict[str, np.ndarray], np.ndarray, int, ap.WelchSettings, np.ndarray]:
    """Target Zin from one simulated PRBS12 period, Welch H1 with the thesis's settings."""
    circuit = get_model(NAME).circuit
    w = td.simulate_pris(circuit, PORT, SOURCE_FRF, FS_FRF, periods=1)
    n = w["time_s"].size
    welch = ap.WelchSettings()
    bins, f = ap.bin_frequencies(FS_FRF, welch.segment(n), F_MIN, F_MAX, N_POINTS)
    _, resp, _ = ap.responses_from_waveforms(w, FS_FRF, [ap.ZIN_SPEC["Zin"]], welch, bins)
    return resp, f, n, welch, bins


def time_target() -> dict[str, np.ndarray]:
    """Target waveforms: one PRBS6 period at 11 MHz (the current is what the estimate receives)."""
    return td.simulate_pris(get_model(NAME).circuit, PORT, SOURCE_TIME, FS_TIME, periods=1)


def build_approach(approach: str, metric: str, params: ParameterSet | None = None) -> ap.Approach:
    """One approach with one cost metric, target built here."""
    params = params or make_params()
    circuit = get_model(NAME).circuit
    if approach == "frequency":
        target, f, n, welch, bins = frequency_target()
        engine = ap.PrisEngine(circuit, PORT, SOURCE_FRF, FS_FRF, n, probes=[])
        cost = ap.frequency_cost("rmse" if metric == "rmse" else "correlation", ["Zin"])
        return ap.SimulatedFrequency(params, engine, [ap.ZIN_SPEC["Zin"]], welch, bins, target, cost, chunk=8)
    if approach in ("time", "emd", "iemd"):
        w = time_target()
        engine = ap.InjectionEngine(circuit, PORT, w["i_in"], FS_TIME)
        cls = {"time": ap.TimeDomain, "emd": ap.EMDApproach, "iemd": ap.IEMDApproach}[approach]
        return cls(params, engine, w["v_in"], metric)
    raise common.StudyError(f"three-section approach must be one of {', '.join(APPROACHES)} (got {approach!r})")


def optimiser_settings(approach: str, optimiser: str, quick: bool) -> tuple[str, dict[str, Any], Budget]:
    """Method name, options and budget: population and iterations reduced from the thesis's 1000 x 250."""
    pop, iters = (60, 50) if quick else (300, 150)
    if approach == "frequency":
        pop, iters = (24, 12) if quick else (100, 60)
    if approach == "emd":
        pop, iters = (16, 8) if quick else (100, 50)
    if optimiser == "ga":
        glob = {"pop_size": pop, "max_generations": iters}
        method = "ga+local"
    else:
        glob = {"swarm_size": pop, "max_iter": iters}
        method = "pso+local"
    local = {"max_iter": 20 if quick else 200}
    evals = pop * (iters + 1) + (200 if quick else 3000)
    return method, {"global_options": glob, "local_options": local, "global_share": 0.85}, Budget(max_evals=evals)


def run_one(approach: str, optimiser: str, metric: str, quick: bool = True, seed: int = 1) -> dict[str, Any]:
    """One run of Table 4.9/4.10: approach x optimiser x cost metric; one row."""
    t0 = time.perf_counter()
    params = make_params()
    a = build_approach(approach, metric, params)
    u_target = params.to_unit({k: TARGET[k] for k in NAMES})
    cost_at_target = float(a.cost_batch(u_target[None])[0])
    method, options, budget = optimiser_settings(approach, optimiser, quick)
    res, _ = common.optimise(a, method, seed, budget, options)
    values = params.values(res.x)
    est = {k: float(values[k]) for k in NAMES}
    errors = common.errors_percent(est, TARGET)
    return {
        "study": NAME,
        "case": f"{approach}/{optimiser}/{metric}",
        "approach": approach,
        "optimiser": optimiser,
        "cost_function": metric,
        "engine": a.engine,
        "errors_percent": errors,
        "estimate": est,
        "within_10pct": int(sum(abs(e) < 10 for e in errors.values())),
        "non_identifiable": [],
        "cost": float(res.fun),
        "cost_at_target": cost_at_target,
        "wall_s": time.perf_counter() - t0,
        "nfev": int(res.nfev),
        "per_eval_s": a.stats.per_eval_s,
        "optimiser_message": res.message,
        "settings": {"quick": quick, "seed": seed, "method": method, **options, "max_evals": budget.max_evals},
    }


def search_space(approach: str, quick: bool = True, span: float | None = None, step: float | None = None
                 ) -> dict[str, Any]:
    """Costs (both metrics) as Rs, Cs, Cg, Ls move one at a time from the target (Figs. 4.19-4.22)."""
    span = span if span is not None else (0.2 if quick else 0.5)
    step = step if step is not None else (0.02 if quick else 0.002)
    params = make_params()
    rel = np.round(np.arange(-span, span + step / 2, step), 10)
    out: dict[str, Any] = {"approach": approach, "relative_change": rel.tolist(), "costs": {}}
    for metric in METRICS:
        a = build_approach(approach, metric, params)
        per: dict[str, list[float]] = {}
        for name in SHOWN:
            pts = []
            for r in rel:
                v = dict(TARGET)
                v[name] = TARGET[name] * (1 + r)
                pts.append(params.to_unit(v))
            per[name] = [float(c) for c in a.cost_batch(np.clip(np.array(pts), 0, 1))]
        out["costs"][metric] = per
    return out


def tasks(quick: bool = True, seed: int = 1, approaches: Sequence[str] | None = None) -> list[Task]:
    mode = "quick" if quick else "full"
    chosen = list(approaches) if approaches else APPROACHES
    for a in chosen:
        if a not in APPROACHES:
            raise common.StudyError(f"three-section approach must be one of {', '.join(APPROACHES)} (got {a!r})")
    out = [Task(f"three-section-{a}-{o}-{m}-{mode}-seed{seed}", run_one,
                {"approach": a, "optimiser": o, "metric": m, "quick": quick, "seed": seed},
                label=f"three-section {a} {o} {m}")
           for m in METRICS for a in chosen for o in OPTIMISERS]
    out += [Task(f"three-section-searchspace-{a}-{mode}", search_space, {"approach": a, "quick": quick},
                 label=f"three-section search space {a}") for a in chosen]
    return out


def run(quick: bool = True, out: str | None = None, scheduler: str | None = None, workers: int | None = None,
        seed: int = 1, progress: bool = True, approaches: Sequence[str] | None = None) -> dict[str, Any]:
    """Run (or resume) the study; the JSON answer of ``pris-cosim study three-section``."""
    t0 = time.perf_counter()
    ts = tasks(quick, seed, approaches)
    results = common.run_study(NAME, ts, out, scheduler, workers, progress)
    rows = [r for r in results if "errors_percent" in r]
    spaces = [r for r in results if "relative_change" in r]
    figures = []
    if out is not None:
        from ..plotting import search_space_figure

        for sp in spaces:
            path = Path(out) / f"search_space_{sp['approach']}.png"
            search_space_figure(sp, path)
            figures.append(str(path))
    table = common.comparison_table(rows, THESIS, lambda r: r["case"], NAMES)
    summary = {"study": NAME, "quick": quick, "rows": rows, "thesis": THESIS, "search_spaces": spaces,
               "figures": figures, "wall_s": time.perf_counter() - t0, "table": table, "out": out}
    common.write_summary(out, summary)
    if progress:
        common.say(table)
    return summary
