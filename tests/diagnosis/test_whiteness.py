"""Whiteness of a fit's residuals along frequency (Ljung-Box), the test that lets a fit near the noise settle.

White complex noise passes at about the stated false-alarm rate; the same
noise with a smooth error added (what an effect the model lacks leaves,
here a slow sinusoid in log frequency, and a skin-effect-like rise) fails
even when that error is no larger than the noise. The chi-squared limit is
recomputed here from the statistic's definition, written out.
"""

import numpy as np
from scipy.stats import chi2

from estimation.diagnosis.evidence import WHITENESS_ALPHA, WHITENESS_LAGS, residuals_white


def _noise(rng, n=200, s=0.003):
    return s * (rng.standard_normal(n) + 1j * rng.standard_normal(n))


def test_white_noise_passes_at_the_false_alarm_rate():
    rng = np.random.default_rng(5)
    fails = sum(not residuals_white({"Zin": _noise(rng)}) for _ in range(400))
    assert fails <= 3  # expected 0.4 (alpha 1e-3 over the real and imaginary parts, Bonferroni)


def test_a_smooth_error_within_the_noise_fails():
    rng = np.random.default_rng(6)
    x = np.linspace(0, 1, 200)
    # RMS 0.0021 and 0.0024 (after the mean), below the noise 0.003 per part
    for smooth in (0.003 * np.sin(2 * np.pi * 2 * x), 0.008 * x ** 2 * (1 + 1j)):
        misses = sum(residuals_white({"Zin": _noise(rng) + smooth}) for _ in range(50))
        assert misses <= 2


def test_limit_is_the_chi_squared_quantile_of_the_ljung_box_statistic():
    # a series built to sit just above / below the limit: an AR(1) series' statistic, computed here
    rng = np.random.default_rng(7)
    limit = chi2.ppf(1 - WHITENESS_ALPHA / 2, WHITENESS_LAGS)
    for phi in (0.0, 0.15, 0.3, 0.5):
        e = np.zeros(400)
        w = rng.standard_normal(400)
        for k in range(1, 400):
            e[k] = phi * e[k - 1] + w[k]
        x = e - e.mean()
        n = x.size
        rho = [x[k:] @ x[:-k] / (x @ x) for k in range(1, WHITENESS_LAGS + 1)]
        q = n * (n + 2) * sum(r ** 2 / (n - k) for k, r in enumerate(rho, start=1))
        # the imaginary part is white (zero-mean noise far below the limit): the verdict is the real part's
        imag = rng.standard_normal(400)
        assert residuals_white({"Zin": e + 1j * imag}) == (q <= limit) or abs(q - limit) < 1e-9
