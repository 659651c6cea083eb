"""Evidence a user can check: residuals by band, resonance counts and positions, where the misfit sits."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy.optimize import minimize

from estimation.resonances import find_resonances

REGIONS = ("low-frequency open-circuit", "low-frequency short-circuit", "resonance damping", "high frequency", "mid band")


def band_table(f: np.ndarray, errors: Mapping[str, np.ndarray], bands_per_decade: int = 1) -> list[dict[str, float]]:
    """RMS magnitude (dB) and phase (deg) error per response and per band."""
    lo, hi = np.floor(np.log10(f[0]) * bands_per_decade), np.ceil(np.log10(f[-1]) * bands_per_decade)
    edges = 10 ** (np.arange(lo, hi + 1) / bands_per_decade)
    rows = []
    for name, e in errors.items():
        for a, b in zip(edges[:-1], edges[1:]):
            sel = (f >= a) & (f < b) if b < edges[-1] else (f >= a) & (f <= b)
            if not np.any(sel):
                continue
            rows.append({
                "response": name, "band_hz": [float(max(a, f[0])), float(min(b, f[-1]))],
                "mag_rms_db": float(20 / np.log(10) * np.sqrt(np.mean(e[sel].real ** 2))),
                "phase_rms_deg": float(np.degrees(np.sqrt(np.mean(e[sel].imag ** 2)))),
            })
    return rows


def resonance_comparison(f: np.ndarray, measured: Mapping[str, np.ndarray], model: Mapping[str, np.ndarray]) -> dict[str, dict]:
    """Parallel/series resonances found in the measured and the model responses (impedances only)."""
    out = {}
    for name in measured:
        if not name.startswith("Z"):
            continue
        m = find_resonances(f, measured[name], min_prominence_db=1.0)
        p = find_resonances(f, model[name], min_prominence_db=1.0)
        out[name] = {
            "measured_parallel_hz": [r.frequency_hz for r in m if r.kind == "parallel"],
            "model_parallel_hz": [r.frequency_hz for r in p if r.kind == "parallel"],
            "measured_series_hz": [r.frequency_hz for r in m if r.kind == "series"],
            "model_series_hz": [r.frequency_hz for r in p if r.kind == "series"],
        }
    return out


def localise(f: np.ndarray, measured: Mapping[str, np.ndarray], errors: Mapping[str, np.ndarray]) -> dict[str, object]:
    """Where the baseline misfit sits: share of squared residual per region, and the dominant region."""
    energy = dict.fromkeys(REGIONS, 0.0)
    for name, e in errors.items():
        w = np.abs(e) ** 2
        res = [r.frequency_hz for r in find_resonances(f, measured[name], min_prominence_db=1.0)]
        near = np.zeros(f.size, bool)
        for fr in res:
            near |= np.abs(np.log(f / fr)) < np.log(1.15)
        first = res[0] if res else np.sqrt(f[0] * f[-1])
        last = res[-1] if res else np.sqrt(f[0] * f[-1])
        low = (f < first / 1.15) & ~near
        high = (f > last * 1.15) & ~near
        lowname = "low-frequency short-circuit" if "sc" in name.lower() else "low-frequency open-circuit"
        energy[lowname] += float(w[low].sum())
        energy["resonance damping"] += float(w[near].sum())
        energy["high frequency"] += float(w[high].sum())
        energy["mid band"] += float(w[~(low | high | near)].sum())
    total = sum(energy.values()) or 1.0
    shares = {k: v / total for k, v in energy.items()}
    return {"region": max(shares, key=lambda k: shares[k]), "shares": shares}


def noise_weights(uncertainty: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-point residual weights ``u_k`` from each response's standard deviations ``s_k`` of ``ln H``.

    ``u_k^2 = (1/s_k^2) / mean(1/s_k^2)``: inverse-variance weights scaled to a
    mean of one, so that the weighted cost ``mean_k u_k^2 |e_k|^2`` stays in
    the units of the unweighted one and each response still counts equally.
    """
    out = {}
    for n, s in uncertainty.items():
        inv = 1.0 / np.asarray(s, float) ** 2
        out[n] = np.sqrt(inv / np.mean(inv))
    return out


def noise_variance(f: np.ndarray, h: np.ndarray, sd: np.ndarray | None = None) -> float:
    """Variance ``E|n|^2`` of the complex log noise of one measured response, estimated from the data.

    The third difference of ``ln H`` along frequency removes any smooth
    response (quadratic in the index) and leaves ``20`` times the noise
    variance, ``|d|^2`` exponentially distributed about it. Two things
    bend that picture, and the estimate allows for both:

    - near a sharp resonance the response's own curvature adds to ``d`` at a
      few points. They sit in the upper tail, and even a median moves with
      them (a tenth of the points so raised moves it to the 56th percentile
      of the noise's: 17 % high). The scale is fitted to the points below
      ``CLIP`` times it (:func:`clipped_exponential_scale`), and those
      points drop out however many they are;
    - the noise's level changes across the band (the instrument's ranges,
      the response's magnitude: a short-circuit record's low-frequency
      points are 25 to 100 times noisier than its mid band): its log is
      taken as a quadratic in ``log f`` (``NOISE_DEGREE``), and the variance
      returned is its mean over the points, the cost a perfect model would
      still have. (A profile with more freedom, a linear spline chosen by
      BIC, follows a resonance's curvature where the points cluster and was
      13 % high on the broad draws, against 4 % for the quadratic.)
      A single median of noise whose spread grows 100-fold across the band
      is 13 times too low.

    With standard deviations ``sd`` (of ``ln|H|`` per point, from the data
    file) each third difference is divided by its own standard deviation
    ``sqrt(s_k^2 + 9 s_{k+1}^2 + 9 s_{k+2}^2 + s_{k+3}^2)``, which leaves
    ``2 c^2``, the factor by which the stated variances are off (the data
    set their shape, the data's roughness their scale; one constant, fitted
    the same way); the result is the weighted mean ``mean_k u_k^2 E|n_k|^2``
    (:func:`noise_weights`), ``2 c^2 / mean(1/s^2)``: the cost a perfect
    model would still have under the weights.
    """
    y = np.log(np.abs(h)) + 1j * np.unwrap(np.angle(h))
    if y.size < 8:
        return 0.0
    d = y[3:] - 3 * y[2:-1] + 3 * y[1:-2] - y[:-3]
    if sd is None:
        lf = np.log(np.asarray(f, float))
        x = 0.5 * (lf[1:-2] + lf[2:-1])  # the centre of each difference's four points
        t = 2 * (x - x.min()) / np.ptp(x) - 1 if np.ptp(x) > 0 else np.zeros(x.size)
        theta = clipped_exponential_scale(np.abs(d) ** 2, np.vander(t, NOISE_DEGREE + 1, increasing=True))
        return float(np.mean(theta)) / 20
    s2 = np.asarray(sd, float) ** 2
    u = np.abs(d) ** 2 / (s2[3:] + 9 * s2[2:-1] + 9 * s2[1:-2] + s2[:-3])
    return float(clipped_exponential_scale(u, np.ones((u.size, 1)))[0]) / float(np.mean(1.0 / s2))


#: Points above this many times the fitted scale are left out of it (:func:`clipped_exponential_scale`): an
#: exponential sample has 5 % of its points there, and the mean of the rest is 0.843 of the whole mean.
CLIP = 3.0
#: Degree, in log frequency, of the log of the noise's level along the band (:func:`noise_variance`).
NOISE_DEGREE = 2


def clipped_exponential_scale(a: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The scale (mean) of exponentially distributed values whose upper tail holds outliers, ``log`` of it
    linear in the columns of ``X``.

    Maximum likelihood of ``a_k ~ Exp(theta_k)``, ``log theta = X b``
    (a convex problem, :func:`scipy.optimize.minimize` with its exact
    Hessian), over the points below ``CLIP theta_k``; the mean of an
    exponential variable below ``CLIP`` times its mean is
    ``g = 1 - CLIP e^-CLIP / (1 - e^-CLIP)`` of that mean, so the fitted
    scale is divided by ``g``, and the points are chosen again until they
    no longer change. With one constant column this is the mean of the
    points below ``CLIP`` times it, over ``g``.

    Parameters
    ----------
    a : numpy.ndarray
        Non-negative values (``|d|^2``, in their own units).
    X : numpy.ndarray
        Regressors of ``log theta``, one row per value (a column of ones for a constant scale).

    Returns
    -------
    numpy.ndarray
        The scale at each value, in the units of ``a``; zeros for an all-zero sample.
    """
    a = np.asarray(a, float)
    n = a.size
    if not n or not np.any(a > 0):
        return np.zeros(n)
    log_g = np.log(1.0 - CLIP * np.exp(-CLIP) / (1.0 - np.exp(-CLIP)))
    b = np.zeros(X.shape[1])
    b[0] = np.log(np.median(a[a > 0]) / np.log(2))  # the first column is the constant
    keep = np.ones(n, bool)
    for _ in range(100):
        b = _exponential_fit(X[keep], a[keep], b)
        b[0] -= log_g  # the kept points' mean is g of the scale
        new = a < CLIP * np.exp(X @ b)
        if np.array_equal(new, keep) or not new.any():
            break
        keep = new
        b[0] += log_g  # refitted from where the kept points put it
    return np.exp(X @ b)


def _exponential_fit(X: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Maximum likelihood of ``a ~ Exp(exp(X b))`` from ``b``: the minimum of ``sum(X b + a exp(-X b))``."""
    def rate(v: np.ndarray) -> np.ndarray:
        return a * np.exp(-np.clip(X @ v, -700, 700))

    sol = minimize(lambda v: float(np.sum(X @ v + rate(v))), b, method="trust-exact",
                   jac=lambda v: X.T @ (1 - rate(v)), hess=lambda v: (X * rate(v)[:, None]).T @ X)
    return sol.x


#: Lags of the whiteness test of the residuals (:func:`residuals_white`).
WHITENESS_LAGS = 10
#: Its false-alarm probability: a model whose residuals are white noise is taken as not white this rarely.
WHITENESS_ALPHA = 1e-3


def residuals_white(errors: Mapping[str, np.ndarray], lags: int = WHITENESS_LAGS,
                    alpha: float = WHITENESS_ALPHA) -> bool:
    """Whether the log errors of a fit look like white noise along frequency (Ljung-Box test).

    The residual test of system identification: for white residuals the
    autocorrelations at lags ``1..m`` are independent with variance
    ``1/N``, and ``Q = N (N + 2) sum_k rho_k^2 / (N - k)`` is chi-squared
    with ``m`` degrees of freedom. An effect the model lacks leaves a smooth
    error along frequency, strongly correlated from one point to the next,
    even when its size is within the noise's estimate. The real and the
    imaginary parts of each response are tested; all must pass at the
    ``alpha`` level (Bonferroni over the series).
    """
    from scipy.stats import chi2

    series = [part for e in errors.values() for part in (np.real(e), np.imag(e))]
    limit = float(chi2.ppf(1 - alpha / max(len(series), 1), lags))
    for x in series:
        x = np.asarray(x, float) - np.mean(x)
        n = x.size
        var = float(x @ x)
        if n <= 2 * lags or var <= 0:
            continue
        rho = np.array([float(x[k:] @ x[:-k]) / var for k in range(1, lags + 1)])
        q = n * (n + 2) * float(np.sum(rho ** 2 / (n - np.arange(1, lags + 1))))
        if q > limit:
            return False
    return True


def noise_floor(f: np.ndarray, measured: Mapping[str, np.ndarray],
                uncertainty: Mapping[str, np.ndarray] | None = None) -> dict[str, object]:
    """The cost a perfect model would still have: the sum over responses of the noise variances.

    ``uncertainty`` (standard deviations of ``ln H`` per point, for some or all
    responses) makes the floor that of the weighted cost (:func:`noise_variance`).

    Returns
    -------
    dict
        ``cost`` (same units as the diagnosis cost), ``per_response`` noise RMS
        (complex log units: 0.01 is 1 % / 0.57 deg; weighted where a response
        has an uncertainty), ``method``.
    """
    unc = dict(uncertainty or {})
    per = {n: noise_variance(f, v, unc.get(n)) for n, v in measured.items()}
    method = ("mean of |third difference of ln H|^2 / 20 per response, the points of a resonance's curvature left out "
              "and the level followed along the band")
    if unc:
        method += ("; responses with a stated uncertainty: third differences divided by their own standard "
                   "deviation, residuals weighted by 1/sd (mean weight one)")
    return {"cost": float(sum(per.values())), "per_response": {n: float(np.sqrt(v)) for n, v in per.items()},
            "method": method, "weighted": sorted(unc)}


def unexplained_bands(f: np.ndarray, errors: Mapping[str, np.ndarray], noise_rms: Mapping[str, float],
                      per_decade: float = 6.0, factor: float = 4.0, max_bands: int = 8) -> list[dict[str, object]]:
    """Frequency bands where the residual still stands above the noise.

    The residual is averaged over a sliding window of ``1/per_decade``
    decade (at least 5 points); where the average exceeds ``factor`` times
    the noise of such an average (``sigma / sqrt(w)``) and the residual's
    own RMS exceeds twice the noise RMS, the point is systematic. Adjacent
    points join into bands (gaps under half a window bridged); bands of
    fewer than a window are dropped.

    Returns
    -------
    list of dict
        Largest first: ``response``, ``band_hz``, ``rms`` (complex log),
        ``mag_rms_db``, ``phase_rms_deg``, ``noise_rms``, ``above_noise`` (rms / noise).
    """
    n_dec = np.log10(f[-1] / f[0]) if f.size > 1 else 1.0
    w = max(5, int(round(f.size / max(n_dec, 1e-9) / per_decade)))
    kernel = np.ones(w) / w
    bands = []
    for name, e in errors.items():
        sigma = max(float(noise_rms.get(name, 0.0)), 1e-12)
        if e.size < w:
            continue
        smooth = np.convolve(e, kernel, mode="same")
        local = np.sqrt(np.convolve(np.abs(e) ** 2, kernel, mode="same"))
        hot = (np.abs(smooth) > factor * sigma / np.sqrt(w)) & (local > 2 * sigma)
        idx = np.flatnonzero(hot)
        if idx.size == 0:
            continue
        groups = np.split(idx, np.flatnonzero(np.diff(idx) > max(1, w // 2)) + 1)
        for g in groups:
            if g[-1] - g[0] + 1 < w:
                continue
            seg = e[g[0]: g[-1] + 1]
            rms = float(np.sqrt(np.mean(np.abs(seg) ** 2)))
            bands.append({"response": name, "band_hz": [float(f[g[0]]), float(f[g[-1]])], "rms": rms,
                          "mag_rms_db": float(20 / np.log(10) * np.sqrt(np.mean(seg.real ** 2))),
                          "phase_rms_deg": float(np.degrees(np.sqrt(np.mean(seg.imag ** 2)))),
                          "noise_rms": sigma, "above_noise": rms / sigma})
    bands.sort(key=lambda b: -b["rms"] ** 2 * (b["band_hz"][1] / b["band_hz"][0]))
    return bands[:max_bands]
