"""Checks of command-line options made before a command starts any work.

:func:`check_options` looks at the parsed options of any command (those of
the plug-in commands too) by their destination names and refuses, with one
line naming the option, values out of range, missing input files, output
paths that cannot be written, and requests whose size would exhaust memory
or run for hours. The commands' own checks stay in place; these run first so
that nothing is computed, started or written before a bad value is seen.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import Any

#: Samples in one PRBS period (``(2**order - 1) * fs / fclk``) above which a request is refused.
MAX_PERIOD_SAMPLES = 5e7
#: Samples in a whole record (periods times one period) above which a request is refused.
MAX_RECORD_SAMPLES = 2e8
#: Most PRBS periods in one record.
MAX_PERIODS = 100_000
#: Most local worker processes.
MAX_WORKERS = 256
#: Largest PRIS source resistance, Ohm: above it the source's conductance is lost against the
#: winding's in the exact state-space reduction (the network looks open).
MAX_SOURCE_RESISTANCE = 1e11
#: Most frequency points of one request (``--points``).
MAX_POINTS = 1_000_000
#: Most bytes the dense state-space form of a circuit may take (time-domain engines, FMUs, fits).
MAX_DENSE_BYTES = 2 * 2**30
#: Most optimisation runs one study may schedule.
MAX_STUDY_RUNS = 20_000
#: Frequency options accepted, Hz.
FREQUENCY_RANGE = (1e-6, 1e12)
#: Sampling rate accepted, Hz.
SAMPLING_RANGE = (1.0, 1e11)


class OptionError(ValueError):
    """A command-line option has a bad value (the message names the option)."""


def _flag(dest: str) -> str:
    return "--" + dest.replace("_", "-")


def _finite(dest: str, value: float, low: float | None = None, high: float | None = None,
            unit: str = "", positive: bool = False, nonnegative: bool = False) -> None:
    flag = _flag(dest)
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise OptionError(f"{flag} must be a finite number (got {value!r})")
    if positive and not value > 0:
        raise OptionError(f"{flag} must be positive (got {value:g}{unit})")
    if nonnegative and value < 0:
        raise OptionError(f"{flag} must not be negative (got {value:g}{unit})")
    if low is not None and value < low or high is not None and value > high:
        raise OptionError(f"{flag} {value:g}{unit} is outside the accepted range {low:g} .. {high:g}{unit}")


def _checked_path(check: Any) -> Any:
    """Turn an OSError of a path check (name too long, permission) into a one-line OptionError."""
    def wrapper(flag: str, value: str, *args: Any, **kwargs: Any) -> None:
        try:
            if value and any(len(part.encode("utf-8", "surrogateescape")) > 255 for part in Path(value).parts):
                raise OptionError(f"{flag}: a name in {value[:60]!r}... is longer than 255 bytes")
            check(flag, value, *args, **kwargs)
        except OSError as exc:
            raise OptionError(f"{flag}: {exc.strerror or exc}: {value[:200]}") from None
    return wrapper


@_checked_path
def _input_file(flag: str, value: str) -> None:
    if not value:
        raise OptionError(f"{flag}: empty file name")
    p = Path(value)
    if not p.exists():
        raise OptionError(f"{flag}: file not found: {value}")
    if p.is_dir():
        raise OptionError(f"{flag}: {value} is a directory, not a file")
    if not os.access(p, os.R_OK):
        raise OptionError(f"{flag}: file {value} is not readable")


def _existing_ancestor(p: Path) -> Path:
    q = p.absolute()
    while not q.exists() and q != q.parent:
        q = q.parent
    return q


@_checked_path
def _output_file(flag: str, value: str, parent_must_exist: bool = False) -> None:
    if not value or not value.strip():
        raise OptionError(f"{flag}: empty file name")
    p = Path(value)
    if value.endswith(("/", os.sep)) or p.is_dir():
        raise OptionError(f"{flag}: {value} is a directory; give a file name")
    if p.exists() and not os.access(p, os.W_OK):
        raise OptionError(f"{flag}: file {value} is not writable")
    parent = p.absolute().parent
    if parent_must_exist and not parent.is_dir():
        raise OptionError(f"{flag}: directory {parent} does not exist")
    base = _existing_ancestor(parent)
    if not base.is_dir():
        raise OptionError(f"{flag}: {base} is not a directory")
    if not os.access(base, os.W_OK | os.X_OK):
        raise OptionError(f"{flag}: directory {base} is not writable")


@_checked_path
def _output_dir(flag: str, value: str) -> None:
    if not value or not value.strip():
        raise OptionError(f"{flag}: empty directory name")
    p = Path(value)
    if p.exists() and not p.is_dir():
        raise OptionError(f"{flag}: {value} exists and is not a directory")
    base = _existing_ancestor(p)
    if not base.is_dir():
        raise OptionError(f"{flag}: {base} is not a directory")
    if not os.access(base, os.W_OK | os.X_OK):
        raise OptionError(f"{flag}: directory {base} is not writable")


# Commands whose --out is a file (others: a directory).
_OUT_FILE_COMMANDS = {"lab", "simulate"}
# Commands whose --config is an input file (others: a configuration name).
_CONFIG_FILE_COMMANDS = {"estimate"}


def check_options(args: argparse.Namespace) -> None:
    """Refuse bad option values of ``args`` before the command runs.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed options; ``args.command`` names the command.

    Raises
    ------
    OptionError
        One line naming the option and what is wrong with its value.
    """
    command = getattr(args, "command", "")
    v = vars(args)

    def given(dest: str) -> bool:
        return v.get(dest) is not None

    for dest in ("netlist", "measured", "reference", "repeat"):
        if given(dest):
            _input_file(_flag(dest), v[dest])
    if given("model_out"):
        _output_file("--model-out", v["model_out"])
    if command in _CONFIG_FILE_COMMANDS and given("config"):
        _input_file("--config", v["config"])
    if given("out"):
        if command in _OUT_FILE_COMMANDS:
            _output_file("--out", v["out"], parent_must_exist=command == "lab")
            suffix = Path(v["out"]).suffix.lower()
            if command == "simulate" and suffix not in (".csv", ".npz", ".mat"):
                raise OptionError(f"--out {v['out'][:200]}: unknown waveform format {suffix or '(no extension)'!r}; "
                                  "use .csv, .npz or .mat")
        else:
            _output_dir("--out", v["out"])
    if given("plot"):
        _output_file("--plot", v["plot"])
    for dest in ("plots", "report", "fmu_dir", "cache"):
        if given(dest):
            _output_dir(_flag(dest), v[dest])
    if given("model") and isinstance(v["model"], str):
        if not v["model"].strip():
            raise OptionError("--model: empty model name")
    if given("seed"):
        seed = v["seed"]
        if not isinstance(seed, int) or not 0 <= seed < 2**32:
            raise OptionError(f"--seed must be an integer from 0 to {2**32 - 1} (got {seed})")
    if given("workers"):
        if not 1 <= v["workers"] <= MAX_WORKERS:
            raise OptionError(f"--workers must be from 1 to {MAX_WORKERS} (got {v['workers']})")
    for dest in ("fmin", "fmax"):
        if given(dest):
            _finite(dest, v[dest], *FREQUENCY_RANGE, unit=" Hz")
    if given("fmin") and given("fmax") and not v["fmin"] < v["fmax"]:
        raise OptionError(f"--fmin ({v['fmin']:g} Hz) must be below --fmax ({v['fmax']:g} Hz)")
    if given("points") and v["points"] < 1:
        raise OptionError(f"--points must be at least 1 (got {v['points']})")
    if given("points") and v["points"] > MAX_POINTS:
        n = float(min(v["points"], 10**300))
        raise OptionError(
            f"--points {str(v['points'])[:40]} asks for {n:.3g} frequencies (about {n * 16 / 2**30:.3g} GiB in memory and "
            f"{n * 50 / 2**30:.3g} GiB of output per response); at most {MAX_POINTS:g}: lower --points")
    for dest in ("cases", "configs", "optimisers"):
        if given(dest) and isinstance(v[dest], str) and not any(x.strip() for x in v[dest].split(",")):
            raise OptionError(f"{_flag(dest)}: empty list {v[dest]!r}; name at least one item or leave the option out")
    for dest, role in (("port", "the driven node"), ("probe", "the probed node")):
        if given(dest) and isinstance(v[dest], str) and v[dest].strip().lower() in ("0", "gnd"):
            raise OptionError(f"--{dest} {v[dest]!r} is ground; {role} must be another node")
    if given("scheduler") and isinstance(v["scheduler"], str) and v["scheduler"] not in ("processes", "serial") \
            and "://" not in v["scheduler"]:
        raise OptionError(f"--scheduler must be 'processes', 'serial' or an address tcp://host:port "
                          f"(got {v['scheduler'][:80]!r})")
    if command == "study":
        _study_budget(v)
    if command == "estimate" and given("config"):
        _estimate_budget(v["config"])
    if command == "diagnose" and given("port") and not given("netlist"):
        raise OptionError("--port applies to a --netlist baseline only")
    _source_checks(v, given)
    if given("name") and command == "build-fmu" and not str(v["name"]).strip():
        raise OptionError("--name: empty name")


def _source_checks(v: dict[str, Any], given: Any) -> None:
    """PRIS source, sampling and record options (simulate, build-fmu, diagnose)."""
    from pris_cosim.units import ELEMENT_RANGES

    for dest, kind in (("rpris", "R"), ("lpris", "L"), ("cpris", "C"), ("rload", "R")):
        if given(dest):
            low, high = ELEMENT_RANGES[kind]
            if dest == "rpris":
                high = MAX_SOURCE_RESISTANCE
            _finite(dest, v[dest], low, high, unit={"R": " Ohm", "L": " H", "C": " F"}[kind])
    for dest, high, unit in (("rsnub", MAX_SOURCE_RESISTANCE, " Ohm"), ("csnub", ELEMENT_RANGES["C"][1], " F"),
                             ("lsw", ELEMENT_RANGES["L"][1], " H"), ("csw", ELEMENT_RANGES["C"][1], " F")):
        if given(dest):
            _finite(dest, v[dest], nonnegative=True)
            _finite(dest, v[dest], 0.0, high, unit=unit)
    if given("lsw") and v["lsw"] > 0 and not (v.get("csw") or 0) > 0 and not (v.get("csnub") or 0) > 0:
        raise OptionError("--lsw needs --csw (or a snubber, --rsnub and --csnub): the node between the switch "
                          "inductance and the series RLC would carry inductors only")
    if given("vdc"):
        _finite("vdc", v["vdc"], positive=True)
        _finite("vdc", v["vdc"], 0.0, 1e9, unit=" V")
    if given("fclk"):
        _finite("fclk", v["fclk"], *FREQUENCY_RANGE, unit=" Hz")
    if given("fs"):
        _finite("fs", v["fs"], *SAMPLING_RANGE, unit=" Hz")
    if given("prbs_order"):
        from pris_cosim.signals.perturbation import MAX_LENGTH_TAPS

        if v["prbs_order"] not in MAX_LENGTH_TAPS:
            raise OptionError(f"--prbs-order must be one of {min(MAX_LENGTH_TAPS)} .. {max(MAX_LENGTH_TAPS)} "
                              f"(got {v['prbs_order']})")
    if given("periods"):
        if not 1 <= v["periods"] <= MAX_PERIODS:
            raise OptionError(f"--periods must be from 1 to {MAX_PERIODS} (got {v['periods']})")
    if given("fs") and given("fclk") and given("prbs_order"):
        period = (2 ** v["prbs_order"] - 1) * v["fs"] / v["fclk"]
        if period > MAX_PERIOD_SAMPLES:
            raise OptionError(
                f"--prbs-order {v['prbs_order']} at --fs {v['fs']:g} Hz and --fclk {v['fclk']:g} Hz makes "
                f"{period:.3g} samples per PRBS period ({period * 8 / 2**30:.3g} GiB per waveform); at most "
                f"{MAX_PERIOD_SAMPLES:g}: lower --prbs-order or --fs")
        if given("periods") and period * v["periods"] > MAX_RECORD_SAMPLES:
            total = period * v["periods"]
            raise OptionError(
                f"--periods {v['periods']} of {period:.3g} samples make {total:.3g} samples "
                f"({total * 8 / 2**30:.3g} GiB per waveform); at most {MAX_RECORD_SAMPLES:g}: lower --periods, "
                f"--prbs-order or --fs")


def _study_budget(v: dict[str, Any]) -> None:
    """Runs a study would schedule: three-section cells x optimisers x seeds x noise levels."""
    seeds = v.get("seeds")
    if seeds is None:
        return
    if not isinstance(seeds, int) or seeds < 1:
        raise OptionError(f"--seeds must be at least 1 (got {seeds})")
    optimisers = len([x for x in str(v.get("optimisers") or "ga,pso,cma").split(",") if x.strip()]) or 3
    levels = 1 + len([x for x in str(v.get("snr_db") or "").split(",") if x.strip()])
    cells = 8  # three-section: 4 approaches x 2 cost functions
    runs = cells * optimisers * levels * seeds
    if runs > MAX_STUDY_RUNS:
        raise OptionError(
            f"--seeds {seeds} makes {runs} optimisation runs ({cells} cells x {optimisers} optimisers x {levels} "
            f"noise levels x {seeds} seeds, hours to days of computing); at most {MAX_STUDY_RUNS}: lower --seeds, "
            "--optimisers or --snr-db")


def _estimate_budget(path: str) -> None:
    """Record length, frequency points and evaluation budget of an ``estimate`` configuration."""
    import json

    try:
        if os.path.getsize(path) > 10 * 2**20:
            raise OptionError(f"--config: {path} is larger than 10 MiB; a configuration is a small JSON object")
        with open(path, encoding="utf-8") as fh:
            cfg = json.load(fh)
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return  # the command reports unreadable or malformed files itself, with the line and column
    if not isinstance(cfg, dict):
        return

    def number(x: Any) -> float | None:
        return float(x) if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) else None

    fs, duration = number(cfg.get("fs")), number(cfg.get("duration"))
    if fs is not None and duration is not None and fs * duration > MAX_RECORD_SAMPLES:
        n = fs * duration
        raise OptionError(f"--config {path}: fs x duration makes {n:.3g} samples ({n * 8 / 2**30:.3g} GiB per "
                          f"waveform); at most {MAX_RECORD_SAMPLES:g}: lower 'fs' or 'duration'")
    freq = cfg.get("frequency")
    points = number(freq.get("points")) if isinstance(freq, dict) else None
    if points is not None and points > MAX_POINTS:
        raise OptionError(f"--config {path}: frequency.points {points:.3g} (about {points * 16 / 2**30:.3g} GiB "
                          f"per response); at most {MAX_POINTS:g}: lower 'points'")
    budget = cfg.get("budget")
    if isinstance(budget, dict):
        evals, seconds = number(budget.get("max_evals")), number(budget.get("max_time_s"))
        if seconds is not None and seconds > 7 * 86400:
            raise OptionError(f"--config {path}: budget.max_time_s {seconds:.3g} s is over a week; "
                              "at most 604800: lower 'max_time_s'")
        if evals is not None and evals > 1e9 and seconds is None:
            raise OptionError(f"--config {path}: budget.max_evals {evals:.3g} without max_time_s runs for days "
                              "(about 1 ms per evaluation); at most 1e9: lower 'max_evals' or set 'max_time_s'")


def check_circuit_size(circuit: Any, command: str) -> None:
    """Refuse a circuit too large for the dense state-space form a command builds.

    ``frf`` solves large circuits sparsely and is not limited here; the
    time-domain engines, FMUs and fits hold dense ``nodes x nodes`` stamps
    per element.

    Parameters
    ----------
    circuit : Circuit
        The circuit read from ``--netlist`` or ``--model``.
    command : str
        The command about to run.

    Raises
    ------
    OptionError
        One line with the estimate and the cap.
    """
    if command == "frf":
        return
    n_nodes = len(circuit.nodes)
    n_el = len(circuit.of_kind("R", "C"))
    n = n_nodes + len(circuit.of_kind("L")) + len(circuit.of_kind("V"))
    need = (n_el * n_nodes**2 + 12 * n**2) * 8.0
    if need > MAX_DENSE_BYTES:
        raise OptionError(
            f"--netlist: {n_nodes} nodes and {n_el} R/C elements need about {need / 2**30:.3g} GiB for the dense "
            f"state-space form {command} uses; at most {MAX_DENSE_BYTES / 2**30:g} GiB: use a smaller netlist "
            "(frf solves large netlists sparsely)")
