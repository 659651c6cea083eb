"""Drift of a whole group: every value of one role (all capacitances to ground, say) off the design by one factor.

A design can be wrong by one factor over a group of values: the insulation's
permittivity over every capacitance to ground, the turns' length over every
resistance. Under the per-value log-normal prior (:mod:`.prior`) such a change
is pulled back value by value, and the fit spreads it over the other values,
or a new section (whose values carry no prior) takes it. Here each group is
given one common factor ``s``: the prior of its members is centred on
``s x design`` instead of the design (``sqrt(s) x design`` for a capacitance
in parallel with another, :func:`member_shares`), and ``s`` is fitted with the values
(alternately: ``ln s`` is the mean of the members' ``ln(v/d)``, the optimum of
the prior's term for fixed values, and the values are refitted around it).

The factor is one parameter more. A group is reported as drift when, by the
same criteria as a cause and a single drifted value:

* the model with the factor is preferred to the model without it by BIC
  (one parameter more): of two descriptions of the same drift, one factor or
  the values moved one by one under their priors, the better one, and
* the data reject the factor at the tolerance's edge, by the test a single
  value's drift passes (:func:`.drift.relaxed_drift`): the members' own prior
  left out, the members fitted freely; then their common factor held at the
  edge (``1 + tolerance`` or its inverse), each member keeping its ratio to
  that factor, and the other values refitted: the fit must lose
  ``DRIFT_MIN_DBIC``, the hold counted as one parameter. (Held at the edge
  with each member's prior centred there instead, the members reach
  ``(1 + tolerance)^2`` within one tolerance each, and a group 1.5x off
  passes for one within it), and
* the model with the factor explains the data (:mod:`.verdict`): a group
  moved is sought as the explanation of a misfit, not as a share of one.

Groups: capacitances to ground, series capacitances, inductances and
resistances, each of at least ``MIN_MEMBERS`` values the prior anchors.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import GROUND

from estimation.diagnosis.baseline import fit_multistart
from estimation.diagnosis.context import NOISE_MARGIN
from estimation.diagnosis.drift import DRIFT_MIN_DBIC, freed_fit, parallel_partners
from estimation.diagnosis.fit import CANDIDATE_FAILURES, FitResult, configuration_ports, current_nc
from estimation.diagnosis.prior import DesignPrior

#: A group has at least this many values: with two, a common factor is one value's drift and its neighbour's.
MIN_MEMBERS = 3
#: Alternations of the factor and the values (the factor moves less than 1 % by the third on the cases tried).
ITERATIONS = 4

ROLES = {"Cg": "capacitances to ground", "Cs": "series capacitances", "L": "inductances", "R": "resistances"}


def value_groups(prior: DesignPrior, circuit: Any, ports: Sequence[str] = ()) -> dict[str, list[str]]:
    """The groups of anchored values by role (:data:`ROLES`), each with at least ``MIN_MEMBERS`` members.

    A capacitance is a series capacitance when it is one of a winding section's (:func:`.sections.find_chains` from
    ``ports``), else a capacitance to ground when one of its ends is ground. The series capacitance of a section
    that ends at ground is in parallel with that node's capacitance to ground (the data see their sum): it is in
    the group of the capacitances to ground, and the group's drift entry names it under ``in_parallel``.
    """
    from estimation.diagnosis.causes.sections import find_chains

    anchored = prior.anchored(circuit)
    series = set()
    try:
        for ch in find_chains(circuit, ports):
            series |= {c.lower() for sec in ch.sections for c in sec.series_caps}
    except (ValueError, KeyError, StopIteration):
        pass
    out: dict[str, list[str]] = {k: [] for k in ROLES}
    for e in circuit.elements:
        key = e.name.lower()
        if key not in anchored or e.kind not in "RLC":
            continue
        role = ("Cs" if key in series or GROUND not in e.nodes else "Cg") if e.kind == "C" else e.kind
        out[role].append(e.name)
    return {k: v for k, v in out.items() if len(v) >= MIN_MEMBERS}


def rescaled(prior: DesignPrior, shares: Mapping[str, float], s: float) -> DesignPrior:
    """``prior`` with the design of each member of ``shares`` multiplied by ``s`` to the member's power (one, or
    one half for a capacitance in parallel with another, :func:`member_shares`)."""
    power = {m.lower(): p for m, p in shares.items()}
    return replace(prior, design={k: v * s ** power[k] if k in power else v for k, v in prior.design.items()})


def member_shares(circuit: Any, members: Sequence[str]) -> dict[str, float]:
    """The power of the group's factor each member's prior is centred on.

    A capacitance that shares both nodes with another (the series capacitance of a section ending at ground beside
    that node's capacitance to ground) is one value with it to the data, and which of the two moved with the group
    is not known: their sum moved by a factor between one and the group's. Their priors are centred halfway, on
    the square root of the group's factor (within one tolerance of either end for a group up to ``(1 + tolerance)^2``
    off); every other member on the factor itself. With fewer than two members without such a partner, every member
    counts fully.
    """
    shared = {m for m in members if parallel_partners(circuit, m)}
    if len(members) - len(shared) < 2:
        shared = set()
    return {m: 0.5 if m in shared else 1.0 for m in members}


def _refit(ctx: Any, r: FitResult, prior: DesignPrior, nfev: int = 40) -> FitResult:
    fit = ctx.fit(r.fitted_circuit(), r.effects, prior=prior, couplings=r.couplings)
    return fit.fit(x0s=np.concatenate([np.zeros(fit.nc), r.x[current_nc(r):]])[None], grid=False, max_nfev=nfev,
                   tol=1e-7)


def _scanned_start(ctx: Any, r: FitResult, shares: Mapping[str, float]) -> tuple[FitResult, float] | None:
    """The design values with the group scaled by the factor of ``SCAN`` whose response fits best (no fit: one batch
    of predictions), fitted locally under the prior centred there; None when the network degenerates.

    A fit that absorbed the group's change in other values sits in another basin, which a refit from it keeps: the
    scan starts from the design, where the group's factor is the only change. A factor beyond the tolerance is fitted
    as the baseline is (:func:`.baseline.fit_multistart`: random starts around it and modes moved onto the misfit).
    """
    fit = ctx.fit(r.fitted_circuit(), r.effects, prior=ctx.prior, couplings=r.couplings)
    x0 = fit.design_vector(np.concatenate([np.zeros(fit.nc), r.x[current_nc(r):]]))
    cols = [fit.free.index(m) for m in shares if m in fit.free]
    power = np.array([shares[m] for m in shares if m in fit.free])
    X = np.repeat(x0[None], SCAN.size, axis=0)
    X[:, cols] += np.log(SCAN)[:, None] * power[None, :]
    res = fit.residuals_batch(X)[:, : 2 * ctx.f.size * len(ctx.data)]
    k = int(np.argmin(np.sum(res * res, axis=1)))
    s = float(SCAN[k])
    scaled = ctx.fit(r.fitted_circuit(), r.effects, prior=rescaled(ctx.prior, shares, s), couplings=r.couplings)
    if abs(np.log(s)) <= ctx.prior.tau:  # a group within the tolerance is no drift: one local fit is enough
        return scaled.fit_continued(X[k], max_nfev=100), s  # through smoothed errors, as the baseline's own fit
    # a group that may be the answer gets the baseline's own effort: a winding whose every resonance moved (every
    # capacitance to ground x1.7) is a rough landscape, where one fit from the scaled design values ends near or far
    # from the optimum as the path goes (from 1.5, 1.84 or 2 times the design: 300, 0.8 or 300 times the noise)
    return fit_multistart(scaled, x0=X[k], max_nfev=100, good_enough=NOISE_MARGIN * ctx.floor, floor=ctx.floor), s


#: Factors of the group scanned from the design values (:func:`_scanned_start`).
SCAN = np.exp(np.linspace(np.log(0.4), np.log(2.5), 25))


def _factor_fit(ctx: Any, r: FitResult, shares: Mapping[str, float]) -> tuple[FitResult, float]:
    """The fit with the group's common factor free (alternating), and the factor: the geometric mean of the ratios
    to the design of the members that count fully (:func:`member_shares`: a node's two capacitances to ground are
    one value to the data, and the factor of their sum is not the group's when only one of them moved)."""
    basis = [m for m, p in shares.items() if p == 1.0]
    design = ctx.prior.design
    cur, ln_s = r, 0.0
    try:
        scanned = _scanned_start(ctx, r, shares)
    except CANDIDATE_FAILURES:
        scanned = None
    if scanned is not None and scanned[0].objective < r.objective:
        cur, ln_s = scanned[0], float(np.log(scanned[1]))
    for _ in range(ITERATIONS):
        new = float(np.mean([np.log(cur.values[m] / design[m.lower()]) for m in basis]))
        if abs(new - ln_s) < 0.01:
            break
        ln_s = new
        cur = _refit(ctx, cur, rescaled(ctx.prior, shares, float(np.exp(ln_s))))
    return cur, float(np.exp(ln_s))


def _edge_dbic(ctx: Any, fitted: FitResult, shares: Mapping[str, float]) -> float:
    """How much worse (BIC) the fit gets with the group's common factor held at the tolerance's edge.

    The members' own prior is left out of both fits (as a single value's is in :func:`.drift.relaxed_drift`): the
    members are first fitted freely, then scaled together so that their factor (the geometric mean of the ratios of
    the members that count fully) sits at the edge on its side, held there, and the other values refitted. The hold counts as one
    parameter (the factor), so the difference is ``N ln(RSS_held / RSS_free) - ln N``; ``-inf`` when the freed
    members' factor is back within the tolerance.
    """
    members = list(shares)
    basis = [m for m, p in shares.items() if p == 1.0]
    names = {m.lower() for m in members}
    design = ctx.prior.design
    loose = replace(ctx.prior, design={k: v for k, v in design.items() if k not in names})
    free = _refit(ctx, fitted, loose, nfev=60)
    ln_s = float(np.mean([np.log(free.values[m] / design[m.lower()]) for m in basis]))
    if abs(ln_s) <= ctx.prior.tau:
        return -np.inf
    shift = float(np.exp(np.copysign(ctx.prior.tau, ln_s) - ln_s))
    held_circuit = free.fitted_circuit().with_values({m: free.values[m] * shift ** shares[m] for m in members})
    fit = ctx.fit(held_circuit, free.effects, fixed=members, prior=loose, couplings=free.couplings)
    held = fit.fit(x0s=np.concatenate([np.zeros(fit.nc), free.x[current_nc(free):]])[None], grid=False, max_nfev=60,
                   tol=1e-6)
    return float(held.bic - free.bic + (len(members) - 1) * np.log(free.n_residuals))


def group_drift(ctx: Any, r: FitResult, log: Callable[[str], None], tried: list[FitResult] | None = None
                ) -> tuple[FitResult, DesignPrior, dict] | None:
    """The group whose common factor explains the data, if any (the module docstring's criteria).

    ``tried`` (if given) gets every group's fit with its factor: started from the design values scaled, such a fit
    may find a better optimum of the baseline's own model than its fit did (a factor within the tolerance that
    fits far better), which the caller can adopt.

    Returns
    -------
    tuple or None
        ``(fit, prior, entry)``: the fit with the factor, the prior centred on the group's factor, and the drift
        entry (``name``, ``members``, ``design`` 1, ``fitted`` and ``ratio`` the factor, ``sigmas``, ``delta_bic``
        against the model without the factor, ``edge_delta_bic`` at the tolerance's edge).
    """
    if ctx.prior is None:
        return None
    best = None
    for role, members in value_groups(ctx.prior, r.circuit, configuration_ports(ctx.configs)).items():
        shares = member_shares(r.circuit, members)
        shared = [m for m in members if parallel_partners(r.circuit, m)]
        try:
            fitted, s = _factor_fit(ctx, r, shares)
        except CANDIDATE_FAILURES:
            continue
        if tried is not None:
            tried.append(fitted)
        dbic = r.bic - (fitted.bic + np.log(fitted.n_residuals))  # one parameter more: the factor
        if abs(np.log(s)) <= ctx.prior.tau or dbic <= 0 or ctx.unfit(fitted):
            log(f"{ROLES[role]} x{s:.3g} together: dBIC {dbic:.1f}, cost {fitted.cost:.4g}: not kept")
            continue
        edge = float(np.exp(np.copysign(ctx.prior.tau, np.log(s))))
        try:
            edge_dbic = _edge_dbic(ctx, fitted, shares)
        except CANDIDATE_FAILURES:
            continue
        if edge_dbic < DRIFT_MIN_DBIC:
            log(f"{ROLES[role]} x{s:.3g} together: at the tolerance's edge x{edge:.3g} the BIC is only "
                f"{edge_dbic:.1f} higher: not kept")
            continue
        entry = {"name": f"{role} (all {ROLES[role]})", "members": list(members), "design": 1.0, "fitted": s,
                 "in_parallel": shared,
                 "ratio": s, "sigmas": float(abs(np.log(s)) / ctx.prior.tau), "delta_bic": float(dbic),
                 "edge_delta_bic": edge_dbic, "group": True}
        log(f"{ROLES[role]} x{s:.3g} together explain the data: cost {r.cost:.4g} -> {fitted.cost:.4g}, dBIC "
            f"{dbic:.1f}, {edge_dbic:.1f} at the tolerance's edge")
        if best is None or fitted.bic < best[0].bic:
            best = (fitted, rescaled(ctx.prior, shares, s), entry)
    return best


def value_without_group(ctx: Any, prior: DesignPrior, located: FitResult, entry: dict,
                        log: Callable[[str], None]) -> FitResult | None:
    """The backward step of a group once one value is found off the design on top of it.

    ``located`` (the group's model, the value ``located.freed`` freed, the
    others' prior centred on the group's factor ``entry``) is refitted from
    its own values under ``prior`` (the design's, the group dropped), the
    same value freed. A group of six capacitances to ground at x1.32 with one
    of them at x2.1 on top is one capacitance off the design when this fit's
    BIC is no higher than the group's with its factor counted (one parameter
    more, ``ln N``).

    Returns
    -------
    FitResult or None
        The refitted model (``freed`` set, ``structure`` kept) when the value alone is the answer, else None.
    """
    nc = current_nc(located)
    alone = freed_fit((replace(ctx, prior=prior), located, located.freed,
                       np.concatenate([np.zeros(nc), located.x[nc:]])))
    g_bic = located.bic + np.log(located.n_residuals)
    if alone is None or alone.bic > g_bic:
        return None
    log(f"{located.freed} alone off the design: BIC {g_bic - alone.bic:.1f} below {entry['name']} "
        f"x{entry['ratio']:.3g} with it: not the group")
    alone.structure = located.structure
    return alone
