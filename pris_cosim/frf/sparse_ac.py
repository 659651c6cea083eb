"""Sparse AC solve of large circuits (thousands of elements).

The dense paths of :mod:`pris_cosim.circuits.mna` hold stamp matrices of shape
``(elements, nodes * nodes)`` and solve ``(nodes x nodes)`` systems per
frequency; a 2000-section RC ladder would need tens of GiB. Here the same
modified nodal equations

.. math::

    \\begin{bmatrix} G + sC_n & A_L & A_V \\\\ -A_L^T & sL & 0 \\\\ A_V^T & 0 & 0 \\end{bmatrix}
    \\begin{bmatrix} v \\\\ i_L \\\\ i_V \\end{bmatrix} = \\begin{bmatrix} B_I u \\\\ 0 \\\\ 0 \\end{bmatrix}

are assembled once as sparse matrices (``scipy.sparse``) and factorised by a
sparse LU (``splu``) at each frequency. Memory grows with the number of
elements, time with elements times frequencies.

:class:`SparseMNA` offers the frequency-domain part of the :class:`~pris_cosim.circuits.mna.MNA`
interface (``nodes``, ``solve_dense``, ``solve_grid``), so
:class:`~pris_cosim.frf.response.ResponseModel` uses it for circuits above
:data:`SPARSE_ABOVE` unknowns (see :func:`use_sparse`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit, Numeric
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.mna import population_size

#: Unknowns (nodes + inductor currents + V-source currents) above which the sparse solve is used.
SPARSE_ABOVE = 400


def n_unknowns(circuit: Circuit) -> int:
    """Size of the MNA system of ``circuit``: nodes, inductor currents and V-source currents."""
    return len(circuit.nodes) + len(circuit.of_kind("L")) + len(circuit.of_kind("V"))


def use_sparse(circuit: Circuit) -> bool:
    """Whether ``circuit`` is large enough for the sparse solve (more than :data:`SPARSE_ABOVE` unknowns)."""
    return n_unknowns(circuit) > SPARSE_ABOVE


class SparseMNA:
    """Sparse modified nodal equations of a circuit driven by currents at given nodes.

    Parameters
    ----------
    circuit : Circuit
        The network (after any shorts); independent sources in it are zeroed
        (V short, I open).
    current_inputs : sequence of str
        Nodes into which an input current (A) is injected from ground.
    voltage_inputs : sequence of str
        Not supported here (an empty sequence); kept for the signature of
        :class:`~pris_cosim.circuits.mna.MNA`.
    """

    def __init__(self, circuit: Circuit, current_inputs: Sequence[str] = (), voltage_inputs: Sequence[str] = ()):
        if voltage_inputs:
            raise CircuitError("the sparse solve takes current inputs only")
        circuit.check_topology(current_inputs)
        self.circuit = circuit
        self.nodes = circuit.nodes
        self._index = {n: i for i, n in enumerate(self.nodes)}
        self.resistors = circuit.of_kind("R")
        self.capacitors = circuit.of_kind("C")
        self.inductors = circuit.of_kind("L")
        self.vsources = circuit.of_kind("V")
        self.couplings = circuit.of_kind("K")
        self.current_inputs = [circuit.require_node(n, "input node") for n in current_inputs]
        if GROUND in self.current_inputs:
            raise CircuitError("an input current cannot be injected at ground")
        self._lindex = {e.key: i for i, e in enumerate(self.inductors)}
        for k in self.couplings:
            for name in k.nodes:
                if name.lower() not in self._lindex:
                    raise CircuitError(f"element {k.name!r}: {name!r} is not an inductor of the circuit")
        N, m, q = len(self.nodes), len(self.inductors), len(self.vsources)
        self.size = N + m + q
        self._N, self._m = N, m

    # ------------------------------------------------------------------ structure
    def _terminals(self, elements: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """Node indices of both terminals (-1 for ground)."""
        a = np.array([self._index.get(e.nodes[0], -1) for e in elements], dtype=np.int64)
        b = np.array([self._index.get(e.nodes[1], -1) for e in elements], dtype=np.int64)
        return a, b

    @staticmethod
    def _two_terminal(a: np.ndarray, b: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """COO triplets of admittances ``y`` between nodes ``a`` and ``b`` (ground = -1 dropped)."""
        rows = np.concatenate([a, b, a, b])
        cols = np.concatenate([a, b, b, a])
        data = np.concatenate([y, y, -y, -y])
        keep = (rows >= 0) & (cols >= 0)
        return rows[keep], cols[keep], data[keep]

    def _matrices(self, values: Mapping[str, Numeric], p: int, P: int) -> tuple:
        """Sparse static part ``S`` and dynamic part ``D`` (``K(s) = S + s D``) of parameter set ``p``."""
        from scipy import sparse

        def column(elements: Sequence) -> np.ndarray:
            if not elements:
                return np.zeros(0)
            return np.array([np.broadcast_to(np.asarray(values[e.key]), (P,))[p] for e in elements])

        N, m, n = self._N, self._m, self.size
        rows, cols, data = [], [], []
        g = column(self.resistors)
        if g.size:
            with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
                r, c, d = self._two_terminal(*self._terminals(self.resistors), 1.0 / g)
            rows.append(r)
            cols.append(c)
            data.append(d)
        li = np.arange(m)
        la, lb = self._terminals(self.inductors)
        for sign, node in ((1.0, la), (-1.0, lb)):
            keep = node >= 0
            rows += [node[keep], N + li[keep]]
            cols += [N + li[keep], node[keep]]
            data += [np.full(keep.sum(), sign), np.full(keep.sum(), -sign)]
        va, vb = self._terminals(self.vsources)
        vi = np.arange(len(self.vsources))
        for sign, node in ((1.0, va), (-1.0, vb)):
            keep = node >= 0
            rows += [node[keep], N + m + vi[keep]]
            cols += [N + m + vi[keep], node[keep]]
            data += [np.full(keep.sum(), sign), np.full(keep.sum(), sign)]
        dtype = complex if any(np.iscomplexobj(x) for x in data) else float
        S = sparse.coo_matrix((np.concatenate(data).astype(dtype) if data else np.zeros(0),
                               (np.concatenate(rows) if rows else np.zeros(0, int),
                                np.concatenate(cols) if cols else np.zeros(0, int))), shape=(n, n)).tocsc()
        rows, cols, data = [], [], []
        cap = column(self.capacitors)
        if cap.size:
            r, c, d = self._two_terminal(*self._terminals(self.capacitors), cap)
            rows.append(r)
            cols.append(c)
            data.append(d)
        lval = np.real(column(self.inductors)).astype(float)
        rows.append(N + li)
        cols.append(N + li)
        data.append(lval)
        for k in self.couplings:
            i, j = (self._lindex[name.lower()] for name in k.nodes)
            kv = float(np.real(np.broadcast_to(np.asarray(values[k.key]), (P,))[p]))
            mutual = kv * np.sqrt(lval[i] * lval[j])
            rows.append(np.array([N + i, N + j]))
            cols.append(np.array([N + j, N + i]))
            data.append(np.array([mutual, mutual]))
        D = sparse.coo_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)).tocsc()
        return S, D

    def _rhs(self) -> np.ndarray:
        rhs = np.zeros((self.size, len(self.current_inputs)))
        for j, node in enumerate(self.current_inputs):
            rhs[self._index[node], j] = 1.0
        return rhs

    def _solve(self, K, rhs: np.ndarray, s: complex) -> np.ndarray:
        from scipy.sparse.linalg import splu

        try:
            with np.errstate(all="raise"):
                lu = splu(K.astype(complex).tocsc())
                x = lu.solve(rhs.astype(complex))
        except (RuntimeError, FloatingPointError):
            raise CircuitError(
                f"the circuit equations are singular or overflow at {abs(s) / (2 * np.pi):.6g} Hz "
                "(a node with only inductors or sources, or element values out of scale)") from None
        if not np.all(np.isfinite(x)):
            raise CircuitError(f"the circuit equations have no finite solution at {abs(s) / (2 * np.pi):.6g} Hz")
        return x

    # ------------------------------------------------------------------ frequency responses
    def state_space(self, values: Mapping[str, Numeric]):
        """Not available for large circuits: raises :class:`~pris_cosim.errors.CircuitError`."""
        raise CircuitError(
            f"circuit with {self.size} unknowns: no state-space form is built above {SPARSE_ABOVE}; "
            "frequency responses use the sparse solve")

    def solve_dense(self, values: Mapping[str, Numeric], s: np.ndarray, outputs: Sequence[int], chunk: int = 0) -> np.ndarray:
        """Node voltages per unit input current by a sparse LU solve per frequency.

        Same contract as :meth:`pris_cosim.circuits.mna.MNA.solve_dense`.

        Parameters
        ----------
        values : mapping
            Resolved element values (scalars or length-P arrays; resistor values may be complex).
        s : numpy.ndarray
            Complex frequencies ``j 2 pi f``, rad/s, shape ``(F,)``.
        outputs : sequence of int
            Indices into :attr:`nodes` of the node voltages wanted.
        chunk : int
            Unused (signature of the dense path).

        Returns
        -------
        numpy.ndarray
            Shape ``(P, len(outputs), nu, F)``, V/A.
        """
        P = population_size(values)
        rhs = self._rhs()
        out_idx = list(outputs)
        out = np.empty((P, len(out_idx), rhs.shape[1], s.size), complex)
        for p in range(P):
            S, D = self._matrices(values, p, P)
            for f, sf in enumerate(s):
                out[p, :, :, f] = self._solve(S + sf * D, rhs, sf)[out_idx]
        return out

    def solve_grid(self, values: Mapping[str, Numeric], s: np.ndarray, outputs: Sequence[int]) -> np.ndarray:
        """Node voltages per unit input for element values that may vary with frequency.

        Same contract as :meth:`pris_cosim.circuits.mna.MNA.solve_grid`: values are
        scalars, ``(P, 1)``, ``(F,)`` or ``(P, F)``; returns shape
        ``(P, F, len(outputs), nu)``.
        """
        shape = np.broadcast_shapes((1, s.size), *[np.shape(v) for v in values.values()])
        P, F = (1, shape[-1]) if len(shape) == 1 else shape
        rhs = self._rhs()
        out_idx = list(outputs)
        out = np.empty((P, F, len(out_idx), rhs.shape[1]), complex)
        grid = {k: np.broadcast_to(np.asarray(v), (P, F)) for k, v in values.items()}
        for f in range(F):
            at_f = {k: v[:, f] for k, v in grid.items()}
            for p in range(P):
                S, D = self._matrices(at_f, p, P)
                out[p, f] = self._solve(S + s[f] * D, rhs, s[f])[out_idx]
        return out


__all__ = ["SPARSE_ABOVE", "SparseMNA", "n_unknowns", "use_sparse"]
