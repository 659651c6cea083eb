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
    # the unweighted floor of the same data is set by the median point, far above the weighted one
    assert noise_floor(f, {"Z": h})["cost"] > 5 * got


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
