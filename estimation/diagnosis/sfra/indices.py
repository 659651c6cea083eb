"""Standard SFRA comparison indices per frequency band.

The indices compare the magnitude in dB, ``X = 20 log10 |H_ref|`` and
``Y = 20 log10 |H_new|``, of the end-to-end response (here the end-to-end
admittance ``-Y21``, i.e. ``|S21|`` up to the port terminations) over the
``N`` points of a band:

* correlation coefficient ``CC = sum(X Y) / sqrt(sum(X^2) sum(Y^2))``
  (the uncentred form of the Chinese standard DL/T 911-2004 and of the
  CIGRE TB 342 guide; 1 = identical shapes);
* absolute sum of logarithmic error ``ASLE = sum |Y - X| / N`` in dB;
* standard deviation ``SD = sqrt(sum (Y - X)^2 / (N - 1))`` in dB.

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

__all__ = ["BANDS", "band_indices", "comparison_indices"]

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
