"""Command-line commands ``simulate`` and ``build-fmu`` (added by :func:`register`).

``simulate`` runs the PRIS arrangement (thesis Fig. 2.15) and writes the
waveform CSV ``time_s,v_bprbs,v_in,i_in[,v_out]``; ``--engine numpy`` is the
in-process exact engine (:func:`pris_cosim.timedomain.simulate_pris`),
``--engine fmu`` builds the monolithic FMU and simulates it with fmpy.
``build-fmu`` writes the DUT FMU, and with ``--with-source`` also the PRIS
source FMU and the monolithic source-plus-DUT FMU, each with its ``.mo`` text.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from .arrangement import SourceSettings
from .circuit import Circuit
from .cli import UsageError, _emit, add_circuit_options, load_circuit
from .models import Model
from .units import parse_value


def _si(text: str) -> float:
    """A number with an optional SI suffix (``4m``, ``10n``, ``31.8k``) for argparse."""
    try:
        return parse_value(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"cannot parse value {text!r}") from None


def register(sub: Any) -> None:
    """Add the ``simulate`` and ``build-fmu`` sub-commands to an argparse sub-parser set."""
    p = sub.add_parser("simulate", help="PRIS waveforms of a netlist or model (CSV time_s,v_bprbs,v_in,i_in)")
    add_circuit_options(p)
    _config_option(p)
    _source_options(p, required=True)
    p.add_argument("--fs", type=_si, required=True, help="sampling frequency, Hz")
    p.add_argument("--periods", type=int, required=True, help="number of PRBS periods")
    p.add_argument("--out", required=True, metavar="FILE.csv", help="waveform CSV to write")
    p.add_argument("--engine", choices=("numpy", "fmu", "cosim"), default="numpy",
                   help="numpy: exact in-process ZOH engine (default); fmu: monolithic FMU run by fmpy; "
                        "cosim: source FMU and winding FMU coupled exactly by the master")
    p.add_argument("--probe", metavar="NODE", help="write v(NODE) as the v_out column")
    p.add_argument("--fmu-dir", metavar="DIR", help="keep the FMU built by --engine fmu here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)

    b = sub.add_parser("build-fmu", help="build FMI 2.0 or 3.0 FMUs (co-simulation + model exchange) of a network")
    add_circuit_options(b)
    _config_option(b)
    b.add_argument("--out", required=True, metavar="DIR", help="directory for the .fmu and .mo files")
    b.add_argument("--with-source", action="store_true",
                   help="also build the PRIS source FMU and the monolithic source+DUT FMU")
    b.add_argument("--name", help="base name of the FMUs (default: model or netlist name)")
    b.add_argument("--fmi-version", dest="fmi_version", type=int, choices=(2, 3), default=2,
                   help="FMI version of the FMUs (default 2)")
    _source_options(b, required=False)
    b.add_argument("--json", action="store_true", help="print one JSON object")
    b.set_defaults(func=cmd_build_fmu)


def _config_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", metavar="NAME", help="test configuration of a model (port and shorted nodes)")


def _source_options(p: argparse.ArgumentParser, required: bool) -> None:
    d = SourceSettings()
    default = "the model's thesis case, else {}"
    for flag, dest, unit, value in (("--vdc", "vdc", "V", d.vdc), ("--fclk", "fclk", "Hz", d.fclk),
                                    ("--rpris", "rpris", "Ohm", d.rpris), ("--lpris", "lpris", "H", d.lpris),
                                    ("--cpris", "cpris", "F", d.cpris)):
        p.add_argument(flag, dest=dest, type=_si, required=required, default=None,
                       help=f"PRIS source {dest}, {unit}" + ("" if required else f" (default {default.format(value)})"))
    p.add_argument("--prbs-order", dest="prbs_order", type=int, required=required, default=None,
                   help="LFSR order of the PRBS" + ("" if required else f" (default {default.format(d.prbs_order)})"))
    for flag, dest, unit in (("--rsnub", "rsnub", "Ohm"), ("--csnub", "csnub", "F"), ("--lsw", "lsw", "H"),
                             ("--csw", "csw", "F")):
        p.add_argument(flag, dest=dest, type=_si, default=None,
                       help=f"optional source {dest}, {unit} (default {'the thesis case, else ' if not required else ''}0)")


def _settings(args: argparse.Namespace, base: SourceSettings | None = None) -> SourceSettings:
    """Source settings from the options; options not given come from ``base`` (default :class:`SourceSettings`)."""
    base = base or SourceSettings()
    names = ("vdc", "prbs_order", "fclk", "rpris", "lpris", "cpris", "rsnub", "csnub", "lsw", "csw")
    return SourceSettings(**{n: getattr(base, n) if getattr(args, n) is None else getattr(args, n) for n in names})


def _port_and_shorts(circuit: Circuit, model: Model | None, args: argparse.Namespace) -> tuple[str, tuple[str, ...]]:
    if args.config:
        if model is None:
            raise UsageError("--config needs --model (a netlist has no named test configurations; use --port)")
        if args.port:
            raise UsageError("--config cannot be combined with --port")
        cfg = model.configuration(args.config)
        return cfg.port, tuple(cfg.shorts)
    if args.port:
        return circuit.require_node(args.port, "port"), ()
    if model is not None and len(model.configurations) == 1:
        cfg = next(iter(model.configurations.values()))
        return cfg.port, tuple(cfg.shorts)
    if model is None and circuit.ports:
        return circuit.ports[0], ()
    raise UsageError("missing --port (or --config for a model with several test configurations)")


def _base_name(args: argparse.Namespace) -> str:
    """FMU base name: ``--name``, else the model (and configuration) or the netlist file's stem."""
    if getattr(args, "name", None):
        return args.name
    if args.model:
        return args.model + (f"_{args.config}" if args.config else "")
    return Path(args.netlist).stem


def cmd_simulate(args: argparse.Namespace) -> int:
    """``simulate``: write the PRIS waveform CSV; with ``--json`` print samples, engine, wall_s, out."""
    from .measured import Waveforms, write_waveform_csv

    circuit, model = load_circuit(args)
    port, shorts = _port_and_shorts(circuit, model, args)
    settings = _settings(args)
    if not args.fs > 0:
        raise UsageError(f"--fs must be positive (got {args.fs})")
    if args.periods < 1:
        raise UsageError(f"--periods must be at least 1 (got {args.periods})")
    probe = None
    if args.probe:
        probe = circuit.require_node(args.probe, "probe")
        if probe in shorts or probe == port:
            raise UsageError(f"--probe {args.probe}: node is the port or shorted")
        if probe not in circuit.probes:
            circuit = circuit.copy()
            circuit.probes.append(probe)
    t0 = time.perf_counter()
    extra: dict[str, Any] = {}
    if args.engine == "numpy":
        from .timedomain import simulate_pris

        w = simulate_pris(circuit, port, settings, args.fs, args.periods, shorts)
    elif args.engine == "cosim":
        w, extra = _simulate_cosim(circuit, port, settings, shorts, args)
    else:
        w, extra = _simulate_fmu(circuit, port, settings, shorts, args)
    wall = time.perf_counter() - t0
    comments = [f"pris-cosim simulate, engine {args.engine}: {circuit.title or 'circuit'} driven at {port}"
                + (f", shorted {', '.join(shorts)}" if shorts else ""),
                f"vdc={settings.vdc} V, prbs_order={settings.prbs_order}, fclk={settings.fclk} Hz, "
                f"rpris={settings.rpris} Ohm, lpris={settings.lpris} H, cpris={settings.cpris} F, fs={args.fs} Hz"]
    v_out = w[f"v_{probe}"] if probe else None
    write_waveform_csv(args.out, Waveforms(w["time_s"], w["v_bprbs"], w["v_in"], w["i_in"], v_out,
                                           comments=comments))
    result = {"samples": int(len(w["time_s"])), "engine": args.engine, "wall_s": wall, "out": str(args.out)} | extra
    if args.json:
        _emit(result)
    else:
        print(f"wrote {result['samples']} samples to {args.out} ({args.engine} engine, {wall:.3f} s)", file=sys.stderr)
    return 0


def _simulate_fmu(circuit: Circuit, port: str, settings: SourceSettings, shorts: tuple[str, ...],
                  args: argparse.Namespace) -> tuple[dict, dict[str, Any]]:
    """Build (or reuse) the monolithic FMU and run it with fmpy; returns waveforms and timing keys."""
    from .codegen import arrangement_model
    from .cosim import FmuRunner, simulate_pris_fmu
    from .fmi import build_fmu

    name = _base_name(args) + "_pris"
    t0 = time.perf_counter()
    model = arrangement_model(circuit, port, settings, shorts, name=name)
    with tempfile.TemporaryDirectory(prefix="pris-sim-") as tmp:
        path = build_fmu(model, args.fmu_dir or tmp, write_modelica=bool(args.fmu_dir))
        build_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        with FmuRunner(path) as runner:
            w = simulate_pris_fmu(runner, settings, args.fs, args.periods)
    info: dict[str, Any] = {"build_s": build_s, "run_s": time.perf_counter() - t1}
    if args.fmu_dir:
        info["fmu"] = str(path)
    return w, info


def _simulate_cosim(circuit: Circuit, port: str, settings: SourceSettings, shorts: tuple[str, ...],
                    args: argparse.Namespace) -> tuple[dict, dict[str, Any]]:
    """Build (or reuse) the source and winding FMUs and couple them exactly; adds ``coupling_error``."""
    from .codegen import dut_model, source_model
    from .cosim import FmuRunner, pris_samples
    from .cosim_exact import cosimulate_exact
    from .fmi import build_fmu

    base = _base_name(args)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="pris-cosim-") as tmp:
        where = args.fmu_dir or tmp
        src = build_fmu(source_model(settings, name=f"{base}_source"), where, write_modelica=bool(args.fmu_dir))
        dut = build_fmu(dut_model(circuit, port, shorts, name=f"{base}_dut"), where, write_modelica=bool(args.fmu_dir))
        build_s = time.perf_counter() - t0
        t1 = time.perf_counter()
        with FmuRunner(src, "ModelExchange") as s_run, FmuRunner(dut, "ModelExchange") as d_run:
            probes = [f"v_{args.probe}"] if args.probe else []
            w, err = cosimulate_exact(s_run, d_run, args.fs, pris_samples(settings, args.fs, args.periods),
                                      probes=probes)
    info: dict[str, Any] = {"build_s": build_s, "run_s": time.perf_counter() - t1, "coupling_error": err}
    if args.fmu_dir:
        info["fmus"] = [str(src), str(dut)]
    return w, info


def cmd_build_fmu(args: argparse.Namespace) -> int:
    """``build-fmu``: write the FMUs (and .mo files); with ``--json`` print ``{"fmus": [paths]}``."""
    from .fmi import build_pris_fmus

    from .thesis_cases import case_for

    circuit, model = load_circuit(args)
    port, shorts = _port_and_shorts(circuit, model, args)
    case = case_for(model.name, port) if model is not None else None
    settings = _settings(args, case.settings if case else None) if args.with_source else None
    name = _base_name(args)
    same_prbs = case and settings and (settings.prbs_order, settings.fclk) == (case.settings.prbs_order,
                                                                               case.settings.fclk)
    experiment = case.experiment if same_prbs else None
    paths = build_pris_fmus(circuit, port, args.out, settings, shorts, name=name, experiment=experiment,
                            dut_experiment=case.experiment if case else None, fmi_version=args.fmi_version)
    fmus = [str(p) for p in paths.values()]
    if args.json:
        _emit({"fmus": fmus})
    else:
        for f in fmus:
            print(f)
    return 0
