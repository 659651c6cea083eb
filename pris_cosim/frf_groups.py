"""Responses of several test configurations of one circuit, grouped by the circuit they drive, and their
parameter sensitivities.

Test configurations that short the same nodes drive the same network: the
open-circuit tests of a two-winding transformer (LVOC, HVOC, LVHV, HVLV)
differ only in the port the current enters. :class:`GroupedResponseSet`
compiles one network per distinct set of shorts, with every port of its
configurations as an input, so one eigen-decomposition of the state matrix
serves them all (the pole-residue path of :class:`pris_cosim.frf.ResponseModel`,
one decomposition per configuration there), and resolves the element values
once per call instead of once per configuration. It returns the same
numbers as :class:`pris_cosim.models.ResponseSet` (to rounding).

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

from .circuit import Circuit, Numeric
from .errors import CircuitError
from .frf_kernels import pole_residue_sum, pole_sum
from .mna import MNA
from .models import Configuration


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


class GroupedResponseSet:
    """The responses of several configurations of one circuit, one network per distinct set of shorts.

    Drop-in for :class:`pris_cosim.models.ResponseSet` on circuits without voltage sources.

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
        """All responses, as :meth:`pris_cosim.models.ResponseSet.evaluate`.

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

    # ------------------------------------------------------------------ derivatives
    def sensitivities(self, frequency_hz: Sequence[float] | np.ndarray, base: Mapping[str, Numeric],
                      upper: Mapping[str, Numeric], steps: np.ndarray, lower: Mapping[str, Numeric] | None = None
                      ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
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

        Returns
        -------
        responses : dict
            Name to complex ``(F,)`` at ``base`` (from the nodal solve).
        jacobian : dict
            Name to complex ``(F, n)``: the derivative along each direction (response units per
            direction unit).
        """
        f = np.asarray(frequency_hz, dtype=float)
        s = 2j * np.pi * f
        h = np.asarray(steps, float)
        n = h.size
        v0 = self.circuit.resolve(base, check=False)
        v1 = self.circuit.resolve(upper, check=False)
        vm = v0 if lower is None else self.circuit.resolve(lower, check=False)

        def real(v: Numeric) -> np.ndarray:
            return np.real(np.asarray(v, float))

        def element_derivatives(kind: str, transform) -> tuple[dict[str, float], dict[str, np.ndarray]]:
            x0, dx = {}, {}
            for e in self.circuit.of_kind(kind):
                a = transform(np.broadcast_to(real(vm[e.key]), (n,)))
                b = transform(np.broadcast_to(real(v1[e.key]), (n,)))
                x0[e.key], dx[e.key] = float(transform(real(v0[e.key]))), (b - a) / h
            return x0, dx

        g0, dg = element_derivatives("R", lambda r: 1.0 / r)
        c0, dc = element_derivatives("C", lambda c: c)
        magnetic = [e.key for e in self.circuit.inductors()] + [k.key for k in self.circuit.of_kind("K")]
        L0 = self.circuit.inductance_matrix({k: real(v0[k]) for k in magnetic})
        L1 = self.circuit.inductance_matrix({k: np.broadcast_to(real(v1[k]), (n,)) for k in magnetic})
        Lm = self.circuit.inductance_matrix({k: np.broadcast_to(real(vm[k]), (n,)) for k in magnetic})
        dL = (L1 - Lm) / h[:, None, None]
        order = [e.key for e in self.circuit.inductors()]
        resp: dict[str, np.ndarray] = {}
        jac: dict[str, np.ndarray] = {}
        for g in self.groups:
            if [e.key for e in g.mna.inductors] != order:  # pragma: no cover - shorting keeps the element order
                raise CircuitError("grouped responses: inductor order differs between the networks")
            z, dz = self._adjoint(g, (g0, dg), (c0, dc), (L0, dL), s)
            resp.update({k: v[0] for k, v in self._combine(g, z[None]).items()})
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
        return {r: resp[r] for r in self.names}, {r: jac[r] for r in self.names}

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

    def _adjoint(self, g: _Group, cond: tuple[dict, dict], cap: tuple[dict, dict], ind: tuple[np.ndarray, np.ndarray],
                 s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Transfer impedances ``(outputs, inputs, F)`` and their derivatives ``(outputs, inputs, n, F)``.

        ``cond``, ``cap``: element key to value (S, F) and to its ``(n,)`` derivatives; ``ind``: the
        inductance matrix (H) and its ``(n, m, m)`` derivatives.
        """
        mna = g.mna
        AR, AC = self._incidence(g, "R", mna.resistors), self._incidence(g, "C", mna.capacitors)
        gv = np.array([cond[0][e.key] for e in mna.resistors]).reshape(-1)
        cv = np.array([cap[0][e.key] for e in mna.capacitors]).reshape(-1)
        dg = np.array([cond[1][e.key] for e in mna.resistors]).reshape(len(gv), -1)  # (nR, n)
        dc = np.array([cap[1][e.key] for e in mna.capacitors]).reshape(len(cv), -1)
        L0, dL = ind
        N, m = AR.shape[0], L0.shape[0]
        K, F, n = N + m, s.size, dL.shape[0]
        M = np.zeros((F, K, K), complex)
        M[:, :N, :N] = (AR * gv) @ AR.T + s[:, None, None] * ((AC * cv) @ AC.T)
        M[:, :N, N:] = mna.AL
        M[:, N:, :N] = mna.AL.T
        M[:, N:, N:] = -s[:, None, None] * L0
        E = np.zeros((K, len(g.out_index)))
        E[g.out_index, np.arange(len(g.out_index))] = 1.0
        X = np.linalg.solve(M, np.broadcast_to(E, (F, K, E.shape[1])))  # (F, K, outputs)
        inputs = [g.outputs.index(p) for p in g.ports]
        z = np.moveaxis(X[:, g.out_index][:, :, inputs], 0, -1)  # (outputs, inputs, F)
        no, ni = X.shape[2], len(inputs)
        # x_o^T dM_p x_j: per element, (a_e^T x_o)(a_e^T x_j) times its derivatives; L as a full matrix
        pr, pc = AR.T @ X[:, :N], AC.T @ X[:, :N]  # (F, elements, outputs)
        xi = X[:, N:]
        rows = F * no * ni
        t_r = (pr[:, :, :, None] * pr[:, :, None, inputs]).transpose(0, 2, 3, 1).reshape(rows, -1) @ dg
        t_c = (pc[:, :, :, None] * pc[:, :, None, inputs]).transpose(0, 2, 3, 1).reshape(rows, -1) @ dc
        t_l = np.einsum("fao,fbj->fojab", xi, xi[:, :, inputs]).reshape(rows, m * m) @ dL.reshape(n, m * m).T
        sv = np.repeat(s, no * ni)[:, None]
        dz = -(t_r + sv * (t_c - t_l))
        return z, np.moveaxis(dz.reshape(F, no, ni, n), 0, -1)


__all__ = ["GroupedResponseSet"]
