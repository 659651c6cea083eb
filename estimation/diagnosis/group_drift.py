"""Drift of a whole group: every value of one role (all capacitances to ground, say) off the design by one factor.

A design can be wrong by one factor over a group of values: the insulation's
permittivity over every capacitance to ground, the turns' length over every
resistance. Under the per-value log-normal prior (:mod:`.prior`) such a change
is pulled back value by value, and the fit spreads it over the other values,
or a new section (whose values carry no prior) takes it. Here each group is
given one common factor ``s``: the prior of its members is centred on
``s x design`` instead of the design, and ``s`` is fitted with the values
(alternately: ``ln s`` is the mean of the members' ``ln(v/d)``, the optimum of
the prior's term for fixed values, and the values are refitted around it).

The factor is one parameter more. A group is reported as drift when, by the
same criteria as a cause and a single drifted value:

* the model with the factor beats the model without it by ``DRIFT_MIN_DBIC``
  in BIC (one parameter more), and
* the data reject the factor at the tolerance's edge: held there
  (``s = 1 + tolerance`` or its inverse, the values refitted) the fit loses
  ``DRIFT_MIN_DBIC`` too, and
* the model with the factor explains the data (:mod:`.verdict`): a group
  moved is sought as the explanation of a misfit, not as a share of one.

Groups: capacitances to ground, series capacitances, inductances and
resistances, each of at least ``MIN_MEMBERS`` values the prior anchors.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import GROUND

from estimation.diagnosis.drift import DRIFT_MIN_DBIC
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


def rescaled(prior: DesignPrior, members: list[str], s: float) -> DesignPrior:
    """``prior`` with the design of ``members`` multiplied by ``s``."""
    names = {m.lower() for m in members}
    return replace(prior, design={k: v * s if k in names else v for k, v in prior.design.items()})


def _refit(ctx: Any, r: FitResult, prior: DesignPrior, nfev: int = 40) -> FitResult:
    fit = ctx.fit(r.fitted_circuit(), r.effects, prior=prior, couplings=r.couplings)
    return fit.fit(x0s=np.concatenate([np.zeros(fit.nc), r.x[current_nc(r):]])[None], grid=False, max_nfev=nfev,
                   tol=1e-7)


def _scanned_start(ctx: Any, r: FitResult, members: list[str]) -> tuple[FitResult, float] | None:
    """The design values with the group scaled by the factor of ``SCAN`` whose response fits best (no fit: one batch
    of predictions), fitted locally under the prior centred there; None when the network degenerates.

    A fit that absorbed the group's change in other values sits in another basin, which a refit from it keeps: the
    scan starts from the design, where the group's factor is the only change."""
    fit = ctx.fit(r.fitted_circuit(), r.effects, prior=ctx.prior, couplings=r.couplings)
    x0 = fit.design_vector(np.concatenate([np.zeros(fit.nc), r.x[current_nc(r):]]))
    cols = [fit.free.index(m) for m in members if m in fit.free]
    X = np.repeat(x0[None], SCAN.size, axis=0)
    X[:, cols] += np.log(SCAN)[:, None]
    res = fit.residuals_batch(X)[:, : 2 * ctx.f.size * len(ctx.data)]
    k = int(np.argmin(np.sum(res * res, axis=1)))
    s = float(SCAN[k])
    scaled = ctx.fit(r.fitted_circuit(), r.effects, prior=rescaled(ctx.prior, members, s), couplings=r.couplings)
    return scaled.fit_continued(X[k], max_nfev=100), s  # through smoothed errors, as the baseline's own fit


#: Factors of the group scanned from the design values (:func:`_scanned_start`).
SCAN = np.exp(np.linspace(np.log(0.4), np.log(2.5), 25))


def _factor_fit(ctx: Any, r: FitResult, members: list[str]) -> tuple[FitResult, float]:
    """The fit with the group's common factor free (alternating), and the factor."""
    design = ctx.prior.design
    cur, ln_s = r, 0.0
    try:
        scanned = _scanned_start(ctx, r, members)
    except CANDIDATE_FAILURES:
        scanned = None
    if scanned is not None and scanned[0].objective < r.objective:
        cur, ln_s = scanned[0], float(np.log(scanned[1]))
    for _ in range(ITERATIONS):
        new = float(np.mean([np.log(cur.values[m] / design[m.lower()]) for m in members]))
        if abs(new - ln_s) < 0.01:
            break
        ln_s = new
        cur = _refit(ctx, cur, rescaled(ctx.prior, members, float(np.exp(ln_s))))
    return cur, float(np.exp(ln_s))


def group_drift(ctx: Any, r: FitResult, log: Callable[[str], None]) -> tuple[FitResult, DesignPrior, dict] | None:
    """The group whose common factor explains the data, if any (the module docstring's criteria).

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
        try:
            fitted, s = _factor_fit(ctx, r, members)
        except CANDIDATE_FAILURES:
            continue
        dbic = r.bic - (fitted.bic + np.log(fitted.n_residuals))  # one parameter more: the factor
        if abs(np.log(s)) <= ctx.prior.tau or dbic < DRIFT_MIN_DBIC or ctx.unfit(fitted):
            log(f"{ROLES[role]} x{s:.3g} together: dBIC {dbic:.1f}, cost {fitted.cost:.4g}: not kept")
            continue
        edge = float(np.exp(np.copysign(ctx.prior.tau, np.log(s))))
        try:
            held = _refit(ctx, fitted, rescaled(ctx.prior, members, edge), nfev=60)
        except CANDIDATE_FAILURES:
            continue
        edge_dbic = float(held.bic - fitted.bic)
        if edge_dbic < DRIFT_MIN_DBIC:
            log(f"{ROLES[role]} x{s:.3g} together: at the tolerance's edge x{edge:.3g} the BIC is only "
                f"{edge_dbic:.1f} higher: not kept")
            continue
        ends = {m: frozenset(r.circuit.element(m).nodes) for m in members}
        shared = [m for m in members if sum(e == ends[m] for e in ends.values()) > 1]
        entry = {"name": f"{role} (all {ROLES[role]})", "members": list(members), "design": 1.0, "fitted": s,
                 "in_parallel": shared,
                 "ratio": s, "sigmas": float(abs(np.log(s)) / ctx.prior.tau), "delta_bic": float(dbic),
                 "edge_delta_bic": edge_dbic, "group": True}
        log(f"{ROLES[role]} x{s:.3g} together explain the data: cost {r.cost:.4g} -> {fitted.cost:.4g}, dBIC "
            f"{dbic:.1f}, {edge_dbic:.1f} at the tolerance's edge")
        if best is None or fitted.bic < best[0].bic:
            best = (fitted, rescaled(ctx.prior, members, s), entry)
    return best
