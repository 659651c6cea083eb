"""Empirical-mode-decomposition costs of the thesis (PyEMD).

``C^m_nrmse`` (4.39)-(4.41) with zero padding, ``C^m_rho`` (4.42) with
truncation, and the inferred-EMD costs ``C^i_nrmse`` (4.45), ``C^i_rho``
(4.46) built on the inferred IMFs (4.43).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimation.costs.metrics import ArrayLike, _finite_or_inf, correlation_cost

EMD_METHODS = ("emd", "eemd", "ceemdan")


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


