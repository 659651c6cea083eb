"""A drift answer weighed against the causes fitted: the causes the data barely tell from it, the whole answer a
value's drift set aside must beat, and a cause that explains the data better than the drift left to be reported.

Every comparison is by BIC between whole models: each value freed from the design prior (a value reported off the
design) counts as one parameter, as a cause's own parameters do.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimation.diagnosis.context import NOISE_MARGIN, Context, log
from estimation.diagnosis.converge import converged_job
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import FitResult

#: Two causes whose fits alone are this close in BIC are reported as not told apart by the data
#: (:attr:`.result.Diagnosis.cause_alternatives`): below 2 the evidence is "not worth more than a bare mention" on
#: Kass and Raftery's scale.
CAUSE_TIE_DBIC = 2.0


def whole_answer(ctx: Context, aside: FitResult, final: FitResult, chosen: list[str],
                 results: dict[str, FitResult]) -> FitResult | None:
    """One value off the design set aside for a cause whose single fit had a lower BIC
    (:func:`.diagnose._drift_answer`), weighed against the answer the selection gave (``final``, its causes
    ``chosen``), both whole: their BIC with every value freed from the prior counted as one parameter. The cause that
    set the drift aside may not be named in the end (a new section refused on the points it was not fitted to), and
    what the selection names instead must then beat the drift itself. Returns ``aside`` (its ``cause_ties`` set) when its BIC is the lower, else
    None (``final``'s ``cause_ties`` set when it names no cause: a drift as well)."""
    n = final.n_residuals
    final_bic = final.cause_bic + np.log(n) * (1 if getattr(final, "freed", None) else 0)
    said = ", ".join(chosen) or "no cause"
    if aside.answer_bic >= final_bic:
        log(f"{aside.freed} off the design, set aside: {said} has a BIC lower by {aside.answer_bic - final_bic:.1f}",
            ctx.progress)
        if not chosen:  # the answer is a drift too: the causes its BIC barely tells from it, as when the aside is taken
            final.cause_ties = list(getattr(final, "cause_ties", [])) + [
                t for t in ties(results, final_bic) if abs(t["delta_bic"]) < CAUSE_TIE_DBIC]
        return None
    log(f"{aside.freed} off the design, set aside for a cause: BIC lower by {final_bic - aside.answer_bic:.1f} than "
        f"{said}{' with ' + str(final.freed) if getattr(final, 'freed', None) else ''}: the value's drift is the "
        "answer", ctx.progress)
    near = [t for t in ties(results, aside.answer_bic) if abs(t["delta_bic"]) < CAUSE_TIE_DBIC]
    if chosen and final_bic - aside.answer_bic < CAUSE_TIE_DBIC and " + ".join(chosen) not in {t["cause"] for t in near}:
        near.append({"cause": " + ".join(chosen), "delta_bic": float(final_bic - aside.answer_bic)})
    aside.cause_ties = near
    return aside


def cause_over_drift(ctx: Context, relaxed: FitResult, on_top: list[dict[str, Any]],
                     results: dict[str, FitResult], min_delta_bic: float = 10.0) -> FitResult | None:
    """A cause that explains the data (at the noise, no value far off) with a BIC lower by ``min_delta_bic`` (the
    selection's margin to name a cause) than the drift the selection left to be reported, both whole: the drift's
    model with each value reported off counted as one parameter. The
    selection weighs a cause against the baseline under the prior, whose BIC holds the values it pulled back; the
    values reported off are freed from the prior, and that answer is the one the cause must beat. Both are weighed
    converged: the drift's model is (:func:`.drift.relaxed_drift`), and every cause is refitted from its own values
    (:func:`.converge.converged`, a new section too: no selection goes on from it) before the ones that explain the
    data are sought among them. Returns the cause's fit (the refits replace the causes' entries in ``results``), or
    None. The drift is the model without the cause, and a cause is named over it on the evidence that names it over
    the baseline: a cause lower in BIC by less than ``min_delta_bic`` is not named (a split of section 1 of ten fits
    below the noise the truth's values leave, 8.7 lower than L10 x0.65 off the design, the value really off), and is
    reported beside the drift (``relaxed.cause_tie``), as is one a drift beats by less than ``CAUSE_TIE_DBIC``, and
    a cause at the noise with a value far off (not named over the drift) whose BIC is lower than the drift's or
    within that margin."""
    keys = list(results)
    for c, r in zip(keys, shared_map(converged_job, [(ctx, results[c], True) for c in keys])):
        if r is not results[c]:
            log(f"  {c} refitted to convergence: {results[c].objective:.4g} -> {r.objective:.4g}", ctx.progress)
            results[c] = r
    drift_bic = relaxed.cause_bic + len(on_top) * np.log(relaxed.n_residuals)
    names = ", ".join(d["name"] for d in on_top)
    rivals = [r for r in results.values() if ctx.explained(r)]
    if not rivals:
        # a cause at the noise that moves a value of the design far off is not named over the drift, but with a BIC
        # no worse than the drift's by CAUSE_TIE_DBIC the data do not tell it from the drift: it is reported beside it
        near = [r for r in results.values() if r.objective <= NOISE_MARGIN * ctx.floor
                and r.cause_bic - drift_bic < CAUSE_TIE_DBIC]
        if near:
            best = min(near, key=lambda r: r.cause_bic)
            log(f"{best.cause} fits to the noise with a BIC {best.cause_bic - drift_bic:+.1f} against {names} off the "
                f"design, but moves {', '.join(d['name'] for d in ctx.gross(best))} far off: reported beside the drift",
                ctx.progress)
            relaxed.cause_tie = [{"cause": best.cause, "delta_bic": float(best.cause_bic - drift_bic)}]
        return None
    best = min(rivals, key=lambda r: r.cause_bic)
    if best.cause_bic > drift_bic - min_delta_bic:
        log(f"{names} off the design: BIC {best.cause_bic - drift_bic:+.1f} against {best.cause}, the best cause that "
            f"explains the data (named when lower by {min_delta_bic:g})", ctx.progress)
        if best.cause_bic - drift_bic < CAUSE_TIE_DBIC:
            relaxed.cause_tie = [{"cause": best.cause, "delta_bic": float(best.cause_bic - drift_bic)}]
        return None
    log(f"{best.cause} explains the data with a BIC lower by {drift_bic - best.cause_bic:.1f} than {names} off the "
        "design (each counted): named", ctx.progress)
    best.drift_tie = ([{"cause": f"drift of {names}", "delta_bic": float(drift_bic - best.cause_bic)}]
                      if drift_bic - best.cause_bic < CAUSE_TIE_DBIC else [])
    return best


def ties(results: dict[str, FitResult], drift_bic: float) -> list[dict[str, Any]]:
    """The single causes whose BIC is within ``CAUSE_TIE_DBIC`` of a drift that explains the data (``cause``,
    ``delta_bic``): the data tell the drift only barely from them."""
    ranked = sorted(results.values(), key=lambda r: r.cause_bic)
    return [{"cause": r.cause, "delta_bic": float(r.cause_bic - drift_bic)} for r in ranked
            if r.cause_bic - drift_bic < CAUSE_TIE_DBIC]
