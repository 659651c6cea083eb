"""Cramer-Rao bounds of the estimation cells, and success judged against them.

A cell (approach x optimiser x cost x noise level) estimates the parameters
from one noisy record. Its best possible spread is the Cramer-Rao bound of
the data the approach compares:

- time, EMD and IEMD compare the terminal voltage ``v_in`` sample by sample;
  with white Gaussian noise of standard deviation ``sigma`` on it the Fisher
  information is ``J^T J / sigma^2``, ``J = d v_in / d ln(theta)``
  (:func:`cramer_rao`);
- the frequency approach compares ``log10 |Zin|`` at a set of Welch bins;
  the noise of each bin (through Welch's H1 of the noisy voltage and
  current) is measured by a Monte-Carlo over noise draws at the truth
  (:func:`bin_spread`), and the Fisher information is ``J^T W J`` with
  ``W = diag(1 / sd_k^2)`` (independent bins).

Bounds are relative one-sigma values in percent (``sqrt(diag(F^-1))``),
the form of the studies' ``sensitivity``. A run succeeds when every
parameter is within ``max(floor, factor x bound)`` of the truth
(:func:`within`), and the efficiency of a cell is its median ``|error|``
over seeds divided by the bound (:func:`efficiency`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from estimation.parameters import ParameterSet
from estimation.verdict import fisher_information

#: Success: every parameter within max(FLOOR_PERCENT, FACTOR x its bound).
FLOOR_PERCENT = 5.0
FACTOR = 3.0


def noise_sigma(x: np.ndarray, snr_db: float) -> float:
    """Standard deviation of white noise ``snr_db`` below the waveform's RMS about its mean (as the cells add)."""
    return float(np.std(np.asarray(x, float))) * 10.0 ** (-float(snr_db) / 20.0)


#: Relative difference steps tried in turn for the Jacobian of :func:`cramer_rao`, and the agreement
#: (relative) between two successive steps' bounds at which the smaller step is taken as converged.
STEPS = (1e-4, 1e-5, 1e-6, 1e-7)
STEP_AGREEMENT = 0.05


def cramer_rao(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet, values: Mapping[str, float],
               sigma: float | np.ndarray) -> dict[str, float]:
    """Relative one-sigma Cramer-Rao bound of each parameter, percent.

    The Jacobian is a central difference in each log-value. An ill-conditioned
    model (the three-section winding's Jacobian spans six decades of singular
    values) makes the bound on its sloppy combinations sensitive to the
    difference's truncation error: at a step of 1e-4 the bound on ``Cs`` of its
    voltage record came out 13 times too small, against the spread of the
    least-squares estimates over noise draws. The step therefore shrinks through
    :data:`STEPS` until two successive bounds agree within :data:`STEP_AGREEMENT`.

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, N)`` on unit-cube points (model minus data; the data's
        noise-free value is what matters, the Jacobian is taken at ``values``).
    params : ParameterSet
    values : mapping
        True parameter values.
    sigma : float or numpy.ndarray
        Noise standard deviation of every residual, or ``(N,)`` one per residual
        (unit of the residuals).
    """
    s = np.asarray(sigma, float)
    if s.ndim == 0:
        fun, level = residuals, float(s)
    else:
        if np.any(~np.isfinite(s)) or np.any(s <= 0):
            raise ValueError("per-residual noise levels must be finite and positive")

        def fun(U: np.ndarray) -> np.ndarray:
            return np.asarray(residuals(U), float) / s

        level = 1.0
    return dict(converged_fisher(fun, params, values, level)["relative_sd_percent"])


def converged_fisher(residuals: Callable[[np.ndarray], np.ndarray], params: ParameterSet,
                     values: Mapping[str, float], sigma: float) -> dict[str, Any]:
    """:func:`estimation.verdict.fisher_information` at the largest step of :data:`STEPS` whose bounds agree
    within :data:`STEP_AGREEMENT` with the next smaller step's (the smallest step when none do)."""
    last: dict[str, Any] | None = None
    for step in STEPS:
        fi = fisher_information(residuals, params, values, sigma, rel_step=step)
        if last is not None and all(_close(fi["relative_sd_percent"][k], last["relative_sd_percent"][k])
                                    for k in fi["relative_sd_percent"]):
            return fi
        last = fi
    assert last is not None
    return last


def _close(a: float, b: float) -> bool:
    if not (math.isfinite(a) and math.isfinite(b)):
        return a == b
    return abs(a - b) <= STEP_AGREEMENT * max(abs(a), abs(b))


def bin_spread(record: Mapping[str, np.ndarray], response: Callable[[Mapping[str, np.ndarray]], np.ndarray],
               add_noise: Callable[[Mapping[str, np.ndarray], int], Mapping[str, np.ndarray]],
               draws: int = 24, seed: int = 90_001) -> np.ndarray:
    """Standard deviation of each bin of a response estimate over noise draws (Monte-Carlo).

    Parameters
    ----------
    record : mapping
        Noise-free waveforms at the truth.
    response : callable
        Waveforms to the ``(F,)`` real compared quantity (e.g. ``log10 |Zin|`` at the bins).
    add_noise : callable
        ``add_noise(record, seed)``: the waveforms with one draw of the measurement noise.
    draws : int
    seed : int
        First noise seed (``seed .. seed + draws - 1``; distinct from the cells' seeds).

    Returns
    -------
    numpy.ndarray
        ``(F,)`` sample standard deviations.
    """
    if draws < 3:
        raise ValueError(f"bin_spread needs at least 3 draws (got {draws})")
    vals = np.array([np.asarray(response(add_noise(record, seed + d)), float) for d in range(draws)])
    return np.std(vals, axis=0, ddof=1)


def limit_percent(bound: Mapping[str, float] | None, name: str, floor: float = FLOOR_PERCENT,
                  factor: float = FACTOR) -> float:
    """The success limit of one parameter: ``max(floor, factor x bound)`` (``floor`` without a bound)."""
    if not bound or name not in bound or not math.isfinite(bound[name]):
        return floor if not bound or name not in bound else math.inf
    return max(floor, factor * float(bound[name]))


def within(errors: Mapping[str, float], bound: Mapping[str, float] | None, floor: float = FLOOR_PERCENT,
           factor: float = FACTOR) -> bool:
    """Every parameter within ``max(floor, factor x bound)`` percent (errors in percent)."""
    return all(math.isfinite(e) and abs(e) <= limit_percent(bound, k, floor, factor) for k, e in errors.items())


def efficiency(errors_by_seed: Sequence[Mapping[str, float]], bound: Mapping[str, float] | None
               ) -> dict[str, float]:
    """Median ``|error|`` over seeds divided by the bound, per parameter (NaN without a bound)."""
    if not errors_by_seed:
        return {}
    names = list(errors_by_seed[0])
    out = {}
    for k in names:
        med = float(np.median([abs(e[k]) for e in errors_by_seed]))
        b = float(bound[k]) if bound and k in bound else math.nan
        out[k] = med / b if b > 0 and math.isfinite(b) else math.nan
    return out
