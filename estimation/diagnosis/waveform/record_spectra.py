"""A PRIS record as exact periodic spectra, and the arrangement's sampled response to its bridge voltage.

A record ``time_s, v_bprbs, v_in, i_in`` whose bridge voltage repeats (a PRBS
played two or more times) and switches on the sample instants (the waveform
contract: row ``k`` holds from ``time_s[k]`` to ``time_s[k+1]``) is, after
the first period (the source's transient), in periodic steady state. Over
one period of ``L`` samples the DFT of every recorded signal then obeys

``Y_k = H_d(e^{j w_k h}) U_k``, ``w_k = 2 pi k / (L h)``,

exactly, where ``U_k`` is the DFT of the bridge voltage samples and ``H_d``
the arrangement's response sampled with a zero-order hold on its input. With
the continuous response ``H(s)`` (a circuit with any frequency-dependent
elements), Poisson's sum gives

``H_d = (1 - e^{-j w h}) / h * sum_m H(j W_m) / (j W_m)``, ``W_m = w + 2 pi m / h``.

The sum is taken over ``|m| <= ALIASES``; its tail is that of the asymptote
``a / (j W)^2`` (``a`` read from the outermost terms), whose whole sum is
``-(h / 2)^2 / sin^2(w h / 2)``: the remainder falls as ``1 / M^2``.

The spectra of the periods after the first are averaged. The noise of each
channel is estimated from the record between switching edges
(:func:`.waveform_signals.waveform_noise`: white noise of standard deviation
``sigma`` gives ``L sigma^2 / n`` per averaged bin), with a floor of
``MIN_NOISE_RMS`` relative to each bin's magnitude (a record's values are not
known better than that: instrument gain, a simulator's integration error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.measured.formats import Waveforms

from estimation.diagnosis.prior import MIN_NOISE_RMS
from estimation.diagnosis.waveform.signals import SIGNALS, _bit_samples, _edges, _switch_times, waveform_noise
from estimation.diagnosis.waveform.winding import prbs_period

#: Alias terms on either side in the sampled response's sum.
ALIASES = 2
#: Bins whose bridge-voltage magnitude is below this fraction of the largest carry no excitation (the PRBS nulls).
MIN_EXCITATION = 1e-3
#: Most bins replayed (a longer period: every k-th excited bin).
MAX_BINS = 1500
#: Highest frequency replayed, as a fraction of the sampling rate: a record's anti-alias filter, its
#: interpolation or a simulator's time step distort the top of the band.
MAX_FS_FRACTION = 0.1


@dataclass
class PeriodicRecord:
    """The steady-state spectra of a PRIS record on its excited bins.

    Attributes
    ----------
    f : numpy.ndarray, Hz
        Bins replayed.
    U : numpy.ndarray, V
        DFT of one period of the bridge voltage at ``f``.
    Y : numpy.ndarray
        ``(B, 2)`` averaged DFTs of ``v_in`` (V) and ``i_in`` (A).
    sigma : numpy.ndarray
        ``(B, 2)`` standard deviation of the complex noise of ``Y``.
    h : float, s
        Sampling interval.
    info : dict
        Period, periods averaged, clock, noise.
    """

    f: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    sigma: np.ndarray
    h: float
    info: dict[str, Any] = field(default_factory=dict)


def periodic_record(w: Waveforms, max_fs_fraction: float = MAX_FS_FRACTION) -> tuple[PeriodicRecord | None, str]:
    """The record's periodic spectra, or ``None`` with the reason an exact replay is not possible.

    Parameters
    ----------
    w : Waveforms
        ``time_s`` (s, uniform), ``v_bprbs`` (V), ``v_in`` (V), ``i_in`` (A).
    max_fs_fraction : float
        Highest frequency replayed, fraction of the sampling rate.

    Returns
    -------
    record : PeriodicRecord or None
    reason : str
        Why the record can (or cannot) be replayed exactly.
    """
    u = np.asarray(w.v_bprbs, float)
    if _edges(u).size < 4:
        return None, "the bridge voltage switches fewer than four times"
    lag = prbs_period(u)
    if lag is None or u.size < 2 * lag:
        return None, "the bridge voltage does not repeat within the record (fewer than two whole periods)"
    switch, timing = _switch_times(u)
    if switch is not None:
        return None, "the bridge switches between samples (its instants are known only from a fitted clock)"
    n = u.size // lag - 1
    seg = slice(lag, (n + 1) * lag)
    ub = u[seg].reshape(n, lag)
    if not np.all(ub == ub[0]):
        return None, "the bridge voltage's periods differ"
    Uk = np.fft.rfft(ub[0])
    Y = np.stack([np.fft.rfft(np.asarray(getattr(w, s), float)[seg].reshape(n, lag), axis=1).mean(axis=0)
                  for s in SIGNALS], axis=1)
    f = np.fft.rfftfreq(lag, w.dt)
    bit = _bit_samples(u)
    keep = (np.arange(f.size) > 0) & (np.abs(Uk) >= MIN_EXCITATION * np.abs(Uk).max()) & (f <= max_fs_fraction * w.fs)
    if np.count_nonzero(keep) < 20:
        return None, "fewer than 20 excited frequencies below a tenth of the sampling rate"
    idx = np.flatnonzero(keep)
    stride = int(math.ceil(idx.size / MAX_BINS))
    if stride > 1:  # every stride-th bin: each bin's relation is exact on its own (the time a fit takes)
        keep[:] = False
        keep[idx[::stride]] = True
    noise = waveform_noise(w)
    white = np.array([noise["per_signal"][s] for s in SIGNALS]) * math.sqrt(lag / n)
    Yk = Y[keep]
    sigma = np.sqrt(white[None, :] ** 2 + (MIN_NOISE_RMS * np.abs(Yk)) ** 2)
    info = {"period_samples": int(lag), "periods_averaged": int(n), "samples_per_bit": float(bit),
            "clock_hz": float(w.fs / bit), "band_hz": [float(f[keep][0]), float(f[keep][-1])],
            "bins": int(np.count_nonzero(keep)), "bin_stride": stride,
            "noise_rms": {s: float(noise["per_signal"][s]) for s in SIGNALS},
            "noise_method": noise["method"] + f"; per bin L sigma^2 / n plus ({MIN_NOISE_RMS:g} |Y|)^2",
            "edge_timing": timing.get("reason", "")}
    return PeriodicRecord(f[keep], Uk[keep], Yk, sigma, w.dt, info), (
        f"the bridge voltage repeats ({n + 1} periods of {lag} samples) and switches on the samples: "
        "the periods after the first are the arrangement's exact periodic response to it")


def alias_grid(f: np.ndarray, h: float, aliases: int = ALIASES) -> np.ndarray:
    """Signed angular frequencies ``W_m = w + 2 pi m / h``, shape ``(2 M + 1, B)``, rad/s."""
    m = np.arange(-aliases, aliases + 1)[:, None]
    return 2 * np.pi * (np.asarray(f)[None, :] + m / h)


def sampled_response(H: np.ndarray, W: np.ndarray, h: float) -> np.ndarray:
    """The zero-order-hold sampled response from the continuous one on the alias grid.

    Parameters
    ----------
    H : numpy.ndarray
        ``(..., 2 M + 1, B)`` continuous responses at ``j W``.
    W : numpy.ndarray, rad/s
        ``(2 M + 1, B)`` from :func:`alias_grid` (row ``M`` the base band).
    h : float, s

    Returns
    -------
    numpy.ndarray
        ``(..., B)`` the sampled response at the base-band frequencies.
    """
    s = 1j * W
    a = 0.5 * (H[..., 0, :] * s[0] + H[..., -1, :] * s[-1])  # asymptote a / s of the outermost terms
    w = W[W.shape[0] // 2]
    total = np.sum(H / s - a[..., None, :] / s ** 2, axis=-2) - a * (h / 2) ** 2 / np.sin(w * h / 2) ** 2
    return (1 - np.exp(-1j * w * h)) / h * total


def source_responses(zw: np.ndarray, W: np.ndarray, r: np.ndarray, l: np.ndarray, c: np.ndarray,
                     lsw: np.ndarray | None = None, csw: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``v_in / v_bridge`` and ``i_in / v_bridge`` of the PRIS source driving a port impedance ``zw``.

    The bridge (behind ``L_sw``, with ``C_sw`` across its output when given:
    :func:`pris_cosim.circuits.arrangement.source_circuit`) drives ``R``, ``L``, ``C`` in
    series into the port.

    Parameters
    ----------
    zw : numpy.ndarray, Ohm
        ``(P, ...)`` port impedance at ``j W``.
    W : numpy.ndarray, rad/s
        Signed angular frequencies broadcasting with ``zw``.
    r, l, c : numpy.ndarray, Ohm, H, F
        ``(P,)`` series values.
    lsw, csw : numpy.ndarray, H, F, optional
        ``(P,)`` switch parasitics.
    """
    shape = (-1,) + (1,) * (zw.ndim - 1)
    s = 1j * W
    zl = zw + r.reshape(shape) + s * l.reshape(shape) + 1 / (s * c.reshape(shape))
    i = 1 / zl
    if lsw is not None:
        y = s * csw.reshape(shape) + i
        i = i / (1 + s * lsw.reshape(shape) * y)
    return i * zw, i
