"""Diagnosis of data with a stated uncertainty per point: weights, the noise floor, resonances of noisy points."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.diagnosis import DiagnosisError, diagnose_frequency
from estimation.diagnosis.evidence import noise_floor, noise_weights
from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.causes.unmerge import MAX_RESONANCE_SD, missing_modes, resolved_points
from pris_cosim.models.builtin import get_model


def _rlc(f: np.ndarray) -> np.ndarray:
    """Series R + L with a parallel C: one parallel resonance near 5 kHz (closed form)."""
    w = 2 * np.pi * f
    zs = 2.0 + 1j * w * 10e-3
    return zs / (1 + 1j * w * 100e-9 * zs)


def test_weights_have_unit_mean_square_and_follow_the_inverse_sd():
    s = np.array([0.01, 0.02, 0.04, 0.01])
    u = noise_weights({"Z": s})["Z"]
    assert np.mean(u ** 2) == pytest.approx(1.0)
    np.testing.assert_allclose(u / u[0], s[0] / s)


@pytest.mark.parametrize("c", [1.0, 1.7])
def test_noise_floor_from_stated_sd_and_the_data_scale(c):
    """Noise whose spread is c times the stated sd, which grows 100-fold across the band: the floor is the
    weighted mean of the true variances, 2 c^2 / mean(1/s^2)."""
    rng = np.random.default_rng(5)
    f = np.geomspace(10, 1e5, 3000)
    s = np.geomspace(1e-3, 1e-1, f.size)
    noise = c * s * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
    h = _rlc(f) * np.exp(noise)
    got = noise_floor(f, {"Z": h}, {"Z": s})["cost"]
    assert got == pytest.approx(2 * c ** 2 / np.mean(1 / s ** 2), rel=0.12)
    # the unweighted floor of the same data is the mean of the true variances, far above the weighted one (a single
    # median of the differences would be set by the median point: 13 times too low)
    plain = noise_floor(f, {"Z": h})["cost"]
    assert plain > 5 * got and plain == pytest.approx(2 * c ** 2 * np.mean(s ** 2), rel=0.12)


def _noisy(z: np.ndarray, sigma: float, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """``z`` with complex log-normal noise of RMS ``sigma``, and the realised noise's ``mean |n|^2``."""
    n = sigma / np.sqrt(2) * (rng.standard_normal(z.size) + 1j * rng.standard_normal(z.size))
    return z * np.exp(n), float(np.mean(np.abs(n) ** 2))


def test_noise_floor_of_white_noise_is_unbiased():
    """A flat response with white complex noise: the estimate over 200 records of 500 points averages the realised
    variance within 2 %."""
    rng = np.random.default_rng(11)
    f = np.geomspace(1e3, 1e6, 500)
    ratios = []
    for _ in range(200):
        h, true = _noisy(np.full(f.size, 50.0 + 0j), 0.01, rng)
        ratios.append(noise_floor(f, {"Z": h})["cost"] / true)
    assert abs(np.mean(ratios) - 1) < 0.02, np.mean(ratios)


def test_noise_floor_is_not_raised_by_sharp_resonances():
    """Six parallel resonances of Q 40 (closed form) on 600 points over four decades, 0.5 % noise: each resonance's
    own curvature raises the third differences at a few points. The median of ``|d|^2`` (written out here) moves with
    them, about 30 % high; the floor, from the points below three times its mean, stays within 15 %."""
    f = np.logspace(3, 7, 600)
    w = 2 * np.pi * f
    fr = np.logspace(3.5, 6.6, 6)
    L = 1e-3 * fr[0] / fr
    C = 1 / ((2 * np.pi * fr) ** 2 * L)
    R = 40 * np.sqrt(L / C)
    z = sum(1 / (1 / R[k] + 1j * w * C[k] + 1 / (1j * w * L[k])) for k in range(fr.size)) + 2.0 + 1j * w * 1e-6
    rng = np.random.default_rng(3)
    median, floor = [], []
    for _ in range(40):
        h, true = _noisy(z, 0.005, rng)
        y = np.log(np.abs(h)) + 1j * np.unwrap(np.angle(h))
        d = y[3:] - 3 * y[2:-1] + 3 * y[1:-2] - y[:-3]
        median.append(np.median(np.abs(d) ** 2) / (20 * np.log(2)) / true)
        floor.append(noise_floor(f, {"Z": h})["cost"] / true)
    assert np.mean(median) > 1.25 and abs(np.mean(floor) - 1) < 0.15, (np.mean(median), np.mean(floor))


def test_fit_cost_is_the_weighted_mean_square():
    model = get_model("two-section")
    cfg = list(model.configurations.values())
    name = cfg[0].responses[0].name
    f = np.geomspace(100, 1e6, 50)
    h = model.response_set().evaluate(f)[name] * np.exp(0.01 * np.sin(np.arange(f.size)))
    w = {name: np.sqrt(np.linspace(0.2, 1.8, f.size))}
    fit = FrequencyFit(model.circuit, cfg, f, {name: h}, weights=w)
    x = np.zeros(fit.nc)
    r = fit.result(x)
    e = r.errors[name]
    assert r.cost == pytest.approx(np.mean(w[name] ** 2 * np.abs(e) ** 2), rel=1e-12)
    assert 2 * np.sum(fit.residuals(x) ** 2) == pytest.approx(r.cost, rel=1e-12)


def test_noisy_points_make_no_resonances():
    rng = np.random.default_rng(2)
    f = np.geomspace(100, 1e5, 400)
    model = _rlc(f)
    s = np.where(f > 2e4, 0.5, 1e-3)  # a noisy top decade, as near a PRBS clock's nulls
    meas = model * np.exp(s * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
    assert missing_modes(f, {"Zin": meas}, {"Zin": model}) > 0  # noise alone makes peaks and dips
    resolved = resolved_points({"Zin": s})
    assert np.array_equal(resolved["Zin"], s <= MAX_RESONANCE_SD)
    assert missing_modes(f, {"Zin": meas}, {"Zin": model}, resolved) == 0


def test_bad_uncertainty_is_refused():
    f = np.geomspace(10, 1e4, 20)
    with pytest.raises(DiagnosisError, match="uncertainty of 'Zx'"):
        diagnose_frequency(f, {"Zin": _rlc(f)}, uncertainty={"Zx": np.ones(f.size)}, progress=False)
    with pytest.raises(DiagnosisError, match="uncertainty of 'Zin'"):
        diagnose_frequency(f, {"Zin": _rlc(f)}, uncertainty={"Zin": np.zeros(f.size)}, progress=False)
