"""Fuzzing the readers and the command options: no traceback, no leaked warning, no NaN in JSON, no hang.

Every rejection is one line naming the file (netlists: file, line and column) or the option, with exit
status 2. Property-based with a fixed seed (``derandomize``) and a bounded number of examples; the long
run with at least 1000 inputs per reader is ``benchmarks/bench_fuzz.py``. The fixed corpus in
``tests/data/fuzz/`` holds the nastiest cases found.
"""

from __future__ import annotations

import random
import re
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cli import test_fuzz_cases as fc

CORPUS = Path(__file__).parents[1] / "data" / "fuzz"
FUZZ = settings(derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def fuzz(examples: int) -> settings:
    """Fixed-seed settings with ``examples`` inputs."""
    return settings(FUZZ, max_examples=examples)


SEEDS = st.integers(min_value=0, max_value=2**32 - 1)


def _path(tmp_path: Path, name: str, data: bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


# --------------------------------------------------------------------------- netlists


@fuzz(80)
@given(seed=SEEDS)
def test_fuzzed_netlists_keep_the_contract(tmp_path, seed):
    path = _path(tmp_path, f"n{seed}.cir", fc.netlist_case(random.Random(seed)))
    verdict, outcome = fc.check_netlist_cli(path)
    assert verdict in ("ok", "rejected"), (verdict, path.read_bytes()[:300], outcome.stderr, outcome.exception)


@pytest.mark.parametrize("path", sorted(CORPUS.glob("*.cir")), ids=lambda p: p.stem)
def test_netlist_corpus(path):
    verdict, outcome = fc.check_netlist_cli(path)
    expected = "ok" if path.name.startswith("good_") else "rejected"
    assert verdict == expected, (outcome.stderr, outcome.exception)
    if expected == "rejected" and path.stem not in ("bad_binary",):
        # file:line:column, or the file alone for problems of the whole file
        assert re.search(re.escape(str(path)) + r"(:\d+:\d+)?: ", outcome.stderr), outcome.stderr


@pytest.mark.parametrize("value, line, column, words", [
    ("{10", 5, 10, "unbalanced '{'"),
    ("10}", 5, 12, "unbalanced '}'"),
    ("0x10", 5, 10, "malformed number '0x10'"),
    ("10k junk", 5, 14, "unexpected 'junk'"),
    ("{R1}x", 5, 14, "unexpected 'x' after the value"),
    ("{1/0}", 5, 10, "division by zero"),
    ("1e-300", 5, 10, "outside the accepted range 1e-09 .. 1e+15 Ohm"),
    ("{2**10000}", 5, 10, "overflows"),
])
def test_strict_reading_names_line_and_column(tmp_path, value, line, column, words):
    text = (CORPUS / "good_two_section.cir").read_text().replace("R1 in a1 {R1}", f"R1 in a1 {value}")
    path = _path(tmp_path, "x.cir", text.encode())
    outcome = fc.run_cli(["frf", "--netlist", str(path), "--port", "in", "--points", "3", "--json"])
    assert fc.judge(outcome, [str(path)]) == "rejected", outcome.stderr
    assert f"{path}:{line}:{column}: " in outcome.stderr and words in outcome.stderr, outcome.stderr


# --------------------------------------------------------------------------- values and expressions


@fuzz(300)
@given(text=st.one_of(st.sampled_from(fc.NASTY_VALUES),
                      st.text(alphabet="0123456789.eE+-*/^(){} kmunpfgMEGxal1r_sqrtogpi", max_size=30),
                      st.text(max_size=12)))
def test_fuzzed_values_and_expressions(text):
    assert fc.check_value(text) in ("ok", "rejected"), text


@fuzz(60)
@given(a=st.floats(allow_nan=True, allow_infinity=True), b=st.floats(allow_nan=True, allow_infinity=True),
       op=st.sampled_from(["+", "-", "*", "/", "**"]))
def test_expression_arithmetic_is_finite_or_one_line(a, b, op):
    from pris_cosim.circuits.expressions import Expression

    verdict = fc.judge_call(lambda: float(Expression(f"{{x {op} y}}").evaluate({"x": a, "y": b})), [],
                            check=lambda v: v == v and abs(v) != float("inf"))
    assert verdict in ("ok", "rejected")


# --------------------------------------------------------------------------- measured data


@pytest.mark.parametrize("reader", sorted(fc.FILE_READERS))
def test_fuzzed_measured_files(tmp_path, reader):
    @fuzz(50)
    @given(seed=SEEDS)
    def check(seed):
        ext, data = fc.FILE_READERS[reader](random.Random(seed))
        path = _path(tmp_path, f"{reader}{seed}{ext}", data)
        verdict = fc.check_measured(path)
        assert verdict in ("ok", "rejected"), (reader, data[:300])

    check()


@fuzz(50)
@given(seed=SEEDS)
def test_fuzzed_mat_files(tmp_path, seed):
    path = fc.mat_case(random.Random(seed), tmp_path)
    assert fc.check_measured(path) in ("ok", "rejected")


@pytest.mark.parametrize("path", sorted(p for p in CORPUS.iterdir() if p.suffix != ".cir" and p.name != "README.md"),
                         ids=lambda p: p.name)
def test_measured_corpus(path):
    verdict = fc.check_measured(path)
    assert verdict == ("ok" if path.name.startswith("good_") else "rejected")


# --------------------------------------------------------------------------- command options


@fuzz(40)
@given(seed=SEEDS)
def test_fuzzed_options(tmp_path, seed):
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    try:
        from bench_fuzz import option_case, option_names
    finally:
        sys.path.pop(0)
    argv, option = option_case(random.Random(seed), tmp_path)
    outcome = fc.run_cli(argv)
    verdict = fc.judge(outcome, option_names(argv, option), json_mode="--json" in argv)
    assert verdict in ("ok", "rejected"), (argv, outcome.stderr, outcome.exception)


def test_subprocess_rejections_are_one_line(tmp_path):
    """The console entry point as scripts run it: one line, exit 2, nothing on stdout."""
    bad = CORPUS / "bad_sum_20000.cir"
    for argv, words in ((["frf", "--netlist", str(bad), "--port", "in", "--json"], f"{bad}:3:"),
                        (["frf", "--model", "two-section", "--points", "nan"], "--points")):
        proc = subprocess.run([sys.executable, "-m", "pris_cosim", *argv], capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2 and proc.stdout == ""
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and words in lines[0], proc.stderr


@pytest.mark.parametrize("argv, words", [
    (["study", "two-section", "--quick", "--cases", " ", "--json"], "--cases: empty list"),
    (["frf", "--model", "two-section", "--port", "0", "--json"], "--port '0' is ground"),
    (["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "31.8k", "--lpris", "2.53",
      "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "999", "--json"],
     "--out 999: unknown waveform format"),
    (["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "1e12", "--lpris", "2.53",
      "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "w.csv", "--json"],
     "--rpris 1e+12 Ohm is outside the accepted range"),
    (["frf", "--model", "two-section", "--points", "1" * 60, "--json"], "--points 1111"),
    (["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "31.8k", "--lpris", "2.53",
      "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "w.csv", "--probe", "0",
      "--json"], "--probe '0' is ground"),
    (["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "31.8k", "--lpris", "2.53",
      "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "w.csv", "--lsw", "1e-6",
      "--json"], "--lsw needs --csw"),
])
def test_lines_found_by_the_long_fuzz_run(argv, words):
    """Command lines the long run (benchmarks/bench_fuzz.py) found hanging or refused without the option's name."""
    outcome = fc.run_cli(argv, timeout_s=20)
    assert outcome.code == 2 and len(outcome.lines()) == 1 and words in outcome.stderr, (outcome.stderr, outcome.exception)
