"""SPICE-subset netlists: read and write :class:`~pris_cosim.circuits.circuit.Circuit`.

Accepted, a subset of ngspice's grammar: ``R``, ``L``, ``C`` elements
``NAME n1 n2 value [ic=..] [m=1] [tc1=..] [tc2=..]``, couplings
``K NAME L1 L2 k``, independent ``V``/``I`` sources (kept, zeroed in
small-signal analysis), values as decimal numbers with SI suffixes or
``{expression}``, ``.param NAME=VALUE ...`` lines, ``*`` comment lines,
``;`` trailing comments, ``+`` continuation lines; ``.control``/``.endc``
blocks and other dot-lines are skipped; ``.subckt``, ``.include`` and
``.lib`` are refused. Names are case-insensitive and node ``0`` is ground.

Reading is strict: an unbalanced brace, a hexadecimal or otherwise
malformed number, and anything after a value are refused with
``file:line:column``. After the parameters are evaluated, every value must
lie in the physical range of its kind
(:data:`pris_cosim.units.ELEMENT_RANGES`), or it is refused naming the
element and the column of its value.

Ports, probes and parameter units travel in comment directives that SPICE
ignores: ``*@ port in``, ``*@ probe mid``, ``*@ unit Cg F``.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

from pris_cosim.circuits.circuit import Circuit, value_text
from pris_cosim.errors import CircuitError, ExpressionError, NetlistError
from pris_cosim.circuits.expressions import Expression
from pris_cosim.units import is_number, parse_value, range_problem

Token = tuple[str, int, int]  # text, line, column (1-based)

#: Longest accepted netlist file, bytes.
MAX_BYTES = 64 * 1024 * 1024
#: Instance parameters accepted after an R, L or C value (``m`` only as 1; the others do not change a
#: small-signal value at the nominal temperature).
_INSTANCE_PARAMETERS = ("ic", "m", "tc1", "tc2", "temp", "dtemp")


def _tokens(line: str, number: int, source: str) -> list[Token]:
    """Tokens of one physical line with their columns: words, ``=``, and words holding ``{...}`` groups.

    Raises NetlistError at the column of an unbalanced or nested brace.
    """
    out: list[Token] = []
    i, n = 0, len(line)
    while i < n:
        if line[i].isspace():
            i += 1
            continue
        if line[i] == "=":
            out.append(("=", number, i + 1))
            i += 1
            continue
        start = i
        while i < n and not line[i].isspace() and line[i] != "=":
            if line[i] == "{":
                close = line.find("}", i + 1)
                inner = line.find("{", i + 1)
                if close < 0:
                    raise NetlistError(f"{source}:{number}:{i + 1}: unbalanced '{{' (no closing '}}' on this line)")
                if 0 <= inner < close:
                    raise NetlistError(f"{source}:{number}:{inner + 1}: '{{' inside braces")
                i = close + 1
            elif line[i] == "}":
                raise NetlistError(f"{source}:{number}:{i + 1}: unbalanced '}}' (no opening '{{')")
            else:
                i += 1
        out.append((line[start:i], number, start + 1))
    return out


def _logical_lines(text: str, source: str) -> list[tuple[int, str, list[Token]]]:
    """Join ``+`` continuation lines; strip ``;`` comments.

    Returns (line number, stripped text, tokens) per logical line; comment lines (``*``) keep their text and
    have one token, their ``*``.
    """
    out: list[tuple[int, str, list[Token]]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if stripped.startswith("*"):
            out.append((number, stripped, [("*", number, raw.index("*") + 1)]))
            continue
        line = raw.split(";", 1)[0].rstrip()
        stripped = line.lstrip()
        if stripped.startswith("+") and out and out[-1][2] and not out[-1][1].startswith("*"):
            plus = line.index("+")
            tokens = _tokens(line[:plus] + " " + line[plus + 1:], number, source)
            prev = out[-1]
            out[-1] = (prev[0], prev[1] + " " + stripped[1:].strip(), prev[2] + tokens)
        elif stripped.startswith("+"):
            raise NetlistError(f"{source}:{number}:{line.index('+') + 1}: continuation line '+' without a line to continue")
        else:
            out.append((number, stripped, _tokens(line, number, source) if stripped else []))
    return out


def _at(source: str, token: Token) -> str:
    return f"{source}:{token[1]}:{token[2]}"


def parse_netlist(text: str, source: str = "<netlist>") -> Circuit:
    """Parse netlist text into a Circuit.

    The accepted grammar is a subset of ngspice's (see the module
    docstring); values are checked against
    :data:`pris_cosim.units.ELEMENT_RANGES` after the parameters are
    evaluated.

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
        ``source:line:column: reason`` for anything that cannot be read or
        lies outside the accepted physical range (``source: reason`` for
        problems of the whole file).
    """
    circuit = Circuit()
    lines = _logical_lines(text, source)
    in_control = False
    units: dict[str, str] = {}
    where_of: dict[tuple[str, str], Token] = {}
    for index, (number, line, tokens) in enumerate(lines):
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
                _directive(circuit, units, body[1:].split(), f"{where}:{tokens[0][2]}")
            elif index == 0 and not circuit.title:
                circuit.title = body
            else:
                circuit.comments.append(body)
            continue
        head = tokens[0][0].lower()
        try:
            if head == ".control":
                in_control = True
            elif head == ".param":
                for name, value in _param_pairs(tokens[1:], source, tokens[0]):
                    circuit.add_parameter(name[0], _value_text(value, source))
                    where_of[("param", name[0].lower())] = value
            elif head in (".subckt", ".include", ".lib", ".inc"):
                raise NetlistError(f"{_at(source, tokens[0])}: {tokens[0][0]} is not supported (flatten the netlist first)")
            elif head.startswith("."):
                continue
            else:
                token = _element(circuit, tokens, source)
                where_of[("element", tokens[0][0].lower())] = token
        except NetlistError:
            raise
        except (CircuitError, ValueError) as exc:
            raise NetlistError(f"{_at(source, tokens[0])}: {exc}") from None
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
    _check_values(circuit, where_of, source)
    return circuit


def _param_pairs(tokens: list[Token], source: str, head: Token) -> list[tuple[Token, Token]]:
    """``NAME = VALUE`` pairs of a ``.param`` line."""
    pairs = []
    i = 0
    if not tokens:
        raise NetlistError(f"{_at(source, head)}: .param needs NAME=VALUE")
    while i < len(tokens):
        name = tokens[i]
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name[0]):
            raise NetlistError(f"{_at(source, name)}: cannot parse .param: expected a parameter name, got {_short(name[0])!r}")
        if i + 1 >= len(tokens) or tokens[i + 1][0] != "=":
            at = tokens[i + 1] if i + 1 < len(tokens) else name
            raise NetlistError(f"{_at(source, at)}: cannot parse .param: expected '=' after {name[0]}")
        if i + 2 >= len(tokens):
            raise NetlistError(f"{_at(source, tokens[i + 1])}: cannot parse .param: {name[0]} has no value")
        value = tokens[i + 2]
        if value[0] == "=":
            raise NetlistError(f"{_at(source, value)}: cannot parse .param: {name[0]} has no value")
        pairs.append((name, value))
        i += 3
    return pairs


def _short(text: str, limit: int = 40) -> str:
    s = " ".join(text.split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _value_text(token: Token, source: str) -> str:
    """A value token checked for trailing text after a brace group; the text to give the circuit."""
    text = token[0]
    if "{" in text or "}" in text:
        if not text.startswith("{"):
            raise NetlistError(f"{_at(source, token)}: unexpected {_short(text[:text.index('{')])!r} before '{{'")
        close = text.index("}")
        if close != len(text) - 1:
            raise NetlistError(f"{source}:{token[1]}:{token[2] + close + 1}: unexpected "
                               f"{_short(text[close + 1:])!r} after the value")
    return text


def _directive(circuit: Circuit, units: dict[str, str], words: list[str], where: str) -> None:
    if len(words) == 2 and words[0].lower() in ("port", "probe"):
        (circuit.ports if words[0].lower() == "port" else circuit.probes).append(words[1].lower())
    elif len(words) == 3 and words[0].lower() == "unit":
        units[words[1]] = words[2]
    else:
        raise NetlistError(f"{where}: unknown directive '*@ {_short(' '.join(words))}'")


def _check_node(token: Token, source: str, what: str) -> str:
    if token[0] == "=" or "{" in token[0]:
        raise NetlistError(f"{_at(source, token)}: expected {what}, got {_short(token[0])!r}")
    return token[0]


def _element(circuit: Circuit, tokens: list[Token], source: str) -> Token:
    """Add the element of one logical line; return the token of its value (for later messages)."""
    name = tokens[0]
    kind = name[0][0].upper()
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_.\-+\[\]:#$]*", name[0]):
        raise NetlistError(f"{_at(source, name)}: {_short(name[0])!r} is not an element name")
    if kind in "VI":
        if len(tokens) < 3:
            raise NetlistError(f"{_at(source, name)}: source {name[0]!r} needs two nodes")
        n1, n2 = (_check_node(t, source, "a node name") for t in tokens[1:3])
        words = [t[0] for t in tokens[3:]]
        dc = _source_dc(tokens[3:], source)
        problem = range_problem(kind, dc)
        if problem:
            raise NetlistError(f"{_at(source, tokens[3])}: element {name[0]!r}: {problem}")
        circuit.add(name[0], n1, n2, dc, source_spec=" ".join(words))
        return tokens[3] if len(tokens) > 3 else name
    if kind not in "RLCK":
        raise NetlistError(f"{_at(source, name)}: element type {kind!r} of {name[0]!r} is not supported (R, L, C, K, V, I)")
    if len(tokens) < 4:
        raise NetlistError(f"{_at(source, name)}: element {name[0]!r} needs two {'inductors' if kind == 'K' else 'nodes'} and a value")
    n1, n2 = (_check_node(t, source, "an inductor name" if kind == "K" else "a node name") for t in tokens[1:3])
    value = tokens[3]
    if value[0] == "=":
        raise NetlistError(f"{_at(source, value)}: element {name[0]!r}: expected a value, got '='")
    i = 4
    while i < len(tokens):
        word = tokens[i]
        if kind in "RLC" and word[0].lower() in _INSTANCE_PARAMETERS and i + 2 < len(tokens) \
                and tokens[i + 1][0] == "=":
            val = tokens[i + 2]
            try:
                number = parse_value(val[0])
            except ValueError as exc:
                raise NetlistError(f"{_at(source, val)}: element {name[0]!r}: {word[0]}: {exc}") from None
            if word[0].lower() == "m" and number != 1.0:
                raise NetlistError(f"{_at(source, val)}: element {name[0]!r}: multiplier m={val[0]} is not supported "
                                   f"(write the combined value)")
            i += 3
            continue
        raise NetlistError(f"{_at(source, word)}: element {name[0]!r}: unexpected {_short(word[0])!r} after the value")
    text = _value_text(value, source)
    try:
        circuit.add(name[0], n1, n2, text)
    except CircuitError as exc:
        at = value if "value" in str(exc) or "expression" in str(exc) or "parse" in str(exc) else name
        raise NetlistError(f"{_at(source, at)}: {exc}") from None
    return value


def _source_dc(tokens: list[Token], source: str) -> float:
    """DC value of a source spec (``5``, ``DC 5 AC 1``, ``PULSE(...)``): 0 when absent."""
    words = [t[0] for t in tokens]
    if words and is_number(words[0]):
        return _number(tokens[0], source)
    for (a, _, _), b in zip(tokens, tokens[1:]):
        if a.lower() == "dc":
            return _number(b, source)
    return 0.0


def _number(token: Token, source: str) -> float:
    try:
        return parse_value(token[0])
    except ValueError as exc:
        raise NetlistError(f"{_at(source, token)}: {exc}") from None


def _check_values(circuit: Circuit, where_of: dict[tuple[str, str], Token], source: str) -> None:
    """Evaluate parameters and element values; refuse failures and values outside the physical ranges.

    Each message names the line and column of the value at fault.
    """
    env: dict[str, float] = {}
    pending = {p.key: p for p in circuit.parameters}

    def at(kind: str, key: str) -> str:
        token = where_of.get((kind, key))
        return _at(source, token) if token else source

    while pending:
        progressed = False
        for key, p in list(pending.items()):
            if isinstance(p.value, Expression):
                if not p.value.names <= env.keys():
                    unknown = p.value.names - env.keys() - pending.keys()
                    if unknown:
                        raise NetlistError(f"{at('param', key)}: parameter {p.name!r}: unknown name "
                                           f"{sorted(unknown)[0]!r}")
                    continue
                try:
                    env[key] = float(p.value.evaluate(env))
                except ExpressionError as exc:
                    raise NetlistError(f"{at('param', key)}: parameter {p.name!r}: {exc}") from None
            else:
                env[key] = float(p.value)
            del pending[key]
            progressed = True
        if not progressed:
            first = next(iter(pending))
            raise NetlistError(f"{at('param', first)}: parameters {', '.join(sorted(pending))} depend on each other "
                               f"in a cycle")
    inductors = {e.key for e in circuit.of_kind("L")}
    for e in circuit.elements:
        if isinstance(e.value, Expression):
            try:
                value = float(e.value.evaluate(env))
            except ExpressionError as exc:
                raise NetlistError(f"{at('element', e.key)}: element {e.name!r}: {exc}") from None
        else:
            value = float(e.value)
        if e.kind == "K":
            for n in e.nodes:
                if n.lower() not in inductors:
                    raise NetlistError(f"{at('element', e.key)}: element {e.name!r}: {n!r} is not an inductor of the "
                                       f"netlist")
            if e.nodes[0].lower() == e.nodes[1].lower():
                raise NetlistError(f"{at('element', e.key)}: element {e.name!r} couples {e.nodes[0]!r} with itself")
        problem = range_problem(e.kind, value)
        if problem:
            raise NetlistError(f"{at('element', e.key)}: element {e.name!r}: {problem}")


def check_ranges(circuit: Circuit, values: dict[str, float] | None = None) -> None:
    """Refuse element values outside :data:`pris_cosim.units.ELEMENT_RANGES`.

    Parameters
    ----------
    circuit : Circuit
    values : dict, optional
        Resolved element values (default: ``circuit.resolve(check=False)``).

    Raises
    ------
    CircuitError
        Naming the first element out of range, its value and the range.
    """
    values = circuit.resolve(check=False) if values is None else values
    for e in circuit.elements:
        if e.kind in "VI":
            continue
        problem = range_problem(e.kind, float(values[e.key]))
        if problem:
            raise CircuitError(f"element {e.name!r}: {problem}")


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
        if p.is_dir():
            raise NetlistError(f"{p}: cannot read netlist (it is a directory)")
        with open(p, "rb") as fh:
            data = fh.read(MAX_BYTES + 1)
    except OSError as exc:
        raise NetlistError(f"{p}: cannot read netlist ({exc.strerror or exc})") from None
    if len(data) > MAX_BYTES:
        raise NetlistError(f"{p}: netlist larger than {MAX_BYTES // 2**20} MiB")
    nul = data.find(b"\0")
    if nul >= 0:
        line = data.count(b"\n", 0, nul) + 1
        col = nul - (data.rfind(b"\n", 0, nul) + 1) + 1
        raise NetlistError(f"{p}:{line}:{col}: NUL byte: not a text netlist")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    circuit = parse_netlist(text, str(p))
    if not circuit.elements:
        raise NetlistError(f"{p}: no circuit elements found")
    try:
        circuit.check_topology()
    except CircuitError as exc:
        raise NetlistError(f"{p}{_locate(text, str(exc))}: {exc}") from None
    return circuit


def locate_element(path: Path, message: str) -> str:
    """``:line:column`` in the netlist file ``path`` of the element (or node) that ``message`` names, else ``""``."""
    try:
        return _locate(path.read_text(errors="replace"), message)
    except OSError:
        return ""


def _locate(text: str, message: str) -> str:
    """``:line:column`` of the element a topology message names (or of the first element on the node it names)."""
    m = re.search(r"element '([^']+)'|node '([^']+)'", message)
    if not m:
        return ""
    element, node = m.group(1), m.group(2)
    for number, raw in enumerate(text.splitlines(), start=1):
        words = raw.split(";", 1)[0].split()
        if not words or raw.lstrip().startswith(("*", ".", "+")):
            continue
        if element and words[0].lower() == element.lower() or node and node in (w.lower() for w in words[1:3]):
            return f":{number}:{raw.index(words[0]) + 1}"
    return ""


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
