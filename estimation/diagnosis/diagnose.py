"""Frequency-response diagnosis: fit the baseline, fit every cause, choose causes one by one, measure the gain.

Steps:

1. The baseline (a built-in model, a netlist, or a lumped R-L-C fitted to
   one-port data) is fitted to the data, from its values and from random
   starts around them (:func:`fit_multistart`). A baseline that fits to the
   noise floor ends the diagnosis: ``none``, nothing else is fitted.
2. Every cause of the catalogue (:mod:`.catalogue`: each in the thesis's
   form and in causal forms, per winding group; :mod:`.sections`: a missing
   section, split or added at either end of every winding) is fitted together
   with the baseline's values, starting from the fitted baseline and from
   the baseline's nominal values. A fit that ends at or above the baseline
   cost has failed: it is retried from further starts, and when none beats
   the baseline it is reported as failed, never as a candidate. A candidate
   whose circuit values, with the effect removed, fit better than the
   baseline improves the baseline itself (so no gain comes from a better
   optimum of the baseline). When the measurement shows a resonance the
   fitted baseline lacks, or the baseline stays far above the noise, a
   missing section is also sought from the nominal circuit as two whole
   sections seeded at the measured resonances (:mod:`.unmerge`); its two
   sections merged back refit the baseline. For one-port data that no
   single cause explains, every section of the fitted model (and, when
   those splits do not explain the data either, of the design) is made two
   whole sections, as designed and respaced along the winding made one
   section longer (:class:`.unmerge.Unmerged`), and fitted from several starts
   (:func:`.section_fits.split_every_section`), alone and beside the effect
   that does best alone. A baseline that does not explain the data
   (:meth:`.context.Context.unfit`) is also tried against the drift of a
   whole group of values (:mod:`.group_drift`), the answer when its BIC is
   below every single cause's; one that does not explain the data against
   one value off the design (:func:`.drift.located_drift`), weighed the same
   way (the freed value counted as one parameter).
3. Forward selection: the cause with the lowest Bayesian information
   criterion ``BIC = N ln(RSS/N) + k ln N`` is named if it beats the
   baseline's BIC by ``min_delta_bic`` (10: "very strong" evidence on Kass and
   Raftery's scale) and removes at least ``min_gain`` of the misfit above the
   noise floor (:func:`_share`; none for a model at the floor already); then
   each remaining cause is refitted together with those named, and the best
   is added while its BIC improves by ``min_delta_bic`` and it removes at
   least ``min_step_gain`` of what is left above the floor. Against a model that reaches the
   noise floor only by moving a value more than ``GROSS_DRIFT`` tolerances
   off the design (no explanation), a candidate that reaches it within them
   needs the BIC margin but no share of the cost. A structural cause (a missing
   section) must also remove that share of the cost on held-out points
   (:mod:`.holdout`, refits converged and with the design prior), and one found from the nominal circuit only while a
   measured resonance is still missing from the model or when it brings the
   fit to the noise floor (a split of the design with its couplings free:
   only within ``UNMERGE_ABOVE_FLOOR`` times it, whatever the resonances); one refused by the held-out check
   is tried again after the next cause is named, and a section alone refused
   as the first cause is fitted together with each effect (pairs). Selection stops when the cost
   reaches the noise floor estimated from the data (:func:`.evidence.noise_floor`; for one-port data also
   ``NOISE_MARGIN`` times the floor estimated from the model's residuals, :meth:`Context.residual_floor`)
   without values of the design moved far off it (a new section's own values
   are not anchored to the design; one it leaves far off took another
   cause's share).
   A new section sought before any other cause is named frees the tight
   couplings of the sections it touches (:mod:`.sections`), in its fit and
   every later refit of that model; one sought after a frequency-dependent
   cause keeps the couplings (with them free it would take that cause's rest).
   A cause made redundant by those named after it is dropped; while the model
   stays above the noise, each named cause's form and group is then chosen
   again with the others in the model (:mod:`.forms`; a swap only if the BIC
   improves by ``min_delta_bic``). When a form changes, the causes not named
   are fitted again with the changed model and the selection goes on from
   it (once).
4. What is still above the noise after the last step is reported by band
   (:func:`.evidence.unexplained_bands`). A model that stays above twice the
   noise floor does not explain the data (:mod:`.verdict`): with no cause
   named the answer is ``unexplained``, never ``none``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration, Model, get_model

from estimation.diagnosis.baseline import fit_multistart, lumped_from_data
from estimation.diagnosis.cores import helper_available, shared_map
from estimation.diagnosis.causes.catalogue import FREQUENCY_CAUSES, Effect
from estimation.diagnosis.evidence import (band_table, localise, noise_floor, noise_weights, resonance_comparison,
    unexplained_bands)
from estimation.diagnosis.fit import (CANDIDATE_FAILURES, DiagnosisError, FitResult, FrequencyFit,
    configuration_ports, current_nc, significant)
from estimation.diagnosis.drift import DRIFT_MIN_DBIC, freed_fit, located_drift, relaxed_drift, with_parallel
from estimation.diagnosis.converge import converged, converged_job
from estimation.diagnosis.causes.extend import extensions
from estimation.diagnosis.holdout import held_out_gain
from estimation.diagnosis.prior import DEFAULT_TOLERANCE, DesignPrior, design_prior
from estimation.diagnosis.causes.forms import rechoose_forms
from estimation.diagnosis.causes.realise import realise_extended
from estimation.diagnosis.causes.rivals import CAUSE_TIE_DBIC, cause_over_drift, ties, whole_answer
from estimation.diagnosis.report import parallel_note
from estimation.diagnosis.result import Diagnosis
from estimation.diagnosis.causes.section_fits import (every_section_split, section_pairs, structure_prior,
    split_every_section)
from estimation.diagnosis.causes.single import single_causes, start_tails
from estimation.diagnosis.causes.unmerge import missing_modes, resolved_points
from estimation.diagnosis.verdict import explains, misfit_sentence
from estimation.diagnosis.group_drift import group_drift, value_without_group
from estimation.diagnosis.context import (MAX_BASELINE_RMS, NOISE_MARGIN, STRUCTURAL, STRUCTURAL_FLOOR,
    UNMERGE_ABOVE_FLOOR, Context, log)

def _refuse(pool: dict[str, Any], failed: list[dict[str, Any]], best: Any, cause: str, progress: bool,
            message: str, reason: str) -> None:
    """Refuse a structural candidate: say why on stderr, record it in ``failed``, drop it from ``pool``."""
    log(f"{cause}: {message}: refused", progress)
    failed.append({"cause": cause, "cost": best.cost, "reason": reason})
    pool.pop(best.cause if best.cause in pool else cause)


def diagnose_frequency(
    frequency_hz: np.ndarray,
    measured: Mapping[str, np.ndarray],
    model: Model | None = None,
    circuit: Circuit | None = None,
    port: str | None = None,
    min_delta_bic: float = 10.0,
    min_gain: float = 0.2,
    min_step_gain: float = 0.2,
    max_causes: int = 3,
    causes: Sequence[str] | None = None,
    progress: bool = True,
    tolerance: float = DEFAULT_TOLERANCE,
    uncertainty: Mapping[str, np.ndarray] | None = None,
) -> Diagnosis:
    """Diagnose measured frequency responses against a baseline model.

    Parameters
    ----------
    frequency_hz : numpy.ndarray, Hz
    measured : mapping
        Response name (``Zin``, ``Zlvoc`` ...) to complex values.
    model : Model, optional
        Baseline with test configurations (two-winding models, built-ins).
    circuit, port : Circuit, str, optional
        Baseline given as a one-port netlist driven at ``port`` (response ``Zin``).
    min_delta_bic, min_gain : float
        Thresholds for naming the first cause instead of ``none``: the BIC margin, and the share of the misfit above
        the noise floor the cause must remove (:func:`_share`).
    min_step_gain : float
        Share of the remaining misfit above the noise floor a further cause must remove.
    max_causes : int
        Most causes named.
    causes : sequence of str, optional
        Causes to try (default: the whole catalogue).
    progress : bool
        Progress lines on stderr.
    tolerance : float
        How far the baseline's values (a netlist or a built-in model: the
        design) may be from the truth, relative (default 0.2). Every fit gets
        a log-normal prior of that width around the design values
        (:mod:`.prior`); ``inf`` leaves the values free. No effect on a
        lumped baseline fitted to the data.
    uncertainty : mapping, optional
        Response name to the standard deviation of ``ln H`` at each frequency
        (e.g. a response CSV's ``NAME_ln_sd`` column). Each residual is then
        weighted by its inverse (scaled to a mean square of one per response),
        and the noise floor is that of the weighted cost, its scale read from
        the data (:func:`.evidence.noise_floor`).

    Returns
    -------
    Diagnosis
    """
    from threadpoolctl import threadpool_limits

    helper_available()  # the helper process on another core (:mod:`.cores`), started while the first fits run here
    with threadpool_limits(limits=1):  # small matrices: BLAS threads only contend for the cores
        try:
            return _diagnose(frequency_hz, measured, model, circuit, port, min_delta_bic, min_gain, min_step_gain,
                             max_causes, causes, progress, tolerance, uncertainty)
        except CircuitError as exc:
            raise DiagnosisError(f"baseline: {exc}") from None


def _diagnose(frequency_hz, measured, model, circuit, port, min_delta_bic, min_gain, min_step_gain, max_causes,
              causes, progress, tolerance=DEFAULT_TOLERANCE, uncertainty=None) -> Diagnosis:
    t0 = time.perf_counter()
    if not (isinstance(tolerance, (int, float)) and tolerance > 0):
        raise DiagnosisError(f"--tolerance must be a positive number or inf, got {tolerance!r}")
    f = np.asarray(frequency_hz, float)
    data = {k: np.asarray(v, complex) for k, v in measured.items()}
    if not data:
        raise DiagnosisError("no measured responses")
    if f.ndim != 1 or f.size < 5 or np.any(~np.isfinite(f)) or np.any(f <= 0) or np.any(np.diff(f) <= 0):
        if f.size < 5:
            raise DiagnosisError(f"too few points: {f.size} frequencies")
        raise DiagnosisError("frequencies must be positive and increasing")
    for k, v in data.items():
        if v.shape != f.shape or not np.all(np.isfinite(v)) or np.any(v == 0):
            raise DiagnosisError(f"response {k!r}: values must be finite, non-zero and one per frequency")
    sd = {k: np.asarray(v, float) for k, v in (uncertainty or {}).items()}
    for k, v in sd.items():
        if k not in data or v.shape != f.shape or not np.all(np.isfinite(v) & (v > 0)):
            raise DiagnosisError(f"uncertainty of {k!r}: one finite positive value per frequency of a measured response")
    if circuit is not None:
        if port is None:
            raise DiagnosisError("a netlist baseline needs --port")
        port = circuit.require_node(port, "port")
        model = Model("netlist", circuit.title, circuit,
                      {"default": Configuration("default", port, (), (Response("Zin"),))})
    todo = tuple(causes) if causes is not None else FREQUENCY_CAUSES
    unknown = [c for c in todo if c not in FREQUENCY_CAUSES]
    if unknown:
        raise DiagnosisError(f"unknown cause {unknown[0]!r} (known: {', '.join(FREQUENCY_CAUSES)})")
    fixed = tuple(model.fixed) if model is not None else ()
    impedance_scale = float(np.median([np.median(np.abs(v)) for k, v in data.items() if k.startswith("Z")] or [1.0]))
    if model is None:
        if len(data) != 1:
            raise DiagnosisError(f"no baseline given: one-port data expected, got responses {', '.join(data)}")
        sd = {"Zin": next(iter(sd.values()))} if sd else {}
        data = {"Zin": next(iter(data.values()))}
    floor = noise_floor(f, data, sd)
    weights = noise_weights(sd)
    prior = None
    # ---- baseline
    if model is None:
        starts = lumped_from_data(f, data["Zin"])
        fits = [FrequencyFit(m.circuit, list(m.configurations.values()), f, data, weights=weights).fit()
                for m in starts]
        best_i = int(np.argmin([r.cost for r in fits]))
        baseline = fits[best_i]
        model = Model("lumped-rlc", "Lumped R-L-C fitted to the data", starts[best_i].circuit,
                      starts[best_i].configurations, family=("lumped",))
        log(f"no baseline given: lumped R-L-C fitted (cost {baseline.cost:.4g})", progress)
    else:
        design = FrequencyFit(model.circuit, list(model.configurations.values()), f, data, fixed, weights=weights)
        prior = design_prior(dict(zip(design.free, design.start)), tolerance, floor["cost"], f.size, len(data),
                             model.circuit)
        baseline = fit_multistart(FrequencyFit(model.circuit, list(model.configurations.values()), f, data, fixed,
                                               prior=prior, weights=weights), good_enough=NOISE_MARGIN * floor["cost"],
                                  floor=floor["cost"])
        log(f"baseline {model.name} fitted: cost {baseline.cost:.4g} in {baseline.wall_s:.1f} s", progress)
    worst = max(float(np.sqrt(np.mean(np.abs(e) ** 2))) for e in baseline.errors.values())
    if worst > MAX_BASELINE_RMS:
        raise DiagnosisError(
            f"the baseline does not fit the data at all (RMS error {20 / np.log(10) * worst:.1f} dB after fitting); "
            "check the port, the test configuration or the model"
        )
    configs = list(model.configurations.values())
    one_port = len(configs) == 1 and all(r.node is None for r in configs[0].responses)
    ctx = Context(f, data, configs, fixed, impedance_scale, one_port, progress,
                   nominal=model.circuit if model.family != ("lumped",) else None)
    ctx.floor = floor["cost"]
    ctx.noise = dict(floor["per_response"])
    ctx.prior = prior
    ctx.weights = weights
    ctx.resolved = resolved_points(sd)
    # a missing section is one of the places the search weighs: each has its share of the cause's prior
    ctx.cause_prior["missing-section"] = structure_prior(model.circuit, configuration_ports(configs))
    if prior is not None:
        moved = ctx.drift(baseline)
        log(f"design prior: tolerance {prior.tolerance:g}; baseline moved {len(moved)} value(s) beyond it"
             + (": " + ", ".join(f"{d['name']} x{d['ratio']:.3g}" for d in moved[:6]) if moved else ""), progress)
    log(f"noise floor {floor['cost']:.3g} (noise RMS "
         + ", ".join(f"{k} {100 * v:.2g} %" for k, v in floor["per_response"].items()) + ")", progress)
    # ---- a whole group of values off the design by one factor (all capacitances to ground x1.5): drift of the group
    # (:mod:`.group_drift`), sought from the baseline; it is the answer when its BIC (the factor one parameter) is
    # below every single cause's, measured after them
    # (also for a baseline at the noise with values beyond the tolerance: their drift, value by value, is what the
    # group's one factor is weighed against)
    group, group_on = None, baseline
    if prior is not None and (not ctx.explained(baseline) or ctx.drift(baseline)):
        group_fits: list[FitResult] = []
        group = group_drift(ctx, baseline, lambda m: log(m, progress), group_fits)
        # a group's fit, started from the design values scaled, whose BIC is lower than the baseline's by
        # DRIFT_MIN_DBIC with its factor counted may have found a better optimum of the baseline's own model: the
        # baseline refitted from its values (kept when it fits better), and the groups sought again
        better = [g for g in group_fits
                  if baseline.bic - (g.bic + np.log(g.n_residuals)) >= DRIFT_MIN_DBIC]
        if better:
            baseline = _polish_baseline(ctx, baseline, better, progress)
            group, group_on = group_drift(ctx, baseline, lambda m: log(m, progress)), baseline
    group_entry = None

    # ---- single causes; a candidate's circuit values may fit better than the baseline's own optimum: then the
    # baseline adopts them and every cause is fitted again from it (at most twice)
    # (each cause keeps its best fit over the passes; no second pass once a cause reaches the noise floor)
    results, failed, variants_tried = {}, [], {}
    # (a baseline at the noise with values beyond the tolerance is weighed against itself within the tolerance box:
    # when the data reject the box, something the design lacks is at work, a cause or a value off, and the causes
    # are fitted as for a baseline above the noise)
    passes = 0 if ctx.explained(baseline) and ctx.within_design(baseline) else 3
    if not passes:
        log("the baseline fits to the noise floor within the design tolerance: no cause is fitted", progress)
    elif ctx.explained(baseline):
        log(f"the baseline fits to the noise floor only with values beyond the tolerance (the data reject the "
            f"tolerance box by dBIC {baseline.rejected:.1f}): the causes are fitted", progress)
    for attempt in range(passes):
        res_i, failed_i, variants_i = single_causes(ctx, todo, baseline, progress)
        for cause, r in res_i.items():
            if cause not in results or r.objective < results[cause].objective:
                results[cause] = r
        failed = [x for x in failed + failed_i if x["cause"] not in results]
        variants_tried.update(variants_i)
        polished = _polish_baseline(ctx, baseline, results.values(), progress)
        moved = polished.objective < 0.5 * baseline.objective
        baseline = polished
        explained = any(ctx.explained(r) for r in results.values())
        if not moved or explained or attempt == 2:
            break
        log("causes fitted again from the refitted baseline", progress)
    if (prior is not None and baseline.objective < 0.5 * group_on.objective
            and (not ctx.explained(baseline) or ctx.drift(baseline))):
        group = group_drift(ctx, baseline, lambda m: log(m, progress))  # sought again on the baseline refitted
    # ---- one-port data that no single cause explains within the design, above the noise, fitted only by distorted
    # values or by values the data need beyond the tolerance: every section split, from the fitted values and, when
    # those splits do not explain the data, from the design's (a fitted baseline stuck above the noise keeps its poor
    # optimum in every split started from it); run once, before a drift is taken as the answer
    # (:func:`_drift_answer`), else after it
    split_searched = False

    def every_split(drift_bic: float = np.inf) -> None:
        nonlocal split_searched
        if (split_searched or not (ctx.one_port and ctx.nominal is not None and "missing-section" in todo and passes)
                or not (ctx.unfit(baseline) or ctx.distorted(baseline) or not ctx.within_design(baseline))
                or _explained_within_design(ctx, results, drift_bic)):
            return
        split_searched = True
        t = time.perf_counter()
        wide = every_section_split(ctx, baseline, configuration_ports(configs))
        if wide is not None and wide.objective < baseline.objective and ctx.penalised_bic(wide) < (
                ctx.penalised_bic(results["missing-section"]) if "missing-section" in results else np.inf):
            results["missing-section"] = wide
            failed[:] = [x for x in failed if x["cause"] != "missing-section"]
            log(f"missing-section (every split): {wide.structure}: cost {wide.cost:.4g}, gain "
                 f"{1 - wide.cost / baseline.cost:.3f}, dBIC {baseline.cause_bic - wide.cause_bic:.1f} "
                 f"({time.perf_counter() - t:.1f} s)", progress)

    # ---- the group's drift, then one value off the design, weighed against every single cause
    prior_before = ctx.prior
    baseline, group_entry, answered, located_on = _drift_answer(ctx, baseline, group, results, failed, None,
                                                                 bool(passes), every_split)
    prior = ctx.prior
    weighed = results  # what a drift answer was weighed against, counting its located value alone (weighed again)
    if answered:
        results, passes = {}, 0
    every_split()
    if passes and results and ctx.one_port:
        # the single causes compared between converged fits, as the further causes are (:mod:`.causes.extend`): a
        # fit stopped after tens of evaluations shows less than its form holds, and by a share that differs between
        # forms; the baseline is refitted too, the reference their gains are measured against
        keys = [c for c, r in results.items() if not r.structure]
        *fits, polished = shared_map(converged_job, [(ctx, results[c]) for c in keys] + [(ctx, baseline)])
        for c, r in zip(keys, fits):
            if r is not results[c]:
                log(f"  {c} refitted to convergence: {results[c].objective:.4g} -> {r.objective:.4g}", progress)
                results[c] = r
        if polished is not baseline:
            log(f"baseline refitted to convergence: {baseline.objective:.4g} -> {polished.objective:.4g}", progress)
            baseline = polished
    for cause in list(results):
        if results[cause].objective >= baseline.objective:
            failed.append({"cause": cause, "cost": results.pop(cause).cost,
                           "reason": "no better than the baseline refitted from its circuit values"})
    # a cause that explained the data (no split searched for it) and is no better than the baseline refitted from its
    # values explains nothing: the search runs now if the baseline still needs it
    every_split()

    # ---- pairs: a missing section and a continuous effect fitted together, when no single cause is enough
    pool = dict(results)
    if ("missing-section" in todo and max_causes >= 2 and ctx.unfit(baseline)
            and not any(significant(baseline.cause_bic, baseline.objective, r.cause_bic, r.objective, min_delta_bic,
                                    min_gain) for r in results.values())):
        pool.update(section_pairs(ctx, results, baseline))
        # one-port data: every section split beside the effect that does best alone (its parameters free too)
        effects_alone = [r for c, r in results.items()
                         if c not in STRUCTURAL and r.effects and r.cause_bic < baseline.cause_bic]
        if ctx.one_port and ctx.nominal is not None and effects_alone:
            single = min(effects_alone, key=lambda r: r.cause_bic)
            t = time.perf_counter()
            log(f"missing-section: every section split beside {single.cause}", progress)
            pair = split_every_section(ctx, single, configuration_ports(configs), from_design=ctx.distorted(single))
            if pair is not None and pair.objective < min([single.objective] + [r.objective for c, r in pool.items()
                                                                                if c == pair.cause]):
                pool[pair.cause] = pair
                log(f"pair {pair.cause} (every split): {pair.structure}: cost {pair.cost:.4g}, gain "
                    f"{1 - pair.objective / baseline.objective:.3f}, dBIC {baseline.cause_bic - pair.cause_bic:.1f} "
                    f"({time.perf_counter() - t:.1f} s)", progress)

    # ---- forward selection, then a backward check; a section named with other causes is checked against the
    # selection without it (a section's free values take a share of any effect, and a greedy first step that names
    # it may never reach the model of the effects alone)
    opts = dict(min_delta_bic=min_delta_bic, min_gain=min_gain, min_step_gain=min_step_gain, max_causes=max_causes)
    current, chosen, steps = _select(ctx, baseline, pool, results, variants_tried, failed, **opts)
    section_tie: list[dict[str, Any]] = []
    if any(c in STRUCTURAL for c in chosen) and (len(chosen) > 1 or not ctx.explained(current)):
        alt_pool = {c: r for c, r in pool.items() if not any(s in c.split("+") for s in STRUCTURAL)}
        if alt_pool:
            log("selection again without " + ", ".join(c for c in chosen if c in STRUCTURAL), progress)
            alt_failed: list[dict[str, Any]] = []
            alt = _select(ctx, baseline, alt_pool, results, variants_tried, alt_failed, **opts)
            # kept when it is better both ways: a lower BIC and a data cost no higher (under the prior, a model
            # that fits the data worse can win the BIC on the penalty of the values a section moved), or a lower
            # BIC at the noise floor (both fit to the noise: what the section adds to the fit is noise)
            # a BIC lower by less than CAUSE_TIE_DBIC is a tie ("not worth more than a bare mention"): it does not
            # overturn the selection, and the causes without the section are reported beside it
            if (alt[1] and alt[0].cause_bic < current.cause_bic - CAUSE_TIE_DBIC
                    and (alt[0].cost <= current.cost or ctx.settled(alt[0]))):
                log(f"{', '.join(alt[1])} without the section: BIC lower by "
                    f"{current.cause_bic - alt[0].cause_bic:.1f} "
                    f"than {', '.join(chosen)}, cost {alt[0].cost:.4g} + {alt[0].penalty:.4g} against "
                     f"{current.cost:.4g} + {current.penalty:.4g}: kept", progress)
                current, chosen, steps = alt
                failed += alt_failed
            else:
                if alt[1] and abs(alt[0].cause_bic - current.cause_bic) < CAUSE_TIE_DBIC:
                    section_tie = [{"cause": " + ".join(alt[1]),
                                    "delta_bic": float(alt[0].cause_bic - current.cause_bic)}]
                log(f"without the section ({', '.join(alt[1]) or 'none'}): BIC "
                    f"{alt[0].cause_bic - current.cause_bic:+.1f}, "
                    f"cost {alt[0].cost:.4g} + {alt[0].penalty:.4g} against {current.cost:.4g} + {current.penalty:.4g}: the "
                     "section stays", progress)
    extended = current if chosen else None
    # ---- a value of the design really off: one value freed may explain what the prior's spread-out fit leaves
    if (prior is not None and not ctx.explained(extended or baseline) and not hasattr(extended or baseline, "freed")
            and (extended or baseline) is not located_on):
        located = located_drift(ctx, extended or baseline, NOISE_MARGIN * floor["cost"], lambda m: log(m, progress))
        if located is not None:
            located.structure = (extended or baseline).structure
            if extended is not None:
                located.cause = extended.cause
                extended = located
            else:
                baseline = located
                # the group with the value on top of it, against the value alone
                alone = value_without_group(ctx, prior_before, located, group_entry, lambda m: log(m, progress)) \
                    if group_entry is not None else None
                if alone is not None:
                    baseline, group_entry = alone, None
                    ctx.prior = prior = prior_before
    aside = ctx.drift_aside
    if aside is not None and group_entry is None:
        taken = whole_answer(ctx, aside, extended or baseline, chosen, results)
        if taken is not None:
            baseline, extended, current, chosen, steps = taken, None, taken, [], []
    on_top, relaxed = relaxed_drift(ctx, extended or baseline, lambda m: log(m, progress)) if prior is not None \
        else ([], None)
    if group_entry is not None and extended is None and len(on_top) == 1 and on_top[0]["name"] in baseline.values:
        # one value beyond the group's tolerance on top of it: the same backward step as for a value the one-value
        # search found (the value freed in the group's model, then without the group)
        nc = current_nc(baseline)
        located = freed_fit((ctx, baseline, on_top[0]["name"], np.concatenate([np.zeros(nc), baseline.x[nc:]])))
        if located is not None:
            located.structure = baseline.structure
        alone = value_without_group(ctx, prior_before, located, group_entry, lambda m: log(m, progress)) \
            if located is not None else None
        if alone is not None:
            baseline, group_entry = alone, None
            ctx.prior = prior = prior_before
            on_top, relaxed = relaxed_drift(ctx, baseline, lambda m: log(m, progress))
    if prior is not None and not chosen and on_top and group_entry is None and (results or weighed):
        # a drift taken as the answer (``weighed``) was weighed with its located value alone counted; every value
        # reported is a parameter of the answer, and the causes are weighed again against it whole
        named = cause_over_drift(ctx, relaxed, on_top, results or weighed, min_delta_bic)
        if named is not None:
            results = results or weighed
            extended = current = named
            chosen = list(named.causes or [named.cause])
            steps = [{"cause": chosen[-1], "gain": 1 - named.objective / baseline.objective,
                      "delta_bic": baseline.cause_bic - named.cause_bic, "cost": named.cost, "penalty": named.penalty,
                      "total_gain": 1 - named.objective / baseline.objective, "model": named.structure}]
            on_top, relaxed = relaxed_drift(ctx, named, lambda m: log(m, progress))
        elif getattr(relaxed, "cause_tie", None):  # a cause barely told from the drift: reported beside it
            said = {t["cause"] for t in relaxed.cause_tie}  # weighed whole, in the place of its entry as one value
            baseline.cause_ties = [t for t in getattr(baseline, "cause_ties", []) if t["cause"] not in said] + \
                relaxed.cause_tie
    if (prior is not None and not chosen and not on_top and group_entry is None and ctx.drift(baseline)
            and ctx.within_design(baseline) and baseline.boxed is not None and ctx.explained(baseline.boxed)):
        baseline = baseline.boxed  # ``none``: the model returned has every value within the tolerance
    cands = sorted(results.values(), key=lambda r: r.cause_bic)
    diag = Diagnosis(chosen[0] if chosen else "none", baseline, extended, cands, f, data, causes=chosen, steps=steps,
                     noise=floor, failed=failed)
    final = extended or baseline
    diag.tolerance = float(tolerance) if prior is not None else float("inf")
    diag.drift = ([group_entry] if group_entry else []) + on_top
    diag.baseline_drift = with_parallel(baseline.circuit, baseline.values, prior.design, ctx.drift(baseline)) \
        if prior is not None else []
    diag.drift_alternatives = list(getattr(final, "drift_alternatives", [])) + [
        a for d in on_top for a in d.pop("alternatives", [])]
    first = results.get(chosen[0]) if chosen else None
    if not chosen:  # a drift that explains the data, and the causes it is barely told from
        diag.cause_alternatives = list(getattr(baseline, "cause_ties", []))
    if first is not None:
        diag.cause_alternatives = [{"cause": r.cause, "delta_bic": float(r.cause_bic - first.cause_bic)} for r in cands
                                   if r is not first and r.cause not in chosen and "+" not in r.cause
                                   and abs(r.cause_bic - first.cause_bic) < CAUSE_TIE_DBIC]
        section_tie = section_tie + list(getattr(extended, "drift_tie", []))
        diag.cause_alternatives += [t for t in section_tie if t["cause"] not in
                                    {a["cause"] for a in diag.cause_alternatives}]
    if diag.drift:
        log("values beyond the design tolerance in the final model: "
             + ", ".join(f"{d['name']} {d['design']:.4g} -> {d['fitted']:.4g} (x{d['ratio']:.3g})" for d in diag.drift
                         if not d.get("group")),
             progress)
        for d in diag.drift:
            if d.get("parallel"):
                log(parallel_note(d), progress)
    final_errors = {n: e * weights[n] if n in weights else e for n, e in final.errors.items()}
    diag.unexplained = unexplained_bands(f, final_errors, floor["per_response"])
    # ``none`` is a finding only when the returned model fits (:mod:`.verdict`): else ``unexplained``, with where the
    # misfit sits, its shape and the best candidate tried
    diag.explained = explains(final.cost, floor["cost"], ())
    if not diag.explained:
        diag.misfit = misfit_sentence(f, final_errors, data, diag.unexplained, final.cost, floor["cost"])
        tried = [r for r in cands if r is not extended]
        diag.best_tried = min(tried, key=lambda r: r.cause_bic).cause if tried else ""
        if not chosen:
            diag.cause = "unexplained"
        log(("unexplained: " if not chosen else f"{', '.join(chosen)} leave{'s' if len(chosen) == 1 else ''} a misfit: ")
            + diag.misfit
            + (f" Best candidate tried: {diag.best_tried}." if diag.best_tried else ""), progress)
    diag.evidence = {
        "baseline_model": model.name,
        "localisation": localise(f, data, baseline.errors),
        "resonances": resonance_comparison(f, data, baseline.predicted),
        "bands_before": band_table(f, baseline.errors),
        "bands_after": band_table(f, extended.errors) if extended else [],
        "gain_per_response": ({n: 1 - float(np.mean(np.abs(extended.errors[n]) ** 2) / np.mean(np.abs(baseline.errors[n]) ** 2))
                               for n in data} if extended else {}),
        "criterion": (("" if prior is None else f"every fit penalised by a log-normal prior around the design values "
                       f"(tolerance {prior.tolerance:g}), BIC and gains on the penalised cost; ")
                      + f"forward selection by BIC: a cause is named if dBIC >= {min_delta_bic} and it removes at least "
                      f"{min_gain} (first cause) or {min_step_gain} (further causes) of the misfit above the noise "
                      f"floor; stop at {NOISE_MARGIN} x the noise floor"),
    }
    if extended is not None:
        diag.realisation = realise_extended(extended, configs, f)
    diag.wall_s = time.perf_counter() - t0
    log(f"causes: {', '.join(chosen) or 'none'} (gain {diag.gain:.3f}) in {diag.wall_s:.1f} s", progress)
    return diag


def _share(ctx: Context, current: FitResult, share: float) -> float:
    """The share of ``current``'s cost (penalised) a cause must remove: ``share`` of the misfit the noise does not
    account for (the data cost above :attr:`.context.Context.floor`), none for a model at the noise already.

    The share guards the BIC against a systematic misfit, on which every extra parameter gains a "very strong" BIC
    (the BIC's likelihood assumes white residuals at the misfit's level); at the noise floor the residuals are the
    noise's and the BIC alone decides, the evidence then lying in the prior's term (values off the design).
    """
    excess = max(0.0, current.cost - ctx.floor)
    return share * min(1.0, excess / current.objective) if current.objective > 0 else share



def _select(ctx: Context, baseline: FitResult, pool: dict[str, FitResult], results: dict[str, FitResult],
            variants_tried: dict[str, list[Effect]], failed: list[dict[str, Any]], min_delta_bic: float,
            min_gain: float, min_step_gain: float, max_causes: int
            ) -> tuple[FitResult, list[str], list[dict[str, Any]]]:
    """Forward selection by BIC from ``baseline`` over the candidates in ``pool``, then the backward check and the
    forms chosen again: the final model, the causes named and the steps (``failed`` gets the refused ones)."""
    progress, prior, weights = ctx.progress, ctx.prior, ctx.weights
    configs, f, data, fixed, impedance_scale = ctx.configs, ctx.f, ctx.data, ctx.fixed, ctx.scale
    pool = dict(pool)
    allowed = [c for c in pool if "+" not in c and c in results]  # the causes this selection may name
    current, chosen, steps, deferred = baseline, [], [], set()
    # forward selection measured each cause against the named ones in the forms they had then; a form chosen
    # again changes that model (a magnetising change in its causal form left a new section's share unseen, two-winding
    # magnetising change + missing section 500): the causes not named are measured once more against it
    for round_ in range(2):
        while pool and len(chosen) < max_causes:
            if ctx.settled(current):
                log("cost at the noise floor: no further cause", progress)
                break
            best = min(pool.values(), key=lambda r: r.cause_bic)
            need = _share(ctx, current, min_gain if not chosen else min_step_gain)
            # a model that reaches the noise only by moving values far off the design is no explanation: against it, a
            # candidate that reaches the noise within the design, or with fewer values far off (a value really off the
            # design stays off in every model), needs the BIC margin but no share of the cost
            # (the count not for a structural candidate: a new section frees the values of the section it touches
            # from the prior, so it has fewer values off the design by construction; a split is measured with its
            # halves merged back against the design's section, :meth:`.context.Context.drift`)
            structural = any(c in STRUCTURAL for c in best.causes)
            if ctx.distorted(current) and (ctx.explained(best) or (
                    not structural and best.objective <= NOISE_MARGIN * ctx.floor
                    and len(ctx.gross(best)) < len(ctx.gross(current)))):
                need = 0.0
            ref = getattr(best, "reference", current)  # an extension's gain: between converged fits (.causes.extend)
            if not significant(ref.cause_bic, ref.objective, best.cause_bic, best.objective, min_delta_bic, need):
                break
            new_causes = [c for c in best.causes if c not in chosen]
            new_cause = new_causes[-1] if any(c in STRUCTURAL for c in new_causes) and len(new_causes) > 1 else \
                new_causes[0]
            if new_cause in STRUCTURAL:
                if getattr(best, "from_design", False) and best.objective > UNMERGE_ABOVE_FLOOR * ctx.floor:
                    _refuse(pool, failed, best, new_cause, progress,
                            f"a split of the design values that stays {UNMERGE_ABOVE_FLOOR:g} x above the noise",
                            "a split of the design values with its couplings free, and the fit with it stays far above "
                            "the noise")
                    continue
                if not chosen and best.couplings and best.objective > UNMERGE_ABOVE_FLOOR * ctx.floor:
                    _refuse(pool, failed, best, new_cause, progress,
                            f"a first cause with free couplings that stays {UNMERGE_ABOVE_FLOOR:g} x above the noise",
                            "a new section with its couplings free named first, and the fit with it stays far above "
                            "the noise (free couplings take the share of a frequency-dependent effect)")
                    deferred.add(new_cause)  # not first: tried again once another cause is named
                    continue
                if (getattr(best, "merged_back", None) and best.objective > NOISE_MARGIN * STRUCTURAL_FLOOR * ctx.floor
                        and not missing_modes(f, data, current.predicted, ctx.resolved)):
                    _refuse(pool, failed, best, new_cause, progress,
                            "the model without it has every measured resonance and the split does not reach the noise",
                            "no measured resonance missing from the model without it, and the fit with it stays above "
                            "the noise")
                    continue
                # a pair (effect and section fitted together) is held out against the effect alone: the section must
                # add to it on points it was not fitted to (against the model before, the effect's share passes it)
                before = current
                alone = results.get(new_causes[0]) if len(new_causes) == 2 else None
                if alone is not None and alone.objective < current.objective:
                    before = alone
                try:
                    held, held_se = held_out_gain(before, best, configs, f, data, fixed, impedance_scale,
                                                  weights=weights, max_nfev=HOLDOUT_NFEV, prior=prior, noise=ctx.noise,
                                                  with_error=True)
                except _CANDIDATE_FAILURES:
                    held, held_se = -np.inf, 0.0
                # the share needed on the points left out as well, and the extension refused only when its gain there
                # is significantly below it (HELD_OUT_SE standard errors of the paired gain): with no share needed (a
                # model within the design against one that reaches the noise only with values far off, or a model at
                # the noise already) both fit to the noise, and their held-out costs differ by about one error
                bar = need - HELD_OUT_SE * held_se
                if held < bar:
                    log(f"{new_cause}: held-out gain {held:.3f} < {bar:.3f}: refused (fits the points it was fitted to "
                         "only)", progress)
                    failed.append({"cause": best.cause, "cost": best.cost,
                                   "reason": f"held-out gain {held:.3f} below {bar:.3f} (alternate points)"})
                    pool.pop(best.cause if best.cause in pool else new_cause)
                    deferred.add(new_cause)  # tried again once another cause is named: it may hold with it
                    if not chosen and len(new_causes) == 1:  # a section alone that takes an effect's share: with it
                        pool.update(section_pairs(ctx, results, baseline, have=pool))
                    continue
            for other in new_causes[:-1] if len(new_causes) > 1 else []:  # a pair: the effect named with the section
                steps.append({"cause": other, "joint": True, "gain": 1 - best.objective / ref.objective,
                              "delta_bic": ref.cause_bic - best.cause_bic, "cost": best.cost, "penalty": best.penalty,
                              "total_gain": 1 - best.objective / baseline.objective, "model": best.structure})
                chosen.append(other)
            new_cause = new_causes[-1]
            steps.append({"cause": new_cause, "gain": 1 - best.objective / ref.objective,
                          "delta_bic": ref.cause_bic - best.cause_bic, "cost": best.cost, "penalty": best.penalty,
                          "total_gain": 1 - best.objective / baseline.objective,
                          "model": best.structure + ("; " if best.structure and best.effects else "")
                          + ", ".join(e.label for e in best.effects)})
            chosen.append(new_cause)
            current = converged(ctx, best, lambda m: log(m, progress))
            log(f"step {len(chosen)}: {new_cause} (gain {steps[-1]['gain']:.3f}, dBIC {steps[-1]['delta_bic']:.1f})",
                 progress)
            remaining = [c for c in pool if c not in chosen and "+" not in c]
            remaining += sorted(c for c in deferred if c in results and c not in chosen and c not in remaining)
            deferred.clear()
            pool = {}
            if len(chosen) >= max_causes or ctx.settled(current):
                continue
            pool = extensions(ctx, current, remaining, results, variants_tried)

        # ---- backward check: a cause made redundant by those named after it is dropped
        if len(chosen) > 1:
            n_named = len(chosen)
            current, chosen, steps = _drop_redundant(ctx, current, chosen, steps, min_delta_bic, progress)
            if len(chosen) < n_named:  # the order forward selection gives the causes kept: by their single fits
                chosen.sort(key=lambda c: results[c].cause_bic if c in results else np.inf)
        swaps = []
        if chosen and current.effects and not ctx.settled(current):  # each cause's form against all the others
            current, swaps = rechoose_forms(ctx, current, min_delta_bic, _CANDIDATE_FAILURES,
                                            lambda m: log(m, progress))
            steps = steps + swaps
        if round_ or not swaps or len(chosen) >= max_causes or ctx.settled(current):
            break
        remaining = [c for c in allowed if c not in chosen]
        if not remaining:
            break
        log("forms chosen again: " + ", ".join(remaining) + " measured again against the model", progress)
        pool = extensions(ctx, current, remaining, results, variants_tried)
    return current, chosen, steps


# ============================================================================== fitting causes
#: Evaluations of each refit of the held-out check (:mod:`.holdout`): converged, so the check does not depend on
#: where a short refit stopped.
HOLDOUT_NFEV = 100


#: What a candidate's fit may raise when its parameters make the network degenerate (e.g. a node left with
#: only inductors): the candidate is dropped, the diagnosis goes on.
_CANDIDATE_FAILURES = CANDIDATE_FAILURES


def _polish_baseline(ctx: Context, baseline: FitResult, fits, progress: bool) -> FitResult:
    """Refit the baseline from each candidate's circuit values; keep the best baseline.

    Candidates of the same structure give their values; a section split from
    the nominal circuit (:mod:`.unmerge`) gives its values with the two
    sections merged back, so a split that only helped the fit out of a poor
    optimum of the baseline gains nothing.
    """
    best = baseline
    free = {n.lower() for n in baseline.values}
    jobs = []
    for r in sorted(fits, key=lambda r: r.objective):
        if getattr(r, "merged_back", None):  # a split fitted from the nominal: its two sections merged again
            jobs.append((ctx, baseline.circuit.with_values({n: v for n, v in r.merged_back.items() if n.lower() in free}),
                         200))
        elif not r.structure and _topology(r.circuit) == _topology(baseline.circuit):
            jobs.append((ctx, baseline.circuit.with_values(r.values), 80))
    for trial in shared_map(_baseline_refitted, jobs):  # shared with the helper process (:mod:`.cores`)
        if trial is not None and trial.objective < best.objective * (1 - 1e-6):
            best = trial
    if best is not baseline:
        best.wall_s += baseline.wall_s
        log(f"baseline refitted from a candidate's values: cost {baseline.cost:.4g} -> {best.cost:.4g}", progress)
    return best


def _drift_answer(ctx: Context, baseline: FitResult, group: tuple | None, results: dict[str, FitResult],
                  failed: list[dict[str, Any]], located_on: FitResult | None, search: bool,
                  structures: Callable[[float], None] = lambda bic: None
                  ) -> tuple[FitResult, dict[str, Any] | None, bool, FitResult | None]:
    """A group's drift, then one value off the design, weighed against every cause in ``results`` by BIC.

    A whole group of values off the design by one factor (:mod:`.group_drift`) is the answer when its BIC (the
    factor one parameter) is below every cause's and below that of one value off the design alone (the other
    description of a drift with one parameter: one resistance at 3x moves its group's mean beyond the tolerance
    too). Else, with causes fitted (``search``) and the baseline not explaining the data within the design
    (:meth:`.context.Context.within_design`), one value of the design really off (a capacitance doubled,
    :func:`.drift.located_drift`) is weighed the same way, the freed value one parameter; below them all it is the
    answer (drift, no cause), and no structure is sought for what it explains. ``failed`` gets the causes so set aside.

    A drift is taken as the answer on the best fit of every rival: when it is open (its model does not explain
    the data, or a new section's fit comes within ``DRIFT_MIN_DBIC`` of it), ``structures`` (the search of every
    section split, which adds its best to ``results``; it runs when no cause explains the data within the design
    with a BIC no higher than the drift's, given to it) runs first and the drift is weighed again.

    Returns
    -------
    tuple
        The baseline (the group's or the value's fit when one is the answer), the group's drift entry (or None),
        whether a drift is the answer, and the model the one-value search ran on (not run again on it).
    """
    progress = ctx.progress
    one = None
    # the lowest objective a cause reached: the one-value search seeks each value's best fit at least that hard
    rival = min((r.objective for r in results.values()), default=None)
    if group is not None and baseline is not located_on:
        # one value off the design is the other description of a drift with one parameter: a value 3x its design
        # moves its group's mean beyond the tolerance too, and the lower BIC of the two tells which it is
        one = located_drift(ctx, baseline, NOISE_MARGIN * ctx.floor, lambda m: log(m, progress), rival)
        located_on = baseline
        if one is not None and one.bic < group[0].bic:
            log(f"{group[2]['name']} x{group[2]['ratio']:.3g}: {one.freed} alone off the design has a BIC lower by "
                f"{group[0].bic - one.bic:.1f}: not the group", progress)
            group = None
    if group is not None:
        g_bic = group[0].bic + np.log(group[0].n_residuals)
        if _open(ctx, group[0], g_bic, results, group[1]):
            structures(g_bic)
        rival = min(results.values(), key=lambda r: r.cause_bic) if results else None
        if rival is None or g_bic < rival.cause_bic:
            log(f"{group[2]['name']} x{group[2]['ratio']:.3g}: BIC below every single cause's"
                + (f" ({rival.cause}: {rival.cause_bic - g_bic:.1f} higher)" if rival else "") + ": the group's drift "
                "explains the data, no cause", progress)
            ctx.prior = group[1]
            failed += [{"cause": c, "cost": r.cost, "reason": "the drift of a group explains the data with a lower BIC"}
                       for c, r in results.items()]
            group[0].cause_ties = ties(results, g_bic)
            return group[0], group[2], True, located_on
        log(f"{group[2]['name']} x{group[2]['ratio']:.3g}: {rival.cause} has a BIC lower by "
            f"{g_bic - rival.cause_bic:.1f}:"
            " not reported", progress)
    if ctx.prior is None or not search or not results or (ctx.explained(baseline) and ctx.within_design(baseline)):
        return baseline, None, False, located_on
    if baseline is not located_on:
        one = located_drift(ctx, baseline, NOISE_MARGIN * ctx.floor, lambda m: log(m, progress), rival)
    if one is None:
        return baseline, None, False, baseline
    o_bic = one.bic + np.log(one.n_residuals)
    if _open(ctx, one, o_bic, results):
        structures(o_bic)
    rival = min(results.values(), key=lambda r: r.cause_bic)
    if o_bic < rival.cause_bic:
        log(f"{one.freed} off the design: BIC below every single cause's ({rival.cause}: "
            f"{rival.cause_bic - o_bic:.1f} higher): the value's drift explains the data, no cause", progress)
        failed += [{"cause": c, "cost": r.cost, "reason": "the drift of one value explains the data with a lower BIC"}
                   for c, r in results.items()]
        one.cause_ties = ties(results, o_bic)
        return one, None, True, baseline
    log(f"{one.freed} off the design: {rival.cause} has a BIC lower by {o_bic - rival.cause_bic:.1f}: set aside",
        progress)
    one.answer_bic = float(o_bic)  # weighed again against the selection's answer (:func:`.causes.rivals.whole_answer`)
    ctx.drift_aside = one
    return baseline, None, False, baseline


#: Standard errors of the paired held-out gain below the share needed (:func:`_share`; zero at the noise) at which a
#: structural extension is refused (:func:`_select`): two, a one-sided test at about 2 %; two fits to the noise differ
#: on the points left out by about one standard error either way.
HELD_OUT_SE = 2.0


def _open(ctx: Context, drift: FitResult, bic: float, results: dict[str, FitResult],
          prior: DesignPrior | None = None) -> bool:
    """A drift answer (its fit and BIC with the drift's parameters counted) that the structures must be weighed
    against at their best: its model does not explain the data within the design (above the noise, or a value
    besides the drift's own beyond the tolerance: the group's under its ``prior``, the freed value not counted; the
    drift would then be of several values, each a parameter the answer's BIC did not count), or a new section's fit
    (a local optimum of a search that is not complete), refitted to convergence first (it replaces its entry in
    ``results``), comes within ``DRIFT_MIN_DBIC`` ("very strong") of it."""
    section = results.get("missing-section")
    if section is not None:
        # weighed at its own convergence, as the drift's fit is: a split's first fit stops after tens of evaluations
        section = results["missing-section"] = converged(ctx, section, lambda m: log(m, ctx.progress), structure=True)
    if section is not None and section.cause_bic - bic < DRIFT_MIN_DBIC:
        return True
    freed = str(getattr(drift, "freed", "")).lower()
    others = [d for d in ctx.drift(drift, prior) if d["name"].lower() != freed]
    return drift.objective > NOISE_MARGIN * ctx.floor or bool(others)


def _explained_within_design(ctx: Context, results: dict[str, FitResult], drift_bic: float = np.inf) -> bool:
    """The cause of ``results`` with the lowest BIC among those that fit to the noise floor
    (:meth:`.context.Context.explained`) needs no value beyond the tolerance
    (:meth:`.context.Context.within_design`), and a drift weighed against the causes (its BIC ``drift_bic``) is not
    below it: the data are explained within the design, and no structure is sought. A drift below it is the answer
    over that cause, and every structure is weighed against the drift first (a six-section winding, 0.52 % noise,
    section 5 split: the skin effect fits to the noise within the design, Cg6 x3.6 with two more values beyond the
    tolerance is lower in BIC, and the splits were not searched).

    A baseline at the noise whose values the data reject at the tolerance's edge leaves every cause at the noise
    too, each by the same values beyond it: such a cause explains nothing the baseline does not (a split of section 1
    of 8 answered as C1 x1.38: every cause "at the noise", the box rejected by 335 in BIC, the split search not
    run)."""
    fits = [r for r in results.values() if ctx.explained(r)]
    if not fits:
        return False
    best = min(fits, key=lambda r: r.cause_bic)
    return best.cause_bic <= drift_bic and ctx.within_design(best)


def _baseline_refitted(args: tuple[Context, Circuit, int]) -> FitResult | None:
    """The baseline (no effect) fitted from a candidate's circuit values (:func:`_polish_baseline`)."""
    ctx, circuit, nfev = args
    try:
        return ctx.fit(circuit).fit(max_nfev=nfev, tol=1e-8)
    except _CANDIDATE_FAILURES:
        return None


def _drop_redundant(ctx: Context, current: FitResult, chosen: list[str], steps: list[dict[str, Any]],
                    min_delta_bic: float, progress: bool) -> tuple[FitResult, list[str], list[dict[str, Any]]]:
    """Refit without each named effect in turn (:func:`_without_effect`); drop it when the BIC does not worsen by
    ``min_delta_bic``.

    Structural causes (a missing section) are kept. A core loss that added its resistor (the baseline had no core
    loop) is dropped with it.
    """
    changed = True
    while changed and len(current.effects) > 1:
        changed = False
        # the model without each effect, shared with the helper process (:mod:`.cores`); read in order, up to the
        # first effect dropped
        without = shared_map(_without_effect, [(ctx, current, j, min_delta_bic) for j in range(len(current.effects))])
        for j, (eff, res) in enumerate(zip(current.effects, without)):
            if eff.cause in STRUCTURAL or res is None:  # (None: the network degenerates without it: it stays)
                continue
            if res.bic - current.bic >= min_delta_bic:
                log(f"{eff.cause} kept: without it the BIC is higher by {res.bic - current.bic:.1f}", progress)
            else:
                res.structure = current.structure
                res.causes = [c for c in current.causes if c != eff.cause]
                res.cause = "+".join(res.causes)
                log(f"{eff.cause} dropped: redundant once {', '.join(res.causes)} are in the model "
                     f"(dBIC {current.bic - res.bic:.1f})", progress)
                steps = steps + [{"cause": eff.cause, "dropped": True, "delta_bic": current.bic - res.bic,
                                  "cost": res.cost, "gain": 1 - res.objective / current.objective}]
                chosen = [c for c in chosen if c != eff.cause]
                current = res
                changed = True
                break
    return current, chosen, steps


def _without_effect(args: tuple[Context, FitResult, int, float]) -> FitResult | None:
    """``current`` refitted without its effect ``j`` (:func:`_drop_redundant`); None for a structural cause or when
    the network degenerates. A core loss that added its resistor is removed with it.

    Warm-started; when that refit is worse than ``current`` by ``min_delta_bic`` or more, also from each remaining
    effect's start grid (the best of all is returned)."""
    ctx, current, j, min_delta_bic = args
    eff = current.effects[j]
    if eff.cause in STRUCTURAL:
        return None
    nc = current_nc(current)
    offsets = np.cumsum([0] + [len(e.parameters) for e in current.effects])
    circuit = current.fitted_circuit()
    if eff.cause == "core-loss" and circuit.has_element("Rcore") and not (
            ctx.nominal is not None and ctx.nominal.has_element("Rcore")):
        circuit = replace(circuit, elements=[e for e in circuit.elements if e.key != "rcore"])
    keep = [e for i, e in enumerate(current.effects) if i != j]
    tails = [list(current.x[nc + offsets[i]: nc + offsets[i + 1]]) for i in range(len(current.effects)) if i != j]
    try:
        fit = ctx.fit(circuit, keep, couplings=current.couplings)
        best = fit.fit(x0s=np.concatenate([np.zeros(fit.nc)] + tails)[None], grid=False, max_nfev=60, tol=1e-6)
    except _CANDIDATE_FAILURES:
        return None
    if best.bic - current.bic < min_delta_bic:
        return best
    # kept from the warm start: the others' parameters were fitted beside it and may sit where it was needed (a
    # skin effect's corner beside a core loss that took part of its rise). Each other effect from its start grid
    for k, eff_k in enumerate(keep):
        rows = [np.concatenate([np.zeros(fit.nc)] + tails[:k] + [t] + tails[k + 1:])
                for t in start_tails(ctx, fit, eff_k)]
        try:
            res = fit.fit(x0s=np.array(rows), grid=False, max_nfev=60, tol=1e-6, keep_starts=3)
        except _CANDIDATE_FAILURES:
            continue
        if res.objective < best.objective:
            best = res
    return best


def _topology(circuit: Circuit) -> list[tuple[str, str, tuple[str, ...]]]:
    """Element names, kinds and nodes (values left out)."""
    return [(e.name.lower(), e.kind, tuple(e.nodes)) for e in circuit.elements]


def load_baseline(model_name: str | None) -> Model | None:
    return get_model(model_name) if model_name else None
