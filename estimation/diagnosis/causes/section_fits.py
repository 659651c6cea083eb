"""Fits of a missing section: every split and end addition of the fitted model, and the splits of the design.

The candidates' first fits are independent and shared with the helper
process on another core (:mod:`.cores`).
"""

from __future__ import annotations

import time
from collections.abc import Container, Sequence
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit

from estimation.diagnosis.align import aligned_start
from estimation.diagnosis.causes.catalogue import Effect
from estimation.diagnosis.context import NOISE_MARGIN, STRUCTURAL, STRUCTURAL_FLOOR, WIDE_SEED_NFEV, Context, log
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.realign import realigned
from estimation.diagnosis.fit import (CANDIDATE_FAILURES, WIDE_CONTINUATION, WIDER_CONTINUATION, FitResult,
    FrequencyFit, configuration_ports, current_nc)
from estimation.diagnosis.causes.sections import find_chains, section_candidates
from estimation.diagnosis.causes.unmerge import Unmerged, missing_modes, search_unmerged


def fit_missing_section(ctx: Context, base: FitResult, effects: Sequence[Effect], must_beat: float,
                         top: int = 2) -> FitResult | None:
    """Every split and end addition: the new elements fitted alone first, the best ``top`` then in full.

    With ``effects`` (causes already named) their fitted parameters start
    every fit and stay free. When the measurement has a resonance the fitted
    model lacks, or the model stays far above the noise, the sections split
    from the nominal circuit (:func:`.unmerge.search_unmerged`) are tried too.
    """
    circuit = base.fitted_circuit()
    ports = configuration_ports(ctx.configs)
    tail = base.x[current_nc(base):] if effects else np.zeros(0)
    cands = section_candidates(circuit, ports)
    for cand in cands:  # one port, after a frequency-dependent cause: a section with free couplings would only
        if effects and ctx.one_port:  # take its rest
            cand.couplings = []
    # the new elements of every candidate fitted alone, shared with the helper process (:mod:`.cores`)
    staged = [(r.cost, cand, r) for cand, r in zip(cands, shared_map(_new_elements_fitted,
                                                                     [(ctx, cand, effects, tail) for cand in cands]))
              if r is not None]
    staged.sort(key=lambda t: t[0])
    best = None
    for i, (_, cand, first) in enumerate(staged):
        if i >= top and (best is not None and best.objective < must_beat or i >= top + 3):
            break
        try:
            fit = ctx.fit(cand.circuit.with_values(first.values), effects, couplings=cand.couplings)
            res = fit.fit(x0s=np.concatenate([np.zeros(fit.nc), first.x[current_nc(first):]])[None], grid=False,
                          max_nfev=60, tol=1e-6)
        except CANDIDATE_FAILURES:
            continue
        res.structure = cand.how
        if cand.split_of is not None:  # its halves merged back are held to the design's section (:meth:`.Context.drift`)
            try:
                res.unmerged = Unmerged(*cand.split_of)
            except CANDIDATE_FAILURES:
                pass
        _named(res, base)
        if best is None or ctx.penalised_bic(res) < ctx.penalised_bic(best):
            best = res
    # a missing section alone (no cause named yet): the design's sections split with their couplings free
    if not effects and ctx.nominal is not None and (ctx.unfit(base)
                                                    or ctx.distorted(base)):
        split = _split_nominal(ctx, effects, tail, ports)
        if split is not None:
            _named(split, base)
        if split is not None and (best is None or ctx.penalised_bic(split) < ctx.penalised_bic(best)):
            best = split
    if ctx.nominal is not None and (ctx.unfit(base) or ctx.distorted(base)
                                    or missing_modes(ctx.f, ctx.data, base.predicted, ctx.resolved) > 0):
        found = search_unmerged(lambda c, k: ctx.fit(c, effects, couplings=k), ctx.f, ctx.data, ctx.nominal, ports,
                                tail, free_couplings=not effects, resolved=ctx.resolved, all_seeds=False,
                                seed_nfev=WIDE_SEED_NFEV, schedules=(WIDE_CONTINUATION, WIDER_CONTINUATION),
                                good_enough=NOISE_MARGIN * STRUCTURAL_FLOOR * ctx.floor)
        if found is not None:
            found[0].unmerged = found[1]  # ranked with its halves merged back (:meth:`.Context.penalised`)
            _named(found[0], base)
        if found is not None and (best is None or ctx.penalised_bic(found[0]) < ctx.penalised_bic(best)):
            best, um, merged = found
            best.structure = um.candidate.how
            best.merged_back = {**merged.values, **um.merged_back(merged.fitted_circuit())}
    return best


def _named(res: FitResult, base: FitResult) -> None:
    """``res``, a fit of a missing section on ``base``, given its causes: ``base``'s and the missing section (its
    :attr:`.fit.FitResult.cause_bic` then counts the section's prior share, :attr:`.context.Context.cause_prior`)."""
    res.causes = [c for c in base.causes if c not in ("none", "missing-section")] + ["missing-section"]
    res.cause = "+".join(res.causes)


def structure_prior(circuit: Circuit, ports: Sequence[str]) -> float:
    """``2 ln M`` (BIC units) for the ``M`` places a section may be missing from ``circuit``: each section of
    each winding split, and each winding lengthened at either end.

    The search for a missing section weighs every place and keeps the best, so the
    cause's prior is shared among them: each place has ``1/M`` of it, and the best
    place's BIC plus ``2 ln M`` is that cause's (``-2 ln`` of its evidence when one
    place dominates, and a bound on it otherwise). Without the share the best of
    ``M`` places fitted to the noise alone gains the maximum of ``M`` draws, about
    ``2 ln M`` in BIC over one (twelve places on ten sections, 5.0).
    """
    places = sum(len(ch.sections) + 2 for ch in find_chains(circuit, ports))
    return 2.0 * float(np.log(max(places, 1)))


def _new_elements_fitted(args: tuple[Context, Any, Sequence[Effect], np.ndarray]) -> FitResult | None:
    """A candidate structure's new elements fitted alone, the others held (:func:`fit_missing_section`); None
    when the data drive it into a degenerate network."""
    ctx, cand, effects, tail = args
    try:
        whole = ctx.fit(cand.circuit, effects, couplings=cand.couplings)
        new = {n.lower() for n in list(cand.new_elements) + list(cand.couplings)}
        first = ctx.fit(cand.circuit, effects, fixed=[n for n in whole.free if n.lower() not in new],
                        couplings=cand.couplings)
        return first.fit(x0s=np.concatenate([np.zeros(first.nc), tail])[None], grid=False, max_nfev=15, tol=1e-5)
    except CANDIDATE_FAILURES:
        return None


def _split_screened(args: tuple[Context, Any, Sequence[Effect], np.ndarray]
                    ) -> tuple[FrequencyFit | None, FitResult | None]:
    """A split of the nominal circuit screened by a short fit of all its values (:func:`_split_nominal`)."""
    ctx, cand, effects, tail = args
    try:
        fit = ctx.fit(cand.circuit, effects, couplings=cand.couplings)
        return fit, fit.fit(x0s=np.concatenate([np.zeros(fit.nc), tail])[None], grid=False,
                            max_nfev=NOMINAL_SCREEN_NFEV, tol=1e-5)
    except CANDIDATE_FAILURES:
        return None, None


#: Splits of the nominal circuit (:func:`_split_nominal`): evaluations of each screening fit and of the final fit.
NOMINAL_SCREEN_NFEV = 15
NOMINAL_NFEV = 100


def _split_nominal(ctx: Context, effects: Sequence[Effect], tail: np.ndarray, ports: Sequence[str]
                   ) -> FitResult | None:
    """Every section of the nominal circuit split in two, every value and the touched (tight) couplings free.

    A fitted baseline far from the data has distorted values that a split
    started from it keeps; the design values are free of that. Each split is
    screened by a short fit of all its values, the best is fitted in full.
    """
    # loosely coupled sections: the splits of the nominal circuit are :mod:`.unmerge`'s
    cands = [c for c in section_candidates(ctx.nominal, ports, grid=()) if c.couplings]
    screened = [(r.objective, cand, fit, r) for cand, (fit, r) in zip(cands, shared_map(
        _split_screened, [(ctx, cand, effects, tail) for cand in cands])) if r is not None]
    if not screened:
        return None
    _, cand, fit, first = min(screened, key=lambda t: t[0])
    try:
        res = fit.fit(x0s=first.x[None], grid=False, max_nfev=NOMINAL_NFEV, tol=1e-7)
    except CANDIDATE_FAILURES:
        res = first
    res.structure = f"{cand.how} (from the design values)"
    res.from_design = True
    return res


def section_pairs(ctx: Context, results: dict[str, FitResult], baseline: FitResult,
                   have: Container[str] = ()) -> dict[str, FitResult]:
    """A missing section fitted together with each continuous effect's single fit, by the pair's cause name.

    Sought when no single cause is enough, and when a section alone, the
    best first cause, is refused by the held-out check: fitted alone, its
    values take a share of an effect that is there too and fail on the
    points left out (design missing section + skin effect 703: the split
    alone gained 0.54, held out -0.08; with the skin effect, 0.83). Pairs
    already in ``have`` are not fitted again.
    """
    pairs = {}
    for cause, single in results.items():
        if cause in STRUCTURAL or not single.effects or f"{cause}+missing-section" in have:
            continue
        t = time.perf_counter()
        try:
            pair = fit_missing_section(ctx, single, single.effects, must_beat=single.objective)
        except CANDIDATE_FAILURES:
            pair = None
        if pair is None or pair.objective >= single.objective:
            continue
        pairs[pair.cause] = pair
        log(f"pair {pair.cause}: cost {pair.cost:.4g}, gain {1 - pair.objective / baseline.objective:.3f}, "
             f"dBIC {baseline.bic - pair.bic:.1f} ({time.perf_counter() - t:.1f} s)", ctx.progress)
    return pairs


#: Random starts of each split's multistart fit (:func:`split_every_section`; the baseline's own fit uses
#: :data:`.baseline.BASELINE_STARTS`): half of them, as the split starts from a fitted model, not from the design.
SPLIT_STARTS = 8
#: Seeds of each split (:meth:`.unmerge.Unmerged.seeds`, ranked by their cost) fitted through smoothed errors.
SPLIT_SEEDS = 3
#: Splits refitted from random starts (:func:`split_every_section`): the best of the seeded fits, ranked by their
#: objective with the merged halves' penalty. The random starts move a seeded split by a share of its cost (the
#: equal-halves saddle); they do not turn a split that fits no better than the rest into the best one.
SPLIT_REFINED = 3


def _split_seeded(args: tuple[Context, Any, Any, int, bool, Sequence[Effect], np.ndarray]) -> tuple[Any, Any] | None:
    """Section ``j`` of chain ``ch`` made two (``respaced``: the winding one section longer) and fitted from its
    best seeds (:func:`split_every_section`): ``(Unmerged, FitResult)``, None when the split cannot be built or
    fitted."""
    ctx, circuit, ch, j, respaced, effects, tail = args
    try:
        um = Unmerged(circuit, ch, j, respaced)
        pair = {um.first["L"].lower(), um.second["L"].lower()}
        # respaced, the couplings are the winding's profile over the lengthened winding (no new parameters); else
        # the couplings of the two halves are free (how the section's coupling is shared is not known)
        ks = [] if respaced else [e.name for e in um.candidate.circuit.of_kind("K")
                                  if {n.lower() for n in e.nodes} & pair]
        fit = ctx.fit(um.candidate.circuit, effects, couplings=ks)
        rows = um.seeds(fit.free, tail)
        r = fit.residuals_batch(rows)
        order = np.argsort(np.sum(r * r, axis=1))[:SPLIT_SEEDS]
        # each seed's resonances moved onto the measured ones, the two sections' own values free of the pull (how
        # the section is shared is what the seeds guess); a local fit from there, else through smoothed errors
        own_names = set(um.own_elements())
        own = [i for i, n in enumerate(fit.free) if n in own_names]
        fits = []
        for i in order:
            aligned = aligned_start(fit, rows[i], free=own)
            fits.append(fit.fit(x0s=aligned[None], grid=False, max_nfev=100, tol=1e-7) if aligned is not None
                        else fit.fit_continued(rows[i], max_nfev=100))
        seeded = min(fits, key=lambda x: x.objective)
    except CANDIDATE_FAILURES:
        return None
    seeded.unmerged = um
    seeded.couplings_freed = ks
    return um, seeded


def split_every_section(ctx: Context, base: FitResult, ports: Sequence[str], from_design: bool = False
                        ) -> FitResult | None:
    """Every section of the fitted model made two whole sections, each fitted from its seeds; the best from
    several starts.

    With effects in ``base`` (a cause named or fitted alone) they stay in every fit, their parameters free. With
    ``from_design`` the sections of the design (the nominal circuit) are split instead of the fitted model's: a
    baseline that reached the data only with values far off the design has absorbed the missing section in them.

    For each section ``j`` of each winding the split of :class:`.unmerge.Unmerged` (two sections in series, the
    inductance and the series capacitance shared between them, the new node with its own capacitance to ground)
    is built from the *fitted* model's values, with the couplings of the two new inductors free (the coupling
    partition of the split), and again respaced (every distance counted along the winding made one section longer,
    :class:`.unmerge.Unmerged`), its couplings then held at the winding's profile. Its ``SPLIT_SEEDS`` best seeds
    (by cost) are fitted through smoothed errors (every section's, shared with the helper process). The
    ``SPLIT_REFINED`` best splits, ranked by BIC with their halves merged back under the prior
    (:meth:`.context.Context.penalised_bic`: a split with its couplings free has more parameters than one respaced,
    and only a lower cost worth them ranks it first), are fitted again from
    ``SPLIT_STARTS`` random starts around them, as the baseline is (:func:`.baseline.fit_multistart`): the equal
    halves of a split are a saddle of the split model, and the seeds' partitions are a few points of a space the
    random starts sample more widely. Every section of every winding is tried, so the search does not depend on
    where the misfit seemed to sit.
    """
    from estimation.diagnosis.baseline import fit_multistart

    circuit = ctx.nominal if from_design and ctx.nominal is not None else base.fitted_circuit()
    effects = list(base.effects)
    tail = base.x[current_nc(base):]
    t = time.perf_counter()
    items = [(ctx, circuit, ch, j, respaced, effects, tail) for ch in find_chains(circuit, ports)
             for j in range(len(ch.sections)) for respaced in (False, True)]
    seeded = [s for s in shared_map(_split_seeded, items) if s is not None]
    seeded.sort(key=lambda s: ctx.penalised_bic(s[1]))
    log(f"  {len(seeded)} splits fitted from their seeds ({time.perf_counter() - t:.1f} s)"
        + (f"; best {seeded[0][0].candidate.how}: cost {seeded[0][1].cost:.4g}" if seeded else ""), ctx.progress)
    best = None
    for um, first in seeded[:SPLIT_REFINED]:
        t = time.perf_counter()
        try:
            again = ctx.fit(first.fitted_circuit(), effects, couplings=first.couplings_freed)
            res = fit_multistart(again, starts=SPLIT_STARTS, good_enough=NOISE_MARGIN * ctx.floor, floor=ctx.floor,
                                 x0=np.concatenate([np.zeros(again.nc), first.x[again.nc:]]))
            # splits of one winding fit within a few tens of per cent of the floor alike, and what tells them apart
            # is the last of their misfit: the modes moved onto every misfit the noise does not account for
            # (:func:`.realign.misfits`), not only until the objective is within NOISE_MARGIN of the floor
            res = realigned(again, res, ctx.floor, 0.0)
        except CANDIDATE_FAILURES:
            continue
        res.structure = um.candidate.how + (" (from the design values)" if from_design else "")
        res.unmerged = um
        _named(res, base)
        log(f"  {um.candidate.how}: cost {res.cost:.4g} ({time.perf_counter() - t:.1f} s)", ctx.progress)
        if best is None or ctx.penalised_bic(res) < ctx.penalised_bic(best):
            best = res
    return best


def every_section_split(ctx: Context, base: FitResult, ports: Sequence[str]) -> FitResult | None:
    """Every section of the fitted model split (:func:`split_every_section`) and every section of the design: the
    better by BIC with the merged halves' penalty (:meth:`.context.Context.penalised_bic`), or None.

    Both starts are always fitted: a split from the fitted values can reach the noise floor in the basin the
    baseline's values fell into (moved to make up for the missing node), while the split from the design values
    finds the section at a cost lower by the tens of BIC that tell it from a drift; a fit at the floor does not
    show that no other fit is lower."""
    log("missing-section: every section of the fitted model made two", ctx.progress)
    wide = split_every_section(ctx, base, ports)
    log("missing-section: every section of the design made two", ctx.progress)
    other = split_every_section(ctx, base, ports, from_design=True)
    if other is not None and (wide is None or ctx.penalised_bic(other) < ctx.penalised_bic(wide)):
        wide = other
    return wide
