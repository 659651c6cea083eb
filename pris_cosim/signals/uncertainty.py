"""Which bins of a PRBS-excited H1 estimate carry information, and how uncertain each one is.

* :func:`clock_null_mask` -- the bins near the nulls of the PRBS spectrum
  ``sinc^2(f/f_clk)`` at the multiples of the clock, where the source does
  not excite the device (the estimate there is noise and leakage);
* :func:`welch_averages` -- the number of segments a Welch estimate averages;
* :func:`h1_log_sd` -- the standard deviation of ``ln H1`` from the
  coherence (Bendat and Piersol, *Random Data*, 4th ed., eq. 9.90 and 9.91:
  the normalised random error of ``|H1|`` and the standard deviation of its
  phase in radians are both ``sqrt(1 - g^2) / (|g| sqrt(2 n_d))``);
* :func:`pooled` -- a moving mean over neighbouring bins: the coherence is
  pooled over ``POOL_BINS`` bins before the error formula (an estimate from
  a few segments scatters too much bin by bin: with three segments and a
  true coherence of 0.6 one bin in six comes out below 1/3, where the bias
  correction leaves nothing);
* :func:`local_linear` -- the response and that standard deviation at
  log-spaced frequencies, from a local straight line through the nearest
  bins (not a band average, which flattens resonances narrower than the
  band).

All frequencies in Hz; standard deviations in complex-log units (0.01 is
1 % in magnitude and 0.57 degrees in phase).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["NULL_WIDTH", "clock_null_mask", "h1_log_sd", "local_linear", "log_band_edges", "pooled", "welch_averages"]

#: Bins within this fraction of the clock from one of its non-zero multiples are near a PRBS null.
NULL_WIDTH = 0.08
#: Coherence is clipped to [MIN_COHERENCE_CLIP, 1 - MIN_COHERENCE_CLIP] before the error formula.
MIN_COHERENCE_CLIP = 1e-6
#: Bins the coherence is pooled over (:func:`pooled`).
POOL_BINS = 8
#: Most bins a value at a log-spaced frequency is fitted from (:func:`local_linear`).
LOCAL_BINS = 5


def clock_null_mask(frequency_hz: ArrayLike, fclk: float, width: float = NULL_WIDTH) -> NDArray[np.bool_]:
    """True where a frequency lies within ``width * fclk`` of a non-zero multiple of the clock ``fclk``.

    Parameters
    ----------
    frequency_hz : array_like, Hz
    fclk : float, Hz
        PRBS clock frequency (> 0).
    width : float
        Half-width of each excluded band, as a fraction of the clock (0 <= width < 0.5).

    Returns
    -------
    numpy.ndarray of bool
        ``|f/fclk - n| < width`` for the nearest integer ``n >= 1``.
    """
    if not fclk > 0:
        raise ValueError(f"fclk must be positive, got {fclk!r}")
    if not 0 <= width < 0.5:
        raise ValueError(f"width must lie in [0, 0.5), got {width!r}")
    x = np.asarray(frequency_hz, float) / float(fclk)
    n = np.round(x)
    return (np.abs(x - n) < width) & (n >= 1)


def pooled(values: ArrayLike, pool: int = POOL_BINS) -> NDArray[np.float64]:
    """Mean of ``values`` over ``pool`` neighbouring bins (a window centred where it can be, shifted at the ends)."""
    v = np.asarray(values, float)
    if v.size == 0 or pool <= 1:
        return v.copy()
    pool = min(pool, v.size)
    csum = np.concatenate(([0.0], np.cumsum(v)))
    a = np.clip(np.arange(v.size) - pool // 2, 0, v.size - pool)
    return (csum[a + pool] - csum[a]) / pool


def welch_averages(n_samples: int, nperseg: int, overlap: float) -> int:
    """Segments a Welch estimate averages: ``1 + (N - nperseg) // (nperseg - round(overlap nperseg))``."""
    step = max(1, nperseg - round(overlap * nperseg))
    return 1 + max(0, n_samples - nperseg) // step


def h1_log_sd(coherence: ArrayLike, n_averages: int) -> NDArray[np.float64]:
    """Standard deviation of ``ln|H1|`` (and of its phase in rad) from the coherence and the averages.

    ``sqrt((1 - g^2) / (2 n_d g^2))``, where ``g^2`` is the estimated
    coherence corrected for its bias from ``n_d`` averages,
    ``(n_d g_est^2 - 1) / (n_d - 1)`` (an estimate from few segments is
    biased towards 1: from one segment it is 1 whatever the noise), and
    clipped to ``[MIN_COHERENCE_CLIP, 1 - MIN_COHERENCE_CLIP]``. A
    first-order result, meaningful for small errors (where it is large the
    estimate has no information, which is what it says).
    """
    if n_averages < 1:
        raise ValueError(f"n_averages must be >= 1, got {n_averages!r}")
    g2 = np.asarray(coherence, float)
    if n_averages > 1:
        g2 = (n_averages * g2 - 1) / (n_averages - 1)
    g2 = np.clip(g2, MIN_COHERENCE_CLIP, 1 - MIN_COHERENCE_CLIP)
    return np.sqrt((1 - g2) / (2 * n_averages * g2))


def log_band_edges(centres: ArrayLike) -> NDArray[np.float64]:
    """Band edges halfway in log frequency between log-spaced ``centres`` (as :func:`.spectral.log_resample`)."""
    lc = np.log(np.asarray(centres, float))
    half = 0.5 * (lc[1] - lc[0])
    return np.exp(np.concatenate(([lc[0] - half], 0.5 * (lc[:-1] + lc[1:]), [lc[-1] + half])))


def local_linear(frequency_hz: ArrayLike, values: ArrayLike, bin_sd: ArrayLike, centres: ArrayLike,
                 max_bins: int = LOCAL_BINS) -> tuple[NDArray[np.complex128], NDArray[np.float64], NDArray[np.int_]]:
    """A response at log-spaced ``centres`` from its bins: a local straight line through the nearest bins.

    At each centre whose log band (halfway to the neighbouring centres) holds
    ``m >= 1`` bins, a straight line in frequency is fitted (least squares) to
    the complex values of the ``max(2, min(max_bins, m))`` bins nearest the
    centre and evaluated at the centre, provided the centre lies between
    those bins (no extrapolation; otherwise the centre counts as holding no
    bin). Unlike a band average it is not
    biased by the slope of the response, and with few bins it is hardly
    biased by its curvature (a band of 2.3 % averaged over a resonance
    narrower than the band flattens it); the noise it leaves is the bins'
    noise through the fit's weights, ``sqrt(sum_i w_i^2 s_i^2)``, with each
    ``s_i^2`` the mean of ``bin_sd^2`` over at least ``pool`` bins around it
    (the noise level changes slowly with frequency; a coherence from a few
    segments does not).

    Parameters
    ----------
    frequency_hz : array_like, Hz
        Bin frequencies (increasing, at least 2).
    values : array_like of complex
        Response at the bins.
    bin_sd : array_like
        Standard deviation of ``ln H`` per bin (:func:`h1_log_sd`).
    centres : array_like, Hz
        Log-spaced output frequencies.
    max_bins : int

    Returns
    -------
    values : numpy.ndarray of complex
        At the centres (NaN where the band holds no bin).
    sd : numpy.ndarray
        Standard deviation of ``ln H`` there (``inf`` where no bin).
    m : numpy.ndarray of int
        Bins in each band (0 where the centre would be extrapolated).
    """
    f = np.asarray(frequency_hz, float)
    h = np.asarray(values, complex)
    c = np.asarray(centres, float)
    if f.size < 2:
        raise ValueError("need at least 2 bins")
    v = np.asarray(bin_sd, float) ** 2
    edges = log_band_edges(c)
    m = np.searchsorted(f, edges[1:], side="left") - np.searchsorted(f, edges[:-1], side="left")
    out = np.full(c.size, np.nan + 0j)
    sd = np.full(c.size, np.inf)
    for j in np.flatnonzero(m > 0):
        k = max(2, min(max_bins, int(m[j])))
        i = int(np.searchsorted(f, c[j]))
        lo = max(0, min(i - k, f.size - 2 * k))
        cand = np.arange(lo, min(f.size, lo + 2 * k))
        sel = cand[np.argsort(np.abs(f[cand] - c[j]), kind="stable")[:k]]
        if not f[sel].min() <= c[j] <= f[sel].max():  # no extrapolation (e.g. at the edge of a left-out null)
            m[j] = 0
            continue
        x = (f[sel] - c[j]) / max(float(np.ptp(f[sel])), 1e-300)
        A = np.column_stack([np.ones(sel.size), x])
        w = np.linalg.pinv(A)[0]  # weights giving the line's value at the centre
        out[j] = w @ h[sel]
        sd[j] = float(np.sqrt(np.sum(w ** 2 * v[sel])))
    return out, sd, m
