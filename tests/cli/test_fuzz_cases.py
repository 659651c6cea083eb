"""Fuzz inputs and the judge of outcomes, shared by the fuzz tests and ``benchmarks/bench_fuzz.py`` (no tests here).

Every generator takes a :class:`random.Random` and returns the bytes of one
input file (or an argument list), mutated from a valid seed: deleted,
duplicated and swapped lines, nasty values, unbalanced braces, binary
garbage, unicode, huge lines. :func:`run_cli` runs the command line in this
process and :func:`judge` classifies what happened against the contract:

- ``"ok"``: exit 0, with ``--json`` exactly one strict JSON object (no NaN
  or Infinity) on stdout, no numerical warning on stderr;
- ``"rejected"``: exit 2 with exactly one line on stderr naming the file
  (or the option), nothing on stdout;
- anything else is a failure, named by the first problem found
  (``"traceback"``, ``"exit N"``, ``"lines N"``, ``"unnamed"``,
  ``"warning"``, ``"nan-json"``, ``"bad-json"``, ``"hang"``).
"""

from __future__ import annotations

import contextlib
import io
import json
import random
import signal
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

# --------------------------------------------------------------------------- running and judging


class _Hang(BaseException):
    """Raised by the alarm when a command runs past its time limit."""


@dataclass
class Outcome:
    """What one command-line run did."""

    code: Any
    stdout: str
    stderr: str
    exception: str = ""

    def lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]


def run_cli(argv: Sequence[str], timeout_s: float = 30.0) -> Outcome:
    """Run ``pris-cosim argv`` in this process with a time limit; never raises."""
    from pris_cosim.cli.commands import main

    out, err = io.StringIO(), io.StringIO()

    def alarm(signum: int, frame: Any) -> None:
        raise _Hang()

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout_s)
    exception = ""
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("default")  # as a user's interpreter: a warning is a printed line
            try:
                code: Any = main(list(argv))
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
                if not isinstance(exc.code, int) and exc.code is not None:
                    err.write(str(exc.code) + "\n")
    except _Hang:
        code, exception = "hang", "hang"
    except BaseException as exc:  # noqa: BLE001 - anything escaping main is a failure to report
        code, exception = "traceback", f"{type(exc).__name__}: {exc}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    return Outcome(code, out.getvalue(), err.getvalue(), exception)


def _strict_json(text: str) -> Any:
    def refuse(name: str) -> Any:
        raise ValueError(f"non-finite number {name} in JSON")

    return json.loads(text, parse_constant=refuse)


def judge(outcome: Outcome, names: Sequence[str] = (), json_mode: bool = True) -> str:
    """Classify an outcome: ``"ok"``, ``"rejected"`` or the name of a failure.

    Parameters
    ----------
    outcome : Outcome
    names : sequence of str
        A rejection must mention one of these (the input file, or the option).
    json_mode : bool
        The command ran with ``--json``: stdout must hold exactly one object.
    """
    if outcome.code in ("hang", "traceback"):
        return str(outcome.code)
    lines = outcome.lines()
    if any("Traceback" in line for line in lines):
        return "traceback"
    if outcome.code == 0:
        if any("encountered" in line or "RuntimeWarning" in line for line in lines):
            return "warning"
        if json_mode:
            try:
                obj = _strict_json(outcome.stdout)
            except ValueError as exc:
                return "nan-json" if "non-finite" in str(exc) else "bad-json"
            if not isinstance(obj, dict) or outcome.stdout.count("\n") != 1:
                return "bad-json"
        return "ok"
    if outcome.code == 2:
        if len(lines) != 1:
            return f"lines {len(lines)}"
        if outcome.stdout.strip():
            return "stdout on error"
        if names and not any(n in lines[0] for n in names):
            return "unnamed"
        return "rejected"
    return f"exit {outcome.code}"


def judge_call(fn: Callable[[], Any], names: Sequence[str], error: type = ValueError,
               check: Callable[[Any], bool] | None = None) -> str:
    """Classify a reader call: ``"ok"`` (result passes ``check``), ``"rejected"`` (``error`` with one line
    naming one of ``names``), or a failure (``"traceback"``, ``"warning"``, ``"unnamed"``, ``"nan"``,
    ``"lines"``, ``"hang"``)."""
    def alarm(signum: int, frame: Any) -> None:
        raise _Hang()

    previous = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, 20.0)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                result = fn()
            except error as exc:
                if caught:
                    return "warning"
                text = str(exc)
                if "\n" in text.strip() or not text.strip():
                    return "lines"
                if names and not any(n in text for n in names):
                    return "unnamed"
                return "rejected"
            except _Hang:
                return "hang"
            except Exception:  # noqa: BLE001
                return "traceback"
            if caught:
                return "warning"
            if check is not None and not check(result):
                return "nan"
            return "ok"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


@dataclass
class Tally:
    """Counts of outcomes, with one example input per failure kind."""

    counts: dict[str, int] = field(default_factory=dict)
    examples: dict[str, str] = field(default_factory=dict)

    def add(self, verdict: str, example: str = "") -> None:
        self.counts[verdict] = self.counts.get(verdict, 0) + 1
        if verdict not in ("ok", "rejected"):
            self.examples.setdefault(verdict, example[:300])

    @property
    def failures(self) -> int:
        return sum(n for k, n in self.counts.items() if k not in ("ok", "rejected"))

    @property
    def total(self) -> int:
        return sum(self.counts.values())


# --------------------------------------------------------------------------- values

NASTY_VALUES = [
    "0", "-10", "1e308", "1e-320", "1e-300", "{1/0}", "{2**10000}", "{10.0**400}", "{9**9**9}",
    "{" + "+".join(["1"] * 20000) + "}", "{" + "+".join(["1"] * 300) + "}", "{sqrt(-1)}", "nan", "inf", "-inf",
    "1e400", "0x10", "{0x10}", "{10", "10}", "{1}0", "10k5", "1..2", "{}", "{ }", "{zz}", "1meg", "1MEGohm",
    "{(-8)**(1/3)}", "{log(0)}", "{exp(1e3)}", "1e-9", "1e15", "1e16", "{1e308*10}", "10$", "\u0663", "1_000", "1j",
    "{__import__('os')}", "{a.b}", "'10'", "{" + "(" * 500 + "1" + ")" * 500 + "}", "1" * 5000, "0.", ".", "-",
    "+1", "--1", "1e", "e3", "{-" + "-" * 5000 + "1}", "1e-18", "1e-19", "{1/3}", "{pi}", "{L1*2}", "{r1}", "10nF",
    "1mil", "4.7K", "\u00b5", "1\u00a0k", "{1e-320}", "{2^0.5}", "{0**-1}", "{abs(-3)}", "{log10(1e300)}",
]
NASTY_NUMBERS = [
    "nan", "NaN", "inf", "-inf", "1e400", "-1e400", "1e-320", "1e308", "-1e308", "0", "-0", "-1", "1e-30", "1e30",
    "", " ", "abc", "0x10", "1,5", "1.2.3", "+-1", "1e", "\u0663", "\x00", "9" * 400, "1e-400", "2.5e-3", "3",
]
BAD_LINES = [
    "Q1 a b c model", "K9 L1 Lx 0.5", "K9 L1 L1 0.5", "K9 L1 L2 1.5", "K9 R1 L2 0.5", "V9 in 0 DC 5",
    "V9 in 0 DC 1e20", "V8 in 0 0", "I9 mid 0 1", "R9 float1 float2 10", "C9 isl 0 1n", "C10 isl in 1n",
    "L9 in 0 1m", "L10 in 0 1m", ".param L1=0", ".param L1=-10", ".param pa={pb} pb={pa}", ".param q=",
    ".param = 3", ".subckt x a b", ".include foo.lib", "+ 10", "*@ port zz", "*@ bogus", "R9 in", "R9", "=",
    "{", "}", ".control", ".endc", "R9 in 0 10 m=2", "R9 in 0 10 tc1=0.1", "R9 in 0 10 junk", "R9 in 0 {1} 2",
    "R9 = 0 10", "R9 in {x} 10", ".end", "R9 in 0 10 ; comment", "* comment", "R\u00b5 in 0 10", "\t\t",
    "R9 in 0 " + "1" * 100000, "x" * 200000,
]

NETLIST_SEEDS = [
    """* two-section winding (thesis Table 4.2)
*@ port in
.param R1=10 R2=10 C1=1n C2=1n L1=10 L2=100 M12=30
C1 in mid {C1}
R1 in a1 {R1}
L1 a1 mid {L1}
C2 mid 0 {C2}
R2 mid a2 {R2}
L2 a2 0 {L2}
K12 L1 L2 {M12/sqrt(L1*L2)}
.end
""",
    """* RC ladder with continuation lines
*@ port in
R1 in n1 100
C1 n1 0
+ 1u
R2 n1 n2 100 ; second section
C2 n2 0 1u
R3 n2 0 1k
""",
    """* coupled coils with a source
*@ port in
.param k=0.5
V1 src 0 DC 0 AC 1
R0 src in 50
L1 in 0 1m
L2 out 0 4m
R2 out 0 100
K1 L1 L2 {k}
C1 in 0 1n
""",
]


def _lines_mutation(rng: random.Random, lines: list[str]) -> list[str]:
    op = rng.randrange(9)
    i = rng.randrange(len(lines)) if lines else 0
    if op == 0 and lines:
        del lines[i]
    elif op == 1 and lines:
        lines.insert(i, lines[i])
    elif op == 2 and len(lines) > 1:
        j = rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    elif op == 3:
        lines.insert(i, rng.choice(BAD_LINES))
    elif op == 4 and lines:
        line = lines[i]
        if line:
            k = rng.randrange(len(line))
            lines[i] = line[:k] + rng.choice(["{", "}", "=", " ", "\t", "0x", "e", "..", "\u00e9", "\ufffd", "*",
                                              ";", "+", "-", "$", "(", ")", "'"]) + line[k + 1:]
    elif op == 5 and lines:
        lines[i] = lines[i][: rng.randrange(len(lines[i]) + 1)]
    elif op == 6:
        lines.insert(i, "".join(chr(rng.randrange(32, 0x2FFF)) for _ in range(rng.randrange(1, 40))))
    else:
        # replace the last word of a line (element values, .param values) by a nasty value
        cand = [k for k, line in enumerate(lines) if line and not line.startswith(("*", "."))]
        if cand:
            k = rng.choice(cand)
            words = lines[k].split()
            words[-1] = rng.choice(NASTY_VALUES)
            lines[k] = " ".join(words)
    return lines


def netlist_case(rng: random.Random) -> bytes:
    """A mutated netlist, as bytes."""
    lines = rng.choice(NETLIST_SEEDS).splitlines()
    for _ in range(rng.randint(1, 3)):
        lines = _lines_mutation(rng, lines)
    data = ("\r\n" if rng.random() < 0.1 else "\n").join(lines).encode("utf-8", "surrogatepass")
    return _bytes_mutation(rng, data) if rng.random() < 0.15 else data


def _bytes_mutation(rng: random.Random, data: bytes) -> bytes:
    op = rng.randrange(5)
    k = rng.randrange(len(data) + 1)
    if op == 0:
        return data[:k]
    if op == 1:
        return data[:k] + bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64))) + data[k:]
    if op == 2:
        return data[:k] + b"\x00" + data[k:]
    if op == 3:
        return b"\xef\xbb\xbf" + data
    return b"\xff\xfe" + data.decode("utf-8", "replace").encode("utf-16-le")


# --------------------------------------------------------------------------- measured data files


def _number_text(rng: random.Random, x: float) -> str:
    return repr(x) if rng.random() < 0.8 else f"{x:+.11e}"


def _rows(rng: random.Random, n: int, columns: Callable[[float], list[float]], f0: float = 10.0,
          step: float = 1.5) -> list[list[str]]:
    out, f = [], f0
    for _ in range(n):
        out.append([repr(f)] + [_number_text(rng, v) for v in columns(f)])
        f *= step
    return out


def _mutate_rows(rng: random.Random, rows: list[list[str]]) -> list[list[str]]:
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(8)
        if not rows:
            break
        i = rng.randrange(len(rows))
        if op <= 2:
            j = rng.randrange(len(rows[i]))
            rows[i][j] = rng.choice(NASTY_NUMBERS)
        elif op == 3:
            del rows[i]
        elif op == 4:
            rows.insert(i, list(rows[i]))
        elif op == 5:
            rows[i] = rows[i][:-1] if rng.random() < 0.5 else rows[i] + ["1"]
        elif op == 6:
            scale = rng.choice(["1e-300", "1e300", "1e-30", "1e30", "0"])
            for row in rows:
                j = rng.randrange(len(row))
                row[j] = scale
        else:
            j = rng.randrange(len(rows))
            rows[i], rows[j] = rows[j], rows[i]
    return rows


def response_csv_case(rng: random.Random) -> tuple[str, bytes]:
    header = rng.choice(["frequency_hz,Zin_mag,Zin_phase_deg", "frequency_hz,Zin_re,Zin_im,V_mid_mag,V_mid_phase_deg",
                         "frequency_hz,Zin_mag", "frequency_hz,Zin_mag,Zin_phase_deg,Zin_re",
                         "frequency_hz,Zlvoc_mag,Zlvoc_phase_deg"])
    ncol = header.count(",")
    rows = _rows(rng, rng.randint(1, 12), lambda f: [100.0 / (1 + f / 1e3), 45.0, 1.0, 0.5][:ncol])
    rows = _mutate_rows(rng, rows) if rng.random() < 0.85 else rows
    lines = ["# fuzz response"] + [header] + [",".join(r) for r in rows]
    if rng.random() < 0.2:
        lines = _lines_mutation(rng, lines)
    data = "\n".join(lines).encode()
    return ".csv", _bytes_mutation(rng, data) if rng.random() < 0.1 else data


def multisegment_case(rng: random.Random) -> tuple[str, bytes]:
    lines = ["FREQUENCY [Hz],MAG [O],PHASE [deg]"]
    for label in rng.sample(["1/(j*w*.2e-12)     # .2 pF load (open)", "0 # short", "50 # load"], rng.randint(1, 3)):
        lines.append(f"<segment> {label}")
        lines += [",".join(r) for r in _mutate_rows(rng, _rows(rng, rng.randint(1, 6), lambda f: [40.0, 87.0],
                                                                f0=1e4))]
    if rng.random() < 0.3:
        lines = _lines_mutation(rng, lines)
    return ".csv", "\n".join(lines).encode()


def waveform_case(rng: random.Random) -> tuple[str, bytes]:
    header = rng.choice(["time_s,v_bprbs,v_in,i_in", "time_s,v_bprbs,v_in,i_in,v_out", "time_s,v_in,i_in"])
    ncol = header.count(",")
    dt = rng.choice([1e-6, 1e-6, 1e-12, 1e3, 1e-300, 1e300])
    rows = [[repr(k * dt)] + [_number_text(rng, v) for v in [30.0 * (-1) ** k, 1.0, 1e-3, 0.5][:ncol]]
            for k in range(rng.randint(1, 16))]
    rows = _mutate_rows(rng, rows) if rng.random() < 0.85 else rows
    lines = [header] + [",".join(r) for r in rows]
    if rng.random() < 0.2:
        lines = _lines_mutation(rng, lines)
    return ".csv", "\n".join(lines).encode()


def touchstone_case(rng: random.Random) -> tuple[str, bytes]:
    option = rng.choice(["# Hz Z RI R 50", "# kHz Z MA R 50", "# Hz S DB R 50", "# Hz Y RI R 1", "# GHz Z RI R 0",
                         "# Hz Z RI R -50", "# Hz Q RI R 50", ""])
    rows = _rows(rng, rng.randint(1, 8), lambda f: [10.0, 5.0])
    rows = _mutate_rows(rng, rows) if rng.random() < 0.85 else rows
    lines = ["! fuzz touchstone", option] + [" ".join(r) for r in rows]
    if rng.random() < 0.2:
        lines = _lines_mutation(rng, lines)
    return ".s1p", "\n".join(lines).encode()


def e4990a_case(rng: random.Random) -> tuple[str, bytes]:
    columns = rng.choice(["Frequency(Hz), R(Ohm)-data, X(Ohm)-data", "Frequency(Hz), |Z|(Ohm)-data, theta-z(deg)-data",
                          "Frequency(kHz), |Y|(S)-data, theta-y(rad)-data", "Frequency(Hz), G(S)-data, B(S)-data",
                          "Frequency(Hz), Q-data, D-data"])
    rows = _rows(rng, rng.randint(1, 8), lambda f: [0.1, 1.2], f0=20.0)
    rows = _mutate_rows(rng, rows) if rng.random() < 0.85 else rows
    lines = ["!Agilent Technologies,E4990A,FUZZ,A.02.12", "!Date: fuzz", "", "BEGIN CH1_DATA", columns]
    lines += [", ".join(r) for r in rows] + ["END"]
    if rng.random() < 0.3:
        lines = _lines_mutation(rng, lines)
    return ".csv", "\n".join(lines).encode()


def mag_phase_rows_case(rng: random.Random) -> tuple[str, bytes]:
    rows = [[_number_text(rng, 1e-3 * (k + 1)), _number_text(rng, 80.0)] for k in range(rng.randint(1, 10))]
    rows = _mutate_rows(rng, rows) if rng.random() < 0.85 else rows
    return ".txt", "\n".join(" " + "  ".join(r) for r in rows).encode()


def mat_case(rng: random.Random, directory: Path) -> Path:
    """A mutated MATLAB file written into ``directory``."""
    import numpy as np
    import scipy.io

    path = directory / f"fuzz{rng.randrange(10**9)}.mat"
    if rng.random() < 0.15:
        path.write_bytes(rng.choice([b"frequency_hz,Zin_mag\n1,2\n", b"", b"MATLAB 5.0 MAT-file" + b"\x00" * 20,
                                     bytes(rng.randrange(256) for _ in range(200))]))
        return path
    n = rng.randint(1, 8)
    f = 10.0 * 1.5 ** np.arange(n)
    variables: dict[str, Any] = {"frequency_hz" if rng.random() < 0.8 else "f": f}
    style = rng.randrange(3)
    if style == 0:
        variables["Zin"] = (100.0 + 10j * f)
    elif style == 1:
        variables["Zin_mag"], variables["Zin_phase_deg"] = 100.0 * np.ones(n), 45.0 * np.ones(n)
    else:
        variables["Zin_re"], variables["Zin_im"] = np.ones(n), f
    for _ in range(rng.randint(1, 3)):
        if not variables:
            break
        key = rng.choice(list(variables))
        op = rng.randrange(7)
        a = np.atleast_1d(np.array(variables[key]))
        if op == 0 and a.size and a.dtype.kind in "fc":
            a.flat[rng.randrange(a.size)] = rng.choice([np.nan, np.inf, -1.0, 0.0, 1e-320, 1e308, -np.inf])
        elif op == 1:
            a = a[: rng.randrange(a.size + 1)]
        elif op == 2:
            a = a.reshape(1, -1) if rng.random() < 0.5 else np.stack([a, a])
        elif op == 3:
            a = np.array("text")
        elif op == 4:
            a = a[::-1]
        elif op == 5:
            del variables[key]
            continue
        else:
            variables[rng.choice(["comments", "segment", "x"])] = rng.choice([np.array(["a", "b"]), np.eye(3), "seg"])
            continue
        variables[key] = a
    try:
        scipy.io.savemat(path, variables)
    except Exception:  # noqa: BLE001 - an unsavable mutation: keep a plain valid file instead
        scipy.io.savemat(path, {"frequency_hz": f, "Zin": 100.0 + 10j * f})
    if rng.random() < 0.1:
        data = path.read_bytes()
        path.write_bytes(data[: rng.randrange(len(data) + 1)])
    return path


FILE_READERS: dict[str, Callable[[random.Random], tuple[str, bytes]]] = {
    "response-csv": response_csv_case,
    "multisegment-csv": multisegment_case,
    "waveform-csv": waveform_case,
    "touchstone": touchstone_case,
    "e4990a": e4990a_case,
    "mag-phase-rows": mag_phase_rows_case,
}


def finite_result(result: Any) -> bool:
    """True when every array of a reader's result is finite."""
    import numpy as np

    arrays = []
    if hasattr(result, "responses"):
        arrays = [result.frequency_hz, *result.responses.values()]
    elif hasattr(result, "time_s"):
        arrays = [getattr(result, k) for k in ("time_s", "v_bprbs", "v_in", "i_in", "v_out")
                  if getattr(result, k, None) is not None]
    return all(np.all(np.isfinite(np.asarray(a))) for a in arrays)


def check_measured(path: Path) -> str:
    """Verdict of reading one measured-data file through the public reader."""
    from pris_cosim.measured.formats import load_measured

    return judge_call(lambda: load_measured(path), [str(path)], check=finite_result)


def check_netlist_cli(path: Path) -> tuple[str, Outcome]:
    """Verdict of ``frf --netlist PATH --port in --points 4 --json``."""
    outcome = run_cli(["frf", "--netlist", str(path), "--port", "in", "--points", "4", "--json"])
    return judge(outcome, [str(path), "--port"]), outcome


def check_value(text: str) -> str:
    """Verdict of parsing a value as a number and as an expression (finite float or one-line ValueError)."""
    import math

    from pris_cosim.circuits.expressions import Expression
    from pris_cosim.units import parse_value

    def both() -> float:
        try:
            x = parse_value(text)
        except ValueError:
            x = float(Expression(text).evaluate({"a": 2.0, "l1": 1e-3, "r1": 10.0}))
        return x

    return judge_call(both, [], check=lambda x: isinstance(x, float) and math.isfinite(x))


# --------------------------------------------------------------------------- command options

BAD_OPTION_VALUES = ["nan", "inf", "-inf", "-1", "0", "1e400", "", " ", "abc", "0x10", "1e12", "99999999999999999999",
                     "/nonexistent/dir/x", "/dev/null/x", "-", "--json", "\u00b5", "1" * 400]

#: Cheap valid commands, and options whose values the fuzzer replaces (one at a time).
OPTION_FUZZ: list[tuple[list[str], list[str]]] = [
    (["frf", "--model", "two-section", "--points", "4", "--json"],
     ["--fmin", "--fmax", "--points", "--port", "--set", "--config", "--ratio", "--short", "--method", "--model"]),
    (["models", "--json"], ["models"]),
    (["simulate", "--model", "two-section", "--vdc", "30", "--fclk", "10k", "--rpris", "31.8k", "--lpris", "2.53",
      "--cpris", "10n", "--prbs-order", "4", "--fs", "100k", "--periods", "1", "--out", "{tmp}/w.csv", "--json"],
     ["--vdc", "--fclk", "--rpris", "--lpris", "--cpris", "--prbs-order", "--fs", "--periods", "--out", "--probe",
      "--rsnub", "--csnub", "--lsw", "--csw", "--engine", "--config"]),
]
