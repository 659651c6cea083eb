"""Tests for pris_cosim.signals.spectral.

References are independent of the module: scipy.signal.welch/csd for the
wrapped spectra, scipy.signal.freqz for the response of a known discrete
filter driven by seeded white noise or by a maximum-length sequence (PRBS),
closed-form coherence s/(1+s), and closed-form functions for resampling.
Every random signal is seeded; the tolerances are explained where they are set.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from pris_cosim.signals.spectral import (DEFAULT_OVERLAP, FrequencyResponse, coherence, cross_psd, estimate_response,
    log_resample, synthesise_two_clock, tfestimate, welch_psd)

FS = 100e3  # Hz
N = 2**16


def resonant_filter() -> tuple[np.ndarray, np.ndarray]:
    """A second-order discrete system with a resonance (~5 kHz) and an anti-resonance (~12.5 kHz).

    |H| spans 0.14 .. 25.6, like a winding impedance with a parallel/series pair.
    """
    p = 0.97 * np.exp(1j * 0.1 * np.pi)
    z = 0.95 * np.exp(1j * 0.25 * np.pi)
    a = np.real(np.poly([p, np.conj(p)]))
    b = np.real(np.poly([z, np.conj(z)]))
    return b, a


def true_response(f: np.ndarray, b: np.ndarray, a: np.ndarray, fs: float = FS) -> np.ndarray:
    return signal.freqz(b, a, worN=f, fs=fs)[1]


def prbs(n: int, samples_per_bit: int, nbits: int = 12) -> np.ndarray:
    """Bipolar maximum-length sequence, each bit held for ``samples_per_bit`` samples."""
    seq = signal.max_len_seq(nbits)[0] * 2.0 - 1.0
    held = np.repeat(seq, samples_per_bit)
    return np.tile(held, n // held.size + 1)[:n]


@pytest.fixture(scope="module")
def white() -> np.ndarray:
    return np.random.default_rng(1).standard_normal(N)


# ---------------------------------------------------------------------------
# Welch spectra: defaults, agreement with scipy, Parseval
# ---------------------------------------------------------------------------


def test_welch_defaults_are_thesis_settings(white):
    f, pxx = welch_psd(white, FS)
    nperseg = N // 2
    f_ref, p_ref = signal.welch(
        white, fs=FS, window="hann", nperseg=nperseg, noverlap=round(0.625 * nperseg), scaling="density"
    )
    assert DEFAULT_OVERLAP == 0.625
    assert f.size == nperseg // 2 + 1
    assert f[1] == pytest.approx(FS / nperseg)
    np.testing.assert_allclose(f, f_ref, rtol=1e-14)
    np.testing.assert_allclose(pxx, p_ref, rtol=1e-12)


def test_cross_psd_matches_scipy_and_reduces_to_psd(white):
    y = signal.lfilter(*resonant_filter(), white)
    f, pxy = cross_psd(white, y, FS, nperseg=1024)
    _, ref = signal.csd(white, y, fs=FS, window="hann", nperseg=1024, noverlap=640)
    np.testing.assert_allclose(pxy, ref, rtol=1e-12)
    _, pxx_c = cross_psd(white, white, FS, nperseg=1024)
    _, pxx = welch_psd(white, FS, nperseg=1024)
    np.testing.assert_allclose(pxx_c.real, pxx, rtol=1e-12)
    np.testing.assert_allclose(pxx_c.imag, 0.0, atol=1e-15 * pxx.max())


def test_window_array_sets_segment_length(white):
    win = signal.windows.hamming(512, sym=False)
    f, pxx = welch_psd(white, FS, window=win, overlap=0.5)
    _, ref = signal.welch(white, fs=FS, window=win, nperseg=512, noverlap=256)
    assert f.size == 257
    np.testing.assert_allclose(pxx, ref, rtol=1e-12)


@pytest.mark.parametrize("nperseg", [None, 1024])
def test_parseval_psd_integrates_to_variance(white, nperseg):
    # Coloured noise. Welch with density scaling normalises each windowed
    # segment by sum(w**2), so sum(P) df is the mean windowed power; it differs
    # from the sample variance only by segment-to-segment fluctuation
    # (~0.2 % here). 1 % leaves room without hiding a wrong scaling (a
    # two-sided or window-gain error is a factor of 2 or 1.5).
    x = signal.lfilter(*resonant_filter(), white)
    f, pxx = welch_psd(x, FS, nperseg=nperseg)
    assert np.sum(pxx) * (f[1] - f[0]) == pytest.approx(np.var(x), rel=0.01)


@pytest.mark.parametrize("f0", [1234.5, 10000.0])
def test_parseval_sinusoid_power(f0):
    # A sinusoid of amplitude A has power A**2/2 whatever the window leakage;
    # off-bin and on-bin frequencies both within 1e-3 (observed < 1e-6).
    t = np.arange(N) / FS
    amp = 3.0
    f, pxx = welch_psd(amp * np.sin(2 * np.pi * f0 * t + 0.3), FS)
    assert np.sum(pxx) * (f[1] - f[0]) == pytest.approx(amp**2 / 2, rel=1e-3)
    assert abs(f[np.argmax(pxx)] - f0) <= f[1]


# ---------------------------------------------------------------------------
# tfestimate against a known filter
# ---------------------------------------------------------------------------


def test_tfestimate_matches_freqz_white_noise(white):
    # Noise-free: the only error is window leakage plus the filter transient at
    # segment edges, largest at the resonance peak (observed 0.65 %). Bound:
    # 2 % anywhere with coherence > 0.99, 0.1 % in the median.
    b, a = resonant_filter()
    y = signal.lfilter(b, a, white)
    f, h = tfestimate(white, y, FS)
    _, coh = coherence(white, y, FS)
    ht = true_response(f, b, a)
    good = (f > 0) & (coh > 0.99)
    assert good.sum() > 0.99 * (f.size - 1)
    rel = np.abs(h[good] / ht[good] - 1)
    assert rel.max() < 0.02
    assert np.median(rel) < 1e-3


def test_tfestimate_matches_freqz_prbs():
    # PRBS clocked at 10 kHz (10 samples per bit): its power falls towards the
    # sinc nulls at multiples of the clock, so the thesis uses it up to
    # f_clk/3; there the error is as for white noise (observed 0.43 %).
    b, a = resonant_filter()
    u = prbs(N, 10)
    y = signal.lfilter(b, a, u)
    f, h = tfestimate(u, y, FS)
    band = (f > 0) & (f < FS / 10 / 3)
    rel = np.abs(h[band] / true_response(f[band], b, a) - 1)
    assert rel.max() < 0.02
    assert np.median(rel) < 1e-3


def test_tfestimate_convention_is_output_over_input(white):
    # A pure delay of d samples has phase -2 pi f d / fs (lagging). With the
    # conjugate on the wrong signal the phase would come out leading.
    d = 3
    y = np.concatenate((np.zeros(d), white[:-d]))
    f, h = tfestimate(white, y, FS, nperseg=1024)
    resid = h * np.exp(2j * np.pi * f * d / FS)
    assert np.max(np.abs(np.angle(resid))) < 0.01  # rad; observed 3.3e-3
    assert np.max(np.abs(np.abs(h) - 1)) < 0.01
    # Swapping the arguments estimates the inverse system.
    _, h_inv = tfestimate(y, white, FS, nperseg=1024)
    assert np.max(np.abs(np.angle(h_inv * np.exp(-2j * np.pi * f * d / FS)))) < 0.01


def test_tfestimate_static_gain_is_exact(white):
    f, h = tfestimate(white, -2.5 * white, FS, nperseg=256)
    np.testing.assert_allclose(h, -2.5, rtol=1e-12)


# ---------------------------------------------------------------------------
# coherence
# ---------------------------------------------------------------------------


def test_coherence_is_one_without_noise(white):
    y = signal.lfilter(*resonant_filter(), white)
    _, coh = coherence(white, y, FS)
    assert coh[1:].min() > 0.999
    _, coh = coherence(white, y, FS, nperseg=4096)  # ~40 segments, more leakage
    assert coh[1:].min() > 0.99


@pytest.mark.parametrize("snr", [0.25, 1.0, 4.0])
def test_coherence_flat_snr_matches_theory(white, snr):
    # y = x + n with output SNR s gives coherence s/(1+s). With 256-sample
    # segments (~680 overlapping averages) the estimator bias, about
    # (1-C)**2 / n_eff, is < 1e-3 and the per-bin spread a few per cent:
    # the mean over bins within 0.01, every bin within 0.1 (observed <= 0.067).
    rng = np.random.default_rng(7)
    y = white + rng.standard_normal(N) / np.sqrt(snr)
    _, coh = coherence(white, y, FS, nperseg=256)
    c = coh[1:-1]
    expected = snr / (1 + snr)
    assert c.mean() == pytest.approx(expected, abs=0.01)
    assert np.max(np.abs(c - expected)) < 0.1


def test_coherence_frequency_dependent_snr(white):
    # Filter output plus white noise: s(f) = |H(f)|**2 var(x) / var(n) runs
    # from 1e-3 to 25, so the theory curve sweeps 0 .. 0.96. Median deviation
    # < 0.02, 95th percentile < 0.06 (observed 0.009 and 0.034); the tail is
    # leakage at the sharp resonance plus estimator spread.
    b, a = resonant_filter()
    sigma_n = 5.0
    rng = np.random.default_rng(11)
    y = signal.lfilter(b, a, white) + sigma_n * rng.standard_normal(N)
    f, coh = coherence(white, y, FS, nperseg=512)
    s = np.abs(true_response(f, b, a)) ** 2 / sigma_n**2
    err = np.abs(coh - s / (1 + s))[1:-1]
    assert np.median(err) < 0.02
    assert np.percentile(err, 95) < 0.06


def test_coherence_of_a_single_segment_is_one():
    # The documented caveat: with one segment coherence carries no information.
    rng = np.random.default_rng(2)
    x, y = rng.standard_normal(4096), rng.standard_normal(4096)
    _, coh = coherence(x, y, FS, nperseg=4096)
    np.testing.assert_allclose(coh[1:-1], 1.0, rtol=1e-9)


# ---------------------------------------------------------------------------
# H1 bias
# ---------------------------------------------------------------------------


def _mean_ratio(x: np.ndarray, y: np.ndarray, b: np.ndarray, a: np.ndarray) -> complex:
    f, h = tfestimate(x, y, FS, nperseg=512)
    return complex(np.mean(h[1:-1] / true_response(f[1:-1], b, a)))


def test_h1_unbiased_by_output_noise_biased_by_input_noise(white):
    # Output noise shaped like the signal (y = h * (x + n'), var n' = var x)
    # makes the SNR 1 at every frequency (coherence 0.5). H1 stays unbiased:
    # the mean of H/H_true over 255 bins is 1 within 0.02 (per-bin spread
    # ~5 %, averaged over ~100 independent bins). Noise of equal variance on
    # the input instead pulls H1 to Pxx/(Pxx+Pnn) = 0.5.
    b, a = resonant_filter()
    rng = np.random.default_rng(5)
    y_noisy = signal.lfilter(b, a, white + rng.standard_normal(N))
    ratio = _mean_ratio(white, y_noisy, b, a)
    assert abs(ratio - 1) < 0.02
    x_noisy = white + rng.standard_normal(N)
    ratio_in = _mean_ratio(x_noisy, signal.lfilter(b, a, white), b, a)
    assert abs(ratio_in - 0.5) < 0.02


# ---------------------------------------------------------------------------
# estimate_response and FrequencyResponse
# ---------------------------------------------------------------------------


def test_estimate_response_drops_dc_and_limits_band(white):
    b, a = resonant_filter()
    y = signal.lfilter(b, a, white)
    resp = estimate_response(white, y, FS, nperseg=1024, name="H")
    f, h = tfestimate(white, y, FS, nperseg=1024)
    _, coh = coherence(white, y, FS, nperseg=1024)
    assert resp.name == "H"
    assert resp.frequency_hz[0] == pytest.approx(FS / 1024)
    np.testing.assert_array_equal(resp.frequency_hz, f[1:])
    np.testing.assert_allclose(resp.values, h[1:], rtol=1e-12)
    np.testing.assert_allclose(resp.coherence, coh[1:], rtol=1e-12)

    part = estimate_response(white, y, FS, fmin=1000, fmax=20000, nperseg=1024)
    assert part.frequency_hz[0] >= 1000 and part.frequency_hz[-1] <= 20000
    assert part.frequency_hz[0] - 1000 < FS / 1024 and 20000 - part.frequency_hz[-1] < FS / 1024
    assert len(part) == part.coherence.size


def test_frequency_response_helpers():
    resp = FrequencyResponse(np.array([1.0, 10.0, 100.0]), np.array([1j, -10.0, 0.1 - 0.1j]), name="z")
    np.testing.assert_allclose(resp.mag, [1.0, 10.0, np.sqrt(0.02)])
    np.testing.assert_allclose(resp.phase_deg, [90.0, 180.0, -45.0])
    np.testing.assert_allclose(resp.db, [0.0, 20.0, 20 * np.log10(np.sqrt(0.02))])
    assert resp.values.dtype == np.complex128
    assert resp.coherence is None and len(resp) == 3
    sub = resp.band(5.0, 100.0)
    np.testing.assert_array_equal(sub.frequency_hz, [10.0, 100.0])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"frequency_hz": [[1.0, 2.0]], "values": [[1, 2]]}, "frequency_hz must be 1-D"),
        ({"frequency_hz": [2.0, 1.0], "values": [1, 2]}, "strictly increasing"),
        ({"frequency_hz": [-1.0, 1.0], "values": [1, 2]}, "frequency_hz must be finite and >= 0"),
        ({"frequency_hz": [1.0, 2.0], "values": [1, 2, 3]}, "values must have the shape"),
        ({"frequency_hz": [1.0, 2.0], "values": [1, 2], "coherence": [1.0]}, "coherence must have the shape"),
    ],
)
def test_frequency_response_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        FrequencyResponse(**kwargs)


# ---------------------------------------------------------------------------
# argument validation of the estimators
# ---------------------------------------------------------------------------

_X = np.random.default_rng(0).standard_normal(64)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: welch_psd(_X, 0.0), "fs must be finite and > 0"),
        (lambda: welch_psd(_X, float("nan")), "fs must be finite and > 0"),
        (lambda: welch_psd(_X, "1e3"), "fs must be a real number"),
        (lambda: welch_psd(_X.reshape(8, 8), FS), "x must be 1-D"),
        (lambda: welch_psd(_X + 1j, FS), "x must hold real numbers"),
        (lambda: welch_psd(np.r_[_X, np.nan], FS), "x contains NaN"),
        (lambda: welch_psd(_X[:3], FS), "x needs at least 4 samples"),
        (lambda: welch_psd(_X, FS, nperseg=65), r"nperseg must be in \[2, len\(x\)=64\]"),
        (lambda: welch_psd(_X, FS, nperseg=16.0), "nperseg must be an integer"),
        (lambda: welch_psd(_X, FS, overlap=1.0), r"overlap must be in \[0, 1\)"),
        (lambda: welch_psd(_X, FS, nperseg=2, overlap=0.9), "overlap=0.9 leaves no step"),
        (lambda: welch_psd(_X, FS, window="nosuchwindow"), "window 'nosuchwindow'"),
        (lambda: welch_psd(_X, FS, window=np.ones(8), nperseg=16), "does not match the window"),
        (lambda: welch_psd(_X, FS, detrend="quadratic"), "detrend must be"),
        (lambda: cross_psd(_X, _X[:-1], FS), "x and y must have the same length"),
        (lambda: tfestimate(_X, [[1.0]], FS), "y must be 1-D"),
        (lambda: coherence(_X, _X, -5.0), "fs must be finite and > 0"),
        (lambda: estimate_response(_X, _X, FS, fmin=10, fmax=5), "fmin=10.0 must not exceed fmax=5.0"),
        (lambda: estimate_response(_X, _X, FS, fmin=-1), "fmin must be finite and >= 0"),
        (lambda: estimate_response(_X, _X, FS, fmin=FS), "no frequencies"),
    ],
)
def test_estimator_validation(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_zero_input_gives_nan_not_warnings():
    # Pxx == 0 everywhere: H and coherence are NaN, and no warning is raised
    # (the suite runs with warnings as errors).
    f, h = tfestimate(np.zeros(256), np.ones(256), FS, nperseg=64)
    assert np.all(np.isnan(h))
    _, coh = coherence(np.zeros(256), np.ones(256), FS, nperseg=64)
    assert np.all(np.isnan(coh))


# ---------------------------------------------------------------------------
# log_resample
# ---------------------------------------------------------------------------


def smooth(f: np.ndarray) -> np.ndarray:
    """First-order low-pass times a damped (Q = 5) resonance at 8 kHz with a zero at 3 kHz."""
    s = 1j * f
    return 1 / (1 + s / 1000.0) * (1 + s / 3000.0) / (1 - (f / 8000.0) ** 2 + s / 8000.0)


F_LIN = np.linspace(0.0, 50e3, 20001)  # 2.5 Hz bins, DC included


def test_log_resample_interp_reproduces_smooth_function():
    # Linear interpolation of log|H| and phase over log f: error is second
    # order in the spacing of the source bins (2.5 Hz); observed 3e-5, so 1e-4.
    f_new, h_new = log_resample(F_LIN, smooth(F_LIN), 10.0, 40e3, 40, method="interp")
    assert f_new[0] == 10.0 and f_new[-1] == 40e3
    np.testing.assert_allclose(np.diff(np.log(f_new)), np.log(4000) / 39, rtol=1e-9)
    np.testing.assert_allclose(h_new, smooth(f_new), rtol=1e-4)


def test_log_resample_average_reproduces_smooth_function():
    # Band averaging smooths: its bias grows with (band width)**2 times the
    # curvature, largest at the resonance. With 100 points over 3.6 decades
    # (bands 8.7 % wide, resonance 1/Q = 20 % wide) observed 0.28 %; 1 %.
    # Below ~30 Hz the log bands are narrower than the 2.5 Hz bins and hold
    # one bin or none; those are filled by interpolation and stay exact too.
    f_new, h_new = log_resample(F_LIN, smooth(F_LIN), 10.0, 40e3, 100)
    np.testing.assert_allclose(h_new, smooth(f_new), rtol=0.01)
    low = f_new < 30
    np.testing.assert_allclose(h_new[low], smooth(f_new[low]), rtol=1e-4)


def test_log_resample_average_reduces_variance():
    # 10 % complex noise per bin. At high frequency each band holds hundreds
    # of bins, so the averaged error is far below the interpolated one.
    rng = np.random.default_rng(3)
    noisy = smooth(F_LIN) * (1 + 0.1 * (rng.standard_normal(F_LIN.size) + 1j * rng.standard_normal(F_LIN.size)))
    f_new, h_avg = log_resample(F_LIN, noisy, 10.0, 40e3, 60)
    _, h_int = log_resample(F_LIN, noisy, 10.0, 40e3, 60, method="interp")
    hi = f_new > 5000
    err_avg = np.abs(h_avg[hi] / smooth(f_new[hi]) - 1).mean()
    err_int = np.abs(h_int[hi] / smooth(f_new[hi]) - 1).mean()
    assert err_avg < 0.4 * err_int


def test_frequency_response_log_resample_carries_coherence():
    coh = np.clip(F_LIN / 50e3, 0, 1)
    resp = FrequencyResponse(F_LIN, smooth(F_LIN), coh, "s")
    out = resp.log_resample(100.0, 10e3, 50)
    assert out.name == "s" and len(out) == 50
    # Band averages of a function linear in f, re-interpolated linearly over
    # log f: a small curvature error (observed 3.4e-4).
    np.testing.assert_allclose(out.coherence, out.frequency_hz / 50e3, rtol=1e-3)
    full = resp.log_resample(points=20)
    assert full.frequency_hz[0] == F_LIN[1] and full.frequency_hz[-1] == F_LIN[-1]


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        ((F_LIN, smooth(F_LIN), 0.0, 100.0, 10), {}, "fmin must be finite and > 0"),
        ((F_LIN, smooth(F_LIN), 100.0, 100.0, 10), {}, "fmin=100.0 must be below fmax=100.0"),
        ((F_LIN, smooth(F_LIN), 1.0, 100.0, 10), {}, "not inside the data range"),
        ((F_LIN, smooth(F_LIN), 10.0, 60e3, 10), {}, "not inside the data range"),
        ((F_LIN, smooth(F_LIN), 10.0, 100.0, 1), {}, "points must be an integer >= 2"),
        ((F_LIN, smooth(F_LIN), 10.0, 100.0, 10), {"method": "spline"}, "method must be"),
        ((F_LIN[::-1], smooth(F_LIN), 10.0, 100.0, 10), {}, "f must be strictly increasing"),
        ((F_LIN, smooth(F_LIN)[:-1], 10.0, 100.0, 10), {}, "H must have the shape of f"),
    ],
)
def test_log_resample_validation(args, kwargs, match):
    with pytest.raises(ValueError, match=match):
        log_resample(*args, **kwargs)


# ---------------------------------------------------------------------------
# two-clock synthesis
# ---------------------------------------------------------------------------


def _flat(f: np.ndarray, value: complex, coh: float | None = None, name: str = "") -> FrequencyResponse:
    c = None if coh is None else np.full(f.size, coh)
    return FrequencyResponse(f, np.full(f.size, value, dtype=complex), c, name)


F_HIGH = np.arange(1, 4001) * 12.5  # 12.5 Hz .. 50 kHz (20 kHz clock record)
F_LOW = np.arange(1, 801) * 1.25  # 1.25 Hz .. 1 kHz (2 kHz clock record)


def test_two_clock_picks_low_below_and_high_above():
    high = _flat(F_HIGH, 2.0 + 0j, 0.9, "Z_lvsc")
    low = _flat(F_LOW, 1.0j, 0.7)
    out = synthesise_two_clock(high, low, 666.0)
    expected_f = np.union1d(F_LOW[F_LOW < 666.0], F_HIGH[F_HIGH >= 666.0])
    np.testing.assert_array_equal(out.frequency_hz, expected_f)
    below = out.frequency_hz < 666.0
    np.testing.assert_array_equal(out.values[below], 1.0j)
    np.testing.assert_array_equal(out.values[~below], 2.0)
    np.testing.assert_array_equal(out.coherence[below], 0.7)
    np.testing.assert_array_equal(out.coherence[~below], 0.9)
    assert out.name == "Z_lvsc"
    # The transition frequency itself, when on the high grid, comes from it.
    out = synthesise_two_clock(high, low, 200.0, name="R_lvhv")
    assert out.name == "R_lvhv"
    assert 200.0 in out.frequency_hz and out.values[out.frequency_hz == 200.0][0] == 2.0


def test_two_clock_coherence_dropped_if_either_lacks_it():
    out = synthesise_two_clock(_flat(F_HIGH, 2.0, 0.9), _flat(F_LOW, 1.0), 666.0)
    assert out.coherence is None


def test_two_clock_blend_is_a_smooth_crossfade():
    # Grids sharing frequencies inside the band must not produce duplicates.
    high = _flat(F_HIGH, 4.0 * np.exp(1j * 0.2), 1.0)
    low = _flat(F_LOW, 1.0 * np.exp(-1j * 0.2), 0.0)
    ft, decades = 300.0, 0.5
    out = synthesise_two_clock(high, low, ft, blend_decades=decades)
    f = out.frequency_hz
    assert np.all(np.diff(f) > 0)
    lo_edge, hi_edge = ft * 10 ** (-decades / 2), ft * 10 ** (decades / 2)
    band = (f >= lo_edge) & (f <= hi_edge)
    expected_f = np.union1d(
        np.union1d(F_LOW[F_LOW < lo_edge], F_HIGH[F_HIGH > hi_edge]),
        np.union1d(F_LOW[(F_LOW >= lo_edge) & (F_LOW <= hi_edge)], F_HIGH[(F_HIGH >= lo_edge) & (F_HIGH <= hi_edge)]),
    )
    np.testing.assert_array_equal(f, expected_f)
    np.testing.assert_allclose(out.values[f < lo_edge], np.exp(-0.2j))
    np.testing.assert_allclose(out.values[f > hi_edge], 4.0 * np.exp(0.2j))
    # Raised-cosine weight in log f: log-magnitude and phase move monotonically
    # from the low to the high value; halfway (at ft) the magnitude is the
    # geometric mean (2) and the phase the mean (0).
    w_high = 0.5 * (1 - np.cos(np.pi * np.log(f[band] / lo_edge) / np.log(hi_edge / lo_edge)))
    np.testing.assert_allclose(np.log(out.mag[band]), w_high * np.log(4.0), atol=1e-12)
    np.testing.assert_allclose(np.angle(out.values[band]), -0.2 + 0.4 * w_high, atol=1e-12)
    np.testing.assert_allclose(out.coherence[band], w_high, atol=1e-12)
    assert np.all(np.diff(out.mag[band]) >= 0)
    at_ft = out.values[f == ft][0]
    assert abs(at_ft) == pytest.approx(2.0) and np.angle(at_ft) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize(
    "high_f, low_f, ft, kwargs, match",
    [
        (F_HIGH, F_LOW[F_LOW < 500], 666.0, {}, "resp_low_clk covers .* does not include f_transition = 666 Hz"),
        (F_HIGH[F_HIGH > 1000], F_LOW, 666.0, {}, "resp_high_clk covers .* does not include f_transition"),
        (F_HIGH, F_LOW, 800.0, {"blend_decades": 0.5}, "resp_low_clk covers .* does not include the crossfade band"),
        (F_HIGH, F_LOW, 20.0, {"blend_decades": 0.5}, "resp_high_clk covers .* does not include the crossfade band"),
        (F_HIGH, F_LOW, 0.0, {}, "f_transition must be finite and > 0"),
        (F_HIGH, F_LOW, 666.0, {"blend_decades": -0.1}, "blend_decades must be finite and >= 0"),
        (F_HIGH, F_LOW[F_LOW >= 666.25], 666.25, {}, "resp_low_clk has no frequencies below"),
    ],
)
def test_two_clock_validation(high_f, low_f, ft, kwargs, match):
    with pytest.raises(ValueError, match=match):
        synthesise_two_clock(_flat(high_f, 2.0), _flat(low_f, 1.0), ft, **kwargs)


def test_two_clock_rejects_non_responses():
    with pytest.raises(ValueError, match="resp_low_clk must be a FrequencyResponse"):
        synthesise_two_clock(_flat(F_HIGH, 2.0), (F_LOW, np.ones(F_LOW.size)), 666.0)


def test_two_clock_from_prbs_measurements():
    # Section 5.1.2 in miniature: one resonant plant perturbed by PRBS clocked
    # at 20 kHz and at 2 kHz with the same output noise. The 2 kHz clock puts
    # more power below f_clk/3 = 666 Hz, the 20 kHz clock above it; the
    # synthesis keeps the better of the two on each side.
    fs = 200e3
    wz, wp = 2 * np.pi * 300, 2 * np.pi * 3000
    b, a = signal.bilinear([1, wz / 2, wz**2], [1, wp / 5, wp**2], fs)
    rng = np.random.default_rng(3)
    n = 2**17

    def measure(samples_per_bit: int) -> FrequencyResponse:
        u = prbs(n, samples_per_bit, nbits=10)
        y = signal.lfilter(b, a, u) + 0.05 * rng.standard_normal(n)
        return estimate_response(u, y, fs, fmin=10, fmax=20e3, nperseg=n // 8)

    high, low = measure(10), measure(100)
    syn = synthesise_two_clock(high, low, 666.0)

    def median_err(r: FrequencyResponse, lo: float, hi: float) -> float:
        sel = (r.frequency_hz >= lo) & (r.frequency_hz < hi)
        return float(np.median(np.abs(r.values[sel] / true_response(r.frequency_hz[sel], b, a, fs) - 1)))

    assert median_err(low, 10, 666) < 0.5 * median_err(high, 10, 666)
    assert median_err(high, 666, 20e3) < 0.5 * median_err(low, 666, 20e3)
    assert median_err(syn, 10, 666) == median_err(low, 10, 666)
    assert median_err(syn, 666, 20e3) == median_err(high, 666, 20e3)
    assert median_err(syn, 666, 20e3) < 0.02
