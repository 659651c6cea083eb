"""Fast responses of a circuit whose branch impedances change with frequency.

A frequency-dependent element (a skin-effect resistance, an inductance that
falls with frequency, a core-loss resistance) would need a dense nodal solve
at every frequency. Instead each such branch gets a voltage source ``V_j``
in series (inserted at a terminal without capacitance, so the state-space
reduction of :class:`pris_cosim.circuits.mna.MNA` still applies). The circuit with
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

Derivatives of the responses with respect to the circuit values come from
the full nodal system closed by the branch changes, ``K(s) u = b`` (node
voltages, inductor and source currents; a probe source's row reads
``v_+ - v_- - dZ i = 0``): ``dv/dp = -U (dK/dp) X`` with ``X = K^{-1} b`` and
``U`` the output rows of ``K^{-1}``, the same for every value. A resistor
or capacitor between nodes ``a`` and ``b`` stamps ``g (e_a - e_b)(e_a - e_b)^T``,
so its term is a product of two differences; the inductances enter through
the ``s L`` block, a branch change through ``-dZ``. The network is
reciprocal, so ``U`` is ``X`` for currents injected at the response nodes,
and ``X`` comes from the pole-residue form of the evaluation that gave the
responses (the states include the inductor currents), without a solve per
frequency (:meth:`ProbedConfiguration.response_derivatives`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.frf.response import Response
from pris_cosim.circuits.mna import MNA

#: Eigenvector condition number above which the resolvent is solved directly instead.
MAX_CONDITION = 1e10
#: Eigenvector condition number up to which the derivatives use the kept eigen-decomposition (as the responses).
KEPT_CONDITION = MAX_CONDITION


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

        def where(n: str | None) -> int | None:
            n = None if n is None else c.require_node(n)
            return None if n in (None, GROUND) else nodes.index(n)

        #: Per response: its name and the indices (in ``nodes``) of its two nodes (None for ground).
        self._terms = [(r.name, where(r.node), where(r.minus)) for r in self.responses]
        self._impedances = {r.name for r in self.responses if r.node is None}
        # a current input at every response node (the port first): the derivatives need each output's row
        # of the inverse, which reciprocity gives as the response to a current injected there
        self.mna = MNA(self.circuit, current_inputs=nodes, voltage_inputs=self.sources)
        self._rows = [self.mna.outputs.index(f"v({n})") for n in nodes] + \
                     [self.mna.outputs.index(f"i({v})") for v in self.sources]
        self._cols = [0] + list(range(len(nodes), len(nodes) + len(self.sources)))
        self._nodal: dict | None = None
        #: Eigen-decomposition of the last single parameter set (:meth:`transfer` with ``keep``).
        self._kept: dict | None = None

    @property
    def k(self) -> int:
        """Number of changeable branches."""
        return len(self.branches)

    def port_system(self, values: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``A, B, C, D`` of the port impedance (current into the port, port voltage out) for one parameter set.

        ``B`` is ``(n, 1)``, ``C`` ``(1, n)``, ``D`` ``(1, 1)``; the branch sources are zero.
        """
        vals = dict(values)
        for v in self.sources:
            vals[v.lower()] = 0.0
        ss = self.mna.state_space(vals)
        return (ss.A[0], ss.B[0][:, [self._cols[0]]], ss.C[0][[self._rows[0]], :],
                np.atleast_2d(ss.D[0][self._rows[0], self._cols[0]]))

    def transfer(self, values: Mapping[str, np.ndarray | float], s: np.ndarray, keep: bool = False) -> np.ndarray:
        """``T(s)`` for every parameter set: shape ``(P, nodes + k, 1 + k, F)``.

        Parameters
        ----------
        values : mapping
            Resolved element values of the (unprobed) circuit, scalars or length-P arrays.
        s : numpy.ndarray
            ``j 2 pi f``, rad/s.
        keep : bool
            Keep the eigen-decomposition of a single parameter set for
            :meth:`response_derivatives` at the same values.
        """
        vals = dict(values)
        for v in self.sources:
            vals[v.lower()] = 0.0
        ss = self.mna.state_space(vals)
        C = ss.C[:, self._rows]
        D = ss.D[:, self._rows][:, :, self._cols]
        B = ss.B[:, :, self._cols]
        P, n = ss.A.shape[0], ss.A.shape[1]
        no, ni = C.shape[1], D.shape[2]
        if keep:
            self._kept = None
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
        if keep and P == 1:
            self._kept = {"lam": lam[0], "V": V[0], "Vinv": Vinv[0], "B": ss.B[0], "C": ss.C[0], "D": ss.D[0],
                          "cond": float(cond[0])}
        good = np.flatnonzero(cond < MAX_CONDITION)
        if good.size:
            W = Vinv[good] @ B[good]  # (g, n, ni)
            CV = C[good] @ V[good]  # (g, no, n)
            R = np.einsum("pon,pni->poin", CV, W).reshape(good.size, no * ni, n)
            inv = 1.0 / (s[None, None, :] - lam[good][:, :, None])  # (g, n, F)
            out[good] = (R @ inv).reshape(good.size, no, ni, s.size) + D[good][..., None]
        for p in np.flatnonzero(~(cond < MAX_CONDITION)):  # (nearly) defective: solve the resolvent
            eye = np.eye(n)
            X = np.linalg.solve(s[:, None, None] * eye - ss.A[p][None], np.broadcast_to(B[p], (s.size, n, ni)))
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
        out = {}
        zin = z[:, 0]
        ratio_scale = 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            if port_map is not None:
                zin = port_map(zin)
                ratio_scale = z[:, 0] / zin
            for name, plus, minus in self._terms:
                if name in self._impedances:
                    out[name] = zin
                else:
                    v = (0.0 if plus is None else z[:, plus]) - (0.0 if minus is None else z[:, minus])
                    out[name] = v / z[:, 0] * ratio_scale
        return out

    # ------------------------------------------------------------------ derivatives
    def _nodal_structure(self) -> dict:
        """Incidence matrices and row indices of the full nodal system (built once)."""
        if self._nodal is None:
            mna = self.mna
            N, m, q = len(mna.nodes), len(mna.inductors), len(mna.vsources)
            index = {n: i for i, n in enumerate(mna.nodes)}

            incidence = mna.incidence
            ind = {e.key: i for i, e in enumerate(mna.inductors)}
            sources = {v.key: i for i, v in enumerate(mna.vsources)}
            sign = np.ones(N + m + q)
            sign[N:N + m] = -1.0
            self._nodal = {
                "N": N, "m": m, "q": q, "sign": sign,
                "nodes": np.array([index[n] for n in self.nodes], int),
                "probes": N + m + np.array([sources[v.lower()] for v in self.sources], int),
                "AR": incidence(mna.resistors), "AC": incidence(mna.capacitors),
                "couplings": [(k, ind[k.nodes[0].lower()], ind[k.nodes[1].lower()])
                              for k in self.circuit.of_kind("K")],
            }
        return self._nodal

    def nodal_solution(self, values: Mapping[str, np.ndarray | float], s: np.ndarray,
                       dz: np.ndarray | None = None) -> np.ndarray:
        """Solution of the full nodal system for a unit current into each response node, ``(F, n, nodes)``.

        The unknowns are the node voltages, the inductor currents and the
        source currents; the branch changes ``dz`` ``(1, F, k, k)`` close the
        probe sources (their rows read ``v_+ - v_- - dZ i = 0``). The network
        is reciprocal (R, L, C, K and sources, ``dZ`` symmetric): ``K^T = S K S``
        with ``S = diag(1, -1, 1)``, so row ``o`` of ``K^{-1}`` is the ``S``-signed
        column ``o``, and the first column (the port current) also gives every
        output's row.

        Parameters
        ----------
        values : mapping
            Resolved element values of one parameter set (scalars or length-1 arrays).
        s : numpy.ndarray
            ``j 2 pi f``, rad/s.
        dz : numpy.ndarray, optional
            Branch changes, Ohm.
        """
        st = self._nodal_structure()
        N, m, q = st["N"], st["m"], st["q"]
        vals = {k: np.ravel(v)[:1] for k, v in values.items()}
        for v in self.sources:
            vals[v.lower()] = np.zeros(1)
        G, Cn, L = self.mna.matrices(vals)
        n = N + m + q
        sv = s[:, None, None]
        K = np.zeros((s.size, n, n), complex)
        K[:, :N, :N] = G[0] + sv * Cn[0]
        K[:, :N, N:N + m] = self.mna.AL
        K[:, N:N + m, :N] = -self.mna.AL.T
        K[:, N:N + m, N:N + m] = sv * L[0]
        K[:, :N, N + m:] = self.mna.AV
        K[:, N + m:, :N] = self.mna.AV.T
        if dz is not None and self.k:
            p = st["probes"]
            K[:, p[:, None], p[None, :]] -= dz[0]
        b = np.zeros((n, st["nodes"].size))
        b[st["nodes"], np.arange(st["nodes"].size)] = 1.0
        return np.linalg.solve(K, np.broadcast_to(b, (s.size, n, b.shape[1])))

    def kept_solution(self, s: np.ndarray, dz: np.ndarray | None = None) -> np.ndarray | None:
        """:meth:`nodal_solution` from the eigen-decomposition kept by :meth:`transfer` (None when none is kept or
        its eigenvectors are not well conditioned).

        The state-space outputs give the node voltages and source currents,
        the states the inductor currents; the branch changes close the probe
        sources as in :meth:`responses_from`.
        """
        kept = self._kept
        if kept is None or not kept["cond"] < KEPT_CONDITION:
            return None
        st = self._nodal_structure()
        N, m, q = st["N"], st["m"], st["q"]
        n = kept["lam"].size
        r = n - m
        full = np.zeros((N + m + q, n))  # unknowns of the nodal system from the states
        full[:N] = kept["C"][:N]
        full[N + m:] = kept["C"][N:]
        full[N:N + m, r:] = np.eye(m)
        direct = np.zeros((N + m + q, kept["D"].shape[1]))
        direct[:N] = kept["D"][:N]
        direct[N + m:] = kept["D"][N:]
        CV = full @ kept["V"]  # (n_full, n)
        W = kept["Vinv"] @ kept["B"]  # (n, inputs)
        g = 1.0 / (s[None, :] - kept["lam"][:, None])  # (n, F)
        nf, ni = CV.shape[0], W.shape[1]
        T = ((CV[:, None, :] * W.T[None, :, :]).reshape(nf * ni, n) @ g).reshape(nf, ni, s.size)
        T = np.moveaxis(T + direct[..., None], 2, 0)  # (F, n_full, inputs)
        nq = len(self.nodes)
        X = T[:, :, :nq]
        if dz is not None and self.k:
            p = st["probes"]
            M = np.eye(self.k) - T[:, p, nq:] @ dz[0]
            y = dz[0] @ np.linalg.solve(M, T[:, p, :nq])  # probe voltages (F, k, nodes)
            X = X + T[:, :, nq:] @ y
        return X

    def response_derivatives(self, values: Mapping[str, np.ndarray | float], slopes: Mapping[str, np.ndarray],
                             s: np.ndarray, dz: np.ndarray | None = None, ddz: np.ndarray | None = None,
                             kept: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Response node voltages per unit port current, ``(1, nodes, F)``, and their derivatives ``(J, nodes, F)``.

        ``dv/dp = -U (dK/dp) X`` on the closed nodal system
        (:meth:`nodal_solution`): a resistor or capacitor between nodes ``a``
        and ``b`` stamps ``g (e_a - e_b)(e_a - e_b)^T`` (an outer product of two
        differences), an inductance through the ``s L`` block, a branch change
        through ``-dZ`` at the probe sources.

        Parameters
        ----------
        values : mapping
            Resolved element values of one parameter set (scalars or length-1 arrays).
        slopes : mapping
            Element name (lower case) to the derivative of its value along each
            of J directions, shape ``(J,)`` (SI units per unit of the direction);
            elements not named do not change.
        s : numpy.ndarray
            ``j 2 pi f``, rad/s.
        dz, ddz : numpy.ndarray, optional
            Branch changes ``(1, F, k, k)``, Ohm, and their derivatives ``(J, F, k, k)``.
        kept : bool
            ``values`` are those of the last :meth:`transfer` with ``keep``: its
            eigen-decomposition gives the nodal solution (:meth:`kept_solution`)
            instead of a solve per frequency.
        """
        st = self._nodal_structure()
        N, m = st["N"], st["m"]
        J = len(next(iter(slopes.values()))) if slopes else (0 if ddz is None else ddz.shape[0])
        Y = self.kept_solution(s, dz) if kept else None
        if Y is None:
            Y = self.nodal_solution(values, s, dz)  # (F, n, no)
        X = Y[:, :, 0]  # the port current's solution (F, n)
        U = np.swapaxes(Y * st["sign"][None, :, None], 1, 2)  # output rows of K^-1 (F, no, n)
        F, no = s.size, U.shape[1]
        z = np.moveaxis(Y[:, st["nodes"], 0], 0, 1)[None]  # (1, no, F)
        terms, weights = [], []
        mna = self.mna

        def val(key: str) -> float:
            return float(np.real(np.ravel(values[key])[0]))

        for elements, inc, kind in ((mna.resistors, st["AR"], "R"), (mna.capacitors, st["AC"], "C")):
            used = [j for j, e in enumerate(elements) if e.key in slopes]
            if not used:
                continue
            a = inc[:, used]
            t = (U[:, :, :N] @ a) * (X[:, :N] @ a)[:, None, :]  # (F, no, e)
            if kind == "R":  # dK/dR = -(1/R^2) a a^T
                t = t * np.array([1.0 / val(elements[j].key) ** 2 for j in used])
            else:  # dK/dC = s a a^T
                t = t * -s[:, None, None]
            terms.append(t)
            weights += [slopes[elements[j].key] for j in used]
        magnetic = [(i, e) for i, e in enumerate(mna.inductors) if e.key in slopes]
        kappa = [(c, a, b) for c, a, b in st["couplings"] if c.key in slopes]
        if magnetic or kappa:
            Ld = np.array([val(e.key) for e in mna.inductors])
            dL = np.zeros((len(magnetic) + len(kappa), m, m))
            for r, (i, e) in enumerate(magnetic):
                dL[r, i, i] = 1.0
                for c, a, b in st["couplings"]:  # M_ab = k sqrt(L_a L_b)
                    if i in (a, b) and a != b:
                        o = b if i == a else a
                        d = val(c.key) * np.sqrt(Ld[o] / Ld[i]) / 2
                        dL[r, a, b] += d
                        dL[r, b, a] += d
            for r, (c, a, b) in enumerate(kappa, start=len(magnetic)):
                d = np.sqrt(Ld[a] * Ld[b])
                dL[r, a, b] += d
                dL[r, b, a] += d
            W = np.array([slopes[e.key] for _, e in magnetic] + [slopes[c.key] for c, _, _ in kappa], float)
            dLj = np.tensordot(W.reshape(dL.shape[0], J).T, dL, axes=1)  # (J, m, m): L along each direction
            # an entry (a, b) of s L stamps from inductor row a to inductor column b
            t = (-s[:, None, None, None] * U[:, :, N:N + m, None] * X[:, None, None, N:N + m])
            terms.append(t.reshape(F, no, m * m))
            weights += list(dLj.reshape(J, m * m).T)
        dv = np.zeros((J, no, F), complex)
        if terms:
            W = np.array(weights, float).reshape(len(weights), J)
            dv += np.moveaxis(np.concatenate(terms, axis=2) @ W, 2, 0).swapaxes(1, 2)
        if ddz is not None and self.k:  # dK = -ddZ at the probe sources
            p = st["probes"]
            dv += np.einsum("foa,jfab,fb->jof", U[:, :, p], ddz, X[:, p])
        return z, dv

    def responses_tangent(self, z: np.ndarray, dv: np.ndarray, port_map=None
                          ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Responses ``(1, F)`` and their derivatives ``(J, F)`` from the response node voltages per unit port
        current (:meth:`response_derivatives`).

        Parameters
        ----------
        z, dv : numpy.ndarray
            Node voltages ``(1, nodes, F)`` and their derivatives ``(J, nodes, F)``.
        port_map : callable, optional
            Port impedance to the impedance at the instrument and its derivative
            with respect to the port impedance (both ``(1, F)``).
        """
        z0, dz0 = z[:, 0], dv[:, 0]
        zin, dzin = z0, dz0
        if port_map is not None:
            zin, slope = port_map(z0)
            dzin = slope * dz0
        out, dout = {}, {}
        with np.errstate(divide="ignore", invalid="ignore"):
            for name, plus, minus in self._terms:
                if name in self._impedances:
                    out[name], dout[name] = zin, dzin
                    continue
                num, dnum = 0.0, 0.0
                for i, sign in ((plus, 1.0), (minus, -1.0)):
                    if i is not None:
                        num = num + sign * z[:, i]
                        dnum = dnum + sign * dv[:, i]
                ratio = num / zin  # with a port map, (v - v_minus) / z * z / zin
                out[name], dout[name] = ratio, (dnum - ratio * dzin) / zin
        return out, dout
