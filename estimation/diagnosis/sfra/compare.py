"""The comparison an utility engineer reads: FRA traces, a common grid, the DL/T 911 factors and the repeat.

An FRA trace is the voltage ratio ``V_resp / V_ref`` on its frequencies,
from a two-port Touchstone sweep (:attr:`estimation.diagnosis.sfra.sweep.Sweep.voltage_ratio`)
or from an instrument's CSV export (:func:`pris_cosim.measured.fra_csv.read_fra_csv`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from estimation.diagnosis.sfra.dlt911 import BANDS, dlt911_indices
from estimation.diagnosis.sfra.repeatability import repeatability

__all__ = ["FraTrace", "is_touchstone", "load_trace", "on_grid", "standard_comparison"]


@dataclass
class FraTrace:
    """One FRA trace.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        Frequencies in Hz, increasing, shape ``(F,)``.
    h : numpy.ndarray
        Complex ``V_resp / V_ref`` (dimensionless), shape ``(F,)``.
    source : str
        File it came from.
    """

    frequency_hz: np.ndarray
    h: np.ndarray
    source: str = ""


def is_touchstone(path: str | os.PathLike) -> bool:
    """Whether ``path`` is named as a Touchstone file (``.sNp``, ``.ts``)."""
    from pris_cosim.measured.touchstone import ports_from_extension

    return ports_from_extension(path) is not None or Path(path).suffix.lower() == ".ts"


def load_trace(path: str | os.PathLike) -> FraTrace:
    """Read a trace from an FRA instrument's CSV export (layouts in :mod:`pris_cosim.measured.fra_csv`).

    Raises
    ------
    MeasuredDataError
        One line naming the file and line.
    """
    from pris_cosim.measured.fra_csv import RESPONSE, read_fra_csv

    d = read_fra_csv(path)
    return FraTrace(d.frequency_hz, d.responses[RESPONSE], os.fspath(path))


def on_grid(f: np.ndarray, trace: FraTrace) -> tuple[np.ndarray, np.ndarray]:
    """``trace`` on the frequencies ``f`` (Hz), and a mask of the points inside its own range.

    The same grid is returned as it is; another grid is interpolated linearly in ``log f`` (magnitude in
    dB, unwrapped phase); points of ``f`` outside the trace's range are masked out.
    """
    f = np.asarray(f, dtype=float)
    g = trace.frequency_hz
    if g.shape == f.shape and np.allclose(g, f, rtol=1e-6, atol=0):
        return trace.h, np.ones(f.size, bool)
    inside = (f >= g[0] * (1 - 1e-9)) & (f <= g[-1] * (1 + 1e-9))
    lf, lg = np.log(f), np.log(g)
    db = np.interp(lf, lg, 20.0 * np.log10(np.abs(trace.h)))
    ph = np.interp(lf, lg, np.unwrap(np.angle(trace.h)))
    return 10.0 ** (db / 20.0) * np.exp(1j * ph), inside


def standard_comparison(ref: FraTrace, new: FraTrace, repeat: FraTrace | None = None) -> tuple[dict, dict | None]:
    """The DL/T 911 factors of ``new`` (and of ``repeat``) against ``ref``, and the repeatability judgement.

    Returns
    -------
    standard_indices : dict
        ``{"dlt911": {...}}`` (:func:`estimation.diagnosis.sfra.dlt911.dlt911_indices`), plus ``"dlt911_repeat"`` for
        the repeat against the reference, and ``"grid"`` when a trace was interpolated onto the reference's
        frequencies.
    repeatability : dict or None
        ``None`` without a repeat; else ``{"repeat", "bands", "summary"}``
        (:func:`estimation.diagnosis.sfra.repeatability.repeatability`).
    """
    f = ref.frequency_hz
    h_new, in_new = on_grid(f, new)
    traces = [(new, in_new)]
    h_rep = None
    if repeat is not None:
        h_rep, in_rep = on_grid(f, repeat)
        traces.append((repeat, in_rep))
    keep = np.logical_and.reduce([m for _, m in traces])
    fk = f[keep]
    std = {"dlt911": dlt911_indices(fk, ref.h[keep], h_new[keep])}
    moved = [t.source for t, m in traces if not (t.frequency_hz.shape == f.shape and
                                                   np.allclose(t.frequency_hz, f, rtol=1e-6, atol=0))]
    if moved:
        std["grid"] = (f"interpolated onto the reference's {f.size} frequencies (log f; dB and unwrapped phase): "
                       + ", ".join(moved) + f"; {int(keep.sum())} points in the common range")
    if repeat is None:
        return std, None
    std["dlt911_repeat"] = dlt911_indices(fk, ref.h[keep], h_rep[keep])
    bands = repeatability(fk, ref.h[keep], h_rep[keep], h_new[keep])
    beyond = [k for k, v in bands.items() if v is not None and v["judgement"] == "beyond repeatability"]
    within = [k for k, v in bands.items() if v is not None and v["judgement"] == "within repeatability"]
    missing = [k for k, _, _ in BANDS if bands.get(k) is None]
    parts = []
    if beyond:
        parts.append("beyond repeatability in " + ", ".join(beyond))
    if within:
        parts.append("within repeatability in " + ", ".join(within))
    if missing:
        parts.append("not covered: " + ", ".join(missing))
    return std, {"repeat": repeat.source, "bands": bands, "summary": "; ".join(parts)}
