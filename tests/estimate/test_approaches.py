"""Estimation approaches: batched engines against the reference engines and the FMU, costs at the target."""

from __future__ import annotations

import numpy as np
import pytest

from estimation import approaches as ap
from estimation.studies.three_section import cases
from estimation.studies.three_section import study as three
from estimation.studies import two_section as two
from pris_cosim.signals import spectral
from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.models.builtin import get_model

TWO_SMALL = SourceSettings(vdc=30.0, prbs_order=4, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9)
THREE_SMALL = SourceSettings(vdc=100.0, prbs_order=5, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)


def max_rel(a, b) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max())


@pytest.mark.parametrize("name, port, settings, fs", [
    ("two-section", "in", TWO_SMALL, 300e3),
    ("three-section", "n1", THREE_SMALL, 2.5e6),
])
def test_pris_engine_equals_simulate_pris_for_a_population(name, port, settings, fs):
    circuit = get_model(name).circuit
    first = circuit.parameters[0].name
    v0 = circuit.parameter_values()[first.lower()]
    n = 2 * (2 ** settings.prbs_order - 1) * int(fs / settings.fclk) - 7  # two periods, not a whole number of bits
    eng = ap.PrisEngine(circuit, port, settings, fs, n)
    w = eng.simulate({first: np.array([v0, 1.5 * v0])})
    for k, scale in enumerate([1.0, 1.5]):
        ref = td.simulate_pris(circuit, port, settings, fs, periods=2, overrides={first: scale * v0})
        for key in ["v_in", "i_in"] + [f"v_{p}" for p in circuit.probes]:
            assert max_rel(w[key][k], ref[key][:n]) < 1e-9, (key, k)
    assert np.array_equal(eng.v_bprbs, td.simulate_pris(circuit, port, settings, fs, periods=2)["v_bprbs"][:n])


def test_pris_engine_equals_the_fmu(tmp_path):
    """The in-process batched engine and the generated monolithic FMU (fmpy) agree to 1e-9."""
    from pris_cosim.fmi import codegen, cosim, build as fmi

    circuit = get_model("two-section").circuit
    fs = 10 * TWO_SMALL.fclk
    fmu = fmi.build_fmu(codegen.arrangement_model(circuit, "in", TWO_SMALL, name="two_section_pris_eq"), tmp_path)
    with cosim.FmuRunner(fmu) as runner:
        w = cosim.simulate_pris_fmu(runner, TWO_SMALL, fs)
    n = w["time_s"].size
    ours = ap.PrisEngine(circuit, "in", TWO_SMALL, fs, n).simulate()
    for key in ("v_in", "i_in"):
        assert max_rel(ours[key][0], w[key]) < 1e-9, key


def test_injection_engine_equals_simulate_current_injection():
    circuit = get_model("three-section").circuit
    w = td.simulate_pris(circuit, "n1", THREE_SMALL, 11e6)
    eng = ap.InjectionEngine(circuit, "n1", w["i_in"], 11e6, hold="step")
    v = eng.simulate({"Rs": np.array([0.083, 0.2]), "Ls": np.array([181e-6, 150e-6])})
    for k, over in enumerate([{"Rs": 0.083, "Ls": 181e-6}, {"Rs": 0.2, "Ls": 150e-6}]):
        ref = td.simulate_current_injection(circuit, "n1", w["i_in"], 11e6, overrides=over)
        assert max_rel(v[k], ref["v_in"]) < 1e-9


def test_batched_welch_equals_spectral_module():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 4000))
    y = np.cumsum(x, axis=1) * 0.1 + rng.standard_normal((3, 4000))
    f, H, C, _ = ap.welch_h1(x, [y], 1e3, ap.WelchSettings())
    for k in range(3):
        f_ref, h_ref = spectral.tfestimate(x[k], y[k], 1e3)
        _, c_ref = spectral.coherence(x[k], y[k], 1e3)
        assert np.allclose(f, f_ref)
        assert np.allclose(H[0][k], h_ref, rtol=1e-12, atol=0)
        assert np.allclose(C[0][k], c_ref, rtol=1e-12, atol=1e-15)


def _analytic_two_section(responses):
    params = two.make_params()
    model = get_model("two-section")
    f = np.logspace(1, 4, 150)
    target = {k: v for k, v in model.response_set().evaluate(f, two._target_overrides()).items() if k in responses}
    return params, ap.AnalyticFrequency(params, model.response_set(), f, target, ap.frequency_cost("sse", responses))


def test_analytic_cost_is_zero_at_the_target_and_positive_elsewhere():
    params, a = _analytic_two_section(["Zin", "R2in"])
    u0 = params.to_unit({k: two.TARGET[k] for k in params.varying})
    rng = np.random.default_rng(0)
    U = np.vstack([u0, rng.random((20, 5)), np.clip(u0 + 1e-3 * np.eye(5), 0, 1)])
    c = a.cost_batch(U)
    assert c[0] < 1e-20
    assert np.all(c[1:21] > 1e-3)
    assert np.all(c[21:] > 1e-12)  # 0.1 % of the cube: even the weak resistance direction raises the cost
    assert a.stats.evaluations == 26 and a.stats.per_eval_s > 0


def test_simulated_frequency_at_the_target_is_close_to_analytic_where_coherent():
    """Welch H1 of the simulated PRIS record vs the analytic Zin: within 0.01 decades (2.3 %)
    wherever the coherence (quarter-record segments) is at least 0.999."""
    spec = two.CASES["2"]
    resp, f, (n, welch, bins, _) = two.simulated_target(spec, ["Zin"])
    w = td.simulate_pris(get_model("two-section").circuit, "in", two.SOURCE, spec["fs"], overrides=two._target_overrides())
    w = {k: v[:n] for k, v in w.items()}
    short = ap.WelchSettings(nperseg=n // 4)
    f_c, _, coh = ap.responses_from_waveforms(w, spec["fs"], [ap.ZIN_SPEC["Zin"]], short)
    coh_at = np.interp(f, f_c, coh["Zin"])
    za = get_model("two-section").response_set().evaluate(f)["Zin"]
    err = np.abs(np.log10(np.abs(resp["Zin"])) - np.log10(np.abs(za)))
    good = coh_at >= 0.999
    assert good.sum() > 0.5 * f.size
    assert err[good].max() < 0.01
    # and the simulated approach's own cost is zero at the target (same record, same processing)
    a, params, _ = two.build_approach("2")
    u0 = params.to_unit({k: two.TARGET[k] for k in params.varying})
    assert a.cost_batch(u0[None])[0] < 1e-15


def test_welch_proxy_follows_the_simulated_welch_estimate():
    a, params, _ = two.build_approach("2")
    proxy = ap.WelchProxyFrequency(params, get_model("two-section").circuit, "in", two.SOURCE, a.sim.fs,
                                   a.welch.segment(a.sim.n_samples), a.bins, a.specs, a.target, a.cost)
    u0 = params.to_unit({k: two.TARGET[k] for k in params.varying})
    est = proxy.responses(params.evaluate(u0[None]).overrides)
    for k in a.target:
        d = np.log10(np.abs(est[k][0])) - np.log10(np.abs(a.target[k]))
        assert np.sqrt(np.mean(d ** 2)) < 0.02, k


@pytest.fixture(scope="module")
def three_time():
    params = three.make_params()
    circuit = get_model("three-section").circuit
    w = three.time_target()
    eng = ap.InjectionEngine(circuit, "n1", w["i_in"], cases.FS_TIME)
    v_inj = eng.simulate()[0]  # the target's voltage for the same sampled current
    u0 = params.to_unit({k: three.TARGET[k] for k in three.NAMES})
    return params, eng, w, v_inj, u0


@pytest.mark.parametrize("cls", [ap.TimeDomain, ap.EMDApproach, ap.IEMDApproach])
@pytest.mark.parametrize("metric", ["rmse", "correlation"])
def test_time_emd_iemd_costs_are_zero_at_the_target(three_time, cls, metric):
    params, eng, w, v_inj, u0 = three_time
    a = cls(params, eng, v_inj, metric)
    rng = np.random.default_rng(1)
    c = a.cost_batch(np.vstack([u0, rng.random((2, 7))]))
    assert abs(c[0]) < 1e-9
    assert np.all(c[1:] > 1e-6)


def test_time_cost_against_the_pris_voltage_shows_the_sampling_discrepancy(three_time):
    """Thesis Fig. 4.14: the injected sampled current leaves a small voltage difference at the true parameters."""
    params, eng, w, v_inj, u0 = three_time
    a = ap.TimeDomain(params, eng, w["v_in"], "rmse")
    c0 = a.cost_batch(u0[None])[0]
    rms = np.sqrt(np.mean(w["v_in"] ** 2))
    assert 0 < c0 < 0.05 * rms
    far = params.to_unit({**three.TARGET, "Ls": 1.2 * three.TARGET["Ls"]})
    assert a.cost_batch(far[None])[0] > 3 * c0
