"""The command line as outside scripts call it (subprocess, JSON on stdout, one-line errors)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from pris_cosim import ngspice
from pris_cosim.netlist import read_netlist

from conftest import needs_ngspice


def run(*args, check=True):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", *args], capture_output=True, text=True, timeout=120)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


def complex_of(resp):
    return np.array(resp["re"]) + 1j * np.array(resp["im"])


@needs_ngspice
def test_frf_netlist_json_matches_ngspice(netlist_dir):
    path = netlist_dir / "two_section_table4_2.cir"
    out = json.loads(run("frf", "--netlist", str(path), "--port", "in", "--ratio", "mid", "--fmin", "10",
                         "--fmax", "1e5", "--points", "41", "--json").stdout)
    f = np.array(out["frequency_hz"])
    assert f.size == 41 and f[0] == pytest.approx(10) and f[-1] == pytest.approx(1e5)
    fs, v = ngspice.ac_analysis(read_netlist(path), "in", ["in", "mid"], 10, 1e5, points_per_decade=10)
    np.testing.assert_allclose(fs, f, rtol=1e-12)
    z = complex_of(out["responses"]["Zin"])
    assert np.max(np.abs(z - v[0]) / np.abs(v[0])) < 1e-6
    r = complex_of(out["responses"]["V_mid"])
    assert np.max(np.abs(r - v[1] / v[0]) / np.abs(v[1] / v[0])) < 1e-6
    assert out["passive"] is True


@needs_ngspice
def test_frf_model_config_matches_ngspice_with_short(netlist_dir):
    out = json.loads(run("frf", "--model", "hv-4section", "--config", "LVSC,HVLV", "--fmin", "10", "--fmax", "1e6",
                         "--points", "51", "--json").stdout)
    assert set(out["responses"]) == {"Zlvsc", "Rhvlv"}
    ref = read_netlist(netlist_dir / "hv_transformer_4section_table5_4.cir")
    _, v = ngspice.ac_analysis(ref.shorted(["b1"]), "a1", ["a1"], 10, 1e6, points_per_decade=10)
    z = complex_of(out["responses"]["Zlvsc"])
    assert np.max(np.abs(z - v[0]) / np.abs(v[0])) < 1e-6
    _, v = ngspice.ac_analysis(ref, "b1", ["b1", "a1"], 10, 1e6, points_per_decade=10)
    r = complex_of(out["responses"]["Rhvlv"])
    assert np.max(np.abs(r - v[1] / v[0]) / np.abs(v[1] / v[0])) < 1e-6


def test_frf_non_passive_warns_on_stderr_and_reports():
    proc = run("frf", "--model", "hv-6section", "--config", "HVOC", "--points", "5", "--json")
    out = json.loads(proc.stdout)
    assert out["passive"] is False
    assert out["smallest_inductance_eigenvalue_h"] == pytest.approx(-0.314, abs=0.005)
    assert "not passive" in proc.stderr and "-0.314" in proc.stderr


def test_frf_set_override_changes_result():
    a = json.loads(run("frf", "--model", "two-section", "--points", "3", "--json").stdout)
    b = json.loads(run("frf", "--model", "two-section", "--set", "C2=2n", "--points", "3", "--json").stdout)
    assert set(a["responses"]) == {"Zin", "R1in", "R2in"}
    assert a["responses"]["Zin"]["re"] != b["responses"]["Zin"]["re"]


def test_models_listing():
    out = json.loads(run("models", "--json").stdout)
    names = {m["name"] for m in out["models"]}
    assert {"two-section", "three-section", "hv-4section", "hv-6section", "hv-4section-cab2a"} <= names
    hv6 = next(m for m in out["models"] if m["name"] == "hv-6section")
    assert hv6["passive"] is False
    assert set(hv6["configurations"]) == {"LVOC", "LVSC", "HVOC", "HVSC", "LVHV", "HVLV"}
    assert "Lc" in hv6["fixed"]


@pytest.mark.parametrize("args, words", [
    (["frf", "--model", "nope"], "unknown model 'nope'"),
    (["frf", "--model", "two-section", "--port", "zz"], "port 'zz' is not a node"),
    (["frf", "--model", "two-section", "--set", "R1=abc"], "--set R1: cannot parse value"),
    (["frf", "--model", "two-section", "--set", "M12=40"], "outside the accepted range -1 < k < 1"),
    (["frf", "--model", "hv-4section", "--set", "Ka1b1=1.2"], "element 'Ka1b1'"),
    (["frf", "--model", "hv-4section", "--config", "XXOC"], "no configuration 'XXOC'"),
    (["frf", "--model", "three-section", "--fmin", "0"], "fmin"),
])
def test_bad_input_one_line_error(args, words, tmp_path):
    plot = tmp_path / "p.png"
    proc = run(*args, "--plot", str(plot), check=False)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], proc.stderr
    assert proc.stdout == ""
    assert not plot.exists()


def test_bad_netlist_and_missing_port(tmp_path):
    bad = tmp_path / "bad.cir"
    bad.write_text("* t\nR1 a 0 1.2.3\nC1 a 0 1n\n")
    proc = run("frf", "--netlist", str(bad), "--port", "a", check=False)
    assert proc.returncode != 0 and "bad.cir:2" in proc.stderr
    good = tmp_path / "good.cir"
    good.write_text("* t\nR1 a 0 10\nC1 a 0 1n\n")
    proc = run("frf", "--netlist", str(good), check=False)
    assert proc.returncode != 0 and "missing --port" in proc.stderr


def test_plot_written(tmp_path):
    plot = tmp_path / "z.png"
    run("frf", "--model", "three-section", "--points", "50", "--plot", str(plot))
    assert plot.stat().st_size > 10_000
