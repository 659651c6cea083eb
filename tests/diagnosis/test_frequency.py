"""Diagnosis names skin effect in real data, reports and realises it, and refuses bad input.

Hidden-effect cases from the independent generator are in ``test_diagnosis_hidden.py``.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from estimation.diagnosis import DiagnosisError, diagnose_frequency
from estimation.diagnosis.report import write_report
from pris_cosim.measured.formats import read_multisegment_csv
from pris_cosim.models.builtin import get_model
from pris_cosim.circuits.netlist import parse_netlist

from conftest import REAL as REAL_DIR
from hidden_cases import one_port_case

REAL = REAL_DIR / "small_transformer_3_loads.csv"


@pytest.fixture(scope="module")
def real_short():
    return read_multisegment_csv(REAL, "short")


@pytest.mark.slow
def test_real_short_circuit_is_skin_effect(real_short, tmp_path):
    d = diagnose_frequency(real_short.frequency_hz, real_short.responses, progress=False)
    assert d.cause == "skin-effect" and d.gain >= 0.5
    # the fitted resistance rises with frequency, as the measured real part does (about tenfold 10 kHz - 350 kHz)
    skin = d.best.extra["skin-effect"] if len(d.causes) > 1 else d.best.extra
    assert skin["a"] > 1
    # the phase droop above about 5 MHz: named (fixture capacitance) or reported with its band
    assert "stray-capacitance" in d.causes or any(u["band_hz"][1] > 5e6 for u in d.unexplained)
    assert d.realisation["kind"] == "ladder" and d.realisation["max_deviation_db"] < 0.1
    report = write_report(d, tmp_path / "rep", source="short")
    text = report.read_text()
    assert "skin-effect" in text and (tmp_path / "rep" / "fits.png").stat().st_size > 10_000
    assert (tmp_path / "rep" / "extended.cir").exists()


@pytest.mark.slow
def test_cli_real_open_segment_report(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(REAL), "--segment", "open",
                           "--report", str(tmp_path / "open"), "--json"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert {"cause", "candidates", "baseline_cost", "extended_cost", "gain"} <= set(out)
    assert all({"cause", "cost", "gain"} <= set(c) for c in out["candidates"])
    text = (tmp_path / "open" / "report.md").read_text()
    assert "Candidates" in text and "Residual per band" in text


def test_responses_not_matching_model():
    case = one_port_case("none", 1)
    with pytest.raises(DiagnosisError, match="'Zin' is not a response of the model"):
        diagnose_frequency(case.frequency_hz, case.measured, model=get_model("hv-4section"), progress=False)


def test_too_few_points():
    case = one_port_case("none", 1, points=4)
    with pytest.raises(DiagnosisError, match="too few points"):
        diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist), port=case.port,
                           progress=False)


def test_baseline_that_does_not_fit_at_all():
    f = np.logspace(3, 6, 100)
    active = -100.0 * np.ones(f.size, complex)  # a negative resistance: no passive R-L-C fits it
    winding = parse_netlist("* R-L-C\nR1 in x 1\nL1 x 0 1m\nC1 in 0 10p\n")
    with pytest.raises(DiagnosisError, match="does not fit the data at all"):
        diagnose_frequency(f, {"Zin": active}, circuit=winding, port="in", progress=False)


def test_improper_baseline_is_refused():
    f = np.logspace(3, 6, 100)
    inductor = parse_netlist("* R-L\nR1 in x 1\nL1 x 0 1m\n")
    with pytest.raises(DiagnosisError, match="improper"):
        diagnose_frequency(f, {"Zin": 1j * f}, circuit=inductor, port="in", progress=False)


def test_cli_bad_input_one_line(tmp_path):
    bad = tmp_path / "z.csv"
    bad.write_text("frequency_hz,Zin_mag,Zin_phase_deg\n10,1,0\n5,1,0\n")
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(bad), "--json"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ""
    assert len(proc.stderr.strip().splitlines()) == 1 and "z.csv" in proc.stderr


@pytest.mark.slow
def test_extended_model_is_simulable_and_an_fmu(real_short, tmp_path):
    """The frequency-dependent extension is realised as a circuit: exact time stepping and an FMU build work."""
    from pris_cosim.fmi import codegen, build as fmi
    from pris_cosim.lab.timedomain import simulate_current_injection

    d = diagnose_frequency(real_short.frequency_hz, real_short.responses, progress=False)
    ladder = d.realisation["circuit"]
    fs = 200e6
    t = np.arange(2000) / fs
    i = np.sin(2 * np.pi * 5e6 * t)
    out = simulate_current_injection(ladder, "in", i, fs)
    v = out["v_in"] if "v_in" in out else next(iter(v for k, v in out.items() if k.startswith("v")))
    assert np.all(np.isfinite(v)) and np.max(np.abs(v)) > 0
    path = fmi.build_fmu(codegen.dut_model(ladder, "in", name="short_extended"), tmp_path)
    assert path.exists()
