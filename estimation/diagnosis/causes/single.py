"""Each cause of the catalogue fitted alone with the baseline's values: the first pass of a diagnosis.

Every form and winding group of a continuous cause (:mod:`.catalogue`) is
first fitted with the circuit values held (a screening of its start grid),
from the fitted baseline's values and, when the baseline was given and has
absorbed something (values moved far off the design), from the design
values too: a baseline fitted without the effect has absorbed it into
distorted values, a local minimum the full fit seldom leaves, while the
design values are free of it. The best two forms of the first pool, and
every form of the second, are then fitted in full (circuit values free). A
form screened on the design values is held at resonances that miss the
measured ones, and that miss, not the form, sets its screened cost: so each
form of the second pool starts with its resonances moved onto the measured
ones (:func:`.align.aligned_start`), and none is ranked out before. A cause
that reaches the noise floor from the fitted baseline needs no second pool,
and once one cause does, the others start from the fitted baseline only.

When the baseline has values beyond the tolerance, the best fit of each
cause is also followed from the baseline's values back onto the tolerance
(:func:`onto_tolerance`), and kept when its BIC is lower.

Each batch (the screenings of a cause's forms; their refinements, with the
screenings from the design values beside them) is shared with the helper
process (:mod:`.cores`). A missing section (:mod:`.section_fits`) is fitted
at its place in the catalogue's order.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit

from estimation.diagnosis.align import aligned_start
from estimation.diagnosis.causes.catalogue import CoreLoss, Effect, effect_variants, winding_groups
from estimation.diagnosis.context import Context, log
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import (CANDIDATE_FAILURES, FitResult, FrequencyFit, configuration_ports, current_nc,
                                     group_names)
from estimation.diagnosis.causes.section_fits import fit_missing_section
from estimation.diagnosis.onto_box import onto_box

#: A screened form: its screened cost, the effect, its fit object and the screened result.
Screened = tuple[float, Effect, FrequencyFit, FitResult]
#: Refinements of the first pool (from the fitted baseline: its best two by screened cost) and of the second (from
#: the design values: every form, as the screened costs there measure the resonances' miss, not the form), with
#: their evaluation budgets.
TOP_FIRST, NFEV_FIRST = 2, 50
NFEV_SECOND = 30


def effect_starts(ctx: Context, fit: FrequencyFit, effect: Effect) -> list[dict[str, float]] | None:
    """The start grid of ``effect``'s parameters on ``fit``'s circuit (``None``: the parameters' own starts)."""
    if isinstance(effect, CoreLoss):
        return effect.starts(fit.circuit, fit.circuit.resolve(check=False), ctx.scale, float(ctx.f[0]), float(ctx.f[-1]))
    return None


def start_grid(ctx: Context, fit: FrequencyFit, effect: Effect) -> list[dict[str, float]]:
    """The start grid of ``effect``'s parameters on ``fit``'s circuit: :func:`effect_starts`, else every combination
    of the parameters' own starts (the geometric middle of the bounds for a parameter without any)."""
    return effect_starts(ctx, fit, effect) or [
        dict(zip([p.name for p in effect.parameters], vals))
        for vals in itertools.product(*[p.starts or (np.sqrt(p.lower * p.upper),) for p in effect.parameters])]


def start_tails(ctx: Context, fit: FrequencyFit, effect: Effect) -> list[list[float]]:
    """:func:`start_grid` as parameter vectors (log-scaled where the parameter is)."""
    return [[np.log(g[p.name]) if p.log else g[p.name] for p in effect.parameters] for g in start_grid(ctx, fit, effect)]


def _screened_form(args: tuple[Context, Circuit, Effect]) -> tuple[FrequencyFit | None, FitResult | None]:
    """The effect's parameters alone fitted from its start grid on ``circuit``."""
    ctx, circuit, eff = args
    try:
        fit = ctx.fit(circuit, [eff])
        return fit, fit.fit([effect_starts(ctx, fit, eff)], circuit_free=False, max_nfev=40, keep_starts=2)
    except CANDIDATE_FAILURES:
        return None, None


def _refined_form(args: tuple[Context, FrequencyFit, Effect, FitResult, float, int, bool]) -> FitResult | None:
    """A screened form fitted in full, circuit values free; with ``align`` from its resonances moved onto the
    measured ones (:func:`.align.aligned_start`, the effect's screened parameters kept)."""
    ctx, fit, eff, pre, must_beat, nfev, align = args
    try:
        x0 = aligned_start(fit, pre.x) if align else None
        return fit.fit([effect_starts(ctx, fit, eff)], x0s=(pre.x if x0 is None else x0)[None], keep_starts=1,
                       must_beat=must_beat, max_nfev=nfev, tol=1e-6)
    except CANDIDATE_FAILURES:
        return None


def _pool(variants: Sequence[Effect], fitted: Sequence[tuple[FrequencyFit | None, FitResult | None]]
          ) -> list[Screened]:
    """The screened forms by screened cost (the forms whose screening failed left out)."""
    screened = [(pre.cost, eff, fit, pre) for eff, (fit, pre) in zip(variants, fitted) if pre]
    screened.sort(key=lambda t: t[0])
    return screened


def _to_refine(screened: list[Screened], top: int) -> list[Screened]:
    """The best ``top`` forms of a pool by screened cost, and the best by screened BIC when it is not among them
    (the forms differ in parameter counts, and the refined ones are weighed by BIC: a form with fewer parameters
    that screens a little above another may be the better); a form that is a special case of another screened form
    (one relaxation time of a distribution) is not refined: the wider form's fit covers it, and it would take
    another's place."""
    open_ = [t for t in screened if not any(t[1].nested_in(u[1]) for u in screened)]
    out = open_[:top]
    by_bic = min(open_, key=lambda t: t[3].bic, default=None)
    return out + ([by_bic] if by_bic is not None and all(by_bic is not t for t in out) else [])


def _best_refined(screened: list[Screened], refine: list[Screened], refined: Sequence[FitResult | None],
                  must_beat: float, best: FitResult | None, ranked: bool = True) -> FitResult | None:
    """The best of ``best`` and a pool's refinements by BIC; when the pool is ``ranked`` by its screened costs, a form
    clearly worse than the pool's best screened one is not used once a fit beats ``must_beat`` (it is fitted beside
    the first, not used)."""
    for i, ((cost, *_), res) in enumerate(zip(refine, refined)):
        if ranked and i and best is not None and best.objective < must_beat and cost > 2 * screened[0][0]:
            break
        if res is not None and (best is None or res.bic < best.bic):  # the forms differ in parameter counts
            best = res
    return best


def _form_job(job: tuple[Any, tuple]) -> Any:
    """``fn(args)`` of a ``(fn, args)`` pair: a screening and a refinement in one batch (:func:`fit_cause`)."""
    fn, args = job
    return fn(args)


def fit_cause(ctx: Context, cause: str, base: FitResult, must_beat: float, from_nominal: bool = True
              ) -> tuple[FitResult | None, list[Effect]]:
    """Every form and group of ``cause``: effect-only fits from the start grids, then the best in full.

    The best forms of the first pool (from ``base``'s fitted values) and,
    unless those reach the noise floor or ``from_nominal`` is false, every
    form of the second (from the design values with the resonances aligned,
    when the baseline was given and ``base`` has no effect) are fitted in
    full. Returns the best fit and the forms by screened cost from ``base``.
    """
    circuit = base.fitted_circuit()
    groups = winding_groups(circuit, configuration_ports(ctx.configs), group_names(ctx.configs))
    variants = effect_variants(cause, groups, circuit, float(ctx.f[0]), ctx.one_port, ctx.scale, float(ctx.f[-1]),
                               level=ctx.prior is not None)
    pools: list[list[Screened]] = []
    best = None
    starts = [circuit] + ([ctx.nominal] if ctx.nominal is not None and not base.effects and from_nominal else [])
    # the design values' screening goes in the batch of the first refinement (not used if that reaches the noise)
    ahead = None
    for k, start in enumerate(starts):
        if pools and best is not None and ctx.explained(best):
            break  # explained to the noise from the fitted baseline: the design values are not needed
        fitted = ahead if ahead is not None else shared_map(_screened_form, [(ctx, start, eff) for eff in variants])
        screened = _pool(variants, fitted)
        pools.append(screened)
        top, nfev = (TOP_FIRST, NFEV_FIRST) if k == 0 else (len(screened), NFEV_SECOND)
        refine = _to_refine(screened, top)
        jobs = [(_refined_form, (ctx, fit, eff, pre, must_beat, nfev, k > 0)) for _, eff, fit, pre in refine]
        following = [(_screened_form, (ctx, starts[k + 1], eff)) for eff in variants] if k + 1 < len(starts) else []
        done = shared_map(_form_job, jobs + following)
        ahead = done[len(jobs):] if following else None
        best = _best_refined(screened, refine, done[: len(jobs)], must_beat, best, ranked=k == 0)
    if best is not None and best.effects and ctx.prior is not None and ctx.drift(base):
        # the baseline's values beyond the tolerance may hold this cause's share: followed back onto the tolerance
        # with the cause fitted at each step, they either return (the cause takes their share) or cannot
        followed = onto_tolerance(ctx, base, best)
        if followed is not None and followed.bic < best.bic:
            best = followed
    return best, [t[1] for t in pools[0]]


def onto_tolerance(ctx: Context, base: FitResult, res: FitResult) -> FitResult | None:
    """``res`` (a cause fitted on ``base``'s values) followed from those values onto the design's tolerance.

    A baseline fitted without an effect absorbs it into values moved beyond
    the tolerance, and a fit of the effect from there stays in that basin
    (the effect gains little while the values hold its share), while from
    the design values its resonances are not aligned with the data's. Here
    the bounds of every value the prior holds close from where it starts
    onto its tolerance box (:func:`.onto_box.onto_box`), the effect fitted
    at each step: the data keep the resonances aligned while the values
    return, and the effect's parameters take what the values can no longer
    hold. A cause that is really there reaches the noise with every value
    back within the tolerance; one that is not cannot follow. Returns the
    released fit, or ``None`` when a fit fails.
    """
    try:
        fit = ctx.fit(base.fitted_circuit(), list(res.effects))
        if not fit.anchored_columns.size:
            return None
        out = onto_box(fit, np.concatenate([np.zeros(fit.nc), res.x[current_nc(res):]]), ctx.prior.tau)
    except CANDIDATE_FAILURES:
        return None
    out.structure = res.structure
    return out


def single_causes(ctx: Context, todo: Sequence[str], baseline: FitResult, progress: bool
                  ) -> tuple[dict[str, FitResult], list[dict[str, Any]], dict[str, list[Effect]]]:
    """Each cause of ``todo`` fitted alone with the baseline's values, in that order.

    Returns
    -------
    results : dict
        The fits that end below the baseline's objective, by cause.
    failed : list of dict
        The causes whose every fit ended at or above it (``cause``, ``cost``, ``reason``).
    variants : dict
        The forms of each continuous cause, by screened cost from the fitted baseline.
    """
    results: dict[str, FitResult] = {}
    failed: list[dict[str, Any]] = []
    variants_tried: dict[str, list[Effect]] = {}
    # with a design prior, a baseline whose values all stay within GROSS_DRIFT tolerances has absorbed nothing: the
    # design values add no start
    distorted = ctx.prior is None or ctx.distorted(baseline)
    for cause in todo:
        t = time.perf_counter()
        explained = any(ctx.explained(r) for r in results.values())
        if cause == "missing-section":
            res = fit_missing_section(ctx, baseline, [], must_beat=baseline.objective)
            # the structures also from the baseline's optimum nearest the given values (:func:`.baseline.fit_multistart`):
            # a split of a better-fitting but more distorted optimum can stop far above the split of the other
            # (not once another cause explains the data to the noise: the split then only has to be ranked)
            alt = getattr(baseline, "alternative", None)
            if alt is not None and not explained:
                other = fit_missing_section(ctx, alt, [], must_beat=baseline.objective)
                if other is not None and (res is None or other.objective < res.objective):
                    res = other
        else:
            # once a cause explains the data to the noise, the others are fitted from the fitted baseline only
            res, variants_tried[cause] = fit_cause(ctx, cause, baseline, must_beat=baseline.objective,
                                                   from_nominal=distorted and not explained)
        if res is None:
            continue
        if res.objective >= baseline.objective:
            failed.append({"cause": cause, "cost": res.cost, "reason": "every start ended at or above the baseline cost"})
            log(f"{cause}: failed (cost {res.cost:.4g} >= baseline {baseline.cost:.4g})", progress)
            continue
        results[cause] = res
        log(f"{cause}: {res.structure or res.effects[0].label}: cost {res.cost:.4g}, gain "
            f"{1 - res.cost / baseline.cost:.3f}, dBIC {baseline.cause_bic - res.cause_bic:.1f} "
            f"({time.perf_counter() - t:.1f} s)",
            progress)
    return results, failed, variants_tried
