"""The relative factors and verdict of the Chinese power-industry standard DL/T 911 (2004, 2016).

DL/T 911 "Frequency response analysis on winding deformation of power
transformers" compares the magnitude in dB of two sweeps of the same winding,
``X = 20 lg |H_ref|`` and ``Y = 20 lg |H_new|``, on the ``N`` frequency points
of a band.  With the means ``mX``, ``mY``:

* ``Dx = (1/N) sum (X - mX)^2``, ``Dy = (1/N) sum (Y - mY)^2`` (variances);
* ``Cxy = (1/N) sum (X - mX)(Y - mY)`` (covariance);
* ``LRxy = Cxy / sqrt(Dx Dy)`` (the centred, Pearson correlation coefficient);
* ``Rxy = 10`` if ``1 - LRxy < 1e-10``, else ``Rxy = -lg(1 - LRxy)``.

Being centred, ``R`` ignores a constant offset between the curves (a change of
gain of the whole band) and measures the change of shape only.  ``R`` is
negative when the curves are anti-correlated (``LRxy < 0``).

Bands: low frequency (LF) 1-100 kHz, medium (MF) 100-600 kHz, high (HF)
600 kHz-1 MHz.  A point belongs to the band ``lo <= f < hi``; the HF band
includes 1 MHz.

Verdict (the standard's table, checked from the most severe row down):

* ``severe`` deformation if ``R_LF < 0.6``;
* ``obvious`` if ``0.6 <= R_LF < 1.0`` or ``R_MF < 0.6``;
* ``slight`` if ``1.0 <= R_LF < 2.0`` or ``0.6 <= R_MF < 1.0``;
* ``normal`` if ``R_LF >= 2.0`` and ``R_MF >= 1.0`` and ``R_HF >= 0.6``.

The table leaves one corner open: ``R_HF < 0.6`` with LF and MF normal.  Here
it is ``slight``: the sweep cannot be ``normal`` (the normal row asks for
``R_HF >= 0.6``), and no row lets the HF band alone rank a change above
slight; the HF band is where the leads, their routing and the grounding of
the set-up weigh most, so the answer is a slight change to be confirmed by a
repeated sweep (the ``note`` says so).

A band the sweep does not cover (its first point above the band's low edge or
its last below the high edge by more than one step of the sweep's own grid,
or fewer than :data:`MIN_POINTS` points in it) has no factor (``None``); a band
with a flat curve (``Dx`` or ``Dy`` zero) has none either.  The verdict is
then given only when the missing factors cannot change it (three-valued
logic over the table's rows); otherwise it is ``None`` and the note names the
missing bands and the verdict the covered bands already establish.

The response is the one an FRA instrument records: the ratio of the voltage
at the response terminal (across the 50 Ohm input of the instrument) to the
voltage at the reference terminal, ``V_resp / V_ref``; for a 50 Ohm two-port
sweep this is ``S21 / (1 + S11)`` = ``-Y21 / (Y22 + 1/50 S)``
(:func:`voltage_ratio`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BANDS", "MIN_POINTS", "VERDICTS", "band_masks", "dlt911_indices", "relative_factor", "verdict",
           "voltage_ratio"]

#: (key, low Hz, high Hz) of the standard's bands.
BANDS = (("LF", 1e3, 1e5), ("MF", 1e5, 6e5), ("HF", 6e5, 1e6))

#: Fewest points in a band for a factor (a correlation of fewer points says nothing).
MIN_POINTS = 3

#: Verdicts from the least to the most severe.
VERDICTS = ("normal", "slight", "obvious", "severe")

#: Input resistance of an FRA instrument's response channel, Ohm.
R_INSTRUMENT = 50.0


def voltage_ratio(y21: np.ndarray, y22: np.ndarray, r_load: float = R_INSTRUMENT) -> np.ndarray:
    """``V_resp / V_ref`` of a two-port driven at port 1 with port 2 loaded by ``r_load``.

    Parameters
    ----------
    y21, y22 : numpy.ndarray
        Transfer and port-2 driving-point admittances in S, shape ``(F,)``.
    r_load : float
        Load of port 2 in Ohm (50 Ohm: the instrument's input).

    Returns
    -------
    numpy.ndarray
        Complex voltage ratio ``V2 / V1 = -Y21 / (Y22 + 1 / r_load)``, shape ``(F,)``; for ``r_load``
        equal to the reference resistance of S this is ``S21 / (1 + S11)``.
    """
    return -np.asarray(y21, dtype=complex) / (np.asarray(y22, dtype=complex) + 1.0 / r_load)


def relative_factor(x_db: np.ndarray, y_db: np.ndarray) -> float | None:
    """The standard's relative factor ``R`` of two dB curves on the same points (module docstring).

    Returns ``None`` for fewer than :data:`MIN_POINTS` points or a flat curve (no correlation defined).
    """
    x = np.asarray(x_db, dtype=float)
    y = np.asarray(y_db, dtype=float)
    if x.size < MIN_POINTS or x.shape != y.shape:
        return None
    dx = x - x.mean()
    dy = y - y.mean()
    vx, vy = np.mean(dx * dx), np.mean(dy * dy)
    if not (vx > 0 and vy > 0):
        return None
    lr = float(np.mean(dx * dy) / np.sqrt(vx * vy))
    return 10.0 if 1.0 - lr < 1e-10 else float(-np.log10(1.0 - lr))


def _lt(r: float | None, limit: float) -> bool | None:
    return None if r is None else r < limit


def _and(*v: bool | None) -> bool | None:
    if any(x is False for x in v):
        return False
    return None if any(x is None for x in v) else True


def _or(*v: bool | None) -> bool | None:
    if any(x is True for x in v):
        return True
    return None if any(x is None for x in v) else False


def _not(v: bool | None) -> bool | None:
    return None if v is None else not v


def verdict(r_lf: float | None, r_mf: float | None, r_hf: float | None) -> tuple[str | None, str]:
    """The standard's verdict from the three factors (``None`` = band not covered).

    Returns
    -------
    verdict : str or None
        One of :data:`VERDICTS`, or ``None`` when the missing factors could change it.
    note : str
        Which row decided, the open corner, or what is missing.
    """
    rows = (
        ("severe", _lt(r_lf, 0.6), "R_LF < 0.6"),
        ("obvious", _or(_and(_not(_lt(r_lf, 0.6)), _lt(r_lf, 1.0)), _lt(r_mf, 0.6)),
         "0.6 <= R_LF < 1.0 or R_MF < 0.6"),
        ("slight", _or(_and(_not(_lt(r_lf, 1.0)), _lt(r_lf, 2.0)), _and(_not(_lt(r_mf, 0.6)), _lt(r_mf, 1.0))),
         "1.0 <= R_LF < 2.0 or 0.6 <= R_MF < 1.0"),
    )
    missing = [k for k, r in zip(("R_LF", "R_MF", "R_HF"), (r_lf, r_mf, r_hf)) if r is None]
    for name, cond, text in rows:
        if cond is True:
            return name, f"{text}"
        if cond is None:
            worst = next((n for n, c, _ in rows if c is True), None)
            return None, (f"not determined: {', '.join(missing)} missing (the sweep does not cover the band); "
                          f"the covered bands {'establish at least ' + repr(worst) if worst else 'alone cannot decide'}")
    if r_hf is None:
        return None, "not determined: R_HF missing (the sweep does not cover 600 kHz-1 MHz); LF and MF are normal"
    if r_hf < 0.6:
        return "slight", ("R_HF < 0.6 with LF and MF normal, a corner the table leaves open: not normal, and the "
                          "HF band (leads, set-up) alone ranks no higher than slight; confirm with a repeated sweep")
    return "normal", "R_LF >= 2.0, R_MF >= 1.0, R_HF >= 0.6"


def band_masks(f: np.ndarray) -> dict[str, np.ndarray | None]:
    """Boolean point masks of the standard's bands on frequencies ``f`` (Hz); ``None`` if not covered.

    A band is covered when the sweep reaches within one of its own frequency steps of both band
    edges and has at least :data:`MIN_POINTS` points in the band.
    """
    f = np.asarray(f, dtype=float)
    out: dict[str, np.ndarray | None] = {}
    if f.size < 2:
        return {k: None for k, _, _ in BANDS}
    first_step, last_step = f[1] / f[0], f[-1] / f[-2]
    for i, (key, lo, hi) in enumerate(BANDS):
        last = i == len(BANDS) - 1
        sel = (f >= lo) & ((f <= hi) if last else (f < hi))
        covered = f[0] <= lo * first_step and f[-1] >= hi / last_step and int(sel.sum()) >= MIN_POINTS
        out[key] = sel if covered else None
    return out


def _db(h: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.abs(np.asarray(h)))


def dlt911_indices(f: np.ndarray, h_ref: np.ndarray, h_new: np.ndarray) -> dict:
    """DL/T 911 factors and verdict of a new sweep against a reference on the same frequencies.

    Parameters
    ----------
    f : numpy.ndarray
        Frequencies in Hz, shape ``(F,)``, increasing.
    h_ref, h_new : numpy.ndarray
        Complex voltage ratios ``V_resp / V_ref`` (dimensionless), shape ``(F,)``.

    Returns
    -------
    dict
        ``R_LF``, ``R_MF``, ``R_HF`` (float, or ``None`` for a band not covered), ``verdict``
        (``normal``/``slight``/``obvious``/``severe`` or ``None``), ``note``, ``points`` per band and
        ``bands_hz`` (the band edges).
    """
    x, y = _db(h_ref), _db(h_new)
    ok = np.isfinite(x) & np.isfinite(y)
    masks = band_masks(f)
    r: dict[str, float | None] = {}
    points: dict[str, int] = {}
    for key, _, _ in BANDS:
        m = masks[key]
        sel = None if m is None else m & ok
        points[key] = 0 if sel is None else int(sel.sum())
        r[key] = None if sel is None else relative_factor(x[sel], y[sel])
    v, note = verdict(r["LF"], r["MF"], r["HF"])
    return {"R_LF": r["LF"], "R_MF": r["MF"], "R_HF": r["HF"], "verdict": v, "note": note, "points": points,
            "bands_hz": {k: [lo, hi] for k, lo, hi in BANDS},
            "response": "V_resp/V_ref (S21/(1+S11) of a 50 Ohm two-port sweep), magnitude in dB"}
