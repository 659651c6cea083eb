"""Drift: the values of a fitted model off the design, and which of them the data need.

A fit against a design (:mod:`.prior`) may end with values beyond the
tolerance. The prior pulls a value that is really off back towards the
design, and the others move to make up for it; this module frees the
furthest off in turn, then reports only the values that the data need beyond
the tolerance.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit, node_name

from estimation.diagnosis.align import aligned_start, resonance_mismatch
from estimation.diagnosis.baseline import fit_multistart
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import CANDIDATE_FAILURES, FitResult, FrequencyFit, current_nc
from estimation.diagnosis.onto_box import onto_box, within_box
from estimation.diagnosis.realign import realigned

#: A fit that reaches the noise floor but moves a value more than this many tolerances from the design
#: (``|ln(v/d)| > GROSS_DRIFT ln(1 + tolerance)``) is not an explanation: causes are sought from the design values.
GROSS_DRIFT = 2.0


#: Most values freed from the prior when the drift is relaxed (:func:`relaxed_drift`).
MAX_FREED = 4
#: Most drifted values (the furthest off) checked against their design values; the others are not reported.
MAX_HELD = 6
#: A drifted value is reported only if holding it at the edge of the tolerance worsens the BIC by this much ("very
#: strong").
DRIFT_MIN_DBIC = 10.0


def relaxed_drift(ctx: Any, final: FitResult, log: Callable[[str], None]
                  ) -> tuple[list[dict[str, Any]], FitResult]:
    """The values off the design in the final model, each freed from the prior in turn, and the model they are
    reported from (``final`` when none is).

    The prior pulls a value that is really off the design back towards it,
    and the others then move to make up for it. The value furthest beyond the
    tolerance is freed (its prior removed) and the model refitted; then the
    next, while any is left more than ``GROSS_DRIFT`` tolerances off (at most
    ``MAX_FREED``).
    What stays beyond it after that is the drift reported, with the refitted
    values, and of those only the values the data need beyond the tolerance:
    each freed from the prior (if not freed already) and then held at the
    tolerance's edge on its side (the others refitted, its own prior left
    out of both), the fit must lose ``DRIFT_MIN_DBIC`` (the ``MAX_HELD``
    furthest off are checked). When two or more values pass, one value off
    with every other followed back onto the tolerance may explain the data
    better (:func:`_one_for_many`); it then stands for them, with the
    others that explain the data as well as ``alternatives``. The named
    causes and the gain are not changed by this. Nothing is reported when
    a fit with every value within the tolerance box has a BIC no higher
    than ``final``'s own (:meth:`.context.Context.within_design` keeps it as
    ``boxed``): ``final`` then sits in a poorer basin than the box's best,
    and the tests of its values at their edges, started from it, would
    weigh that basin rather than the data.
    """
    if ctx.prior is None:
        return [], final
    drift = ctx.drift(final)
    if drift and ctx.within_design(final) and final.boxed is not None and final.boxed.bic <= final.bic:
        # a fit with every value within the tolerance (from the model, or from the design values realigned) has a
        # BIC no higher than the model's own: the model sits in a poorer basin, and the data need none of its values
        # beyond the tolerance
        log(f"beyond the tolerance, but a fit within it is {final.bic - final.boxed.bic:.1f} lower in BIC: "
            + ", ".join(f"{d['name']} x{d['ratio']:.3g}" for d in drift) + " not reported")
        return [], final
    if drift:
        log("beyond the tolerance before relaxing: " + ", ".join(f"{d['name']} x{d['ratio']:.3g}" for d in drift))
    current, freed = final, []
    while len(freed) < MAX_FREED:
        # a value just beyond the tolerance is within the prior's reach: freeing it only lets it wander
        todo = [d for d in drift if d["name"].lower() not in freed and d["sigmas"] > GROSS_DRIFT]
        if not todo:
            break
        freed.append(todo[0]["name"].lower())
        loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k not in freed})
        try:
            fit = ctx.fit(current.fitted_circuit(), current.effects, prior=loose, couplings=current.couplings)
            tail = current.x[current_nc(current):]
            trial = fit.fit(x0s=np.concatenate([np.zeros(fit.nc), tail])[None], grid=False, max_nfev=60, tol=1e-7)
        except CANDIDATE_FAILURES:
            break
        current = trial
        drift = ctx.drift(current)
    if freed:
        log(f"drift relaxed: {', '.join(freed)} freed from the prior; cost {final.cost:.4g} -> {current.cost:.4g}")
    # a value the data do not need beyond the tolerance is not reported: freed from the prior, and held at the edge
    # of the tolerance on its side (design x (1 + tolerance) or / (1 + tolerance); the others refitted, its own
    # prior left out of both), the fit must lose DRIFT_MIN_DBIC. A value not freed above is freed for this check
    # (the prior held it near the tolerance while the others made up for it), and reported with its freed value.
    within = getattr(final, "boxed", None)  # the box's best fit (:meth:`.context.Context.within_design`), if sought
    kept, current = _needed(ctx, current, freed, drift, log, within)
    kept = _with_swaps(kept, _located_swaps(ctx, current, kept), log)
    if len(kept) >= 2:
        one = _one_for_many(ctx, current, freed, kept, log)
        if one is not None:
            kept, current = _needed(ctx, one, [one.freed.lower()], ctx.drift(one), log, within)
            for d in kept:  # the values that explain the data as well, with the one they stand beside
                if d["name"] == one.freed:
                    seen = {a["name"] for a in d.get("alternatives", [])}
                    d["alternatives"] = d.get("alternatives", []) + [a for a in one.drift_alternatives
                                                                     if a["name"] not in seen]
    return with_parallel(current.circuit, current.values, ctx.prior.design, kept), current


def _needed(ctx: Any, current: FitResult, freed: list[str], drift: list[dict[str, Any]],
            log: Callable[[str], None], within: FitResult | None = None) -> tuple[list[dict[str, Any]], FitResult]:
    """Of the values ``drift`` of ``current`` (``freed`` from the prior), those the data need beyond the tolerance:
    each held at its edge (:func:`_held_check`, the ``MAX_HELD`` furthest off), then the fewest together
    (:func:`_fewest_needed`), then with every other value within its box (:func:`_box_needed`). ``within``, the
    box's best fit of the same structure, is one more start of each hold. Returns them and the model they are
    reported from."""
    kept = []
    for d, message in shared_map(_held_check, [(ctx, current, freed, d, within) for d in drift[:MAX_HELD]]):
        if message:
            log(message)
        if d is not None:
            kept.append(d)
    kept = _fewest_needed(ctx, current, freed, kept, log)
    out, box = _box_needed(ctx, current, drift, kept, log, within)
    return out, box or current


def _units(ctx: Any, current: FitResult, entries: Sequence[dict[str, Any]]) -> list[list[str]]:
    """The values of ``entries`` in ``current``, each with the others of its kind in parallel with it
    (:func:`parallel_partners`): one unit to the data."""
    units: list[list[str]] = []
    for d in entries:
        name = d["name"]
        if name not in current.values or any(name in u for u in units):
            continue
        units.append([name] + [p for p in parallel_partners(current.circuit, name)
                               if p.lower() in ctx.prior.design and p in current.values])
    return units


def _boxed(args: tuple[Any, FitResult, Sequence[str]]) -> FitResult | None:
    """``(ctx, model, free)`` to the model with the values ``free`` freed from the prior and every other value the
    prior holds followed onto its tolerance box (:func:`.onto_box.onto_box`, not released); None if it fails."""
    ctx, current, free = args
    keys = {n.lower() for n in free}
    loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k not in keys})
    try:
        fit = ctx.fit(current.fitted_circuit(), current.effects, prior=loose, couplings=current.couplings)
        return onto_box(fit, np.concatenate([np.zeros(fit.nc), current.x[current_nc(current):]]), ctx.prior.tau,
                        release_nfev=None)
    except CANDIDATE_FAILURES:
        return None


def design_rejected(ctx: Any, model: FitResult) -> tuple[float, FitResult | None]:
    """By how much (BIC) the data reject ``model`` with every value within the design's tolerance box, and that
    model.

    ``model`` followed onto the box (:func:`_boxed`) is weighed against it
    followed onto the box with the values it has beyond the tolerance freed
    from the prior, each freed value (or values in parallel) counted as one
    parameter. Zero (and ``None``) when no value is beyond the tolerance or
    a fit fails: a model at the noise floor whose values the box holds needs
    no cause.
    """
    drift = ctx.drift(model) if ctx.prior is not None else []
    if not drift:
        return 0.0, None
    units = _units(ctx, model, drift)
    inside, free = shared_map(_boxed, [(ctx, model, []), (ctx, model, [n for u in units for n in u])])
    if inside is None or free is None:
        return 0.0, None
    from_design = _design_boxed(ctx, model)
    if from_design is not None and from_design.bic < inside.bic:
        inside = from_design
    return float(inside.bic - (free.bic + len(units) * np.log(free.n_residuals))), inside


def _design_boxed(ctx: Any, model: FitResult) -> FitResult | None:
    """The best fit within the box reached from the design values rather than from ``model`` (:func:`design_rejected`).

    Followed onto the box, a model can stop in another basin than the box's best: its values return while a
    weak mode stays where they put it. From the design values, with the resonances aligned
    (:func:`.align.aligned_start`), the fit within the box is realigned onto its misfits
    (:func:`.realign.realigned`) as the baseline is; the realigned fit counts when every value stays within the
    tolerance, else the fit within the box. None when a fit fails.
    """
    try:
        fit = ctx.fit(model.fitted_circuit(), model.effects, couplings=model.couplings)
        boxed, moved = _aligned_boxed(ctx, fit, fit.design_vector(
            np.concatenate([np.zeros(fit.nc), model.x[current_nc(model):]])))
    except CANDIDATE_FAILURES:
        return None
    return moved if moved is not boxed and not ctx.drift(moved) else boxed


#: Evaluations of the alignment within the box (:func:`_aligned_boxed`): it aligns the modes to a fraction of their
#: width, and each evaluation is one eigen-decomposition per configuration.
BOXED_ALIGN_NFEV = 200


def _aligned_boxed(ctx: Any, fit: FrequencyFit, x: np.ndarray, free: Sequence[int] = (), good_enough: float = 0.0
                   ) -> tuple[FitResult, FitResult]:
    """``fit`` within the tolerance box from ``x`` with the resonances aligned (:func:`.align.aligned_start`; the
    columns ``free`` not pulled back), and that fit realigned onto its misfits (:func:`.realign.realigned`, which
    stops at the objective ``good_enough``; the fit itself when no move lowers it). A failed solve raises."""
    boxed = _boxed_aligned(ctx, fit, x, free)
    return boxed, realigned(fit, boxed, ctx.floor, good_enough)


def _boxed_aligned(ctx: Any, fit: FrequencyFit, x: np.ndarray, free: Sequence[int] = ()) -> FitResult:
    """``fit`` within the tolerance box from ``x`` with the resonances aligned within it (:func:`.align.aligned_start`,
    the columns ``free`` not pulled back nor bounded by the box). A failed solve raises."""
    aligned = aligned_start(fit, x, free=free, box=ctx.prior.tau, max_nfev=BOXED_ALIGN_NFEV)
    return within_box(fit, x if aligned is None else aligned, ctx.prior.tau, max_nfev=200)


def _same_structure(a: FitResult | None, b: FitResult) -> bool:
    """``a`` is a fit of ``b``'s values, effects and couplings (a start, or a stand-in, for ``b``'s fits)."""
    return a is not None and set(a.values) == set(b.values) and tuple(a.couplings) == tuple(b.couplings) \
        and [e.label for e in a.effects] == [e.label for e in b.effects]


def _box_needed(ctx: Any, current: FitResult, drift: list[dict[str, Any]], kept: list[dict[str, Any]],
                log: Callable[[str], None], within: FitResult | None = None
                ) -> tuple[list[dict[str, Any]], FitResult | None]:
    """The values of ``drift`` the data need beyond the tolerance when every other returns into its box.

    The checks before (each value held at its edge, then the fewest of
    those together) leave the other values under the prior, free to move
    beyond the tolerance to make up for the one held: two values off may
    each pass for the other, and none is reported while the model has both
    beyond. Here ``current`` with only ``kept`` freed, every other value
    followed onto its box (:func:`_boxed`), is weighed against it with every
    value of ``drift`` freed (each freed value, or values in parallel,
    counted as one parameter). While the data reject it by
    ``DRIFT_MIN_DBIC``, or the value whose freeing fits best lowers the BIC
    by as much, that value is added (forward selection); then, from the
    model with them all, the value whose return into its box costs least is
    dropped while the data accept the box without it, against every value
    freed and against the values kept (backward). With nothing freed,
    ``within`` (the box's best fit of the same structure,
    :meth:`.context.Context.within_design`) stands for the box when it fits
    better than ``current`` followed onto it. Returns the entries to report
    and the boxed model they come from (``None`` when ``kept`` stands).
    """
    units = _units(ctx, current, drift[:MAX_HELD])
    names = {d["name"] for d in kept}
    chosen = [i for i, u in enumerate(units) if u[0] in names]
    if len(chosen) == len(units):
        return kept, None
    n_log = np.log(current.n_residuals)
    scores: dict[tuple[int, ...], tuple[FitResult | None, float]] = {}

    def score(sets: list[list[int]]) -> None:  # the boxed fits of the sets not scored yet
        todo = [tuple(sorted(s)) for s in sets if tuple(sorted(s)) not in scores]
        fits = shared_map(_boxed, [(ctx, current, [n for i in key for n in units[i]]) for key in todo])
        for key, fit in zip(todo, fits):
            scores[key] = (fit, np.inf if fit is None else fit.bic + len(key) * n_log)

    every = list(range(len(units)))
    score([chosen, every])
    if _same_structure(within, current) and within.bic < scores.get((), (None, np.inf))[1]:
        scores[()] = (within, within.bic)
    ref = scores[tuple(every)][1]
    start_set = sorted(chosen)
    while np.isfinite(ref) and len(chosen) < len(units):  # forward
        here = scores[tuple(sorted(chosen))][1]
        rest = [i for i in every if i not in chosen]
        score([chosen + [i] for i in rest])
        add = min(rest, key=lambda i: scores[tuple(sorted(chosen + [i]))][1])
        if here - ref < DRIFT_MIN_DBIC and here - scores[tuple(sorted(chosen + [add]))][1] < DRIFT_MIN_DBIC:
            break
        chosen.append(add)
    if sorted(chosen) == start_set:
        return _with_swaps(kept, _swaps(ctx, units, chosen, scores, score), log), None
    # backward: a value needed before another was freed may not be needed beside it (each dropped in turn, from the
    # model with them all; the one whose drop costs least goes while the data accept the box without it, against
    # every value freed and against the values kept)
    while len(chosen) > 1 and scores[tuple(sorted(chosen))][0] is not None:
        here = scores[tuple(sorted(chosen))][1]
        start = scores[tuple(sorted(chosen))][0]
        fits = shared_map(_boxed, [(ctx, start, [n for j in chosen if j != i for n in units[j]]) for i in chosen])
        trials = [(f.bic + (len(chosen) - 1) * n_log, i, f) for i, f in zip(chosen, fits) if f is not None]
        if not trials:
            break
        value, drop, fit = min(trials, key=lambda t: t[0])
        if value - ref >= DRIFT_MIN_DBIC or value - here >= DRIFT_MIN_DBIC:
            break
        chosen.remove(drop)
        if value < scores.get(tuple(sorted(chosen)), (None, np.inf))[1]:
            scores[tuple(sorted(chosen))] = (fit, value)
    box = scores[tuple(sorted(chosen))][0]
    if box is None:
        return kept, None
    out = ctx.prior.drift({units[i][0]: box.values[units[i][0]] for i in chosen})
    log(f"within the tolerance together, the others beyond it freed: dBIC "
        f"{scores[tuple(sorted(i for i in every if units[i][0] in names))][1] - ref:.1f}; the data need "
        + ", ".join(f"{d['name']} x{d['ratio']:.3g}" for d in out) + " beyond it")
    return _with_swaps(out, _swaps(ctx, units, chosen, scores, score), log), box


def _swaps(ctx: Any, units: list[list[str]], chosen: list[int],
           scores: dict[tuple[int, ...], tuple[FitResult | None, float]],
           score: Callable[[list[list[int]]], None]) -> dict[str, list[dict[str, Any]]]:
    """For each unit of ``chosen`` (indices into ``units``), the other units that, freed in its place with every
    other value in its box, fit the data as well (:func:`_box_needed`'s scores: BIC within ``DRIFT_MIN_DBIC``, the
    criterion by which a value is needed at all) and end beyond the tolerance: name, design, fitted, ratio,
    delta_bic (against ``chosen``'s own), keyed by the chosen unit's first name.

    Two capacitances to ground at neighbouring nodes of a long winding move the same modes nearly alike; the
    driving-point impedance at a percent of noise may not tell which of them is off, and the one reported is then
    as likely the other: the report names both.
    """
    base = scores.get(tuple(sorted(chosen)), (None, np.inf))[1]
    rest = [i for i in range(len(units)) if i not in chosen]
    if not np.isfinite(base) or not rest:
        return {}
    pairs = [(c, o, sorted([j for j in chosen if j != c] + [o])) for c in chosen for o in rest]
    score([s for _, _, s in pairs])
    out: dict[str, list[dict[str, Any]]] = {}
    for c, o, s in pairs:
        fit, value = scores[tuple(s)]
        if fit is None or value - base >= DRIFT_MIN_DBIC:
            continue
        moved = ctx.prior.drift({units[o][0]: fit.values[units[o][0]]})
        if moved:
            out.setdefault(units[c][0], []).append(_alternative(moved[0], value - base))
    return out


def _located_swaps(ctx: Any, current: FitResult, entries: list[dict[str, Any]]) -> dict[str, list[dict[str, Any]]]:
    """For each value of ``entries`` that the one-value search fitted (:func:`located_drift`, ``ctx.located``, on
    ``current``'s structure, effects and couplings), the other values it fitted that alone explain the data as well:
    the BIC within ``DRIFT_MIN_DBIC`` of that value's own fit, the value beyond the tolerance and no other more than
    ``GROSS_DRIFT`` tolerances off. Entries as :func:`_swaps`'.

    The search fits every value alike, each freed from the prior in turn; two values whose fits it cannot tell
    apart by the criterion a value is needed by are equally the answer, whichever the model settled on.
    """
    if ctx.prior is None:
        return {}
    labels, couplings, names = [e.label for e in current.effects], tuple(current.couplings), set(current.values)
    same = {v: o for v, o in ctx.located.items()
            if len(o) > 5 and o[1] == labels and o[2] == couplings and set(o[3]) == names}
    out: dict[str, list[dict[str, Any]]] = {}
    for d in entries:
        own = same.get(d["name"])
        if own is None:
            continue
        for v, o in sorted(same.items(), key=lambda t: t[1][5]):
            moved = {e["name"]: e for e in ctx.prior.drift(o[3])}
            if (v == d["name"] or v not in moved or o[5] - own[5] >= DRIFT_MIN_DBIC
                    or any(e["sigmas"] > GROSS_DRIFT for n, e in moved.items() if n != v)):
                continue
            out.setdefault(d["name"], []).append(_alternative(moved[v], o[5] - own[5]))
    return out


def _alternative(entry: Mapping[str, Any], delta_bic: float) -> dict[str, Any]:
    """A drift entry (:meth:`.prior.DesignPrior.drift`) as an alternative: name, design, fitted, ratio, delta_bic."""
    return {k: entry[k] for k in ("name", "design", "fitted", "ratio")} | {"delta_bic": float(delta_bic)}


def _with_swaps(entries: list[dict[str, Any]], swaps: dict[str, list[dict[str, Any]]],
                log: Callable[[str], None]) -> list[dict[str, Any]]:
    """``entries`` with each one's swaps (:func:`_swaps`, :func:`_located_swaps`) added to its ``alternatives`` (once
    each), logged."""
    for d in entries:
        for a in swaps.get(d["name"], []):
            if a["name"] in {b["name"] for b in d.get("alternatives", [])}:
                continue
            d.setdefault("alternatives", []).append(a)
            log(f"  {d['name']} or {a['name']} x{a['ratio']:.3g} in its place, fitted as well (dBIC "
                f"{a['delta_bic']:+.1f}): the data do not tell which")
    return entries


def one_at_a_time(origin: np.ndarray, cols: np.ndarray, design: np.ndarray, log_ratios: np.ndarray) -> np.ndarray:
    """Start vectors with one value of ``cols`` at a time set to ``log_ratios`` times its design value, the others as
    in ``origin``: shape ``(cols.size * log_ratios.size, origin.size)``, value by value."""
    X = np.repeat(origin[None], cols.size * log_ratios.size, axis=0)
    X[np.arange(X.shape[0]), np.repeat(cols, log_ratios.size)] = np.tile(log_ratios, cols.size) + np.repeat(
        design[cols], log_ratios.size)
    return X


def _alternatives(ctx: Any, best: FitResult, trials: Sequence[FitResult], keep: Callable[[FitResult], bool],
                  log: Callable[[str], None]) -> list[dict[str, Any]]:
    """The other values freed in ``trials`` that explain the data as well as ``best`` (BIC within
    ``DRIFT_MIN_DBIC``, and ``keep``), each once at its best fit: name, design, fitted, ratio, delta_bic."""
    out, named = [], {best.freed}
    for t in sorted(trials, key=lambda t: t.bic):
        if t.freed in named or t.bic - best.bic >= DRIFT_MIN_DBIC or not keep(t):
            continue
        named.add(t.freed)
        d = ctx.prior.design[t.freed.lower()]
        out.append({"name": t.freed, "design": float(d), "fitted": float(t.values[t.freed]),
                    "ratio": float(t.values[t.freed] / d), "delta_bic": float(t.bic - best.bic)})
        log(f"  as well explained by {t.freed} x{t.values[t.freed] / d:.3g} (dBIC {t.bic - best.bic:.1f})")
    return out


#: Values ranked by a scan (besides the values reported) tried as the one value off (:func:`_one_for_many`).
ONE_FOR_MANY_FITS = 4


def _one_for_many(ctx: Any, current: FitResult, freed: list[str], kept: list[dict[str, Any]],
                  log: Callable[[str], None]) -> FitResult | None:
    """One value off the design that explains what the several values ``kept`` explain together, if any.

    A value that is really off (a capacitance to ground doubled) is pulled
    back by the prior while its neighbours move beyond the tolerance to make
    up for it, and the fit settles in their basin: each of them, held at its
    edge from there, loses (the local refit does not find the other basin),
    and two or three values are reported for one. Here each value ``v`` of
    ``kept``, and the ``ONE_FOR_MANY_FITS`` values that alone best fit the
    data with every other value clipped into its tolerance box (a scan over
    ``LOCATE_RANGE``), is freed from the prior while every other value
    returns onto the box (:func:`.onto_box.onto_box`: the bounds close from
    where the values are, the data keeping the resonances aligned, ``v``
    taking what they no longer hold). The best such model replaces the
    several when its BIC, one freed value counted as one parameter, is lower
    than theirs with ``kept`` freed (each counted). Returns it (``freed`` set
    to ``v``) or ``None``.
    """
    names = [d["name"] for d in kept]
    keys = {n.lower() for n in names} | set(freed)
    tail = current.x[current_nc(current):]
    try:
        loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k not in keys})
        several = ctx.fit(current.fitted_circuit(), current.effects, prior=loose, couplings=current.couplings)
        x_cur = np.concatenate([np.zeros(several.nc), tail])
        ref = several.fit(x0s=x_cur[None], grid=False, max_nfev=60, tol=1e-7)
        whole = ctx.fit(current.fitted_circuit(), current.effects, couplings=current.couplings)
    except CANDIDATE_FAILURES:
        return None
    n_log = np.log(ref.n_residuals)
    ref_bic = ref.bic + len(keys) * n_log
    cols = whole.anchored_columns
    design = whole.design_vector(x_cur)
    boxed = x_cur.copy()
    boxed[cols] = np.clip(x_cur[cols], design[cols] - ctx.prior.tau, design[cols] + ctx.prior.tau)
    # each value scanned alone, the others clipped into their box, and again at their design values (the model's
    # values may hold the others in another basin)
    ratios = np.linspace(np.log(LOCATE_RANGE[0]), np.log(LOCATE_RANGE[1]), LOCATE_SCAN)
    scans, points = [], []
    for origin in (boxed, design):
        X = one_at_a_time(origin, cols, design, ratios)
        r = whole.residuals_batch(X)[:, : whole.n_residuals - cols.size]
        scan = np.sum(r ** 2, axis=1).reshape(cols.size, ratios.size)
        scans.append(scan.min(axis=1))
        points.append(X.reshape(cols.size, ratios.size, -1)[np.arange(cols.size), np.argmin(scan, axis=1)])
    ranked = [whole.free[cols[p]] for p in np.argsort(np.minimum(*scans))]
    candidates = list(dict.fromkeys(names + [n for n in ranked if n not in names][:ONE_FOR_MANY_FITS]))
    jobs = []
    for v in candidates:
        p = next(k for k, c in enumerate(cols) if whole.free[c] == v)
        # and the one-value search's fit of that value (:func:`located_drift`), on any model: it may hold the others
        # in the basin where that value alone explains the data
        found = _start_from(whole, current, ctx.located[v]) if v in ctx.located else None
        jobs.append((ctx, current, v, [pts[p] for pts in points] + ([found] if found is not None else [])))
    trials = [t for t in shared_map(_freed_onto_box, jobs) if t is not None]
    if not trials:
        return None
    best = min(trials, key=lambda t: t.bic)
    # the best value's model once more, realigned onto its misfits (:func:`_aligned_in_box`)
    again = _realigned_in_box(ctx, current, best.freed)
    if again is not None and again.bic < best.bic:
        trials.append(again)
        best = again
    gain = ref_bic - (best.bic + n_log)
    d = ctx.prior.design[best.freed.lower()]
    log(f"{best.freed} x{best.values[best.freed] / d:.3g} alone, the others onto the tolerance: cost "
        f"{best.cost:.4g}, dBIC {gain:.1f} against {', '.join(names)} together"
        + (": the one value off" if gain > 0 else ": not kept"))
    if gain <= 0:
        return None
    # another value that, alone, explains the data as well (the BIC within DRIFT_MIN_DBIC): the data do not tell which
    best.drift_alternatives = _alternatives(ctx, best, trials, lambda t: True, log)
    return best


def _start_from(fit: FrequencyFit, current: FitResult, other: tuple) -> np.ndarray | None:
    """A fit kept by :func:`located_drift` (``ctx.located``: objective, effect labels, couplings, values, effect
    parameters, BIC) as a parameter vector of ``fit`` (built on ``current``'s fitted circuit, its values the origin), or
    None when the two models differ in structure, effects or couplings."""
    labels, couplings, values, tail = other[1:5]
    if labels != [e.label for e in current.effects] or couplings != tuple(current.couplings):
        return None
    x = np.zeros(fit.nc + len(fit.extra))
    for i, n in enumerate(fit.free):
        if fit.is_k[i]:
            continue
        a, b = values.get(n), current.values.get(n)
        if a is None or b is None or not (a > 0 and b > 0):
            return None
        x[i] = np.log(a / b)
    x[fit.nc:] = tail
    return x


def _freed_onto_box(args: tuple[Any, FitResult, str, list[np.ndarray]]) -> FitResult | None:
    """``(ctx, model, name, scanned)`` to the model with ``name`` freed from the prior and every other value within
    its tolerance box, ``freed`` set; None when every fit fails.

    The starts: the model's values followed onto the box (:func:`.onto_box.onto_box`), and each point of
    ``scanned`` (``name`` at its best ratio of a scan, the others in their box) fitted within it
    (:func:`.onto_box.within_box`), and the design's values aligned within the box (:func:`_aligned_in_box`). The
    best is kept.
    """
    ctx, current, name, scanned = args
    loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k != name.lower()})
    outs = []
    try:
        fit = ctx.fit(current.fitted_circuit(), current.effects, prior=loose, couplings=current.couplings)
    except CANDIDATE_FAILURES:
        return None
    origin = np.concatenate([np.zeros(fit.nc), current.x[current_nc(current):]])
    for run in (lambda: onto_box(fit, origin, ctx.prior.tau, release_nfev=None),
                *(lambda x=x: within_box(fit, x, ctx.prior.tau) for x in scanned),
                lambda: _aligned_in_box(ctx, fit, current, name, realign=False)):
        try:
            outs.append(run())
        except CANDIDATE_FAILURES:
            pass
    if not outs:
        return None
    out = min(outs, key=lambda t: t.bic)
    out.freed = name
    return out


def _realigned_in_box(ctx: Any, current: FitResult, name: str) -> FitResult | None:
    """:func:`_aligned_in_box` realigned, on its own fit (``name`` freed from the prior), ``freed`` set; None when a
    fit fails."""
    loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k != name.lower()})
    try:
        out = _aligned_in_box(ctx, ctx.fit(current.fitted_circuit(), current.effects, prior=loose,
                                           couplings=current.couplings), current, name)
    except CANDIDATE_FAILURES:
        return None
    out.freed = name
    return out


def _aligned_in_box(ctx: Any, fit: FrequencyFit, current: FitResult, name: str, realign: bool = True) -> FitResult:
    """``fit`` (``current``'s, ``name`` freed from the prior) within the tolerance box, fitted from the design's
    values with ``name`` at ``current``'s: the resonances aligned first within the box (:func:`.align.aligned_start`,
    the freed value not pulled back) and, with ``realign``, the fit within the box realigned onto its misfits
    (:func:`.realign.realigned`, as the box's own fit is, :func:`_design_boxed`) and, realigned, fitted within the box
    again; the better of the two fits within the box. A failed solve raises.

    The starts of :func:`_freed_onto_box` leave the other values where the model or the design put them, and the
    design's values, each within the tolerance of the truth, shift the resonances by a few per cent: a local fit
    from them stops in another basin (broad draw 1190, Cg3 at 2.2x: 1.0845e-5 from those starts; 1.0607e-5 aligned
    and realigned, the level of the fit started from the truth's values). With nine sections the basin of the
    truth's values is narrower still (draw 1151, Cg4 at 2.28x: 2.6e-2 aligned onto the sampled peaks, 1.7e-6, the
    noise, aligned within the box onto the refined resonances).
    """
    origin = np.concatenate([np.zeros(fit.nc), current.x[current_nc(current):]])
    column = fit.free.index(name)
    x = fit.design_vector(origin)
    x[column] = origin[column]
    if not realign:
        return _boxed_aligned(ctx, fit, x, [column])
    out, moved = _aligned_boxed(ctx, fit, x, free=[column], good_enough=ctx.floor)
    if moved is not out:
        # the realignment's fits are not bounded: back within the box
        moved = within_box(fit, moved.x, ctx.prior.tau, max_nfev=200)
        out = moved if moved.objective < out.objective else out
    return out


def _fewest_needed(ctx: Any, current: FitResult, freed: list[str], kept: list[dict[str, Any]],
                   log: Callable[[str], None]) -> list[dict[str, Any]]:
    """The fewest of the values ``kept`` that the data need beyond the tolerance together (forward selection).

    Each value passed its own test with the others under their prior, and
    two values may pass for one that is off: the fit spreads the change over
    both (an inductance at 0.46x taken as itself at 0.57x and a neighbour at
    0.71x), and each, held at its edge, leaves the other's prior in the way.
    Here the values are weighed together: with every one of them held at the
    tolerance's nearest edge, the model is compared in BIC with them all free
    (the holds counted as parameters); while the data reject it by
    ``DRIFT_MIN_DBIC``, the value whose freeing fits best is freed. What is
    freed then is the drift reported. Each fit starts from the model's values
    and from the design's (the basin of a spread-out optimum is not the
    basin of the value off alone). Values in parallel (:func:`parallel_partners`)
    are one unit, as in :func:`_held_check`: held with their combination at
    the edge, each keeping its share, the hold counted as one parameter.
    """
    units = _units(ctx, current, kept)
    if len(units) < 2:
        return kept
    tail = current.x[current_nc(current):]
    keys = {n.lower() for u in units for n in u} | set(freed)
    loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k not in keys})
    n_res = current.n_residuals

    def combined(unit: list[str]) -> float:  # the unit's ratio to the design
        kind = current.circuit.element(unit[0]).kind
        return parallel_value(kind, [current.values[g] for g in unit]) / \
            parallel_value(kind, [ctx.prior.design[g.lower()] for g in unit])

    def fitted(free: list[int]) -> tuple[FitResult, float] | None:  # the units not in ``free`` held at the edge
        held_units = [u for i, u in enumerate(units) if i not in free]
        edge = {}
        for u in held_units:
            ratio = combined(u)
            shift = float(np.exp(np.clip(np.log(ratio), -ctx.prior.tau, ctx.prior.tau))) / ratio
            edge.update({g: current.values[g] * shift for g in u})
        held = [g for u in held_units for g in u]
        try:
            fit = ctx.fit(current.fitted_circuit().with_values(edge), current.effects, fixed=held, prior=loose,
                          couplings=current.couplings)
            x0 = np.concatenate([np.zeros(fit.nc), tail])
            best = fit.fit(x0s=x0[None], grid=False, max_nfev=60, tol=1e-7)
            other = fit.fit_continued(fit.design_vector(x0), max_nfev=60, tol=1e-7)
        except CANDIDATE_FAILURES:
            return None
        res = other if other.objective < best.objective else best
        return res, res.bic + sum(len(u) - 1 for u in held_units) * np.log(n_res)  # one parameter per hold

    every, now = fitted(list(range(len(units)))), fitted([])
    if every is None or now is None:
        return kept
    chosen: list[int] = []
    while len(chosen) < len(units) and now[1] - every[1] >= DRIFT_MIN_DBIC:
        trials = [(t, i) for t, i in ((fitted(chosen + [i]), i) for i in range(len(units)) if i not in chosen)
                  if t is not None]
        if not trials:
            return kept
        now, pick = min(trials, key=lambda t: t[0][1])
        chosen.append(pick)
    dropped = [n for i, u in enumerate(units) if i not in chosen for n in u]
    if dropped:
        said = [", ".join(u) for i, u in enumerate(units) if i in chosen]
        log(f"{', '.join(dropped)}: held within the tolerance together"
            + (f" with {'; '.join(said)} free" if said else "")
            + ", the data do not need them beyond it: not reported")
    return [d for d in kept if d["name"] not in dropped]


def parallel_partners(circuit: Circuit, name: str) -> list[str]:
    """The other elements of ``name``'s kind across the same two nodes (R, L or C; uncoupled inductors): the
    terminals see only their combination with ``name``."""
    el = circuit.element(name) if circuit.has_element(name) else None
    if el is None or el.kind not in "RLC":
        return []
    coupled = {n.lower() for e in circuit.elements if e.kind == "K" for n in e.nodes}
    if el.key in coupled:
        return []
    ends = {node_name(n) for n in el.nodes}
    return [e.name for e in circuit.elements if e.kind == el.kind and e.key != el.key and e.key not in coupled
            and {node_name(n) for n in e.nodes} == ends]


def parallel_value(kind: str, values: Sequence[float]) -> float:
    """The value of elements of one ``kind`` in parallel (SI): capacitances add, resistances and uncoupled
    inductances combine as conductances."""
    return float(sum(values)) if kind == "C" else 1.0 / sum(1.0 / x for x in values)


def with_parallel(circuit: Circuit, values: Mapping[str, float], design: Mapping[str, float],
                  drift: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``drift`` with, for each value that has others of its kind across the same two nodes, ``parallel`` (their
    names) and ``combined`` (``design``, ``fitted`` and ``ratio`` of the combination: capacitances add, resistances
    and uncoupled inductances combine as conductances).

    The terminals see only the combination: a capacitance across a section that ends at ground is in parallel with
    that node's capacitance to ground, and a change of either fits the data equally well.
    """
    fitted = {k.lower(): float(v) for k, v in values.items()}
    out = []
    for d in drift:
        d = dict(d)
        group = [circuit.element(n) for n in parallel_partners(circuit, d["name"])]
        if group:
            el = circuit.element(d["name"])
            if all(e.key in fitted and design.get(e.key) for e in group):
                both = {"design": parallel_value(el.kind, [d["design"]] + [design[e.key] for e in group]),
                        "fitted": parallel_value(el.kind, [d["fitted"]] + [fitted[e.key] for e in group])}
                both["ratio"] = both["fitted"] / both["design"]
                d["parallel"] = [e.name for e in group]
                d["combined"] = both
        out.append(d)
    return out


def _held_check(args: tuple[Any, FitResult, list[str], dict[str, Any], FitResult | None]
                ) -> tuple[dict[str, Any] | None, str]:
    """One drifted value freed from the prior, then held at the tolerance's edge (:func:`relaxed_drift`).

    ``(ctx, model, freed, drift entry, box's best fit or None)`` to the entry to report (or None)
    and a progress line (or ``""``). A value with others of its kind across
    the same two nodes (:func:`parallel_partners`) is one value with them to
    the data: they are freed and held together, their combination (a sum of
    capacitances, of conductances) at the edge, each keeping its share, the
    hold counted as one parameter. (Held alone, the partner takes the change
    within its own tolerance, and a node's capacitance 1.3x off passes for
    two within it.)
    """
    ctx, current, freed, d, within = args
    name = d["name"]
    circuit = current.circuit
    group = [name] + [p for p in parallel_partners(circuit, name)
                      if p.lower() in ctx.prior.design and p in current.values]
    keys = {g.lower() for g in group}
    tail = current.x[current_nc(current):]
    loose = replace(ctx.prior, design={k: v for k, v in ctx.prior.design.items() if k not in freed and k not in keys})

    def combined(values: dict[str, float]) -> float:  # the combination's ratio to the design's
        kind = circuit.element(name).kind
        return parallel_value(kind, [values[g] for g in group]) / \
            parallel_value(kind, [ctx.prior.design[g.lower()] for g in group])

    try:
        free_fit = current
        if not keys <= set(freed):
            fit = ctx.fit(current.fitted_circuit(), current.effects, prior=loose, couplings=current.couplings)
            free_fit = fit.fit(x0s=np.concatenate([np.zeros(fit.nc), tail])[None], grid=False, max_nfev=60,
                               tol=1e-7)
            if abs(np.log(combined(free_fit.values))) <= ctx.prior.tau:
                return None, (f"{name}: x{d['ratio']:.3g} off the design, back within the tolerance once freed"
                              + (" (with " + ", ".join(group[1:]) + " in parallel)" if len(group) > 1 else "")
                              + ": not reported")
            moved = ctx.prior.drift({name: free_fit.values[name]})
            d = moved[0] if moved else {**d, "fitted": float(free_fit.values[name]),
                                        "ratio": float(free_fit.values[name] / ctx.prior.design[name.lower()])}
        edge = float(np.exp(np.copysign(ctx.prior.tau, np.log(combined(free_fit.values)))))
        # the profile at the edge is the lowest cost of any model holding it there: fitted from the freed model
        # moved onto the edge and from the model before freeing moved onto it (a freed value that wanders off
        # while the others follow it leaves the held fit far from the basin the model was in), and from the box's
        # best fit moved onto it (a model whose values all sit within the tolerance may lie in another basin than
        # the one the model settled in: the others beyond the tolerance there made the held value look needed)
        starts = [free_fit] if free_fit is current else [free_fit, current]
        if _same_structure(within, current):
            starts.append(within)
        trials = []
        for start in starts:
            shift = edge / combined(start.values)
            held = start.fitted_circuit().with_values({g: start.values[g] * shift for g in group})
            fit = ctx.fit(held, current.effects, fixed=group, prior=loose, couplings=current.couplings)
            trials.append(fit.fit(x0s=np.concatenate([np.zeros(fit.nc), start.x[current_nc(start):]])[None],
                                  grid=False, max_nfev=40, tol=1e-6))
        trial = min(trials, key=lambda t: t.bic)
    except CANDIDATE_FAILURES:
        return d, ""
    # the freed fit carries the same prior as the held one (its own value's term left out); the hold is one
    # parameter however many values in parallel it holds
    d["delta_bic"] = float(trial.bic - free_fit.bic + (len(group) - 1) * np.log(free_fit.n_residuals))
    if d["delta_bic"] >= DRIFT_MIN_DBIC:
        return d, ""
    return None, (f"{name}: x{d['ratio']:.3g} off the design, but the data do not need it beyond the tolerance "
                  f"(dBIC {d['delta_bic']:.1f} at its edge): not reported")


def _freed(ctx: Any, final: FitResult, name: str) -> FrequencyFit:
    """The fit of ``final``'s model with the value ``name`` freed from the design prior."""
    loose = replace(ctx.prior, design={n: v for n, v in ctx.prior.design.items() if n != name.lower()})
    return ctx.fit(final.fitted_circuit(), final.effects, prior=loose, couplings=final.couplings)


def freed_fit(args: tuple[Any, FitResult, str, np.ndarray]) -> FitResult | None:
    """``(ctx, model, name, start)`` to the model fitted from ``start`` with the value ``name`` freed from its prior
    (``freed`` set to it), or None when the fit fails (:func:`located_drift`)."""
    ctx, final, name, x0 = args
    try:
        trial = _freed(ctx, final, name).fit_continued(x0, max_nfev=100, tol=1e-7)
    except CANDIDATE_FAILURES:
        return None
    trial.freed = name
    return trial


def freed_multistart(args: tuple[Any, FitResult, str, np.ndarray, float]) -> FitResult | None:
    """``(ctx, model, name, start, reach)`` to the model fitted with the value ``name`` freed from its prior, from
    the design with that value as in ``start`` (every other value at its design value) and from random starts
    around it as the baseline is (:func:`.baseline.fit_multistart`), those tried unless the fit from the design
    reaches ``reach``; None when the fit fails (:func:`located_drift`). The fitted values that made up for the
    value under its prior are left behind: they hold the basin the local fits stopped in."""
    ctx, final, name, x0, reach = args
    try:
        one = _freed(ctx, final, name)
        trial = fit_multistart(one, good_enough=reach, x0=one.design_vector(x0), floor=ctx.floor)
    except CANDIDATE_FAILURES:
        return None
    trial.freed = name
    return trial


def release_gains(fit: FrequencyFit, x: np.ndarray) -> np.ndarray:
    """Predicted fall of the weighted sum of squared residuals when each anchored value's prior is released.

    The score (Lagrange multiplier) test of each value's prior: with that
    prior's residual removed, one Gauss-Newton step from the fitted model
    predicts how far the cost falls, to second order. A model that holds a
    value really off the design spreads it over several values, each pulled
    back by the prior; its resonances are aligned with the data's already,
    so a scan of one value's ratio does not rank the values (every ratio
    misaligns them alike), but the value whose release gains most is the
    first to free (:func:`located_drift`).

    Parameters
    ----------
    fit : FrequencyFit
        The fit, with its design prior (:attr:`.fit.FrequencyFit.anchored_columns`).
    x : numpy.ndarray
        The fitted parameter vector (an optimum of ``fit``'s residuals).

    Returns
    -------
    numpy.ndarray
        One gain per anchored column, in the units of the residuals' sum of squares (half the cost as
        :meth:`.fit.FrequencyFit.fit` ranks it); zeros without a prior or when the Jacobian is not finite.
    """
    cols = fit.anchored_columns
    gains = np.zeros(cols.size)
    if not cols.size:
        return gains
    r = fit.residuals(x)
    J = fit.jacobian(x)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return gains
    n_data = r.size - cols.size  # the prior's residuals come last, one per anchored column
    for k in range(cols.size):
        keep = np.ones(r.size, bool)
        keep[n_data + k] = False
        step = np.linalg.lstsq(J[keep], -r[keep], rcond=None)[0]
        after = r[keep] + J[keep] @ step
        gains[k] = float(r @ r - after @ after)
    return gains


#: Range (ratios to the design) and points of the scan of each value tried as the one off the design
#: (:func:`located_drift`).
LOCATE_RANGE = (0.25, 4.0)
LOCATE_SCAN = 21
#: Local fits of the most promising one-value hypotheses.
LOCATE_FITS = 4


def _remember(ctx: Any, trial: FitResult) -> None:
    """Keep ``trial`` in ``ctx.located`` when it is the best fit of its freed value so far: a start of that value's
    fits within the box (:func:`_one_for_many`), what :func:`_start_from` needs, not the whole fit (the context goes
    to every parallel job)."""
    seen = ctx.located.get(trial.freed)
    if seen is None or trial.objective < seen[0]:
        ctx.located[trial.freed] = (trial.objective, [e.label for e in trial.effects], tuple(trial.couplings),
                                    dict(trial.values), trial.x[current_nc(trial):].copy(), trial.bic)


def located_drift(ctx: Any, final: FitResult, target: float, log: Callable[[str], None],
                  rival: float | None = None) -> FitResult | None:
    """The final model refitted with one design value off the design, if that alone explains the data.

    Under the log-normal prior a value that is really off (a capacitance
    doubled) is pulled back towards the design, and the fit spreads its
    effect over several values within reach of the prior: a poor optimum
    with the wrong values reported off. A local view of that optimum does
    not see the other basin (freeing one value's prior there changes
    nothing to first order), but the resonances do. Each value the prior
    holds is scanned alone over ``LOCATE_RANGE`` times its design value
    (``LOCATE_SCAN`` points, the other values at their design values, and
    again at the final model's) for how close it
    brings the model's resonances to the measured ones
    (:func:`.align.resonance_mismatch`). The ``LOCATE_FITS`` values that
    align best from each origin are each aligned from their best ratio with the others
    pulled towards their origin (:func:`.align.aligned_start`) and fitted
    locally, that value freed from its prior; so are the values the final
    model moved beyond the tolerance (a resistance moves no resonance),
    and the ``LOCATE_FITS`` values whose prior, released, the score test
    predicts to lower the cost most (:func:`release_gains`: the
    scan from a model at the noise aligns every value alike), from where
    they are. The best is kept if it
    reaches ``target`` (the noise margin) without gross drift of the values
    still held, and beats the final model's BIC by ``DRIFT_MIN_DBIC``. The
    other values fitted that reach ``target`` too, with a BIC within
    ``DRIFT_MIN_DBIC`` of it, are kept as ``drift_alternatives`` (name,
    design, fitted, ratio, delta_bic): a driving-point impedance may not
    tell which of two values far apart in a winding changed.

    With ``rival`` (the lowest objective a rival model reached, a cause
    or a structure) above the best local fit, every value tried is fitted
    again from the design with it at its best ratio and from random starts
    around that (:func:`freed_multistart`): a local fit from a
    model whose other values sit a few per cent off stalls on the sharp
    resonances of a lightly damped winding, and a value is weighed against
    its rivals by its best fit, not by where a local fit stopped.

    Returns
    -------
    FitResult or None
        The refitted model (same structure and effects), or ``None``.
    """
    if ctx.prior is None:
        return None
    t0 = time.perf_counter()
    try:
        fit = ctx.fit(final.fitted_circuit(), final.effects, couplings=final.couplings)
    except CANDIDATE_FAILURES:
        return None
    cols = fit.anchored_columns
    if not cols.size:
        return None
    x_fitted = np.concatenate([np.zeros(fit.nc), final.x[current_nc(final):]])
    x_design = fit.design_vector(x_fitted)
    # each value scanned alone (the others at their design values, and at the final model's: a model far above the
    # noise may still hold every other value near its truth) for the resonances it alone can align
    ratios = np.exp(np.linspace(np.log(LOCATE_RANGE[0]), np.log(LOCATE_RANGE[1]), LOCATE_SCAN))
    starts = []
    for origin in (x_design, x_fitted):
        X = one_at_a_time(origin, cols, x_design, np.log(ratios))  # the ratio to the design value, whatever the origin
        mismatch = resonance_mismatch(fit, X).reshape(cols.size, ratios.size)
        for p in np.argsort(mismatch.min(axis=1))[:LOCATE_FITS]:
            x0 = X[p * ratios.size + int(np.argmin(mismatch[p]))]
            aligned = aligned_start(fit, x0, free=[cols[p]])
            starts.append((p, x0 if aligned is None else aligned))
    # and the values the final model already moved beyond the tolerance, each freed where it is (a resistance moves
    # no resonance, and the scan does not rank it)
    beyond = [d["name"].lower() for d in ctx.drift(final)]
    from_fitted = [p for p, c in enumerate(cols) if fit.free[c].lower() in beyond[:LOCATE_FITS]]
    # and the values whose prior, released, is predicted to lower the cost most (the score test): a model at the
    # noise has its resonances aligned already, and the scan from it does not rank the values
    gains = release_gains(fit, x_fitted)
    from_fitted += [int(p) for p in np.argsort(-gains)[:LOCATE_FITS] if gains[p] > 0 and p not in from_fitted]
    starts += [(p, x_fitted) for p in from_fitted]
    t_align = time.perf_counter() - t0

    def others_gross(t: FitResult) -> bool:  # a value besides the freed one more than GROSS_DRIFT tolerances off
        return any(d["name"].lower() != t.freed.lower() for d in ctx.gross(t))

    best, trials = None, []
    for trial in shared_map(freed_fit, [(ctx, final, fit.free[cols[p]], x0) for p, x0 in starts]):
        if trial is None:
            continue
        trials.append(trial)
        _remember(ctx, trial)
        if best is None or trial.bic < best.bic:
            best = trial
    if best is not None and rival is not None and best.objective > rival:
        # the local fits stopped above the objective a rival model reached: the data can be fitted closer than they
        # came, and each value's profile is the lowest cost of any model with it free, so each value tried is
        # fitted again from the design with it at its best fit's ratio and from random starts around that (until
        # one reaches the rival), as the baseline is
        t = time.perf_counter()
        own = {}
        for trial in trials:
            if trial.freed not in own or trial.objective < own[trial.freed].objective:
                own[trial.freed] = trial
        for trial in shared_map(freed_multistart, [(ctx, final, v, o.x, rival) for v, o in own.items()]):
            if trial is not None and trial.objective < own[trial.freed].objective:
                trials.append(trial)
                _remember(ctx, trial)
                if trial.bic < best.bic:
                    best = trial
        log(f"one value off the design: {len(own)} values fitted again from random starts, a rival reaching "
            f"{rival:.4g} ({time.perf_counter() - t:.1f} s)")
    if best is None:
        return None
    dbic = final.bic - best.bic
    ratio = best.values[best.freed] / ctx.prior.design[best.freed.lower()]
    if best.objective > target or others_gross(best) or dbic < DRIFT_MIN_DBIC:
        log(f"one value off the design: {best.freed} x{ratio:.3g} fits to {best.objective:.4g} (dBIC {dbic:.1f}): "
            "not kept")
        return None
    # another value that explains the data as well (the BIC within DRIFT_MIN_DBIC): the data do not tell which
    best.drift_alternatives = _alternatives(ctx, best, trials, lambda t: t.objective <= target and not others_gross(t),
                                            log)
    log(f"one value off the design: {best.freed} x{ratio:.3g} explains the data (cost {final.objective:.4g} -> "
        f"{best.objective:.4g}, dBIC {dbic:.1f}; {t_align:.1f} s aligning, {time.perf_counter() - t0:.1f} s in all)")
    return best
