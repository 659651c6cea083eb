"""``pris-cosim estimate`` with an FMU in the loop: a recipe for an expensive black box.

Config (JSON)::

    {
      "fmu": "fmus/two-section/two_section_dut.fmu",   # FMI 2.0 or 3.0 Co-Simulation, any tool
      "input": "i_in",          # the FMU's input, a column of the record; omit for an FMU with its own source
      "input_hold": "auto",     # "auto" (default: decided from the record), "zoh" or "linear"
      "output": "v_in",         # the FMU output compared with the record
      "outputs": ["v_mid"],     # optional further compared outputs (columns of the record)
      "current": "i_in",        # FMU without input, approach "frequency": its current output
      "parameters": {"R1": {"min": 1, "max": 100}, "L1": {"min": 1, "max": 100}},
      "values": {"R_src": 50},  # optional: FMU parameters set for every run, not estimated
      "ties": {"R2": "R1"},     # optional: FMU parameters set equal to (expressions of) others
      "target": {"kind": "waveforms-csv", "path": "record.csv",   # columns time_s, input, output(s)
                 "values": {"R1": 10}},                          # optional true values (errors_percent)
      "approach": "time",       # "time", "emd", "iemd" or "frequency" (Welch H1 of the waveforms)
      "frequency": {"fmin": 20, "fmax": 9000, "points": 200},
      "budget": {"design": 70, "candidates": 8, "restarts": 2, "simulations": 280},
      "substeps": 2,            # communication steps per sample for a linear hold without input derivatives
      "diff_step": 1e-5,        # finite-difference step in the unit cube
      "seed": 1
    }

The input's hold (:func:`estimation.holds.decide_hold`): an input with few
distinct levels (a PRBS, a DAC staircase) changes only at sample instants and
is held over each sample (zero-order hold); any other input varies linearly
between samples. The answer reports the hold and the reason.

Recipe: the staged recipe of :func:`estimation.recipe.run_recipe`, the one every
model kind runs (built-in models and netlists through
:class:`estimation.estimate.ApproachKind`); the FMU's stages
(:class:`FmuKind`) are made for few evaluations, each a whole FMU run or a
window of one:

1. start: a Latin-hypercube design of ``budget.design`` points (default ``10 n + 10``,
   :class:`scipy.stats.qmc.LatinHypercube`) in the unit cube (log scale for
   positive bounds), ranked on the record's *responses*: the log-magnitude of
   the Welch H1 responses from the input (or recorded current) to every
   compared output over the whole record (:meth:`~estimation.fmu.problem.FmuProblem.response_target`,
   Hann segments of an 8th of the record, over its first quarter: three
   segments, each design point a run of a quarter of the record), a smooth function of the
   parameters where the time residual of a long record is a needle; then
   the *screen*: from the ``budget.candidates`` best design points (default
   ``max(2 restarts, n + 2)``), a trust-region least squares
   (:func:`scipy.optimize.least_squares`, ``trf``, two-point finite-difference
   Jacobian, bounds of the cube) on the time residual over doubling first
   windows of the record up to a 32nd of it (cheap runs), by successive
   halving: after each window the better half of the candidates (at least
   ``restarts + 1``) goes on to the next one from where it ended; a start in a
   wrong basin ends well above the noise. Restart ``k`` starts from the
   ``k``-th best screened end, each from its own design point and run as its
   own task (independent restarts);
2. descend: the longer windows, the whole record and the approach's own
   residuals (:mod:`estimation.fmu.problem`); the start is also scored on the
   whole record and kept when the continuation ends above it;
3. restarts: ``budget.restarts`` first (default 2), more (up to ``n + 2``,
   screening the next design points when the screened ends run out) while
   fewer than two ends explain the record (:meth:`FmuKind.explains`);
4. the verdict of :func:`estimation.fmu.verdict.judge` on the best end point:
   converged only when its residual is the record's own noise (a chi-square
   test) and another independent restart reaches the same values within
   their uncertainty; uncertainty from the Fisher information only then;
   non-identifiable parameters from the Fisher information at the answer;
   failed runs by reason. A best end short of its minimum is polished once
   more on the whole record.

Budgets: every stage stops when the least squares converges, when its best
cost fell by less than a 1e-4 fraction over its last ``4 (n + 1)`` runs
(progress), or at the cap of ``budget.simulations`` runs (default
``40 (n + 1)``). The answer reports the runs of every stage of every restart
(``restarts[].runs_per_stage``), of the design and of the screen.

Every design chunk, screened candidate and restart is a task of :func:`estimation.search.executor.run_tasks`
(local processes, ``serial``, or a Dask scheduler address), stored atomically
as it finishes under ``--out DIR``; running the same command again skips the
stored ones. Each worker process instantiates the FMU once and resets it per
run; a run that fails, returns NaN or diverges costs :data:`~estimation.fmu.problem.PENALTY`
and is counted (``failed_evaluations``).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimation.fmu.model import FmuSetupError, fmu_variables
from estimation.fmu.problem import APPROACHES, problem, read_record
from estimation.holds import HOLDS, decide_hold
from estimation.search.local_search import staged_least_squares
from estimation.recipe import End, Start

__all__ = ["FmuKind", "design_task", "make_setup", "restart_task", "run_fmu_estimate"]

KNOWN = {"fmu", "input", "output", "outputs", "current", "parameters", "ties", "target", "approach", "frequency",
         "budget", "substeps", "diff_step", "seed", "first_window", "design_score", "window_growth", "values",
         "input_hold"}


def _bad(text: str) -> FmuSetupError:
    return FmuSetupError(text)


def _choices(names: Sequence[str], limit: int = 30) -> str:
    """The valid entries of a config key, for an error line."""
    names = list(names)
    if not names:
        return "none"
    return ", ".join(names[:limit]) + (f" ... ({len(names)} in all)" if len(names) > limit else "")


#: A parameter named like a coupling coefficient: ``k``, ``k12``, ``k_ab``, ``K23``.
COUPLING_NAME = re.compile(r"[kK](_?[A-Za-z0-9]{1,4})?")
#: Largest magnitude a coupling bound is clipped to: a coupling of magnitude 1 makes the inductance matrix singular.
COUPLING_MAX = 0.999


def _coupling_bounds(name: str, lo: float, hi: float) -> tuple[float, float]:
    """Bounds of a coupling coefficient clipped into ``(-1, 1)`` with a one-line warning; others unchanged."""
    if not COUPLING_NAME.fullmatch(name) or (-1.0 < lo and hi < 1.0):
        return lo, hi
    lo2, hi2 = max(lo, -COUPLING_MAX), min(hi, COUPLING_MAX)
    if not lo2 < hi2:
        raise _bad(f"config key 'parameters': {name!r}: a coupling coefficient must lie in (-1, 1) "
                   f"(got min {lo:g}, max {hi:g})")
    print(f"warning: config key 'parameters': {name!r}: bounds [{lo:g}, {hi:g}] admit a coupling of magnitude >= 1 (an "
          f"inductance matrix that is not positive definite); clipped to [{lo2:g}, {hi2:g}]", file=sys.stderr,
          flush=True)
    return lo2, hi2


def _check_ties(ties: Mapping[str, str], known: set[str]) -> None:
    """Every tie's expression parses and uses known names only (one line naming the tie)."""
    from pris_cosim.circuits.expressions import Expression, ExpressionError

    lower = {k.lower(): k for k in known}
    for k, e in ties.items():
        try:
            expr = Expression(e)
        except ExpressionError as exc:
            raise _bad(f"config key 'ties': {k!r}: {exc} (it may use: {_choices(sorted(known))})") from None
        unknown = sorted(n for n in expr.names if n.lower() not in lower and n.lower() not in _FUNCTIONS)
        if unknown:
            m = re.search(rf"(?i)\b{re.escape(unknown[0])}\b", e)
            bad = m.group(0) if m else unknown[0]
            raise _bad(f"config key 'ties': {k!r}: {bad!r} in {e!r} is not a parameter, value or FMU "
                       f"parameter (it may use: {_choices(sorted(known))})")


_FUNCTIONS = {"sqrt", "exp", "log", "log10", "abs", "min", "max", "pi", "sin", "cos", "tan", "pow"}


def make_setup(cfg: Mapping[str, Any], base: str | Path = ".") -> dict[str, Any]:
    """Check an FMU config and turn it into the JSON-ready setup the workers build their problem from.

    Raises
    ------
    FmuSetupError
        One line naming the bad key, file or variable.
    """
    unknown = sorted(set(cfg) - KNOWN)
    if unknown:
        raise _bad(f"config key {unknown[0]!r} is not known with 'fmu' (known: {', '.join(sorted(KNOWN))})")
    base = Path(base)
    for key, kind in (("budget", dict), ("frequency", dict), ("substeps", int), ("first_window", int),
                      ("seed", int), ("diff_step", (int, float))):
        if key in cfg and (not isinstance(cfg[key], kind) or isinstance(cfg[key], bool)):
            want = {dict: "an object", int: "an integer"}.get(kind, "a number")
            raise _bad(f"config key {key!r} must be {want} (got {cfg[key]!r})")
    for key, value in dict(cfg.get("budget", {})).items():
        if key not in ("design", "restarts", "simulations", "candidates") or not isinstance(value, int) or value < 1:
            raise _bad(f"config key 'budget': {key!r} must be one of design, candidates, restarts, simulations, "
                       "a positive integer")
    if "diff_step" in cfg and not 0 < float(cfg["diff_step"]) < 0.5:
        raise _bad("config key 'diff_step' must lie in (0, 0.5)")
    if "substeps" in cfg and cfg["substeps"] < 1:
        raise _bad("config key 'substeps' must be at least 1")
    growth = cfg.get("window_growth", 2.0)
    if not isinstance(growth, (int, float)) or isinstance(growth, bool) or not 1.05 <= growth <= 16:
        raise _bad("config key 'window_growth' must be a number from 1.05 to 16")
    if cfg.get("design_score", "auto") not in ("auto", "response", "window", "frequency"):
        raise _bad("config key 'design_score' must be 'auto', 'response', 'window' or 'frequency'")
    if "first_window" in cfg and cfg["first_window"] < 0:
        raise _bad("config key 'first_window' must be 0 (automatic) or a number of samples")

    def path_of(p: Any, key: str) -> str:
        if not isinstance(p, str) or not p:
            raise _bad(f"config key {key!r} must name a file")
        q = Path(p) if Path(p).is_absolute() else (base / p)
        return str(q.resolve())

    fmu = path_of(cfg["fmu"], "fmu")
    md, variables = fmu_variables(fmu)
    name = Path(fmu).name
    of = {c: [k for k, v in variables.items() if v.causality == c] for c in ("input", "output", "parameter")}
    inp = cfg.get("input")
    if inp is not None and (not isinstance(inp, str) or variables.get(inp) is None
                            or variables[inp].causality != "input"):
        raise _bad(f"config key 'input': {inp!r} is not an input of {name} ({_choices(of['input'])})")
    output = cfg.get("output", "v_in")
    if not isinstance(output, str) or output not in variables:
        raise _bad(f"config key 'output': {output!r} is not a variable of {name} (outputs: {_choices(of['output'])})")
    extra = cfg.get("outputs", [])
    if not isinstance(extra, list):
        raise _bad(f"config key 'outputs' must be a list of variables of {name} (outputs: {_choices(of['output'])})")
    for o in extra:
        if not isinstance(o, str) or o not in variables:
            raise _bad(f"config key 'outputs': {o!r} is not a variable of {name} (outputs: {_choices(of['output'])})")
    approach = cfg.get("approach", "time")
    if approach not in APPROACHES:
        raise _bad(f"config key 'approach' must be one of {', '.join(APPROACHES)} (got {approach!r})")
    spec = cfg.get("parameters")
    if not isinstance(spec, dict) or not spec:
        raise _bad("config key 'parameters' must map FMU parameters to {\"min\": .., \"max\": ..}")
    params: dict[str, list[Any]] = {}
    ties = cfg.get("ties", {})
    if not isinstance(ties, dict):
        raise _bad(f"config key 'ties' must map parameters of {name} to expressions")
    for k, e in ties.items():
        if k not in variables or variables[k].causality != "parameter":
            raise _bad(f"config key 'ties': {k!r} is not a parameter of {name} "
                       f"(parameters: {_choices(of['parameter'])})")
        if not isinstance(e, str):
            raise _bad(f"config key 'ties': {k!r} must be an expression (text), got {e!r}")
    tie_text = " ".join(ties.values())
    for name, b in spec.items():
        v = variables.get(name)
        helper = v is None and name in tie_text  # e.g. a coupling k12 in "M12": "k12*sqrt(L1*L2)"
        if not helper and (v is None or v.causality != "parameter"):
            raise _bad(f"config key 'parameters': {name!r} is not a parameter of {Path(fmu).name} (parameters: "
                       f"{_choices(of['parameter'])}; or a name used in 'ties')")
        if not isinstance(b, dict) or not {"min", "max"} <= set(b):
            raise _bad(f"config key 'parameters': {name!r}: give {{\"min\": .., \"max\": ..}} (got {b!r})")
        try:
            lo, hi = float(b["min"]), float(b["max"])
        except (TypeError, ValueError):
            raise _bad(f"config key 'parameters': {name!r}: min and max must be numbers (got {b['min']!r}, "
                       f"{b['max']!r})") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise _bad(f"config key 'parameters': {name!r}: need finite min < max (got {lo:g}, {hi:g})")
        lo, hi = _coupling_bounds(name, lo, hi)
        scale = b.get("scale", "log" if lo > 0 else "linear")
        if scale not in ("log", "linear") or (scale == "log" and lo <= 0):
            raise _bad(f"config key 'parameters': {name!r}: scale must be 'linear', or 'log' with min > 0 "
                       f"(got {scale!r}, min {lo:g})")
        params[name] = [lo, hi, scale]
    fixed = cfg.get("values", {})
    if not isinstance(fixed, dict):
        raise _bad("config key 'values' must map FMU parameters to numbers")
    _check_ties(ties, set(params) | set(fixed) | set(of["parameter"]))
    for name, value in fixed.items():
        v = variables.get(name)
        if v is None or v.causality != "parameter" or v.type not in ("Real", "Float64"):
            raise _bad(f"config key 'values': {name!r} is not a real parameter of {Path(fmu).name} (parameters: "
                       f"{_choices(of['parameter'])})")
        if name in params or name in ties:
            raise _bad(f"config key 'values': {name!r} is also in {'parameters' if name in params else 'ties'}")
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(float(value)):
            raise _bad(f"config key 'values': {name!r} must be a finite number (got {value!r})")
    hold = cfg.get("input_hold", "auto")
    if hold not in HOLDS:
        raise _bad(f"config key 'input_hold' must be one of {', '.join(HOLDS)} (got {hold!r})")
    tgt = cfg.get("target")
    if not isinstance(tgt, dict) or tgt.get("kind", "waveforms-csv") != "waveforms-csv":
        raise _bad("config key 'target' must be {\"kind\": \"waveforms-csv\", \"path\": FILE} with an FMU")
    setup = {"fmu": fmu, "input": inp, "output": output, "extra_outputs": list(extra),
             "current": cfg.get("current", "i_in" if inp is None and "i_in" in variables else None),
             "parameters": params, "ties": dict(ties), "target": path_of(tgt.get("path"), "target.path"),
             "approach": approach, "frequency": dict(cfg.get("frequency", {})),
             "substeps": int(cfg.get("substeps", 2)), "diff_step": float(cfg.get("diff_step", 1e-5)),
             "first_window": int(cfg.get("first_window", 0)), "design_score": cfg.get("design_score", "auto"),
             "window_growth": float(cfg.get("window_growth", 2.0)),
             "values": {k: float(v) for k, v in fixed.items()}}
    if not Path(setup["target"]).is_file():
        raise _bad(f"config key 'target.path': file not found: {tgt.get('path')} (taken from {base.resolve()})")
    if inp is None:
        setup["input_hold"], setup["hold_reason"] = None, "no input: the FMU makes its own drive"
    elif hold == "auto":
        setup["input_hold"], setup["hold_reason"] = decide_hold(read_record(setup["target"], [inp])[inp], inp)
    else:
        setup["input_hold"], setup["hold_reason"] = hold, "set in the config ('input_hold')"
    problem(setup)  # reads the record and instantiates the FMU here: every setup error now, in one line
    return setup


# ---------------------------------------------------------------------- tasks (run in worker processes)
#: Welch segments of the response stages, as fractions of the record: coarse (smooth) first, then fine.
RESPONSE_SEGMENTS = (8, 2)


def response_segments(pb: Any) -> list[int]:
    """Welch segment lengths (samples) of the response stages the record supports (may be empty)."""
    out = []
    for m in RESPONSE_SEGMENTS:
        nper = pb.n // m
        if nper >= 64 and pb.response_target(nper) is not None and nper not in out:
            out.append(nper)
    return out


def stages_of(pb: Any, part: str = "all") -> list[tuple[str, int | None]]:
    """The stages of a restart: ``(residual, window)`` pairs, in order.

    1. ``("time", w)``: the time residual over doubling first windows of the
       record; the windows up to a 32nd of the record are the *screen*
       (``part="screen"``): cheap, run from many candidates, whose end costs
       tell a start in the right basin (it fits the window to the noise) from
       one in a wrong one;
    2. the longer windows, the whole record's time residual, and the approach's
       own residual over the whole record (``part="rest"``).
    """
    wins = pb.windows()
    cut = max(wins[0] if wins else 0, pb.n // 32)
    screen: list[tuple[str, int | None]] = [("time", w) for w in wins if w <= cut]
    rest: list[tuple[str, int | None]] = [("time", w) for w in wins if w > cut]
    if pb.approach != "time":
        rest.append(("time", None))
    rest.append((pb.approach, None))
    if not screen:
        screen, rest = rest[:1], rest[1:]
    if part.startswith("screen:"):  # one stage of the screen (its rounds, :meth:`FmuKind._screen_more`)
        return screen[int(part.split(":")[1]):][:1]
    return {"screen": screen, "rest": rest, "all": screen + rest}[part]


def design_score_of(pb: Any, setup: Mapping[str, Any]) -> tuple[str, int | None]:
    """What ranks the design points: the coarse response when the record has one, else the first window."""
    choice = setup.get("design_score", "auto")
    segs = response_segments(pb)
    if choice in ("auto", "response") and segs:
        return "response", segs[0]
    if choice == "frequency" and pb.has_frequency:
        return "frequency", None
    wins = pb.windows()
    return "time", (wins[0] if wins else None)


def design_task(setup: dict[str, Any], points: list[list[float]]) -> dict[str, Any]:
    """Costs of design points (unit cube) with the worker's FMU instance."""
    pb = problem(setup)
    which, window = design_score_of(pb, setup)
    costs = [pb.residual(np.asarray(x, float), which, window)[1] for x in points]
    label = {"response": f"response, segments of {window} samples", "frequency": "frequency"}.get(
        which, f"time, first {window or pb.n} samples")
    return {"costs": costs, "scored_on": label, **pb.stats()}


def stage_label(which: str, window: int | None) -> str:
    if which == "response":
        return f"response ({window}-sample segments)"
    return f"{which}{f' (first {window} samples)' if window else ''}"


#: Seconds between progress lines of a running task.
PROGRESS_EVERY_S = 20.0


def progress_writer(name: str, path: str, every: float = 2.0) -> Any:
    """A ``report(stage, runs, best cost)`` callable that writes the task's state to ``path`` at most every
    ``every`` s (a worker process prints nothing: the parent reads the file, :class:`ProgressWatch`)."""
    t0 = time.perf_counter()
    last = [t0]

    def report(stage: str, runs: int, cost: float) -> None:
        now = time.perf_counter()
        if now - last[0] >= every:
            last[0] = now
            tmp = f"{path}.tmp"
            try:
                Path(tmp).write_text(f"{name}: {stage}: {runs} runs, best cost {cost:.4g}, {now - t0:.0f} s")
                os.replace(tmp, path)
            except OSError:
                pass

    return report


class ProgressWatch:
    """Prints the state of the running tasks (their progress files) on stderr every ``every`` s."""

    def __init__(self, folder: Path, every: float = PROGRESS_EVERY_S):
        import threading

        self.folder, self.every = folder, every
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def __enter__(self) -> "ProgressWatch":
        self.folder.mkdir(parents=True, exist_ok=True)
        self.thread.start()
        return self

    def _loop(self) -> None:
        seen: dict[str, float] = {}
        while not self.stop.wait(self.every):
            for f in sorted(self.folder.glob("*.txt")):
                try:
                    m = f.stat().st_mtime
                    if seen.get(f.name) != m:
                        seen[f.name] = m
                        print(f"  {f.read_text()}", file=sys.stderr, flush=True)
                except OSError:
                    pass

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(timeout=5)
        for f in self.folder.glob("*.txt"):
            f.unlink(missing_ok=True)


def _settled_on(pb: Any) -> Any:
    """The whole record's stage is settled when its residual is the record's noise (chi-square test) and its
    sum of squares fell by less than one chi-square unit over the stall span: the values then move within
    their 1-sigma (a Gauss-Newton step of one unit moves them by about one standard deviation)."""
    from estimation.fmu.verdict import block_noise, chi_square

    blocks = len(pb.outputs)  # the time residual: every compared output
    n = len(pb.params.varying)

    def settled(stage: Any, r: np.ndarray, then: float, now: float) -> bool:
        if stage[1] is not None or stage[0] != "time":  # a window's end is the next stage's start
            return False
        r = np.asarray(r, float)
        sigma = block_noise(r, blocks)
        if not chi_square(r, sigma, n)["consistent"]:
            return False
        fall = r.size * (then ** 2 - now ** 2) / float(np.mean(sigma ** 2))
        return fall < 1.0

    return settled


def restart_task(setup: dict[str, Any], x0: list[float], simulations: int, part: str = "all",
                 name: str = "restart", progress_file: str | None = None) -> dict[str, Any]:
    """One restart from ``x0``: a trust-region least squares per stage (:func:`stages_of` ``part``).

    :func:`estimation.search.local_search.staged_least_squares`: each stage stops when the least squares
    converges, when its best cost stops falling (progress), or after ``simulations`` FMU runs (a cap).
    With ``part="rest"`` the start is also scored on the last stage (one run): when the continuation
    ended above it there, the start is the answer (a screened candidate is never lost).
    """
    pb = problem(setup)
    stages = stages_of(pb, part)
    x0 = np.asarray(x0, float)
    start_cost = pb.residual(x0, *stages[-1])[1] if part == "rest" else math.inf
    out = staged_least_squares(lambda z, st: pb.residual(z, st[0], st[1]), x0, stages,
                               simulations, lambda: pb.simulations, lambda st: stage_label(*st),
                               float(setup["diff_step"]), finish=False,
                               report=progress_writer(name, progress_file) if progress_file else None,
                               settled=_settled_on(pb) if part == "rest" else None)
    if start_cost < out["cost"]:
        out = {**out, "x": [float(v) for v in x0], "cost": float(start_cost),
               "message": out["message"] + f"; its start was better on the last stage ({start_cost:.4g}): kept"}
    return {**out, "stages": stages, **pb.stats()}


# ---------------------------------------------------------------------- the recipe
def _hold_text(setup: Mapping[str, Any], pb: Any) -> str | None:
    if not setup["input"]:
        return None
    if setup["input_hold"] == "zoh":
        return "zoh (each sample held over its interval)"
    return ("linear (input derivatives)" if pb.model.interpolates
            else f"linear (midpoint of {setup['substeps']} substeps)")


def _out_dir(cfg: Mapping[str, Any], setup: Mapping[str, Any]) -> Path:
    key = hashlib.sha256(json.dumps({"cfg": cfg, "setup": setup}, sort_keys=True, default=str).encode()).hexdigest()
    return Path(f"estimate-{Path(setup['fmu']).stem}-{key[:8]}")


class FmuKind:
    """An FMU in the loop: the stages of :func:`estimation.recipe.run_recipe` (module docstring, Recipe).

    - start ``k``: at the first call, the design (ranked on the record's responses) and the screen
      of the best design points on short windows, each chunk and candidate a task of
      :func:`estimation.search.executor.run_tasks`; then the ``k``-th best screened candidate, while its
      screen cost is within :data:`SCREEN_RATIO` of the best one's (a worse one started in another
      basin);
    - descend: the window continuation from each start to the whole record and the approach's own
      residual, one task per start (parallel, stored, resumed);
    - polish: the approach's own residual over the whole record once more.

    Parameters
    ----------
    setup : dict
        :func:`make_setup`'s answer.
    budget : mapping
        The config's ``budget`` (``design``, ``candidates``, ``restarts``, ``simulations``).
    seed : int
        Seed of the Latin-hypercube design.
    store : path
        Results directory of the tasks.
    executor : str
        ``"processes"``, ``"serial"`` or a Dask address.
    workers : int, optional
        Local worker processes.
    progress : bool
        One line per finished task on stderr.
    """

    def __init__(self, setup: dict[str, Any], budget: Mapping[str, Any], seed: int, store: Path, executor: str,
                 workers: int | None, progress: bool):
        self.setup, self.store, self.executor, self.workers, self.progress = setup, store, executor, workers, progress
        self.pb = problem(setup)
        self.params = self.pb.params
        n = len(self.pb.params.varying)
        self.n_design = int(budget.get("design", 10 * n + 10))
        self.restarts = int(budget.get("restarts", 2))
        self.per_stage = int(budget.get("simulations", 40 * (n + 1)))  # a cap per stage; stages stop on progress
        # screened at first; more are screened while fewer than two restarts explain the record
        self.candidates = int(budget.get("candidates", max(2 * self.restarts, n + 2)))
        if self.n_design < 1 or self.restarts < 1 or self.per_stage < n + 2:
            raise _bad(f"config key 'budget': need design >= 1, restarts >= 1, simulations >= {n + 2}")
        self.max_restarts = max(self.restarts, n + 2)
        self.seed = int(seed)
        self.verdict_options = {"step_within_sigma": True}  # a long record's time residual is a needle at the
        # scale of the noise's 1-sigma: a Gauss-Newton step within it is no evidence of a better minimum
        self.design_res: list[dict[str, Any]] = []
        self.screened: list[dict[str, Any]] = []
        self.ranked: list[int] = []
        self.design = np.zeros((0, n))
        self.order: list[int] = []  # design points by cost, screened in this order
        self.started: set[int] = set()  # screened ends a restart started from
        self.t0 = time.perf_counter()
        self.blocks = len(self.pb.outputs) if self.pb.approach == "time" else 1
        self.ends: list[dict[str, Any]] = []
        self.polish_stats = {"simulations": 0, "failures": 0, "samples": 0}

    def _run(self, tasks: list[Any]) -> list[dict[str, Any]]:
        from estimation.search.executor import run_tasks

        if not self.progress:
            return run_tasks(tasks, executor=self.executor, store=self.store, progress=False, workers=self.workers)
        with ProgressWatch(self.store / "progress"):
            return run_tasks(tasks, executor=self.executor, store=self.store, progress=True, workers=self.workers)

    def _progress_file(self, name: str) -> str:
        return str((self.store / "progress" / f"{name}.txt").resolve())

    def _say(self, text: str) -> None:
        if self.progress:
            print(f"estimate (FMU): {text}, {time.perf_counter() - self.t0:.0f} s", file=sys.stderr, flush=True)

    def _design_and_screen(self) -> None:
        from scipy.stats import qmc

        from estimation.search.executor import Task

        n = len(self.pb.params.varying)
        self.design = design = qmc.LatinHypercube(d=n, seed=self.seed).random(self.n_design)
        nw = self.workers or os.cpu_count() or 1
        chunks = [c for c in np.array_split(np.arange(self.n_design), min(nw, self.n_design)) if c.size]
        self._say(f"design: {self.n_design} points")
        self.design_res = self._run([Task(f"design-{k:03d}", design_task,
                                          {"setup": self.setup, "points": design[c].tolist()},
                                          label=f"design {k + 1}/{len(chunks)} ({c.size} runs)")
                                     for k, c in enumerate(chunks)])
        self.costs = np.concatenate([np.asarray(r["costs"], float) for r in self.design_res])
        self.order = [int(i) for i in np.argsort(self.costs, kind="stable")]
        self._screen_more(max(self.candidates, self.restarts))

    def _screen_more(self, count: int) -> bool:
        """Screen the next ``count`` design points (by design cost); False when none is left."""
        from estimation.search.executor import Task

        done = len(self.screened)
        cand = self.order[done:done + count]
        if not cand:
            return False
        best = min((float(r["cost"]) for r in self.screened), default=math.inf)
        n_stages = len(stages_of(self.pb, "screen"))
        self._say(f"screen: {len(cand)} candidates over {n_stages} first windows, the better half going on at "
                  "each" + (f" (best so far {best:.4g})" if done else ""))
        rows = [{"x": self.design[i].tolist(), "cost": math.inf, "per_stage": [], "message": "", "failures": 0,
                 "simulations": 0, "samples": 0, "failure_reasons": {}, "round": 0} for i in cand]
        alive = list(range(len(cand)))
        for st in range(n_stages):
            res = self._run([Task(f"screen-{done + k + 1}-{st + 1}", restart_task,
                                  {"setup": self.setup, "x0": rows[k]["x"], "simulations": self.per_stage,
                                   "part": f"screen:{st}", "name": f"screen {done + k + 1}",
                                   "progress_file": self._progress_file(f"screen-{done + k + 1}")},
                                  label=f"screen {done + k + 1} (design point {cand[k]}), window {st + 1}/{n_stages}")
                             for k in alive])
            for k, r in zip(alive, res):
                row = rows[k]
                row.update(x=r["x"], cost=float(r["cost"]), round=st + 1)
                row["per_stage"] += list(r.get("per_stage", []))
                row["message"] = "; then ".join(m for m in (row["message"], str(r["message"])) if m)
                for key in ("failures", "simulations", "samples"):
                    row[key] += int(r.get(key, 0))
                for why, f in dict(r.get("failure_reasons") or {}).items():
                    m = row["failure_reasons"].setdefault(why, {"runs": 0, "at": f.get("at", {})})
                    m["runs"] += int(f.get("runs", 0))
            # successive halving: the better half goes on to the next, longer window (at least restarts + 1)
            alive = sorted(alive, key=lambda k: rows[k]["cost"])[:max(self.restarts + 1, -(-len(alive) // 2))]
        self.screened += rows
        # the candidates that went furthest first, by cost; each from its own design point (independent starts:
        # two that screened to the same point and descend to the same end are two basins' worth of evidence)
        self.ranked = sorted(range(len(self.screened)),
                             key=lambda k: (-self.screened[k]["round"], self.screened[k]["cost"]))
        return True

    def start(self, k: int) -> Start | None:
        """The ``k``-th best screened end (each restart from its own design point: independent).

        The first two are always descended (two restarts are needed for agreement); further ones while
        fewer than two ends explain the record (:meth:`explains`), screening more design points when the
        distinct ends run out.
        """
        if not self.screened:
            self._design_and_screen()
        if k >= self.max_restarts:
            return None
        full = len(stages_of(self.pb, "screen"))
        while True:
            fresh = [j for j in self.ranked if j not in self.started]
            if fresh and self.screened[fresh[0]]["round"] >= full:
                break
            if not self._screen_more(self.candidates):  # the distinct, fully screened ends ran out
                if not fresh:
                    return None
                break
        j = fresh[0]
        self.started.add(j)
        sc = self.screened[j]
        runs = {str(p["stage"]): int(p["runs"]) for p in sc.get("per_stage", [])}
        return Start(np.asarray(sc["x"], float), float(sc["cost"]), runs, str(sc["message"]), {"screen": j + 1})

    def explains(self, r: np.ndarray) -> bool:
        """Whether a restart's end residual is the record's noise (:func:`estimation.fmu.verdict.chi_square`)."""
        from estimation.fmu.verdict import block_noise, chi_square

        return chi_square(r, block_noise(r, self.blocks), len(self.params.varying))["consistent"]

    def judge(self, x: np.ndarray, ends: Sequence[tuple[np.ndarray, float]]) -> dict[str, Any]:
        """The verdict of :func:`estimation.fmu.verdict.judge` on the answer ``x``."""
        from estimation.fmu.verdict import judge
        from estimation.verdict import noise_floor

        self._say("verdict")
        return judge(self.pb.residuals, self.params, x, ends, blocks=self.blocks,
                     data_noise=noise_floor(self.pb.data()))

    def descend(self, starts: Sequence[tuple[int, Start]]) -> list[End]:
        from estimation.search.executor import Task

        self._say(f"descend: restart(s) {', '.join(str(k + 1) for k, _ in starts)} to the whole record")
        res = self._run([Task(f"restart-{k + 1}", restart_task,
                              {"setup": self.setup, "x0": s.x.tolist(), "simulations": self.per_stage, "part": "rest",
                               "name": f"restart {k + 1}", "progress_file": self._progress_file(f"restart-{k + 1}")},
                              label=f"restart {k + 1} from screen {s.info['screen']} (cost {s.cost:.3g})")
                         for k, s in starts])
        out = []
        for (_, s), e in zip(starts, res):
            self.ends.append(e)
            runs = dict(s.runs)
            for p in e.get("per_stage", []):
                runs[str(p["stage"])] = runs.get(str(p["stage"]), 0) + int(p["runs"])
            msg = f"{s.message}; then {e['message']}"
            out.append(End(np.asarray(e["x"], float), float(e["cost"]), runs, msg,
                           {"failures": int(e["failures"]) + int(self.screened[s.info["screen"] - 1]["failures"]),
                            "message": msg}))
        return out

    def residuals(self, U: np.ndarray) -> np.ndarray:
        return self.pb.residuals(U)

    def data(self) -> np.ndarray:
        return self.pb.data()

    def polish(self, x: np.ndarray) -> tuple[np.ndarray, float, int, str] | None:
        before = self.pb.simulations
        self._say("polish: the best end once more on the whole record")
        t0 = time.perf_counter()
        last = [t0]

        def report(stage: str, runs: int, cost: float) -> None:
            if self.progress and time.perf_counter() - last[0] >= PROGRESS_EVERY_S:
                last[0] = time.perf_counter()
                print(f"  polish: {stage}: {runs} runs, best cost {cost:.4g}, {last[0] - t0:.0f} s",
                      file=sys.stderr, flush=True)

        out = staged_least_squares(lambda z, st: self.pb.residual(z, st[0], st[1]), np.asarray(x, float),
                                   stages_of(self.pb, "rest")[-1:], self.per_stage, lambda: self.pb.simulations,
                                   lambda st: stage_label(*st), float(self.setup["diff_step"]), finish=False,
                                   report=report, settled=_settled_on(self.pb))
        return np.asarray(out["x"], float), float(out["cost"]), self.pb.simulations - before, str(out["message"])


def failed_runs(stats: Sequence[Mapping[str, Any]], pb: Any) -> list[str]:
    """Failed runs by reason, most frequent first: ``"<reason> at k12=0.97, k23=0.95: 92 runs"``.

    The values named are those of the first such run that lie furthest from the middle of their bounds
    (unit cube), at most three: where the failing region is.
    """
    merged: dict[str, dict[str, Any]] = {}
    for st in stats:
        for key, row in dict(st.get("failure_reasons") or {}).items():
            m = merged.setdefault(key, {"runs": 0, "at": row.get("at", {})})
            m["runs"] += int(row.get("runs", 0))
    names = list(pb.params.varying)
    out = []
    for key, row in sorted(merged.items(), key=lambda kv: -kv[1]["runs"]):
        at = row["at"]
        where = ""
        if all(k in at for k in names):
            try:
                u = np.asarray(pb.params.to_unit({k: at[k] for k in names}), float)
                far = [names[j] for j in np.argsort(-np.abs(u - 0.5))[:3]]
                where = " at " + ", ".join(f"{k}={at[k]:.3g}" for k in names if k in far)
            except (ValueError, TypeError, KeyError):
                where = ""
        out.append(f"{key}{where}: {row['runs']} run{'s' if row['runs'] != 1 else ''}")
    return out


def run_fmu_estimate(cfg: Mapping[str, Any], out: str | os.PathLike[str] | None = None,
                     scheduler: str | None = None, workers: int | None = None, progress: bool = True,
                     base: str | Path = ".") -> dict[str, Any]:
    """Estimate FMU parameters from a waveform record (see the module docstring).

    Parameters
    ----------
    cfg : mapping
        The config.
    out : path, optional
        Results directory (stored design chunks and restarts; a rerun resumes).
        Default ``estimate-<fmu stem>-<config hash>``.
    scheduler : str, optional
        ``"processes"`` (default), ``"serial"`` or a Dask address ``tcp://host:port``.
    workers : int, optional
        Local worker processes (default: CPU count).
    progress : bool
        One line per finished task on stderr.
    base : path
        Directory relative paths of the config are taken from.

    Returns
    -------
    dict
        ``estimate``, ``cost``, ``fmu_simulations`` (runs of any window), ``fmu_record_equivalents``
        (simulated samples over the record's), ``failed_evaluations``,
        ``wall_s``, the verdict (``converged``, ``uncertainty``, ``non_identifiable`` ...),
        ``restarts``, ``errors_percent`` when the target gives true ``values``.
    """
    from estimation.recipe import run_recipe

    t0 = time.perf_counter()
    setup = make_setup(cfg, base)
    store = Path(out) if out is not None else _out_dir(cfg, setup)
    kind = FmuKind(setup, dict(cfg.get("budget", {})), int(cfg.get("seed", 1)), store, scheduler or "processes",
                   workers, progress)
    pb = kind.pb
    names = list(pb.params.varying)
    pb.reset_stats()
    # more restarts (further distinct screened ends) while fewer than two explain the record
    outcome = run_recipe(kind, kind.restarts, kind.max_restarts, progress=progress, label="estimate (FMU)")
    v, xb = outcome.verdict, outcome.x
    screened, ends, res = kind.screened, kind.ends, kind.design_res
    used = {r["screen"] - 1 for r in outcome.stages}
    sims = (sum(int(r["simulations"]) for r in list(res) + list(screened) + list(ends)) + pb.simulations)
    fails = (sum(int(r["failures"]) for r in list(res) + list(screened) + list(ends)) + pb.model.failures)
    samples = sum(int(r.get("samples", 0)) for r in list(res) + list(screened) + list(ends)) + pb.model.samples
    est = pb.values(xb)
    answer: dict[str, Any] = {
        "fmu": Path(setup["fmu"]).name, "approach": setup["approach"],
        "input": setup["input"], "input_hold": _hold_text(setup, pb), "input_hold_reason": setup["hold_reason"],
        "values": dict(setup["values"]),
        "estimate": {k: est[k] for k in names}, "tied": {k: est[k] for k in setup["ties"]},
        "cost": float(outcome.cost), "fmu_simulations": sims, "failed_evaluations": fails,
        "fmu_record_equivalents": samples / pb.n,
        "wall_s": time.perf_counter() - t0, "converged": v["converged"],
        "convergence_reason": v["convergence_reason"], "uncertainty": v["uncertainty"],
        "local_curvature": v["local_curvature"],
        "non_identifiable": v["non_identifiable"], "non_identifiable_reasons": v["non_identifiable_reasons"],
        "failed_runs": failed_runs(list(res) + list(screened) + list(ends) + [pb.stats()], pb),
        "verdict": {k: v[k] for k in ("residual_rms", "noise_floor", "noise_sigma", "chi_square", "tolerance",
                                      "at_bound", "restarts", "condition")},
        "design": {"points": kind.n_design, "best_cost": float(kind.costs.min()),
                   "failed": int(np.sum(kind.costs >= 1e3)), "scored_on": res[0].get("scored_on"),
                   "runs": int(sum(int(r["simulations"]) for r in res))},
        "screen": {"candidates": len(screened), "kept": len(used),
                   "runs": int(sum(int(r["simulations"]) for r in screened)),
                   "costs": [float(r["cost"]) for r in screened]},
        "restarts": [{"restart": r["restart"], "cost": r["cost"],
                      "simulations": int(r["evaluations"]) - 1, "failures": r["failures"],
                      "message": r["message"],
                      "runs_per_stage": [{"stage": k, "runs": n} for k, n in r["runs_per_stage"].items()],
                      "estimate": {kk: pb.values(np.asarray(e["x"]))[kk] for kk in names}}
                     for r, e in zip(outcome.stages, ends)],
        "runs_per_stage": {"design": int(sum(int(r["simulations"]) for r in res)),
                           "screen": int(sum(int(r["simulations"]) for r in screened)),
                           "continuation": int(sum(int(r["simulations"]) for r in ends)),
                           "verdict and polish": int(pb.simulations)},
        "out": str(store),
    }
    truth = (cfg.get("target") or {}).get("values")
    if isinstance(truth, dict):
        answer["target"] = {k: float(truth[k]) for k in names if k in truth}
        answer["errors_percent"] = {k: (est[k] - float(truth[k])) / float(truth[k]) * 100 for k in names
                                    if k in truth and float(truth[k]) != 0}
    return answer
