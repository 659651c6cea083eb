"""Symbolic transfer functions from a circuit (sympy), for checking hand derivations.

The nodal equations of :mod:`pris_cosim.circuits.mna` are built with symbols in
place of numbers; a driving-point impedance or voltage ratio comes out as a
ratio of polynomials in ``s`` whose coefficients are expressions in the
circuit's parameters. Slow for big networks: meant for small ones (the
two-section model of thesis Table 4.1) and for documentation.
"""

from __future__ import annotations

from typing import Any

from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.circuits.expressions import Expression


def _sympy() -> Any:
    try:
        import sympy
    except ImportError:  # pragma: no cover
        raise ImportError("symbolic analysis needs sympy (pip install sympy)") from None
    return sympy


def element_symbols(circuit: Circuit) -> tuple[dict[str, Any], dict[str, Any]]:
    """Positive symbols for parameters and element values.

    Returns
    -------
    symbols : dict
        Display name to sympy Symbol for every parameter and every numeric element.
    values : dict
        Lower-case element name to its sympy expression.
    """
    sp = _sympy()
    symbols = {p.name: sp.Symbol(p.name, positive=True) for p in circuit.parameters}
    env = {name.lower(): sym for name, sym in symbols.items()}
    env["sqrt"] = sp.sqrt
    values: dict[str, Any] = {}
    for e in circuit.elements:
        if e.kind in "VI":
            continue
        if isinstance(e.value, Expression):
            body = e.value.text.strip("{} ")
            values[e.key] = sp.sympify(body.lower().replace("^", "**"), locals=env)
        else:
            sym = sp.Symbol(e.name, positive=True)
            symbols[e.name] = sym
            values[e.key] = sym
    return symbols, values


def transfer_functions(circuit: Circuit, port: str, nodes: list[str]) -> dict[str, Any]:
    """Symbolic ``V(node)/I(port)`` for a unit current injected at ``port``.

    Parameters
    ----------
    circuit : Circuit
    port : str
    nodes : list of str
        Nodes whose transfer impedances are wanted (the port for Zin).

    Returns
    -------
    dict
        ``"s"``: the Laplace variable; node name to a cancelled rational
        expression in ``s``.
    """
    sp = _sympy()
    s = sp.Symbol("s")
    _, values = element_symbols(circuit)
    circuit.check_topology([port])
    node_list = circuit.nodes
    idx = {n: i for i, n in enumerate(node_list)}
    inductors = circuit.inductors()
    lidx = {e.key: len(node_list) + j for j, e in enumerate(inductors)}
    n = len(node_list) + len(inductors)
    K = sp.zeros(n, n)

    def stamp(a: str, b: str, y: Any) -> None:
        for p, q, sign in ((a, a, 1), (b, b, 1), (a, b, -1), (b, a, -1)):
            if p != GROUND and q != GROUND:
                K[idx[p], idx[q]] += sign * y

    for e in circuit.of_kind("R"):
        stamp(*e.nodes, 1 / values[e.key])
    for e in circuit.of_kind("C"):
        stamp(*e.nodes, s * values[e.key])
    for e in inductors:
        j = lidx[e.key]
        a, b = e.nodes
        if a != GROUND:
            K[idx[a], j] += 1
            K[j, idx[a]] -= 1
        if b != GROUND:
            K[idx[b], j] -= 1
            K[j, idx[b]] += 1
        K[j, j] += s * values[e.key]
    for k in circuit.of_kind("K"):
        a, b = (lidx[x.lower()] for x in k.nodes)
        mutual = values[k.key] * sp.sqrt(values[a_key(inductors, a, lidx)] * values[a_key(inductors, b, lidx)])
        K[a, b] += s * mutual
        K[b, a] += s * mutual
    rhs = sp.zeros(n, 1)
    rhs[idx[circuit.require_node(port)], 0] = 1
    x = K.LUsolve(rhs)
    out: dict[str, Any] = {"s": s}
    for node in nodes:
        out[node] = sp.cancel(sp.simplify(x[idx[circuit.require_node(node)], 0]))
    return out


def a_key(inductors: list, index: int, lidx: dict[str, int]) -> str:
    """Element key of the inductor at matrix row ``index``."""
    for key, j in lidx.items():
        if j == index:
            return key
    raise KeyError(index)  # pragma: no cover


def coefficients(expr: Any, s: Any) -> tuple[list[Any], list[Any]]:
    """Numerator and denominator coefficients (highest power first) of a rational function of ``s``."""
    sp = _sympy()
    num, den = sp.fraction(sp.cancel(sp.together(expr)))
    return sp.Poly(sp.expand(num), s).all_coeffs(), sp.Poly(sp.expand(den), s).all_coeffs()
