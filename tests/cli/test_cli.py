"""The command line as outside scripts call it (subprocess, JSON on stdout, one-line errors)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pris_cosim.circuits import ngspice
from pris_cosim.circuits.netlist import read_netlist

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


# --------------------------------------------------------------------------- options checked before any work

_FUZZ = Path(__file__).parents[1] / "data" / "fuzz"
_SIM = ["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "31.8k", "--lpris", "2.53",
        "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "{tmp}/w.csv"]
_BASES = {
    "frf": ["frf", "--model", "two-section", "--points", "4"],
    "models": ["models"],
    "reproduce": ["reproduce", "two-section", "--out", "{tmp}/fig"],
    "simulate": _SIM,
    "build-fmu": ["build-fmu", "--model", "two-section", "--out", "{tmp}/fmu", "--with-source"],
    "lab": ["lab", "--quick", "--out", "{tmp}/lab.csv"],
    "study": ["study", "two-section", "--quick", "--out", "{tmp}/study"],
    "estimate": ["estimate", "--config", str(Path(__file__).parents[1] / "data" / "estimate" / "two_section_frequency.json")],
    "diagnose": ["diagnose", "--measured", str(_FUZZ / "good_response.csv"), "--model", "two-section"],
}
# (command, option, bad value, words the one line must hold); the option replaces its value in the base
# command, or is appended; "-" as option replaces the positional argument after the command name.
_BAD_OPTIONS = [
    ("frf", "--model", "nope", "unknown model 'nope'"),
    ("frf", "--netlist", "{tmp}/missing.cir", "--netlist: file not found"),
    ("frf", "--port", "zz", "port 'zz' is not a node"),
    ("frf", "--set", "R1=abc", "--set R1: cannot parse value"),
    ("frf", "--set", "R1=1e-300", "--set: element 'R1': resistance 1e-300 Ohm is outside the accepted range"),
    ("frf", "--config", "XXOC", "no configuration 'XXOC'"),
    ("frf", "--ratio", "zz", "--ratio and --short need --port"),
    ("frf", "--short", "zz", "--ratio and --short need --port"),
    ("frf", "--fmin", "nan", "--fmin must be a finite number"),
    ("frf", "--fmax", "-1", "--fmax -1 Hz is outside the accepted range"),
    ("frf", "--points", "nan", "argument --points: invalid int value: 'nan'"),
    ("frf", "--points", "0", "--points must be at least 1"),
    ("frf", "--method", "bogus", "argument --method: invalid choice"),
    ("frf", "--plot", "/dev/null/z.png", "--plot: /dev/null is not a directory"),
    ("models", "-", "nope", "unknown model 'nope'"),
    ("reproduce", "-", "bogus", "argument figure: invalid choice"),
    ("reproduce", "--out", "", "--out: empty directory name"),
    ("simulate", "--vdc", "-1", "--vdc must be positive"),
    ("simulate", "--fclk", "0", "--fclk 0 Hz is outside the accepted range"),
    ("simulate", "--rpris", "nan", "argument --rpris: cannot parse value 'nan'"),
    ("simulate", "--lpris", "0", "--lpris 0 H is outside the accepted range"),
    ("simulate", "--cpris", "-1", "--cpris -1 F is outside the accepted range"),
    ("simulate", "--prbs-order", "99", "--prbs-order must be one of"),
    ("simulate", "--fs", "0", "--fs 0 Hz is outside the accepted range"),
    ("simulate", "--fs", "100g", "--prbs-order 4 at --fs 1e+11 Hz and --fclk 10000 Hz makes 1.5e+08 samples"),
    ("simulate", "--periods", "0", "--periods must be from 1"),
    ("simulate", "--periods", "200000", "--periods must be from 1 to 100000"),
    ("simulate", "--out", "", "--out: empty file name"),
    ("simulate", "--engine", "x", "argument --engine: invalid choice"),
    ("simulate", "--probe", "zz", "probe 'zz' is not a node"),
    ("simulate", "--rsnub", "-1", "--rsnub must not be negative"),
    ("simulate", "--csnub", "-1", "--csnub must not be negative"),
    ("simulate", "--lsw", "-1", "--lsw must not be negative"),
    ("simulate", "--csw", "-1", "--csw must not be negative"),
    ("simulate", "--fmu-dir", "/dev/null/x", "--fmu-dir: /dev/null is not a directory"),
    ("simulate", "--config", "XX", "no configuration 'XX'"),
    ("simulate", "--model", "nope", "unknown model 'nope'"),
    ("simulate", "--netlist", "{tmp}/missing.cir", "--netlist: file not found"),
    ("simulate", "--port", "zz", "port 'zz' is not a node"),
    ("simulate", "--set", "L1=-1", "--set: element"),
    ("build-fmu", "--out", "/dev/null/x", "--out: /dev/null is not a directory"),
    ("build-fmu", "--name", " ", "--name: empty name"),
    ("build-fmu", "--fmi-version", "4", "argument --fmi-version: invalid choice"),
    ("build-fmu", "--split", "bogus", "argument --split: invalid choice"),
    ("build-fmu", "--vdc", "nan", "argument --vdc: cannot parse value 'nan'"),
    ("build-fmu", "--prbs-order", "1", "--prbs-order must be one of"),
    ("build-fmu", "--config", "XX", "no configuration 'XX'"),
    ("build-fmu", "--fclk", "-5", "--fclk -5 Hz is outside the accepted range"),
    ("build-fmu", "--rpris", "0", "--rpris 0 Ohm is outside the accepted range"),
    ("build-fmu", "--lpris", "1e9", "--lpris 1e+09 H is outside the accepted range"),
    ("build-fmu", "--cpris", "1e6", "--cpris 1e+06 F is outside the accepted range"),
    ("build-fmu", "--rsnub", "-1", "--rsnub must not be negative"),
    ("build-fmu", "--csnub", "-1", "--csnub must not be negative"),
    ("build-fmu", "--lsw", "-1", "--lsw must not be negative"),
    ("build-fmu", "--csw", "-1", "--csw must not be negative"),
    ("build-fmu", "--fmi-version", "5", "argument --fmi-version: invalid choice"),
    ("build-fmu", "--model", "nope", "unknown model 'nope'"),
    ("build-fmu", "--netlist", str(_FUZZ / "bad_hex.cir"), "bad_hex.cir:5:10: element 'R1': malformed number '0x10'"),
    ("build-fmu", "--port", "zz", "port 'zz' is not a node"),
    ("build-fmu", "--set", "K12=1", "--set: element 'K12'"),
    ("lab", "--out", "", "--out: empty file name"),
    ("lab", "--out", "{tmp}/no/dir/x.csv", "--out: directory"),
    ("lab", "--seed", "-1", "--seed must be an integer from 0"),
    ("lab", "--configs", "XX", "--configs: unknown configuration 'XX'"),
    ("lab", "--plots", "/dev/null/x", "--plots: /dev/null is not a directory"),
    ("lab", "--model", "two-section", "not a two-winding model"),
    ("lab", "--netlist", "{tmp}/missing.cir", "--netlist: file not found"),
    ("study", "-", "bogus", "unknown study 'bogus'"),
    ("study", "--seed", "-1", "--seed must be an integer from 0"),
    ("study", "--workers", "0", "--workers must be from 1"),
    ("study", "--scheduler", "bogus", "--scheduler must be"),
    ("study", "--out", "/dev/null/x", "--out: /dev/null is not a directory"),
    ("study", "--measured", "{tmp}/missing.csv", "--measured: file not found"),
    ("study", "--cases", "9", "--cases: unknown case '9'"),
    ("study", "--seeds", "100000", "--seeds 100000 makes 2400000 optimisation runs"),
    ("study", "--snr-db", "abc", "apply to the three-section study only"),
    ("study", "--optimisers", "xx", "apply to the three-section study only"),
    ("estimate", "--config", "{tmp}/missing.json", "--config: file not found"),
    ("estimate", "--workers", "0", "--workers must be from 1"),
    ("estimate", "--scheduler", "bogus", "--scheduler must be"),
    ("estimate", "--out", "/dev/null/x", "--out: /dev/null is not a directory"),
    ("diagnose", "--measured", "{tmp}/missing.csv", "--measured: file not found"),
    ("diagnose", "--measured", str(_FUZZ / "bad_nan_magnitude.csv"), "bad_nan_magnitude.csv:"),
    ("diagnose", "--segment", "open", "cannot select segment 'open'"),
    ("diagnose", "--model", "nope", "unknown model 'nope'"),
    ("diagnose", "--netlist", "{tmp}/missing.cir", "--netlist: file not found"),
    ("diagnose", "--port", "in", "--port applies to a --netlist baseline only"),
    ("diagnose", "--rpris", "nan", "argument --rpris: cannot parse value 'nan'"),
    ("diagnose", "--tolerance", "-1", "--tolerance must be a positive number or inf, got '-1'"),
    ("diagnose", "--source-tolerance", "-1", "argument --source-tolerance"),
    ("diagnose", "--lpris", "-1", "--lpris -1 H is outside the accepted range"),
    ("diagnose", "--cpris", "0", "--cpris 0 F is outside the accepted range"),
    ("diagnose", "--rload", "-1", "--rload -1 Ohm is outside the accepted range"),
    ("diagnose", "--report", "/dev/null/x", "--report: /dev/null is not a directory"),
    ("diagnose", "--reference", "{tmp}/missing.s2p", "--reference: file not found"),
    ("diagnose", "--repeat", "{tmp}/missing.s2p", "--repeat: file not found"),
    ("diagnose", "--sections", "0", "--sections must be 1..40"),
    ("diagnose", "--cache", "/dev/null/x", "--cache: /dev/null is not a directory"),
    ("diagnose", "--model-out", "/dev/null/x.s2p", "--model-out: /dev/null is not a directory"),
]


def _argv(command: str, option: str, value: str, tmp: Path) -> list[str]:
    argv = list(_BASES[command])
    if option == "-":
        argv.insert(1, value) if command == "models" else argv.__setitem__(1, value)
    elif option in argv:
        argv[argv.index(option) + 1] = value
    elif option == "--netlist" and "--model" in argv:
        i = argv.index("--model")
        argv[i:i + 2] = ["--netlist", value]
    else:
        argv += [option, value]
    return [a.replace("{tmp}", str(tmp)) for a in argv]


def test_every_command_has_a_bad_value_row():
    from pris_cosim.cli.commands import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert set(sub.choices) == set(_BASES)
    for command, parser in sub.choices.items():
        options = {s for a in parser._actions for s in a.option_strings if s.startswith("--")}
        options -= {"--help", "--json", "--quick", "--no-noise", "--with-source", "--diagnose", "--quiet", "--no-cache",
                    "--ssp", "--no-model"}  # flags; --ssp without --with-source: tests/fmi/test_ssp.py
        tried = {o for c, o, _, _ in _BAD_OPTIONS if c == command}
        assert options <= tried, (command, sorted(options - tried))


@pytest.mark.parametrize("command, option, value, words", _BAD_OPTIONS,
                         ids=[f"{c} {o} {v[:20]}" for c, o, v, _ in _BAD_OPTIONS])
def test_bad_option_value_is_one_line_before_any_work(tmp_path, command, option, value, words):
    from cli import test_fuzz_cases as fc

    argv = _argv(command, option, value, tmp_path)
    outcome = fc.run_cli(argv + ["--json"] if command not in ("estimate",) else argv, timeout_s=20)
    assert fc.judge(outcome) == "rejected", (argv, outcome.stderr, outcome.exception)
    assert words.replace("{tmp}", str(tmp_path)) in outcome.stderr, outcome.stderr
    assert not any(p.name not in ("missing.cir",) for p in tmp_path.iterdir()), "something was written"
