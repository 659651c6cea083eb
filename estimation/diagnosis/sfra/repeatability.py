"""The change of a sweep judged against the spread between two healthy sweeps, per DL/T 911 band.

Two sweeps of a healthy winding never agree exactly: the leads are laid
again, the clamps and the temperature differ, the instrument drifts.  Given a
second healthy sweep (``--repeat``), the spread of the healthy pair sets the
scale a change must exceed to mean anything.

Per band (:data:`estimation.diagnosis.sfra.dlt911.BANDS`), with ``d = Y - X`` the
difference in dB of a sweep against the reference on the band's ``N`` points:

* the spread is ``SD = sqrt(sum d^2 / (N - 1))`` (dB; offsets count) of the
  repeat against the reference, ``SD_rep``, and of the new sweep,
  ``SD_new``; the DL/T 911 factor ``R`` of both is reported too;
* the points of ``d`` are not independent (a drift is smooth along the
  sweep), so the number of independent points is estimated from the repeat's
  difference by Bartlett's formula ``n_eff = N / (1 + 2 sum_k rho_k)``, the sum
  over the lags before the first non-positive autocorrelation ``rho_k``;
* the change is ``within repeatability`` when ``SD_new^2 / SD_rep^2`` does not
  exceed the one-sided 99 % point of the F distribution with ``(n_eff - 1,
  n_eff - 1)`` degrees of freedom: the new sweep's difference is then no
  larger than another healthy sweep's could be; else ``beyond repeatability``.

With one healthy pair the spread is one estimate; the limit carries its
uncertainty through ``n_eff``.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import f as f_dist

from estimation.diagnosis.sfra.dlt911 import band_masks, relative_factor

__all__ = ["LEVEL", "effective_points", "repeatability"]

#: One-sided level of the F test.
LEVEL = 0.99


def effective_points(d: np.ndarray) -> float:
    """Bartlett's number of independent points of a sequence ``d`` (lags up to the first non-positive one)."""
    d = np.asarray(d, dtype=float) - np.mean(d)
    n = d.size
    v = float(np.dot(d, d))
    if n < 3 or v <= 0:
        return float(n)
    acf = np.correlate(d, d, mode="full")[n:] / v  # lags 1 .. n-1
    s = 0.0
    for rho in acf:
        if rho <= 0:
            break
        s += rho
    return float(max(2.0, n / (1.0 + 2.0 * s)))


def _sd(d: np.ndarray) -> float:
    return float(np.sqrt(np.sum(d * d) / (d.size - 1)))


def repeatability(f: np.ndarray, h_ref: np.ndarray, h_repeat: np.ndarray, h_new: np.ndarray) -> dict:
    """Spread of two healthy sweeps per band and the new sweep's change judged against it.

    Parameters
    ----------
    f : numpy.ndarray
        Frequencies in Hz, shape ``(F,)`` (all three sweeps on them).
    h_ref, h_repeat, h_new : numpy.ndarray
        Complex voltage ratios of the reference, the second healthy sweep and the new sweep, shape ``(F,)``.

    Returns
    -------
    dict
        Per band key (``LF``, ``MF``, ``HF``): ``None`` when the band is not covered, else
        ``{"points", "n_eff", "repeat": {"R", "sd_db"}, "new": {"R", "sd_db"}, "ratio", "limit", "judgement"}``
        where ``ratio = (SD_new / SD_rep)^2`` and ``limit`` the F point it is compared with.
    """
    with np.errstate(divide="ignore"):
        x, yr, yn = (20.0 * np.log10(np.abs(np.asarray(h))) for h in (h_ref, h_repeat, h_new))
    ok = np.isfinite(x) & np.isfinite(yr) & np.isfinite(yn)
    out: dict = {}
    for key, m in band_masks(f).items():
        if m is None or int((m & ok).sum()) < 3:
            out[key] = None
            continue
        sel = m & ok
        d_rep, d_new = yr[sel] - x[sel], yn[sel] - x[sel]
        sd_rep, sd_new = _sd(d_rep), _sd(d_new)
        n_eff = effective_points(d_rep)
        limit = float(f_dist.ppf(LEVEL, n_eff - 1.0, n_eff - 1.0))
        ratio = (sd_new / sd_rep) ** 2 if sd_rep > 0 else (0.0 if sd_new == 0 else float("inf"))
        within = ratio <= limit
        out[key] = {"points": int(sel.sum()), "n_eff": round(n_eff, 2),
                    "repeat": {"R": relative_factor(x[sel], yr[sel]), "sd_db": sd_rep},
                    "new": {"R": relative_factor(x[sel], yn[sel]), "sd_db": sd_new},
                    "ratio": ratio if np.isfinite(ratio) else None, "limit": limit,
                    "judgement": "within repeatability" if within else "beyond repeatability"}
    return out
