"""Cost functions: closed forms and defining properties of thesis (2.21)-(2.27), (4.20)-(4.46), (5.8)-(5.11)."""

from __future__ import annotations

import numpy as np
import pytest

from estimation import costs
from estimation.costs import (TABLE_5_1_BANDS, CorrelationCost, CostFunction, Decomposer, EMDCost, IEMDCost,
    LogMagnitudeCost, TimeCost, WNRMSECost)
from estimation.parameters import ParameterSet
from pris_cosim.models.builtin import get_model

Y = np.array([1.0, 2.0, 3.0, 4.0])
YT = np.array([1.0, 2.0, 3.0, 6.0])


# ---------------------------------------------------------------------- generic metrics
def test_metrics_of_known_vectors():
    assert costs.mse(Y, YT) == pytest.approx(1.0)            # 4 / 4
    assert costs.rmse(Y, YT) == pytest.approx(1.0)
    assert costs.mae(Y, YT) == pytest.approx(0.5)            # 2 / 4
    assert costs.mape(Y, YT) == pytest.approx(12.5)          # (2/4)/4 * 100 %
    assert costs.nrmse_mean(Y, YT) == pytest.approx(1.0 / 2.5)
    assert costs.nrmse_range(Y, YT) == pytest.approx(1.0 / 3.0)
    assert costs.rmse(Y, YT, mask=[True, True, True, False]) == 0.0


def test_metrics_are_vectorised_over_a_population():
    pop = np.vstack([Y, YT, 2 * YT])
    out = costs.rmse(Y, pop)
    assert out.shape == (3,)
    np.testing.assert_allclose(out, [costs.rmse(Y, row) for row in pop])


def test_nrmse_invariances():
    rng = np.random.default_rng(0)
    y, yt = rng.normal(3.0, 1.0, 100), rng.normal(3.0, 1.0, 100)
    c, d = 7.5, -4.0
    assert costs.nrmse_range(c * y + d, c * yt + d) == pytest.approx(costs.nrmse_range(y, yt), rel=1e-12)
    assert costs.nrmse_mean(c * y, c * yt) == pytest.approx(costs.nrmse_mean(y, yt), rel=1e-12)
    assert costs.nrmse_mean(y + d, yt + d) != pytest.approx(costs.nrmse_mean(y, yt), rel=1e-3)


def test_correlation_cost_defining_values():
    rng = np.random.default_rng(1)
    y = rng.normal(size=200)
    assert costs.correlation_cost(y, 3.0 * y + 10.0) == pytest.approx(0.0, abs=1e-14)
    assert costs.correlation_cost(y, -y) == pytest.approx(2.0, abs=1e-14)
    assert costs.correlation_cost(y, np.ones_like(y)) == 1.0  # undefined rho taken as 0
    z = rng.normal(size=200)
    assert costs.pearson(y, z) == pytest.approx(np.corrcoef(y, z)[0, 1], rel=1e-12)  # (2.27)


def test_complex_data_is_refused_by_real_metrics():
    with pytest.raises(ValueError, match="take magnitudes"):
        costs.rmse(Y + 0j, YT)


# ---------------------------------------------------------------------- frequency domain
@pytest.fixture(scope="module")
def hv4_responses():
    f = np.logspace(1, 4, 120)
    return f, get_model("hv-4section").response_set().evaluate(f)


def test_log_magnitude_error_zero_for_identical_and_known_for_db_offset(hv4_responses):
    f, target = hv4_responses
    z = target["Zhvoc"]
    assert np.all(costs.log_magnitude_error(z, z) == 0.0)
    db = 6.0
    shifted = z * 10 ** (db / 20)  # every magnitude up by 6 dB, phase unchanged
    np.testing.assert_allclose(costs.log_magnitude_error(z, shifted), -db / 20, rtol=1e-12)
    assert costs.z_rmse(z, shifted) == pytest.approx(db / 20, rel=1e-12)  # (4.29)
    estimate = {k: v * 10 ** (db / 20) for k, v in target.items()}
    expected = len(target) * f.size * (db / 20) ** 2  # (4.21): no 1/N_k
    assert costs.log_magnitude_sse(target, estimate) == pytest.approx(expected, rel=1e-12)


def test_z_correlation_zero_for_scaled_response(hv4_responses):
    _, target = hv4_responses
    z = target["Zlvoc"]
    assert costs.z_correlation(z, 2.0 * z) == pytest.approx(0.0, abs=1e-12)
    assert costs.z_correlation(z, 2.0 * z, on="log-magnitude") == pytest.approx(0.0, abs=1e-12)


def _single_band_setup(lam: float, where: str):
    f = np.logspace(1, 4, 200)
    target = {"Zlvoc": np.full(f.size, 100.0 + 0j)}
    band = TABLE_5_1_BANDS["Zlvoc"]
    inside = (f >= band[0]) & (f <= band[1])
    hit = inside if where == "inside" else ~inside
    est = np.where(hit, 100.0 * 10**0.1, 100.0) + 0j  # 0.1 decade error where hit
    return f, target, {"Zlvoc": est}, hit


@pytest.mark.parametrize("lam", [1.0, 4.0, 20.0])
def test_wnrmse_weight_acts_only_inside_the_band(lam):
    for where in ("inside", "outside"):
        f, target, estimate, hit = _single_band_setup(lam, where)
        cost = costs.wnrmse(target, estimate, f, weight=lam, normalisation="none")
        factor = lam if where == "inside" else 1.0
        expected = np.sqrt(factor * 0.1**2 * hit.sum() / f.size)  # (5.8) with psi = 1
        assert cost == pytest.approx(expected, rel=1e-12)


def test_wnrmse_literal_window_and_normalisation(hv4_responses):
    f, target, estimate, hit = _single_band_setup(5.0, "outside")
    assert costs.wnrmse(target, estimate, f, weight=5.0, normalisation="none", outside=0.0) == 0.0
    f, target = hv4_responses
    estimate = {k: v * 1.1 for k, v in target.items()}
    base = costs.wnrmse(target, estimate, f, normalisation="none")
    psi = np.ptp(np.abs(target["Zhvoc"]))  # (5.11) on the magnitude
    one = costs.wnrmse(target, estimate, f, names=["Zhvoc"])
    assert one == pytest.approx(np.log10(1.1) / psi, rel=1e-12)
    assert base == pytest.approx(len(target) * np.log10(1.1), rel=1e-12)


def test_lvsc_omission_below_50_hz_is_a_mask(hv4_responses):
    f, target = hv4_responses
    estimate = dict(target)
    estimate["Zlvsc"] = np.where(f < 50.0, 10 * target["Zlvsc"], target["Zlvsc"])
    thesis = WNRMSECost.thesis(f, weight=10.0)
    assert thesis(target, estimate) == 0.0
    assert WNRMSECost(f, weight=10.0)(target, estimate) > 0
    assert set(TABLE_5_1_BANDS) == set(target)
    assert TABLE_5_1_BANDS["Zlvoc"] == TABLE_5_1_BANDS["Zhvsc"] == (800.0, 10e3)
    assert {TABLE_5_1_BANDS[k] for k in ("Zlvsc", "Zhvoc", "Rlvhv", "Rhvlv")} == {(2e3, 10e3)}


def test_cost_objects_score_a_response_population():
    model = get_model("hv-4section")
    ps = ParameterSet.from_circuit(model.circuit)
    f = np.logspace(1, 4, 60)
    rs = model.response_set()
    target = rs.evaluate(f)
    u = np.vstack([ps.to_unit(ps.values()), np.random.default_rng(2).random((4, 33))])
    estimate = rs.evaluate(f, ps.overrides(u))
    for cost in (LogMagnitudeCost(), LogMagnitudeCost("rmse"), CorrelationCost(), WNRMSECost.thesis(f, 5.0)):
        assert isinstance(cost, CostFunction)
        c = cost(target, estimate)
        assert c.shape == (5,)
        assert c[0] == pytest.approx(0.0, abs=1e-9) and np.all(c[1:] > 1e-6)
    with pytest.raises(ValueError, match="response 'Zin' is missing from the target"):
        LogMagnitudeCost(responses=["Zin"])(target, estimate)


# ---------------------------------------------------------------------- time domain
def test_time_costs():
    t = np.linspace(0, 1e-3, 500)
    v = np.sin(2 * np.pi * 5e3 * t)
    pop = np.vstack([v, v + 0.1, -v])
    np.testing.assert_allclose(TimeCost("rmse")(v, pop), [0.0, 0.1, 2 * np.sqrt(np.mean(v**2))], atol=1e-14)
    np.testing.assert_allclose(TimeCost("rho")(v, pop), [0.0, 0.0, 2.0], atol=1e-12)


# ---------------------------------------------------------------------- EMD
FS = 4000.0
T = np.arange(4000) / FS
FAST = np.sin(2 * np.pi * 200 * T)
SLOW = 0.8 * np.sin(2 * np.pi * 13 * T + 0.3)
SIGNAL = FAST + SLOW


def test_emd_recovers_two_well_separated_sines():
    imfs = Decomposer()(SIGNAL)
    inner = slice(400, 3600)  # away from the spline end effects
    assert np.sqrt(np.mean((imfs[0] - FAST)[inner] ** 2)) < 1e-3
    assert np.sqrt(np.mean((imfs[1] - SLOW)[inner] ** 2)) < 0.03 * 0.8
    np.testing.assert_allclose(imfs.sum(axis=0), SIGNAL, atol=1e-12)  # (4.35)


def test_emd_cost_zero_for_identical_and_growing_with_perturbation():
    target = Decomposer()(SIGNAL)
    base = np.sum(np.sqrt(np.mean(target**2, axis=1)) / costs.imf_ranges(target))
    cost = EMDCost("nrmse")
    values = cost(SIGNAL, np.vstack([(1 + d) * SIGNAL for d in (0.0, 0.01, 0.1)]))
    # EMD is homogeneous, so scaling by (1 + d) scales every IMF: C^m = d * sum rms / psi (4.39)
    np.testing.assert_allclose(values, [0.0, 0.01 * base, 0.1 * base], rtol=1e-9, atol=1e-14)
    rho = EMDCost("rho")(SIGNAL, np.vstack([SIGNAL, SIGNAL + 0.3 * np.sin(2 * np.pi * 60 * T)]))
    assert rho[0] == pytest.approx(0.0, abs=1e-12) and rho[1] > 0.01


def test_padding_and_truncation_shapes():
    a, b = np.ones((5, 100)), 2 * np.ones((3, 100))
    pa, pb = costs.pad_sets(a, b)
    assert pa.shape == pb.shape == (5, 100)
    assert np.all(pb[3:] == 0) and np.all(pb[:3] == 2)
    _, pr = costs.pad_sets(a, b, before_residual=True)
    assert np.all(pr[2:4] == 0) and np.all(pr[-1] == 2)
    ta, tb = costs.truncate_sets(a, b)
    assert ta.shape == tb.shape == (3, 100)
    # psi of padded target waveforms is omitted (4.41): the padded error counts unnormalised
    target = np.vstack([np.sin(np.linspace(0, 20, 100)), np.linspace(0, 1, 100)])
    estimate = np.vstack([target, np.full((1, 100), 0.5)])
    assert costs.emd_nrmse(target, estimate) == pytest.approx(0.5)
    assert costs.emd_correlation(target, estimate) == pytest.approx(0.0, abs=1e-12)  # (4.42) truncates


def test_iemd_uses_the_target_imf_count_and_never_decomposes_the_estimate(monkeypatch):
    dec = Decomposer()
    target = dec(SIGNAL)
    estimate = np.vstack([SIGNAL, 1.05 * SIGNAL + 0.01 * np.sin(2 * np.pi * 500 * T)])
    inferred = costs.inferred_imfs(target, estimate)
    assert inferred.shape == (2,) + target.shape  # N_r from the target, (4.44)
    np.testing.assert_allclose(inferred[0], target, atol=1e-12)  # a perfect estimate infers the target IMFs
    calls = []
    original = Decomposer.__call__
    monkeypatch.setattr(Decomposer, "__call__", lambda self, s: calls.append(1) or original(self, s))
    cost = IEMDCost("nrmse", dec)
    c = cost(SIGNAL, estimate)
    cost(SIGNAL, estimate)
    assert len(calls) == 1  # target decomposed once (then cached), estimates never
    # gamma_r - iIMF_r = v - v~ for every r: C^i_nrmse = C^v_rmse * sum 1/psi_r (4.45)
    expected = costs.v_rmse(SIGNAL, estimate) * np.sum(1.0 / costs.imf_ranges(target))
    np.testing.assert_allclose(c, expected, rtol=1e-9, atol=1e-12)
    rho = IEMDCost("rho", dec)(SIGNAL, estimate)
    assert rho[0] == pytest.approx(0.0, abs=1e-12) and rho[1] > 0


def test_ensemble_methods_are_seeded_and_sum_to_the_signal():
    s = SIGNAL[:1000]
    for method in ("eemd", "ceemdan"):
        a = Decomposer(method, seed=3, trials=4)(s)
        b = Decomposer(method, seed=3, trials=4)(s)
        np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(a.sum(axis=0), s, atol=1e-10)


def test_target_cache_is_small_and_reused():
    dec = Decomposer(cache_size=2)
    first = dec.cached(SIGNAL)
    assert dec.cached(SIGNAL) is first
    dec.cached(FAST)
    dec.cached(SLOW)
    assert dec.cached(SIGNAL) is not first  # evicted after two newer signals
    with pytest.raises(ValueError, match="method must be one of"):
        Decomposer("vmd")


def test_penalise_marks_infeasible_members():
    np.testing.assert_array_equal(costs.penalise([1.0, 2.0], [True, False], 10.0), [1.0, 12.0])
