"""Perturbation signals: PRBS, H-bridge voltage, ideal PRIS, swept sine, metrics.

Implements the perturbation signals of thesis section 2.3 and the PRIS source
RLC design relations (2.18)-(2.19) and (4.15)-(4.17):

* maximal-length PRBS from a Fibonacci linear feedback shift register (LFSR),
* the bipolar H-bridge voltage sampled at a rate unrelated to the bit clock,
* the ideal Pseudo-Random Impulse Sequence (PRIS), eqs. (2.15)-(2.17),
* the swept sine, eqs. (2.11)-(2.13),
* crest factor (2.9) and time factor (2.10),
* series-RLC time constants, their inverse design and impedance scaling,
* the analytic PSD envelope of a random binary signal and a Welch estimator
  configured as in the thesis (Hann window, 62.5 % overlap).
"""

from __future__ import annotations

import warnings
from fractions import Fraction
from typing import Sequence

import numpy as np

__all__ = [
    "MAX_LENGTH_TAPS",
    "THESIS_BASE_RLC",
    "LFSR",
    "UnderdampedWarning",
    "lfsr_prbs",
    "bipolar",
    "hbridge_waveform",
    "pris_ideal",
    "swept_sine",
    "crest_factor",
    "time_factor",
    "damping_ratio",
    "rlc_time_constants",
    "lc_from_time_constants",
    "rlc_from_time_constants",
    "scale_rlc",
    "prbs_psd_theory",
]

#: Feedback taps of maximal-length Fibonacci LFSRs, keyed by order n.  Tap t
#: means register stage t (1-based, output taken from stage n) feeds the XOR;
#: equivalently the output bits obey ``s[j] = XOR over t of s[j - t]``, i.e. the
#: feedback polynomial is ``1 + sum(x**t)``, which is primitive over GF(2) for
#: every entry (checked algebraically in the test-suite).
MAX_LENGTH_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1),
    3: (3, 2),
    4: (4, 3),
    5: (5, 3),
    6: (6, 5),
    7: (7, 6),
    8: (8, 6, 5, 4),
    9: (9, 5),
    10: (10, 7),
    11: (11, 9),
    12: (12, 6, 4, 1),
    13: (13, 4, 3, 1),
    14: (14, 5, 3, 1),
    15: (15, 14),
    16: (16, 15, 13, 4),
    17: (17, 14),
    18: (18, 11),
    19: (19, 6, 2, 1),
    20: (20, 17),
    21: (21, 19),
    22: (22, 21),
    23: (23, 18),
    24: (24, 23, 22, 17),
    25: (25, 22),
    26: (26, 6, 2, 1),
    27: (27, 5, 2, 1),
    28: (28, 25),
    29: (29, 27),
    30: (30, 6, 4, 1),
    31: (31, 28),
    32: (32, 22, 2, 1),
}

#: PRIS source base components (R [Ohm], L [H], C [F]) as printed in thesis
#: section 4.1.2.  Note: the final source quoted there (31.8 kOhm, 2.53 H,
#: 10 nF) is the alpha = 1000 scaling of (31.8 Ohm, 2.53 mH, 10 uF), not of
#: this set; 253 mH is most likely a misprint of 2.53 mH.
THESIS_BASE_RLC: tuple[float, float, float] = (31.8, 0.253, 10e-6)

_MAX_DENOMINATOR = 2**31


class UnderdampedWarning(UserWarning):
    """The series RLC has complex poles, so (2.18)-(2.19) are not time constants."""


# --------------------------------------------------------------------------
# argument checks
# --------------------------------------------------------------------------


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite positive number, got {value!r}")
    return value


def _count(name: str, value: int, minimum: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _order(order: int) -> int:
    if isinstance(order, bool) or order not in MAX_LENGTH_TAPS:
        raise ValueError(
            f"order must be an integer in {min(MAX_LENGTH_TAPS)}..{max(MAX_LENGTH_TAPS)}, "
            f"got {order!r}"
        )
    return int(order)


# --------------------------------------------------------------------------
# PRBS
# --------------------------------------------------------------------------


def _seed_bits(order: int, seed: int | Sequence[int] | None) -> np.ndarray:
    """Seed as the first ``order`` output bits (uint8), defaulting to all ones."""
    if seed is None:
        return np.ones(order, dtype=np.uint8)
    if np.isscalar(seed):
        if int(seed) != seed or not 0 < seed < 2**order:
            raise ValueError(f"seed must be an integer in 1..{2**order - 1}, got {seed!r}")
        return np.array([(int(seed) >> (order - 1 - i)) & 1 for i in range(order)], dtype=np.uint8)
    bits = np.asarray(seed)
    if bits.shape != (order,) or not np.isin(bits, (0, 1)).all() or not bits.any():
        raise ValueError(f"seed must be {order} bits of 0/1, not all zero, got {seed!r}")
    return bits.astype(np.uint8)


def _run_recurrence(head: np.ndarray, taps: Sequence[int], total: int) -> np.ndarray:
    """Extend ``head`` to ``total >= len(head)`` bits with ``s[j] = XOR_t s[j - t]``.

    Over GF(2) squaring the feedback polynomial spreads its lags:
    ``p(x)**2 == p(x**2)``, so the same bits also obey
    ``s[j] = XOR_t s[j - t * step]`` for ``step = 2**m`` once ``j >= n * step``.
    Doubling ``step`` each time the known prefix doubles lets whole blocks of
    ``min(taps) * step`` bits be computed at once with array slices.
    """
    n = len(head)
    out = np.empty(total, dtype=np.uint8)
    out[:n] = head
    known, step = n, 1
    while known < total:
        stop = min(total, 2 * n * step)
        lags = [t * step for t in taps]
        block = min(lags)
        for j in range(known, stop, block):
            end = min(j + block, stop)
            acc = out[j - lags[0] : end - lags[0]].copy()
            for lag in lags[1:]:
                acc ^= out[j - lag : end - lag]
            out[j:end] = acc
        known, step = stop, 2 * step
    return out


class LFSR:
    """Stateful Fibonacci LFSR generating a maximal-length sequence.

    Parameters
    ----------
    order : int
        Register length n (2..32); the period is N = 2**n - 1 bits.
    seed : int or sequence of int, optional
        Initial register contents, which are also the first n output bits.
        A sequence gives those bits in output order; an int is read as its
        n-bit binary representation, most significant bit first.  Must not
        be all zeros.  Default all ones (``1111`` for PRBS4, as the thesis FPGA).

    Notes
    -----
    Generating in pieces equals generating at once: successive
    :meth:`next_bits` calls continue the sequence, and
    ``LFSR(order, seed=gen.state)`` resumes where ``gen`` stopped.
    """

    def __init__(self, order: int, seed: int | Sequence[int] | None = None) -> None:
        self.order = _order(order)
        self.taps = MAX_LENGTH_TAPS[self.order]
        self._next = _seed_bits(self.order, seed)

    @property
    def period(self) -> int:
        """Sequence period N = 2**n - 1, in bits."""
        return 2**self.order - 1

    @property
    def state(self) -> int:
        """Register contents as an int in the ``seed`` format (next n output bits)."""
        return int("".join(map(str, self._next)), 2)

    def next_bits(self, count: int) -> np.ndarray:
        """Return the next ``count`` output bits (uint8 0/1) and advance the state."""
        count = _count("count", count, 0)
        seq = _run_recurrence(self._next, self.taps, count + self.order)
        self._next = seq[count:].copy()
        return seq[:count]


def lfsr_prbs(order: int, periods: int = 1, seed: int | Sequence[int] | None = None) -> np.ndarray:
    """Maximal-length pseudo-random binary sequence (PRBS) from a Fibonacci LFSR.

    Parameters
    ----------
    order : int
        LFSR order n (2..32); period N = 2**n - 1 bits, eq. (2.14).
    periods : int, optional
        Number of whole periods to return (>= 1).
    seed : int or sequence of int, optional
        Initial register contents, see :class:`LFSR`; default all ones.

    Returns
    -------
    numpy.ndarray of uint8
        ``periods * N`` bits of 0/1.
    """
    periods = _count("periods", periods, 1)
    gen = LFSR(order, seed)
    return gen.next_bits(periods * gen.period)


def bipolar(bits: np.ndarray, vdc: float) -> np.ndarray:
    """H-bridge output levels for a bit sequence.

    Parameters
    ----------
    bits : array_like of int
        Bits of 0/1.
    vdc : float, V
        DC-link voltage; bit 1 gives +vdc, bit 0 gives -vdc.

    Returns
    -------
    numpy.ndarray of float, V
    """
    bits = np.asarray(bits)
    if not np.isin(bits, (0, 1)).all():
        raise ValueError("bits must contain only 0 and 1")
    vdc = _positive("vdc", vdc)
    return np.where(bits == 1, vdc, -vdc)


# --------------------------------------------------------------------------
# sampled waveforms
# --------------------------------------------------------------------------


def _clock_ratio(f_clk: float, fs: float) -> tuple[int, int]:
    """Integers (p, q) with f_clk / fs == p / q, q <= 2**31 (nearest such fraction)."""
    ratio = Fraction(_positive("f_clk", f_clk)) / Fraction(_positive("fs", fs))
    ratio = ratio.limit_denominator(_MAX_DENOMINATOR)
    return ratio.numerator, ratio.denominator


def _sample_grid(n_bits: int, f_clk: float, fs: float) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Sample indices k covering ``n_bits`` bits and the bit active at each k/fs."""
    p, q = _clock_ratio(f_clk, fs)
    n_samples = -(-n_bits * q // p)  # ceil: samples with k/fs < n_bits/f_clk
    if (n_samples - 1) * p >= 2**63 or n_bits * q >= 2**63:
        raise ValueError("fs / f_clk is too irregular for exact integer timing at this length")
    k = np.arange(n_samples, dtype=np.int64)
    return k, (k * p) // q, p, q


def hbridge_waveform(
    order: int,
    f_clk: float,
    fs: float,
    vdc: float,
    periods: int = 1,
    seed: int | Sequence[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Commanded H-bridge voltage driven by a PRBS, sampled with zero-order hold.

    Parameters
    ----------
    order : int
        LFSR order n of the PRBS.
    f_clk : float, Hz
        PRBS bit clock frequency.
    fs : float, Hz
        Sampling frequency; need not be a multiple of ``f_clk``.
    vdc : float, V
        DC-link voltage (levels +-vdc).
    periods : int, optional
        Number of PRBS periods to cover.
    seed : int or sequence of int, optional
        LFSR seed, see :class:`LFSR`.

    Returns
    -------
    t : numpy.ndarray, s
        Sample times k / fs covering [0, periods * N / f_clk).
    v : numpy.ndarray, V
        Sample k holds the bit active at k / fs, i.e. bit ``floor(k f_clk / fs)``.

    Notes
    -----
    Bit indices are computed with integer arithmetic on the ratio
    f_clk / fs = p / q, so the waveform never drifts relative to the bit clock.
    The ratio is exact whenever its reduced denominator is at most 2**31 (any
    pair of integer-Hz frequencies below 2 GHz); otherwise the nearest such
    fraction is used.
    """
    bits = lfsr_prbs(order, periods, seed)
    k, idx, _, _ = _sample_grid(bits.size, f_clk, fs)
    return k / float(fs), bipolar(bits[idx], vdc)


def pris_ideal(
    order: int,
    f_clk: float,
    fs: float,
    tau1: float,
    tau2: float,
    amplitude: float,
    periods: int = 1,
    seed: int | Sequence[int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Ideal pseudo-random impulse sequence (PRIS), eqs. (2.15)-(2.17).

    At every PRBS state transition t_i an impulse
    ``+-U [exp(-(t - t_i)/tau1) - exp(-(t - t_i)/tau2)]`` starts, positive for a
    rising (0 -> 1) and negative for a falling (1 -> 0) transition, and is
    chopped at the next transition t_{i+1} by the step window (2.17).

    Parameters
    ----------
    order : int
        LFSR order n of the controlling PRBS.
    f_clk : float, Hz
        PRBS bit clock frequency.
    fs : float, Hz
        Sampling frequency; need not be a multiple of ``f_clk``.
    tau1, tau2 : float, s
        Impulse time constants of (2.16); must differ.  With tau1 > tau2 (the
        ordering (2.18)-(2.19) produce) the impulse has the sign of the
        transition for positive ``amplitude``, tau1 sets its decay and tau2
        its rise.
    amplitude : float, A or V
        Impulse amplitude U of (2.16), in the unit of the returned signal.  For a
        series RLC driven by an H-bridge step of 2 vdc the current impulse has
        U = 2 vdc tau1 tau2 / (L (tau1 - tau2)).
    periods : int, optional
        Number of PRBS periods to cover.
    seed : int or sequence of int, optional
        LFSR seed, see :class:`LFSR`.

    Returns
    -------
    t : numpy.ndarray, s
        Sample times k / fs covering [0, periods * N / f_clk).
    u : numpy.ndarray, unit of ``amplitude``
        PRIS waveform.

    Notes
    -----
    Transition instants are the bit boundaries i / f_clk where the bit differs
    from its predecessor, taken cyclically: the PRBS is treated as periodic, so
    t = 0 is a transition when the last bit of the period differs from the
    first (true for the default all-ones seed), and samples before the first
    transition in the record carry the chopped impulse of the previous
    period's last transition.  The returned waveform is thus exactly one
    slice of the steady-state periodic PRIS.
    """
    tau1, tau2 = _positive("tau1", tau1), _positive("tau2", tau2)
    if tau1 == tau2:
        raise ValueError("tau1 and tau2 must differ: eq. (2.16) vanishes for equal time constants")
    bits = lfsr_prbs(order, periods, seed)
    edges = np.flatnonzero(bits != np.roll(bits, 1))
    k, idx, p, q = _sample_grid(bits.size, f_clk, fs)
    j = np.searchsorted(edges, idx, side="right") - 1
    start = edges[j] - np.where(j < 0, bits.size, 0)  # index -1 wraps to the previous period
    dt = (k * p - start * q) / (p * float(fs))  # k/fs - start/f_clk, exact numerator
    sign = np.where(bits[start], 1.0, -1.0)  # start may be negative: wraps within the period
    u = sign * float(amplitude) * (np.exp(-dt / tau1) - np.exp(-dt / tau2))
    return k / float(fs), u


def swept_sine(
    f1: float, f2: float, T0: float, fs: float, amplitude: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Linear swept sine (periodic chirp), eqs. (2.11)-(2.13).

    ``u(t) = A sin((a t + b) t)`` with ``a = pi (f2 - f1) / T0`` and
    ``b = 2 pi f1``, so the instantaneous frequency ``(2 a t + b) / (2 pi)``
    runs linearly from f1 at t = 0 to f2 at t = T0 (f1 is the start
    frequency; it may be above or below f2).

    Parameters
    ----------
    f1 : float, Hz
        Start frequency (>= 0).
    f2 : float, Hz
        End frequency (>= 0).
    T0 : float, s
        Sweep (measurement) period.
    fs : float, Hz
        Sampling frequency.
    amplitude : float, optional
        Amplitude A, in the unit of the returned signal.

    Returns
    -------
    t : numpy.ndarray, s
        ``round(T0 fs)`` sample times k / fs in [0, T0).
    u : numpy.ndarray
        Swept sine samples.
    """
    for name, value in (("f1", f1), ("f2", f2)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite frequency >= 0 Hz, got {value!r}")
    T0, fs = _positive("T0", T0), _positive("fs", fs)
    t = np.arange(round(T0 * fs)) / fs
    a = np.pi * (f2 - f1) / T0
    b = 2 * np.pi * f1
    return t, amplitude * np.sin((a * t + b) * t)


# --------------------------------------------------------------------------
# excitation quality metrics
# --------------------------------------------------------------------------


def crest_factor(u: np.ndarray) -> float:
    """Crest factor (2.9): peak absolute value over rms value.

    Parameters
    ----------
    u : array_like
        Signal samples (any unit); must not be all zero.

    Returns
    -------
    float
        ``max|u| / sqrt(mean(u**2))``; sqrt(2) for a sine, 1 for a square wave.
    """
    u = np.asarray(u, dtype=float)
    rms = np.sqrt(np.mean(u**2)) if u.size else 0.0
    if rms == 0:
        raise ValueError("u must contain at least one non-zero sample")
    return float(np.max(np.abs(u)) / rms)


def time_factor(u: np.ndarray, fs: float, fmin: float, fmax: float) -> float:
    """Time factor (2.10): ``0.5 Cr(u)**2 (A_rms / A_min)**2``.

    Parameters
    ----------
    u : array_like
        Signal samples (any unit), ideally an integer number of its periods.
    fs : float, Hz
        Sampling frequency.
    fmin, fmax : float, Hz
        Band of interest, inclusive.

    Returns
    -------
    float
        Time factor; larger for less efficient excitations.  A sine whose
        frequency lies on a DFT bin, analysed over a band containing only that
        bin, gives 1 (exactly, if the samples include its peak; otherwise
        slightly less, since the sampled crest factor is below sqrt(2)).

    Notes
    -----
    The amplitude spectrum is ``|rfft(u)|`` on the bins k fs / len(u).  A_rms is
    the rms and A_min the minimum of that spectrum over the bins with
    fmin <= f <= fmax (at least one bin is required).
    """
    u = np.asarray(u, dtype=float)
    fs = _positive("fs", fs)
    if not 0 <= fmin <= fmax:
        raise ValueError(f"fmin and fmax must satisfy 0 <= fmin <= fmax, got {fmin!r}, {fmax!r}")
    spectrum = np.abs(np.fft.rfft(u))
    freqs = np.arange(spectrum.size) * fs / u.size
    band = spectrum[(freqs >= fmin) & (freqs <= fmax)]
    if band.size == 0:
        raise ValueError(f"fmin..fmax ({fmin}..{fmax} Hz) contains no DFT bin")
    if band.min() == 0:
        raise ValueError("the amplitude spectrum is zero somewhere in fmin..fmax")
    a_rms = np.sqrt(np.mean(band**2))
    return float(0.5 * crest_factor(u) ** 2 * (a_rms / band.min()) ** 2)


# --------------------------------------------------------------------------
# PRIS source RLC design
# --------------------------------------------------------------------------


def damping_ratio(R: float, L: float, C: float) -> float:
    """Damping ratio ``zeta = (R / 2) sqrt(C / L)`` of a series RLC.

    Parameters
    ----------
    R : float, Ohm
    L : float, H
    C : float, F

    Returns
    -------
    float
        < 1 underdamped (complex poles), 1 critical, > 1 overdamped.
    """
    R, L, C = _positive("R", R), _positive("L", L), _positive("C", C)
    return float(R / 2 * np.sqrt(C / L))


def rlc_time_constants(R: float, L: float, C: float) -> tuple[float, float]:
    """PRIS impulse time constants of a series RLC, eqs. (2.18)-(2.19).

    The current after a voltage step is a sum of ``exp(s t)`` terms with poles
    ``s = -R/(2L) -+ sqrt((R/(2L))**2 - 1/(LC))``; tau = 1 / |s|.

    Parameters
    ----------
    R : float, Ohm
    L : float, H
    C : float, F

    Returns
    -------
    tau1, tau2 : float, s
        tau1 >= tau2.  Overdamped: tau1 is the slow (decay) and tau2 the fast
        (rise) constant of (2.16).  Underdamped: following the thesis's
        absolute values, both equal ``|s| = 1 / sqrt(LC)`` inverted, i.e.
        ``tau1 = tau2 = sqrt(LC)``, and an :class:`UnderdampedWarning` is issued
        because the response is then a damped oscillation, not (2.16).
    """
    zeta = damping_ratio(R, L, C)
    w0_sq = 1 / (L * C)
    if zeta < 1:
        warnings.warn(
            f"series RLC is underdamped (zeta={zeta:.4g}): poles are complex, "
            "returning tau1 = tau2 = sqrt(LC) from their magnitudes",
            UnderdampedWarning,
            stacklevel=2,
        )
        tau = np.sqrt(L * C)
        return float(tau), float(tau)
    sigma = R / (2 * L)
    s_fast = sigma + np.sqrt(sigma**2 - w0_sq)
    s_slow = w0_sq / s_fast  # product of the pole magnitudes is 1/(LC); avoids cancellation
    return float(1 / s_slow), float(1 / s_fast)


def lc_from_time_constants(tau1: float, tau2: float, R: float) -> tuple[float, float]:
    """Series L and C giving time constants tau1, tau2 with a chosen R.

    Solves ``1/tau1 + 1/tau2 = R/L`` and ``1/(tau1 tau2) = 1/(LC)``:
    ``L = R tau1 tau2 / (tau1 + tau2)`` and ``C = (tau1 + tau2) / R``.

    Parameters
    ----------
    tau1, tau2 : float, s
        Desired time constants (order irrelevant; equal values give critical
        damping).
    R : float, Ohm
        Series resistance.

    Returns
    -------
    L : float, H
    C : float, F
    """
    tau1, tau2, R = _positive("tau1", tau1), _positive("tau2", tau2), _positive("R", R)
    return R * tau1 * tau2 / (tau1 + tau2), (tau1 + tau2) / R


def scale_rlc(R: float, L: float, C: float, alpha: float) -> tuple[float, float, float]:
    """Impedance scaling (4.15)-(4.17): ``(R alpha, L alpha, C / alpha)``.

    Scales the RLC impedance magnitude by alpha at every frequency while leaving
    the time constants (and the damping ratio) unchanged.

    Parameters
    ----------
    R : float, Ohm
    L : float, H
    C : float, F
    alpha : float
        Dimensionless impedance scale factor.

    Returns
    -------
    R, L, C : float
        Scaled components in Ohm, H, F.
    """
    R, L, C = _positive("R", R), _positive("L", L), _positive("C", C)
    alpha = _positive("alpha", alpha)
    return R * alpha, L * alpha, C / alpha


def rlc_from_time_constants(
    tau1: float, tau2: float, impedance_level: float = 1.0
) -> tuple[float, float, float]:
    """Series RLC with time constants tau1, tau2 at a given impedance level.

    Parameters
    ----------
    tau1, tau2 : float, s
        Desired time constants.
    impedance_level : float, optional
        Dimensionless alpha of (4.15)-(4.17): R = alpha * 31.8 Ohm (the thesis
        base resistance), then L and C from :func:`lc_from_time_constants`.
        Changing it is exactly :func:`scale_rlc` of the result.

    Returns
    -------
    R, L, C : float
        Components in Ohm, H, F.
    """
    R = THESIS_BASE_RLC[0] * _positive("impedance_level", impedance_level)
    return (R, *lc_from_time_constants(tau1, tau2, R))


# --------------------------------------------------------------------------
# spectra
# --------------------------------------------------------------------------


def prbs_psd_theory(f: np.ndarray, f_clk: float, vdc: float) -> np.ndarray:
    """One-sided PSD envelope of a random bipolar binary signal.

    ``S(f) = 2 vdc**2 / f_clk * sinc(f / f_clk)**2`` with
    ``sinc(x) = sin(pi x) / (pi x)``: flat at low frequency, nulls at multiples
    of f_clk, -1.65 dB at f_clk / 3 and -3 dB at about 0.443 f_clk.

    Parameters
    ----------
    f : array_like, Hz
        Frequencies.
    f_clk : float, Hz
        Bit clock frequency.
    vdc : float, V
        Signal levels +-vdc.

    Returns
    -------
    numpy.ndarray, V**2/Hz
        Comparable with ``welch_psd`` (one-sided density) for 0 < f < fs/2.  A
        maximal-length PRBS has lines spaced f_clk/N whose smoothed density is
        this envelope times (N + 1)/N.
    """
    f_clk, vdc = _positive("f_clk", f_clk), _positive("vdc", vdc)
    return 2 * vdc**2 / f_clk * np.sinc(np.asarray(f, dtype=float) / f_clk) ** 2
