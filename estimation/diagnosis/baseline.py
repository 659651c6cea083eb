"""Baseline fits of a diagnosis: the design's values fitted from several starts, or a lumped R-L-C from the data."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from pris_cosim.models.builtin import Model, lumped_rlc

from estimation.diagnosis.align import aligned_start
from estimation.diagnosis.cores import SharedBatch, helper_available
from estimation.diagnosis.fit import DiagnosisError, FitResult, FrequencyFit
from estimation.diagnosis.realign import realigned


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
                   max_nfev: int = 200, good_enough: float = 0.0, x0: np.ndarray | None = None,
                   floor: float | None = None) -> FitResult:
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
    x0 : numpy.ndarray, optional
        The start vector (default: the circuit at its values, the effects at
        their first grid start).
    floor : float, optional
        The noise floor's cost. Given, a fit that still misses the data
        beyond the noise at some point (above ``good_enough`` or not) has
        its modes moved onto where it misses (:func:`.realign.realigned`).
    """
    x0 = fit.start_vectors()[0] if x0 is None else np.asarray(x0, float)
    # with a helper process (:mod:`.cores`), the random starts' short fits are handed to it before the fit from the
    # given values runs here (the result does not depend on the order), and given up if that fit is good enough
    batch = _StartsFitted(fit, x0, starts, spread, max_nfev) if starts > 0 and helper_available() else None
    first = fit.fit_continued(x0, max_nfev=max_nfev)
    best = first
    if first.objective <= good_enough or starts <= 0:
        if batch is not None:
            batch.cancel()
    else:
        short = (batch or _StartsFitted(fit, x0, starts, spread, max_nfev)).result()
        if short.objective < first.objective:
            best = fit.fit(x0s=short.x[None], grid=False, keep_starts=1, max_nfev=max_nfev)
            best.wall_s += first.wall_s + short.wall_s
            best.alternative = first  # the optimum reached from the given values: structures are sought from it too
    if floor is not None:
        # a model at the noise in total may still miss a weak mode: its misfit is a point beyond what the noise
        # reaches anywhere in the record (:func:`.realign.misfits`), whatever the cost
        best = realigned(fit, best, floor, 0.0)
    return best


class _StartsFitted:
    """The short local fits from the random starts and the aligned start (:mod:`.align`), in the order of their
    screened costs, as :meth:`.fit.FrequencyFit.fit` with every start kept.

    The random starts are handed to the helper process first
    (:class:`.cores.SharedBatch`); the aligned start, which takes a
    resonance search to find, is found and fitted here meanwhile.
    """

    def __init__(self, fit: FrequencyFit, x0: np.ndarray, starts: int, spread: float, max_nfev: int) -> None:
        self.t0 = time.perf_counter()
        rng = np.random.default_rng(20260101)
        lo, hi = fit.bounds()
        self.fit, self.options = fit, {"max_nfev": max(10, max_nfev // 2)}
        X = np.clip(x0 + spread * rng.standard_normal((starts, x0.size)), lo + 1e-9, hi - 1e-9)
        r = fit.residuals_batch(X)
        self.screened = np.sum(r * r, axis=1)
        self.order = np.argsort(self.screened)
        self.batch = SharedBatch(_start_fitted, [(fit, X[i], self.options) for i in self.order])
        # and from the given values with the model's resonances moved onto the measured ones (row 0 of the starts)
        aligned = aligned_start(fit, x0)
        self.aligned = None if aligned is None else np.clip(aligned, lo + 1e-9, hi - 1e-9)
        if self.aligned is not None:
            r = fit.residuals_batch(self.aligned[None])
            self.screened = np.concatenate([np.sum(r * r, axis=1), self.screened])

    def cancel(self) -> None:
        """Give the random starts up unfitted (the helper process is free for the next batch)."""
        self.batch.cancel()

    def result(self) -> FitResult:
        """The best fit; of equal costs the first in the screened order."""
        shift = 0 if self.aligned is None else 1
        fitted = {} if self.aligned is None else {0: _start_fitted((self.fit, self.aligned, self.options))}
        fitted.update({int(i) + shift: res for i, res in zip(self.order, self.batch.result())})  # by row
        rank = {int(row): k for k, row in enumerate(np.argsort(self.screened))}
        best = min(fitted, key=lambda row: (fitted[row][1], rank[row]))
        return self.fit.result(fitted[best][0], None, len(fitted) + sum(n for _, _, n in fitted.values()),
                               time.perf_counter() - self.t0)


def _start_fitted(args: tuple[FrequencyFit, np.ndarray, dict[str, Any]]) -> tuple[np.ndarray, float, int]:
    """One short local fit from one start: ``(fit, x0, options)`` to ``(x, cost, nfev)``, the cost as
    :meth:`.fit.FrequencyFit.fit` ranks its starts (the sum of the squared residuals)."""
    fit, x0, options = args
    r = fit.fit(x0s=x0[None], grid=False, keep_starts=1, **options)
    return r.x, float(np.sum(fit.residuals(r.x) ** 2)), int(r.nfev)
