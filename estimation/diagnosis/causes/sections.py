"""Winding sections found from a circuit's topology, and circuits with one section more.

A *section* is a series branch of resistors and inductors (at least one
inductor) between two *chain nodes*, whose internal nodes join only the
branch's own elements; capacitors between its two ends are its series
capacitance. A *chain* (a winding) is the path of sections that starts at a
port and ends at ground or at an open end; capacitors from its nodes to
ground are its shunt capacitances. Nothing here depends on how the circuit
was built: built-in models, netlists and fitted estimates are read alike.

A missing section is tried in two ways for every chain: each section split
into two halves, and a new section added at either end. Couplings of the
new inductors follow the chain's coupling decay ``k(d) = rho^d`` fitted to
the existing couplings over the distance ``d`` in sections; a split keeps
the winding's low-frequency inductance (the sum of the two halves and their
mutual equals the old inductance, couplings to the rest scaled so the
common mode is unchanged), so the split circuit starts where the baseline
ended. Every new inductance matrix is checked to be positive definite (new
couplings shrunk until it is).

A new section changes the leakage between the sections it touches: the
tight couplings (``k >= 0.9``, windings on one core) of the changed
inductors (the split section's two halves, the added section and its
neighbour) to every other inductor are named in the candidate
(:attr:`SectionCandidate.couplings`), for the fit to free them.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit, Element
from pris_cosim.circuits.expressions import Expression


@dataclass(frozen=True)
class Section:
    """One series R-L branch of a chain, oriented away from the port."""

    start: str
    end: str
    elements: tuple[str, ...]  # R and L element names, in order from start to end
    inductor: str
    resistor: str | None
    series_caps: tuple[str, ...] = ()


@dataclass
class Chain:
    """A winding: the sections from ``port`` to ``end`` (ground or an open node)."""

    port: str
    sections: list[Section]
    shunt_caps: dict[str, list[str]] = field(default_factory=dict)

    @property
    def nodes(self) -> list[str]:
        return [self.port] + [s.end for s in self.sections]

    @property
    def end(self) -> str:
        return self.sections[-1].end if self.sections else self.port

    @property
    def inductors(self) -> list[str]:
        return [s.inductor for s in self.sections]

    @property
    def resistors(self) -> list[str]:
        return [s.resistor for s in self.sections if s.resistor]


def _degree(circuit: Circuit) -> dict[str, list[Element]]:
    at: dict[str, list[Element]] = {}
    for e in circuit.elements:
        if e.kind in "RLC":
            for n in e.nodes:
                at.setdefault(n, []).append(e)
    return at


def find_sections(circuit: Circuit, ports: Sequence[str] = ()) -> list[tuple[str, str, tuple[str, ...]]]:
    """Series R-L branches ``(node, node, element names)`` between chain nodes (unoriented)."""
    at = _degree(circuit)
    keep = {GROUND} | {circuit.require_node(p) for p in ports}

    def internal(n: str) -> bool:
        return n not in keep and len(at.get(n, [])) == 2 and all(e.kind in "RL" for e in at[n])

    seen: set[str] = set()
    out = []
    for l in circuit.of_kind("L"):
        if l.key in seen:
            continue
        path = [l]
        ends = []
        for side in (0, 1):  # walk through internal nodes on both sides
            node, prev = l.nodes[side], l
            while internal(node):
                nxt = next(e for e in at[node] if e.key != prev.key)
                if any(e.key == nxt.key for e in path):
                    break
                path.insert(0 if side == 0 else len(path), nxt)
                node = nxt.nodes[1] if nxt.nodes[0] == node else nxt.nodes[0]
                prev = nxt
            ends.append(node)
        seen.update(e.key for e in path)
        if ends[0] == ends[1] or sum(e.kind == "L" for e in path) != 1:
            continue  # a loop (e.g. a core-loss loop L || R) or several inductors in series
        out.append((ends[0], ends[1], tuple(e.name for e in path)))
    return out


def find_chains(circuit: Circuit, ports: Sequence[str]) -> list[Chain]:
    """The chain of sections starting at each port (ports with no section give no chain)."""
    branches = find_sections(circuit, ports)
    used: set[int] = set()
    caps = circuit.of_kind("C")
    chains = []
    for p in ports:
        node = circuit.require_node(p)
        sections: list[Section] = []
        visited = {node}
        while node != GROUND:
            nxt = [i for i, (a, b, _) in enumerate(branches) if i not in used and node in (a, b)]
            if len(nxt) != 1:
                break
            i = nxt[0]
            a, b, names = branches[i]
            if (b if a == node else a) in visited:
                break
            used.add(i)
            if a != node:  # orient from the port
                a, b, names = b, a, tuple(reversed(names))
            inductor = next(n for n in names if n[0].upper() == "L")
            resistor = next((n for n in names if n[0].upper() == "R"), None)
            series = tuple(c.name for c in caps if set(c.nodes) == {a, b} and b != GROUND)
            sections.append(Section(a, b, names, inductor, resistor, series))
            visited.add(b)
            node = b
        if sections:
            nodes = [n for n in [sections[0].start] + [s.end for s in sections] if n != GROUND]
            shunt = {n: [c.name for c in caps if set(c.nodes) == {n, GROUND}] for n in nodes}
            chains.append(Chain(circuit.require_node(p), sections, shunt))
    return chains


def coupling_matrix(circuit: Circuit, values: Mapping[str, float]) -> dict[frozenset[str], float]:
    """Coupling coefficient of each coupled inductor pair (lower-case names)."""
    return {frozenset(n.lower() for n in k.nodes): float(values[k.key]) for k in circuit.of_kind("K")}


def coupling_decay(circuit: Circuit, chains: Sequence[Chain], values: Mapping[str, float]) -> float:
    """``rho`` of ``k(d) = rho^d`` fitted (least squares on ``ln k``) over the chains' section couplings.

    0 when no section of any chain is coupled to another of the same chain.
    """
    ks = coupling_matrix(circuit, values)
    num = den = 0.0
    for ch in chains:
        ind = [x.lower() for x in ch.inductors]
        for i, j in itertools.combinations(range(len(ind)), 2):
            k = ks.get(frozenset((ind[i], ind[j])))
            if k is not None and k > 0:
                d = j - i
                num += d * np.log(k)
                den += d * d
    return float(np.exp(num / den)) if den else 0.0


def _scaled(value: float | Expression, factor: float) -> float | Expression:
    if isinstance(value, Expression):
        body = value.text[1:-1] if value.text.startswith("{") else value.text
        return Expression("{(" + body + ")*" + repr(float(factor)) + "}")
    return float(value) * factor


def _unique(circuit: Circuit, base: str) -> str:
    names = {e.key for e in circuit.elements} | {p.key for p in circuit.parameters}
    if base.lower() not in names:
        return base
    for i in itertools.count(2):
        if f"{base}_{i}".lower() not in names:
            return f"{base}_{i}"
    raise AssertionError


def _new_node(circuit: Circuit, base: str) -> str:
    nodes = set(circuit.nodes)
    for i in itertools.count(1):
        if f"{base}{i}" not in nodes:
            return f"{base}{i}"
    raise AssertionError


def _numeric(circuit: Circuit, name: str) -> float:
    return float(circuit.resolve(check=False)[name.lower()])


def _make_pd(circuit: Circuit, new_k: Sequence[str]) -> Circuit:
    """Shrink the listed couplings until the inductance matrix is positive definite."""
    for shrink in (1.0, 0.9995, 0.998, 0.995, 0.99, 0.98, 0.95, 0.9, 0.8, 0.6, 0.3, 0.0):
        c = circuit.with_values({k: float(circuit.element(k).value) * shrink for k in new_k}) if shrink < 1 else circuit
        if c.smallest_inductance_eigenvalue(c.resolve(check=False)) > 0:
            return c
    return c


@dataclass
class SectionCandidate:
    """A circuit with one more section, how it was made, and its new elements."""

    circuit: Circuit
    how: str
    new_elements: list[str]
    port: str = ""
    #: K elements whose coupling the change touches (fitted with the new elements).
    couplings: list[str] = field(default_factory=list)
    #: A split: the circuit, chain and section index it splits (so its halves can be merged back, :mod:`.unmerge`).
    split_of: tuple[Any, ...] | None = None


#: Couplings at least this tight are freed by a new section (:func:`touched_couplings`).
TIGHT_COUPLING = 0.9


def touched_couplings(circuit: Circuit, inductors: Sequence[str], tight: float = TIGHT_COUPLING) -> list[str]:
    """Numeric K elements of ``circuit`` that couple one of ``inductors`` to any inductor at ``k >= tight``.

    Only tight couplings are freed: where the leakage ``1 - k`` is small, a
    change of ``k`` by a fraction of a per cent changes it by tens of per
    cent, which no split with the couplings held can follow; looser
    couplings (a winding's sections among themselves) follow the winding's
    coupling profile.
    """
    names = {n.lower() for n in inductors}
    return [k.name for k in circuit.of_kind("K") if not isinstance(k.value, Expression)
            and names & {n.lower() for n in k.nodes} and float(k.value) >= tight]


def _couple_new(c: Circuit, new_l: str, partners: Mapping[str, float]) -> list[str]:
    names = []
    for other, k in partners.items():
        if k <= 0:
            continue
        name = _unique(c, f"K_{new_l}_{other}")
        c.add(name, new_l, other, float(min(k, 0.99995)))
        names.append(name)
    return names


def split_section(circuit: Circuit, chain: Chain, j: int, rho: float, shunt_scale: float = 1.0) -> SectionCandidate:
    """Section ``j`` of ``chain`` split into two halves joined at a new node (with a shunt capacitor).

    The halves are equal, so with a small shunt capacitor (``shunt_scale``
    times the chain's mean) the split circuit responds as the original.
    """
    sec = chain.sections[j]
    values = circuit.resolve(check=False)
    ks = coupling_matrix(circuit, values)
    c = circuit.copy()
    mid = _new_node(c, "ms")
    k_in = float(np.sqrt(rho)) if rho > 0 else 0.0
    h_l = 1.0 / (2.0 * (1.0 + k_in))
    scale_k = float(np.sqrt((1.0 + k_in) / 2.0))
    # first half: the old elements now end at the new node; second half: copies from the new node
    last = c.element(sec.elements[-1])
    idx = next(i for i, e in enumerate(c.elements) if e.key == last.key)
    c.elements[idx] = replace(last, nodes=tuple(mid if n == sec.end else n for n in last.nodes))
    new: list[str] = []
    node = mid
    for pos, name in enumerate(sec.elements):
        e = c.element(name)
        factor = h_l if e.kind == "L" else 0.5
        nxt = sec.end if pos == len(sec.elements) - 1 else _new_node(c, "xs")
        copy = c.add(_unique(c, f"{e.name}s"), node, nxt, _scaled(e.value, factor))
        new.append(copy.name)
        node = nxt
        i = next(i for i, x in enumerate(c.elements) if x.key == e.key)
        c.elements[i] = replace(c.elements[i], value=_scaled(e.value, factor))
    new_l = next(n for n in new if n[0].upper() == "L")
    for cap in sec.series_caps:
        e = c.element(cap)
        i = next(i for i, x in enumerate(c.elements) if x.key == e.key)
        c.elements[i] = replace(e, nodes=(sec.start, mid), value=_scaled(e.value, 2.0))
        new.append(c.add(_unique(c, f"{e.name}s"), mid, sec.end, _scaled(e.value, 2.0)).name)
    shunt = _mean_shunt(circuit, chain, values) * shunt_scale
    if shunt > 0:
        new.append(c.add(_unique(c, "Cgs"), mid, GROUND, shunt).name)
    old_l = sec.inductor.lower()
    partners = {}
    for pair, k in ks.items():
        if old_l in pair:
            other = next(iter(pair - {old_l}))
            partners[other] = k * scale_k
            for kel in c.of_kind("K"):  # the old half keeps its couplings, scaled for the common mode
                if {n.lower() for n in kel.nodes} == pair:
                    i = next(i for i, x in enumerate(c.elements) if x.key == kel.key)
                    c.elements[i] = replace(kel, value=float(k * scale_k))
    partners[old_l] = k_in
    new_k = _couple_new(c, new_l, partners)
    new_k += [k.name for k in c.of_kind("K") if old_l in {n.lower() for n in k.nodes} and k.name not in new_k]
    c = _make_pd(c, new_k)
    return SectionCandidate(c, f"split section {j + 1} of the winding at {chain.port}", new, chain.port,
                            touched_couplings(c, [sec.inductor, new_l]))


def _mean_shunt(circuit: Circuit, chain: Chain, values: Mapping[str, float]) -> float:
    shunt = [float(values[n.lower()]) for node, names in chain.shunt_caps.items() for n in names]
    if shunt:
        return float(np.mean(shunt))
    series = [float(values[n.lower()]) for s in chain.sections for n in s.series_caps]
    return 1e-2 * float(np.mean(series)) if series else 0.0


def add_section(circuit: Circuit, chain: Chain, at: str, rho: float, l_scale: float = 1.0,
                c_scale: float = 1.0) -> SectionCandidate:
    """A new section added at the port end (``at="port"``) or the far end (``at="end"``) of ``chain``.

    Its values are the chain's means (inductance times ``l_scale``, series
    capacitance times ``c_scale``); its couplings continue the neighbour's
    by one step of the decay ``rho``.
    """
    values = circuit.resolve(check=False)
    ks = coupling_matrix(circuit, values)
    c = circuit.copy()
    m = _new_node(c, "ms")
    nb = chain.sections[0] if at == "port" else chain.sections[-1]
    if at == "port":  # the old first section now starts at the new node
        a, b = chain.port, m
        moved = [nb.elements[0]] + list(nb.series_caps)
        old = chain.port
    else:
        a, b = m, chain.end
        moved = [nb.elements[-1]] + (list(nb.series_caps) if chain.end != GROUND else [])
        old = chain.end
    for name in moved:
        e = c.element(name)
        i = next(i for i, x in enumerate(c.elements) if x.key == e.key)
        c.elements[i] = replace(e, nodes=tuple(m if n == old else n for n in e.nodes))
    R = [float(values[s.resistor.lower()]) for s in chain.sections if s.resistor]
    L = [float(values[s.inductor.lower()]) for s in chain.sections]
    Cs = [float(values[n.lower()]) for s in chain.sections for n in s.series_caps]
    new: list[str] = []
    x = _new_node(c, "xs")
    if R:
        new.append(c.add(_unique(c, "Rs_new"), a, x, float(np.mean(R))).name)
        new.append(c.add(_unique(c, "Ls_new"), x, b, float(np.mean(L)) * l_scale).name)
    else:
        new.append(c.add(_unique(c, "Ls_new"), a, b, float(np.mean(L)) * l_scale).name)
    if Cs and b != GROUND:
        new.append(c.add(_unique(c, "Cs_new"), a, b, float(np.mean(Cs)) * c_scale).name)
    shunt = _mean_shunt(circuit, chain, values)
    if shunt > 0:
        new.append(c.add(_unique(c, "Cg_new"), m, GROUND, shunt * (c_scale if not Cs else 1.0)).name)
    new_l = next(n for n in new if n[0].upper() == "L")
    nb_l = nb.inductor.lower()
    partners = {}
    step = rho if rho > 0 else 0.0
    for pair, k in ks.items():
        if nb_l in pair:
            other = next(iter(pair - {nb_l}))
            within = other in {i.lower() for i in chain.inductors}
            partners[other] = k * step if within else k
    partners[nb_l] = step
    new_k = _couple_new(c, new_l, partners)
    c = _make_pd(c, new_k)
    where = "at the port end" if at == "port" else "at the far end"
    return SectionCandidate(c, f"new section {where} of the winding at {chain.port}", new, chain.port,
                            touched_couplings(c, [new_l, nb.inductor]))


def section_candidates(circuit: Circuit, ports: Sequence[str], grid: Sequence[float] = (0.3, 1.0, 3.0)
                       ) -> list[SectionCandidate]:
    """Every split (with a small and a typical shunt capacitor) and every end addition (over a grid of
    inductance scales; none for an empty ``grid``) for every chain."""
    chains = find_chains(circuit, ports)
    values = circuit.resolve(check=False)
    rho = coupling_decay(circuit, chains, values)
    out = []
    for ch in chains:
        for j in range(len(ch.sections)):
            for shunt in (0.01, 1.0):
                cand = split_section(circuit, ch, j, rho, shunt)
                cand.split_of = (circuit, ch, j)
                out.append(cand)
        for at in ("port", "end"):
            for g in grid:
                out.append(add_section(circuit, ch, at, rho, l_scale=g, c_scale=1.0 / g))
    return out
