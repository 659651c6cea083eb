"""The three-section study's time paths when the record shows too few modes to guide the search.

Behind the ADC cell's anti-alias filter (:data:`estimation.studies.three_section.study.ADC`) the record shows
one ringing mode, fewer than the modal stage needs (:data:`~estimation.studies.three_section.study.MODAL_MIN_MODES`).
The voltage is then fitted from restarts of the optimiser with least squares, its worst-determined
parameters are profiled (:func:`estimation.search.local_search.profile_scan`), and the approach's own cost
refines the answer as on the modal route.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation.parameters import ParameterSet
from estimation.search import local_search
from estimation.studies import cells, common
from estimation.studies.three_section.cases import (MODAL_MIN_MODES, NAME, NAMES, PROFILED, TARGET, Level,
    _own_cost_stage, build_approach, case_key, optimiser_settings)


def run_unguided(a: ap.Approach, params: ParameterSet, approach: str, optimiser: str, metric: str, quick: bool,
                 seed: int, snr_db: Level, plan: dict[str, Any], cost_at_target: float, t0: float
                 ) -> dict[str, Any]:
    """Time, EMD, IEMD when the record shows fewer than :data:`MODAL_MIN_MODES` modes (behind an anti-alias
    filter): the voltage fit restarted (the optimiser + local, least squares), its :data:`PROFILED`
    worst-determined parameters profiled in turn (:func:`estimation.search.local_search.profile_scan`), then the
    approach's own cost as in :func:`_run_modal`."""
    m = plan["modal"]
    vplan = optimiser_settings("time", optimiser, quick)  # the voltage fit's budgets, whatever the approach
    own_ls = metric == "rmse" and approach in ("time", "iemd")
    volt = a if approach == "time" and metric == "rmse" else build_approach("time", "rmse", params, snr_db, seed)
    best_x, best_c, nfev, notes = None, math.inf, 0, []
    for k in range(m["restarts"]):
        res, _ = common.optimise(volt, vplan["method"], 1000 * seed + k, vplan["budget"], vplan["options"])
        pol = common.least_squares_polish(volt, res.x, max_nfev=vplan["polish_iterations"],
                                          max_time_s=vplan["polish_time_s"])
        nfev += int(res.nfev) + int(pol["nfev"])
        c = float(volt.cost_batch(np.asarray(pol["x"])[None])[0])
        notes.append(f"start {k + 1}: voltage cost {c:.4g}")
        if c < best_c:
            best_x, best_c = np.asarray(pol["x"]), c
    assert best_x is not None
    x = best_x
    for k_p in local_search.sloppy_parameters(volt, best_x, PROFILED):
        prof = local_search.profile_scan(volt, x, k_p)
        nfev += int(prof["nfev"]) + volt.n + 1
        c_prof = float(volt.cost_batch(np.asarray(prof["x"])[None])[0])
        notes.append(f"profile of {NAMES[k_p]}: voltage cost {best_c:.4g} -> {min(c_prof, best_c):.4g}")
        if c_prof < best_c:
            x, best_c = np.asarray(prof["x"]), c_prof
    if a is not volt:
        x, n2 = _own_cost_stage(a, x, own_ls, plan, seed)
        nfev += n2
    cost = float(a.cost_batch(x[None])[0])
    values = params.values(x)
    est = {k: float(values[k]) for k in NAMES}
    errors = common.errors_percent(est, TARGET)
    wall = time.perf_counter() - t0
    second = "" if a is volt else (" -> least squares on the cost's residuals" if own_ls else
                                    " -> local solver on the cost")
    method = (f"{m['restarts']} x [{vplan['method']} on the voltage -> least squares]; lowest kept; its "
              f"{PROFILED} worst-determined parameters profiled{second} (fewer than {MODAL_MIN_MODES} modes in the "
              "record)")
    return {
        "study": NAME, "case": case_key(approach, optimiser, metric, snr_db), "approach": approach,
        "optimiser": optimiser, "cost_function": metric, "snr_db": snr_db, "drive": "bridge", "engine": a.engine,
        "errors_percent": errors, "estimate": est, "success": cells.success(errors),
        "success_rate": float(cells.success(errors)), "within_10pct": int(sum(abs(e) < 10 for e in errors.values())),
        "non_identifiable": [], "cost": cost, "cost_at_target": cost_at_target, "wall_s": wall, "nfev": nfev,
        "evaluations": nfev, "evals_per_s": nfev / max(wall, 1e-9), "per_eval_s": a.stats.per_eval_s,
        "optimiser_message": "; ".join(notes), "method": method, "trace": [[float(nfev), cost]],
        "settings": {"quick": quick, "seed": seed, "method": method, "restarts": m["restarts"],
                     "max_evals": plan["budget"].max_evals, "polish_iterations": plan["polish_iterations"]},
    }
