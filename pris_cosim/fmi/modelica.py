"""Modelica text (``.mo``) of a network FMU, for people who use Modelica tools.

The model uses the Modelica Standard Library 4 (``Modelica.Electrical.Analog``):
``Basic.Resistor``, ``Basic.Capacitor``, ``Basic.Inductor`` for uncoupled
inductors, and one ``Basic.M_Transformer`` (inductance matrix given as its
upper triangle ``L = {L11, L12, ..., L22, ...}``) per group of inductors
joined by K couplings. Parameters keep their names and ties; the FMU's inputs
and outputs become ``RealInput`` / ``RealOutput`` connectors of the same
names. The PRBS of a source is a Fibonacci LFSR: a ``when sample(...)``
equation on ``pre(reg)`` with the taps of
:data:`pris_cosim.signals.perturbation.MAX_LENGTH_TAPS` (no algorithm section). The FMU's
default experiment becomes the model's ``experiment`` annotation.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from pathlib import Path

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR
from pris_cosim.circuits.circuit import GROUND, Circuit, Element
from pris_cosim.fmi.codegen import OUT_INPUT, OUT_NODE, OUT_STATE, SOURCE_TERMINAL_INPUT, NetworkModel, parameter_order
from pris_cosim.circuits.expressions import Expression
from pris_cosim.circuits.netlist import write_text_atomic
from pris_cosim.signals.perturbation import MAX_LENGTH_TAPS

_KEYWORDS = {
    "algorithm", "and", "annotation", "block", "break", "class", "connect", "connector", "constant",
    "constrainedby", "der", "discrete", "each", "else", "elseif", "elsewhen", "encapsulated", "end",
    "enumeration", "equation", "expandable", "extends", "external", "false", "final", "flow", "for",
    "function", "if", "import", "impure", "in", "initial", "inner", "input", "loop", "model", "not",
    "operator", "or", "outer", "output", "package", "parameter", "partial", "protected", "public", "pure",
    "record", "redeclare", "replaceable", "return", "stream", "then", "true", "type", "when", "while", "within",
}
_SI = {"R": "SI.Resistance", "L": "SI.Inductance", "C": "SI.Capacitance"}
_PARAM_TYPES = {"Ohm": "SI.Resistance", "H": "SI.Inductance", "F": "SI.Capacitance", "Hz": "SI.Frequency",
                "V": "SI.Voltage", "A": "SI.Current", "s": "SI.Time"}
_HELPERS = {
    "pow(": '  function pow "a^b"\n    input Real a;\n    input Real b;\n    output Real y;\n'
            "  algorithm\n    y := a^b;\n  end pow;",
    "fabs(": '  function fabs "absolute value"\n    input Real a;\n    output Real y;\n'
             "  algorithm\n    y := abs(a);\n  end fabs;",
}


def _ident(name: str, taken: set[str]) -> str:
    base = re.sub(r"\W", "_", name)
    if not base or base[0].isdigit():
        base = "_" + base
    if base in _KEYWORDS:
        base += "_"
    ident = base
    k = 1
    while ident in taken:
        ident = f"{base}_{k}"
        k += 1
    taken.add(ident)
    return ident


def _coupled_groups(circuit: Circuit) -> list[list[Element]]:
    """Inductors joined by K couplings, each group in circuit order (singletons included)."""
    inductors = circuit.inductors()
    parent = {e.key: e.key for e in inductors}

    def find(k: str) -> str:
        while parent[k] != k:
            k = parent[k]
        return k

    for k in circuit.of_kind("K"):
        a, b = (find(n.lower()) for n in k.nodes)
        parent[a] = b
    groups: dict[str, list[Element]] = {}
    for e in inductors:
        groups.setdefault(find(e.key), []).append(e)
    return list(groups.values())


def modelica_text(model: NetworkModel) -> str:
    """Modelica source of the network of an FMU model.

    Parameters
    ----------
    model : NetworkModel

    Returns
    -------
    str
        One ``model`` with the FMU's identifier as its name.
    """
    circuit = model.circuit
    taken: set[str] = {"SI", "ground", "Iin", "i_in", "v_in", "v_bprbs", "vdc", "fclk", "prbs_order", "taps", "reg",
                       "feedback", "pow", "fabs"} | {o.variable.name for o in model.outputs}
    decl: list[str] = []
    eqs: list[str] = []
    pname: dict[str, str] = {}
    for p in parameter_order(circuit):
        pname[p.key] = _ident(p.name, taken)
    env = circuit.parameter_values()

    def value(v: float | Expression) -> str:
        return v.to_c(pname) if isinstance(v, Expression) else repr(float(v))

    for p in parameter_order(circuit):
        kind = _PARAM_TYPES.get(p.unit, "Real")
        rhs = value(p.value) if isinstance(p.value, Expression) else repr(float(env[p.key]))
        comment = f' "{p.description}"' if p.description else ""
        decl.append(f"  parameter {kind} {pname[p.key]} = {rhs}{comment};")

    def named(e: Element, kind: str) -> str:
        """A tied value as its expression; a numeric one as a parameter named after the element."""
        if isinstance(e.value, Expression):
            return f"({value(e.value)})"
        ident = _ident(e.name, taken)
        decl.append(f"  parameter {kind} {ident} = {float(e.value)!r} \"value of element {e.name}\";")
        return ident

    pins: dict[str, list[str]] = {}

    def attach(node: str, pin: str) -> None:
        pins.setdefault(node, []).append(pin)

    inst: dict[str, str] = {}
    for e in circuit.elements:
        if e.kind in "RC":
            name = inst[e.key] = _ident(e.name, taken)
            attr = "R" if e.kind == "R" else "C"
            cls = "Resistor" if e.kind == "R" else "Capacitor"
            decl.append(f"  Modelica.Electrical.Analog.Basic.{cls} {name}({attr} = {value(e.value)});")
            attach(e.nodes[0], f"{name}.p")
            attach(e.nodes[1], f"{name}.n")
        elif e.kind == "V":
            name = inst[e.key] = _ident(e.name, taken)
            if e.name.lower() in (BRIDGE.lower(), SOURCE_TERMINAL_INPUT.lower()):
                decl.append(f"  Modelica.Electrical.Analog.Sources.SignalVoltage {name};")
            else:  # other sources are zeroed, as in the analysis
                decl.append(f"  Modelica.Electrical.Analog.Sources.ConstantVoltage {name}(V = 0);")
            attach(e.nodes[0], f"{name}.p")
            attach(e.nodes[1], f"{name}.n")
    couplings = {frozenset(n.lower() for n in k.nodes): k for k in circuit.of_kind("K")}
    ind_current: dict[str, str] = {}
    for group in _coupled_groups(circuit):
        if len(group) == 1:
            e = group[0]
            name = inst[e.key] = _ident(e.name, taken)
            decl.append(f"  Modelica.Electrical.Analog.Basic.Inductor {name}(L = {value(e.value)});")
            attach(e.nodes[0], f"{name}.p")
            attach(e.nodes[1], f"{name}.n")
            ind_current[e.key] = f"{name}.i"
            continue
        name = _ident("M_" + "_".join(e.name for e in group), taken)
        text = {e.key: named(e, "SI.Inductance") for e in group}
        entries = []
        for i, a in enumerate(group):
            for b in group[i:]:
                if a is b:
                    entries.append(text[a.key])
                else:
                    k = couplings.get(frozenset((a.key, b.key)))
                    entries.append("0.0" if k is None else
                                   f"{named(k, 'Real')}*sqrt({text[a.key]}*{text[b.key]})")
        decl.append(f"  Modelica.Electrical.Analog.Basic.M_Transformer {name}(N = {len(group)}, L = {{"
                    + ", ".join(entries) + "}) \"" + ", ".join(e.name for e in group) + "\";")
        for j, e in enumerate(group, start=1):
            attach(e.nodes[0], f"{name}.p[{j}]")
            attach(e.nodes[1], f"{name}.n[{j}]")
            ind_current[e.key] = f"{name}.i[{j}]"
    decl.append("  Modelica.Electrical.Analog.Basic.Ground ground;")
    attach(GROUND, "ground.p")

    io_decl, io_eqs = _interface(model, inst, pins, ind_current)
    for node, plist in pins.items():
        for other in plist[1:]:
            eqs.append(f"  connect({plist[0]}, {other});")
    body = decl + io_decl
    text = "\n".join(body)
    helpers = [h for key, h in _HELPERS.items() if key in text]
    header = [
        f"model {model.identifier} {_quote(model.description or model.kind)}",
        "  import SI = Modelica.Units.SI;",
    ]
    trailer = [f"end {model.identifier};", ""]
    if model.experiment is not None:
        stop, step = model.experiment
        trailer.insert(0, f"  annotation(experiment(StartTime = 0.0, StopTime = {float(stop)!r}, "
                          f"Interval = {float(step)!r}));")
    parts = header + body + (["protected", *helpers] if helpers else []) + ["equation", *eqs, *io_eqs] + trailer
    return "\n".join(parts)


def _quote(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _node_potential(pins: Mapping[str, list[str]], node: str) -> str:
    return f"{pins[node][0]}.v"


def _interface(model: NetworkModel, inst: Mapping[str, str], pins: dict[str, list[str]],
               ind_current: Mapping[str, str]) -> tuple[list[str], list[str]]:
    """Connectors, PRBS generator and output equations of the FMU interface."""
    decl: list[str] = []
    eqs: list[str] = []
    nodes = model.mna.nodes
    s = model.settings
    if s is not None:
        order = int(s.prbs_order)
        taps = ", ".join(str(t) for t in MAX_LENGTH_TAPS[order])
        decl += [
            f"  parameter SI.Voltage vdc = {float(s.vdc)!r} \"H-bridge DC voltage (levels +-vdc)\";",
            f"  parameter SI.Frequency fclk = {float(s.fclk)!r} \"PRBS clock frequency\";",
            f"  parameter Integer prbs_order = {order} \"LFSR order n (period 2^n - 1 bits, n <= 30 here)\";",
            f"  parameter Integer taps[:] = {{{taps}}} \"maximal-length LFSR taps of this order\";",
            "  discrete Integer reg(start = integer(2^prbs_order) - 1, fixed = true) "
            "\"next prbs_order output bits, first one in the most significant bit (all-ones seed)\";",
            "  discrete Integer feedback(start = 0, fixed = true);",
        ]
    if model.kind == "dut":
        decl += ['  Modelica.Blocks.Interfaces.RealInput i_in "current injected into the port, A";',
                 "  Modelica.Electrical.Analog.Sources.SignalCurrent Iin;"]
        pins[GROUND].append("Iin.p")
        pins[model.port].append("Iin.n")
        eqs.append("  connect(i_in, Iin.i);")
    if model.kind == "load":
        decl.append('  Modelica.Blocks.Interfaces.RealInput v_bprbs "H-bridge voltage, V";')
        eqs.append(f"  connect(v_bprbs, {inst[BRIDGE.lower()]}.v);")
    if model.kind == "source":
        decl.append('  Modelica.Blocks.Interfaces.RealInput v_in "DUT terminal voltage, V";')
        eqs.append(f"  connect(v_in, {inst[SOURCE_TERMINAL_INPUT.lower()]}.v);")
    for o in model.outputs:
        v = o.variable
        decl.append(f"  Modelica.Blocks.Interfaces.RealOutput {v.name} {_quote(v.description + ', ' + v.unit)};")
        if o.kind == OUT_NODE:
            eqs.append(f"  {v.name} = {_node_potential(pins, nodes[o.index])};")
        elif o.kind == OUT_STATE:
            eqs.append(f"  {v.name} = {ind_current[SENSE_INDUCTOR.lower()]};")
        elif o.kind == OUT_INPUT:
            eqs.append(f"  {v.name} = if mod(div(reg, integer(2^(prbs_order - 1))), 2) == 1 then vdc else -vdc;")
    if s is not None:
        n_taps = len(MAX_LENGTH_TAPS[int(s.prbs_order)])
        bits = " + ".join(f"mod(div(pre(reg), integer(2^(taps[{j}] - 1))), 2)" for j in range(1, n_taps + 1))
        eqs.append(f"  {inst[BRIDGE.lower()]}.v = v_bprbs;")
        eqs += [
            "  when sample(1 / fclk, 1 / fclk) then  // one LFSR shift per clock: equations on pre(reg)",
            f"    feedback = mod({bits}, 2);",
            "    reg = mod(2 * pre(reg) + feedback, integer(2^prbs_order));",
            "  end when;",
        ]
    return decl, eqs


def write_modelica(model: NetworkModel, path: str | os.PathLike[str]) -> Path:
    """Write :func:`modelica_text` to ``path`` atomically; returns the path."""
    return write_text_atomic(path, modelica_text(model))


__all__ = ["modelica_text", "write_modelica"]
