"""Exact time-domain engine: analytic cases, two independent algorithms, ngspice."""

from __future__ import annotations

import numpy as np
import pytest

from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import BRIDGE, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError, NonPassiveError
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import get_model
from pris_cosim.signals.perturbation import hbridge_waveform, lfsr_prbs

from conftest import needs_ngspice

THREE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)  # thesis 4.2.2
TWO = SourceSettings(vdc=30.0, prbs_order=4, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9)  # thesis 4.1.2


def rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def rc_circuit(R: float = 1e3, C: float = 1e-6) -> Circuit:
    c = Circuit(title="parallel RC")
    c.add("R1", "a", "0", R)
    c.add("C1", "a", "0", C)
    return c


def test_zoh_of_a_first_order_system_is_analytic():
    tau, h = 2e-3, 5e-4
    Phi, Gam = td.zoh(np.array([[-1 / tau]]), np.array([[1 / tau]]), h)
    assert Phi[0, 0] == pytest.approx(np.exp(-h / tau), rel=1e-14)
    assert Gam[0, 0] == pytest.approx(1 - np.exp(-h / tau), rel=1e-13)


def test_current_step_into_parallel_rc_is_exact_at_samples():
    R, C, I, fs = 1e3, 1e-6, 2e-3, 20e3
    w = td.simulate_current_injection(rc_circuit(R, C), "a", np.full(200, I), fs)
    expected = I * R * (1 - np.exp(-w["time_s"] / (R * C)))
    np.testing.assert_allclose(w["v_in"], expected, rtol=1e-12, atol=1e-15)


def test_blocked_recurrence_equals_plain_stepping():
    """simulate_pwc's blocked evaluation equals x[k+1] = Phi x[k] + Gamma u[k] stepped one by one."""
    c = get_model("three-section").circuit
    mna = MNA(c, current_inputs=["n1"])
    ss = mna.state_space(c.resolve())
    rng = np.random.default_rng(7)
    u = rng.standard_normal(333) * 1e-3  # not a multiple of the block length
    h = 1e-7
    x, y = td.simulate_pwc(ss, u, h)
    Phi, Gam = td.zoh(ss.A[0], ss.B[0], h)
    xr = np.zeros_like(x)
    for k in range(1, u.size):
        xr[k] = Phi @ xr[k - 1] + Gam[:, 0] * u[k - 1]
    np.testing.assert_allclose(x, xr, rtol=0, atol=1e-12 * np.abs(xr).max())
    np.testing.assert_allclose(y, xr @ ss.C[0].T + u[:, None] @ ss.D[0].T, atol=1e-12 * np.abs(y).max())


def test_pris_engine_equals_generic_zoh_with_bridge_samples():
    """Bit-wise switching algorithm (simulate_pris) vs sample-wise ZOH of the commanded voltage."""
    dut = get_model("three-section").circuit
    fs = 10e6
    w = td.simulate_pris(dut, "n1", THREE, fs, periods=2)
    c = pris_arrangement(dut, "n1", THREE)
    mna = MNA(c, voltage_inputs=[BRIDGE])
    x, y = td.simulate_pwc(mna.state_space(c.resolve()), w["v_bprbs"], 1 / fs)
    assert rel_rms(w["v_in"], y[:, mna.outputs.index("v(n1)")]) < 1e-12
    assert rel_rms(w["i_in"], x[:, mna.states.index("i(Lpris)")]) < 1e-12
    assert rel_rms(w["v_n3"], y[:, mna.outputs.index("v(n3)")]) < 1e-12
    t, v = hbridge_waveform(THREE.prbs_order, THREE.fclk, fs, THREE.vdc, 2)
    np.testing.assert_array_equal(w["time_s"], t)
    np.testing.assert_array_equal(w["v_bprbs"], v)


@pytest.mark.parametrize("fs", [2.5e5, 1.2e5, 7e4])
def test_switching_inside_sample_intervals_is_exact(fs):
    """fs not a multiple of fclk: samples of a fine grid holding every switching instant agree."""
    dut = get_model("three-section").circuit
    s = SourceSettings(vdc=100.0, prbs_order=4, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    w = td.simulate_pris(dut, "n1", s, fs, periods=2)
    p, q = td.clock_ratio(s.fclk, fs)
    fine = fs * p  # both the bit clock and fs divide it
    ref = td.simulate_pris(dut, "n1", s, fine, periods=2)
    idx = np.arange(w["time_s"].size) * p
    for name in ("v_in", "i_in", "v_n2"):
        assert rel_rms(w[name], ref[name][idx]) < 1e-9, name
    bits = lfsr_prbs(s.prbs_order, 2)
    np.testing.assert_array_equal(w["v_bprbs"] > 0, bits[(np.arange(w["time_s"].size) * p) // q] == 1)


def test_long_record_is_fast_and_finite():
    w = td.simulate_pris(get_model("three-section").circuit, "n1",
                         SourceSettings(vdc=100.0, prbs_order=10, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6),
                         10e6)
    assert w["time_s"].size == 1023 * 100
    assert np.all(np.isfinite(w["v_in"])) and np.abs(w["i_in"]).max() > 0


def test_non_passive_circuit_is_refused():
    m = get_model("hv-6section")
    cfg = m.configuration("LVOC")
    with pytest.raises(NonPassiveError, match="not passive"):
        td.simulate_pris(m.circuit, cfg.port, THREE, 1e6)
    with pytest.raises(NonPassiveError):
        td.simulate_current_injection(m.circuit, cfg.port, np.zeros(10), 1e6)


def test_invalid_override_names_the_element():
    with pytest.raises(CircuitError, match="R1"):
        td.simulate_pris(get_model("three-section").circuit, "n1", THREE, 1e6, overrides={"Rs": -1.0})


def test_current_injection_of_the_pris_current_reproduces_the_voltage_approximately():
    """Thesis 4.2.3 / Fig. 4.14: the sampled current only approximates the continuous one;
    the voltage discrepancy falls as the sampling rate rises."""
    dut = get_model("three-section").circuit
    errors = []
    for fs in (10e6, 40e6):
        w = td.simulate_pris(dut, "n1", THREE, fs)
        inj = td.simulate_current_injection(dut, "n1", w["i_in"], fs)
        errors.append(rel_rms(inj["v_in"], w["v_in"]))
    assert errors[1] < 0.5 * errors[0]
    assert errors[0] < 0.2


@pytest.mark.slow
@needs_ngspice
def test_three_section_matches_ngspice():
    """PRBS4 at 100 kHz, two periods, 10 MHz sampling; ngspice at 2 ns maximum step from zero state."""
    dut = get_model("three-section").circuit
    s = SourceSettings(vdc=100.0, prbs_order=4, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    w = td.simulate_pris(dut, "n1", s, 10e6, periods=2)
    ref = td.pris_ngspice(dut, "n1", s, 10e6, periods=2, max_step=2e-9)
    for name in ("v_in", "i_in", "v_n2", "v_n3"):
        assert rel_rms(w[name], ref[name]) < 2e-3, name


@pytest.mark.slow
@needs_ngspice
def test_two_section_matches_ngspice():
    """Thesis 4.1.2 source (30 V, 10 kHz, 31.8 kOhm, 2.53 H, 10 nF), PRBS3, 1 MHz sampling, 2 ns step."""
    dut = get_model("two-section").circuit
    s = SourceSettings(vdc=30.0, prbs_order=3, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9)
    w = td.simulate_pris(dut, "in", s, 1e6)
    ref = td.pris_ngspice(dut, "in", s, 1e6, max_step=2e-9)
    for name in ("v_in", "i_in", "v_mid"):
        assert rel_rms(w[name], ref[name]) < 2e-3, name
