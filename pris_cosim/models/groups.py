"""Responses of several test configurations of one circuit, grouped by the circuit they drive, and their
parameter sensitivities.

Test configurations that short the same nodes drive the same network: the
open-circuit tests of a two-winding transformer (LVOC, HVOC, LVHV, HVLV)
differ only in the port the current enters. :class:`GroupedResponseSet`
compiles one network per distinct set of shorts, with every port of its
configurations as an input, so one eigen-decomposition of the state matrix
serves them all (the pole-residue path of :class:`pris_cosim.frf.response.ResponseModel`,
one decomposition per configuration there), and resolves the element values
once per call instead of once per configuration. It returns the same
numbers as :class:`pris_cosim.models.builtin.ResponseSet` (to rounding).

:meth:`GroupedResponseSet.sensitivities` gives the derivatives of the
responses with respect to a set of parameters by the adjoint of the
augmented nodal system. With node voltages ``v`` and inductor currents
``i`` the network obeys

.. math::

    M(s) \\begin{bmatrix} v \\\\ i \\end{bmatrix}
    = \\begin{bmatrix} G + s C_n & A_L \\\\ A_L^T & -s L \\end{bmatrix}
      \\begin{bmatrix} v \\\\ i \\end{bmatrix} = \\begin{bmatrix} e_k \\\\ 0 \\end{bmatrix}

for a unit current into node ``k``. ``M`` is complex symmetric, so the
transfer impedance ``z_{ok} = e_o^T M^{-1} e_k`` has the derivative
``dz_{ok}/dp = -x_o^T (dM/dp) x_k`` with ``x_k = M^{-1} e_k``: one solve per
frequency serves every parameter. ``dM/dp`` is built from the derivatives of
``G``, ``C_n`` and ``L``; those are linear in the conductances, capacitances
and inductance-matrix entries, so differencing them between the base point
and a perturbed one is exact up to the perturbation of the parameter map
(ties, log scales, a passivity repair), which costs no circuit solve.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from pris_cosim.circuits.circuit import Circuit, Numeric
from pris_cosim.errors import CircuitError
from pris_cosim.frf.kernels import pole_residue_sum, pole_sum
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import Configuration


@dataclass
class _Group:
    """One shorted network: its MNA (inputs: every port of its configurations) and its outputs."""

    shorts: tuple[str, ...]
    circuit: Circuit
    mna: MNA
    ports: list[str]
    outputs: list[str]
    out_index: list[int]
    configurations: list[Configuration]
    incidence: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class NodalSolution:
    """The nodal solve of :meth:`GroupedResponseSet.nodal` at one parameter set.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        ``(F,)``, Hz.
    responses : dict
        Response name to complex ``(F,)``.
    states : list of tuple
        Per group: node voltages ``(F, N, outputs)`` (V/A), inductor currents ``(F, m, outputs)``
        (A/A) for a unit current into each output node, transfer impedances ``(outputs, inputs, F)``.
    """

    frequency_hz: np.ndarray
    responses: dict[str, np.ndarray]
    states: list[tuple[np.ndarray, np.ndarray, np.ndarray]]


class GroupedResponseSet:
    """The responses of several configurations of one circuit, one network per distinct set of shorts.

    Drop-in for :class:`pris_cosim.models.builtin.ResponseSet` on circuits without voltage sources.

    Parameters
    ----------
    circuit : Circuit
    configurations : sequence of Configuration
    """

    def __init__(self, circuit: Circuit, configurations: Sequence[Configuration]):
        self.circuit = circuit
        self.configurations = list(configurations)
        by_shorts: dict[tuple[str, ...], list[Configuration]] = {}
        for c in self.configurations:
            by_shorts.setdefault(tuple(sorted(c.shorts)), []).append(c)
        self.groups: list[_Group] = []
        for shorts, configs in by_shorts.items():
            net = circuit.shorted(shorts) if shorts else circuit
            ports = list(dict.fromkeys(net.require_node(c.port, "port") for c in configs))
            outputs = list(ports)
            for c in configs:
                for r in c.responses:
                    for n in (r.node, r.minus):
                        if n is None:
                            continue
                        n = net.require_node(n, f"node of response {r.name!r}")
                        if n != "0" and n not in outputs:
                            outputs.append(n)
            mna = MNA(net, current_inputs=ports)
            if mna.vsources:
                raise CircuitError("grouped responses take circuits without voltage sources")
            self.groups.append(_Group(shorts, net, mna, ports, outputs, [mna.nodes.index(n) for n in outputs],
                                      configs))
        self.names = [r.name for c in self.configurations for r in c.responses]

    # ------------------------------------------------------------------ values
    def values(self, overrides: Mapping[str, Numeric] | None = None) -> dict[str, Numeric]:
        """Resolved element values (once for every group), with the passivity warning of ``ResponseModel``."""
        values = self.circuit.resolve(overrides)
        self.circuit.check_passive(values, strict=False)
        return values

    @staticmethod
    def _combine(group: _Group, z: np.ndarray) -> dict[str, np.ndarray]:
        """Responses from transfer impedances ``z`` of shape ``(P, outputs, inputs, F)``."""
        pos = {n: i for i, n in enumerate(group.outputs)}
        out: dict[str, np.ndarray] = {}
        with np.errstate(divide="ignore", invalid="ignore"):
            for c in group.configurations:
                j = group.ports.index(group.circuit.require_node(c.port))

                def volt(n: str | None) -> np.ndarray | float:
                    n = None if n is None else group.circuit.require_node(n)
                    return 0.0 if n in (None, "0") else z[:, pos[n], j]

                for r in c.responses:
                    zin = z[:, pos[group.ports[j]], j]
                    out[r.name] = zin if r.node is None else (volt(r.node) - volt(r.minus)) / zin
        return out

    # ------------------------------------------------------------------ responses
    def evaluate(self, frequency_hz: Sequence[float] | np.ndarray, overrides: Mapping[str, Numeric] | None = None,
                 method: str = "fast") -> dict[str, np.ndarray]:
        """All responses, as :meth:`pris_cosim.models.builtin.ResponseSet.evaluate`.

        Parameters
        ----------
        frequency_hz : array_like, Hz
            ``(F,)`` positive frequencies.
        overrides : mapping, optional
            Parameter or element values; arrays of length P evaluate a population.
        method : {"fast", "dense"}
            One eigen-decomposition per group and parameter set (pole-residue sum), or a dense
            nodal solve per frequency.

        Returns
        -------
        dict
            Response name to complex ``(F,)`` (scalar values) or ``(P, F)``; impedances in Ohm.
        """
        f = np.asarray(frequency_hz, dtype=float)
        if f.ndim != 1 or f.size == 0 or np.any(~np.isfinite(f)) or np.any(f <= 0):
            raise CircuitError("frequencies must be a non-empty 1-D array of positive numbers (Hz)")
        if method not in ("fast", "dense"):
            raise CircuitError(f"unknown method {method!r} (use 'fast' or 'dense')")
        values = self.values(overrides)
        scalar = all(np.ndim(v) == 0 for v in values.values())
        s = 2j * np.pi * f
        out: dict[str, np.ndarray] = {}
        for g in self.groups:
            z = self._fast(g, values, s) if method == "fast" else g.mna.solve_dense(values, s, g.out_index)
            out.update(self._combine(g, z))
        return {r: (out[r][0] if scalar else out[r]) for r in self.names}

    @staticmethod
    def _fast(g: _Group, values: Mapping[str, Numeric], s: np.ndarray) -> np.ndarray:
        """``(P, outputs, inputs, F)`` transfer impedances from one eigen-decomposition per parameter set."""
        try:
            ss = g.mna.state_space(values).select([f"v({n})" for n in g.outputs])
        except CircuitError:  # improper: no state space
            return g.mna.solve_dense(values, s, g.out_index)
        lam, V = np.linalg.eig(ss.A)
        P, n = lam.shape
        ny, nu = ss.C.shape[1], ss.B.shape[2]
        with np.errstate(all="ignore"):
            try:
                Vi = np.linalg.inv(V)
            except np.linalg.LinAlgError:
                Vi = np.full_like(V, np.nan)
            cond = np.linalg.norm(V, axis=(1, 2)) * np.linalg.norm(Vi, axis=(1, 2))
            ok = np.isfinite(cond)
            W = np.full((P, n, nu), np.nan, complex)
            if np.any(ok):
                W[ok] = np.linalg.solve(V[ok], ss.B[ok].astype(complex))
        cv = ss.C @ V  # (P, ny, n)
        residues = (cv[:, :, None, :] * np.swapaxes(W, 1, 2)[:, None, :, :]).reshape(P, ny * nu, n)
        direct = ss.D.reshape(P, ny * nu)
        if np.isrealobj(ss.A):
            z = pole_residue_sum(lam, residues, direct, s.imag, compiled=True)
        else:
            z = pole_sum(lam, residues, direct, s)
        z = z.reshape(P, ny, nu, s.size)
        bad = np.flatnonzero(~(cond < 1e10))
        if bad.size:  # nearly defective eigenvectors: the dense solve there
            sub = {k: (np.asarray(v)[bad] if np.ndim(v) else v) for k, v in values.items()}
            z[bad] = g.mna.solve_dense(sub, s, g.out_index)
        return z

    # ------------------------------------------------------------------ nodal solve and derivatives
    def nodal(self, frequency_hz: Sequence[float] | np.ndarray, base: Mapping[str, Numeric]) -> NodalSolution:
        """Responses at one parameter set by the nodal solve, kept for :meth:`sensitivities`.

        With the inductor currents eliminated, ``(G + s C_n + A_L L^{-1} A_L^T / s) v = e_k``
        for every port ``k`` and response node (the adjoint right-hand sides); the inductor
        currents are ``i = L^{-1} A_L^T v / s``.

        Parameters
        ----------
        frequency_hz : array_like, Hz
            ``(F,)`` positive frequencies.
        base : mapping
            Overrides (scalars).

        Returns
        -------
        NodalSolution
        """
        f = np.asarray(frequency_hz, dtype=float)
        s = 2j * np.pi * f
        values = self.circuit.resolve(base, check=False)
        g0 = {e.key: 1.0 / _real(values[e.key]) for e in self.circuit.of_kind("R")}
        c0 = {e.key: _real(values[e.key]) for e in self.circuit.of_kind("C")}
        L0 = self.circuit.inductance_matrix({k: _real(values[k]) for k in self._magnetic()})
        order = [e.key for e in self.circuit.inductors()]
        states, resp = [], {}
        for g in self.groups:
            if [e.key for e in g.mna.inductors] != order:  # pragma: no cover - shorting keeps the element order
                raise CircuitError("grouped responses: inductor order differs between the networks")
            mna = g.mna
            AR, AC = self._incidence(g, "R", mna.resistors), self._incidence(g, "C", mna.capacitors)
            gv = np.array([g0[e.key] for e in mna.resistors], float).reshape(-1)
            cv = np.array([c0[e.key] for e in mna.capacitors], float).reshape(-1)
            N = AR.shape[0]
            if mna.AL.shape[1]:
                B = np.linalg.solve(L0, mna.AL.T)  # L^-1 A_L^T, (m, N)
                gamma = mna.AL @ B
            else:
                B, gamma = np.zeros((0, N)), np.zeros((N, N))
            Y = ((AR * gv) @ AR.T)[None] + s[:, None, None] * ((AC * cv) @ AC.T)[None] + gamma[None] / s[:, None, None]
            E = np.zeros((N, len(g.out_index)))
            E[g.out_index, np.arange(len(g.out_index))] = 1.0
            X = np.linalg.solve(Y, np.broadcast_to(E, (f.size, N, E.shape[1])))  # (F, N, outputs)
            XI = (B @ X) / s[:, None, None]  # inductor currents, (F, m, outputs)
            inputs = [g.outputs.index(p) for p in g.ports]
            z = np.moveaxis(X[:, g.out_index][:, :, inputs], 0, -1)  # (outputs, inputs, F)
            states.append((X, XI, z))
            resp.update({k: v[0] for k, v in self._combine(g, z[None]).items()})
        return NodalSolution(f, {r: resp[r] for r in self.names}, states)

    def sensitivities(self, frequency_hz: Sequence[float] | np.ndarray, base: Mapping[str, Numeric],
                      upper: Mapping[str, Numeric], steps: np.ndarray, lower: Mapping[str, Numeric] | None = None,
                      solution: NodalSolution | None = None) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Responses at one parameter set and their derivatives along ``n`` directions (adjoint nodal solve).

        The element values are differenced between ``upper`` and ``lower`` (``base`` when omitted):
        direction ``i`` moves the point by ``steps[i]`` from ``lower`` to ``upper``. Central
        differences (``lower`` the base moved back) are worth their negligible cost: with couplings
        near 1 the responses depend on small differences of inductance-matrix entries, which
        amplifies the truncation error of a one-sided step.

        Parameters
        ----------
        frequency_hz : array_like, Hz
            ``(F,)`` positive frequencies.
        base : mapping
            Overrides (scalars) of the point where the derivatives are taken.
        upper : mapping
            Overrides of ``n`` points (length-``n`` arrays), one per direction.
        steps : numpy.ndarray
            ``(n,)`` distance from ``lower`` to ``upper`` along each direction (in the units of the
            directions, nonzero).
        lower : mapping, optional
            Overrides of the ``n`` points the differences start from (default: ``base``).
        solution : NodalSolution, optional
            :meth:`nodal` at ``base`` on the same frequencies, when already computed.

        Returns
        -------
        responses : dict
            Name to complex ``(F,)`` at ``base`` (from the nodal solve).
        jacobian : dict
            Name to complex ``(F, n)``: the derivative along each direction (response units per
            direction unit).
        """
        f = np.asarray(frequency_hz, dtype=float)
        if solution is None or solution.frequency_hz.shape != f.shape or np.any(solution.frequency_hz != f):
            solution = self.nodal(f, base)
        s = 2j * np.pi * f
        h = np.asarray(steps, float)
        n = h.size
        v1 = self.circuit.resolve(upper, check=False)
        vm = self.circuit.resolve(base if lower is None else lower, check=False)

        def derivatives(kind: str, transform) -> dict[str, np.ndarray]:
            return {e.key: (transform(np.broadcast_to(_real(v1[e.key]), (n,)))
                            - transform(np.broadcast_to(_real(vm[e.key]), (n,)))) / h for e in self.circuit.of_kind(kind)}

        dg = derivatives("R", lambda r: 1.0 / r)
        dc = derivatives("C", lambda c: c)
        magnetic = self._magnetic()
        dL = (self.circuit.inductance_matrix({k: np.broadcast_to(_real(v1[k]), (n,)) for k in magnetic})
              - self.circuit.inductance_matrix({k: np.broadcast_to(_real(vm[k]), (n,)) for k in magnetic})) / h[:, None, None]
        jac: dict[str, np.ndarray] = {}
        for g, (X, XI, z) in zip(self.groups, solution.states):
            dz = self._adjoint(g, X, XI, dg, dc, dL, s)
            pos = {nd: i for i, nd in enumerate(g.outputs)}
            for c in g.configurations:
                j = g.ports.index(g.circuit.require_node(c.port))
                zin, dzin = z[pos[g.ports[j]], j], dz[pos[g.ports[j]], j]
                for r in c.responses:
                    if r.node is None:
                        jac[r.name] = dzin.T
                        continue
                    num = np.zeros(f.size, complex)
                    dnum = np.zeros(dzin.shape, complex)
                    for node, sign in ((r.node, 1.0), (r.minus, -1.0)):
                        node = None if node is None else g.circuit.require_node(node)
                        if node not in (None, "0"):
                            num = num + sign * z[pos[node], j]
                            dnum = dnum + sign * dz[pos[node], j]
                    with np.errstate(divide="ignore", invalid="ignore"):
                        jac[r.name] = ((dnum - (num / zin)[None] * dzin) / zin[None]).T
        return dict(solution.responses), {r: jac[r] for r in self.names}

    def _magnetic(self) -> list[str]:
        return [e.key for e in self.circuit.inductors()] + [k.key for k in self.circuit.of_kind("K")]

    @staticmethod
    def _incidence(g: _Group, kind: str, elements: Sequence) -> np.ndarray:
        """``(N, len(elements))`` node incidence of the group's R or C elements (computed once)."""
        if kind in g.incidence:
            return g.incidence[kind]
        index = {nd: i for i, nd in enumerate(g.mna.nodes)}
        a = np.zeros((len(index), len(elements)))
        for j, e in enumerate(elements):
            if e.nodes[0] in index:
                a[index[e.nodes[0]], j] += 1.0
            if e.nodes[1] in index:
                a[index[e.nodes[1]], j] -= 1.0
        g.incidence[kind] = a
        return a

    def _adjoint(self, g: _Group, X: np.ndarray, XI: np.ndarray, dg: Mapping[str, np.ndarray],
                 dc: Mapping[str, np.ndarray], dL: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Derivatives ``(outputs, inputs, n, F)`` of the transfer impedances: ``-x_o^T dM x_k``.

        ``X``, ``XI``: node voltages ``(F, N, outputs)`` and inductor currents ``(F, m, outputs)``
        for unit currents into the output nodes; ``dg``, ``dc``: element key to the ``(n,)``
        derivatives of its conductance (S) or capacitance (F); ``dL``: ``(n, m, m)``, H.
        """
        mna = g.mna
        AR, AC = self._incidence(g, "R", mna.resistors), self._incidence(g, "C", mna.capacitors)
        n, m = dL.shape[0], dL.shape[1]
        DG = np.array([dg[e.key] for e in mna.resistors]).reshape(-1, n)  # (nR, n)
        DC = np.array([dc[e.key] for e in mna.capacitors]).reshape(-1, n)
        F, no = X.shape[0], X.shape[2]
        inputs = [g.outputs.index(p) for p in g.ports]
        ni = len(inputs)
        # per element (a_e^T x_o)(a_e^T x_k) times its derivatives; L as a full matrix
        pr, pc = AR.T @ X, AC.T @ X  # (F, elements, outputs)
        rows = F * no * ni
        t_r = (pr[:, :, :, None] * pr[:, :, None, inputs]).transpose(0, 2, 3, 1).reshape(rows, -1) @ DG
        t_c = (pc[:, :, :, None] * pc[:, :, None, inputs]).transpose(0, 2, 3, 1).reshape(rows, -1) @ DC
        t_l = np.einsum("fao,fbj->fojab", XI, XI[:, :, inputs]).reshape(rows, m * m) @ dL.reshape(n, m * m).T
        sv = np.repeat(s, no * ni)[:, None]
        dz = -(t_r + sv * (t_c - t_l))
        return np.moveaxis(dz.reshape(F, no, ni, n), 0, -1)


def _real(v: Numeric) -> np.ndarray:
    return np.real(np.asarray(v, float))


__all__ = ["GroupedResponseSet", "NodalSolution"]
