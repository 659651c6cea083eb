"""The PRIS arrangement diagnosed from its own waveforms: source and winding causes, replayed from the bridge voltage.

Records are made here by ngspice (:mod:`pris_records`: a deck written without the package, the thesis's
three-section winding of Table 4.7 driven by the 4.2.2 source through a PWL bridge voltage, 0.2 % white noise on
``v_in`` and ``i_in``), and from the records in ``tests/data/pris_records`` (see the README there).
"""

import gzip
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg as sl
from conftest import needs_ngspice

from estimation.diagnosis.waveform.record_spectra import alias_grid, periodic_record, sampled_response, source_responses
from pris_cosim.measured.formats import Waveforms

DATA = Path(__file__).parents[1] / "data" / "pris_records"


def _exact_zoh(A, b, c, h, f):
    """``c (z I - Phi)^-1 Gamma`` of the zero-order-hold discretisation by the matrix exponential."""
    n = A.shape[0]
    M = sl.expm(np.block([[A, b[:, None]], [np.zeros((1, n + 1))]]) * h)
    Phi, Gam = M[:n, :n], M[:n, n]
    return np.array([c @ np.linalg.solve(z * np.eye(n) - Phi, Gam) for z in np.exp(2j * np.pi * f * h)])


def test_sampled_response_is_the_zero_order_hold_discretisation():
    """The alias sum with its tail against the matrix exponential: the source on 15 Ohm, with and without the
    bridge's parasitics (states: i_L, v_C, i_Lsw, v_Csw)."""
    R, L, C, RL, Ls, Cs, h = 57.1, 1e-3, 4e-6, 15.0, 10.4e-6, 0.463e-9, 1e-7
    f = np.linspace(1e3, 1e6, 40)
    W = alias_grid(f, h)
    zw = np.full((1,) + W.shape, RL + 0j)
    _, i = source_responses(zw, W, np.array([R]), np.array([L]), np.array([C]))
    A = np.array([[-(R + RL) / L, -1 / L], [1 / C, 0]])
    want = _exact_zoh(A, np.array([1 / L, 0]), np.array([1.0, 0]), h, f)
    assert np.max(np.abs(sampled_response(i, W, h)[0] / want - 1)) < 1e-6
    _, i = source_responses(zw, W, np.array([R]), np.array([L]), np.array([C]), np.array([Ls]), np.array([Cs]))
    A = np.array([[-(R + RL) / L, -1 / L, 0, 1 / L], [1 / C, 0, 0, 0], [0, 0, 0, -1 / Ls], [-1 / Cs, 0, 1 / Cs, 0]])
    want = _exact_zoh(A, np.array([0, 0, 1 / Ls, 0]), np.array([1.0, 0, 0, 0]), h, f)
    assert np.max(np.abs(sampled_response(i, W, h)[0] / want - 1)) < 1e-4


def test_a_record_that_does_not_repeat_is_not_replayed():
    rng = np.random.default_rng(0)
    bits = np.repeat(rng.choice([-1.0, 1.0], 300), 20)
    t = np.arange(bits.size) * 1e-7
    w = Waveforms(t, bits, rng.standard_normal(bits.size), rng.standard_normal(bits.size))
    rec, why = periodic_record(w)
    assert rec is None and "repeat" in why


def test_bad_source_tolerance_is_one_line(tmp_path):
    path = tmp_path / "rec.csv"
    path.write_text("time_s,v_bprbs,v_in,i_in\n0,1,0,0\n1e-7,1,0,0\n")
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(path), "--model",
                           "three-section", "--rpris", "150", "--lpris", "4m", "--cpris", "1u",
                           "--source-tolerance", "-1"], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--source-tolerance" in proc.stderr and "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------------------- ngspice records
def _diagnose(rec, rpris=150.0, lpris=4e-3, cpris=1e-6):
    from estimation.diagnosis.waveform.replay import diagnose_pris_record
    from pris_cosim.models.builtin import get_model

    w = Waveforms(rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"])
    return diagnose_pris_record(w, rpris, lpris, cpris, model=get_model("three-section"), progress=False)


@pytest.mark.slow
@needs_ngspice
def test_a_contact_resistance_in_the_source_is_named_with_its_value():
    from pris_records import record

    d = _diagnose(record(contact=45.0, noise=0.002))
    out = d.as_json()
    assert out["causes"] == ["series-resistance"] and out["path"]["path"] == "exact-replay", out["steps"]
    assert abs(out["steps"][0]["values"]["r_series_ohm"] - 45.0) < 2.0
    assert out["drift"] == []


@pytest.mark.slow
@needs_ngspice
def test_a_capacitance_across_the_port_is_named_as_the_winding_cause():
    from pris_records import record

    d = _diagnose(record(stray=330e-12, noise=0.002))
    assert d.causes == ["stray-capacitance"], d.steps
    assert d.as_json()["source_values"]["rpris"] == pytest.approx(150.0, rel=0.01)


@pytest.mark.slow
@needs_ngspice
def test_a_source_fault_and_a_winding_effect_are_both_named():
    from pris_records import record

    d = _diagnose(record(stray=330e-12, contact=45.0, noise=0.002))
    assert set(d.causes) == {"series-resistance", "stray-capacitance"}, d.steps


@pytest.mark.slow
@needs_ngspice
def test_switch_ringing_beside_a_capacitance_at_the_port_is_named_too():
    """The bridge's 10.4 uH and 0.463 nF ring at 2.29 MHz, above the replayed band: named at its frequency."""
    from pris_records import record

    d = _diagnose(record(lsw=10.4e-6, csw=0.463e-9, stray=330e-12, noise=0.002))
    assert set(d.causes) == {"stray-capacitance", "switch-ringing"}, d.steps
    src = d.as_json()["source_values"]
    f_ring = 1 / (2 * np.pi * np.sqrt(src["lsw"] * src["csw"]))
    assert f_ring == pytest.approx(1 / (2 * np.pi * np.sqrt(10.4e-6 * 0.463e-9)), rel=0.05)
    assert d.drift == []


@pytest.mark.slow
@needs_ngspice
@pytest.mark.parametrize("settings", [
    dict(order=7, fclk=200e3, rpris=100.0, lpris=2e-3, cpris=2.2e-6),
    dict(order=5, fclk=50e3, rpris=330.0, lpris=10e-3, cpris=0.47e-6),
])
def test_nothing_hidden_with_other_source_settings_gives_none(settings):
    """0.2 % noise on both channels (errors in variables): no false alarm."""
    from pris_records import record

    d = _diagnose(record(noise=0.002, **settings), settings["rpris"], settings["lpris"], settings["cpris"])
    assert d.causes == [] and d.drift == [], (d.steps, d.drift)
    assert d.as_json()["path"]["path"] == "exact-replay"


CASES = [  # name, baseline, source (R, L, C), true causes
    ("source_series_r", "load", (57.1, 1e-3, 4e-6), {"series-resistance"}),
    ("source_drift", "load", (57.1, 1e-3, 4e-6), {"component-drift"}),
    ("source_none", "load", (57.1, 1e-3, 4e-6), set()),
    ("source_ringing", "load", (57.1, 1e-3, 4e-6), {"series-resistance", "switch-ringing"}),
    pytest.param("three_section_ngspice_10MHz", "three-section", (150.0, 4e-3, 1e-6), set(), marks=pytest.mark.long,
                 id="three_section_ngspice_10MHz"),
    ("three_section_stray_10MHz", "three-section", (150.0, 4e-3, 1e-6), {"stray-capacitance"}),
]


@pytest.mark.slow
@pytest.mark.parametrize("name,baseline,src,truth", CASES, ids=[getattr(c, "id", None) or c[0] for c in CASES])
def test_the_recorded_cases_through_the_command(tmp_path, name, baseline, src, truth):
    path = tmp_path / f"{name}.csv"
    with gzip.open(DATA / f"{name}.csv.gz", "rb") as fin, open(path, "wb") as fout:
        shutil.copyfileobj(fin, fout)
    base = (["--model", baseline] if baseline != "load"
            else ["--netlist", str(DATA / "ho_load15.cir"), "--port", "p"])
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(path), *base,
                           "--rpris", str(src[0]), "--lpris", str(src[1]), "--cpris", str(src[2]), "--json"],
                          check=False, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert set(out["causes"]) == truth, out["steps"]
    assert {"cause", "causes", "steps", "drift", "unexplained", "noise_floor", "gain", "path"} <= set(out)


@pytest.mark.slow
def test_the_source_on_a_load_given_by_its_resistance(tmp_path):
    path = tmp_path / "rec.csv"
    with gzip.open(DATA / "source_series_r.csv.gz", "rb") as fin, open(path, "wb") as fout:
        shutil.copyfileobj(fin, fout)
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(path), "--rload", "15",
                           "--rpris", "57.1", "--lpris", "1m", "--cpris", "4u", "--json"],
                          check=False, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout)
    assert out["causes"] == ["series-resistance"], out["steps"]
    assert out["source_values"]["rpris"] == pytest.approx(61.2, rel=0.01)
