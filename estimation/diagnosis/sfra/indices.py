"""Comparison indices per frequency band: CC, ASLE and SD (the literature's, not DL/T 911's).

The indices compare the magnitude in dB, ``X = 20 log10 |H_ref|`` and
``Y = 20 log10 |H_new|``, of one response of the two sweeps (the caller says
which: the end-to-end admittance ``-Y21`` of a two-port sweep, or the voltage
ratio of an instrument's CSV export) over the ``N`` points of a band:

* correlation coefficient ``CC = sum(X Y) / sqrt(sum(X^2) sum(Y^2))``,
  **uncentred** (no means subtracted; a common offset in dB raises it, so it
  is close to 1 for most pairs of SFRA curves; Ryder 2003, Secue and Mombello
  2008).  It is not the factor of DL/T 911, which is centred (the Pearson
  coefficient) and mapped to ``R = -lg(1 - LR)``: :mod:`estimation.diagnosis.sfra.dlt911`;
* absolute sum of logarithmic error ``ASLE = sum |Y - X| / N`` in dB,
  **uncentred** (offsets count);
* standard deviation ``SD = sqrt(sum (Y - X)^2 / (N - 1))`` in dB,
  **uncentred** (the root-mean-square difference about zero, not about its
  mean, with the ``N - 1`` of the literature).

References: J. R. Secue and E. E. Mombello, "Sweep frequency response
analysis (SFRA) for the assessment of winding displacements and
deformation in power transformers", Electric Power Systems Research 78
(2008) 1119-1128; S. A. Ryder, "Diagnosing transformer faults using
frequency response analysis", IEEE Electrical Insulation Magazine 19(2)
(2003) 16-22; IEEE C57.149-2012 (bands).

Bands (IEEE C57.149 / IEC 60076-18 practice): below 2 kHz (core), 2-20 kHz
(bulk winding and interactions), 20 kHz-1 MHz (winding structure), above
1 MHz (leads and set-up).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BANDS", "DEFINITIONS", "band_indices", "comparison_indices"]

#: The indices' formulas and centring, as written into the JSON answer.
DEFINITIONS = {
    "cc": {"formula": "sum(X*Y) / sqrt(sum(X^2) * sum(Y^2))", "centred": False,
           "note": "uncentred correlation (not the DL/T 911 factor, which is centred: standard_indices.dlt911)"},
    "asle": {"formula": "sum(|Y - X|) / N", "unit": "dB", "centred": False},
    "sd": {"formula": "sqrt(sum((Y - X)^2) / (N - 1))", "unit": "dB", "centred": False},
    "X, Y": "20 log10 |H| of the reference and the new sweep on the band's N points",
}

#: (name, low Hz, high Hz) of the reporting bands.
BANDS = (
    ("below 2 kHz", 0.0, 2e3),
    ("2-20 kHz", 2e3, 2e4),
    ("20 kHz-1 MHz", 2e4, 1e6),
    ("above 1 MHz", 1e6, np.inf),
)


def band_indices(x_db: np.ndarray, y_db: np.ndarray) -> dict[str, float | int | None]:
    """CC, ASLE (dB) and SD (dB) of two dB magnitude curves on the same points.

    Returns ``None`` values when there are fewer than 2 points.
    """
    x = np.asarray(x_db, dtype=float)
    y = np.asarray(y_db, dtype=float)
    n = x.size
    if n < 2:
        return {"points": int(n), "cc": None, "asle": None, "sd": None}
    den = np.sqrt(np.sum(x * x) * np.sum(y * y))
    cc = float(np.sum(x * y) / den) if den > 0 else None
    d = y - x
    return {"points": int(n), "cc": cc, "asle": float(np.sum(np.abs(d)) / n),
            "sd": float(np.sqrt(np.sum(d * d) / (n - 1)))}


def comparison_indices(f: np.ndarray, h_ref: np.ndarray, h_new: np.ndarray) -> dict[str, dict]:
    """Indices per band of two complex responses on frequencies ``f`` (Hz)."""
    f = np.asarray(f, dtype=float)
    with np.errstate(divide="ignore"):
        x = 20.0 * np.log10(np.abs(h_ref))
        y = 20.0 * np.log10(np.abs(h_new))
    ok = np.isfinite(x) & np.isfinite(y)
    out = {}
    for name, lo, hi in BANDS:
        sel = ok & (f >= lo) & (f < hi)
        out[name] = band_indices(x[sel], y[sel])
    return out
