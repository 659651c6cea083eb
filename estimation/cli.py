"""Command-line commands of the estimation package: ``study`` and ``estimate``.

Registered with the ``pris-cosim`` console script through the entry-point
group ``pris_cosim.commands`` (``study = "estimation.cli:register"``);
:func:`register` adds both sub-commands.

``pris-cosim study NAME [--quick] [--json] [--out DIR] [--scheduler ADDR] [--workers N] [--seed N]``
    Runs the estimation study NAME (``two-section``, ``three-section``,
    ``hv-transformer`` (thesis chapter 5; ``--measured FILE.csv`` fits measured
    responses instead of the virtual lab's, ``--cases 1,3`` a subset),
    ``real-data`` (fits of the real measured files)) through :func:`estimation.search.executor.run_tasks`: local
    processes by default, ``--scheduler serial`` in this process, or a Dask
    scheduler ``tcp://host:port``. Every finished run is written at once to
    ``DIR/runs/<id>.json`` and ``DIR/results.csv``; running again resumes
    (stored runs are not repeated). ``DIR/study.json`` holds the answer,
    figures go beside it. Default ``DIR``: ``study-<name>[-quick]``.
    With ``--json`` one JSON object goes to stdout (``rows``: ``case``,
    ``approach``, ``optimiser``, ``cost_function``, ``errors_percent``,
    ``non_identifiable``, ``cost``, ``wall_s`` ...; ``thesis``: the thesis's
    numbers; ``checks``); otherwise the comparison table. Progress on stderr.

``pris-cosim estimate --config FILE.json [--json] [--out DIR] [--scheduler ADDR] [--workers N] [--quiet]``
    One estimation described by a JSON file::

        {
          "model": "two-section",                 # built-in model (pris-cosim models)
          "parameters": {                         # estimated parameters (default: all free ones)
            "R1": {"min": 1, "max": 100},         #   SI bounds; or {"factor": 10}; "scale": "log"|"linear"
            "C1": {}, "L1": {}, "L2": {}, "K12": {"min": 0, "max": 0.99997}
          },
          "ties": {"R2": "R1", "C2": "C1"},       # optional: tied parameters
          "target": {                             # what the estimate is fitted to
            "kind": "simulated",                  #   "simulated": the model itself with "values" (default: its own)
            "values": {"R1": 10},                 #   "responses-csv": measured responses, "path": FILE.csv
            "method": "analytic"                  #   (interfaces CSV); "waveforms-csv": "path" (time/emd/iemd)
          },                                      #   simulated targets: "method" "analytic" or "pris" (Welch H1)
          "approach": "frequency",                # "frequency" (analytic estimate), "frequency-simulated",
                                                  # "time", "emd", "iemd"
          "responses": ["Zin"],                   # frequency approaches (default: all of the configuration;
                                                  # a response file: every configuration it holds, jointly)
          "frequency": {"fmin": 20, "fmax": 9000, "points": 200},   # default band: see estimation.estimate
          "source": {"vdc": 30, "prbs_order": 12, "fclk": 1e4, "rpris": 31800, "lpris": 2.53, "cpris": 1e-8},
          "fs": 300000, "duration": 0.3,          # simulated perturbation: sampling rate (Hz), record (s)
          "drive": "auto",                        # waveform records: "bridge" (recorded v_bprbs through the
                                                  # source's RLC; default when "source" is given), "current"
                                                  # (sampled current held linearly), see estimation.drives
          "cost": "sse",                          # "sse" (4.21), "rmse" (4.29/4.32/4.39/4.45), "correlation"
          "optimiser": "ga+local",                # stage 1: any estimation.search.optimisers.minimize method
          "options": {},                          # its options (default: estimation.estimate.default_plan)
          "budget": {"max_evals": 20000, "max_time_s": 60, "restarts": 3},
          "seed": 1
        }

    A ``"netlist": FILE`` with ``"port": NODE`` replaces ``"model"`` (parameters: element or
    ``.param`` names). An ``"fmu": FILE`` config (FMI 2.0/3.0 Co-Simulation in the loop, keys
    ``input``, ``output``, ``outputs``, ``current``, ``parameters``, ``ties``, ``target``,
    ``approach``, ``budget``, ``substeps``, ``diff_step``, ``first_window``, ``seed``, ``values``,
    ``input_hold``) goes to
    :mod:`estimation.fmu.estimate`; ``--out DIR``, ``--scheduler``, ``--workers`` apply to it.

    Defaults (``estimation.estimate``): GA + L-BFGS-B sized to the number of
    parameters, a least-squares polish on the approach's own residuals, 3
    restarts (more, up to 8, while none reaches the data's noise floor); for an
    input impedance with sharp resonances, the first stage also matches the
    resonance frequencies (refined by vector fitting) to the estimate's modes;
    the two-section model's thesis ties R2 = R1, C2 = C1 and the 4-section
    cascade's uniform winding (equal sections, couplings K12^d at distance d)
    when the config names neither parameters nor ties, the three-section model's
    Table 4.8 bounds when it names no parameters; mutual inductances searched as
    their coupling coefficient (|k| < 1 in the parametrisation).

    Answer (``--json``): ``estimate`` (exactly the values that were scored),
    ``errors_percent`` (for a simulated target with known values), ``cost``,
    ``engine``, ``per_eval_s``, ``nfev``/``evaluations``, ``wall_s``,
    ``message``, and the verdict (``estimation.verdict``): ``converged``,
    ``convergence_reason``, ``uncertainty`` {param: relative 1-sigma},
    ``non_identifiable``, ``verdict`` (residual RMS, noise floor, tolerance,
    parameters at a bound, restarts), ``restarts`` (per-restart costs). When
    not converged, one ``warning:`` line goes to stderr.

Bad input raises :class:`EstimationInputError` (a ``ValueError``): the main
CLI prints one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from estimation.search.executor import to_jsonable

STUDIES = ("two-section", "three-section", "hv-transformer", "real-data")


class EstimationInputError(ValueError):
    """Bad input for ``study`` or ``estimate`` (one line)."""


def _finite(obj: Any) -> Any:
    """JSON-ready copy with non-finite floats as None (strict JSON has no NaN/Infinity)."""
    obj = to_jsonable(obj)
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    return obj


def emit(obj: Any) -> None:
    """Exactly one JSON object on stdout."""
    sys.stdout.write(json.dumps(_finite(obj), allow_nan=False) + "\n")


# ====================================================================== study
def run_study_command(name: str, quick: bool = False, out: str | None = None, scheduler: str | None = None,
                      workers: int | None = None, seed: int = 1, progress: bool = True,
                      measured: str | None = None, cases: str | None = None, diagnose: bool = False,
                      seeds: int | None = None, snr_db: str | None = None, optimisers: str | None = None
                      ) -> dict[str, Any]:
    """Run a study by name; the dictionary that ``--json`` prints.

    ``measured`` (a responses CSV) and ``cases`` (comma-separated, e.g. ``"1,3"``) apply to
    ``hv-transformer`` only.
    """
    if name not in STUDIES:
        raise EstimationInputError(f"unknown study {name!r} (choose from {', '.join(STUDIES)})")
    if workers is not None and workers < 1:
        raise EstimationInputError(f"--workers must be at least 1 (got {workers})")
    if scheduler is not None and scheduler not in ("processes", "serial") and "://" not in scheduler:
        raise EstimationInputError(f"--scheduler must be 'processes', 'serial' or an address tcp://host:port (got {scheduler!r})")
    if (measured or diagnose) and name != "hv-transformer":
        raise EstimationInputError("--measured and --diagnose apply to the hv-transformer study only")
    if cases and name not in ("hv-transformer", "two-section"):
        raise EstimationInputError("--cases applies to the hv-transformer and two-section studies only")
    if (seeds is not None or snr_db or optimisers) and name != "three-section":
        raise EstimationInputError("--seeds, --snr-db and --optimisers apply to the three-section study only")
    if seed is not None and not (isinstance(seed, int) and 0 <= seed < 2**32):
        raise EstimationInputError(f"--seed must be an integer from 0 to {2**32 - 1} (got {seed})")
    out = out or f"study-{name}{'-quick' if quick else ''}"
    if name == "hv-transformer":
        from estimation.studies import hv_transformer

        chosen = [c.strip() for c in cases.split(",") if c.strip()] if cases else None
        for c in chosen or ():
            if c not in hv_transformer.CASES:
                raise EstimationInputError(f"unknown case {c!r} (cases: {', '.join(hv_transformer.CASES)})")
        if measured is not None and not Path(measured).is_file():
            raise EstimationInputError(f"measured data file not found: {measured}")
        return hv_transformer.run(quick=quick, out=out, scheduler=scheduler, workers=workers, seed=seed,
                                  progress=progress, measured=measured, cases=chosen, diagnose=diagnose)
    if name == "real-data":
        from estimation.studies import real_data

        return real_data.run(quick=quick, out=out, scheduler=scheduler, workers=workers, seed=seed, progress=progress)
    if name == "three-section":
        from estimation.studies.three_section import study as three_section

        levels, chosen_opts = _study_lists(snr_db, optimisers, three_section.OPTIMISERS)
        if seeds is not None and seeds < 1:
            raise EstimationInputError(f"--seeds must be at least 1 (got {seeds})")
        return three_section.run(quick=quick, out=out, scheduler=scheduler, workers=workers, seed=seed,
                                 progress=progress, seeds=seeds or 1, snr_db=levels, optimisers=chosen_opts)
    if name == "two-section":
        from estimation.studies import two_section

        chosen = [c.strip() for c in cases.split(",") if c.strip()] if cases else None
        for c in chosen or ():
            if c not in two_section.CASES:
                raise EstimationInputError(f"--cases: unknown case {c!r} (cases: {', '.join(two_section.CASES)})")
        return two_section.run(quick=quick, out=out, scheduler=scheduler, workers=workers, seed=seed,
                               progress=progress, cases=chosen)
    raise EstimationInputError(f"unknown study {name!r}")


def _study_lists(snr_db: str | None, optimisers: str | None, known: list[str]
                 ) -> tuple[list[float | str], list[str] | None]:
    """``--snr-db 60,40,20[,adc]`` and ``--optimisers pso,cma`` as lists (one-line errors)."""
    levels: list[float | str] = []
    for item in (snr_db or "").split(","):
        if not item.strip():
            continue
        if item.strip().lower() == "adc":
            levels.append("adc")
            continue
        try:
            v = float(item)
        except ValueError:
            raise EstimationInputError(f"--snr-db: {item.strip()!r} is not a number (dB) or 'adc'") from None
        if not np.isfinite(v):
            raise EstimationInputError(f"--snr-db: {item.strip()!r} is not a finite number (dB)")
        levels.append(v)
    chosen = [o.strip() for o in optimisers.split(",") if o.strip()] if optimisers else None
    for o in chosen or ():
        if o not in known:
            raise EstimationInputError(f"--optimisers: unknown optimiser {o!r} (choose from {', '.join(known)})")
    return levels, chosen


def _same_terminal() -> bool:
    """True when stdout and stderr are one terminal (a table in the progress is already on screen)."""
    import os

    try:
        return os.isatty(1) and os.isatty(2) and os.path.samestat(os.fstat(1), os.fstat(2))
    except OSError:
        return False


def cmd_study(args: argparse.Namespace) -> int:
    progress = not getattr(args, "quiet", False)
    summary = run_study_command(args.name, args.quick, args.out, args.scheduler, args.workers, args.seed,
                                progress=progress, measured=args.measured, cases=args.cases, diagnose=args.diagnose,
                                seeds=args.seeds, snr_db=args.snr_db, optimisers=args.optimisers)
    if args.json:
        emit(summary)
    else:
        if not (progress and _same_terminal()):  # the progress on stderr ends with the same table
            print(summary["table"])
        if summary.get("checks"):
            print("checks: " + ", ".join(f"{k}={'ok' if v else 'FAILED'}" for k, v in summary["checks"].items()))
        print(f"results in {summary['out']} ({summary['wall_s']:.1f} s)")
    return 0


# ====================================================================== estimate
def _need(cfg: dict[str, Any], key: str, kind: type | tuple[type, ...], default: Any = None) -> Any:
    value = cfg.get(key, default)
    if value is not None and not isinstance(value, kind):
        raise EstimationInputError(f"config key {key!r} has the wrong type ({type(value).__name__})")
    return value


def load_config(path: str | Path) -> dict[str, Any]:
    """Read and check the JSON configuration of ``estimate``."""
    try:
        cfg = json.loads(Path(path).read_text(encoding="utf-8"))
    except OSError as exc:
        raise EstimationInputError(f"cannot read config {path}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise EstimationInputError(f"config {path} is not valid JSON: {exc}") from None
    if not isinstance(cfg, dict):
        raise EstimationInputError(f"config {path} must hold a JSON object")
    known = {"model", "netlist", "port", "parameters", "ties", "target", "approach", "responses", "frequency", "source", "fs",
             "duration", "cost", "optimiser", "options", "budget", "seed", "configuration", "drive", "fmu", "input",
             "output", "outputs", "current", "substeps", "diff_step", "first_window", "design_score",
             "window_growth", "values", "input_hold"}
    unknown = sorted(set(cfg) - known)
    if unknown:
        raise EstimationInputError(f"config key {unknown[0]!r} is not known (known: {', '.join(sorted(known))})")
    return cfg


def _resolved(cfg: dict[str, Any], base: Path) -> dict[str, Any]:
    """The config with its relative file paths (``netlist``, ``target.path``) taken from ``base``."""
    cfg = dict(cfg)

    def fix(p: Any) -> Any:
        return str(base / p) if isinstance(p, str) and p and not Path(p).is_absolute() else p

    if "netlist" in cfg:
        cfg["netlist"] = fix(cfg["netlist"])
    if isinstance(cfg.get("target"), dict) and "path" in cfg["target"]:
        cfg["target"] = {**cfg["target"], "path": fix(cfg["target"]["path"])}
    return cfg


def _read_record(tgt: dict[str, Any]) -> Any:
    """The waveform record of a ``waveforms-csv`` target (one-line errors naming the file)."""
    from pris_cosim.measured.formats import read_waveform_csv

    path = tgt.get("path")
    if not isinstance(path, str):
        raise EstimationInputError("target key 'path' must name the waveform CSV file")
    if not Path(path).is_file():
        raise EstimationInputError(f"target file not found: {path}")
    try:
        return read_waveform_csv(path)
    except ValueError as exc:
        raise EstimationInputError(f"{path}: {exc}") from None


def _parameter_set(model: Any, cfg: dict[str, Any]) -> Any:
    from estimation.parameters import ParameterSet

    from estimation.estimate import DEFAULT_BASE, DEFAULT_BOUNDS, DEFAULT_TIES

    spec = _need(cfg, "parameters", dict, {})
    ties = _need(cfg, "ties", dict, {})
    if not spec and "ties" not in cfg:
        ties = dict(DEFAULT_TIES.get(model.name, {}))
    if not spec:
        spec = {k: {"min": lo, "max": hi} for k, (lo, hi) in DEFAULT_BOUNDS.get(model.name, {}).items()}
    if not spec and model.name in DEFAULT_BASE:
        from pris_cosim.models.builtin import get_model

        keep = set(model.circuit.free_names())
        spec = {k: {} for k in get_model(DEFAULT_BASE[model.name]).circuit.free_names() if k in keep}
    names = list(spec) + [t for t in ties if t not in spec] if spec else None
    bounds = {}
    for k, v in spec.items():
        if not isinstance(v, dict):
            raise EstimationInputError(f"parameter {k!r}: give an object such as {{\"min\": 1, \"max\": 10}}")
        if "min" in v or "max" in v:
            if not ("min" in v and "max" in v):
                raise EstimationInputError(f"parameter {k!r}: give both 'min' and 'max'")
            bounds[k] = (float(v["min"]), float(v["max"]))
        elif "factor" in v:
            bounds[k] = float(v["factor"])
    try:
        ps = ParameterSet.from_model(model, names=names, bounds=bounds or None, ties=ties or None)
        for k, v in spec.items():
            if "scale" in v:
                ps.set(k, scale=v["scale"])
    except (ValueError, KeyError) as exc:
        raise EstimationInputError(str(exc).strip("'\"")) from None
    return ps


def run_estimate(cfg: dict[str, Any], progress: bool = True, out: str | None = None, scheduler: str | None = None,
                 workers: int | None = None, base: str | Path = ".") -> dict[str, Any]:
    """One estimation from a configuration dictionary (see the module docstring).

    A config with ``"fmu"`` goes to :func:`estimation.fmu.estimate.run_fmu_estimate` (``out``,
    ``scheduler``, ``workers`` apply to it; relative paths are taken from ``base``).
    """
    if "fmu" in cfg:
        from estimation.fmu.estimate import run_fmu_estimate
        from estimation.fmu.model import FmuSetupError

        if workers is not None and workers < 1:
            raise EstimationInputError(f"--workers must be at least 1 (got {workers})")
        try:
            answer = run_fmu_estimate(cfg, out=out, scheduler=scheduler, workers=workers, progress=progress,
                                      base=base)
        except FmuSetupError as exc:
            raise EstimationInputError(str(exc)) from None
        if not answer["converged"]:
            print(f"warning: estimate not converged: {answer['convergence_reason']}", file=sys.stderr, flush=True)
        return answer
    for key in ("values", "input_hold"):
        if key in cfg:
            raise EstimationInputError(f"config key {key!r} applies only to a config with 'fmu'")
    cfg = _resolved(cfg, Path(base))
    from pris_cosim.lab import timedomain as td
    from pris_cosim.circuits.arrangement import SourceSettings
    from pris_cosim.measured.formats import read_response_csv
    from pris_cosim.models.builtin import get_model

    from estimation import approaches as ap

    t0 = time.perf_counter()
    try:
        if "netlist" in cfg:
            from estimation.netlist_model import model_from_netlist

            model = model_from_netlist(_need(cfg, "netlist", str, ""), _need(cfg, "port", str, ""))
        else:
            model = get_model(_need(cfg, "model", str, "two-section"))
    except Exception as exc:  # CircuitError is a ValueError
        raise EstimationInputError(str(exc)) from None
    conf = model.configuration(_need(cfg, "configuration", str, "default")) if "configuration" in cfg \
        else next(iter(model.configurations.values()))
    params = _parameter_set(model, cfg)
    approach_name = _need(cfg, "approach", str, "frequency")
    responses = _need(cfg, "responses", list, [r.name for r in conf.responses])
    metric = _need(cfg, "cost", str, "sse" if approach_name.startswith("frequency") else "rmse")
    tgt = _need(cfg, "target", dict, {"kind": "simulated"})
    kind = tgt.get("kind", "simulated")
    values = dict(tgt.get("values", {}))
    source_cfg = _need(cfg, "source", dict, {})
    try:
        source = SourceSettings(**source_cfg)
    except TypeError as exc:
        raise EstimationInputError(f"source: {exc}") from None
    fs = float(_need(cfg, "fs", (int, float), 300e3))
    duration = float(_need(cfg, "duration", (int, float), 0.3))
    fr = _need(cfg, "frequency", dict, {})
    from estimation.estimate import default_band

    band = (20.0, 9e3) if "fmin" in fr and "fmax" in fr else default_band(model, conf)
    fmin, fmax, points = float(fr.get("fmin", band[0])), float(fr.get("fmax", band[1])), int(fr.get("points", 200))
    circuit = model.circuit
    known_target: dict[str, float] | None = None
    proxy: Any = None
    if kind == "simulated":
        base = circuit.resolve(check=False)
        base.update(circuit.parameter_values())
        known_target = {}
        for p in params.varying:
            known_target[p] = float(values.get(p, base.get(p.lower(), params[p].value)))
    if approach_name in ("frequency", "frequency-simulated"):
        cost = ap.frequency_cost(metric, responses)
        if kind == "responses-csv":
            data = read_response_csv(tgt["path"])
            f = data.frequency_hz
            sel = (f >= fmin) & (f <= fmax)
            confs = [conf]
            if "configuration" not in cfg and "responses" not in cfg and len(model.configurations) > 1:
                # every configuration whose responses the file holds, compared jointly (thesis 5.3)
                confs = [c for c in model.configurations.values()
                         if all(r.name in data.responses for r in c.responses)] or [conf]
                conf = confs[0]
                responses = [r.name for c in confs for r in c.responses]
                cost = ap.frequency_cost(metric, responses)
            missing = [r for r in responses if r not in data.responses]
            if missing:
                raise EstimationInputError(f"response {missing[0]!r} is not in {tgt['path']}")
            target = {r: data.responses[r][sel] for r in responses}
            f = f[sel]
            if approach_name != "frequency":
                raise EstimationInputError("a measured response target needs approach 'frequency'")
            approach: ap.Approach = ap.AnalyticFrequency(params, model.response_set([c.name for c in confs]), f,
                                                         target, cost)
        elif kind == "simulated":
            specs = [ap.TWO_SECTION_SPECS.get(r, ap.ResponseSpec(r, "i_in", "v_in")) for r in responses]
            method = tgt.get("method", "analytic" if approach_name == "frequency" else "pris")
            if method == "analytic":
                f = np.logspace(np.log10(fmin), np.log10(fmax), points)
                target = {k: v[0] if v.ndim > 1 else v for k, v in
                          model.response_set([conf.name]).evaluate(f, values or None).items() if k in responses}
                if approach_name != "frequency":
                    raise EstimationInputError("approach 'frequency-simulated' needs a target with method 'pris'")
                approach = ap.AnalyticFrequency(params, model.response_set([conf.name]), f, target, cost)
            else:
                n = int(round(fs * duration))
                welch = ap.WelchSettings()
                bins, f = ap.bin_frequencies(fs, welch.segment(n), fmin, fmax, points)
                periods = -(-int(round(duration * source.fclk)) // (2 ** source.prbs_order - 1))
                w = td.simulate_pris(circuit, conf.port, source, fs, periods=periods, overrides=values or None)
                w = {k: v[:n] for k, v in w.items()}
                _, target, _ = ap.responses_from_waveforms(w, fs, specs, welch, bins)
                if approach_name == "frequency":
                    approach = ap.AnalyticFrequency(params, model.response_set([conf.name]), f, target, cost)
                else:
                    eng = ap.PrisEngine(circuit, conf.port, source, fs, n)
                    approach = ap.SimulatedFrequency(params, eng, specs, welch, bins, target, cost)
        elif kind == "waveforms-csv":
            approach, proxy = _frequency_from_record(approach_name, params, model, conf, source, _read_record(tgt),
                                                     "source" in cfg, metric, fmin, fmax, points)
        else:
            raise EstimationInputError(f"target kind {kind!r} does not suit approach {approach_name!r}")
    elif approach_name in ("time", "emd", "iemd"):
        probe_w: dict[str, np.ndarray] = {}
        v_bprbs: np.ndarray | None = None
        if kind == "waveforms-csv":
            wf = _read_record(tgt)
            i_in, v_in, v_bprbs = wf.i_in, wf.v_in, wf.v_bprbs
            fs = wf.fs
        elif kind == "simulated":
            periods = max(1, -(-int(round(duration * source.fclk)) // (2 ** source.prbs_order - 1)))
            w = td.simulate_pris(circuit, conf.port, source, fs, periods=periods, overrides=values or None)
            n = min(w["time_s"].size, int(round(fs * duration)))
            i_in, v_in = w["i_in"][:n], w["v_in"][:n]
            probe_w = {k: v[:n] for k, v in w.items() if k.startswith("v_") and k not in ("v_in", "v_bprbs")}
        else:
            raise EstimationInputError(f"target kind {kind!r} does not suit approach {approach_name!r}")
        from estimation.drives import choose_drive

        try:
            drive = choose_drive(_need(cfg, "drive", str, "auto"), "source" in cfg, v_bprbs is not None)
        except ValueError as exc:
            raise EstimationInputError(str(exc)) from None
        approach, proxy = _time_approach(approach_name, params, model, conf, source, fs, i_in, v_in, kind,
                                         metric, fmin, fmax, probe_w, v_bprbs if drive == "bridge" else None)
    else:
        raise EstimationInputError(f"approach must be frequency, frequency-simulated, time, emd or iemd (got {approach_name!r})")
    from estimation.estimate import resonance_proxy

    exact = kind == "responses-csv" or (kind == "simulated" and tgt.get("method", "analytic") == "analytic")
    if exact and proxy is None and isinstance(approach, ap.AnalyticFrequency):
        # response targets only: a record's Welch H1 smooths sharp resonances and shifts their peaks
        proxy = resonance_proxy(approach, params, circuit, conf)
    return _fit_and_report(cfg, approach, params, model, approach_name, metric, known_target, t0, progress,
                           proxy)


def _frequency_from_record(name: str, params: Any, model: Any, conf: Any, source: Any, wf: Any, source_known: bool,
                           metric: str, fmin: float, fmax: float, points: int) -> Any:
    """Frequency approaches against a waveform record's own Welch H1 ``Zin`` (bins with coherence >= 0.99).

    ``frequency``: the estimate's analytic ``Zin``; ``frequency-simulated``: the estimate's PRIS
    waveforms driven by the record's bridge voltage through the source's RLC (config ``source``
    required), through the same Welch estimator, with the analytic one as its stage-1 stand-in.

    Returns
    -------
    (approach, stand-in or None)
    """
    from estimation import approaches as ap
    from estimation.drives import RecordBridgeEngine

    fs, n = wf.fs, wf.n_samples
    welch = ap.WelchSettings()
    nper = welch.segment(n)
    lo, hi = max(fmin, 2 * fs / nper), min(fmax, fs / 4)
    if not hi > lo:
        raise EstimationInputError(f"frequency band {fmin:g}..{fmax:g} Hz is empty for this record")
    bins, f = ap.bin_frequencies(fs, nper, lo, hi, points)
    w = {"i_in": wf.i_in, "v_in": wf.v_in}
    spec = [ap.ZIN_SPEC["Zin"]]
    _, resp, coh = ap.responses_from_waveforms(w, fs, spec, welch, bins)
    keep = (coh["Zin"] >= 0.99) & np.isfinite(resp["Zin"]) & (np.abs(resp["Zin"]) > 0)
    if keep.sum() < 5:
        raise EstimationInputError("fewer than 5 frequency bins of the record have coherence >= 0.99")
    target = {"Zin": resp["Zin"][keep]}
    cost = ap.frequency_cost(metric, ["Zin"])
    analytic = ap.AnalyticFrequency(params, model.response_set([conf.name]), f[keep], target, cost)
    if name == "frequency":
        return analytic, None
    if not source_known:
        raise EstimationInputError("approach 'frequency-simulated' on a waveform record needs the source's R, L, C "
                                   "(config key 'source')")
    eng = RecordBridgeEngine(model.circuit, conf.port, source, fs, wf.v_bprbs, probes=[])
    return ap.SimulatedFrequency(params, eng, spec, welch, bins[keep], target, cost), analytic


def _time_approach(name: str, params: Any, model: Any, conf: Any, source: Any, fs: float, i_in: np.ndarray,
                   v_in: np.ndarray, kind: str, metric: str, fmin: float, fmax: float,
                   probes: dict[str, np.ndarray], v_bprbs: np.ndarray | None = None) -> tuple[Any, Any]:
    """Time/EMD/IEMD approach and its stage-1 stand-in.

    The stand-in of a record replayed by its bridge voltage is the arrangement's sampled (zero-order
    hold) response against the record's own map from ``v_bprbs`` (:mod:`estimation.bridge_response`);
    otherwise the analytic responses against the record's Welch H1 (:func:`estimation.estimate.waveform_proxy`).

    A simulated target is compared with the estimate driven by the same commanded bridge voltage
    through the source's series RLC (exact: the true parameters score zero); a recorded one
    by its recorded bridge voltage ``v_bprbs`` through the source's RLC when given (exact when
    the bridge switches on sample instants), else by its sampled current injected at the port,
    held linearly between samples (:mod:`estimation.drives`).
    """
    from estimation import approaches as ap
    from estimation import estimate as es

    m = "rmse" if metric in ("rmse", "nrmse", "sse") else "correlation"
    if kind == "simulated":
        eng: Any = ap.PrisEngine(model.circuit, conf.port, source, fs, int(np.size(v_in)),
                                 probes=[k[2:] for k in probes])
        cls: Any = {"time": es.RecordTime, "emd": es.RecordEMD, "iemd": es.RecordIEMD}[name]
        approach = cls(params, eng, v_in, m, chunk=16)
        approach.probe_targets = dict(probes)
        from estimation.bridge_response import bridge_response_proxy

        proxy = bridge_response_proxy(params, eng, {"v_in": v_in, **probes}, fmin, fmax)
        if proxy is not None:
            return approach, proxy
    elif v_bprbs is not None:
        from estimation.drives import RecordBridgeEngine

        eng = RecordBridgeEngine(model.circuit, conf.port, source, fs, v_bprbs, probes=[k[2:] for k in probes])
        cls = {"time": es.RecordTime, "emd": es.RecordEMD, "iemd": es.RecordIEMD}[name]
        approach = cls(params, eng, v_in, m, chunk=16)
        approach.probe_targets = dict(probes)
        approach.engine = approach.engine.replace("zoh-bridge", "recorded-bridge")
        from estimation.bridge_response import bridge_response_proxy

        # the record's own sampled map from the bridge voltage: no aliasing bias (estimation.bridge_response)
        proxy = bridge_response_proxy(params, eng, {"v_in": v_in, **probes}, fmin, fmax)
        if proxy is not None:
            return approach, proxy
    else:
        eng = ap.InjectionEngine(model.circuit, conf.port, i_in, fs, hold="linear")
        cls = {"time": ap.TimeDomain, "emd": ap.EMDApproach, "iemd": ap.IEMDApproach}[name]
        approach = cls(params, eng, v_in, m)
        approach.engine = approach.engine.replace("zoh-injection", "foh-injection")
    return approach, es.waveform_proxy(params, model.response_set([conf.name]), i_in, v_in, fs, fmin, fmax,
                                       configuration=conf, probes=probes)


def _fit_and_report(cfg: dict[str, Any], approach: Any, params: Any, model: Any, approach_name: str, metric: str,
                    known_target: dict[str, float] | None, t0: float, progress: bool, proxy: Any = None
                    ) -> dict[str, Any]:
    """Run the recipe of :mod:`estimation.estimate` and build the answer (estimate = the scored model)."""
    from estimation.estimate import default_plan, frequency_data, run_plan
    from estimation.search.optimisers import Budget

    b = _need(cfg, "budget", dict, {})
    plan = default_plan(approach.n)
    if "optimiser" in cfg:
        plan["method"] = _need(cfg, "optimiser", str)
        plan["options"] = _need(cfg, "options", dict, {})
    elif "options" in cfg:
        plan["options"] = _need(cfg, "options", dict, {})
    if b.get("max_evals") is not None:
        plan["budget"] = Budget(max_evals=max(1, int(b["max_evals"]) // int(plan["restarts"])))
        plan["max_restarts"] = plan["restarts"]  # a stated budget is not exceeded by extra restarts
        plan["least_squares_starts"] = 0  # nor by the stand-in's least-squares starts
    if "restarts" in b:
        plan["restarts"] = plan["max_restarts"] = int(b["restarts"])
    data = frequency_data(approach) if hasattr(approach, "target") else np.asarray(approach.v_target, float)
    try:
        outcome = run_plan(approach, params, data, seed=int(_need(cfg, "seed", int, 1)), plan=plan, proxy=proxy,
                           time_limit_s=b.get("max_time_s"), progress=progress,
                           noise=0.0 if known_target is not None else None)  # a simulated target is exact
    except ValueError as exc:
        raise EstimationInputError(str(exc)) from None
    ev = params.evaluate(outcome.x)
    est = {k: float(ev.values[k]) for k in params.varying}
    v = outcome.verdict
    out = {"model": model.name, "approach": approach_name, "engine": approach.engine, "cost_function": metric,
           "estimate": est, "cost": float(outcome.cost), "nfev": int(outcome.nfev), "evaluations": int(outcome.nfev),
           "per_eval_s": approach.stats.per_eval_s, "message": outcome.message,
           "converged": v["converged"], "convergence_reason": v["convergence_reason"],
           "uncertainty": v["uncertainty"], "non_identifiable": v["non_identifiable"],
           "non_identifiable_reasons": v["non_identifiable_reasons"],
           "verdict": {k: v[k] for k in ("residual_rms", "noise_floor", "noise_sigma", "tolerance", "at_bound", "restarts",
                                         "condition")},
           "restarts": outcome.stages, "wall_s": time.perf_counter() - t0}
    if known_target is not None:
        out["target"] = known_target
        out["errors_percent"] = {k: (est[k] - known_target[k]) / known_target[k] * 100 for k in est
                                 if known_target[k] != 0}
    if not v["converged"]:
        print(f"warning: estimate not converged: {v['convergence_reason']}", file=sys.stderr, flush=True)
    return out


def cmd_estimate(args: argparse.Namespace) -> int:
    # relative paths of a configuration are taken from its own folder
    out = run_estimate(load_config(args.config), progress=not getattr(args, "quiet", False),
                       out=getattr(args, "out", None), scheduler=getattr(args, "scheduler", None),
                       workers=getattr(args, "workers", None), base=Path(args.config).resolve().parent)
    if args.json:
        emit(out)
    else:
        for k, v in out["estimate"].items():
            e = out.get("errors_percent", {}).get(k)
            print(f"{k:>8} {v:14.6g}" + (f"  {e:+9.3f} %" if e is not None else ""))
        if "fmu_simulations" in out:
            print(f"cost {out['cost']:.6g}, {out['fmu_simulations']} FMU runs ({out['failed_evaluations']} failed), "
                  f"{out['wall_s']:.1f} s; results in {out['out']}")
        else:
            print(f"cost {out['cost']:.6g}, {out['nfev']} evaluations, {out['wall_s']:.1f} s ({out['engine']})")
    return 0


def register(subparsers: Any) -> None:
    """Add ``study`` and ``estimate`` to the ``pris-cosim`` sub-commands."""
    p = subparsers.add_parser("study", help=f"run an estimation study ({', '.join(STUDIES)})")
    p.add_argument("name", help=f"study: {', '.join(STUDIES)}")
    p.add_argument("--quick", action="store_true", help="reduced budgets (minutes), same conclusions")
    p.add_argument("--json", action="store_true", help="one JSON object on stdout")
    p.add_argument("--out", metavar="DIR", help="results directory (default study-NAME[-quick]); reruns resume")
    p.add_argument("--scheduler", metavar="ADDR", help="'processes' (default), 'serial' or a Dask address tcp://host:port")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: CPU count)")
    p.add_argument("--seed", type=int, default=1, help="optimiser seed (default 1; hv-transformer: the virtual lab's noise seed)")
    p.add_argument("--measured", metavar="FILE.csv", help="hv-transformer: fit these six measured responses "
                   "(interfaces CSV) instead of the virtual lab's")
    p.add_argument("--seeds", type=int, metavar="N", help="three-section: repeat every cell over N seeds "
                   "(rows add success_rate, errors_percent_median, evaluations, evals_per_s)")
    p.add_argument("--snr-db", metavar="LIST", help="three-section: also run with measurement noise on the target "
                   "waveforms at these SNRs, e.g. 60,40,20; 'adc' adds the cell measured through the virtual "
                   "lab's anti-alias filter and 16-bit ADC at 1 MS/s")
    p.add_argument("--optimisers", metavar="LIST", help="three-section: comma-separated subset of ga,pso,cma")
    p.add_argument("--cases", metavar="LIST", help="comma-separated subset of the cases: hv-transformer 1,2a,2b,3; "
                   "two-section 1,2,3,4,5")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--diagnose", action="store_true", help="hv-transformer: also diagnose what the best "
                   "estimate still gets wrong (frequency-dependent elements, a missing section ...)")
    p.set_defaults(func=cmd_study)
    q = subparsers.add_parser("estimate", help="one estimation from a JSON configuration")
    q.add_argument("--config", required=True, metavar="FILE.json")
    q.add_argument("--json", action="store_true", help="one JSON object on stdout")
    q.add_argument("--out", metavar="DIR", help="FMU estimates: results directory (a rerun resumes)")
    q.add_argument("--scheduler", metavar="ADDR", help="FMU estimates: 'processes' (default), 'serial' or a Dask "
                   "address tcp://host:port")
    q.add_argument("--workers", type=int, metavar="N", help="FMU estimates: local worker processes")
    q.add_argument("--quiet", action="store_true", help="no progress on stderr")
    q.set_defaults(func=cmd_estimate)
