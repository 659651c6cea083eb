"""What every command of the command line shares: the one-line usage error, JSON output, circuit options."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.models.builtin import Model, get_model, model_names
from pris_cosim.units import parse_value


class UsageError(ValueError):
    """Bad command-line input."""


class Interrupted(KeyboardInterrupt):
    """The command was stopped by Ctrl-C or SIGTERM; the message says what was kept (exit status 130)."""


class OneLineParser(argparse.ArgumentParser):
    """Argument parser whose errors are one line on stderr (exit status 2), not the usage text."""

    def error(self, message: str) -> Any:  # type: ignore[override]
        text = " ".join(str(message).split())
        self.exit(2, f"{self.prog}: error: {text} (see {self.prog} --help)\n")


def _finite_json(obj: Any) -> Any:
    """Copy of ``obj`` with non-finite floats as None (strict JSON has no NaN or Infinity)."""
    if isinstance(obj, float):
        return obj if obj == obj and obj not in (float("inf"), float("-inf")) else None
    if isinstance(obj, dict):
        return {k: _finite_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite_json(v) for v in obj]
    return obj


def _emit(obj: Any) -> None:
    sys.stdout.write(json.dumps(_finite_json(obj), allow_nan=False) + "\n")


def _complex_json(values: np.ndarray) -> dict[str, list[float]]:
    return {"re": [float(x) for x in np.real(values)], "im": [float(x) for x in np.imag(values)]}


def parse_sets(items: Sequence[str]) -> dict[str, float]:
    """``NAME=VALUE`` pairs (values with SI suffixes) from ``--set`` options."""
    out: dict[str, float] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise UsageError(f"--set expects NAME=VALUE (got {item!r})")
        try:
            out[name.strip()] = parse_value(value)
        except ValueError:
            raise UsageError(f"--set {name.strip()}: cannot parse value {value!r}") from None
    return out


def add_circuit_options(p: argparse.ArgumentParser, port_required: bool = False) -> None:
    """``--netlist/--model``, ``--port``, ``--set`` options shared by circuit commands."""
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--netlist", metavar="FILE", help="SPICE-subset netlist")
    src.add_argument("--model", metavar="NAME", help=f"built-in model ({', '.join(model_names())})")
    p.add_argument("--port", metavar="NODE", required=port_required, help="driven node")
    p.add_argument("--set", metavar="NAME=VALUE", action="append", default=[], help="override a parameter or element value")


def load_circuit(args: argparse.Namespace) -> tuple[Circuit, Model | None]:
    """The circuit named by ``--netlist`` or ``--model`` with ``--set`` overrides applied."""
    from pris_cosim.circuits.netlist import read_netlist

    if args.netlist:
        circuit, model = read_netlist(args.netlist), None
        from pris_cosim.cli.checks import check_circuit_size

        check_circuit_size(circuit, getattr(args, "command", ""))
    else:
        model = get_model(args.model)
        circuit = model.circuit
    sets = parse_sets(args.set)
    if sets:
        from pris_cosim.circuits.netlist import check_ranges

        try:
            circuit = circuit.with_values(sets)
            check_ranges(circuit)
        except CircuitError as exc:
            raise UsageError(f"--set: {exc}") from None
        if model is not None:
            model = Model(model.name, model.description, circuit, model.configurations, model.fixed)
    return circuit, model


# ---------------------------------------------------------------------- frf
