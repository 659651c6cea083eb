"""Cost objects that an estimation loop calls as ``cost(target, estimate_population) -> (P,)``."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from estimation.costs.emd import Decomposer, emd_correlation, emd_nrmse, iemd_correlation, iemd_nrmse
from estimation.costs.frequency import (TABLE_5_1_BANDS, _select, log_magnitude_sse, thesis_masks, wnrmse,
    z_correlation, z_rmse)
from estimation.costs.metrics import ArrayLike, Responses, _finite_or_inf, v_correlation, v_rmse


# ====================================================================== cost objects
@runtime_checkable
class CostFunction(Protocol):
    """What an estimation loop calls: ``cost(target, estimate) -> (P,)``.

    ``target`` is the measured/reference data (a response mapping or a
    waveform), ``estimate`` the population's model output of the same
    kind with a leading ``(P,)`` axis. Non-finite costs come back as ``inf``.
    """

    def __call__(self, target: Any, estimate: Any) -> np.ndarray: ...



def _check_metric(metric: str, allowed: Sequence[str]) -> None:
    if metric not in allowed:
        raise ValueError(f"metric must be one of {', '.join(allowed)} (got {metric!r})")


@dataclass(frozen=True)
class LogMagnitudeCost:
    """Log-magnitude frequency-response cost over a set of responses.

    ``metric="sse"``: thesis (4.21), ``sum_r sum_k epsilon_r^2``;
    ``metric="rmse"``: ``sum_r C^z_rmse`` (4.29) (one response: (4.29) itself).

    Parameters
    ----------
    metric : {"sse", "rmse"}
    responses : sequence of str, optional
        The set Gamma (4.18), Table 4.3; default every target response.
    masks : mapping, optional
        Response name to ``(F,)`` bool points to keep.
    """

    metric: str = "sse"
    responses: Sequence[str] | None = None
    masks: Mapping[str, ArrayLike] | None = None

    def __post_init__(self) -> None:
        _check_metric(self.metric, ("sse", "rmse"))

    def __call__(self, target: Responses, estimate: Responses) -> np.ndarray:
        if self.metric == "sse":
            return log_magnitude_sse(target, estimate, self.responses, self.masks)
        total: Any = 0.0
        for n in _select(target, estimate, self.responses):
            m = None if self.masks is None or n not in self.masks else self.masks[n]
            total = total + z_rmse(target[n], estimate[n], m)
        return _finite_or_inf(total)


@dataclass(frozen=True)
class CorrelationCost:
    """Frequency-domain correlation cost ``sum_r C^z_rho`` (thesis (4.31) per response).

    Parameters
    ----------
    responses : sequence of str, optional
    on : {"magnitude", "log-magnitude"}
        See :func:`z_correlation`.
    masks : mapping, optional
    """

    responses: Sequence[str] | None = None
    on: str = "magnitude"
    masks: Mapping[str, ArrayLike] | None = None

    def __call__(self, target: Responses, estimate: Responses) -> np.ndarray:
        total: Any = 0.0
        for n in _select(target, estimate, self.responses):
            m = None if self.masks is None or n not in self.masks else self.masks[n]
            total = total + z_correlation(target[n], estimate[n], self.on, m)
        return _finite_or_inf(total)


@dataclass(frozen=True)
class WNRMSECost:
    """Weighted normalised RMSE cost of thesis (5.8)-(5.11); see :func:`wnrmse`.

    Parameters
    ----------
    frequency : array_like
        ``(F,)``, Hz.
    weight : float
        ``Lambda``.
    bands : mapping, optional
        Default Table 5.1.
    masks : mapping, optional
        Default none; :func:`thesis_masks` gives the LVSC omission.
    normalisation : {"magnitude", "log-magnitude", "none"}
    outside : float
    responses : sequence of str, optional
    """

    frequency: np.ndarray
    weight: float = 1.0
    bands: Mapping[str, tuple[float, float]] | None = None
    masks: Mapping[str, ArrayLike] | None = None
    normalisation: str = "magnitude"
    outside: float = 1.0
    responses: Sequence[str] | None = None

    @classmethod
    def thesis(cls, frequency: ArrayLike, weight: float = 1.0, **kwargs: Any) -> "WNRMSECost":
        """Table 5.1 bands and the LVSC-below-50-Hz omission of thesis 5.2.1."""
        f = np.asarray(frequency, float)
        return cls(f, weight, TABLE_5_1_BANDS, thesis_masks(f), **kwargs)

    def __call__(self, target: Responses, estimate: Responses) -> np.ndarray:
        return wnrmse(target, estimate, self.frequency, self.weight, self.bands, self.masks,
                      self.normalisation, self.outside, self.responses)


@dataclass(frozen=True)
class TimeCost:
    """Time-domain cost: ``C^v_rmse`` (4.32) or ``C^v_rho`` (4.34) on ``(N,)`` vs ``(P, N)`` voltages, V."""

    metric: str = "rmse"

    def __post_init__(self) -> None:
        _check_metric(self.metric, ("rmse", "rho"))

    def __call__(self, target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
        return v_rmse(target, estimate) if self.metric == "rmse" else v_correlation(target, estimate)


def _population(estimate: ArrayLike, n: int) -> tuple[np.ndarray, tuple[int, ...]]:
    v = np.asarray(estimate, float)
    if v.ndim == 0 or v.shape[-1] != n:
        raise ValueError(f"estimate must end in {n} samples like the target (got shape {v.shape})")
    return v.reshape(-1, n), v.shape[:-1]


@dataclass(frozen=True)
class EMDCost:
    """EMD cost: ``C^m_nrmse`` (4.39) or ``C^m_rho`` (4.42).

    The target's decomposition is cached; every estimate is decomposed.

    Parameters
    ----------
    metric : {"nrmse", "rho"}
    decomposer : Decomposer
    before_residual : bool
        Padding position for ``"nrmse"`` (see :func:`pad_sets`).
    """

    metric: str = "nrmse"
    decomposer: Decomposer = field(default_factory=Decomposer)
    before_residual: bool = False

    def __post_init__(self) -> None:
        _check_metric(self.metric, ("nrmse", "rho"))

    def __call__(self, target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
        g = self.decomposer.cached(target)
        pop, lead = _population(estimate, g.shape[1])
        out = np.empty(pop.shape[0])
        for i, v in enumerate(pop):
            if not np.all(np.isfinite(v)):
                out[i] = np.inf
                continue
            gt = self.decomposer(v)
            out[i] = emd_nrmse(g, gt, self.before_residual) if self.metric == "nrmse" else emd_correlation(g, gt)
        return _finite_or_inf(out.reshape(lead))


@dataclass(frozen=True)
class IEMDCost:
    """Inferred-EMD cost: ``C^i_nrmse`` (4.45) or ``C^i_rho`` (4.46).

    Only the target is decomposed (once, cached); every estimate is
    represented by its inferred IMFs (4.43), fully vectorised.

    Parameters
    ----------
    metric : {"nrmse", "rho"}
    decomposer : Decomposer
    """

    metric: str = "nrmse"
    decomposer: Decomposer = field(default_factory=Decomposer)

    def __post_init__(self) -> None:
        _check_metric(self.metric, ("nrmse", "rho"))

    def __call__(self, target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
        g = self.decomposer.cached(target)
        if self.metric == "nrmse":
            return iemd_nrmse(g, estimate)
        return _finite_or_inf(iemd_correlation(g, estimate))


def penalise(cost: ArrayLike, feasible: ArrayLike, penalty: float = 1e6) -> np.ndarray:
    """Add ``penalty`` to the costs of infeasible members (e.g. ``Evaluation.passive`` is False).

    Parameters
    ----------
    cost : array_like
        ``(P,)`` costs.
    feasible : array_like of bool
        ``(P,)``.
    penalty : float
        Added to infeasible costs (same unit as the cost).

    Returns
    -------
    numpy.ndarray
    """
    c = np.asarray(cost, float)
    return np.where(np.asarray(feasible, bool), c, c + penalty)

