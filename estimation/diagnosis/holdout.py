"""Held-out check of a structural extension: fitted on alternate frequency points, scored on the others.

A structure with many new values (a missing section adds four or five) can
lower the cost by following the noise. Both the model before the extension
and the extended one are refitted (from their fitted values, to
convergence, with the design prior of the full fits, its weight scaled to
the half of the points) on every other frequency point and scored on the
points left out, and the other way round; the held-out gain is
``1 - sum(test cost extended) / sum(test cost before)``. Noise followed on the
fitting points does not carry over to the held-out ones, so the gain of an
extension that only fits noise falls to about zero or below.

With the noise level given, each held-out point's squared error counts at
most ``HELD_OUT_CAP`` noise standard deviations squared. A sharp resonance
falls between the fitting points of a fold: its frequency is pinned only to
within the spacing of those points, and a refit free to move it by a fraction
of a per cent turns a held-out point at its peak into an error of several
per cent. That is the resonance's sensitivity, not a structure that fails
away from its fitting points; uncapped, one such point outweighed a missing
section's gain on every other point.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from pris_cosim.models.builtin import Configuration

from estimation.diagnosis.fit import FitResult, FrequencyFit
from estimation.diagnosis.prior import DesignPrior

#: Largest error a held-out point counts for, in noise standard deviations (with the noise level given).
HELD_OUT_CAP = 5.0


def _refit_score(r: FitResult, configs: Sequence[Configuration], f: np.ndarray, data: Mapping[str, np.ndarray],
                 fixed: Sequence[str], scale: float, train: np.ndarray, test: np.ndarray, max_nfev: int,
                 weights: Mapping[str, np.ndarray] | None = None, prior: DesignPrior | None = None,
                 noise: Mapping[str, float] | None = None) -> np.ndarray:
    w = dict(weights or {})
    circuit = r.fitted_circuit()
    nc = r.x.size - sum(len(e.parameters) for e in r.effects)
    tail = r.x[nc:]
    if prior is not None:  # the prior of the whole record, weighed against half its points
        prior = replace(prior, weight=prior.weight * f.size / int(np.sum(train)))
    fit = FrequencyFit(circuit, configs, f[train], {k: v[train] for k, v in data.items()}, fixed, r.effects, scale,
                       prior=prior, couplings=r.couplings, weights={k: v[train] for k, v in w.items()})
    x0 = np.concatenate([np.zeros(fit.nc), tail])
    res = fit.fit(x0s=x0[None], grid=False, max_nfev=max_nfev, tol=1e-7)
    held = FrequencyFit(circuit, configs, f[test], {k: v[test] for k, v in data.items()}, fixed, r.effects, scale,
                        couplings=r.couplings, weights={k: v[test] for k, v in w.items()})
    scored = held.result(res.x)
    # each held-out point's share of the held-out cost (the cost is their sum)
    share = np.zeros(int(np.sum(test)))
    for n, e in scored.errors.items():
        e2 = np.abs(e) ** 2 * (w[n][test] ** 2 if n in w else 1.0)
        if noise and n in noise:
            e2 = np.minimum(e2, (HELD_OUT_CAP * noise[n]) ** 2)
        share += e2 / e2.size
    return share


def held_out_gain(before: FitResult, after: FitResult, configs: Sequence[Configuration], f: np.ndarray,
                  data: Mapping[str, np.ndarray], fixed: Sequence[str] = (), scale: float = 1.0,
                  max_nfev: int = 15, weights: Mapping[str, np.ndarray] | None = None,
                  prior: DesignPrior | None = None, noise: Mapping[str, float] | None = None,
                  with_error: bool = False) -> float | tuple[float, float]:
    """Fraction of the held-out cost of ``before`` that ``after`` removes (two folds: even and odd points).

    Parameters
    ----------
    before, after : FitResult
        Fits on all the points (``after`` extends ``before``).
    configs : sequence of Configuration
    f : numpy.ndarray, Hz
    data : mapping
        Response name to complex values on ``f``.
    fixed : sequence of str
        Names kept at their values.
    scale : float, Ohm
        Typical impedance of the data.
    max_nfev : int
        Evaluations of each refit on half the points.
    weights : mapping, optional
        Per-point residual weights by response (:func:`.evidence.noise_weights`).
    prior : DesignPrior, optional
        The design prior of the full fits (:mod:`.prior`); the refits carry it,
        its weight multiplied by the ratio of all points to fitted points.
    noise : mapping, optional
        Noise RMS of each response (of its log error, weighted as the cost
        is); each held-out point's squared error is capped at
        ``HELD_OUT_CAP`` times it, squared. Without it, uncapped.

    with_error : bool
        Also return the gain's standard error: the held-out points' differences
        of squared error (before minus after) are paired, and their spread over
        the points gives the error of their sum.

    Returns
    -------
    float, or (float, float) with ``with_error``
        Held-out gain (1: the extension removes all the held-out misfit; 0 or
        less: it does not help on points it was not fitted to), and its
        standard error.
    """
    idx = np.arange(f.size)
    folds = [(idx % 2 == 0, idx % 2 == 1), (idx % 2 == 1, idx % 2 == 0)]
    b, a = [], []
    for train, test in folds:
        b.append(_refit_score(before, configs, f, data, fixed, scale, train, test, max_nfev, weights, prior, noise))
        a.append(_refit_score(after, configs, f, data, fixed, scale, train, test, max_nfev, weights, prior, noise))
    sb, sa = np.concatenate(b), np.concatenate(a)
    cost_b = float(np.sum(sb))
    gain = float(1 - np.sum(sa) / cost_b) if cost_b > 0 else 0.0
    if not with_error:
        return gain
    d = sb - sa
    se = float(np.sqrt(d.size) * np.std(d, ddof=1) / cost_b) if cost_b > 0 and d.size > 1 else 0.0
    return gain, se
