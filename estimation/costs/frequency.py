"""Frequency-domain costs of the thesis, vectorised over optimiser populations.

Log-magnitude error (4.20), (4.30), (5.9); its sum of squares over
responses (4.21); ``C^z_rmse`` (4.29); ``C^z_rho`` (4.31); the weighted
normalised RMSE ``C_wnrmse`` with band weights (5.8)-(5.11) and the bands
of Table 5.1.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from estimation.costs.metrics import ArrayLike, Responses, _finite_or_inf, correlation_cost

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


