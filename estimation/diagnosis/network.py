"""Fast responses of a circuit whose branch impedances change with frequency.

A frequency-dependent element (a skin-effect resistance, an inductance that
falls with frequency, a core-loss resistance) would need a dense nodal solve
at every frequency. Instead each such branch gets a voltage source ``V_j``
in series (inserted at a terminal without capacitance, so the state-space
reduction of :class:`pris_cosim.mna.MNA` still applies). The circuit with
constant values is put into pole-residue form once per parameter set, for
the port current and every ``V_j`` as inputs and for the response nodes and
every branch current ``i_j`` as outputs:

.. math::

    \\begin{bmatrix} v \\\\ i \\end{bmatrix} =
    \\begin{bmatrix} T_{vp} & T_{vv} \\\\ T_{ip} & T_{iv} \\end{bmatrix}
    \\begin{bmatrix} I \\\\ V \\end{bmatrix}, \\qquad
    T(s) = \\sum_n \\frac{R_n}{s - p_n} + D .

A change ``dZ(f)`` of the branch impedances (a ``k x k`` matrix: diagonal
for resistors, full for coupled inductors) closes the loop ``V = dZ i``:

.. math:: v = \\left(T_{vp} + T_{vv}\\, dZ\\, (I - T_{iv} dZ)^{-1} T_{ip}\\right) I,

one ``k x k`` solve per frequency. Changing only ``dZ`` (the extension's own
parameters) reuses the pole-residue form, so those Jacobian columns cost no
new eigen-decomposition.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from pris_cosim.circuit import GROUND, Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.frf import Response
from pris_cosim.mna import MNA

#: Eigenvector condition number above which the resolvent is solved directly instead.
MAX_CONDITION = 1e10


def capacitive_nodes(circuit: Circuit) -> set[str]:
    """Nodes touched by a capacitor (ground excluded)."""
    return {n for e in circuit.of_kind("C") for n in e.nodes if n != GROUND}


def insert_series_sources(circuit: Circuit, elements: Sequence[str]) -> tuple[Circuit, list[str]]:
    """A copy of ``circuit`` with a zero-valued voltage source in series with each named element.

    The source ``Vdz_<element>`` sits between the element and one of its
    terminals that has no capacitor (or ground), so the node it adds is
    algebraic; its current (SPICE convention, into its ``+`` node) is the
    element current from the element's first to its second node, and its
    voltage adds to the element's voltage drop in that direction.

    Raises
    ------
    CircuitError
        An element both of whose terminals carry capacitance.
    """
    cap = capacitive_nodes(circuit)
    out = circuit.copy()
    names = []
    for name in elements:
        e = out.element(name)
        n1, n2 = e.nodes
        vname = f"Vdz_{e.name}"
        mid = f"dz_{e.name}".lower()
        idx = next(i for i, x in enumerate(out.elements) if x.key == e.key)
        if n2 == GROUND or n2 not in cap:  # element (n1, mid), source (mid, n2)
            out.elements[idx] = replace(e, nodes=(n1, mid))
            out.add(vname, mid, n2, 0.0, source_spec="DC 0")
        elif n1 == GROUND or n1 not in cap:  # source (n1, mid), element (mid, n2)
            out.elements[idx] = replace(e, nodes=(mid, n2))
            out.add(vname, n1, mid, 0.0, source_spec="DC 0")
        else:
            raise CircuitError(f"element {e.name!r}: both terminals carry capacitance; "
                               "its value cannot be made frequency dependent here")
        names.append(vname)
    return out, names


class ProbedConfiguration:
    """One test configuration of a circuit, with series sources in the branches that may change.

    Parameters
    ----------
    circuit : Circuit
    port : str
        Driven node (unit current from ground).
    shorts : sequence of str
        Nodes tied to ground.
    responses : sequence of Response
        Responses wanted (``Zin``-type when ``node`` is None, else voltage ratios).
    branches : sequence of str
        R or L elements whose impedance may change with frequency.
    """

    def __init__(self, circuit: Circuit, port: str, shorts: Sequence[str], responses: Sequence[Response],
                 branches: Sequence[str] = ()):
        c = circuit.shorted(shorts) if shorts else circuit
        self.port = c.require_node(port, "port")
        self.branches = list(branches)
        self.circuit, self.sources = insert_series_sources(c, self.branches)
        self.responses = list(responses)
        nodes = [self.port]
        for r in self.responses:
            for n in (r.node, r.minus):
                if n is None:
                    continue
                n = c.require_node(n, f"node of response {r.name!r}")
                if n != GROUND and n not in nodes:
                    nodes.append(n)
        self.nodes = nodes
        self.mna = MNA(self.circuit, current_inputs=[self.port], voltage_inputs=self.sources)
        self._rows = [self.mna.outputs.index(f"v({n})") for n in nodes] + \
                     [self.mna.outputs.index(f"i({v})") for v in self.sources]

    @property
    def k(self) -> int:
        """Number of changeable branches."""
        return len(self.branches)

    def transfer(self, values: Mapping[str, np.ndarray | float], s: np.ndarray) -> np.ndarray:
        """``T(s)`` for every parameter set: shape ``(P, nodes + k, 1 + k, F)``.

        Parameters
        ----------
        values : mapping
            Resolved element values of the (unprobed) circuit, scalars or length-P arrays.
        s : numpy.ndarray
            ``j 2 pi f``, rad/s.
        """
        vals = dict(values)
        for v in self.sources:
            vals[v.lower()] = 0.0
        ss = self.mna.state_space(vals)
        C = ss.C[:, self._rows]
        D = ss.D[:, self._rows]
        P, n = ss.A.shape[0], ss.A.shape[1]
        no, ni = C.shape[1], D.shape[2]
        if n == 0:
            return np.broadcast_to(D[..., None], (P, no, ni, s.size)).astype(complex)
        lam, V = np.linalg.eig(ss.A)
        out = np.empty((P, no, ni, s.size), complex)
        try:
            Vinv = np.linalg.inv(V)
            cond = np.linalg.norm(V, axis=(1, 2)) * np.linalg.norm(Vinv, axis=(1, 2))
        except np.linalg.LinAlgError:
            cond = np.full(P, np.inf)
            Vinv = np.zeros_like(V)
        good = np.flatnonzero(cond < MAX_CONDITION)
        if good.size:
            W = Vinv[good] @ ss.B[good]  # (g, n, ni)
            CV = C[good] @ V[good]  # (g, no, n)
            R = np.einsum("pon,pni->poin", CV, W).reshape(good.size, no * ni, n)
            inv = 1.0 / (s[None, None, :] - lam[good][:, :, None])  # (g, n, F)
            out[good] = (R @ inv).reshape(good.size, no, ni, s.size) + D[good][..., None]
        for p in np.flatnonzero(~(cond < MAX_CONDITION)):  # (nearly) defective: solve the resolvent
            eye = np.eye(n)
            X = np.linalg.solve(s[:, None, None] * eye - ss.A[p][None], np.broadcast_to(ss.B[p], (s.size, n, ni)))
            out[p] = np.moveaxis(C[p][None] @ X + D[p][None], 0, -1)
        return out

    def responses_from(self, T: np.ndarray, dz: np.ndarray | None, port_map=None) -> dict[str, np.ndarray]:
        """Responses ``(P, F)`` from ``T`` (P or 1 sets) and branch changes ``dz`` ``(P, F, k, k)``.

        ``port_map``: the impedance seen at the instrument as a function of the
        port impedance (a lead or a fixture capacitance); voltage ratios are
        then taken against the instrument's terminal voltage.
        """
        q = len(self.nodes)
        if dz is None or self.k == 0:
            z = T[:, :q, 0, :]
        else:
            k = self.k
            Tf = np.moveaxis(T, 3, 1)  # (P, F, no, ni)
            Tvp, Tvv = Tf[:, :, :q, 0], Tf[:, :, :q, 1:]
            Tip, Tiv = Tf[:, :, q:, 0], Tf[:, :, q:, 1:]
            M = np.eye(k) - Tiv @ dz
            rhs = np.broadcast_to(Tip[..., None], M.shape[:-1] + (1,))
            x = np.linalg.solve(M, rhs)
            y = (dz @ x)[..., 0]  # (P, F, k)
            z = np.moveaxis(Tvp + np.einsum("pfqk,pfk->pfq", np.broadcast_to(Tvv, y.shape[:2] + Tvv.shape[2:]), y), 1, 2)
        pos = {n: i for i, n in enumerate(self.nodes)}
        out = {}
        zin = z[:, 0]
        ratio_scale = 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            if port_map is not None:
                zin = port_map(zin)
                ratio_scale = z[:, 0] / zin
            for r in self.responses:
                if r.node is None:
                    out[r.name] = zin
                else:
                    def volt(n):
                        n = None if n is None else self.circuit.require_node(n)
                        return 0.0 if n in (None, GROUND) else z[:, pos[n]]
                    out[r.name] = (volt(r.node) - volt(r.minus)) / z[:, 0] * ratio_scale
        return out
