"""Resonances of measured or computed responses, and the model order they suggest.

A parallel resonance is a local maximum of ``|Z|`` (the impedance phase falls
through zero); a series resonance is a local minimum. The number of parallel
resonances of a winding's driving-point impedance is the usual first guess of
the number of sections of its cascade model (thesis 2.1.3, 5.1.3).

Detection works on ``20 log10 |H|`` against log frequency with a prominence
threshold, after a light smoothing whose window adapts to the point density,
so measurement noise does not count as resonances.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Resonance:
    """One resonance.

    Attributes
    ----------
    frequency_hz : float, Hz
    kind : str
        ``"parallel"`` (magnitude peak) or ``"series"`` (magnitude dip).
    magnitude : float
        ``|H|`` at the resonance (Ohm for impedances).
    prominence_db : float, dB
        Height above (or depth below) the surrounding response.
    """

    frequency_hz: float
    kind: str
    magnitude: float
    prominence_db: float

    def as_dict(self) -> dict[str, float | str]:
        return asdict(self)


def _smoothed_db(frequency_hz: np.ndarray, values: np.ndarray, smooth_decades: float) -> np.ndarray:
    db = 20 * np.log10(np.abs(values))
    if smooth_decades <= 0 or db.size < 7:
        return db
    per_decade = (db.size - 1) / max(np.log10(frequency_hz[-1] / frequency_hz[0]), 1e-12)
    window = int(round(smooth_decades * per_decade)) | 1
    if window < 5:
        return db
    from scipy.signal import savgol_filter  # here: scipy.signal takes most of a diagnosis's import time

    return savgol_filter(db, min(window, (db.size - 2) | 1), polyorder=3)


def find_resonances(
    frequency_hz: np.ndarray,
    values: np.ndarray,
    min_prominence_db: float = 1.0,
    smooth_decades: float = 0.02,
    fmin: float | None = None,
    fmax: float | None = None,
) -> list[Resonance]:
    """Parallel and series resonances of a complex response, in frequency order.

    Parameters
    ----------
    frequency_hz : array_like, Hz
        Increasing frequencies (log-spaced is best).
    values : array_like, complex
        The response (an impedance for the parallel/series naming to hold).
    min_prominence_db : float, dB
        Smallest peak or dip that counts.
    smooth_decades : float
        Savitzky-Golay window width in decades (0 disables smoothing).
    fmin, fmax : float, Hz, optional
        Band to search.

    Returns
    -------
    list of Resonance
    """
    f = np.asarray(frequency_hz, float)
    h = np.asarray(values)
    if f.ndim != 1 or f.shape != h.shape or f.size < 3:
        raise ValueError("frequency_hz and values must be 1-D arrays of the same length (at least 3 points)")
    band = np.ones(f.size, bool)
    if fmin is not None:
        band &= f >= fmin
    if fmax is not None:
        band &= f <= fmax
    f, h = f[band], h[band]
    if f.size < 3:
        return []
    from scipy.signal import find_peaks

    db = _smoothed_db(f, h, smooth_decades)
    out: list[Resonance] = []
    for kind, sign in (("parallel", 1.0), ("series", -1.0)):
        idx, props = find_peaks(sign * db, prominence=min_prominence_db)
        out += [Resonance(float(f[i]), kind, float(np.abs(h[i])), float(p)) for i, p in zip(idx, props["prominences"])]
    return sorted(out, key=lambda r: r.frequency_hz)


def count_parallel(resonances: list[Resonance]) -> int:
    """Number of parallel resonances in a list."""
    return sum(r.kind == "parallel" for r in resonances)


def suggest_sections(
    responses: Mapping[str, tuple[np.ndarray, np.ndarray]],
    impedances: tuple[str, ...] = ("Zin", "Zhvsc", "Zhvoc"),
    even: bool = False,
    **kwargs: float,
) -> dict[str, object]:
    """Suggest the number of winding sections from the parallel resonances.

    Parameters
    ----------
    responses : mapping
        Response name to ``(frequency_hz, complex values)``.
    impedances : tuple of str
        Driving-point impedances to count on, in order of preference; the
        largest count among those present is used (thesis 5.1.3 counts the
        HV short-circuit impedance).
    even : bool
        Round up to an even number (two-winding models keep the
        inter-winding capacitance at the HV midpoint).
    **kwargs
        Passed to :func:`find_resonances`.

    Returns
    -------
    dict
        ``sections``, ``counted_on`` and ``resonances`` per response (as dicts).
    """
    found = {name: find_resonances(*responses[name], **kwargs) for name in responses}
    counts = {name: count_parallel(found[name]) for name in impedances if name in found}
    if not counts:
        raise ValueError(f"none of the impedances {', '.join(impedances)} is among the responses ({', '.join(responses)})")
    best = max(counts, key=lambda n: counts[n])
    n = max(1, counts[best])
    if even and n % 2:
        n += 1
    return {
        "sections": n,
        "counted_on": best,
        "parallel_counts": counts,
        "resonances": {name: [r.as_dict() for r in rs] for name, rs in found.items()},
    }


def refine_resonances(f: np.ndarray, z: np.ndarray, peaks: np.ndarray) -> np.ndarray:
    """Resonance frequencies (Hz) of an impedance, sharper than its sampling: peaks moved to fitted poles.

    A resonance far sharper than the frequency grid peaks between two samples;
    its sampled peak is off by up to half a step (a few percent on 200 points
    per band). A rational fit of the whole impedance (vector fitting,
    scikit-rf's :class:`skrf.vectorFitting.VectorFitting`, Gustavsen and
    Semlyen 1999; two real and ``2 len(peaks) + 4`` complex pole pairs, with a
    term proportional to ``s`` for a response that rises as an inductance's or
    a capacitance's admittance does) places
    the poles far more precisely. Each peak moves to the highest fitted pole
    (``|residue / Re(pole)|``, its peak on its own) within one grid step of it; a peak with no such pole
    is dropped when others have one (a shoulder, or a peak off its pole by
    more than a step), and a failed fit changes nothing.

    Parameters
    ----------
    f : numpy.ndarray, Hz
        ``(F,)`` increasing frequencies of the samples.
    z : numpy.ndarray, Ohm
        ``(F,)`` complex impedance.
    peaks : numpy.ndarray, Hz
        Peak frequencies of ``|z|`` on the samples.
    """
    import warnings

    import skrf
    from skrf.vectorFitting import VectorFitting

    peaks = np.asarray(peaks, float)
    step = float(np.median(np.diff(np.log(f)))) if f.size > 1 else 0.0
    try:
        nw = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), z=np.asarray(z).reshape(-1, 1, 1), z0=50.0)
        vf = VectorFitting(nw)
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            vf.vector_fit(n_poles_real=2, n_poles_cmplx=2 * int(peaks.size) + 4, parameter_type="z",
                          init_pole_spacing="log", fit_proportional=True)
        p = np.asarray(vf.poles)
        r = np.abs(np.asarray(vf.residues)).reshape(-1, p.size).max(axis=0)
    except Exception:  # noqa: BLE001 - the fit is a refinement only
        return peaks
    keep = (p.imag > 0) & (p.real < 0)
    fp = p.imag[keep] / (2 * np.pi)
    # each pole's height at its own frequency, |residue / Re(pole)|: a spare pole of the fit sits anywhere with a
    # residue near zero (a pole-zero doublet), the resonance's pole makes the peak
    height = r[keep] / np.abs(p.real[keep])
    if not fp.size:
        return peaks
    out, refined = peaks.copy(), np.zeros(peaks.size, bool)
    for i, pk in enumerate(peaks):
        near = np.flatnonzero(np.abs(np.log(fp / pk)) <= step)
        if near.size:
            out[i], refined[i] = fp[near[np.argmax(height[near])]], True
    # where the fit found some resonances, a peak it does not confirm is a shoulder or lies off its pole
    return out[refined] if refined.any() else out
