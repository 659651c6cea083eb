"""Generic error metrics of the thesis, vectorised over optimiser populations, and the time-domain costs.

Every function compares a *target* (1-D along the last axis) with an
*estimate* of the same length along the last axis; the estimate may carry
leading population dimensions ``(P, ...)``. Results have the estimate's
leading shape: ``(P,)`` for a population, a 0-d array for one estimate.

MSE (2.21), MAE (2.22), RMSE (2.23), MAPE (2.24), NRMSE by mean (2.25) and
by range (2.26), Pearson correlation (2.27), the correlation cost
``1 - rho`` of (4.31), (4.34); time domain: ``C^v_rmse`` (4.32)-(4.33) and
``C^v_rho`` (4.34).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Union

import numpy as np

ArrayLike = Union[np.ndarray, Sequence[float], float]
Responses = Mapping[str, np.ndarray]


# ====================================================================== helpers
def _pair(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Real target and estimate with equal last axes, masked along it."""
    y = np.asarray(target)
    yt = np.asarray(estimate)
    if np.iscomplexobj(y) or np.iscomplexobj(yt):
        raise ValueError("cost metrics take real data: take magnitudes (or log-magnitudes) of complex responses first")
    y, yt = y.astype(float), yt.astype(float)
    if y.ndim == 0 or yt.ndim == 0 or y.shape[-1] != yt.shape[-1]:
        raise ValueError(f"target and estimate must have the same last dimension (got {y.shape} and {yt.shape})")
    if mask is not None:
        m = np.asarray(mask, bool)
        if m.shape != y.shape[-1:]:
            raise ValueError(f"mask must have shape ({y.shape[-1]},) (got {m.shape})")
        y, yt = y[..., m], yt[..., m]
    if y.shape[-1] == 0:
        raise ValueError("no data points left to compare")
    return y, yt


def _finite_or_inf(cost: np.ndarray) -> np.ndarray:
    """Replace NaN costs (e.g. from ``inf - inf``) by ``inf`` so optimisers discard them."""
    cost = np.asarray(cost, float)
    return np.where(np.isnan(cost), np.inf, cost)


# ====================================================================== generic metrics
def mse(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Mean squared error, thesis (2.21): ``(1/N) sum (y_i - y~_i)^2``.

    Parameters
    ----------
    target : array_like
        ``(N,)`` target data ``y`` (any unit).
    estimate : array_like
        ``(..., N)`` model output ``y~``, same unit.
    mask : array_like of bool, optional
        ``(N,)``: points to keep; ``N`` counts the kept points.

    Returns
    -------
    numpy.ndarray
        Leading shape of ``estimate``; unit squared.
    """
    y, yt = _pair(target, estimate, mask)
    return np.mean((y - yt) ** 2, axis=-1)


def mae(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Mean absolute error, thesis (2.22): ``(1/N) sum |y_i - y~_i|`` (unit of the data).

    Parameters are as for :func:`mse`.
    """
    y, yt = _pair(target, estimate, mask)
    return np.mean(np.abs(y - yt), axis=-1)


def rmse(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Root mean squared error, thesis (2.23): ``sqrt((1/N) sum (y_i - y~_i)^2)`` (unit of the data).

    Parameters are as for :func:`mse`.
    """
    return np.sqrt(mse(target, estimate, mask))


def mape(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Mean absolute percentage error, thesis (2.24): ``(1/N) sum |y_i - y~_i| / y_i * 100``, %.

    As written in the thesis the denominator is ``y_i`` itself (not
    ``|y_i|``), so the metric is meant for positive data; zeros in the
    target give ``inf``. Parameters are as for :func:`mse`.
    """
    y, yt = _pair(target, estimate, mask)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _finite_or_inf(np.mean(np.abs(y - yt) / y, axis=-1) * 100.0)


def nrmse_mean(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """RMSE normalised by the target mean, thesis (2.25): ``C_RMSE / mu_y`` (dimensionless).

    Parameters are as for :func:`mse`.
    """
    y, yt = _pair(target, estimate, mask)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _finite_or_inf(np.sqrt(np.mean((y - yt) ** 2, axis=-1)) / np.mean(y, axis=-1))


def nrmse_range(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """RMSE normalised by the target range, thesis (2.26): ``C_RMSE / (max y - min y)`` (dimensionless).

    Parameters are as for :func:`mse`.
    """
    y, yt = _pair(target, estimate, mask)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _finite_or_inf(np.sqrt(np.mean((y - yt) ** 2, axis=-1)) / np.ptp(y, axis=-1))


def pearson(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Pearson correlation coefficient, thesis (2.27).

    ``rho = 1/(N-1) sum ((y_i - mu_y)/sigma_y) ((y~_i - mu_y~)/sigma_y~)``
    with sample standard deviations. ``rho`` is undefined when either
    waveform is constant; it is then taken as 0 (no linear relationship),
    so the correlation cost of a constant waveform is 1.

    Parameters are as for :func:`mse`.

    Returns
    -------
    numpy.ndarray
        In ``[-1, 1]``, leading shape of ``estimate``.
    """
    y, yt = _pair(target, estimate, mask)
    y, yt = np.broadcast_arrays(y, yt)
    dy = y - y.mean(axis=-1, keepdims=True)
    dyt = yt - yt.mean(axis=-1, keepdims=True)
    norm = np.sqrt(np.sum(dy**2, axis=-1) * np.sum(dyt**2, axis=-1))
    num = np.sum(dy * dyt, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(norm > 0, num / np.where(norm > 0, norm, 1.0), 0.0)
    return np.clip(rho, -1.0, 1.0)


def correlation_cost(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Correlation cost ``-rho(y, y~) + 1``, the form of thesis (4.31), (4.34).

    0 for a perfect positive linear relationship, 1 for none, 2 for a
    perfect inverse one. Parameters are as for :func:`mse`.
    """
    return 1.0 - pearson(target, estimate, mask)


# ====================================================================== time domain
def v_rmse(target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Time-domain RMSE cost ``C^v_rmse``, thesis (4.32)-(4.33).

    ``sqrt((1/N_k) sum_k (v_in(t_k) - v~_in(t_k))^2)``

    Parameters
    ----------
    target : array_like
        ``(N,)`` target voltage, V.
    estimate : array_like
        ``(..., N)`` estimated voltage, V, same sample times.

    Returns
    -------
    numpy.ndarray
        V.
    """
    return _finite_or_inf(rmse(target, estimate))


def v_correlation(target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Time-domain correlation cost ``C^v_rho = -rho{v_in, v~_in} + 1``, thesis (4.34).

    Parameters are as for :func:`v_rmse`; the result lies in ``[0, 2]``.
    """
    return correlation_cost(target, estimate)


