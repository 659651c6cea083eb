"""Command line: ``pris-cosim COMMAND ...`` (also ``python -m pris_cosim``).

With ``--json`` a command prints exactly one JSON object on stdout; progress,
warnings and logs go to stderr. Bad input exits with status 2 and one line
naming the problem.

Other packages add commands through the entry-point group
``pris_cosim.commands``: each entry is a function ``register(subparsers)``
that adds its sub-parser and sets ``func`` on it.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from pris_cosim import __version__
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.cli.common import (Interrupted, OneLineParser, UsageError, _complex_json, _emit, add_circuit_options,
    load_circuit)
from pris_cosim.errors import CircuitError, NonPassiveWarning
from pris_cosim.frf.response import Response, logspace_hz
from pris_cosim.models.builtin import Configuration, Model, ResponseSet, get_model, model_names


def _frf_parser(sub: Any) -> None:
    p = sub.add_parser("frf", help="analytic frequency responses of a netlist or built-in model")
    add_circuit_options(p)
    p.add_argument("--config", action="append", default=[], metavar="NAME",
                   help="test configuration of a model (LVOC, LVSC, HVOC, HVSC, LVHV, HVLV; repeat or comma-separate)")
    p.add_argument("--ratio", action="append", default=[], metavar="NODE", help="add V_<node> = V(node)/V(port)")
    p.add_argument("--short", action="append", default=[], metavar="NODE", help="tie a node to ground")
    p.add_argument("--fmin", type=float, default=10.0, help="lowest frequency, Hz (default 10)")
    p.add_argument("--fmax", type=float, default=1e6, help="highest frequency, Hz (default 1e6)")
    p.add_argument("--points", type=int, default=200, help="log-spaced points (default 200)")
    p.add_argument("--method", choices=("fast", "dense"), default="fast", help="pole-residue or dense solve")
    p.add_argument("--plot", metavar="FILE.png", help="write magnitude/phase plots")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_frf)


def _response_set(circuit: Circuit, model: Model | None, args: argparse.Namespace) -> ResponseSet:
    configs = [c.strip() for item in args.config for c in item.split(",") if c.strip()]
    if configs:
        if model is None:
            raise UsageError("--config needs --model (a netlist has no named test configurations; use --port)")
        if args.port or args.ratio or args.short:
            raise UsageError("--config cannot be combined with --port, --ratio or --short")
        return ResponseSet(circuit, [model.configuration(c) for c in configs])
    if args.port:
        port = circuit.require_node(args.port, "port")
        responses = (Response("Zin"),) + tuple(Response(f"V_{circuit.require_node(n, 'ratio node')}", n) for n in args.ratio)
        return ResponseSet(circuit, [Configuration("custom", port, tuple(args.short), responses)])
    if model is None:
        if len(circuit.ports) >= 1 and not args.ratio and not args.short:
            return ResponseSet(circuit, [Configuration("default", circuit.ports[0], (), (Response("Zin"),))])
        raise UsageError("missing --port: name the driven node of the netlist")
    if args.ratio or args.short:
        raise UsageError("--ratio and --short need --port")
    return model.response_set()


def cmd_frf(args: argparse.Namespace) -> int:
    circuit, model = load_circuit(args)
    rs = _response_set(circuit, model, args)
    f = logspace_hz(args.fmin, args.fmax, args.points)
    values = circuit.resolve()
    lam = circuit.smallest_inductance_eigenvalue(values)
    from pris_cosim.circuits.conditioning import check_response_set

    try:  # one line naming the element (and its file:line:column) when double precision cannot resolve the values
        check_response_set(rs, f)
    except CircuitError as exc:
        if args.netlist:
            from pathlib import Path

            from pris_cosim.circuits.netlist import locate_element

            raise CircuitError(f"{args.netlist}{locate_element(Path(args.netlist), str(exc))}: {exc}") from None
        raise CircuitError(f"--model {args.model}: {exc}") from None
    responses = rs.evaluate(f, method=args.method)
    if args.plot:
        from pris_cosim.plotting import plot_responses

        plot_responses(f, responses, args.plot, title=circuit.title)
    if args.json:
        _emit({
            "frequency_hz": [float(x) for x in f],
            "responses": {k: _complex_json(v) for k, v in responses.items()},
            "passive": bool(lam > 0),
            "smallest_inductance_eigenvalue_h": float(lam) if np.isfinite(lam) else None,
            "method": args.method,
        })
    else:
        names = list(responses)
        print("frequency_hz," + ",".join(f"{n}_mag,{n}_phase_deg" for n in names))
        for i, fi in enumerate(f):
            cells = [f"{fi:.6g}"] + [f"{abs(responses[n][i]):.9g},{np.degrees(np.angle(responses[n][i])):.6g}" for n in names]
            print(",".join(cells))
    return 0


# ---------------------------------------------------------------------- models
def _models_parser(sub: Any) -> None:
    p = sub.add_parser("models", help="list the built-in models and their parameters")
    p.add_argument("name", nargs="?", help="show one model")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_models)


def cmd_models(args: argparse.Namespace) -> int:
    names = [args.name] if args.name else [n if n != "cascade-N" else "cascade-4" for n in model_names()]
    out = []
    for name in names:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NonPassiveWarning)
            m = get_model(name)
        values = m.circuit.resolve()
        out.append({
            "name": m.name,
            "description": m.description,
            "configurations": {k: {"port": c.port, "shorts": list(c.shorts), "responses": [r.name for r in c.responses]}
                               for k, c in m.configurations.items()},
            "parameters": m.circuit.summary(),
            "fixed": list(m.fixed),
            "passive": bool(m.circuit.smallest_inductance_eigenvalue(values) > 0),
        })
    if args.json:
        _emit({"models": out})
        return 0
    for m in out:
        print(f"{m['name']}: {m['description']}")
        print(f"  configurations: {', '.join(m['configurations'])}; passive: {m['passive']}")
        if args.name:
            for row in m["parameters"]:
                expr = f"  = {row['expression']}" if row["expression"] else ""
                print(f"  {row['name']:>8} {row['value']:12.6g} {row['unit']}{expr}")
    return 0


# ---------------------------------------------------------------------- reproduce
def _reproduce_parser(sub: Any) -> None:
    p = sub.add_parser("reproduce", help="reproduce the thesis's simulated-perturbation figures (4.3-4.7, 4.11-4.12)")
    p.add_argument("figure", choices=("impedance-level", "two-section", "three-section", "all"))
    p.add_argument("--out", default="figures", metavar="DIR", help="directory for the PNG files (default: figures)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_reproduce)


def cmd_reproduce(args: argparse.Namespace) -> int:
    from pris_cosim.lab import reproductions as rp

    jobs = {"impedance-level": rp.impedance_level_study, "two-section": rp.two_section_responses,
            "three-section": rp.three_section_responses}
    names = list(jobs) if args.figure == "all" else [args.figure]
    out = {}
    for name in names:
        print(f"reproduce: {name} ...", file=sys.stderr, flush=True)
        out[name] = jobs[name](out_dir=args.out)
    if args.json:
        _emit({"figures": out, "out": args.out})
    else:
        for name, res in out.items():
            for key, m in res.items():
                print(f"{name} {key}: median error {m['median_rel_error']:.3%}, 90th percentile {m['p90_rel_error']:.3%}")
    return 0


# ---------------------------------------------------------------------- main
#: Commands of this package; the others come from the ``pris_cosim.commands`` entry points.
BUILTIN_COMMANDS = ("frf", "models", "reproduce", "simulate", "build-fmu", "lab")


def build_parser(plugins: bool = True) -> argparse.ArgumentParser:
    """The command-line parser; ``plugins=False`` leaves out the entry-point commands (faster start)."""
    parser = OneLineParser(prog="pris-cosim", description="PRIS perturbation, circuits, FMUs and estimation")
    parser.add_argument("--version", action="version", version=f"pris-cosim {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _frf_parser(sub)
    _models_parser(sub)
    _reproduce_parser(sub)
    from pris_cosim.cli.sim import register as register_simulation

    register_simulation(sub)
    from pris_cosim.cli.lab import register as register_lab

    register_lab(sub)
    if plugins:
        from importlib.metadata import entry_points

        for ep in entry_points(group="pris_cosim.commands"):
            ep.load()(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``pris-cosim`` console script.

    Returns the exit status: 0 on success, 2 for bad input (one line on
    stderr naming the file, line and column, the element or the option), 130
    when interrupted by Ctrl-C or SIGTERM (one line saying what was kept),
    1 for an internal error (one line; ``PRIS_COSIM_TRACEBACK=1`` prints the
    traceback).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(plugins=command not in BUILTIN_COMMANDS)  # a built-in command needs no plugin imports
    args = parser.parse_args(argv)
    prefix = f"pris-cosim {args.command}"
    restore = _terminate_as_interrupt()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default", NonPassiveWarning)
            # A numerical warning that reaches this level becomes the one-line error below.
            warnings.filterwarnings("error", category=RuntimeWarning)
            warnings.showwarning = _show_warning
            from pris_cosim.cli.checks import check_options

            check_options(args)
            return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:
        text = _one_line(exc) if str(exc) else "interrupted"
        print(f"{prefix}: {text}", file=sys.stderr, flush=True)
        return 130
    except RuntimeWarning as exc:
        print(f"{prefix}: error: numerical problem: {_one_line(exc)} (values outside the range the arithmetic "
              f"can resolve)", file=sys.stderr)
        return 2
    except (ValueError, OSError, ArithmeticError, RecursionError, MemoryError) as exc:
        print(f"{prefix}: error: {_one_line(exc) or type(exc).__name__}", file=sys.stderr)
        return 2
    except Exception as exc:
        if os.environ.get("PRIS_COSIM_TRACEBACK"):
            raise
        print(f"{prefix}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(PRIS_COSIM_TRACEBACK=1 shows the traceback)", file=sys.stderr)
        return 1
    finally:
        restore()


def _one_line(exc: BaseException, limit: int = 2000) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _terminate_as_interrupt() -> Any:
    """Make SIGTERM raise :class:`Interrupted` in the main thread; returns a function that undoes it."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def on_term(signum: int, frame: Any) -> None:
        raise Interrupted()

    previous = signal.signal(signal.SIGTERM, on_term)
    return lambda: signal.signal(signal.SIGTERM, previous)


def _show_warning(message: Any, category: Any, filename: str, lineno: int, file: Any = None, line: Any = None) -> None:
    print(f"pris-cosim: warning: {' '.join(str(message).split())}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
