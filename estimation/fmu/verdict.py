"""Verdict on an FMU estimate: is the residual the record's own noise, and do independent restarts agree?

:func:`judge` decides ``converged`` from two pieces of evidence only:

1. **The residual is the record's noise** (a chi-square test). The noise of
   every compared output ``b`` is read from the record at the answer: the
   robust spread of the fourth differences of the residual
   (:func:`estimation.verdict.noise_floor`; where the model explains the
   record, the residual holds its noise and no signal, so signal near the
   Nyquist frequency is not read as noise), at least the numerical resolution
   of a simulated record, ``sqrt(eps)`` of the output's RMS (a noise-free
   record). The statistic ``T = sum_b sum_i r_bi^2 / sigma_b^2`` over
   ``N - n`` degrees of freedom must not exceed the 0.999 quantile of the F
   distribution ``F(N - n, nu)``: ``nu = 0.14 N`` are the effective degrees of
   freedom of the noise reading (the median absolute deviation has 37 % of the
   efficiency of the variance, and fourth differences of white noise are
   correlated: ``1 + 2 sum rho_k^2 = 2.63``). A fit in a wrong basin leaves a
   structured residual far above its own fourth-difference reading.
2. **At least two independent restarts reach the same values**: besides the
   best end, another restart whose own residual passes the same test and whose
   values lie within ``3 sqrt(2)`` of the best end's 1-sigma (Fisher
   information) on every parameter. One restart is never agreement.

Besides, no parameter may end at a bound, the answer must be a minimum (the
Gauss-Newton step from it moves no value by more than 0.1 %, or would lower
the chi-square by less than the 68.27 % quantile of chi-square with ``n``
degrees of freedom: the answer then lies inside the 1-sigma confidence region
of the minimum), and every parameter must be identifiable.

``uncertainty`` is the Cramer-Rao 1-sigma (relative) from the Fisher
information ``F = J_w^T J_w`` of the noise-weighted residuals
``r_bi / sigma_b``, ``J_w[:, j] = d r_w / d ln(theta_j)``, at the answer,
and only when ``converged``; otherwise it is ``None`` and the same numbers are
reported as ``local_curvature`` (the curvature of the cost where the search
stopped, not an uncertainty of the values). ``non_identifiable`` comes from
the same Fisher information at the answer: a relative 1-sigma above 10 %, or
a (near) null direction of ``J_w``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from estimation.parameters import ParameterSet
from estimation.verdict import AT_BOUND, STEP_TOL, UNCERTAIN, fisher_information, noise_floor

__all__ = ["NUMERIC", "QUANTILE", "MAD_DOF", "block_noise", "chi_square", "judge"]

#: Numerical resolution of a simulated record, relative to each output's RMS (a noise-free record's floor).
NUMERIC = math.sqrt(np.finfo(float).eps)
#: Quantile of the chi-square (F) test of the residual against the record's noise.
QUANTILE = 0.999
#: Effective degrees of freedom of the fourth-difference noise reading, per sample: 0.37 / 2.63.
MAD_DOF = 0.37 / 2.63
#: Confidence region the answer must lie in around the minimum (the Gauss-Newton step's predicted fall).
CONFIDENCE = 0.6827
#: Restarts agree when every value lies within this many combined 1-sigma of the best end's.
AGREE_SIGMA = 3.0


def block_noise(r: np.ndarray, blocks: int, scales: Sequence[float] | None = None) -> np.ndarray:
    """Noise standard deviation of each of ``blocks`` equal parts of a residual (one per compared output).

    Parameters
    ----------
    r : numpy.ndarray
        ``(N,)`` residual, the outputs' residuals concatenated (unit of the residual).
    blocks : int
        Number of equal parts.
    scales : sequence of float, optional
        RMS of each output's data in the residual's unit (default 1): the floor ``NUMERIC * scale``.

    Returns
    -------
    numpy.ndarray
        ``(blocks,)`` standard deviations, unit of the residual.
    """
    parts = np.array_split(np.asarray(r, float).ravel(), max(1, int(blocks)))
    sc = list(scales) if scales is not None else [1.0] * len(parts)
    return np.array([max(noise_floor(p), NUMERIC * float(s)) for p, s in zip(parts, sc)])


def chi_square(r: np.ndarray, sigma: np.ndarray, n_params: int) -> dict[str, float]:
    """Chi-square test of a residual against per-block noise ``sigma`` (module docstring).

    Returns
    -------
    dict
        ``ratio`` (``T / (N - n)``), ``limit`` (the F quantile), ``dof``, ``consistent`` (bool).
    """
    from scipy.stats import f as fdist

    r = np.asarray(r, float).ravel()
    if not r.size or not np.all(np.isfinite(r)):
        return {"ratio": math.inf, "limit": 1.0, "dof": 0, "consistent": False}
    parts = np.array_split(r, len(sigma))
    t = sum(float(np.sum(p ** 2)) / float(s) ** 2 for p, s in zip(parts, sigma))
    dof = max(1, r.size - int(n_params))
    limit = float(fdist.ppf(QUANTILE, dof, max(1.0, MAD_DOF * r.size)))
    ratio = t / dof
    return {"ratio": float(ratio), "limit": limit, "dof": int(dof), "consistent": bool(ratio <= limit)}


def judge(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet, x: np.ndarray,
          ends: Sequence[tuple[np.ndarray, float]], blocks: int = 1, scales: Sequence[float] | None = None,
          data_noise: float | None = None) -> dict[str, Any]:
    """Convergence verdict, uncertainty and non-identifiable parameters of an FMU estimate (module docstring).

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, N)`` on unit-cube points (the approach's residuals, outputs concatenated).
    params : ParameterSet
    x : numpy.ndarray
        ``(n,)`` unit-cube point of the answer.
    ends : sequence of (x, residual RMS)
        Every restart's end (the answer's among them).
    blocks : int
        Compared outputs (equal parts of the residual).
    scales : sequence of float, optional
        RMS of each output's data in the residual's unit.
    data_noise : float, optional
        The data's own fourth-difference reading (reported only).

    Returns
    -------
    dict
        ``converged``, ``convergence_reason``, ``uncertainty`` (None unless converged),
        ``local_curvature``, ``non_identifiable``, ``non_identifiable_reasons``, ``residual_rms``,
        ``noise_floor``, ``noise_sigma`` (per output), ``chi_square``, ``tolerance``, ``at_bound``,
        ``restarts``, ``condition``.
    """
    names = list(params.varying)
    x = np.asarray(x, float)
    ev = params.evaluate(x)
    values = {k: float(ev.values[k]) for k in names}
    r = np.asarray(residuals(x[None]), float)[0]
    rms = float(np.sqrt(np.mean(r ** 2))) if r.size and np.all(np.isfinite(r)) else math.inf
    sigma = block_noise(r, blocks, scales)
    test = chi_square(r, sigma, len(names))
    reasons: list[str] = []
    if not test["consistent"]:
        reasons.append(f"the residual is not the record's noise: chi-square {test['ratio']:.3g} per degree of "
                       f"freedom against the noise read at the answer (limit {test['limit']:.3g}; residual RMS "
                       f"{rms:.3g}, noise {', '.join(f'{s:.3g}' for s in sigma)})")
    weights = np.repeat(1.0 / sigma, [p.size for p in np.array_split(r, len(sigma))])

    def weighted(U: np.ndarray) -> np.ndarray:
        return np.asarray(residuals(U), float) * weights[None, :]

    fi = fisher_information(weighted, params, values, 1.0)
    unc = {k: v / 100.0 for k, v in fi["relative_sd_percent"].items()}
    J = fi.pop("jacobian")
    u = np.asarray(ev.unit, float)
    at_bound = [k for k, ui in zip(names, u) if ui <= AT_BOUND or ui >= 1 - AT_BOUND]
    if at_bound:
        reasons.append(f"{', '.join(at_bound)} at a bound (an equivalent model may lie beyond it)")
    rw = r * weights
    if np.all(np.isfinite(rw)) and rw.size:
        step = np.linalg.lstsq(J, -rw, rcond=1e-12)[0]
        # the step's predicted fall of the chi-square: within the 68.27 % quantile of chi-square with n degrees
        # of freedom, the answer lies inside the 1-sigma confidence region of the minimum (no evidence of a
        # better one: the search error is below the estimate's own uncertainty)
        from scipy.stats import chi2

        gain = float(np.sum((J @ step) ** 2))
        moving = [(k, d) for k, d in zip(names, step) if abs(d) > STEP_TOL and k not in fi["null"]]
        if moving and gain > float(chi2.ppf(CONFIDENCE, len(names))):
            reasons.append("not at a minimum: a Gauss-Newton step would move "
                           + ", ".join(f"{k} by {100 * d:+.3g} %" for k, d in moving)
                           + f" (a fall of the chi-square by {gain:.3g})")
    # independent restarts: the other ends whose own residual is the record's noise, and their values
    others, rows = [], []
    for xe, rms_e in ends:
        xe = np.asarray(xe, float)
        if np.allclose(xe, x, rtol=0, atol=0):
            continue
        re_ = np.asarray(residuals(xe[None]), float)[0]
        ok = chi_square(re_, block_noise(re_, blocks, scales), len(names))["consistent"]
        ve = {k: float(params.evaluate(xe).values[k]) for k in names}
        dev = {k: abs(math.log(abs(ve[k]) / abs(values[k]))) if values[k] and ve[k] and ve[k] * values[k] > 0
               else math.inf for k in names}
        agree = ok and all(dev[k] <= AGREE_SIGMA * math.sqrt(2.0) * unc[k] or not math.isfinite(unc[k])
                           for k in names)
        rows.append({"residual_rms": float(rms_e), "noise_consistent": bool(ok), "agrees": bool(agree)})
        if ok:
            others.append((agree, dev))
    agreeing = 1 + sum(a for a, _ in others)
    if agreeing < 2:
        if not others:
            reasons.append(f"no other restart reached the record's noise ({len(ends)} restart(s)): "
                           "one restart is not agreement")
        else:
            worst = max(others, key=lambda o: max(o[1].values()))[1]
            k = max(worst, key=worst.get)
            reasons.append(f"restarts that reach the record's noise differ (e.g. {k} by {100 * worst[k]:.3g} %, "
                           f"beyond {AGREE_SIGMA:g} sqrt 2 of its 1-sigma)")
    non_ident = [k for k in names if not unc[k] <= UNCERTAIN]
    why = {k: ("in a null direction of the residuals' Jacobian (its effect is matched by others)"
               if k in fi["null"] else f"Fisher-information 1-sigma {100 * unc[k]:.3g} % (above {100 * UNCERTAIN:g} %)")
           for k in non_ident}
    if non_ident:
        reasons.append(f"not identifiable from these data: {', '.join(non_ident)}")
    converged = not reasons
    reason = (f"residual is the record's noise (chi-square {test['ratio']:.3g} per degree of freedom, limit "
              f"{test['limit']:.3g}); no parameter at a bound; {agreeing} of {len(ends)} restarts agree within "
              "their uncertainty" if converged else "; ".join(reasons))
    return {
        "converged": converged,
        "convergence_reason": reason,
        "uncertainty": unc if converged else None,
        "local_curvature": None if converged else {
            "note": "relative 1-sigma from the cost's curvature where the search stopped; not an uncertainty "
                    "of the values, which are not converged", "values": unc},
        "non_identifiable": non_ident,
        "non_identifiable_reasons": why,
        "residual_rms": rms,
        "noise_floor": float(data_noise) if data_noise is not None else None,
        "noise_sigma": [float(s) for s in sigma],
        "chi_square": test,
        "tolerance": float(math.sqrt(test["limit"]) * math.sqrt(float(np.mean(sigma ** 2)))),
        "at_bound": at_bound,
        "restarts": {"count": len(ends), "agreeing": agreeing, "others": rows,
                     "residual_rms": [float(c) for _, c in ends]},
        "condition": fi["condition"],
    }
