"""A named model extended by one more cause: each cause's forms screened, fitted and converged against it.

The forward selection (:func:`.diagnose._select`) measures each cause not
yet named by how much it adds to the model with the causes named so far.
Every form of the cause is screened beside the model, the best few fitted in
full, and each converged before the forms are compared; the model itself is
converged as the reference the gain is measured against.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from pris_cosim.circuits.circuit import Circuit

from estimation.diagnosis.causes.catalogue import Effect
from estimation.diagnosis.causes.section_fits import fit_missing_section
from estimation.diagnosis.causes.single import start_tails
from estimation.diagnosis.context import Context, log
from estimation.diagnosis.converge import converged
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import CANDIDATE_FAILURES, FitResult, FrequencyFit, current_nc


def extensions(ctx: Context, current: FitResult, causes: Sequence[str], results: dict[str, FitResult],
                variants_tried: dict[str, list[Effect]]) -> dict[str, FitResult]:
    """Each of ``causes`` fitted together with ``current`` (:func:`_extend`): the fits that lower the objective.

    A cause's gain is measured between converged fits: each extension and ``current`` itself are refitted to
    convergence (:func:`.converge.converged`), and the extension keeps the converged ``current`` as its
    ``reference``. An extension stopped after tens of evaluations shows less than it holds (a skin effect after a
    split: 2.1 in BIC at 50 evaluations, 15.8 with both converged), and one converged against a model that is not
    shows more."""
    pool = {}
    # independent fits, shared with the helper process (:mod:`.cores`; the batches within each run where it runs)
    jobs = [(ctx, current, cause, results[cause], variants_tried.get(cause, [])) for cause in causes]
    fitted = shared_map(_extension_fitted, jobs + [(ctx, current, None, None, [])])
    reference = fitted.pop()[0]
    for cause, (res, seconds) in zip(causes, fitted):
        if res is None or res.objective >= reference.objective:
            continue
        res.reference = reference
        pool[cause] = res
        log(f"  + {cause}: cost {res.cost:.4g}, gain {1 - res.objective / reference.objective:.3f}, "
             f"dBIC {reference.cause_bic - res.cause_bic:.1f} ({seconds:.1f} s)", ctx.progress)
    return pool


def _extension_fitted(args: tuple[Context, FitResult, str, FitResult, list[Effect]]
                      ) -> tuple[FitResult | None, float]:
    """``current`` plus one cause (:func:`_extend`), refitted to convergence, and the seconds it took
    (:func:`extensions`); with no cause, ``current`` itself refitted to convergence."""
    ctx, current, cause, single, variants = args
    t = time.perf_counter()
    if cause is None:
        return converged(ctx, current, structure=True), time.perf_counter() - t
    return _extend(ctx, current, cause, single, variants), time.perf_counter() - t


def _extend(ctx: Context, current: FitResult, cause: str, single: FitResult, variants: Sequence[Effect]
            ) -> FitResult | None:
    """``current`` plus ``cause``, warm-started from ``current`` and from the cause's own single fit.

    Every form and group in ``variants`` is screened against ``current`` (:func:`_extension_screened`); the single
    fit's form and the ``EXTEND_FORMS`` best others are then fitted in full. With more forms than that, the others
    are ranked by a short fit with the circuit values free (``RANK_NFEV`` evaluations from each screened start): the
    order of the forms on the baseline says little once other causes are named (beside a lamination core loss a skin
    effect on every winding fitted to the noise, while on the baseline it ranked fifth of nine), and with the
    circuit values held a form hardly moves from the current model, whose values took the effect's share.
    """
    if cause == "missing-section":
        return fit_missing_section(ctx, current, current.effects, must_beat=current.objective)
    circuit = current.fitted_circuit()
    own = single.effects[0]
    starts = {}
    for eff in [own] + [v for v in variants if v.label != own.label]:
        fit, pres = _extension_screened(ctx, current, circuit, eff, single if eff is own else None)
        if pres:
            starts[eff.label] = (fit, pres)
    others = [lab for lab in starts if lab != own.label]
    if len(others) > EXTEND_FORMS:
        rank = {}
        for lab in others:
            fit, pres = starts[lab]
            short = []
            for pre in pres:
                try:
                    short.append(fit.fit(x0s=pre.x[None], grid=False, keep_starts=1, max_nfev=RANK_NFEV, tol=1e-6))
                except CANDIDATE_FAILURES:
                    continue
            if short:
                starts[lab], rank[lab] = (fit, short), min(r.objective for r in short)
        others = sorted(rank, key=rank.get)
    best = None
    for label in ([own.label] if own.label in starts else []) + others[:EXTEND_FORMS]:
        fit, pres = starts[label]
        form = None
        for pre in pres:
            try:
                res = fit.fit(x0s=pre.x[None], grid=False, keep_starts=1, max_nfev=50, must_beat=current.objective,
                              tol=1e-6)
            except CANDIDATE_FAILURES:
                continue
            res.structure = current.structure
            res.causes = list(current.causes) + [cause]
            res.cause = "+".join(res.causes)
            if form is None or res.bic < form.bic:
                form = res
        if form is not None:  # each form converged before the forms are compared (they differ after tens of steps)
            form = converged(ctx, form, structure=True)
            if best is None or form.bic < best.bic:  # forms differ in their parameter counts
                best = form
    return best


#: Forms of a cause fitted in full when it extends a model, besides its single fit's form, and the evaluations of
#: the short fits that rank them when there are more (:func:`_extend`).
EXTEND_FORMS = 2
RANK_NFEV = 10


def _extension_screened(ctx: Context, current: FitResult, circuit: Circuit, eff: Effect, single: FitResult | None
                        ) -> tuple[FrequencyFit | None, list[FitResult]]:
    """``eff``'s parameters alone fitted beside ``current``'s effects (:func:`_extend`): the fit and the screened
    results (from the current values and, with a design prior, from the design values: the current values absorbed
    what the named causes left, the design values did not). ``single``: the cause's single fit, whose parameters
    are one more start."""
    cur_tail = list(current.x[current_nc(current):])
    try:
        fit = ctx.fit(circuit, list(current.effects) + [eff], couplings=current.couplings)
    except CANDIDATE_FAILURES:
        return None, []
    tails = start_tails(ctx, fit, eff)
    if single is not None:
        tails.insert(0, list(single.x[current_nc(single):]))
    pres = []
    for circ in [np.zeros(fit.nc)] + ([dx] if (dx := _design_x(ctx, fit)) is not None else []):
        x0s = np.array([list(circ) + cur_tail + t for t in tails])
        try:
            pres.append(fit.fit(x0s=x0s, grid=False, circuit_free=False, max_nfev=40, keep_starts=2))
        except CANDIDATE_FAILURES:
            continue
    return fit, pres


def _design_x(ctx: Context, fit: FrequencyFit) -> np.ndarray | None:
    """The circuit part of ``fit``'s parameter vector at the design values (``None`` without a design prior).

    Values the prior does not anchor (elements of a changed section, added elements) keep their start.
    """
    if ctx.prior is None:
        return None
    anchored = ctx.prior.anchored(fit.circuit)
    x = np.zeros(fit.nc)
    for i, n in enumerate(fit.free):
        d = ctx.prior.design.get(n.lower())
        if d and n.lower() in anchored and fit.start[i] > 0:
            x[i] = np.log(d / fit.start[i])
    if not np.any(x):
        return None
    lo, hi = fit.bounds()
    return np.clip(x, lo[: fit.nc] + 1e-9, hi[: fit.nc] - 1e-9)
