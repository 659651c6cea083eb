"""FMUs in the estimation loop, and replaying sampled records without bias.

Targets come from the prebuilt FMUs run by fmpy's own ``simulate_fmu``
(:class:`pris_cosim.fmi.cosim.FmuRunner`) and from ngspice, not from the code
under test.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import needs_ngspice
from estimation import approaches as ap
from estimation.cli import run_estimate
from estimation.drives import RecordBridgeEngine
from estimation.fmu.model import FmuModel
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.fmi.cosim import FmuRunner
from pris_cosim.models.builtin import get_model
from pris_cosim.fmi.thesis_cases import THREE_SECTION, TWO_SECTION

REPO = Path(__file__).resolve().parents[2]
TWO_PRIS = REPO / "fmus" / "two-section" / "two_section_pris.fmu"
TWO_DUT = REPO / "fmus" / "two-section" / "two_section_dut.fmu"
THREE_PRIS = REPO / "fmus" / "three-section" / "three_section_pris.fmu"
COLUMNS = ["v_bprbs", "v_in", "i_in"]


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def fmu_record(fmu: Path, fs: float, duration: float, values: dict | None = None) -> dict[str, np.ndarray]:
    """Waveforms of a prebuilt arrangement FMU from fmpy's simulate_fmu (sample k at k / fs)."""
    n = int(round(fs * duration))
    with FmuRunner(fmu) as r:
        names = [v.name for v in r.model_description.modelVariables if v.causality == "output"]
        res = r.run(stop_time=(n - 1) / fs, output_interval=1 / fs, output=names, start_values=values or {})
    out = {k: np.asarray(res[k][:n], float) for k in names}
    out["time_s"] = np.arange(n) / fs
    return out


def write_csv(path: Path, w: dict[str, np.ndarray], columns: list[str] = COLUMNS) -> Path:
    np.savetxt(path, np.column_stack([w["time_s"]] + [w[c] for c in columns]), delimiter=",",
               header=",".join(["time_s"] + columns), comments="", fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def two_record(tmp_path_factory) -> Path:
    w = fmu_record(TWO_PRIS, 1e6, 0.02)
    return write_csv(tmp_path_factory.mktemp("two") / "two.csv", w)


# ---------------------------------------------------------------------- unbiased replay (truth scores)
@pytest.mark.parametrize("name,fmu,port,case,duration", [
    ("two-section", TWO_PRIS, "in", TWO_SECTION, 0.05),
    ("three-section", THREE_PRIS, "n1", THREE_SECTION, 0.004),
])
def test_truth_scores_on_fmu_records_at_1mhz(name, fmu, port, case, duration):
    """The true model replayed from the record scores at most 1e-3 of the signal RMS (held current did not)."""
    w = fmu_record(fmu, 1e6, duration)
    circuit = get_model(name).circuit
    bridge = RecordBridgeEngine(circuit, port, case.settings, 1e6, w["v_bprbs"]).simulate({})
    assert rel(bridge["v_in"][0], w["v_in"]) < 1e-3
    held = ap.InjectionEngine(circuit, port, w["i_in"], 1e6, hold="step").simulate({})[0]
    assert rel(held, w["v_in"]) > 5e-3  # the old replay: a half-sample delay of the current
    linear = ap.InjectionEngine(circuit, port, w["i_in"], 1e6).simulate({})[0]
    if name == "two-section":  # modes far below Nyquist: the linear hold suffices
        assert rel(linear, w["v_in"]) < 1e-3
    assert rel(linear, w["v_in"]) < rel(held, w["v_in"])


@needs_ngspice
@pytest.mark.parametrize("fs", [10e6, 1e6])
@pytest.mark.parametrize("name,port,settings,max_step", [
    ("two-section", "in", SourceSettings(vdc=30.0, prbs_order=5, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9),
     1e-8),
    ("three-section", "n1", SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3,
                                           cpris=1e-6), 2e-9),
])
@pytest.mark.slow
def test_truth_scores_on_ngspice_records(name, port, settings, max_step, fs):
    from pris_cosim.lab import timedomain as td

    circuit = get_model(name).circuit
    w = td.pris_ngspice(circuit, port, settings, fs, periods=1, max_step=max_step)
    out = RecordBridgeEngine(circuit, port, settings, fs, w["v_bprbs"]).simulate({})
    assert rel(out["v_in"][0], w["v_in"]) < 1e-3
    assert rel(out["i_in"][0], w["i_in"]) < 1e-3
    linear = ap.InjectionEngine(circuit, port, w["i_in"], fs).simulate({})[0]
    if fs == 10e6:  # sampled well above the fastest mode: the injected current held linearly is unbiased too
        assert rel(linear, w["v_in"]) < 1e-3


def test_linear_hold_is_exact_for_a_ramp_into_parallel_rc():
    """Closed form: i(t) = a t into R || C from rest gives v = a R (t - tau (1 - exp(-t / tau)))."""
    from pris_cosim.circuits.circuit import Circuit

    c = Circuit(title="RC")
    c.add("R1", "a", "0", 1e3)
    c.add("C1", "a", "0", 1e-6)
    fs, a, tau = 1e4, 2.0, 1e-3
    t = np.arange(200) / fs
    v = ap.InjectionEngine(c, "a", a * t, fs).simulate({})[0]
    exact = a * 1e3 * (t - tau * (1 - np.exp(-t / tau)))
    assert np.max(np.abs(v - exact)) < 1e-12 * np.max(np.abs(exact))


# ---------------------------------------------------------------------- the FMU instance
def test_dut_fmu_with_linear_input_reproduces_the_arrangement():
    w = fmu_record(TWO_PRIS, 1e6, 0.02)
    with FmuModel(TWO_DUT, ["R1"], ["v_in"], input="i_in", substeps=2) as m:
        y = m.simulate({"R1": 10.0}, 1e6, w["v_in"].size, w["i_in"])
        assert rel(y[0], w["v_in"]) < 1e-3
        assert m.failures == 0


def test_failed_run_is_counted_and_the_instance_recovers():
    n = 2000
    with FmuModel(TWO_PRIS, ["R1", "L1"], ["v_in"]) as m:
        good = m.simulate({"R1": 10.0, "L1": 10.0}, 1e6, n)
        assert m.simulate({"R1": -5.0, "L1": 10.0}, 1e6, n) is None  # refused by the FMU (min 1e-9)
        assert m.simulate({"R1": 10.0, "L1": float("nan")}, 1e6, n) is None
        assert m.failures == 2 and m.last_error
        again = m.simulate({"R1": 10.0, "L1": 10.0}, 1e6, n)
        assert np.array_equal(good, again)


# ---------------------------------------------------------------------- estimate with an FMU in the loop
def _fmu_cfg(record: Path, **kw) -> dict:
    cfg = {"fmu": str(TWO_PRIS), "output": "v_in", "approach": "time", "seed": 1,
           "parameters": {"C1": {"min": 0.5e-9, "max": 2e-9}, "L2": {"min": 95, "max": 400}},
           "ties": {"C2": "C1"},
           "target": {"kind": "waveforms-csv", "path": str(record), "values": {"C1": 1e-9, "L2": 100.0}},
           "budget": {"design": 6, "restarts": 2, "simulations": 40}}
    cfg.update(kw)
    return cfg


@pytest.mark.slow
def test_fmu_estimate_recovers_and_resumes(tmp_path, two_record):
    out = tmp_path / "run"
    a = run_estimate(_fmu_cfg(two_record), progress=False, out=str(out), workers=2)
    assert all(abs(e) < 0.1 for e in a["errors_percent"].values()), a["errors_percent"]
    assert a["fmu_simulations"] > 0 and a["failed_evaluations"] >= 0 and a["wall_s"] > 0
    assert set(a["uncertainty"]) == {"C1", "L2"} and a["uncertainty"]["C1"] < 0.01
    stored = sorted(p.name for p in (out / "runs").glob("*.json"))
    assert stored[:1] == ["design-000.json"] and "restart-1.json" in stored
    b = run_estimate(_fmu_cfg(two_record), progress=False, out=str(out), workers=2)  # all stored: nothing re-run
    assert b["estimate"] == a["estimate"]
    assert b["fmu_simulations"] == a["fmu_simulations"]
    (out / "runs" / "restart-2.json").unlink()  # as if interrupted before the second restart was stored
    c = run_estimate(_fmu_cfg(two_record), progress=False, out=str(out), scheduler="serial")
    assert c["estimate"] == a["estimate"]
    assert (out / "runs" / "restart-2.json").is_file()


@pytest.mark.slow
@pytest.mark.parametrize("approach", ["iemd", "emd", pytest.param("frequency", marks=pytest.mark.long)])
def test_fmu_estimate_other_approaches_with_a_current_input(tmp_path, approach):
    """The DUT FMU driven by the recorded current (linear input): time, EMD, IEMD and Welch H1."""
    w = fmu_record(TWO_PRIS, 1e6, 0.05 if approach == "frequency" else 0.01)
    rec = write_csv(tmp_path / "r.csv", w)
    cfg = _fmu_cfg(rec, fmu=str(TWO_DUT), input="i_in", approach=approach,
                   parameters={"C1": {"min": 0.5e-9, "max": 2e-9}}, target={"kind": "waveforms-csv", "path": str(rec),
                                                                           "values": {"C1": 1e-9}},
                   budget={"design": 4, "restarts": 1, "simulations": 16})
    if approach == "frequency":
        cfg["frequency"] = {"fmin": 100, "fmax": 20000}
    a = run_estimate(cfg, progress=False, out=str(tmp_path / "o"), scheduler="serial")
    assert abs(a["errors_percent"]["C1"]) < 1.0, a
    assert a["input_hold"].startswith("linear")


def test_fmi3_fmu_in_the_loop(tmp_path):
    from pris_cosim.fmi import build as fmi

    settings = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    paths = fmi.build_pris_fmus(get_model("three-section").circuit, "n1", tmp_path / "f3", settings, name="three",
                                fmi_version=3)
    w2 = fmu_record(THREE_PRIS, 1e6, 0.001)  # FMI 2.0 record of the same network, other source: compare the DUT
    with FmuModel(paths["dut"], ["Rs"], ["v_in"], input="i_in", substeps=2) as m3, \
            FmuModel(REPO / "fmus" / "three-section" / "three_section_dut.fmu", ["Rs"], ["v_in"], input="i_in",
                     substeps=2) as m2:
        y3 = m3.simulate({"Rs": 0.083}, 1e6, w2["i_in"].size, w2["i_in"])
        y2 = m2.simulate({"Rs": 0.083}, 1e6, w2["i_in"].size, w2["i_in"])
    assert y3 is not None and np.max(np.abs(y3 - y2)) <= 1e-9 * np.max(np.abs(y2))


@pytest.mark.parametrize("change,needle", [
    ({"fmu": "nowhere.fmu"}, "nowhere.fmu"),
    ({"parameters": {"Rx": {"min": 1, "max": 2}}}, "Rx"),
    ({"input": "v_in"}, "input"),
    ({"output": "v_nowhere"}, "v_nowhere"),
    ({"approach": "spectral"}, "approach"),
    ({"target": {"kind": "waveforms-csv", "path": "missing.csv"}}, "missing.csv"),
    ({"budget": {"design": "many"}}, "budget"),
    ({"budget": 5}, "budget"),
    ({"design_score": "luck"}, "design_score"),
    ({"outputs": ["v_mid"]}, "v_mid"),  # an FMU output the record does not hold
    ({"values": {"R_nowhere": 1.0}}, "R_nowhere"),
    ({"values": {"C1": "small"}}, "C1"),
    ({"values": {"C2": 1e-9}}, "C2"),  # also tied
    ({"input_hold": "cubic"}, "input_hold"),
])
@pytest.mark.slow
def test_bad_fmu_config_one_line(tmp_path, two_record, change, needle):
    cfg = _fmu_cfg(two_record)
    cfg.update(change)
    p = tmp_path / "c.json"
    p.write_text(json.dumps(cfg))
    r = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(p), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and needle in r.stderr, r.stderr


def test_hold_decided_from_the_input():
    """Few levels changing only at samples are held; a sampled sine is not."""
    from estimation.holds import decide_hold

    rng = np.random.default_rng(3)
    prbs = np.repeat(np.where(rng.random(300) < 0.5, -2.5, 2.5), 7)
    assert decide_hold(prbs, "u")[0] == "zoh"
    assert "2 distinct levels" in decide_hold(prbs, "u")[1]
    steps = np.repeat(rng.integers(0, 16, 100) * 0.25, 3)  # a 4-bit DAC staircase
    assert decide_hold(steps)[0] == "zoh"
    sine = np.sin(2 * np.pi * 0.013 * np.arange(2000))
    assert decide_hold(sine)[0] == "linear"
    assert decide_hold(np.linspace(0, 1, 500))[0] == "linear"  # a ramp


def test_values_set_for_every_run(tmp_path, two_record):
    """A parameter given in "values" is set in every run and reported, not estimated."""
    cfg = _fmu_cfg(two_record)
    cfg["parameters"] = {"C1": {"min": 0.5e-9, "max": 2e-9}}
    cfg["ties"] = {"C2": "C1"}
    cfg["values"] = {"R1": 10.0, "R2": 10.0, "L1": 10.0, "L2": 100.0, "M12": 30.0}
    cfg["budget"] = {"design": 4, "candidates": 2, "restarts": 1, "simulations": 12}
    cfg["target"]["values"] = {"C1": 1e-9}
    a = run_estimate(cfg, progress=False, out=str(tmp_path / "o"), scheduler="serial")
    assert a["values"] == cfg["values"] and set(a["estimate"]) == {"C1"}
    assert a["input_hold"] is None  # an arrangement FMU makes its own drive
    assert abs(a["errors_percent"]["C1"]) < 1.0, a
