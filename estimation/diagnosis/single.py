"""Each cause of the catalogue fitted alone with the baseline's values: the first pass of a diagnosis.

Every form and winding group of a continuous cause (:mod:`.catalogue`) is
first fitted with the circuit values held (a screening of its start grid),
from the fitted baseline's values and, when the baseline was given and has
absorbed something (values moved far off the design), from the design
values too: a baseline fitted without the effect has absorbed it into
distorted values, a local minimum the full fit seldom leaves, while the
design values are free of it. The best two forms of the first pool and the
best of the second are then fitted in full (circuit values free). A cause
that reaches the noise floor from the fitted baseline needs no second pool,
and once one cause does, the others start from the fitted baseline only.

The causes do not depend on each other's fits but for that last rule, so
the fits of all causes run in batches shared with the helper process
(:mod:`.cores`): every screening from the fitted baseline; the refinements
of those; then, for the causes that may need them (those before the first
that explains the data), the screenings from the design values and their
refinements, two causes at a time with the helper (one without it) until
one explains the data. The rule is then applied in the catalogue's order to what was
fitted, which gives each cause the fit it would have had fitted alone in
that order (a fit the rule does not use is discarded). A missing
section (:mod:`.section_fits`) is fitted at its place in that order.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from pris_cosim.circuit import Circuit

from .catalogue import CoreLoss, Effect, effect_variants, winding_groups
from .context import Context, log
from .cores import helper_available, shared_map
from .fit import CANDIDATE_FAILURES, FitResult, FrequencyFit, configuration_ports, group_names
from .section_fits import fit_missing_section

#: A screened form: its screened cost, the effect, its fit object and the screened result.
Screened = tuple[float, Effect, FrequencyFit, FitResult]
#: Refinements of the first pool (from the fitted baseline) and of the second (from the design values), with their
#: evaluation budgets.
TOP_FIRST, NFEV_FIRST = 2, 50
TOP_SECOND, NFEV_SECOND = 1, 30


def effect_starts(ctx: Context, fit: FrequencyFit, effect: Effect) -> list[dict[str, float]] | None:
    """The start grid of ``effect``'s parameters on ``fit``'s circuit (``None``: the parameters' own starts)."""
    if isinstance(effect, CoreLoss):
        return effect.starts(fit.circuit, fit.circuit.resolve(check=False), ctx.scale, float(ctx.f[0]), float(ctx.f[-1]))
    return None


def _screened_form(args: tuple[Context, Circuit, Effect]) -> tuple[FrequencyFit | None, FitResult | None]:
    """The effect's parameters alone fitted from its start grid on ``circuit``."""
    ctx, circuit, eff = args
    try:
        fit = ctx.fit(circuit, [eff])
        return fit, fit.fit([effect_starts(ctx, fit, eff)], circuit_free=False, max_nfev=40, keep_starts=2)
    except CANDIDATE_FAILURES:
        return None, None


def _refined_form(args: tuple[Context, FrequencyFit, Effect, FitResult, float, int]) -> FitResult | None:
    """A screened form fitted in full, circuit values free."""
    ctx, fit, eff, pre, must_beat, nfev = args
    try:
        return fit.fit([effect_starts(ctx, fit, eff)], x0s=pre.x[None], keep_starts=1, must_beat=must_beat,
                       max_nfev=nfev, tol=1e-6)
    except CANDIDATE_FAILURES:
        return None


def _pool(variants: Sequence[Effect], fitted: Sequence[tuple[FrequencyFit | None, FitResult | None]]
          ) -> list[Screened]:
    """The screened forms by screened cost (the forms whose screening failed left out)."""
    screened = [(pre.cost, eff, fit, pre) for eff, (fit, pre) in zip(variants, fitted) if pre]
    screened.sort(key=lambda t: t[0])
    return screened


def _to_refine(screened: list[Screened], top: int) -> list[Screened]:
    """The best ``top`` forms of a pool; a form that is a special case of another screened form (one relaxation
    time of a distribution) is not refined: the wider form's fit covers it, and it would take another's place."""
    return [t for t in screened if not any(t[1].nested_in(u[1]) for u in screened)][:top]


def _best_refined(screened: list[Screened], refine: list[Screened], refined: Sequence[FitResult | None],
                  must_beat: float, best: FitResult | None) -> FitResult | None:
    """The best of ``best`` and a pool's refinements; a clearly worse form than the pool's best screened one is
    not used once a refinement beats ``must_beat`` (it is fitted beside the first, not used)."""
    for i, ((cost, *_), res) in enumerate(zip(refine, refined)):
        if i and best is not None and best.objective < must_beat and cost > 2 * screened[0][0]:
            break
        if res is not None and (best is None or res.objective < best.objective):
            best = res
    return best


def _by_cause(flat: Sequence[Any], sizes: dict[str, int]) -> dict[str, list[Any]]:
    """A flat batch's results cut back into each cause's share (``sizes``: items per cause, in batch order)."""
    out, k = {}, 0
    for cause, n in sizes.items():
        out[cause] = list(flat[k:k + n])
        k += n
    return out


def _screened_all(ctx: Context, circuit: Circuit, variants: dict[str, list[Effect]]) -> dict[str, list[Screened]]:
    """Every form of every cause screened on ``circuit``, in one batch shared with the helper process."""
    fitted = shared_map(_screened_form, [(ctx, circuit, eff) for forms in variants.values() for eff in forms])
    return {c: _pool(variants[c], part) for c, part in _by_cause(fitted, {c: len(v) for c, v in variants.items()}).items()}


def _refined_all(ctx: Context, refine: dict[str, list[Screened]], must_beat: float, nfev: int
                 ) -> dict[str, list[FitResult | None]]:
    """The forms picked of every cause fitted in full, in one batch shared with the helper process."""
    jobs = [(ctx, fit, eff, pre, must_beat, nfev) for forms in refine.values() for _, eff, fit, pre in forms]
    return _by_cause(shared_map(_refined_form, jobs), {c: len(v) for c, v in refine.items()})


def single_causes(ctx: Context, todo: Sequence[str], baseline: FitResult, progress: bool
                  ) -> tuple[dict[str, FitResult], list[dict[str, Any]], dict[str, list[Effect]]]:
    """Each cause of ``todo`` fitted alone with the baseline's values.

    Returns
    -------
    results : dict
        The fits that end below the baseline's objective, by cause.
    failed : list of dict
        The causes whose every fit ended at or above it (``cause``, ``cost``, ``reason``).
    variants : dict
        The forms of each continuous cause, by screened cost from the fitted baseline.
    """
    t0 = time.perf_counter()
    must_beat = baseline.objective
    circuit = baseline.fitted_circuit()
    # with a design prior, a baseline whose values all stay within GROSS_DRIFT tolerances has absorbed nothing: the
    # design values add no start
    design_start = (ctx.nominal is not None and not baseline.effects
                    and (ctx.prior is None or ctx.distorted(baseline)))
    groups = winding_groups(circuit, configuration_ports(ctx.configs), group_names(ctx.configs))
    continuous = [c for c in todo if c != "missing-section"]
    variants = {c: effect_variants(c, groups, circuit, float(ctx.f[0]), ctx.one_port, ctx.scale, float(ctx.f[-1]),
                                   level=ctx.prior is not None) for c in continuous}

    # every form of every cause screened from the fitted baseline's values
    first = _screened_all(ctx, circuit, {c: variants[c] for c in continuous})
    refine_first = {c: _to_refine(first[c], TOP_FIRST) for c in continuous}
    # their best forms refined
    refined_first = _refined_all(ctx, refine_first, must_beat, NFEV_FIRST)
    best_first = {c: _best_refined(first[c], refine_first[c], refined_first[c], must_beat, None) for c in continuous}
    second: dict[str, list[Screened]] = {}
    refine_second: dict[str, list[Screened]] = {}
    refined_second: dict[str, list[FitResult | None]] = {}
    if design_start:
        # from the design values, the causes that may need them: those before the first cause that explains the
        # data from the fitted baseline (every later one starts from the fitted baseline only) and do not; taken in
        # order, as many at a time as there are processes, until one's fit from them explains the data (the helper's
        # fit of the next cause, run beside it, is then not used)
        need = []
        for c in continuous:
            b = best_first[c]
            if b is not None and b.objective < must_beat and ctx.explained(b):
                break
            if b is None or not ctx.explained(b):
                need.append(c)
        width = 2 if helper_available() else 1
        for k in range(0, len(need), width):
            chunk = need[k:k + width]
            second.update(_screened_all(ctx, ctx.nominal, {c: variants[c] for c in chunk}))
            refine_second.update({c: _to_refine(second[c], TOP_SECOND) for c in chunk})
            refined_second.update(_refined_all(ctx, {c: refine_second[c] for c in chunk}, must_beat, NFEV_SECOND))
            finals = [_best_refined(second[c], refine_second[c], refined_second[c], must_beat, best_first[c])
                      for c in chunk]
            if any(r is not None and r.objective < must_beat and ctx.explained(r) for r in finals):
                break
    log(f"every form of {len(continuous)} causes fitted in {time.perf_counter() - t0:.1f} s", progress)

    # the rule applied in the catalogue's order: once a cause explains the data, the others start from the fitted
    # baseline only
    results: dict[str, FitResult] = {}
    failed: list[dict[str, Any]] = []
    for cause in todo:
        t = time.perf_counter()
        explained = any(ctx.explained(r) for r in results.values())
        if cause == "missing-section":
            res = fit_missing_section(ctx, baseline, [], must_beat=must_beat)
            # the structures also from the baseline's optimum nearest the given values (:func:`.baseline.fit_multistart`):
            # a split of a better-fitting but more distorted optimum can stop far above the split of the other
            # (not once another cause explains the data to the noise: the split then only has to be ranked)
            alt = getattr(baseline, "alternative", None)
            if alt is not None and not explained:
                other = fit_missing_section(ctx, alt, [], must_beat=must_beat)
                if other is not None and (res is None or other.objective < res.objective):
                    res = other
            seconds = f" ({time.perf_counter() - t:.1f} s)"
        else:
            res = best_first[cause]
            if design_start and not explained and not (res is not None and ctx.explained(res)):
                if cause not in refined_second:  # not foreseen above (cannot happen): fitted now
                    second[cause] = _pool(variants[cause], [_screened_form((ctx, ctx.nominal, eff))
                                                            for eff in variants[cause]])
                    refine_second[cause] = _to_refine(second[cause], TOP_SECOND)
                    refined_second[cause] = [_refined_form((ctx, fit, eff, pre, must_beat, NFEV_SECOND))
                                             for _, eff, fit, pre in refine_second[cause]]
                res = _best_refined(second[cause], refine_second[cause], refined_second[cause], must_beat, res)
            seconds = ""
        if res is None:
            continue
        if res.objective >= must_beat:
            failed.append({"cause": cause, "cost": res.cost, "reason": "every start ended at or above the baseline cost"})
            log(f"{cause}: failed (cost {res.cost:.4g} >= baseline {baseline.cost:.4g})", progress)
            continue
        results[cause] = res
        log(f"{cause}: {res.structure or res.effects[0].label}: cost {res.cost:.4g}, gain "
            f"{1 - res.cost / baseline.cost:.3f}, dBIC {baseline.bic - res.bic:.1f}{seconds}", progress)
    return results, failed, {c: [t[1] for t in first[c]] for c in continuous}
