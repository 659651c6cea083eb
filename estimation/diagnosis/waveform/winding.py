"""Windings diagnosed from PRIS waveform records: the record's input impedance, then the frequency diagnosis.

A PRIS record of a winding (``time_s, v_bprbs, v_in, i_in``: thesis 2.3.4,
4.2.2) holds the winding's input impedance ``Z = V_in / I_in`` wherever the
PRBS excites it. The impedance is estimated as H1 (``S_vi / S_ii``):

- a record holding two or more whole PRBS periods: the first period (the
  source's transient) is dropped, and the spectra of the following periods
  (rectangular window: the excitation is periodic, so no leakage) are
  averaged;
- otherwise Welch averaging (Hann window, eight segments).

Bins near the PRBS spectrum's nulls (multiples of the clock), bins where
the coherence falls below ``MIN_COHERENCE`` or the current carries little
power, and frequencies above a tenth of the sampling rate or ten times the
clock are left out, one bin per log-spaced band is kept (:func:`band_pick`, gaps
left as gaps) and diagnosed against the
netlist or the built-in model by
:func:`.diagnose.diagnose_frequency`: the same catalogue, the same design
prior, the same keys. The source's own causes are not part of this path: with
the source's nominal values and a record whose bridge voltage repeats, the
whole arrangement is replayed instead (:mod:`.replay`), and this path is the
fallback when it cannot be (the answer's ``path`` says which).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pris_cosim.measured.formats import Waveforms
from pris_cosim.signals.spectral import estimate_response
from pris_cosim.signals.uncertainty import NULL_WIDTH, clock_null_mask

from estimation.diagnosis.fit import DiagnosisError

#: Bins kept: coherence at least this (Welch path) ...
MIN_COHERENCE = 0.9
#: ... and current power at least this fraction of its median over the band (both paths).
MIN_POWER_FRACTION = 0.05
# Bins within NULL_WIDTH (8 %) of a clock multiple are left out (the PRBS spectrum's nulls): clock_null_mask.
#: Highest frequency used: this fraction of the sampling rate (the record's sampling and any interpolation
#: distort above) ...
MAX_FS_FRACTION = 0.1
#: ... and this many times the PRBS clock (little excitation above).
MAX_CLOCK_MULTIPLE = 10.0
#: Log-spaced frequencies the impedance is averaged onto.
POINTS = 200


def prbs_period(u: np.ndarray) -> int | None:
    """Samples per period of a repeated excitation (``None`` when it does not repeat within the record)."""
    x = np.where(u > 0.5 * (np.max(u) + np.min(u)), 1.0, -1.0)
    n = x.size
    spec = np.fft.rfft(x, 2 * n)
    r = np.fft.irfft(spec * np.conj(spec))[:n]
    overlap = n - np.arange(n)
    score = r / np.maximum(overlap, 1)
    for lag in np.flatnonzero((score > 0.999) & (overlap >= n // 4) & (np.arange(n) > 8))[:5]:
        if np.array_equal(x[lag:], x[:-lag]):
            return int(lag)
    return None


def winding_impedance(w: Waveforms, points: int = POINTS) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """The input impedance ``V_in / I_in`` of the device in a PRIS record, on log-spaced frequencies.

    Parameters
    ----------
    w : Waveforms
        ``time_s`` (s, uniform), ``v_bprbs`` (V), ``v_in`` (V), ``i_in`` (A).
    points : int
        Output frequencies.

    Returns
    -------
    f : numpy.ndarray, Hz
    z : numpy.ndarray, Ohm (complex)
    info : dict
        How it was estimated (``method``, ``period_samples``, ``band_hz``, ``bins``).
    """
    fs = w.fs
    u = np.asarray(w.v_bprbs, float)
    v, i = np.asarray(w.v_in, float), np.asarray(w.i_in, float)
    lag = prbs_period(u)
    if lag is not None and v.size >= 2 * lag:
        n_per = v.size // lag
        V = np.fft.rfft(v[lag: n_per * lag].reshape(n_per - 1, lag), axis=1)
        Ii = np.fft.rfft(i[lag: n_per * lag].reshape(n_per - 1, lag), axis=1)
        sii = np.mean(np.abs(Ii) ** 2, axis=0)
        svi = np.mean(V * np.conj(Ii), axis=0)
        f = np.fft.rfftfreq(lag, 1 / fs)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = svi / sii
        f, z, sii = f[1:], z[1:], sii[1:]
        good = np.isfinite(z) & (sii > MIN_POWER_FRACTION * np.median(sii))
        method = f"periodic H1 over {n_per - 1} period(s) after the first ({lag} samples each, rectangular window)"
    else:
        resp = estimate_response(i, v, fs, nperseg=max(64, v.size // 8))
        f, z = resp.frequency_hz, resp.values
        coh = resp.coherence if resp.coherence is not None else np.ones(f.size)
        good = np.isfinite(z) & (coh >= MIN_COHERENCE)
        method = "Welch H1 (Hann, 8 segments), bins with coherence >= 0.9"
    edges = np.flatnonzero(np.diff(u))
    if edges.size > 2:  # the PRBS spectrum's nulls at the clock's multiples carry no excitation
        good &= ~clock_null_mask(f, fs / float(np.min(np.diff(edges))), NULL_WIDTH)
    good &= f <= min(MAX_FS_FRACTION * fs, MAX_CLOCK_MULTIPLE * fs / max(float(np.min(np.diff(edges))), 1.0)
                     if edges.size > 2 else MAX_FS_FRACTION * fs)
    if np.count_nonzero(good) < 20:
        raise DiagnosisError("the record excites too few frequencies for an impedance (fewer than 20 usable bins)")
    f, z = f[good], z[good]
    f_lo, f_hi = f[0], f[-1]
    f_new, z_new = band_pick(f, z, points)
    return f_new, z_new, {"method": method, "period_samples": lag, "band_hz": [float(f_lo), float(f_hi)],
                          "bins": int(f.size)}


def band_pick(f: np.ndarray, z: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """One bin per log-spaced band (the one nearest the band's log-centre); empty bands are left out.

    Neither averaged (an average over a band holding a sharp resonance is
    not the response at any one frequency) nor interpolated (gaps where a
    clock null was left out stay gaps: an interpolation could cross a
    resonance).
    """
    edges = np.geomspace(f[0], f[-1] * (1 + 1e-12), points + 1)
    centres = np.sqrt(edges[:-1] * edges[1:])
    idx = np.searchsorted(edges, f, side="right") - 1
    keep = []
    for b in np.unique(idx):
        sel = np.flatnonzero(idx == b)
        keep.append(sel[np.argmin(np.abs(np.log(f[sel] / centres[b])))])
    return f[keep], z[keep]


def diagnose_winding_waveforms(w: Waveforms, progress: bool = True, **kwargs: Any):
    """Diagnose the winding in a PRIS record against a netlist or a built-in model.

    Parameters
    ----------
    w : Waveforms
    progress : bool
    **kwargs
        Passed to :func:`.diagnose.diagnose_frequency` (``model`` or
        ``circuit`` and ``port``, ``tolerance`` ...).

    Returns
    -------
    Diagnosis
        With ``evidence["impedance_from_waveforms"]`` saying how the impedance was estimated.
    """
    from estimation.diagnosis.diagnose import diagnose_frequency

    f, z, info = winding_impedance(w)
    if progress:
        import sys

        print(f"diagnose: winding impedance from the PRIS record: {info['method']}, "
              f"{info['band_hz'][0]:.4g} - {info['band_hz'][1]:.4g} Hz", file=sys.stderr, flush=True)
    model = kwargs.get("model")
    name = "Zin"
    if model is not None:
        names = [r.name for c in model.configurations.values() for r in c.responses if r.name.startswith("Z")]
        if len(model.configurations) != 1 or not names:
            raise DiagnosisError(f"model {model.name!r} has several test configurations; a PRIS record gives one "
                                 "input impedance: give a one-port model or a netlist with --port")
        name = names[0]
    d = diagnose_frequency(f, {name: z}, progress=progress, **kwargs)
    d.evidence["impedance_from_waveforms"] = info
    return d
