"""Modified nodal analysis and the exact reduction to state-space form.

The circuit equations, with node voltages ``v``, inductor currents ``i_L``
and voltage-source currents ``i_V``, are

.. math::

    C_n \\dot v + G v + A_L i_L + A_V i_V = B_I u, \\qquad
    L \\dot i_L = A_L^T v, \\qquad A_V^T v = B_V u .

Node voltages split into a capacitive part ``a`` (the range of ``C_n``) and
an algebraic part ``b`` (nodes with no capacitance, and one combination per
capacitor cluster that does not reach ground). Both bases are fixed by the
topology alone, so they are computed once; for the usual networks they are
plain node selections and the states are physical node voltages and
inductor currents. Eliminating ``b`` and ``i_V`` (a Schur complement) gives

.. math:: E \\dot x = A_x x + B_x u, \\qquad x = [a; i_L], \\quad E = \\mathrm{diag}(Q_1^T C_n Q_1, L),

then ``A = E^{-1} A_x``. Every step is batched over a population of
parameter sets, shape ``(P, ...)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit, Numeric, components_without_ground
from pris_cosim.errors import CircuitError


@dataclass
class StateSpace:
    """A batch of continuous-time state-space models ``x' = A x + B u, y = C x + D u``.

    Attributes
    ----------
    A, B, C, D : numpy.ndarray
        Shapes ``(P, n, n)``, ``(P, n, nu)``, ``(P, ny, n)``, ``(P, ny, nu)``; time in s.
    states, inputs, outputs : list of str
        Names: ``v(node)`` / ``i(L1)`` states, ``i_in(node)`` / ``v(V1)`` inputs,
        ``v(node)`` / ``i(V1)`` outputs.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    states: list[str]
    inputs: list[str]
    outputs: list[str]

    def select(self, outputs: Sequence[str]) -> "StateSpace":
        """The same systems restricted to the named outputs."""
        idx = [self.outputs.index(o) for o in outputs]
        return StateSpace(self.A, self.B, self.C[:, idx], self.D[:, idx], self.states, self.inputs, list(outputs))


class MNA:
    """Compiled topology of a circuit: stamps, incidence matrices and reduction bases.

    Parameters
    ----------
    circuit : Circuit
        The circuit (after any shorts). Independent sources in it are zeroed
        (V short, I open) unless listed in ``voltage_inputs``.
    current_inputs : sequence of str
        Nodes into which an input current (A) is injected from ground.
    voltage_inputs : sequence of str
        Names of V elements whose voltage (V) is an input.
    """

    def __init__(self, circuit: Circuit, current_inputs: Sequence[str] = (), voltage_inputs: Sequence[str] = ()):
        circuit.check_topology(current_inputs)
        self.circuit = circuit
        self.nodes = circuit.nodes
        N = len(self.nodes)
        index = {n: i for i, n in enumerate(self.nodes)}
        self._index = index

        incidence = self.incidence
        self.resistors = circuit.of_kind("R")
        self.capacitors = circuit.of_kind("C")
        self.inductors = circuit.inductors()
        self.vsources = circuit.of_kind("V")
        vkeys = {v.key: v for v in self.vsources}
        for name in voltage_inputs:
            if name.lower() not in vkeys:
                raise CircuitError(f"voltage input {name!r} is not a V element of the circuit")
        ar, ac = incidence(self.resistors), incidence(self.capacitors)
        # stamp matrices: G.flat = g @ Sg with Sg[j] = outer(a_j, a_j).flat
        self.Sg = np.einsum("ij,kj->jik", ar, ar).reshape(len(self.resistors), N * N)
        self.Sc = np.einsum("ij,kj->jik", ac, ac).reshape(len(self.capacitors), N * N)
        self.AL = incidence(self.inductors)
        self.AV = incidence(self.vsources)
        self.current_inputs = [circuit.require_node(n, "input node") for n in current_inputs]
        self.BI = np.zeros((N, len(self.current_inputs)))
        for j, n in enumerate(self.current_inputs):
            if n == GROUND:
                raise CircuitError("an input current cannot be injected at ground")
            self.BI[index[n], j] = 1.0
        self.voltage_inputs = [vkeys[n.lower()] for n in voltage_inputs]
        self.BV = np.zeros((len(self.vsources), len(self.voltage_inputs)))
        for j, v in enumerate(self.voltage_inputs):
            self.BV[self.vsources.index(v), j] = 1.0
        inductor_index = {e.key: i for i, e in enumerate(self.inductors)}
        self._couplings = []
        for k in circuit.of_kind("K"):
            try:
                self._couplings.append((k.key, *(inductor_index[n.lower()] for n in k.nodes)))
            except KeyError:
                bad = next(n for n in k.nodes if n.lower() not in inductor_index)
                raise CircuitError(f"element {k.name!r}: {bad!r} is not an inductor of the circuit") from None
        self._bases()
        self.states = [f"v({s})" for s in self.dynamic_labels] + [f"i({e.name})" for e in self.inductors]
        self.inputs = [f"i_in({n})" for n in self.current_inputs] + [f"v({v.name})" for v in self.voltage_inputs]
        self.outputs = [f"v({n})" for n in self.nodes] + [f"i({v.name})" for v in self.vsources]

    # ------------------------------------------------------------------ structure

    def incidence(self, elements: Sequence) -> np.ndarray:
        """Node-branch incidence matrix ``(nodes, elements)``: +1 at each element's first node, -1 at its second
        (ground has no row)."""
        a = np.zeros((len(self.nodes), len(elements)))
        for j, e in enumerate(elements):
            if e.nodes[0] != GROUND:
                a[self._index[e.nodes[0]], j] += 1.0
            if e.nodes[1] != GROUND:
                a[self._index[e.nodes[1]], j] -= 1.0
        return a
    def _bases(self) -> None:
        N = len(self.nodes)
        groups = components_without_ground([e.nodes for e in self.capacitors], self.nodes)
        q0_cols, q1_cols, labels = [], [], []
        in_group = {n for g in groups for n in g}
        for n in self.nodes:
            if n not in in_group:
                col = np.zeros(N)
                col[self._index[n]] = 1.0
                q1_cols.append(col)
                labels.append(n)
        for g in groups:
            idx = [self._index[n] for n in g]
            col = np.zeros(N)
            col[idx] = 1.0 / np.sqrt(len(idx))
            q0_cols.append(col)
            if len(idx) > 1:  # orthonormal differences within a floating capacitor cluster
                basis = np.linalg.svd(np.ones((1, len(idx))))[2][1:]
                for k, row in enumerate(basis):
                    c = np.zeros(N)
                    c[idx] = row
                    q1_cols.append(c)
                    labels.append(f"{g[0]}~{k}")
        self.Q1 = np.array(q1_cols).T.reshape(N, len(q1_cols))
        self.Q0 = np.array(q0_cols).T.reshape(N, len(q0_cols))
        self.dynamic_labels = labels
        if self.vsources and self.Q1.shape[1] and np.abs(self.AV.T @ self.Q1).max() > 0:
            bad = self.vsources[int(np.argmax(np.abs(self.AV.T @ self.Q1).max(axis=1)))]
            raise CircuitError(
                f"element {bad.name!r}: voltage source connects directly to a capacitor; "
                "put a resistor or inductor in series with it"
            )

    @property
    def n_states(self) -> int:
        return self.Q1.shape[1] + len(self.inductors)

    # ------------------------------------------------------------------ assembly
    def matrices(self, values: Mapping[str, Numeric]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batched ``G`` (S), ``C_n`` (F) and ``L`` (H) for resolved element values.

        Returns arrays of shape ``(P, N, N)``, ``(P, N, N)``, ``(P, m, m)``.
        """
        P = population_size(values)
        N = len(self.nodes)

        def column(elements: Sequence, real: bool = False) -> np.ndarray:
            vals = [values[e.key] for e in elements]
            cplx = not real and any(np.iscomplexobj(v) for v in vals)
            out = np.empty((P, len(elements)), complex if cplx else float)
            for j, v in enumerate(vals):
                out[:, j] = np.real(v) if real else v
            return out

        G = ((1.0 / column(self.resistors)) @ self.Sg).reshape(P, N, N)
        Cn = (column(self.capacitors) @ self.Sc).reshape(P, N, N)
        m = len(self.inductors)
        diag = column(self.inductors, real=True)
        L = np.zeros((P, m, m))
        L[:, np.arange(m), np.arange(m)] = diag
        for key, i, j in self._couplings:  # M_ij = k_ij sqrt(L_i L_j), as Circuit.inductance_matrix
            mutual = np.real(np.asarray(values[key])).astype(float) * np.sqrt(diag[:, i] * diag[:, j])
            L[:, i, j] += mutual
            L[:, j, i] += mutual
        return G, Cn, L

    def state_space(self, values: Mapping[str, Numeric]) -> StateSpace:
        """Exact state-space form for every parameter set in ``values``.

        Parameters
        ----------
        values : mapping
            Resolved element values (scalars or arrays of length P).

        Returns
        -------
        StateSpace
            Outputs are every node voltage and every V-source current.
        """
        G, Cn, L = self.matrices(values)
        P = G.shape[0]
        Q0, Q1, AL, AV = self.Q0, self.Q1, self.AL, self.AV
        r, n0, m, q = Q1.shape[1], Q0.shape[1], AL.shape[1], AV.shape[1]
        nI, nV = self.BI.shape[1], self.BV.shape[1]
        nx, k = r + m, n0 + q

        G11 = Q1.T @ G @ Q1
        G10 = Q1.T @ G @ Q0
        G00 = Q0.T @ G @ Q0
        C11 = Q1.T @ Cn @ Q1

        M = np.zeros((P, k, k))
        M[:, :n0, :n0] = G00
        M[:, :n0, n0:] = Q0.T @ AV
        M[:, n0:, :n0] = AV.T @ Q0
        Nx = np.zeros((P, k, nx))
        Nx[:, :n0, :r] = Q0.T @ G @ Q1
        Nx[:, :n0, r:] = Q0.T @ AL
        Nu = np.zeros((P, k, nI + nV))
        Nu[:, :n0, :nI] = Q0.T @ self.BI
        Nu[:, n0:, nI:] = self.BV
        if k:
            self._check_algebraic(M)
            Z = np.linalg.solve(M, np.concatenate([-Nx, Nu], axis=2))
            Zx, Zu = Z[:, :, :nx], Z[:, :, nx:]
        else:
            Zx, Zu = np.zeros((P, 0, nx)), np.zeros((P, 0, nI + nV))

        F = np.zeros((P, nx, nx))
        F[:, :r, :r] = -G11
        F[:, :r, r:] = -(Q1.T @ AL)
        F[:, r:, :r] = AL.T @ Q1
        H = np.zeros((P, nx, k))
        H[:, :r, :n0] = -G10
        H[:, :r, n0:] = -(Q1.T @ AV)
        H[:, r:, :n0] = AL.T @ Q0
        J = np.zeros((P, nx, nI + nV))
        J[:, :r, :nI] = Q1.T @ self.BI

        E = np.zeros((P, nx, nx))
        E[:, :r, :r] = C11
        E[:, r:, r:] = L
        rhs = np.concatenate([F + H @ Zx, J + H @ Zu], axis=2)
        try:
            sol = np.linalg.solve(E, rhs)
        except np.linalg.LinAlgError:
            raise CircuitError("inductance matrix is singular (a coupling of exactly |k| = 1 somewhere?)") from None
        A, B = sol[:, :, :nx], sol[:, :, nx:]

        N = len(self.nodes)
        C = np.zeros((P, N + q, nx))
        D = np.zeros((P, N + q, nI + nV))
        C[:, :N, :r] = Q1
        C[:, :N, :] += Q0 @ Zx[:, :n0, :]
        D[:, :N, :] = Q0 @ Zu[:, :n0, :]
        C[:, N:, :] = Zx[:, n0:, :]
        D[:, N:, :] = Zu[:, n0:, :]
        return StateSpace(A, B, C, D, list(self.states), list(self.inputs), list(self.outputs))

    def _check_algebraic(self, M: np.ndarray) -> None:
        s = np.linalg.svd(M[0], compute_uv=False)
        if s.size and s[-1] <= 1e-12 * s[0]:
            n0 = self.Q0.shape[1]
            zero_rows = [j for j in range(n0) if not np.any(M[0, j, :])]
            nodes = [n for j in zero_rows for n, w in zip(self.nodes, self.Q0[:, j]) if w]
            where = f"node(s) {', '.join(nodes)}" if nodes else "the network"
            raise CircuitError(
                f"{where}: no capacitive or resistive connection (only inductors or sources); "
                "the response is improper there"
            )

    # ------------------------------------------------------------------ dense path
    def solve_dense(self, values: Mapping[str, Numeric], s: np.ndarray, outputs: Sequence[int], chunk: int = 64) -> np.ndarray:
        """Responses by a dense complex solve of the full MNA system per frequency.

        Parameters
        ----------
        values : mapping
            Resolved element values (length-P arrays or scalars).
        s : numpy.ndarray
            Complex frequencies ``j 2 pi f``, rad/s, shape ``(F,)``.
        outputs : sequence of int
            Indices into the node list of the node voltages wanted.

        Returns
        -------
        numpy.ndarray
            Shape ``(P, len(outputs), nu, F)``: node voltage per unit input.
        """
        G, Cn, L = self.matrices(values)
        P, N, m, q = G.shape[0], len(self.nodes), L.shape[1], self.AV.shape[1]
        n = N + m + q
        nu = self.BI.shape[1] + self.BV.shape[1]
        rhs = np.zeros((n, nu))
        rhs[:N, : self.BI.shape[1]] = self.BI
        rhs[N + m :, self.BI.shape[1] :] = self.BV
        out = np.empty((P, len(outputs), nu, s.size), complex)
        static = np.zeros((P, n, n))
        static[:, :N, :N] = G
        static[:, :N, N : N + m] = self.AL
        static[:, N : N + m, :N] = -self.AL.T
        static[:, :N, N + m :] = self.AV
        static[:, N + m :, :N] = self.AV.T
        dyn = np.zeros((P, n, n))
        dyn[:, :N, :N] = Cn
        dyn[:, N : N + m, N : N + m] = L
        p_chunk = max(1, 4096 // max(1, min(chunk, s.size)))
        for p0 in range(0, P, p_chunk):
            st, dy = static[p0 : p0 + p_chunk, None], dyn[p0 : p0 + p_chunk, None]
            for f0 in range(0, s.size, chunk):
                sc = s[f0 : f0 + chunk]
                K = st + sc[None, :, None, None] * dy
                x = np.linalg.solve(K, np.broadcast_to(rhs, K.shape[:2] + rhs.shape))
                out[p0 : p0 + p_chunk, :, :, f0 : f0 + chunk] = np.moveaxis(x[:, :, list(outputs), :], 1, -1)
        return out


    def solve_grid(self, values: Mapping[str, Numeric], s: np.ndarray, outputs: Sequence[int]) -> np.ndarray:
        """Node voltages per unit input for element values that may vary with frequency.

        Parameters
        ----------
        values : mapping
            Resolved element values; each a scalar, an array of shape
            ``(P, 1)`` (per parameter set) or ``(P, F)`` / ``(F,)`` (per
            frequency: a skin-effect resistance, an inductance L(f)). Resistor
            values may be complex (frequency-dependent impedances).
        s : numpy.ndarray
            Complex frequencies, rad/s, shape ``(F,)``.
        outputs : sequence of int
            Node indices wanted.

        Returns
        -------
        numpy.ndarray
            Shape ``(P, F, len(outputs), nu)``.
        """
        shape = np.broadcast_shapes((1, s.size), *[np.shape(v) for v in values.values()])
        P, F = (1, shape[-1]) if len(shape) == 1 else shape
        N, m, q = len(self.nodes), len(self.inductors), self.AV.shape[1]
        n = N + m + q
        index = self._index
        K = np.zeros((P, F, n, n), complex)
        sv = s[None, :]

        def stamp(a: str, b: str, y: np.ndarray) -> None:
            ia, ib = index.get(a), index.get(b)
            y = np.broadcast_to(y, (P, F))
            if ia is not None:
                K[:, :, ia, ia] += y
            if ib is not None:
                K[:, :, ib, ib] += y
            if ia is not None and ib is not None:
                K[:, :, ia, ib] -= y
                K[:, :, ib, ia] -= y

        for e in self.resistors:
            stamp(*e.nodes, 1.0 / np.asarray(values[e.key]))
        for e in self.capacitors:
            stamp(*e.nodes, sv * np.asarray(values[e.key]))
        magnetic = [e.key for e in self.inductors] + [k.key for k in self.circuit.of_kind("K")]
        L = self.circuit.inductance_matrix({k: np.broadcast_to(np.real(values[k]), (P, F)) for k in magnetic})
        K[:, :, :N, N : N + m] = self.AL
        K[:, :, N : N + m, :N] = -self.AL.T
        K[:, :, N : N + m, N : N + m] = sv[:, :, None, None] * L
        K[:, :, :N, N + m :] = self.AV
        K[:, :, N + m :, :N] = self.AV.T
        nI = self.BI.shape[1]
        rhs = np.zeros((n, nI + self.BV.shape[1]))
        rhs[:N, :nI] = self.BI
        rhs[N + m :, nI:] = self.BV
        x = np.linalg.solve(K, np.broadcast_to(rhs, (P, F) + rhs.shape))
        return x[:, :, list(outputs), :]


def population_size(values: Mapping[str, Numeric]) -> int:
    """Number of parameter sets P in resolved values (1 when all are scalars)."""
    sizes = {np.size(v) for v in values.values() if np.ndim(v) > 0}
    if len(sizes) > 1 and not sizes <= {1, max(sizes)}:
        raise CircuitError(f"parameter arrays have different lengths {sorted(sizes)}")
    return max(sizes, default=1)
