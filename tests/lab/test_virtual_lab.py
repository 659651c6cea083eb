"""Virtual lab of thesis 5.1: simulation exactness, round trip, noise artefacts, CSV, two-clock synthesis."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from pris_cosim.lab import virtual_lab as vl
from pris_cosim.measured.formats import read_response_csv
from pris_cosim.models.builtin import get_model
from pris_cosim.lab.timedomain import simulate_pris

SIX = ["Zlvoc", "Zlvsc", "Zhvoc", "Zhvsc", "Rlvhv", "Rhvlv"]
MAX_DB = 0.5  # round-trip magnitude tolerance, 10 Hz - 10 kHz
MAX_DEG = 3.0  # round-trip phase tolerance


@pytest.fixture(scope="module")
def model():
    return get_model("hv-4section")


@pytest.fixture(scope="module")
def clean(model):
    """Quick lab, no noise and no quantisation (anti-alias filter and probes kept)."""
    return vl.run_lab(model, quick=True, noise=False)


@pytest.fixture(scope="module")
def noisy(model):
    return vl.run_lab(model, quick=True, noise=True, seed=3, keep_records=["LVHV"])


def test_settings_are_the_thesis_ones(model):
    st = vl.LabSettings()
    lvoc, lvhv, hvsc = (model.configuration(c) for c in ("LVOC", "LVHV", "HVSC"))
    s = st.source(lvoc, "high")
    assert (s.vdc, s.prbs_order, s.fclk, s.rpris, s.lpris, s.cpris) == (30.0, 16, 20e3, 56.0, 500e-6, 4e-6)
    assert st.source(lvhv, "high").vdc == 10.0
    s = st.source(hvsc, "low")
    assert (s.vdc, s.prbs_order, s.fclk, s.rpris, s.lpris, s.cpris) == (120.0, 13, 2e3, 29.7e3, 30e-3, 100e-9)
    assert (s.rsnub, s.csnub) == (55.0, 10e-9)
    q = vl.LabSettings.quick()
    assert q.source(lvoc, "high").fclk == 20e3 and q.source(lvoc, "low").fclk == 2e3
    assert st.transitions["Zlvsc"] == pytest.approx(666.67, abs=0.01) and st.transitions["Rlvhv"] == 200.0
    assert st.chain.fs == 1e6 and st.chain.adc_bits == 16


def test_switch_parasitics_reproduce_the_ringing():
    lp, cp = vl.switch_parasitics()
    assert 1 / (2 * math.pi * math.sqrt(lp * cp)) == pytest.approx(2.2936e6, rel=1e-9)
    assert 1 / (2 * math.pi * math.sqrt(lp * (cp + 10e-9))) == pytest.approx(482.63e3, rel=1e-9)


def test_anti_alias_filter_matches_ef502_figures():
    a, b, c, d = vl.anti_alias_ss(vl.MeasurementChain())

    def gain_db(f):
        s = 2j * math.pi * f
        return 20 * math.log10(abs(c @ np.linalg.solve(s * np.eye(a.shape[0]) - a, b) + d))

    passband = [gain_db(f) for f in np.linspace(1.0, 100e3, 400)]
    assert max(passband) <= 1e-9 and min(passband) >= -1.0 - 1e-6  # the 1 dB passband
    assert gain_db(100e3) == pytest.approx(-1.0, abs=1e-6)
    assert gain_db(199e3) < -30.0


@pytest.mark.parametrize("config,probe", [("LVOC", None), ("LVHV", "b1"), ("HVLV", "a1")])
def test_unfiltered_noise_free_record_equals_simulate_pris(model, config, probe):
    st = vl.LabSettings.quick(8, 6)
    st = replace(st, start="rest", chain=replace(st.chain, aa_cutoff_hz=None))
    rec = vl.perturb(model, config, "high", st, noise=False, keep_true=True)
    cfg = model.configuration(config)
    circuit = model.circuit if probe is None else replace(model.circuit, probes=[probe])
    ref = simulate_pris(circuit, cfg.port, st.source(cfg, "high"), 1e6, 1, shorts=cfg.shorts)
    assert rec.v_in.size == ref["v_in"].size
    np.testing.assert_array_equal(rec.v_bprbs, ref["v_bprbs"])
    for mine, theirs in ((rec.v_in, ref["v_in"]), (rec.i_in, ref["i_in"]), (rec.true["i_in"], ref["i_in"])):
        assert np.max(np.abs(mine - theirs)) <= 1e-9 * np.max(np.abs(theirs))
    if probe is not None:
        assert np.max(np.abs(rec.v_out - ref[f"v_{probe}"])) <= 1e-9 * np.max(np.abs(ref[f"v_{probe}"]))


def test_steady_state_start_is_periodic(model):
    st = replace(vl.LabSettings.quick(8, 6), periods=2)
    rec = vl.perturb(model, "HVSC", "high", st, noise=False, keep_true=True)
    half = rec.v_in.size // 2
    for x in (rec.v_in, rec.true["i_in"]):
        assert np.max(np.abs(x[:half] - x[half:])) <= 1e-8 * np.max(np.abs(x))


@pytest.mark.slow
def test_round_trip_noise_free_recovers_the_analytic_responses(model, clean):
    assert clean.measured.names == SIX
    f = clean.measured.frequency_hz
    # the first frequency whose band holds a bin of the low clock's (1.95 Hz), the last below 100 kHz (the fifth
    # null of the 20 kHz clock)
    assert 10.0 <= f[0] < 14.0 and 90e3 < f[-1] < 100e3
    errors = vl.round_trip_errors(clean.measured, model, 10.0, 10e3)
    for name in SIX:
        db, deg = errors[name]
        assert db < MAX_DB, (name, db)
        assert deg < MAX_DEG, (name, deg)


@pytest.mark.slow
def test_noise_makes_data_above_20khz_noisier(model, clean, noisy):
    """The thesis saw noise above 20 kHz: the PRBS spectrum has its first null at f_clk = 20 kHz."""
    f = noisy.measured.frequency_hz
    ref = model.response_set().evaluate(f)
    lo, hi = (f > 2e3) & (f < 10e3), f > 20e3
    for name in SIX:
        h = noisy.high[name]
        fh = h.frequency_hz
        coh_lo = np.mean(h.coherence[(fh > 2e3) & (fh < 10e3)])
        coh_hi = np.mean(h.coherence[fh > 20e3])
        assert coh_hi < coh_lo, name
        assert 1 - coh_hi > 3 * (1 - coh_lo), name  # incoherent fraction at least 3x larger
        err = 20 * np.log10(np.abs(noisy.measured.responses[name] / ref[name]))
        err0 = 20 * np.log10(np.abs(clean.measured.responses[name] / ref[name]))
        noise_part = err - err0  # remove the (deterministic) estimator error
        assert np.std(noise_part[hi]) > 2 * np.std(noise_part[lo]), name
    # and the noise-free responses show no such thing: coherence above 20 kHz stays at 1
    for name in SIX:
        h = clean.high[name]
        assert np.nanmin(h.coherence[h.frequency_hz > 20e3]) > 0.999


def test_noise_free_option_differs_from_noisy_and_seed_is_reproducible(model):
    st = vl.LabSettings.quick(8, 6)
    a = vl.perturb(model, "LVSC", "high", st, seed=7)
    b = vl.perturb(model, "LVSC", "high", st, seed=7)
    c = vl.perturb(model, "LVSC", "high", st, seed=8)
    np.testing.assert_array_equal(a.v_in, b.v_in)
    assert not np.array_equal(a.v_in, c.v_in)
    lsb = st.chain.lsb_v * a.attenuation["v_in"]
    assert np.allclose(a.v_in / lsb, np.round(a.v_in / lsb), atol=1e-6)  # quantised to the ADC step
    assert sum(a.clipped.values()) == 0


@pytest.mark.slow
def test_csv_round_trip(tmp_path, noisy):
    path = tmp_path / "lab.csv"
    vl.write_lab_csv(path, noisy.measured)
    header = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == "frequency_hz," + ",".join(f"{n}_mag,{n}_phase_deg,{n}_ln_sd" for n in SIX)
    back = read_response_csv(path)
    assert back.names == SIX
    np.testing.assert_array_equal(back.frequency_hz, noisy.measured.frequency_hz)
    for n in SIX:
        np.testing.assert_allclose(back.responses[n], noisy.measured.responses[n], rtol=1e-13, atol=0)
        np.testing.assert_allclose(back.uncertainty[n], noisy.measured.uncertainty[n], rtol=1e-15, atol=0)
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.slow
def test_no_row_without_excitation(noisy):
    """No frequency near a multiple of the 20 kHz clock (the PRBS nulls), none below four low-clock bins, and a
    finite positive standard deviation at every point."""
    st = noisy.settings
    f = noisy.measured.frequency_hz
    x = f / st.lv.fclk
    assert not np.any((np.abs(x - np.round(x)) < 0.08) & (np.round(x) >= 1))
    assert f[-1] < 100e3 * (1 - 0.08 / 5)
    bin_low = noisy.low["Zlvoc"].frequency_hz[1] - noisy.low["Zlvoc"].frequency_hz[0]
    assert f[0] >= 4 * bin_low * (1 - 1e-9)
    for n in SIX:
        sd = noisy.measured.uncertainty[n]
        assert np.all(np.isfinite(sd) & (sd > 0))


@pytest.mark.slow
def test_truth_fits_the_lab_output_near_the_noise_floor():
    """The quick lab of hv-6section-freqdep against the model's own analytic responses: within 3 x the noise
    floor of the weighted cost (each point weighted by its stated standard deviation)."""
    from estimation.diagnosis.evidence import noise_floor, noise_weights

    truth = get_model("hv-6section-freqdep")
    m = vl.run_lab(truth, quick=True, seed=0).measured
    f = m.frequency_hz
    ref = truth.response_set().evaluate(f)
    u = noise_weights(m.uncertainty)
    cost = sum(np.mean(u[n] ** 2 * np.abs(np.log(ref[n] / m.responses[n])) ** 2) for n in SIX)
    floor = noise_floor(f, m.responses, m.uncertainty)["cost"]
    assert cost < 3 * floor
    # unweighted, the noisy points (PRBS roll-off above 20 kHz, Zlvsc below 30 Hz) dominate by far
    plain = sum(np.mean(np.abs(np.log(ref[n] / m.responses[n])) ** 2) for n in SIX)
    assert plain > 100 * floor


@pytest.mark.slow
def test_two_clock_synthesis_uses_low_clock_below_transition(noisy):
    st = noisy.settings
    for name in SIX:
        ft = st.transitions[name]
        s, lo, hi = noisy.synthesised[name], noisy.low[name], noisy.high[name]
        below = s.frequency_hz < ft
        assert np.any(below)
        idx = np.searchsorted(lo.frequency_hz, s.frequency_hz[below])
        np.testing.assert_array_equal(lo.frequency_hz[idx], s.frequency_hz[below])
        np.testing.assert_array_equal(lo.values[idx], s.values[below])
        above = ~below
        idx = np.searchsorted(hi.frequency_hz, s.frequency_hz[above])
        np.testing.assert_array_equal(hi.values[idx], s.values[above])
        # the low clock's bins are finer than the high clock's (longer record)
        assert lo.frequency_hz[0] < hi.frequency_hz[0]


@pytest.mark.slow
def test_plots(tmp_path, model, noisy):
    paths = vl.plot_lab(noisy, model, tmp_path)
    paths += vl.plot_record(noisy.records[("LVHV", "high")], tmp_path)
    assert [p.name for p in paths] == ["virtual_lab_lv.png", "virtual_lab_hv.png",
                                       "virtual_lab_lvhv_high_waveforms.png", "virtual_lab_lvhv_high_spectra.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_arguments(model):
    st = replace(vl.LabSettings.quick(8, 6), chain=replace(vl.MeasurementChain(), fs=1.5e6 + 1))
    with pytest.raises(ValueError, match="integer multiple"):
        vl.perturb(model, "LVOC", "high", st)
    with pytest.raises(ValueError, match="clock"):
        vl.LabSettings().source(model.configuration("LVOC"), "medium")  # type: ignore[arg-type]


#: One worker runs this module under ``pytest -n 2 --dist loadgroup``: its module fixtures are computed once.
pytestmark = pytest.mark.xdist_group("virtual_lab")
