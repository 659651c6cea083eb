"""Cost functions of the thesis, vectorised over optimiser populations.

Every function compares a *target* (measured or reference data, 1-D along
the last axis) with an *estimate* of the same length along the last axis;
the estimate may carry leading population dimensions ``(P, ...)``. Results
have the estimate's leading shape: ``(P,)`` for a population, a 0-d array
for a single estimate.

Sections (thesis equation numbers in brackets):

- generic metrics: MSE (2.21), MAE (2.22), RMSE (2.23), MAPE (2.24),
  NRMSE by mean (2.25) and by range (2.26), Pearson correlation (2.27) and
  the correlation cost ``1 - rho`` of (4.31), (4.34);
- frequency domain: log-magnitude error (4.20), (4.30), (5.9); its sum of
  squares over responses (4.21); ``C^z_rmse`` (4.29); ``C^z_rho`` (4.31);
  the weighted normalised RMSE ``C_wnrmse`` with band weights (5.8)-(5.11)
  and the bands of Table 5.1;
- time domain: ``C^v_rmse`` (4.32)-(4.33), ``C^v_rho`` (4.34);
- empirical mode decomposition: ``C^m_nrmse`` (4.39)-(4.41) with zero
  padding, ``C^m_rho`` (4.42) with truncation, and the inferred-EMD costs
  ``C^i_nrmse`` (4.45), ``C^i_rho`` (4.46) built on the inferred IMFs (4.43);
- :class:`CostFunction` objects that an estimation loop calls as
  ``cost(target, estimate_population) -> (P,)``.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, Union, runtime_checkable

import numpy as np

ArrayLike = Union[np.ndarray, Sequence[float], float]
Responses = Mapping[str, np.ndarray]

#: Weighting bands of thesis Table 5.1, Hz, by response name (order of (5.4)).
TABLE_5_1_BANDS: dict[str, tuple[float, float]] = {
    "Zlvoc": (0.8e3, 10e3),
    "Zlvsc": (2e3, 10e3),
    "Zhvoc": (2e3, 10e3),
    "Zhvsc": (0.8e3, 10e3),
    "Rlvhv": (2e3, 10e3),
    "Rhvlv": (2e3, 10e3),
}
#: Estimation band of thesis 5.2.1, Hz.
ESTIMATION_BAND: tuple[float, float] = (10.0, 10e3)
#: LVSC data below this frequency is omitted (thesis 5.2.1), Hz.
LVSC_OMIT_BELOW = 50.0

EMD_METHODS = ("emd", "eemd", "ceemdan")


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


# ====================================================================== frequency domain
def log_magnitude_error(target: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Point-by-point log-magnitude error, thesis (4.20), (4.30), (5.9).

    ``epsilon(w_k) = log10 |gamma(w_k)| - log10 |gamma~(w_k)|``

    Parameters
    ----------
    target : array_like
        ``(F,)`` complex (or real) target response ``gamma`` (Ohm or V/V).
    estimate : array_like
        ``(..., F)`` estimated response ``gamma~``, same unit.

    Returns
    -------
    numpy.ndarray
        ``(..., F)``, decades.
    """
    g, gt = np.asarray(target), np.asarray(estimate)
    if g.ndim == 0 or gt.ndim == 0 or g.shape[-1] != gt.shape[-1]:
        raise ValueError(f"target and estimate must have the same number of frequencies (got {g.shape} and {gt.shape})")
    with np.errstate(divide="ignore"):
        return np.log10(np.abs(g)) - np.log10(np.abs(gt))


def _select(target: Responses, estimate: Responses, names: Sequence[str] | None) -> list[str]:
    chosen = list(names) if names is not None else list(target)
    for n in chosen:
        if n not in target:
            raise ValueError(f"response {n!r} is missing from the target (has: {', '.join(target)})")
        if n not in estimate:
            raise ValueError(f"response {n!r} is missing from the estimate (has: {', '.join(estimate)})")
    if not chosen:
        raise ValueError("no responses to compare")
    return chosen


def _as_mask(mask: ArrayLike | None, size: int, what: str) -> np.ndarray:
    if mask is None:
        return np.ones(size, bool)
    m = np.asarray(mask, bool)
    if m.shape != (size,):
        raise ValueError(f"mask of {what} must have shape ({size},) (got {m.shape})")
    return m


def _mask_for(masks: Mapping[str, ArrayLike] | None, name: str, size: int) -> np.ndarray:
    return _as_mask(None if masks is None else masks.get(name), size, f"response {name!r}")


def log_magnitude_sse(
    target: Responses, estimate: Responses, names: Sequence[str] | None = None,
    masks: Mapping[str, ArrayLike] | None = None,
) -> np.ndarray:
    """Sum over responses of summed squared log-magnitude errors, thesis (4.21).

    ``C = sum_r sum_k epsilon_r(w_k)^2`` with ``epsilon_r`` from (4.20).
    As written, (4.21) is not divided by the number of points.

    Parameters
    ----------
    target : mapping
        Response name to ``(F,)`` complex target (Ohm or V/V).
    estimate : mapping
        Response name to ``(..., F)`` estimates (e.g. ``ResponseSet.evaluate``).
    names : sequence of str, optional
        Responses in the set Gamma (4.18) (default: every target response).
    masks : mapping, optional
        Response name to ``(F,)`` bool: points to keep.

    Returns
    -------
    numpy.ndarray
        Leading shape of the estimates, decades squared.
    """
    total: Any = 0.0
    for n in _select(target, estimate, names):
        e = log_magnitude_error(target[n], estimate[n])
        m = _mask_for(masks, n, e.shape[-1])
        total = total + np.sum(e[..., m] ** 2, axis=-1)
    return _finite_or_inf(total)


def z_rmse(target: ArrayLike, estimate: ArrayLike, mask: ArrayLike | None = None) -> np.ndarray:
    """Frequency-domain RMSE cost ``C^z_rmse``, thesis (4.29)-(4.30).

    ``sqrt((1/N_k) sum_k (log10 |Z(w_k)| - log10 |Z~(w_k)|)^2)``

    Parameters
    ----------
    target : array_like
        ``(F,)`` complex target impedance, Ohm.
    estimate : array_like
        ``(..., F)`` estimated impedance, Ohm.
    mask : array_like of bool, optional
        ``(F,)`` points to keep (``N_k`` counts them).

    Returns
    -------
    numpy.ndarray
        Decades.
    """
    e = log_magnitude_error(target, estimate)
    m = _as_mask(mask, e.shape[-1], "the response")
    return _finite_or_inf(np.sqrt(np.mean(e[..., m] ** 2, axis=-1)))


def _transform(response: ArrayLike, on: str) -> np.ndarray:
    mag = np.abs(np.asarray(response))
    if on == "magnitude":
        return mag
    if on == "log-magnitude":
        with np.errstate(divide="ignore"):
            return np.log10(mag)
    raise ValueError(f"on must be 'magnitude' or 'log-magnitude' (got {on!r})")


def z_correlation(target: ArrayLike, estimate: ArrayLike, on: str = "magnitude", mask: ArrayLike | None = None) -> np.ndarray:
    """Frequency-domain correlation cost ``C^z_rho = -rho{Z, Z~} + 1``, thesis (4.31).

    The thesis correlates ``Z_i(w)`` with ``Z~_i(w)``; the Pearson
    coefficient (2.27) is defined for real data, so the magnitudes are
    correlated (``on="magnitude"``, default) or, matching the errors of
    (4.30), their logarithms (``on="log-magnitude"``).

    Parameters
    ----------
    target : array_like
        ``(F,)`` complex target impedance, Ohm.
    estimate : array_like
        ``(..., F)`` estimated impedance, Ohm.
    on : {"magnitude", "log-magnitude"}
    mask : array_like of bool, optional
        ``(F,)`` points to keep.

    Returns
    -------
    numpy.ndarray
        In ``[0, 2]``.
    """
    return correlation_cost(_transform(target, on), _transform(estimate, on), mask)


def band_weights(
    frequency: ArrayLike, band: tuple[float, float], weight: float, outside: float = 1.0
) -> np.ndarray:
    """Weighting vector ``lambda_r(w)`` of thesis (5.10).

    ``lambda_r(w) = Lambda (u(w - w_low) - u(w - w_high))`` inside the band
    ``f_low <= f <= f_high`` (both edges included). Taken literally, (5.10)
    is zero outside the band, which would make ``Lambda`` a mere overall
    factor; the thesis sweeps ``Lambda`` from 1 to 20 to emphasise the
    resonances, so by default the errors outside the band keep weight 1
    (``outside=1``). ``outside=0`` gives the literal window.

    Parameters
    ----------
    frequency : array_like
        ``(F,)`` frequencies, Hz.
    band : (float, float)
        ``(f_low, f_high)``, Hz (Table 5.1).
    weight : float
        ``Lambda`` (dimensionless, >= 0).
    outside : float
        Weight outside the band.

    Returns
    -------
    numpy.ndarray
        ``(F,)`` weights.
    """
    f = np.asarray(frequency, float)
    lo, hi = band
    if not lo <= hi:
        raise ValueError(f"weighting band must have f_low <= f_high (got {lo:g}, {hi:g} Hz)")
    if weight < 0 or outside < 0:
        raise ValueError(f"weights must be non-negative (got Lambda={weight:g}, outside={outside:g})")
    return np.where((f >= lo) & (f <= hi), float(weight), float(outside))


def omit_below(frequency: ArrayLike, f_min: float = LVSC_OMIT_BELOW) -> np.ndarray:
    """Mask keeping ``f >= f_min`` (thesis 5.2.1 omits LVSC data below 50 Hz).

    Parameters
    ----------
    frequency : array_like
        ``(F,)``, Hz.
    f_min : float
        Hz.

    Returns
    -------
    numpy.ndarray
        ``(F,)`` bool, True where kept.
    """
    return np.asarray(frequency, float) >= f_min


def thesis_masks(frequency: ArrayLike) -> dict[str, np.ndarray]:
    """Masks of thesis 5.2.1 by response name: ``Zlvsc`` without its data below 50 Hz."""
    return {"Zlvsc": omit_below(frequency, LVSC_OMIT_BELOW)}


def response_range(response: ArrayLike, normalisation: str = "magnitude", mask: ArrayLike | None = None) -> float:
    """Normalisation constant ``psi_r`` of thesis (5.11).

    ``psi_r = max |gamma_r(w)| - min |gamma_r(w)|`` over the measured
    response (``normalisation="magnitude"``, as written). Because the errors
    (5.9) are in decades, ``"log-magnitude"`` (range of ``log10 |gamma_r|``)
    is offered as the scale-consistent alternative; ``"none"`` gives 1.

    Parameters
    ----------
    response : array_like
        ``(F,)`` measured response (Ohm or V/V).
    normalisation : {"magnitude", "log-magnitude", "none"}
    mask : array_like of bool, optional
        ``(F,)``: points used in the cost.

    Returns
    -------
    float
        Ohm or V/V for ``"magnitude"``, decades for ``"log-magnitude"``.
    """
    if normalisation == "none":
        return 1.0
    if normalisation not in ("magnitude", "log-magnitude"):
        raise ValueError(f"normalisation must be 'magnitude', 'log-magnitude' or 'none' (got {normalisation!r})")
    x = _transform(response, normalisation)
    if mask is not None:
        x = x[np.asarray(mask, bool)]
    psi = float(np.ptp(x))
    return psi if psi > 0 else 1.0


def wnrmse(
    target: Responses,
    estimate: Responses,
    frequency: ArrayLike,
    weight: float = 1.0,
    bands: Mapping[str, tuple[float, float]] | None = None,
    masks: Mapping[str, ArrayLike] | None = None,
    normalisation: str = "magnitude",
    outside: float = 1.0,
    names: Sequence[str] | None = None,
) -> np.ndarray:
    """Weighted normalised RMSE over a set of responses, thesis (5.8)-(5.11).

    ``C_wnrmse = sum_r (1/psi_r) sqrt((1/N_k) sum_k lambda_r(w_k) epsilon_r(w_k)^2)``

    with ``epsilon_r`` the log-magnitude error (5.9), ``lambda_r`` the band
    weights (5.10) (:func:`band_weights`) and ``psi_r`` the range (5.11)
    (:func:`response_range`). ``N_k`` counts the points kept by the mask
    of response ``r``.

    Parameters
    ----------
    target : mapping
        Response name to ``(F,)`` complex measured response.
    estimate : mapping
        Response name to ``(..., F)`` estimates.
    frequency : array_like
        ``(F,)``, Hz (log-spaced in the thesis).
    weight : float
        ``Lambda`` (1 to 20 in the thesis).
    bands : mapping, optional
        Response name to ``(f_low, f_high)``, Hz; default Table 5.1
        (:data:`TABLE_5_1_BANDS`). Responses without a band get weight 1.
    masks : mapping, optional
        Response name to ``(F,)`` bool points to keep, e.g.
        :func:`thesis_masks` (LVSC below 50 Hz omitted).
    normalisation : {"magnitude", "log-magnitude", "none"}
        How ``psi_r`` is computed (see :func:`response_range`).
    outside : float
        Weight outside the bands (see :func:`band_weights`).
    names : sequence of str, optional
        Responses to use (default every target response).

    Returns
    -------
    numpy.ndarray
        Leading shape of the estimates.
    """
    bands = TABLE_5_1_BANDS if bands is None else bands
    f = np.asarray(frequency, float)
    total: Any = 0.0
    for n in _select(target, estimate, names):
        e = log_magnitude_error(target[n], estimate[n])
        if e.shape[-1] != f.size:
            raise ValueError(f"response {n!r} has {e.shape[-1]} points but there are {f.size} frequencies")
        lam = band_weights(f, bands[n], weight, outside) if n in bands else np.ones(f.size)
        m = _mask_for(masks, n, f.size)
        psi = response_range(target[n], normalisation, m)
        total = total + np.sqrt(np.mean(lam[m] * e[..., m] ** 2, axis=-1)) / psi
    return _finite_or_inf(total)


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


# ====================================================================== empirical mode decomposition
@dataclass(frozen=True)
class Decomposer:
    """EMD, EEMD or CEEMDAN (PyEMD) with a small cache of target decompositions.

    The result of a decomposition is the set Gamma of (4.37): the IMFs
    followed by the residual, as rows that add up to the signal. A
    residual PyEMD leaves below ``1e-8`` of the signal's peak is folded
    into the last row instead of becoming a near-zero waveform.

    Parameters
    ----------
    method : {"emd", "eemd", "ceemdan"}
    seed : int
        Noise seed of EEMD/CEEMDAN, set before every decomposition so equal
        signals decompose equally.
    trials : int
        Ensemble size of EEMD/CEEMDAN.
    max_imf : int
        Maximum number of IMFs (-1: all).
    noise_width : float
        EEMD noise amplitude relative to the signal range.
    epsilon : float
        CEEMDAN noise scale.
    cache_size : int
        Number of decompositions kept by :meth:`cached` (least recently used
        dropped first).
    """

    method: str = "emd"
    seed: int = 0
    trials: int = 100
    max_imf: int = -1
    noise_width: float = 0.05
    epsilon: float = 0.005
    cache_size: int = 4
    _cache: "OrderedDict[tuple[Any, ...], np.ndarray]" = field(default_factory=OrderedDict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.method not in EMD_METHODS:
            raise ValueError(f"method must be one of {', '.join(EMD_METHODS)} (got {self.method!r})")
        if self.trials < 1:
            raise ValueError(f"trials must be at least 1 (got {self.trials})")

    def __call__(self, signal: ArrayLike) -> np.ndarray:
        """Decompose ``signal`` (``(N,)``, any unit) into ``(N_r, N)`` IMFs plus residual."""
        s = self._check(signal)
        comps = np.atleast_2d(np.asarray(self._run(s), float))
        residual = s - comps.sum(axis=0)
        if np.max(np.abs(residual), initial=0.0) > 1e-8 * max(np.max(np.abs(s)), 1e-300):
            return np.vstack([comps, residual])
        comps[-1] += residual
        return comps

    def cached(self, signal: ArrayLike) -> np.ndarray:
        """:meth:`__call__` with the result kept for the next call with equal data (the target)."""
        s = self._check(signal)
        key = (s.shape, hashlib.blake2b(s.tobytes(), digest_size=16).hexdigest())
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        out = self(s)
        out.setflags(write=False)
        self._cache[key] = out
        while len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return out

    @staticmethod
    def _check(signal: ArrayLike) -> np.ndarray:
        s = np.ascontiguousarray(signal, dtype=float)
        if s.ndim != 1 or s.size < 4:
            raise ValueError(f"EMD needs a 1-D signal of at least 4 samples (got shape {s.shape})")
        if not np.all(np.isfinite(s)):
            raise ValueError("EMD needs a finite signal")
        return s

    def _run(self, s: np.ndarray) -> np.ndarray:
        from PyEMD import CEEMDAN, EEMD, EMD

        if self.method == "emd":
            return EMD().emd(s, max_imf=self.max_imf)
        if self.method == "eemd":
            eemd = EEMD(trials=self.trials, noise_width=self.noise_width, parallel=False)
            eemd.noise_seed(self.seed)
            return eemd.eemd(s, max_imf=self.max_imf)
        ceemdan = CEEMDAN(trials=self.trials, epsilon=self.epsilon, parallel=False)
        ceemdan.noise_seed(self.seed)
        return ceemdan.ceemdan(s, max_imf=self.max_imf)


def _as_set(waveforms: ArrayLike, what: str) -> np.ndarray:
    w = np.asarray(waveforms, float)
    if w.ndim != 2 or w.shape[0] == 0:
        raise ValueError(f"{what} must be a non-empty (N_r, N) set of waveforms (got shape {w.shape})")
    return w


def pad_sets(target_set: ArrayLike, estimate_set: ArrayLike, before_residual: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Zero-pad the smaller IMF set to the size of the larger (text of thesis 4.2.5.3, for (4.39)).

    Parameters
    ----------
    target_set, estimate_set : array_like
        ``(N_r, N)`` and ``(N~_r, N)`` sets (IMFs then residual).
    before_residual : bool
        False (as written): zero waveforms are appended after the residual.
        True: they are inserted before the residual, so residual meets residual.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        Both ``(max(N_r, N~_r), N)``.
    """
    a, b = _as_set(target_set, "target set"), _as_set(estimate_set, "estimate set")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"IMF sets have different lengths ({a.shape[1]} and {b.shape[1]} samples)")
    n = max(a.shape[0], b.shape[0])
    return _pad(a, n, before_residual), _pad(b, n, before_residual)


def _pad(w: np.ndarray, n: int, before_residual: bool) -> np.ndarray:
    zeros = np.zeros((n - w.shape[0], w.shape[1]))
    if before_residual:
        return np.vstack([w[:-1], zeros, w[-1:]])
    return np.vstack([w, zeros])


def truncate_sets(target_set: ArrayLike, estimate_set: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Truncate the larger IMF set to the size ``N_s`` of the smaller (for thesis (4.42)).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        The first ``N_s`` waveforms of each set, ``(N_s, N)``.
    """
    a, b = _as_set(target_set, "target set"), _as_set(estimate_set, "estimate set")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"IMF sets have different lengths ({a.shape[1]} and {b.shape[1]} samples)")
    n = min(a.shape[0], b.shape[0])
    return a[:n], b[:n]


def imf_ranges(target_set: ArrayLike) -> np.ndarray:
    """Normalisation constants ``psi_r = max gamma_r - min gamma_r``, thesis (4.41).

    The constant is omitted (taken as 1) where it is zero: a zero waveform
    padded into the target set, as the thesis states, or a constant one.

    Returns
    -------
    numpy.ndarray
        ``(N_r,)``, unit of the waveforms.
    """
    psi = np.ptp(_as_set(target_set, "target set"), axis=-1)
    return np.where(psi > 0, psi, 1.0)


def emd_nrmse(target_set: ArrayLike, estimate_set: ArrayLike, before_residual: bool = False) -> float:
    """EMD cost ``C^m_nrmse``, thesis (4.39)-(4.41).

    ``sum_r (1/psi_r) sqrt((1/N_k) sum_k (gamma_r(t_k) - gamma~_r(t_k))^2)``
    over the zero-padded sets (:func:`pad_sets`).

    Parameters
    ----------
    target_set, estimate_set : array_like
        ``(N_r, N)``, ``(N~_r, N)`` IMFs plus residual.
    before_residual : bool
        Where padding goes (see :func:`pad_sets`).

    Returns
    -------
    float
        Dimensionless.
    """
    a, b = pad_sets(target_set, estimate_set, before_residual)
    return float(np.sum(np.sqrt(np.mean((a - b) ** 2, axis=-1)) / imf_ranges(a)))


def emd_correlation(target_set: ArrayLike, estimate_set: ArrayLike) -> float:
    """EMD correlation cost ``C^m_rho``, thesis (4.42).

    ``(1/N_s) sum_{r=1}^{N_s} (-rho{gamma_r, gamma~_r} + 1)`` over the sets
    truncated to the smaller size ``N_s`` (:func:`truncate_sets`).

    Returns
    -------
    float
        In ``[0, 2]``.
    """
    a, b = truncate_sets(target_set, estimate_set)
    return float(np.mean(correlation_cost(a, b)))


def inferred_imfs(target_set: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Inferred IMFs of an estimated waveform, thesis (4.43)-(4.44).

    ``v~^i_r(t) = v~(t) - sum_{k != r} gamma_k(t)``: the estimate is never
    decomposed; every target waveform but the ``r``-th is subtracted from
    it, so the set always has the target's size ``N_r``.

    Parameters
    ----------
    target_set : array_like
        ``(N_r, N)`` target IMFs plus residual (4.37).
    estimate : array_like
        ``(..., N)`` estimated waveform(s) ``v~``.

    Returns
    -------
    numpy.ndarray
        ``(..., N_r, N)``.
    """
    g = _as_set(target_set, "target set")
    v = np.asarray(estimate, float)
    if v.ndim == 0 or v.shape[-1] != g.shape[1]:
        raise ValueError(f"estimate must end in {g.shape[1]} samples (got shape {v.shape})")
    others = g.sum(axis=0) - g  # sum over k != r, row r
    return v[..., None, :] - others


def iemd_nrmse(target_set: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Inferred-EMD cost ``C^i_nrmse``, thesis (4.45) with (4.40), (4.41), (4.43).

    ``sum_r (1/psi_r) sqrt((1/N_k) sum_k (gamma_r(t_k) - v~^i_r(t_k))^2)``.
    Since ``gamma_r - v~^i_r = sum_k gamma_k - v~ = v - v~`` for every
    ``r``, this equals ``C^v_rmse * sum_r 1/psi_r`` (the thesis's
    observation that both converge to the same parameters).

    Parameters
    ----------
    target_set : array_like
        ``(N_r, N)`` target IMFs plus residual.
    estimate : array_like
        ``(..., N)`` estimated waveform(s).

    Returns
    -------
    numpy.ndarray
        Leading shape of ``estimate``.
    """
    g = _as_set(target_set, "target set")
    v = np.asarray(estimate, float)
    if v.ndim == 0 or v.shape[-1] != g.shape[1]:
        raise ValueError(f"estimate must end in {g.shape[1]} samples (got shape {v.shape})")
    # gamma_r - v~^i_r = sum_k gamma_k - v~ for every r: one RMS instead of N_r (same value)
    per = np.sqrt(np.mean((g.sum(axis=0) - v) ** 2, axis=-1))
    return _finite_or_inf(per * np.sum(1.0 / imf_ranges(g)))


def iemd_correlation(target_set: ArrayLike, estimate: ArrayLike) -> np.ndarray:
    """Inferred-EMD correlation cost ``C^i_rho``, thesis (4.46).

    ``sum_{r=1}^{N_r} (-rho{gamma_r, v~^i_r} + 1)`` -- a sum, without the
    ``1/N_s`` of (4.42), as written.

    Returns
    -------
    numpy.ndarray
        In ``[0, 2 N_r]``, leading shape of ``estimate``.
    """
    g = _as_set(target_set, "target set")
    v = np.asarray(estimate, float)
    if v.ndim == 0 or v.shape[-1] != g.shape[1]:
        raise ValueError(f"estimate must end in {g.shape[1]} samples (got shape {v.shape})")
    # v~^i_r = gamma_r + d with d = v~ - sum_k gamma_k: the correlations from (co)variances, no (N_r, N) copies
    gc = g - g.mean(axis=-1, keepdims=True)
    d = v - g.sum(axis=0)
    dc = d - d.mean(axis=-1, keepdims=True)
    n = g.shape[1]
    var_g = np.sum(gc ** 2, axis=-1) / n  # (N_r,)
    cov_gd = np.einsum("...k,rk->...r", dc, gc) / n  # (..., N_r)
    var_d = np.sum(dc ** 2, axis=-1)[..., None] / n
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = (var_g + cov_gd) / np.sqrt(var_g * np.maximum(var_g + 2 * cov_gd + var_d, 0.0))
    rho = np.where(np.isfinite(rho), np.clip(rho, -1.0, 1.0), 0.0)
    return np.sum(1.0 - rho, axis=-1)


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


__all__ = [
    "TABLE_5_1_BANDS", "ESTIMATION_BAND", "LVSC_OMIT_BELOW", "EMD_METHODS",
    "mse", "mae", "rmse", "mape", "nrmse_mean", "nrmse_range", "pearson", "correlation_cost",
    "log_magnitude_error", "log_magnitude_sse", "z_rmse", "z_correlation", "band_weights", "omit_below",
    "thesis_masks", "response_range", "wnrmse", "v_rmse", "v_correlation",
    "Decomposer", "pad_sets", "truncate_sets", "imf_ranges", "emd_nrmse", "emd_correlation",
    "inferred_imfs", "iemd_nrmse", "iemd_correlation",
    "CostFunction", "LogMagnitudeCost", "CorrelationCost", "WNRMSECost", "TimeCost", "EMDCost", "IEMDCost",
    "penalise",
]
