"""The circuit description: one object that every analysis path reads.

A :class:`Circuit` holds named parameters (values, units, tied expressions)
and elements R, L, C, K (coupling between two inductors) and independent
V/I sources, plus the nodes a user calls ports and probes. Analytic
frequency responses, the state-space form, the FMU C code, the Modelica
text and the SPICE netlist all derive from it.

Names of elements and parameters are case-insensitive (as in SPICE); they
keep the spelling they were given for display. Node names are stored
lower-case; ``0`` (or ``gnd``) is ground.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Union

import numpy as np

from pris_cosim.errors import CircuitError, ExpressionError, NonPassiveError, NonPassiveWarning
from pris_cosim.circuits.expressions import Expression
from pris_cosim.units import ELEMENT_UNITS

GROUND = "0"
_GROUND_ALIASES = {"0", "gnd"}

Value = Union[float, Expression]
Numeric = Union[float, np.ndarray]


def node_name(name: str) -> str:
    """Canonical node name: lower-case, ground aliases mapped to ``"0"``."""
    n = str(name).strip().lower()
    return GROUND if n in _GROUND_ALIASES else n


def _as_value(value: Any, what: str) -> Value:
    if isinstance(value, Expression):
        return value
    if isinstance(value, str):
        from pris_cosim.units import is_number, parse_value

        try:
            return parse_value(value) if is_number(value) else Expression(value)
        except ValueError as exc:
            raise CircuitError(f"{what}: {exc}") from None
    try:
        return float(value)
    except (TypeError, ValueError):
        raise CircuitError(f"{what}: value {value!r} is neither a number nor an expression") from None


def value_text(value: Value) -> str:
    """SPICE text of a value: exact float repr or ``{expression}``."""
    if isinstance(value, Expression):
        body = value.text[1:-1] if value.text.startswith("{") else value.text
        return "{" + body + "}"
    return repr(float(value))


@dataclass(frozen=True)
class Parameter:
    """A named circuit parameter.

    Parameters
    ----------
    name : str
        Display name (lookup is case-insensitive).
    value : float or Expression
        A number in SI units, or an expression over other parameters (a tie).
    unit : str
        Unit for display, e.g. ``"Ohm"``, ``"H"``, ``"F"``, ``"1"``.
    description : str
        What the parameter means.
    """

    name: str
    value: Value
    unit: str = ""
    description: str = ""

    @cached_property
    def key(self) -> str:
        return self.name.lower()

    @property
    def is_tied(self) -> bool:
        """True when the parameter is an expression of other parameters."""
        return isinstance(self.value, Expression)


@dataclass(frozen=True)
class Element:
    """One circuit element.

    Parameters
    ----------
    name : str
        Element name; its first letter is its kind (R, L, C, K, V, I).
    nodes : tuple of str
        The two nodes (``n+``, ``n-``); for ``K`` the two inductor names.
    value : float or Expression
        Ohm, H, F, or the coupling coefficient k (dimensionless); for sources
        the DC value (sources are zeroed in small-signal analysis).
    source_spec : str
        For V/I sources, the original text after the nodes (kept for writing).
    """

    name: str
    nodes: tuple[str, str]
    value: Value
    source_spec: str = ""

    @property
    def kind(self) -> str:
        return self.name[0].upper()

    @cached_property
    def key(self) -> str:
        return self.name.lower()

    @property
    def unit(self) -> str:
        return ELEMENT_UNITS[self.kind]


@dataclass
class Circuit:
    """A linear lumped circuit with named parameters.

    Parameters
    ----------
    title : str
        First line of the netlist.
    elements : list of Element
    parameters : list of Parameter
    ports : list of str
        Nodes a source can drive, default port first.
    probes : list of str
        Nodes whose voltages are of interest (outputs of the DUT FMU).
    comments : list of str
        Free text kept with the circuit (written as ``*`` lines).
    """

    title: str = ""
    elements: list[Element] = field(default_factory=list)
    parameters: list[Parameter] = field(default_factory=list)
    ports: list[str] = field(default_factory=list)
    probes: list[str] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)

    # ------------------------------------------------------------------ building
    def add_parameter(self, name: str, value: Any, unit: str = "", description: str = "") -> Parameter:
        """Add a ``.param`` (number or expression); returns it."""
        if any(p.key == name.lower() for p in self.parameters):
            raise CircuitError(f"parameter {name!r} is defined twice")
        param = Parameter(name, _as_value(value, f"parameter {name!r}"), unit, description)
        self.parameters.append(param)
        return param

    def add(self, name: str, n1: str, n2: str, value: Any, source_spec: str = "") -> Element:
        """Add an element ``NAME n1 n2 value`` (for K: ``NAME L1 L2 k``); returns it."""
        kind = name[:1].upper()
        if kind not in ELEMENT_UNITS:
            raise CircuitError(f"element {name!r}: unknown element type {kind!r}")
        keys = self.__dict__.get("_element_keys")  # names seen, kept while the list only grows here
        if keys is None or keys[0] is not self.elements or keys[1] != len(self.elements):
            keys = (self.elements, len(self.elements), {e.key for e in self.elements})
        if name.lower() in keys[2]:
            raise CircuitError(f"element {name!r} is defined twice")
        nodes = (n1, n2) if kind == "K" else (node_name(n1), node_name(n2))
        element = Element(name, nodes, _as_value(value, f"element {name!r}"), source_spec)
        self.elements.append(element)
        keys[2].add(element.key)
        self.__dict__["_element_keys"] = (self.elements, len(self.elements), keys[2])
        return element

    # ------------------------------------------------------------------ queries
    def element(self, name: str) -> Element:
        """Element by (case-insensitive) name."""
        key = name.lower()
        for e in self.elements:
            if e.key == key:
                return e
        raise CircuitError(f"no element named {name!r}")

    def has_element(self, name: str) -> bool:
        return any(e.key == name.lower() for e in self.elements)

    def parameter(self, name: str) -> Parameter:
        """Parameter by (case-insensitive) name."""
        key = name.lower()
        for p in self.parameters:
            if p.key == key:
                return p
        raise CircuitError(f"no parameter named {name!r}")

    def of_kind(self, *kinds: str) -> list[Element]:
        """Elements whose kind letter is one of ``kinds``."""
        return [e for e in self.elements if e.kind in kinds]

    @property
    def nodes(self) -> list[str]:
        """Non-ground nodes in order of first appearance."""
        seen: dict[str, None] = {}
        for e in self.elements:
            if e.kind != "K":
                for n in e.nodes:
                    if n != GROUND:
                        seen.setdefault(n)
        return list(seen)

    def require_node(self, node: str, role: str = "node") -> str:
        """Canonical name of ``node``, or a CircuitError naming it."""
        n = node_name(node)
        if n != GROUND and n not in self.nodes:
            raise CircuitError(f"{role} {node!r} is not a node of the circuit (nodes: {', '.join(self.nodes)})")
        return n

    # ------------------------------------------------------------------ values
    def parameter_values(self, overrides: Mapping[str, Numeric] | None = None) -> dict[str, Numeric]:
        """Evaluate every parameter, ties in dependency order.

        Parameters
        ----------
        overrides : mapping, optional
            Parameter name to value (float or array for a population). An
            overridden tied parameter takes the given value instead of its tie.

        Returns
        -------
        dict
            Lower-case parameter name to value.
        """
        over = {k.lower(): v for k, v in (overrides or {}).items()}
        env: dict[str, Numeric] = {}
        pending = {p.key: p for p in self.parameters}
        for key in list(pending):
            if key in over:
                env[key] = over[key]
                del pending[key]
        while pending:
            progressed = False
            for key, p in list(pending.items()):
                if isinstance(p.value, Expression):
                    if not p.value.names <= env.keys():
                        unknown = p.value.names - env.keys() - pending.keys()
                        if unknown:
                            raise ExpressionError(
                                f"parameter {p.name!r}: unknown name {sorted(unknown)[0]!r} in {p.value.text!r}"
                            )
                        continue
                    env[key] = p.value.evaluate(env)
                else:
                    env[key] = p.value
                del pending[key]
                progressed = True
            if not progressed:
                raise ExpressionError(f"parameters {', '.join(sorted(pending))} depend on each other in a cycle")
        return env

    def resolve(self, overrides: Mapping[str, Numeric] | None = None, check: bool = True) -> dict[str, Numeric]:
        """Element values after evaluating parameters and ties.

        Parameters
        ----------
        overrides : mapping, optional
            Names of parameters or elements to values (floats, or equal-length
            arrays for a population of parameter sets). A name that is both
            a parameter and an element sets the parameter.
        check : bool
            Check that R, L, C are positive and ``|k| < 1``.

        Returns
        -------
        dict
            Lower-case element name to value (Ohm, H, F, or k).
        """
        over = {k.lower(): v for k, v in (overrides or {}).items()}
        param_keys = {p.key for p in self.parameters}
        elem_keys = {e.key for e in self.elements}
        unknown = sorted(set(over) - param_keys - elem_keys)
        if unknown:
            raise CircuitError(f"unknown parameter or element {unknown[0]!r}")
        env = self.parameter_values({k: v for k, v in over.items() if k in param_keys})
        values: dict[str, Numeric] = {}
        for e in self.elements:
            if e.key in over and e.key not in param_keys:
                values[e.key] = over[e.key]
            elif isinstance(e.value, Expression):
                try:
                    values[e.key] = e.value.evaluate(env)
                except ExpressionError as exc:
                    raise ExpressionError(f"element {e.name!r}: {exc}") from None
            else:
                values[e.key] = e.value
        if check:
            self.check_values(values)
        return values

    def check_values(self, values: Mapping[str, Numeric]) -> None:
        """Raise CircuitError naming the first element with an unphysical value."""
        names = {"R": "resistance", "L": "inductance", "C": "capacitance"}
        for e in self.elements:
            v = np.asarray(values[e.key], dtype=float)
            if not np.all(np.isfinite(v)):
                raise CircuitError(f"element {e.name!r}: value is not finite ({_show(v)})")
            if e.kind in names and np.any(v <= 0):
                raise CircuitError(
                    f"element {e.name!r}: {names[e.kind]} must be positive (got {_show(v[v <= 0])} {e.unit})"
                )
            if e.kind == "K" and np.any(np.abs(v) >= 1):
                raise CircuitError(f"element {e.name!r}: coupling |k| must be below 1 (got {_show(v[np.abs(v) >= 1])})")

    # ------------------------------------------------------------------ inductance
    def inductors(self) -> list[Element]:
        return self.of_kind("L")

    def inductance_matrix(self, values: Mapping[str, Numeric]) -> np.ndarray:
        """Inductance matrix, H, shape ``(..., m, m)`` in the order of :meth:`inductors`.

        ``M_ij = k_ij sqrt(L_i L_j)`` for every K element.
        """
        inds = self.inductors()
        index = {e.key: i for i, e in enumerate(inds)}
        diag = np.stack(np.broadcast_arrays(*[np.asarray(values[e.key], float) for e in inds]), axis=-1) if inds else np.zeros(0)
        m = len(inds)
        L = np.zeros(diag.shape[:-1] + (m, m))
        idx = np.arange(m)
        L[..., idx, idx] = diag
        for k in self.of_kind("K"):
            i, j = (self._inductor_index(index, k, n) for n in k.nodes)
            mutual = np.asarray(values[k.key], float) * np.sqrt(diag[..., i] * diag[..., j])
            L[..., i, j] += mutual
            L[..., j, i] += mutual
        return L

    def _inductor_index(self, index: Mapping[str, int], k: Element, name: str) -> int:
        try:
            return index[name.lower()]
        except KeyError:
            raise CircuitError(f"element {k.name!r}: {name!r} is not an inductor of the circuit") from None

    def smallest_inductance_eigenvalue(self, values: Mapping[str, Numeric]) -> Numeric:
        """Smallest eigenvalue of the inductance matrix, H (per parameter set)."""
        L = self.inductance_matrix(values)
        if L.shape[-1] == 0:
            return np.inf
        index = {e.key: i for i, e in enumerate(self.inductors())}
        coupled = sorted({index[n.lower()] for k in self.of_kind("K") for n in k.nodes if n.lower() in index})
        alone = np.setdiff1d(np.arange(L.shape[-1]), coupled)  # uncoupled inductors: their own values
        lam = np.min(np.diagonal(L, axis1=-2, axis2=-1)[..., alone], axis=-1, initial=np.inf)
        if coupled:
            lam = np.minimum(lam, np.linalg.eigvalsh(L[..., coupled, :][..., coupled])[..., 0])
        return float(lam) if np.ndim(lam) == 0 else lam

    def check_passive(self, values: Mapping[str, Numeric], strict: bool) -> None:
        """Check that the inductance matrix is positive definite.

        Parameters
        ----------
        values : mapping
            Element values from :meth:`resolve`.
        strict : bool
            Raise :class:`NonPassiveError` (time-domain use, FMU building)
            instead of warning with :class:`NonPassiveWarning`.
        """
        lam = np.atleast_1d(self.smallest_inductance_eigenvalue(values))
        bad = lam <= 0
        if np.any(bad):
            worst = float(lam.min())
            msg = (
                f"circuit {self.title or '(untitled)'!r} is not passive: inductance matrix is not positive "
                f"definite (smallest eigenvalue {worst:.4g} H"
                + (f" in {int(bad.sum())} of {lam.size} parameter sets" if lam.size > 1 else "")
                + ")"
            )
            if strict:
                raise NonPassiveError(msg)
            warnings.warn(msg, NonPassiveWarning, stacklevel=3)

    # ------------------------------------------------------------------ topology
    def check_topology(self, ports: Iterable[str] = ()) -> None:
        """Structural checks; raises CircuitError naming the element or node.

        - every K couples two distinct existing inductors, each pair once;
        - every node has an element path to ground (no floating node);
        - no loop made only of capacitors and voltage sources;
        - the given ports are nodes of the circuit.
        """
        for p in ports:
            self.require_node(p, "port")
        inductor_keys = {e.key for e in self.inductors()}
        pairs: dict[frozenset[str], str] = {}
        for k in self.of_kind("K"):
            a, b = (n.lower() for n in k.nodes)
            for n in (a, b):
                if n not in inductor_keys:
                    raise CircuitError(f"element {k.name!r}: {n!r} is not an inductor of the circuit")
            if a == b:
                raise CircuitError(f"element {k.name!r} couples inductor {a!r} with itself")
            pair = frozenset((a, b))
            if pair in pairs:
                raise CircuitError(f"element {k.name!r} couples the same inductors as {pairs[pair]!r}")
            pairs[pair] = k.name
        groups = _UnionFind()
        for e in self.elements:
            if e.kind not in ("K", "I"):  # a current source is an open circuit for the network's equations
                groups.union(*e.nodes)
        for n in self.nodes:
            if groups.find(n) != groups.find(GROUND):
                raise CircuitError(f"node {n!r} is floating: no element path to ground (current sources do not count)")
        loops = _UnionFind()
        for e in self.of_kind("C"):
            loops.union(*e.nodes)
        for e in self.of_kind("V"):
            if loops.find(e.nodes[0]) == loops.find(e.nodes[1]):
                raise CircuitError(f"element {e.name!r}: voltage source closes a loop of capacitors and voltage sources")
            loops.union(*e.nodes)

    # ------------------------------------------------------------------ variants
    def shorted(self, nodes: Iterable[str]) -> "Circuit":
        """A copy with the given nodes tied to ground (a short-circuit test)."""
        short = {self.require_node(n, "shorted node") for n in nodes}
        elements = [
            e if e.kind == "K" else replace(e, nodes=tuple(GROUND if n in short else n for n in e.nodes))
            for e in self.elements
        ]
        return replace(
            self,
            elements=elements,
            ports=[p for p in self.ports if p not in short],
            probes=[p for p in self.probes if p not in short],
        )

    def with_values(self, values: Mapping[str, float]) -> "Circuit":
        """A copy whose named parameters or elements take new numeric values."""
        over = {k.lower(): float(v) for k, v in values.items()}
        params = [replace(p, value=over.pop(p.key)) if p.key in over else p for p in self.parameters]
        elements = [replace(e, value=over.pop(e.key)) if e.key in over else e for e in self.elements]
        if over:
            raise CircuitError(f"unknown parameter or element {sorted(over)[0]!r}")
        return replace(self, parameters=params, elements=elements)

    def copy(self) -> "Circuit":
        return replace(self, elements=list(self.elements), parameters=list(self.parameters),
                       ports=list(self.ports), probes=list(self.probes), comments=list(self.comments))

    def free_names(self) -> list[str]:
        """Names that can be set independently: numeric parameters and numeric R/L/C/K elements.

        Tied parameters and elements given by expressions follow from these.
        """
        names = [p.name for p in self.parameters if not p.is_tied]
        names += [e.name for e in self.elements if e.kind in "RLCK" and not isinstance(e.value, Expression)]
        return names

    def summary(self) -> list[dict[str, Any]]:
        """Rows describing every parameter and element value (for listings)."""
        rows: list[dict[str, Any]] = []
        env = self.parameter_values()
        for p in self.parameters:
            rows.append({"name": p.name, "kind": "param", "value": float(env[p.key]), "unit": p.unit,
                         "expression": p.value.text if p.is_tied else None, "description": p.description})
        values = self.resolve(check=False)
        for e in self.elements:
            if e.kind in "VI":
                continue
            rows.append({"name": e.name, "kind": e.kind, "nodes": list(e.nodes), "value": float(values[e.key]),
                         "unit": e.unit, "expression": e.value.text if isinstance(e.value, Expression) else None})
        return rows


class _UnionFind:
    def __init__(self) -> None:
        self._parent: dict[str, str] = {}

    def find(self, x: str) -> str:
        self._parent.setdefault(x, x)
        while self._parent[x] != x:
            self._parent[x] = self._parent[self._parent[x]]
            x = self._parent[x]
        return x

    def union(self, a: str, b: str) -> None:
        self._parent[self.find(a)] = self.find(b)


def _show(v: np.ndarray) -> str:
    flat = np.ravel(v)
    return f"{flat[0]:.6g}" if flat.size == 1 else f"{flat[0]:.6g}, ... ({flat.size} values)"


def components_without_ground(edges: Sequence[tuple[str, str]], nodes: Sequence[str]) -> list[list[str]]:
    """Groups of ``nodes`` joined by ``edges`` that do not reach ground (isolated nodes included)."""
    uf = _UnionFind()
    for a, b in edges:
        uf.union(a, b)
    groups: dict[str, list[str]] = {}
    for n in nodes:
        root = uf.find(n)
        if root != uf.find(GROUND):
            groups.setdefault(root, []).append(n)
    return list(groups.values())


__all__ = ["Circuit", "Element", "Parameter", "GROUND", "node_name", "value_text", "components_without_ground"]
