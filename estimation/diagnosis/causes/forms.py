"""Each named cause's form and group chosen again once every cause is named.

Forward selection picks a cause's form and group when it is added, against
the causes named before it; the causes named after it may make another form
of it fit better (a level or a loss that one form of the first cause took
while the second was missing). Each named cause is tried in every other
form and group of the catalogue, with the other causes' parameters and the
circuit values kept (a screening fit of the effects' parameters only); the
best variant is then fitted in full and replaces the named one only if the
BIC improves. A special case of the named form (one relaxation time of a
distribution) is not tried: it screens as well as the named form and would
keep every other form from its full fit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from estimation.diagnosis.causes.catalogue import Effect, effect_variants, winding_groups
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import FitResult, configuration_ports, group_names

#: Screening: local fits (of the effects' parameters) per variant, and their evaluations.
SCREEN_STARTS = 2
SCREEN_NFEV = 20
#: Evaluations of the full fit of the best screened variant.
FULL_NFEV = 40


def _form_screened(args: tuple) -> tuple[Any, FitResult | None]:
    """Effect ``j`` of ``current`` in form ``v``, its parameters alone fitted from their grid (:func:`rechoose_forms`);
    ``(None, None)`` when the fit fails."""
    ctx, circuit, current, j, v, eff, tails, failures = args
    effects = _swapped(current.effects, j, v)
    try:
        fit = ctx.fit(circuit, effects, couplings=current.couplings)
        grid = _grid(v, eff, tails[j])
        x0s = np.array([np.concatenate([np.zeros(fit.nc)] + [t for t in tails[:j]] + [g]
                                       + [t for t in tails[j + 1:]]) for g in grid])
        return fit, fit.fit(x0s=x0s, grid=False, circuit_free=False, max_nfev=SCREEN_NFEV, keep_starts=SCREEN_STARTS)
    except failures:
        return None, None


def rechoose_forms(ctx: Any, current: FitResult, min_delta_bic: float, failures: tuple[type[Exception], ...],
                   log: Callable[[str], None]) -> tuple[FitResult, list[dict[str, Any]]]:
    """``current`` with each named effect's form and group chosen again (kept unless the BIC improves).

    Parameters
    ----------
    ctx : diagnosis context
        Gives ``fit(circuit, effects, couplings=...)``, ``f``, ``configs``, ``one_port``, ``scale`` and
        ``prior`` (free levels with a design prior, see :mod:`.catalogue`).
    current : FitResult
        The model after forward selection.
    min_delta_bic : float
        BIC improvement a swap needs.
    failures : tuple of exception types
        What a candidate's fit may raise (the candidate is skipped).
    log : callable
        Progress messages.

    Returns
    -------
    FitResult
        The model with the forms kept or swapped.
    list of dict
        One step per swap: ``cause``, ``"reformed": True``, ``model`` (the new form's label), ``delta_bic``,
        ``cost``, ``gain`` (of the cost before the swap).
    """
    f = ctx.f
    swaps: list[dict[str, Any]] = []
    for j in range(len(current.effects)):
        eff = current.effects[j]
        if eff.cause == "missing-section" or not eff.parameters:
            continue
        circuit = current.fitted_circuit()
        groups = winding_groups(circuit, configuration_ports(ctx.configs), group_names(ctx.configs))
        variants = [v for v in effect_variants(eff.cause, groups, circuit, float(f[0]), ctx.one_port, ctx.scale,
                                               float(f[-1]), level=ctx.prior is not None)
                    if v.label != eff.label and not v.nested_in(eff)]  # a special case screens as well as the named
        nc = _nc(current)
        offsets = np.cumsum([0] + [len(e.parameters) for e in current.effects])
        tails = [list(current.x[nc + offsets[i]: nc + offsets[i + 1]]) for i in range(len(current.effects))]
        # the other forms screened, shared with the helper process (:mod:`.cores`)
        done = shared_map(_form_screened, [(ctx, circuit, current, j, v, eff, tails, failures) for v in variants])
        screened = [(pre.objective, v, fit, pre) for v, (fit, pre) in zip(variants, done) if pre is not None]
        if not screened:
            continue
        _, v, fit, pre = min(screened, key=lambda t: t[0])
        try:
            res = fit.fit(x0s=pre.x[None], grid=False, keep_starts=1, max_nfev=FULL_NFEV, tol=1e-6)
        except failures:
            continue
        if current.bic - res.bic >= min_delta_bic:
            log(f"{eff.label} -> {v.label}: cost {current.cost:.4g} -> {res.cost:.4g}, "
                f"dBIC {current.bic - res.bic:.1f}")
            res.structure, res.causes, res.cause = current.structure, list(current.causes), current.cause
            swaps.append({"cause": eff.cause, "reformed": True, "model": v.label, "delta_bic": current.bic - res.bic,
                          "cost": res.cost, "gain": 1 - res.objective / current.objective})
            current = res
        else:
            log(f"{eff.label} kept (best other form {v.label}: dBIC {current.bic - res.bic:.1f})")
    return current, swaps


def _nc(r: FitResult) -> int:
    """Number of circuit values in ``r.x`` (the rest are the effects' parameters)."""
    return r.x.size - sum(len(e.parameters) for e in r.effects)


def _swapped(effects: Sequence[Effect], j: int, v: Effect) -> list[Effect]:
    return [v if i == j else e for i, e in enumerate(effects)]


def _grid(v: Effect, named: Effect, named_x: Sequence[float]) -> list[np.ndarray]:
    """Starts of ``v``'s parameters (log-scaled where the parameter is): the named effect's fitted values where
    ``v`` has a parameter of the same name and meaning (same form), then ``v``'s own start grid."""
    axes = [[np.log(s) if p.log else s for s in (p.starts or (np.sqrt(p.lower * p.upper),))] for p in v.parameters]
    mesh = np.meshgrid(*axes, indexing="ij")
    grid = [np.array([m.flat[i] for m in mesh]) for i in range(mesh[0].size)]
    if v.form == named.form:  # another group: the same parameters
        lo = np.array([np.log(p.lower) if p.log else p.lower for p in v.parameters])
        hi = np.array([np.log(p.upper) if p.log else p.upper for p in v.parameters])
        grid.insert(0, np.clip(np.asarray(named_x, float), lo, hi))
    elif v.cause == "core-loss":  # every form shares a and b; the relaxation from one relaxation time
        ab = np.asarray(named_x, float)[:2]
        grid.insert(0, np.concatenate([ab, [1.0]]) if v.form == "relaxation" else ab)
    return grid
