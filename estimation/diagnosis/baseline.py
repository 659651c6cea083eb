"""Baseline fits of a diagnosis: the design's values fitted from several starts, or a lumped R-L-C from the data."""

from __future__ import annotations

import numpy as np

from pris_cosim.models import Model, lumped_rlc

from .align import aligned_start
from .fit import DiagnosisError, FitResult, FrequencyFit


def lumped_from_data(f: np.ndarray, z: np.ndarray) -> list[Model]:
    """Starting lumped R-L-C models estimated from one-port data (several capacitance guesses)."""
    w = 2 * np.pi * f
    k = max(1, f.size // 20)
    l0 = float(np.median(z[:k].imag / w[:k]))
    if not l0 > 0:
        raise DiagnosisError("one-port data is not inductive at low frequency; give a baseline model")
    r0 = float(max(np.median(z[:k].real), 1e-6 * np.abs(z[0])))
    peak = f[int(np.argmax(np.abs(z)))]
    guesses = [peak, 3 * f[-1], 10 * f[-1]]
    return [lumped_rlc(r0, l0, 1 / ((2 * np.pi * fr) ** 2 * l0)) for fr in guesses]


#: Baseline fits: local fits from the given values and from this many starts around them (a value twice its
#: design value is reached from 16, not from 4 or 8, in the design family's drift case).
BASELINE_STARTS = 16
#: Spread of those starts: standard deviation of the log of each value (0.3: about 30 %).
BASELINE_SPREAD = 0.3


def fit_multistart(fit: FrequencyFit, starts: int = BASELINE_STARTS, spread: float = BASELINE_SPREAD,
                   max_nfev: int = 200, good_enough: float = 0.0) -> FitResult:
    """The baseline's values fitted from the given values and, unless that fit is good enough, from random starts.

    The fit from the given values is continued from smoothed errors
    (:meth:`.fit.FrequencyFit.fit_continued`): a resonance of the design a
    few per cent off the measured one stalls a local fit of the raw errors.
    A local fit from the design values alone can end in a poor optimum of
    the baseline (one value driven to a bound while the others compensate),
    and every cause would then seem to explain the data. The random starts
    are drawn with a fixed seed (a diagnosis is repeatable) around the given
    values; each gets a short local fit, and the best of them a full one
    when it beats the fit from the given values.

    Parameters
    ----------
    fit : FrequencyFit
        The baseline (no effects).
    starts : int
        Random starts besides the given values.
    spread : float
        Standard deviation of the log-scale perturbation of every value.
    max_nfev : int
        Evaluations of the full local fits (half of them for the short ones).
    good_enough : float
        Cost at which the fit from the given values is kept without trying
        the random starts (the noise floor).
    """
    first = fit.fit_continued(fit.start_vectors()[0], max_nfev=max_nfev)
    if first.objective <= good_enough or starts <= 0:
        return first
    rng = np.random.default_rng(20260101)
    lo, hi = fit.bounds()
    x0 = fit.start_vectors()[0]
    X = np.clip(x0 + spread * rng.standard_normal((starts, x0.size)), lo + 1e-9, hi - 1e-9)
    # and from the given values with the model's resonances moved onto the measured ones (:mod:`.align`)
    aligned = aligned_start(fit, x0)
    if aligned is not None:
        X = np.vstack([aligned[None], X])
    short = fit.fit(x0s=X, grid=False, keep_starts=X.shape[0], max_nfev=max(10, max_nfev // 2))
    if short.objective >= first.objective:
        return first
    best = fit.fit(x0s=short.x[None], grid=False, keep_starts=1, max_nfev=max_nfev)
    best.wall_s += first.wall_s + short.wall_s
    best.alternative = first  # the optimum reached from the given values: structures are sought from it too
    return best
