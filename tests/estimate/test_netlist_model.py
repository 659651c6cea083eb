"""estimate with a user's netlist in the loop, checked against the built-in model of the same circuit."""

import json
import subprocess
import sys

import pytest

from estimation.cli import run_estimate



def _cfg(netlist_dir, **kw):
    cfg = {"netlist": str(netlist_dir / "two_section_table4_2.cir"), "port": "in", "approach": "frequency", "seed": 1,
           "parameters": {"L1": {"min": 1, "max": 100}, "C2": {"min": 1e-10, "max": 1e-8}},
           "target": {"kind": "simulated", "values": {"L1": 12, "C2": 1.3e-9}}}
    cfg.update(kw)
    return cfg


@pytest.mark.slow
def test_netlist_frequency_recovers_values(netlist_dir):
    out = run_estimate(_cfg(netlist_dir), progress=False)
    assert out["model"] == "two_section_table4_2"
    assert all(abs(e) < 2.0 for e in out["errors_percent"].values())


@pytest.mark.slow
def test_netlist_matches_builtin_model(netlist_dir):
    """The netlist file and the built-in two-section model hold the same circuit: same estimate."""
    a = run_estimate(_cfg(netlist_dir), progress=False)
    cfg = _cfg(netlist_dir)
    del cfg["netlist"], cfg["port"]
    cfg["model"] = "two-section"
    b = run_estimate(cfg, progress=False)
    for k in a["estimate"]:
        assert abs(a["estimate"][k] / b["estimate"][k] - 1) < 1e-6


def test_unknown_port_one_line(tmp_path, netlist_dir):
    p = tmp_path / "c.json"
    p.write_text(json.dumps(_cfg(netlist_dir, port="nowhere")))
    r = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(p)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "nowhere" in r.stderr


# ---------------------------------------------------------------------- every approach on an ngspice record
import numpy as np
import pytest

from conftest import needs_ngspice

#: thesis 4.1.2 source with a PRBS9 (51.1 ms at 10 kHz): long enough to resolve the 550 Hz resonance
SOURCE9 = {"vdc": 30.0, "prbs_order": 9, "fclk": 10e3, "rpris": 31.8e3, "lpris": 2.53, "cpris": 10e-9}


@pytest.fixture(scope="module")
def ngspice_record(tmp_path_factory, netlist_dir):
    """The two-section netlist in the PRIS arrangement simulated by ngspice (independent of the estimator), 1 MHz."""
    from pris_cosim.circuits import ngspice
    from pris_cosim.lab import timedomain as td
    from pris_cosim.circuits.arrangement import SourceSettings
    from pris_cosim.circuits.netlist import read_netlist

    if not ngspice.available():
        pytest.skip("ngspice is not installed")
    w = td.pris_ngspice(read_netlist(netlist_dir / "two_section_table4_2.cir"), "in", SourceSettings(**SOURCE9), 1e6,
                        periods=1, max_step=1e-7)
    path = tmp_path_factory.mktemp("ngspice") / "record.csv"
    np.savetxt(path, np.column_stack([w["time_s"], w["v_bprbs"], w["v_in"], w["i_in"]]), delimiter=",",
               header="time_s,v_bprbs,v_in,i_in", comments="", fmt="%.17g")
    return path


@pytest.mark.slow
@needs_ngspice
@pytest.mark.parametrize("approach", ["frequency", "frequency-simulated", "time", "emd", "iemd"])
def test_netlist_every_approach_on_ngspice_record(netlist_dir, ngspice_record, approach):
    """L1 and C2 of the netlist from an ngspice PRIS record (bounds 0.4x .. 2.5x, small budget)."""
    cfg = {"netlist": str(netlist_dir / "two_section_table4_2.cir"), "port": "in", "approach": approach, "seed": 1,
           "source": SOURCE9, "parameters": {"L1": {"min": 4, "max": 25}, "C2": {"min": 4e-10, "max": 2.5e-9}},
           "target": {"kind": "waveforms-csv", "path": str(ngspice_record)}, "budget": {"max_evals": 3000, "restarts": 1}}
    out = run_estimate(cfg, progress=False)
    tol = 0.5 if approach == "frequency" else 0.05  # analytic Zin against the record's Welch H1 (leakage)
    assert abs(out["estimate"]["L1"] / 10 - 1) * 100 < tol, out["estimate"]
    assert abs(out["estimate"]["C2"] / 1e-9 - 1) * 100 < tol, out["estimate"]
    if approach in ("time", "emd", "iemd"):
        assert out["engine"].startswith("recorded-bridge")


def test_bridge_drive_without_source_one_line(tmp_path, netlist_dir):
    rec = tmp_path / "r.csv"
    t = np.arange(64) * 1e-6
    np.savetxt(rec, np.column_stack([t, np.ones(64), np.sin(t * 1e5), np.cos(t * 1e5)]), delimiter=",",
               header="time_s,v_bprbs,v_in,i_in", comments="")
    cfg = _cfg(netlist_dir, approach="time", drive="bridge", target={"kind": "waveforms-csv", "path": str(rec)})
    p = tmp_path / "c.json"
    p.write_text(json.dumps(cfg))
    r = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(p)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and "source" in r.stderr
