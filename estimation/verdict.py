"""Verdict on an estimate: did it converge, how well is each parameter determined, which are not.

Every answer of ``pris-cosim estimate`` carries a verdict (:func:`verdict`):

``converged`` (bool) and ``convergence_reason`` (text)
    True only when all of these hold:

    - the residual RMS at the estimate is within the data's noise floor:
      ``rms <= max(3 noise, 1e-6 scale)``, where ``noise`` is estimated from
      the data themselves (:func:`noise_floor`: the robust spread of fourth
      differences, which removes a smooth response) and ``scale`` is the
      RMS of the data (decades for log-magnitude responses, volts for
      waveforms);
    - no parameter ends within 1e-3 (unit-cube coordinate) of a bound, unless the residual is within
      the noise floor, at least two restarts found the same values and no coupling was repaired;
    - the estimate is a minimum: a Gauss-Newton step from it would move no
      parameter by more than 0.1 % (with ``step_within_sigma``: or by more than
      its own 1-sigma uncertainty, when that is larger -- for a residual that is
      strongly nonlinear at that scale, such as a long time record);
    - the restarts that reach the best cost agree on every parameter to
      within 1 %; restarts that stop at a higher cost are local minima and
      are reported (``restarts``) but do not count against convergence.

``uncertainty`` {parameter: relative 1-sigma}
    From the Fisher information ``F = J^T J / sigma^2`` of the residuals,
    ``J[:, j] = d r / d ln(theta_j)`` at the estimate, and ``sigma`` the
    larger of the residual standard deviation ``sqrt(SSR / (N - n))`` and the
    noise (0 for a simulated, exact target; otherwise the fourth-difference
    noise floor of the data, or that of the residual at the estimate when the
    data's exceeds three times both it and the residual's spread: signal near
    the Nyquist frequency is not read as noise; at least 1e-12 of the data
    scale) (:func:`fisher_information`, the
    Cramer-Rao bound); ``inf`` for a parameter without effect.

``non_identifiable`` [names]
    Parameters whose relative 1-sigma exceeds 10 %, that lie in a (near)
    null direction of ``J`` (singular value below 1e-8 of the largest), or
    on which agreeing restarts differ.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from estimation.parameters import ParameterSet

#: Relative 1-sigma above which a parameter is reported as not identifiable.
UNCERTAIN = 0.10
#: Unit-cube distance from a bound that counts as "at the bound".
AT_BOUND = 1e-3
#: Two restarts agree when every parameter differs by less than this (relative).
AGREE = 0.01
#: Largest relative Gauss-Newton step from the estimate that still counts as "at the minimum".
STEP_TOL = 1e-3
#: Singular values of the Jacobian below this fraction of the largest count as zero.
NULL_RTOL = 1e-8


def residual_tolerance(data: np.ndarray, noise: float | None = None, scale: float | None = None
                       ) -> tuple[float, float, float]:
    """``(noise, scale, tolerance)`` of a fit to ``data``: the residual RMS that counts as explaining them.

    ``noise``: given, or :func:`noise_floor` of the data; ``scale``: given, or the data's RMS;
    tolerance ``max(3 noise, 1e-6 scale)``. Same unit as ``data``.
    """
    d = np.asarray(data, float).ravel()
    d = d[np.isfinite(d)]
    noise = noise_floor(d) if noise is None else float(noise)
    scale = float(np.sqrt(np.mean(d ** 2))) if scale is None and d.size else float(scale or 1.0)
    return noise, scale, max(3.0 * noise, 1e-6 * scale, 1e-300)


def residual_noise(noise: float, r: np.ndarray, s_res: float | None = None) -> float:
    """The noise standard deviation to believe: the data's reading, or the fit's residual's when the data's is signal.

    The noise read from the data's fourth differences (:func:`noise_floor`) counts every
    component near the Nyquist frequency as noise: a record whose modes lie above it
    (aliased, as the three-section winding sampled at 1 MHz) reads as noisy without any
    noise. Where the model explains the data, the residual holds the noise and not the
    signal: when the data's reading exceeds three times both the residual's spread
    ``s_res`` (default its RMS) and its own reading, it is signal, and the residual's
    reading is the noise.

    Parameters
    ----------
    noise : float
        The data's reading (unit of the data).
    r : numpy.ndarray
        Residual vector of the fit (same unit).
    s_res : float, optional
        Spread of the residual.
    """
    r = np.asarray(r, float).ravel()
    if not r.size or not np.all(np.isfinite(r)):
        return float(noise)
    n_res = noise_floor(r)
    spread = float(np.sqrt(np.mean(r ** 2))) if s_res is None else float(s_res)
    return n_res if noise > 3.0 * max(n_res, spread) else float(noise)


def agreement_tolerance(tol: float, noise: float, noise_sigma: float, scale: float) -> float:
    """Residual RMS within which two fits explain the data equally well.

    The data's tolerance ``tol`` (:func:`residual_tolerance`), or, when the residual showed the
    data's noise reading to be signal (``noise_sigma < noise``, :func:`residual_noise`),
    ``max(3 noise_sigma, 1e-6 scale)``: a fit far above the best one's noise does not fit equally well.
    """
    return float(tol) if not noise_sigma < noise else max(3.0 * float(noise_sigma), 1e-6 * float(scale), 1e-300)


def noise_floor(data: np.ndarray) -> float:
    """Noise standard deviation of a sampled record, from its fourth differences (robust).

    The fourth difference ``x[k-2] - 4 x[k-1] + 6 x[k] - 4 x[k+1] + x[k+2]`` of
    white noise has standard deviation ``sqrt(70) sigma``; a smooth signal
    contributes little to it (on 200 log-spaced points of the two-section
    responses: 5e-8 decades, against 3e-5 for second differences), and jumps
    (switching instants, resonances, the joins between responses) are removed
    by the median absolute deviation. Measured: 1e-3 decades of added noise
    read as 1.07e-3, 1e-5 as 1.4e-5.

    Parameters
    ----------
    data : numpy.ndarray
        ``(N,)`` real samples (or several records concatenated along the last axis).

    Returns
    -------
    float
        Same unit as ``data``.
    """
    x = np.asarray(data, float).ravel()
    x = x[np.isfinite(x)]
    if x.size < 9:
        return 0.0
    d4 = np.diff(x, 4)
    mad = float(np.median(np.abs(d4 - np.median(d4))))
    return 1.4826 * mad / math.sqrt(70.0)


def fisher_information(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet,
                       values: Mapping[str, float], sigma: float, rel_step: float = 1e-4,
                       limit_percent: float = 5.0) -> dict[str, Any]:
    """Fisher information of the parameters (log scale) from the residual Jacobian at ``values``.

    With white noise of standard deviation ``sigma`` on every residual,
    ``F = J^T J / sigma^2`` where ``J[:, j] = d r / d ln(theta_j)`` (central
    differences of relative size ``rel_step``); ``sqrt(diag(F^-1))`` bounds the
    relative standard deviation of each parameter (Cramer-Rao).

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, N)`` on unit-cube points.
    params : ParameterSet
    values : mapping
        Physical values where the Jacobian is taken.
    sigma : float
        Noise standard deviation, unit of the residuals.
    rel_step : float
        Relative difference step.
    limit_percent : float
        Parameters whose bound exceeds this are reported as poorly determined.

    Returns
    -------
    dict
        ``relative_sd_percent`` {name: %}, ``relative_sensitivity`` {name:
        column norm over the largest}, ``condition`` (of ``J``),
        ``poorly_determined`` [names], ``null`` [names in a null direction of
        ``J``], ``sigma``, ``jacobian`` (``J``, ``(N, n)``).
    """
    names = list(params.varying)
    pts = []
    for k in names:
        for s in (1 + rel_step, 1 - rel_step):
            v = dict(values)
            v[k] = values[k] * s
            pts.append(params.to_unit({n: v[n] for n in names}))
    R = np.asarray(residuals(np.array(pts)), float)
    R = np.where(np.isfinite(R), R, 0.0)
    J = ((R[0::2] - R[1::2]) / (2 * rel_step)).T  # (N, n)
    norms = np.linalg.norm(J, axis=0)
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf
    null = set()
    if s.size and s[0] > 0:
        for i in np.flatnonzero(s <= NULL_RTOL * s[0]):
            w = np.abs(vt[i])
            null |= {names[j] for j in np.flatnonzero(w >= 0.1 * w.max())}
    F = J.T @ J / max(sigma, 1e-300) ** 2
    cov = np.linalg.pinv(F, rcond=1e-15)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None)) * 100.0
    sd = np.where(norms > 0, sd, np.inf)
    rel_sd = {k: float(x) for k, x in zip(names, sd)}
    for k in null:
        rel_sd[k] = math.inf
    return {
        "jacobian": J,
        "relative_sd_percent": rel_sd,
        "relative_sensitivity": {k: float(x / max(norms.max(initial=0.0), 1e-300)) for k, x in zip(names, norms)},
        "condition": cond,
        "sigma": float(sigma),
        "null": sorted(null, key=names.index),
        "poorly_determined": [k for k in names if not rel_sd[k] <= limit_percent],
    }


def _rel_diff(a: Mapping[str, float], b: Mapping[str, float], names: Sequence[str]) -> dict[str, float]:
    return {k: abs(a[k] - b[k]) / max(abs(a[k]), abs(b[k]), 1e-300) for k in names}


def verdict(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet, x: np.ndarray,
            data: np.ndarray, ends: Sequence[tuple[np.ndarray, float]] = (),
            noise: float | None = None, scale: float | None = None, step_within_sigma: bool = False
            ) -> dict[str, Any]:
    """Convergence verdict, uncertainties and non-identifiable parameters of an estimate.

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, N)`` of the approach on unit-cube points (the
        same model as the one scored).
    params : ParameterSet
    x : numpy.ndarray
        ``(n,)`` unit-cube point of the estimate.
    data : numpy.ndarray
        The compared data (log10 magnitudes in decades, or voltage samples in V)
        for the noise floor and scale.
    ends : sequence of (x, residual RMS)
        End points of every restart (unit cube) and their residual RMS.
    noise, scale : float, optional
        Known noise standard deviation and data scale (default: from ``data``).
    step_within_sigma : bool
        Accept a Gauss-Newton step within each value's 1-sigma as "at the minimum".

    Returns
    -------
    dict
        ``converged``, ``convergence_reason``, ``uncertainty`` {name:
        relative 1-sigma}, ``non_identifiable``, ``non_identifiable_reasons`` {name: why},
        ``residual_rms``,
        ``noise_floor``, ``tolerance``, ``at_bound``, ``restarts`` and
        ``condition``.
    """
    names = list(params.varying)
    x = np.asarray(x, float)
    ev = params.evaluate(x)
    values = {k: float(ev.values[k]) for k in names}
    r = np.asarray(residuals(x[None]), float)[0]
    finite = np.isfinite(r)
    rms = float(np.sqrt(np.mean(r[finite] ** 2))) if finite.all() and r.size else math.inf
    noise_given = noise is not None
    noise, scale, tol = residual_tolerance(data, noise, scale)
    reasons: list[str] = []
    if not rms <= tol:
        reasons.append(f"residual RMS {rms:.3g} above the data's noise floor ({tol:.3g})")
    u = np.asarray(ev.unit, float)
    at_bound = [k for k, ui in zip(names, u) if ui <= AT_BOUND or ui >= 1 - AT_BOUND]
    if bool(np.any(ev.repaired)):
        at_bound += [k for k in params.couplings + params.mutuals() if k in names and k not in at_bound]
    dof = max(1, r.size - len(names))
    s_res = rms * math.sqrt(r.size / dof) if math.isfinite(rms) else math.inf
    noise_sigma = noise if noise_given else residual_noise(noise, r, s_res)
    # restarts: those reaching the best residual (or the noise) agree?
    agreeing, differing, reached = 1, set(), 1
    ends = list(ends)
    if ends:
        best = min(c for _, c in ends)
        good = [e for e in ends if e[1] <= max(best * 1.5, agreement_tolerance(tol, noise, noise_sigma, scale))]
        reached = len(good)
        vals = [{k: float(params.evaluate(np.asarray(e[0], float)).values[k]) for k in names} for e in good]
        agreeing = 0
        for v in vals:
            dd = _rel_diff(values, v, names)
            bad = [k for k in names if dd[k] > AGREE]
            differing |= set(bad)
            agreeing += not bad
    if at_bound and (not rms <= tol or bool(np.any(ev.repaired)) or agreeing < 2):
        # a value near a bound is the answer only when it explains the data to their noise and
        # independent restarts found it again (else an equivalent circuit may lie beyond the bound)
        reasons.append(f"{', '.join(at_bound)} at a bound")
    if differing:
        reasons.append(f"restarts reach the same cost at different {', '.join(k for k in names if k in differing)}")
    sigma = max(s_res if math.isfinite(s_res) else 0.0, noise_sigma, 1e-12 * max(scale, 1e-300))
    fi = fisher_information(residuals, params, values, sigma)
    unc = {k: v / 100.0 for k, v in fi["relative_sd_percent"].items()}
    # optimality: the Gauss-Newton step from the estimate (relative, ln theta) must be negligible
    J = fi.pop("jacobian")
    if np.all(np.isfinite(r)) and r.size:
        step = np.linalg.lstsq(J, -r, rcond=1e-12)[0]
        # with ``step_within_sigma``, a step within a value's own 1-sigma is no evidence of a better minimum
        moving = [k for k, d in zip(names, step)
                  if abs(d) > max(STEP_TOL, unc[k] if step_within_sigma and math.isfinite(unc[k]) else 0.0)
                  and k not in fi["null"]]
        if moving:
            reasons.append("not at a minimum: a Gauss-Newton step would move "
                           + ", ".join(f"{k} by {100 * d:+.3g} %" for k, d in zip(names, step) if k in moving))
    non_ident = [k for k in names if not unc[k] <= UNCERTAIN or k in differing]
    why: dict[str, str] = {}
    for k in non_ident:
        parts = []
        if k in fi["null"]:
            parts.append("in a null direction of the residuals' Jacobian (its effect is matched by others)")
        elif not unc[k] <= UNCERTAIN:
            parts.append(f"Fisher-information 1-sigma {100 * unc[k]:.3g} % (above {100 * UNCERTAIN:g} %)")
        if k in differing:
            parts.append("restarts that fit equally well differ on it by more than "
                         f"{100 * AGREE:g} %")
        why[k] = "; ".join(parts)
    if non_ident:
        reasons.append(f"not identifiable from these data: {', '.join(non_ident)}")
    converged = not reasons
    return {
        "converged": converged,
        "convergence_reason": ("residual RMS {:.3g} within the noise floor {:.3g}; no parameter at a bound; "
                               "{} of {} restarts agree".format(rms, tol, agreeing, max(len(ends), 1))
                               if converged else "; ".join(reasons)),
        "uncertainty": unc,
        "non_identifiable": non_ident,
        "non_identifiable_reasons": why,
        "residual_rms": rms,
        "noise_floor": noise,
        "noise_sigma": float(noise_sigma),
        "tolerance": tol,
        "at_bound": at_bound,
        "restarts": {"count": len(ends), "reached_best": reached, "agreeing": agreeing,
                     "residual_rms": [float(c) for _, c in ends]},
        "condition": fi["condition"],
    }


__all__ = ["verdict", "fisher_information", "noise_floor", "residual_tolerance", "residual_noise", "agreement_tolerance", "UNCERTAIN", "AT_BOUND", "AGREE"]
