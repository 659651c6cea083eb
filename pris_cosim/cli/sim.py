"""Command-line commands ``simulate`` and ``build-fmu`` (added by :func:`register`).

``simulate`` runs the PRIS arrangement (thesis Fig. 2.15) and writes the
waveform columns ``time_s,v_bprbs,v_in,i_in[,v_out]`` as ``.csv``, ``.npz``
or ``.mat`` (by the extension of ``--out``, :mod:`pris_cosim.measured.waveform_io`);
``--engine numpy`` is the in-process exact engine, computed and written in
chunks of bounded size (:func:`pris_cosim.lab.timedomain.pris_record`),
``--engine fmu`` builds the monolithic FMU and simulates it with fmpy.
Records that would fill the disk or memory, or run for more than an hour,
are refused before any work.
``build-fmu`` writes the DUT FMU, and with ``--with-source`` also the PRIS
source FMU and the monolithic source-plus-DUT FMU, each with its ``.mo`` text.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.cli.common import UsageError, _emit, add_circuit_options, load_circuit
from pris_cosim.models.builtin import Model
from pris_cosim.units import parse_value


def si_value(text: str) -> float:
    """A number with an optional SPICE scale suffix (``4m``, ``10n``, ``31.8k``) for argparse; every command reads values so."""
    try:
        return parse_value(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"cannot parse value {text!r} (a number such as 4m, 1u or 1e-6)") from None


def register(sub: Any) -> None:
    """Add the ``simulate`` and ``build-fmu`` sub-commands to an argparse sub-parser set."""
    p = sub.add_parser("simulate", help="PRIS waveforms of a netlist or model (time_s,v_bprbs,v_in,i_in as .csv/.npz/.mat)")
    add_circuit_options(p)
    _config_option(p)
    _source_options(p, required=True)
    p.add_argument("--fs", type=si_value, required=True, help="sampling frequency, Hz")
    p.add_argument("--periods", type=int, required=True, help="number of PRBS periods")
    p.add_argument("--out", required=True, metavar="FILE", help="waveform file to write; format by extension: "
                   ".csv, .npz (NumPy) or .mat (MATLAB v5), the same columns in each")
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
    b.add_argument("--ssp", action="store_true",
                   help="also write NAME.ssp: an SSP 1.0 system of two FMUs with their connections, parameter "
                        "values, default experiment and step guidance (needs --with-source)")
    b.add_argument("--split", choices=("bridge", "thesis"), default=None,
                   help="where --ssp cuts the arrangement: 'bridge' (default) = H-bridge FMU driving an FMU of the "
                        "series RLC and winding through the bridge voltage, exact in fixed-step masters at any step "
                        "dividing the PRBS bit; 'thesis' = source (bridge and RLC) and winding coupled by v_in and "
                        "i_in, which fixed-step masters need far smaller steps for")
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
        p.add_argument(flag, dest=dest, type=si_value, required=required, default=None,
                       help=f"PRIS source {dest}, {unit}" + ("" if required else f" (default {default.format(value)})"))
    p.add_argument("--prbs-order", dest="prbs_order", type=int, required=required, default=None,
                   help="LFSR order of the PRBS" + ("" if required else f" (default {default.format(d.prbs_order)})"))
    for flag, dest, unit in (("--rsnub", "rsnub", "Ohm"), ("--csnub", "csnub", "F"), ("--lsw", "lsw", "H"),
                             ("--csw", "csw", "F")):
        p.add_argument(flag, dest=dest, type=si_value, default=None,
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


#: Longest record ``simulate`` accepts, samples (about 43 GB of .npz for four columns).
MAX_SAMPLES = 2**30
#: Engine throughput assumed for the up-front time estimate, samples/s (conservative, 2 loaded cores).
_RATE = {"numpy": {"npz": 4e6, "mat": 4e6, "csv": 4e5}, "fmu": 5e4}
#: Longest run ``simulate`` starts, s.
MAX_SECONDS = 3600.0
#: Bytes held per sample by an engine that returns the whole record in memory (columns, copies, fmpy result).
_INMEM_BYTES = 160


def cmd_simulate(args: argparse.Namespace) -> int:
    """``simulate``: write the PRIS waveforms (.csv, .npz or .mat); with ``--json`` print samples, engine, wall_s, out."""
    from pris_cosim.lab.timedomain import CHUNK_SAMPLES, record_samples
    from pris_cosim.measured.waveform_io import check_target

    check_target(args.out)
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
    columns = ["time_s", "v_bprbs", "v_in", "i_in"] + (["v_out"] if probe else [])
    samples = record_samples(settings, args.fs, args.periods)
    _size_guard(args, samples, len(columns))
    comments = [f"pris-cosim simulate, engine {args.engine}: {circuit.title or 'circuit'} driven at {port}"
                + (f", shorted {', '.join(shorts)}" if shorts else ""),
                f"vdc={settings.vdc} V, prbs_order={settings.prbs_order}, fclk={settings.fclk} Hz, "
                f"rpris={settings.rpris} Ohm, lpris={settings.lpris} H, cpris={settings.cpris} F, fs={args.fs} Hz"]
    t0 = time.perf_counter()
    extra: dict[str, Any] = {}
    if args.engine == "numpy":
        from pris_cosim.lab.timedomain import pris_record
        from pris_cosim.measured.waveform_io import IN_MEMORY_BYTES

        record = pris_record(circuit, port, settings, args.fs, args.periods, shorts)
        whole = args.out.lower().endswith((".npz", ".mat")) and samples * 8 * len(columns) <= IN_MEMORY_BYTES
        pieces: Any = (_columns(w, probe) for w in record.chunks(None if whole else CHUNK_SAMPLES))
    else:
        run = _simulate_cosim if args.engine == "cosim" else _simulate_fmu
        w, extra = run(circuit, port, settings, shorts, args)
        samples = int(len(w["time_s"]))
        pieces = [_columns(w, probe)]
    _write(args.out, columns, pieces, samples, comments, t0)
    wall = time.perf_counter() - t0
    result = {"samples": samples, "engine": args.engine, "wall_s": wall, "out": str(args.out)} | extra
    if args.json:
        _emit(result)
    else:
        print(f"wrote {result['samples']} samples to {args.out} ({args.engine} engine, {wall:.3f} s)", file=sys.stderr)
    return 0


def _columns(w: dict[str, Any], probe: str | None) -> dict[str, Any]:
    """The waveform columns of an engine's output (``v_out`` = the probe's voltage)."""
    out = {k: w[k] for k in ("time_s", "v_bprbs", "v_in", "i_in")}
    if probe:
        out["v_out"] = w[f"v_{probe}"]
    return out


def _write(path: str, columns: list[str], pieces: Any, samples: int, comments: list[str], t0: float) -> None:
    """Write the record, with progress on stderr once it has run for more than two seconds."""
    from pris_cosim.measured.waveform_io import write_waveforms

    last = [t0]

    def progress(done: int) -> None:
        now = time.perf_counter()
        if now - t0 > 2.0 and now - last[0] > 2.0 and done < samples:
            last[0] = now
            print(f"simulate: {done / 1e6:.1f} of {samples / 1e6:.1f} M samples ({100 * done / samples:.0f} %), "
                  f"{now - t0:.0f} s", file=sys.stderr, flush=True)

    write_waveforms(path, columns, pieces, samples, comments, progress)


def _size_guard(args: argparse.Namespace, samples: int, columns: int) -> None:
    """Refuse, before any work, records that would fill the disk or memory or run for hours."""
    import shutil

    from pris_cosim.measured.waveform_io import bytes_per_sample, waveform_format

    fmt = waveform_format(args.out)
    what = (f"--periods {args.periods} of PRBS{args.prbs_order} at --fclk {args.fclk:g} Hz sampled at "
            f"--fs {args.fs:g} Hz give {samples:.3g} samples")
    fix = "lower --periods, --prbs-order or --fs"
    size = samples * bytes_per_sample(fmt, columns)
    if samples > MAX_SAMPLES:
        raise UsageError(f"{what} (about {_gb(size)} as .{fmt}), over the limit of {MAX_SAMPLES:.3g}; {fix}")
    directory = Path(args.out).parent
    free = shutil.disk_usage(directory if str(directory) else ".").free
    scratch = 2 if fmt != "csv" and samples * 8 * columns > (96 * 2**20) else 1  # spooled columns, then the archive
    if size * scratch > free:
        raise UsageError(f"{what}: about {_gb(size * scratch)} to write, {_gb(free)} free in "
                         f"{os.fspath(directory) or '.'}; {fix}")
    rate = _RATE["numpy"][fmt] if args.engine == "numpy" else _RATE.get(args.engine, _RATE["fmu"])
    seconds = samples / rate  # type: ignore[operator]
    if seconds > MAX_SECONDS:
        raise UsageError(f"{what}: about {seconds / 3600:.1f} h with --engine {args.engine}; {fix}")
    if args.engine != "numpy":  # whole record in memory
        need, avail = samples * _INMEM_BYTES, _available_memory()
        if avail is not None and need > avail:
            raise UsageError(f"{what}: about {_gb(need)} of memory with --engine {args.engine}, "
                             f"{_gb(avail)} available; {fix}")


def _gb(n: float) -> str:
    return f"{n / 1e9:.3g} GB" if n >= 1e8 else f"{n / 1e6:.3g} MB"


def _available_memory() -> int | None:
    """Available memory, bytes (``MemAvailable`` on Linux), or None when unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def _simulate_fmu(circuit: Circuit, port: str, settings: SourceSettings, shorts: tuple[str, ...],
                  args: argparse.Namespace) -> tuple[dict, dict[str, Any]]:
    """Build (or reuse) the monolithic FMU and run it with fmpy; returns waveforms and timing keys."""
    from pris_cosim.fmi.build import build_fmu
    from pris_cosim.fmi.codegen import arrangement_model
    from pris_cosim.fmi.cosim import FmuRunner, simulate_pris_fmu

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
    from pris_cosim.fmi.build import build_fmu
    from pris_cosim.fmi.codegen import dut_model, source_model
    from pris_cosim.fmi.cosim import FmuRunner, pris_samples
    from pris_cosim.fmi.cosim_exact import cosimulate_exact

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
    """``build-fmu``: write the FMUs (and .mo files); with ``--json`` print ``{"fmus": [paths]}``.

    With ``--ssp`` also the SSP 1.0 archive (``"ssp": path`` in the JSON): of the H-bridge and load FMUs
    (``--split bridge``, the default) or of the source and DUT FMUs (``--split thesis``).
    """
    from pris_cosim.fmi.build import build_pris_fmus
    from pris_cosim.fmi.thesis_cases import case_for

    if getattr(args, "ssp", False) and not args.with_source:
        raise ValueError("--ssp needs --with-source (the system couples the source FMU and the DUT FMU)")
    if getattr(args, "split", None) and not getattr(args, "ssp", False):
        raise ValueError("--split needs --ssp (it chooses the FMUs of the SSP system)")
    split = (getattr(args, "split", None) or "bridge") if getattr(args, "ssp", False) else None
    circuit, model = load_circuit(args)
    port, shorts = _port_and_shorts(circuit, model, args)
    case = case_for(model.name, port) if model is not None else None
    settings = _settings(args, case.settings if case else None) if args.with_source else None
    name = _base_name(args)
    same_prbs = case and settings and (settings.prbs_order, settings.fclk) == (case.settings.prbs_order,
                                                                               case.settings.fclk)
    experiment = case.fmu_experiment if same_prbs else None
    paths = build_pris_fmus(circuit, port, args.out, settings, shorts, name=name, experiment=experiment,
                            dut_experiment=case.fmu_experiment if case else None, fmi_version=args.fmi_version,
                            bridge_split=split == "bridge")
    fmus = [str(p) for p in paths.values()]
    ssp = None
    if split:
        from pris_cosim.fmi.codegen import arrangement_model
        from pris_cosim.fmi.ssp import fastest_period, step_guidance, write_ssp

        system = Path(paths["dut"]).stem.removesuffix("_dut")  # the FMUs' identifier base
        first, second = ("bridge", "load") if split == "bridge" else ("source", "dut")
        guidance = None
        if split == "thesis":
            from fmpy.model_description import read_model_description

            exp = read_model_description(str(paths["source"])).defaultExperiment
            guidance = step_guidance(split, float(exp.stepSize), settings.fclk,
                                     fastest_period(arrangement_model(circuit, port, settings, shorts)))
        ssp = str(write_ssp(paths[first], paths[second], Path(args.out) / f"{system}.ssp", name=system, split=split,
                            guidance=guidance))
    if args.json:
        _emit({"fmus": fmus} | ({"ssp": ssp} if ssp else {}))
    else:
        for f in fmus + ([ssp] if ssp else []):
            print(f)
    return 0
