"""Waveform diagnosis of the PRIS source on a resistive load (thesis 3.3, 5.1.3).

Generated cases with one hidden effect must be named with gain >= 0.5, clean
cases must give ``none``, bad input must raise a one-line DiagnosisError, and
the thesis's own measured-versus-nominal values must be explained by the
source-path resistance.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from estimation.diagnosis.fit import DiagnosisError
from estimation.diagnosis.waveform.source import _Input, _simulate_one, _Structure, diagnose_waveforms
from estimation.diagnosis.waveform.report import write_report
from estimation.diagnosis.waveform.synthetic import NOMINAL, simulate_source, thesis_case, waveform_case
from pris_cosim.measured.formats import Waveforms, write_waveform_csv

KEYS = {"cause", "candidates", "baseline_cost", "extended_cost", "gain"}


def _diagnose(case):
    return diagnose_waveforms(case.waveforms, **case.nominal, **case.diagnose_kwargs, progress=False)


@pytest.fixture(scope="module")
def ringing_diagnosis():
    case = waveform_case("switch-ringing", 2, fs=10e6)  # undamped ringing near 1.4 MHz
    return case, _diagnose(case)


def test_simulation_matches_simulate_pris():
    """The diagnosis's modal ZOH simulation reproduces pris_cosim's exact engine (ringing source)."""
    ref = simulate_source(57.1, 1e-3, 4e-6, 15.3, 10e6, lsw=10e-6, csw=1e-9, rsnub=55.0, csnub=10e-9)
    st = _Structure(57.1, 1e-3, 4e-6, True, 55.0, 10e-9)
    ss = st.state_space({"rload": np.array([15.3]), "lsw": np.array([10e-6]), "csw": np.array([1e-9])}, 1)
    inp = _Input(ref["v_bprbs"])
    y, free, to_state = _simulate_one(ss.A[0], ss.B[0], ss.C[0], ss.D[0], inp, 1e-7, True)
    for j, s in enumerate(("v_in", "i_in")):
        assert np.max(np.abs(y[:, j] - ref[s])) <= 1e-9 * np.max(np.abs(ref[s]))
    # the free-response basis and its state coordinates agree with a simulation from that state
    coef = np.linspace(0.5, -0.3, st.n)
    x0 = to_state @ coef
    y0, _, _ = _simulate_one(ss.A[0], ss.B[0], ss.C[0], ss.D[0], inp, 1e-7, False, x0)
    assert np.allclose(y0 - y, free @ coef, atol=1e-9 * np.max(np.abs(free @ coef)))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_series_resistance_named(seed):
    case = waveform_case("series-resistance", seed)
    d = _diagnose(case)
    assert d.cause == "series-resistance" and d.gain >= 0.5
    assert d.best.extra["r_series_ohm"] == pytest.approx(case.truth["r_series_ohm"], rel=0.05)
    assert d.evidence["localisation"]["where"] != "waveform edges and ringing"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_component_drift_named(seed):
    case = waveform_case("component-drift", seed)
    d = _diagnose(case)
    assert d.cause == "component-drift" and d.gain >= 0.5
    assert d.best.extra["l_scale"] == pytest.approx(case.truth["l_scale"], rel=0.01)
    assert d.best.extra["c_scale"] == pytest.approx(case.truth["c_scale"], rel=0.01)


@pytest.mark.slow
def test_switch_ringing_named(ringing_diagnosis):
    case, d = ringing_diagnosis
    assert d.cause == "switch-ringing" and d.gain >= 0.5
    assert d.best.extra["f_ring_hz"] == pytest.approx(case.truth["f_ring_hz"], rel=0.01)
    assert d.evidence["ringing"]["f_ring_hz"] == pytest.approx(
        1 / (2 * math.pi * math.sqrt(d.best.extra["lsw_h"] * d.best.extra["csw_f"])))
    rms = d.evidence["residual_rms"]["i_in"]
    assert rms["after"] < 0.3 * rms["before"]


@pytest.mark.slow
def test_switch_ringing_with_snubber_named():
    case = waveform_case("switch-ringing", 0, fs=10e6)  # seed 0 draws the thesis's snubber
    assert case.truth["snubber"] and case.diagnose_kwargs
    d = _diagnose(case)
    assert d.cause == "switch-ringing" and d.gain >= 0.5
    assert d.best.extra["lsw_h"] == pytest.approx(case.truth["lsw_h"], rel=0.05)
    assert "f_ring_snubbed_hz" in d.best.extra
    assert d.evidence["localisation"]["where"] == "waveform edges and ringing"


@pytest.mark.slow
@pytest.mark.parametrize("seed,fs", [(1, 2e6), (2, 2e6), (3, 10e6), (4, 1.2345e6)])
def test_clean_data_is_none(seed, fs):
    case = waveform_case("none", seed, fs=fs)
    d = _diagnose(case)
    assert d.cause == "none" and d.gain == 0.0
    assert all(c["gain"] < 0.05 for c in d.candidates())
    assert d.as_json()["extended_cost"] == d.as_json()["baseline_cost"]


@pytest.mark.slow
def test_switching_between_samples():
    """fs not a multiple of f_clk: the bridge switches between samples; the bit clock recovers the instants.

    On the sample grid (the contract's reading) the up-to-one-sample timing
    error looks like an inductance drift; with the recovered instants it does not.
    """
    case = waveform_case("none", 5, fs=1.2345e6)
    d = _diagnose(case)
    assert d.evidence["edge_timing"]["mode"] == "clock"
    assert d.evidence["edge_timing"]["samples_per_bit"] == pytest.approx(123.45, abs=1e-3)
    assert d.cause == "none"
    on_grid = diagnose_waveforms(case.waveforms, **NOMINAL, edge_timing="sample", progress=False)
    assert on_grid.baseline.cost > 5 * d.baseline.cost
    drift = waveform_case("component-drift", 5, fs=1.2345e6)
    d = _diagnose(drift)
    assert d.cause == "component-drift" and d.gain >= 0.5


def test_thesis_measured_values_name_series_resistance():
    """Thesis 3.3: data from 61.2 Ohm / 1.024 mH / 3.707 uF diagnosed with 57.1 Ohm / 1 mH / 4 uF.

    The discrepancy is +7.2 % R, +2.4 % L, -7.3 % C. The extra 4.1 Ohm changes
    the current's amplitude in every bit, whereas the L and C errors only
    reshape the fast edge (L/R = 13 us) and the slow RC decay a little; one
    series resistance explains most of it, as the thesis found (tracks and
    cables), and L, C scale factors cannot mimic a resistance.
    """
    case = thesis_case(0)
    d = _diagnose(case)
    assert d.cause == "series-resistance" and d.gain >= 0.5
    # forward selection may add the L, C drift the data also hold (second, after the resistance)
    assert d.causes[0] == "series-resistance" and set(d.causes) <= {"series-resistance", "component-drift"}
    extra = d.best.extra.get("series-resistance", d.best.extra)
    assert extra["r_series_ohm"] == pytest.approx(61.2 - 57.1, abs=1.5)
    if "component-drift" in d.causes:
        drift = d.best.extra["component-drift"]
        assert drift["l_scale"] == pytest.approx(1.024, rel=0.02) and drift["c_scale"] == pytest.approx(
            3.707 / 4, rel=0.02)
    by = {c["cause"]: c for c in d.candidates()}
    assert by["series-resistance"]["gain"] > by["component-drift"]["gain"]


@pytest.mark.slow
def test_json_and_report(ringing_diagnosis, tmp_path):
    _, d = ringing_diagnosis
    js = d.as_json()
    assert KEYS <= set(js)
    assert {c["cause"] for c in js["candidates"]} == {"series-resistance", "component-drift", "switch-ringing"}
    assert all({"cause", "cost", "gain"} <= set(c) for c in js["candidates"])
    json.dumps(js)
    ev = js["evidence"]
    assert {"residual_rms", "localisation", "ringing"} <= set(ev)
    assert ev["residual_rms"]["v_in"]["unit"] == "V" and ev["residual_rms"]["i_in"]["unit"] == "A"
    path = write_report(d, tmp_path / "rep")
    text = path.read_text()
    assert "switch-ringing" in text and "Hz" in text
    for png in ("waveforms_edge.png", "residuals.png"):
        assert (tmp_path / "rep" / png).stat().st_size > 1000


def test_csv_and_mapping_input(tmp_path):
    case = waveform_case("series-resistance", 4)
    w = case.waveforms
    p = tmp_path / "w.csv"
    write_waveform_csv(p, w)
    d_csv = diagnose_waveforms(p, **NOMINAL, progress=False)
    d_map = diagnose_waveforms({"time_s": w.time_s, "v_bprbs": w.v_bprbs, "v_in": w.v_in, "i_in": w.i_in},
                               **NOMINAL, r_load=case.truth["r_load"], progress=False)
    assert d_csv.cause == d_map.cause == "series-resistance"
    assert d_map.baseline.values["r_load"] == case.truth["r_load"]


# ---------------------------------------------------------------------------- bad input


@pytest.fixture(scope="module")
def clean():
    return waveform_case("none", 0).waveforms


def _one_line_error(match, *args, **kwargs):
    with pytest.raises(DiagnosisError, match=match) as exc:
        diagnose_waveforms(*args, progress=False, **kwargs)
    assert "\n" not in str(exc.value)


def test_too_few_samples(clean):
    w = Waveforms(clean.time_s[:40], clean.v_bprbs[:40], clean.v_in[:40], clean.i_in[:40])
    _one_line_error("too few samples", w, **NOMINAL)


def test_non_uniform_sampling(clean, tmp_path):
    t = clean.time_s.copy()
    t[100:] += 0.3 * clean.dt
    cols = {"time_s": t, "v_bprbs": clean.v_bprbs, "v_in": clean.v_in, "i_in": clean.i_in}
    _one_line_error("uniform", cols, **NOMINAL)
    p = tmp_path / "bad.csv"
    p.write_text("time_s,v_bprbs,v_in,i_in\n" + "\n".join(
        f"{a!r},{b!r},{c!r},{d!r}" for a, b, c, d in zip(t[:500], clean.v_bprbs, clean.v_in, clean.i_in)))
    _one_line_error("uniform", p, **NOMINAL)


def test_missing_column(clean):
    _one_line_error("lacks column.*i_in", {"time_s": clean.time_s, "v_bprbs": clean.v_bprbs, "v_in": clean.v_in},
                    **NOMINAL)


def test_no_switching(clean):
    w = Waveforms(clean.time_s, np.full(clean.n_samples, 30.0), clean.v_in, clean.i_in)
    _one_line_error("switches fewer than twice", w, **NOMINAL)


@pytest.mark.parametrize("wrong", [{"cpris": 40e-6}, {"cpris": 0.4e-6}, {"lpris": 10e-3}, {"lpris": 0.1e-3},
                                   {"rpris": 571.0}, {"rpris": 5.71}])
def test_wrong_nominal_values(clean, wrong):
    _one_line_error("does not fit the data at all", clean, **{**NOMINAL, **wrong})


def test_non_positive_nominal(clean):
    _one_line_error("lpris must be a positive number", clean, **{**NOMINAL, "lpris": 0.0})


@pytest.mark.slow
def test_series_resistance_and_switch_parasitics_both_named():
    """A source with 2 Ohm more in series and switch parasitics (10.4 uH, 0.463 nF), simulated by
    pris_cosim.lab.timedomain.simulate_pris (not the diagnosis's modal simulation), 0.3 % noise."""
    rng = np.random.default_rng(5)
    sim = simulate_source(57.1 + 2.0, 1e-3, 4e-6, 15.3, 10e6, lsw=10.4e-6, csw=0.463e-9)
    noisy = {s: sim[s] + 0.003 * np.sqrt(np.mean(sim[s] ** 2)) * rng.standard_normal(sim[s].size)
             for s in ("v_in", "i_in")}
    d = diagnose_waveforms(Waveforms(sim["time_s"], sim["v_bprbs"], noisy["v_in"], noisy["i_in"]), 57.1, 1e-3, 4e-6,
                           progress=False)
    out = d.as_json()
    assert {"cause", "causes", "steps", "candidates", "unexplained", "noise_floor", "gain"} <= set(out)
    assert sorted(out["causes"]) == ["series-resistance", "switch-ringing"], out["steps"]
    assert len(out["steps"]) == 2 and out["unexplained"] == []
    assert out["extended_cost"] <= 1.25 * out["noise_floor"]
    ext = d.best.extra
    assert ext["series-resistance"]["r_series_ohm"] == pytest.approx(2.0, rel=0.05)
    assert ext["switch-ringing"]["lsw_h"] == pytest.approx(10.4e-6, rel=0.05)
    assert ext["switch-ringing"]["csw_f"] == pytest.approx(0.463e-9, rel=0.05)


def test_noise_floor_from_the_record():
    """The record's own noise estimate against the 0.3 % of signal RMS added here (clean and ringing sources)."""
    from estimation.diagnosis.waveform.source import waveform_noise

    rng = np.random.default_rng(1)
    for par in ({}, {"lsw": 10.4e-6, "csw": 0.463e-9}):
        sim = simulate_source(57.1, 1e-3, 4e-6, 15.3, 10e6, **par)
        sd = {s: 0.003 * np.sqrt(np.mean(sim[s] ** 2)) for s in ("v_in", "i_in")}
        w = Waveforms(sim["time_s"], sim["v_bprbs"], *(sim[s] + sd[s] * rng.standard_normal(sim[s].size)
                                                       for s in ("v_in", "i_in")))
        est = waveform_noise(w)["per_signal"]
        for s in ("v_in", "i_in"):
            assert est[s] == pytest.approx(sd[s], rel=0.1)
