"""The refit to convergence of each model the forward selection names (one-port data).

A cause's fits stop after tens of evaluations, and under the design prior a
model can stop with its values still paying a share of the penalty they
would not need. The next cause is then measured against that: refitted with
it, the shared values converge too, and any cause shows the same gain (design
core loss 704: the core loss stopped at 3.1e-5, half of it penalty; with a
skin effect, a magnetising change or a new section alike, 1.54e-5; the core
loss alone refitted, 1.55e-5). Refitting the named model first leaves a
further cause only what the model cannot reach.

Six-response models are left as they are: each of their evaluations costs
several times more. So is a model with a new section: whether it is at the
noise with values off the design turns on its residuals' whiteness
(:meth:`.context.Context.settled`), and refitted further a split that had
taken a skin effect's share into its values passed that test and stopped
there (design missing section + skin effect 702). Weighed against a drift,
a new section alone is refitted all the same: the drift's own fit is
converged, and a split's first fit stopped 19 in BIC short of its
convergence on design missing section 700
(:func:`.diagnose._open`, :func:`.causes.rivals.cause_over_drift`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from estimation.diagnosis.fit import CANDIDATE_FAILURES, FitResult, current_nc

#: Evaluations of the refit, from its own values, of each model the selection names (one port).
CONVERGE_NFEV = 300

#: Attributes of a fit result that say how its structure was found, carried over to the refit.
_PROVENANCE = ("merged_back", "from_design", "unmerged")


def converged(ctx: Any, r: FitResult, log: Callable[[str], None] = lambda m: None, structure: bool = False
              ) -> FitResult:
    """``r`` refitted from its own values to convergence (one-port data; else ``r`` as it is).

    Parameters
    ----------
    ctx : context.Context
        The diagnosis's shared data: ``one_port`` and ``fit(circuit, effects, couplings=...)`` are used.
    r : FitResult
        The model just named (circuit values and effect parameters).
    log : callable, optional
        Receives one progress line when the refit lowers the objective.
    structure : bool
        Refit a model with a new section too (the reference an extension's gain is measured against,
        :func:`.causes.extend.extensions`, and a section weighed against a drift; not the model the selection goes
        on from after a cause is named, see above).

    Returns
    -------
    FitResult
        The refit when its objective (cost plus design penalty, dimensionless) is lower, else ``r``; the
        refit keeps ``r``'s structure, causes and provenance. Either is marked ``converged`` and not refitted
        again.
    """
    if getattr(r, "converged", False) or not ctx.one_port or (r.structure and not structure):
        return r
    try:
        fit = ctx.fit(r.fitted_circuit(), r.effects, couplings=r.couplings)
        res = fit.fit(x0s=np.concatenate([np.zeros(fit.nc), r.x[current_nc(r):]])[None], grid=False,
                      max_nfev=CONVERGE_NFEV, tol=1e-10)
    except CANDIDATE_FAILURES:
        return r
    if res.objective >= r.objective:
        r.converged = True
        return r
    res.converged = True
    res.structure, res.causes, res.cause = r.structure, list(r.causes), r.cause
    for name in _PROVENANCE:
        if hasattr(r, name):
            setattr(res, name, getattr(r, name))
    log(f"  {r.cause} refitted to convergence: {r.objective:.4g} -> {res.objective:.4g}")
    return res


def converged_job(args: tuple[Any, FitResult] | tuple[Any, FitResult, bool]) -> FitResult:
    """``(ctx, r)`` or ``(ctx, r, structure)`` to :func:`converged`: one job of a batch shared with the helper
    process."""
    return converged(args[0], args[1], structure=bool(args[2]) if len(args) > 2 else False)
