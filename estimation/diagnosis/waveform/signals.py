"""Signal helpers of the waveform diagnosis: switching edges, localisation, residual spectra, the record's noise.

Used by :mod:`estimation.diagnosis.waveform.source`; everything here works on plain
sampled arrays (no circuit).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pris_cosim.measured.formats import Waveforms

#: The compared signals and their units.
SIGNALS = ("v_in", "i_in")
UNITS = {"v_in": "V", "i_in": "A"}

def _edges(u: np.ndarray) -> np.ndarray:
    """Indices k at which the commanded level changes (u[k] != u[k-1])."""
    return np.flatnonzero(np.diff(u) != 0) + 1


def _since_edge(u: np.ndarray, h: float) -> np.ndarray:
    """Time since the last switching edge at every sample (s; from the record start before the first)."""
    K = u.size
    idx = np.zeros(K, dtype=np.int64)
    e = _edges(u)
    idx[e] = e
    idx = np.maximum.accumulate(idx)
    return (np.arange(K) - idx) * h


def _bit_samples(u: np.ndarray) -> float:
    e = _edges(u)
    if e.size < 2:
        return float(u.size)
    runs = np.diff(e)
    return float(runs.min())


def _switch_times(u: np.ndarray) -> tuple[np.ndarray | None, dict[str, Any]]:
    """Sub-sample switching instants from a regular bit clock, or ``None`` for the sample grid.

    The H-bridge switches on a clock: change ``j`` happens at ``phi + b_j P``
    samples (``b_j`` its bit index, ``P`` samples per bit), inside
    ``(k_j - 1, k_j]`` where ``k_j`` is the first sample at the new level. When
    ``P`` is a whole number and every change sits on the grid, the record
    follows the waveform contract (level held from row k) and the instants are
    the samples themselves. Otherwise ``phi`` and ``P`` are the centre of the
    region allowed by all the intervals (a linear programme maximising the
    margin); they are used when that region is narrower than half a sample.
    """
    from scipy.optimize import linprog

    e = _edges(u).astype(float)
    info: dict[str, Any] = {"mode": "sample", "reason": ""}
    if e.size < 4:
        info["reason"] = "too few edges to estimate a bit clock"
        return None, info
    dk = np.diff(e)
    n0 = dk.min()
    bits = np.concatenate([[0.0], np.cumsum(np.rint(dk / n0))])
    P0 = float(np.polyfit(bits, e, 1)[0])
    bits = np.concatenate([[0.0], np.cumsum(np.rint(dk / P0))])
    P = round(P0)
    if P > 0 and np.all(dk == np.diff(bits) * P):
        info.update(reason="edges on a whole number of samples per bit (waveform contract)", samples_per_bit=float(P))
        return None, info
    # maximise m subject to e - 1 + m <= phi + b P <= e - m
    A = np.concatenate([np.stack([np.ones_like(bits), bits, np.ones_like(bits)], 1),
                        np.stack([-np.ones_like(bits), -bits, np.ones_like(bits)], 1)])
    b = np.concatenate([e, -(e - 1)])
    sol = linprog([0.0, 0.0, -1.0], A_ub=A, b_ub=b, bounds=[(None, None), (1.0, None), (0.0, 0.5)], method="highs")
    if not sol.success:
        info["reason"] = "switching instants do not follow a regular clock"
        return None, info
    phi, Pc, margin = (float(v) for v in sol.x)
    info.update(samples_per_bit=Pc, phase_samples=phi, margin_samples=margin)
    if margin > 0.25:
        info["reason"] = "clock phase ambiguous within a sample; switching taken on the samples"
        return None, info
    info.update(mode="clock", reason="switching between samples: instants from the fitted bit clock")
    return phi + bits * Pc, info


def _decimation(u: np.ndarray, per_bit: int = 200) -> tuple[int, int]:
    """Subsampling ``(q, k0)`` that keeps every switching edge on the grid ``k0 + q j`` and at least
    ``per_bit`` samples in the shortest bit (``q = 1``: none)."""
    e = _edges(u)
    if e.size < 2:
        return 1, 0
    g = int(np.gcd.reduce(np.diff(e)))
    bit = int(np.min(np.diff(e)))
    q = max([d for d in range(1, g + 1) if g % d == 0 and bit // d >= per_bit] or [1])
    return q, int(e[0] % q)


def _localise(u: np.ndarray, h: float, before: np.ndarray, after: np.ndarray | None,
              ringing_share: float = 0.0, ringing_hz: float | None = None) -> dict[str, Any]:
    """Where in time the normalised residual sits: at the edges, in the transients after them, or between.

    Three windows by the time since the last switching edge: ``edge`` (the first
    2 % of the shortest bit), ``transient`` (2-30 %) and ``steady`` (the rest).
    The label is ``waveform edges and ringing`` when the edge window's RMS is at
    least 1.5 times the others' or a single ringing line carries at least half of
    the residual's power; ``steady parts between edges`` when the steady window's
    RMS is at least 0.7 times the largest; else ``transients after the edges``.
    """
    since = _since_edge(u, h)
    bit = _bit_samples(u) * h
    window = max(3 * h, 0.02 * bit)
    near = since < window
    time_share = float(np.mean(near))
    masks = {"edge": near, "transient": (since >= window) & (since < 0.3 * bit), "steady": since >= 0.3 * bit}

    def share(e):
        en = np.sum(e ** 2, axis=1)
        tot = float(np.sum(en))
        return float(np.sum(en[near]) / tot) if tot > 0 else 0.0

    def rms(e, m):
        return float(np.sqrt(np.mean(np.sum(e[m] ** 2, axis=1)))) if m.any() else 0.0

    r = {k: rms(before, m) for k, m in masks.items()}
    top = max(r.values()) or 1.0
    if ringing_share >= 0.5 or r["edge"] >= 1.5 * max(r["transient"], r["steady"]):
        where = "waveform edges and ringing"
    elif r["steady"] >= 0.7 * top:
        where = "steady parts between edges"
    else:
        where = "transients after the edges (source time constants)"
    edges_b = np.geomspace(max(h, bit / 1000), bit, 7)
    bounds = np.concatenate([[0.0], edges_b[1:-1], [np.inf]])
    profile = []
    for lo_, hi_ in zip(bounds[:-1], bounds[1:]):
        sel = (since >= lo_) & (since < hi_)
        if not sel.any():
            continue
        row = {"from_s": float(lo_), "to_s": float(hi_) if np.isfinite(hi_) else None, "samples": int(sel.sum()),
               "rms_before": rms(before, sel)}
        if after is not None:
            row["rms_after"] = rms(after, sel)
        profile.append(row)
    out = {"where": where, "edge_window_s": window, "time_share_near_edges": time_share,
           "residual_share_near_edges_before": share(before),
           "rms_by_window_before": r,
           "ringing_line_hz": ringing_hz, "ringing_line_share_of_residual_power": ringing_share,
           "profile_by_time_since_edge": profile,
           "note": "residual = (model - measured) / std(measured) per signal, RMS over both signals"}
    if after is not None:
        out["residual_share_near_edges_after"] = share(after)
        out["rms_by_window_after"] = {k: rms(after, m) for k, m in masks.items()}
    return out


def _line_share(f: np.ndarray, S: np.ndarray, fp: float | None) -> float:
    """Share of the residual power within +-0.5 % of the frequency ``fp``."""
    if not fp:
        return 0.0
    tot = float(np.sum(S[1:]))
    sel = np.abs(f - fp) <= max(0.005 * fp, 3 * (f[1] - f[0]))
    return float(np.sum(S[sel]) / tot) if tot > 0 else 0.0


def _residual_spectrum(e: np.ndarray, h: float, pad: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Power of the normalised residuals (both signals summed) on a zero-padded FFT grid."""
    K = e.shape[0]
    n = 1 << int(math.ceil(math.log2(K * pad)))
    win = np.hanning(K)[:, None]
    S = np.abs(np.fft.rfft((e - e.mean(axis=0)) * win, n=n, axis=0)) ** 2
    return np.fft.rfftfreq(n, h), S.sum(axis=1)


def _spectral_peaks(f: np.ndarray, S: np.ndarray, fmin: float, fmax: float, count: int = 3) -> list[float]:
    """The ``count`` strongest local maxima of ``S`` within [fmin, fmax], at least 10 % apart."""
    sel = np.flatnonzero((f >= fmin) & (f <= fmax))
    if sel.size < 3:
        return []
    s = S[sel]
    loc = np.flatnonzero((s[1:-1] >= s[:-2]) & (s[1:-1] >= s[2:])) + 1
    order = loc[np.argsort(s[loc])[::-1]]
    peaks: list[float] = []
    for i in order:
        k = sel[i]
        # parabolic interpolation of the log power
        a, b, c = np.log(S[k - 1] + 1e-300), np.log(S[k] + 1e-300), np.log(S[k + 1] + 1e-300)
        den = a - 2 * b + c
        d = 0.5 * (a - c) / den if den < 0 else 0.0
        fp = float(f[k] + d * (f[1] - f[0]))
        if all(abs(fp - q) > 0.1 * q for q in peaks):
            peaks.append(fp)
        if len(peaks) >= count:
            break
    return peaks


# ---------------------------------------------------------------------------
# Diagnosis
# ---------------------------------------------------------------------------


#: Order of the linear predictor that estimates the record's noise between switching edges.
NOISE_LP_ORDER = 8


def waveform_noise(w: Waveforms, order: int = NOISE_LP_ORDER) -> dict[str, Any]:
    """The cost a perfect model would still have, from the record itself.

    Between two switching edges a linear source driven by a constant level
    responds as a sum of a few (damped, possibly ringing) exponentials and a
    constant, which a linear recurrence of order ``order`` (at least the
    number of the source's states plus one) predicts exactly. The recurrence
    is fitted by least squares to the samples away from the edges; what it
    leaves is the noise passed through the prediction-error filter
    ``(1, -a_1, ..., -a_p)``, of variance ``sigma^2 (1 + sum a_i^2)``. The
    median of the squared residuals over ``0.455`` (the median of a
    chi-square with one degree of freedom) is robust against outliers. The
    floor is ``sum_s sigma_s^2 / var(y_s)`` in cost units.
    """
    u = np.asarray(w.v_bprbs, float)
    keep = np.ones(u.size, bool)
    keep[:order] = False
    for k in _edges(u):
        keep[k:k + order + 2] = False
    rows = np.flatnonzero(keep)
    per, cost = {}, 0.0
    for s in SIGNALS:
        y = np.asarray(getattr(w, s), float)
        sigma2 = 0.0
        if rows.size > 4 * order:
            X = np.stack([y[rows - i] for i in range(1, order + 1)], axis=1)
            a, *_ = np.linalg.lstsq(X, y[rows], rcond=None)
            r = y[rows] - X @ a
            sigma2 = float(np.median(r * r) / 0.4549364 / (1 + np.sum(a * a)))
        var = float(np.var(y)) or 1.0
        per[s] = math.sqrt(sigma2)
        cost += sigma2 / var
    return {"cost": cost, "per_signal": per,
            "method": f"linear prediction of order {order} between switching edges; median of the squared "
                      "prediction error / 0.455, corrected for the prediction filter's noise gain"}
