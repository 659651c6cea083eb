"""SPICE-subset netlists: read and write :class:`~pris_cosim.circuit.Circuit`.

Accepted (see the project's interface notes): ``R``, ``L``, ``C`` elements
``NAME n1 n2 value``, couplings ``K NAME L1 L2 k``, independent ``V``/``I``
sources (kept, zeroed in small-signal analysis), values with SI suffixes or
``{expression}``, ``.param`` lines, ``*`` comment lines, ``;`` trailing
comments, ``+`` continuation lines; ``.control``/``.endc`` blocks and other
dot-lines are skipped. Names are case-insensitive and node ``0`` is ground.

Ports, probes and parameter units travel in comment directives that SPICE
ignores: ``*@ port in``, ``*@ probe mid``, ``*@ unit Cg F``.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from .circuit import Circuit, value_text
from .errors import CircuitError, NetlistError

_PARAM_RE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(\{[^}]*\}|[^\s{}=]+)")


def _logical_lines(text: str) -> list[tuple[int, str]]:
    """Join ``+`` continuation lines; strip ``;`` comments. Returns (line number, text)."""
    out: list[tuple[int, str]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.rstrip()
        stripped = line.lstrip()
        if not stripped.startswith("*"):
            line = line.split(";", 1)[0].rstrip()
            stripped = line.lstrip()
        if stripped.startswith("+") and out:
            out[-1] = (out[-1][0], out[-1][1] + " " + stripped[1:].strip())
        else:
            out.append((number, stripped))
    return out


def _split_tokens(text: str) -> list[str]:
    """Whitespace tokens, keeping ``{ ... }`` groups (which may hold spaces) whole."""
    return re.findall(r"\{[^}]*\}|[^\s{}]+", text)


def parse_netlist(text: str, source: str = "<netlist>") -> Circuit:
    """Parse netlist text into a Circuit.

    Parameters
    ----------
    text : str
        Netlist text.
    source : str
        File name used in error messages.

    Returns
    -------
    Circuit

    Raises
    ------
    NetlistError
        ``source:line: reason`` for anything that cannot be read.
    """
    circuit = Circuit()
    lines = _logical_lines(text)
    in_control = False
    units: dict[str, str] = {}
    for index, (number, line) in enumerate(lines):
        where = f"{source}:{number}"
        if not line:
            continue
        low = line.lower()
        if in_control:
            in_control = not low.startswith(".endc")
            continue
        if line.startswith("*"):
            body = line[1:].strip()
            if body.startswith("@"):
                _directive(circuit, units, body[1:].split(), where)
            elif index == 0 and not circuit.title:
                circuit.title = body
            else:
                circuit.comments.append(body)
            continue
        try:
            if low.startswith(".control"):
                in_control = True
            elif low.startswith(".param"):
                rest = line[len(".param"):].strip()
                pairs = _PARAM_RE.findall(rest)
                if not pairs or _PARAM_RE.sub("", rest).strip():
                    raise NetlistError(f"{where}: cannot parse .param line {line!r}")
                for name, value in pairs:
                    circuit.add_parameter(name, value)
            elif low.startswith((".subckt", ".include", ".lib")):
                raise NetlistError(f"{where}: {line.split()[0]} is not supported (flatten the netlist first)")
            elif line.startswith("."):
                continue
            else:
                _element(circuit, line, where)
        except NetlistError:
            raise
        except (CircuitError, ValueError) as exc:
            raise NetlistError(f"{where}: {exc}") from None
    for name, unit in units.items():
        try:
            p = circuit.parameter(name)
        except CircuitError:
            raise NetlistError(f"{source}: unit given for unknown parameter {name!r}") from None
        circuit.parameters[circuit.parameters.index(p)] = type(p)(p.name, p.value, unit, p.description)
    for role, nodes in (("port", circuit.ports), ("probe", circuit.probes)):
        for node in nodes:
            try:
                circuit.require_node(node, role)
            except CircuitError as exc:
                raise NetlistError(f"{source}: {exc}") from None
    return circuit


def _directive(circuit: Circuit, units: dict[str, str], words: list[str], where: str) -> None:
    if len(words) == 2 and words[0].lower() in ("port", "probe"):
        (circuit.ports if words[0].lower() == "port" else circuit.probes).append(words[1].lower())
    elif len(words) == 3 and words[0].lower() == "unit":
        units[words[1]] = words[2]
    else:
        raise NetlistError(f"{where}: unknown directive '*@ {' '.join(words)}'")


def _element(circuit: Circuit, line: str, where: str) -> None:
    tokens = _split_tokens(line)
    kind = tokens[0][0].upper()
    if kind in "VI":
        if len(tokens) < 3:
            raise NetlistError(f"{where}: source {tokens[0]!r} needs two nodes")
        spec = " ".join(tokens[3:])
        circuit.add(tokens[0], tokens[1], tokens[2], _source_dc(tokens[3:]), source_spec=spec)
        return
    if kind not in "RLCK":
        raise NetlistError(f"{where}: element type {kind!r} of {tokens[0]!r} is not supported (R, L, C, K, V, I)")
    if len(tokens) < 4:
        raise NetlistError(f"{where}: element {tokens[0]!r} needs two {'inductors' if kind == 'K' else 'nodes'} and a value")
    extra = [t for t in tokens[4:] if not re.match(r"(?i)^(ic|m|tc1|tc2)=", t)]
    if extra:
        raise NetlistError(f"{where}: element {tokens[0]!r}: unexpected {' '.join(extra)!r}")
    circuit.add(tokens[0], tokens[1], tokens[2], tokens[3])


def _source_dc(words: list[str]) -> float:
    """DC value of a source spec (``5``, ``DC 5 AC 1``, ``PULSE(...)``): 0 when absent."""
    from .units import is_number, parse_value

    if words and is_number(words[0]):
        return parse_value(words[0])
    for a, b in zip(words, words[1:]):
        if a.lower() == "dc" and is_number(b):
            return parse_value(b)
    return 0.0


def read_netlist(path: str | os.PathLike[str]) -> Circuit:
    """Read a netlist file.

    Parameters
    ----------
    path : path-like
        The netlist file.

    Returns
    -------
    Circuit
    """
    p = Path(path)
    try:
        text = p.read_text()
    except OSError as exc:
        raise NetlistError(f"{p}: cannot read netlist ({exc.strerror})") from None
    circuit = parse_netlist(text, str(p))
    if not circuit.elements:
        raise NetlistError(f"{p}: no circuit elements found")
    return circuit


def format_netlist(circuit: Circuit) -> str:
    """Netlist text of a circuit (valid ngspice input; reads back identically)."""
    lines = [f"* {circuit.title}" if circuit.title else "* circuit"]
    lines += [f"* {c}" for c in circuit.comments]
    lines += [f"*@ port {p}" for p in circuit.ports]
    lines += [f"*@ probe {p}" for p in circuit.probes]
    lines += [f"*@ unit {p.name} {p.unit}" for p in circuit.parameters if p.unit]
    lines += [f".param {p.name}={value_text(p.value)}" for p in circuit.parameters]
    for e in circuit.elements:
        if e.kind in "VI":
            lines.append(f"{e.name} {e.nodes[0]} {e.nodes[1]} {e.source_spec}".rstrip())
        else:
            lines.append(f"{e.name} {e.nodes[0]} {e.nodes[1]} {value_text(e.value)}")
    lines.append(".end")
    return "\n".join(lines) + "\n"


def write_text_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file, so no half-written file is left."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=p.parent, prefix=f".{p.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def write_netlist(circuit: Circuit, path: str | os.PathLike[str]) -> Path:
    """Write a circuit as a netlist file (atomically)."""
    return write_text_atomic(path, format_netlist(circuit))
