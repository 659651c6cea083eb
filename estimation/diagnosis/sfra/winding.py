"""Lumped winding model for end-to-end (series-through) SFRA sweeps.

The winding is a cascade of ``N`` sections between node 0 (port 1) and node
``N`` (port 2); the iron core is ground.  Each section ``i`` has

* a core inductance ``L_i`` (H), magnetically coupled to every other section
  with mutual inductance ``M_ij = sqrt(L_i L_j) * rho**|i-j|`` (``rho`` is the
  fitted coupling of neighbouring sections; an iron core gives ``rho`` near 1);
* a winding resistance, the share ``L_i / sum(L)`` of the total ``R_dc`` (Ohm);
* a series (turn-to-turn) capacitance ``Cs_i`` (F) across the section;

every node ``j`` has a ground capacitance ``Cg_j`` (F) to the core, and each
port node a constant complex shunt admittance ``g + j b`` (S): the residual
of the fixture and calibration seen in the measured ``Y11 + Y21`` and
``Y22 + Y21`` below 10 kHz (on the shared reference about 3.6e-5 S at -115
degrees on port 2, which no passive element gives: the measured ``|S22|``
is 1.0015 there, a reflection-tracking error of the calibration; it is
fitted so that it does not distort the winding parameters, and it drifts
between sweeps, which :mod:`estimation.diagnosis.sfra.faults` weighs; a leakage
spread along the winding was tried and fitted the reference worse).  The
reference fit (:mod:`estimation.diagnosis.sfra.fingerprint`) makes the sections equal.

Iron-core loss.  The laminated core makes the inductance and its loss
frequency dependent (eddy currents).  All core inductances are multiplied by
the complex relative permeability of a lamination,

    mu(f) = (j f / 1 kHz) ** -beta * tanh(sqrt(j f / f_e)) / sqrt(j f / f_e),

the classical solution of the one-dimensional eddy-current diffusion in a
sheet (``f_e`` is the corner frequency where the skin depth equals half the
sheet thickness) times a fractional-order factor.  Below
``f_e`` the inductance is flat and the loss grows like ``f**2``; above, both
fall like ``f**-0.5`` (``mu -> (1 - j) sqrt(f_e / 2 f)``).  The
fractional-order factor (exponent ``beta`` of a few hundredths) gives the
slow fall of the inductance and the near-constant loss angle of the iron
between 10 Hz and 1 kHz (magnetic viscosity and hysteresis): the shared
reference shows 28 H at 10 Hz and 23 H at 1 kHz at a phase of 84-88
degrees, then a heavily damped first anti-resonance near 3.7 kHz.  Both
factors are fitted; which one carries the loss is left to the data (on the
shared reference the fractional order does, and ``f_e`` ends high).  A
per-section shunt loss resistance was not used: it damps but does not make
the inductance fall with frequency.  Capacitances carry a dielectric loss angle ``tan_c``.

A shorted loop (the fault of :mod:`estimation.diagnosis.sfra.faults`) is an extra
closed branch coupled to the sections, at a continuous position along the
winding; it is eliminated exactly (Schur complement), so the nodal network
keeps ``N + 1`` nodes.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

__all__ = ["WindingModel", "ShortedLoop", "admittance", "core_permeability"]


#: Frequency at which the fractional-order factor is 1 (the ``L`` values refer to it), Hz.
F_REF_HZ = 1000.0


def core_permeability(f: np.ndarray, f_eddy: float, beta: float) -> np.ndarray:
    """Complex relative permeability of a laminated iron core (dimensionless).

    Parameters
    ----------
    f : numpy.ndarray
        Frequencies in Hz.
    f_eddy : float
        Eddy-current corner frequency in Hz.
    beta : float
        Fractional-order exponent (magnetic viscosity / hysteresis):
        ``(j f / F_REF_HZ) ** -beta``, a constant loss angle ``beta * 90``
        degrees with an inductance falling like ``f ** -beta``.
    """
    s = np.sqrt(1j * np.asarray(f, dtype=float) / f_eddy)
    small = np.abs(s) < 1e-4
    with np.errstate(all="ignore"):
        mu = np.where(small, 1.0 - s**2 / 3.0, np.tanh(s) / np.where(small, 1.0, s))
    return mu * (1j * np.asarray(f, dtype=float) / F_REF_HZ) ** (-beta)


@dataclass
class ShortedLoop:
    """A closed shorted loop magnetically coupled to section ``section``.

    Attributes
    ----------
    section : int
        0-based section index the loop belongs to.
    coupling : float
        Coupling coefficient ``c`` of the loop to its section (0..1).  The
        loop's mutual to section ``j`` is ``c * M_kj`` (its position in the
        winding sets its coupling to the others with the fitted ``rho``), its
        self inductance ``L_k``: the loop is referred to the section's turns.
    resistance : float
        Loop resistance referred to the section's turns, Ohm (fault
        resistance plus the loop's own; a loop of ``a`` times the section's
        turns with resistance ``R`` refers to ``R / a**2``).
    position : float, optional
        Where the loop sits along the winding, in sections from the port-1
        end (``section <= position <= section + 1``); its mutual to section
        ``j`` is then ``c sqrt(L_k L_j) rho**|position - (j + 0.5)|``.
        ``None``: the section's centre (mutuals ``c M_kj``).
    """

    section: int
    coupling: float
    resistance: float
    position: float | None = None

    def mutuals(self, model: "WindingModel") -> np.ndarray:
        """Mutual inductances of the loop to every section, H (before the core factor), shape ``(N,)``."""
        M = model.mutual()
        if self.position is None:
            return self.coupling * M[self.section]
        L = np.asarray(model.L, dtype=float)
        centres = np.arange(L.size) + 0.5
        m = self.coupling * np.sqrt(L[self.section] * L) * model.rho ** np.abs(self.position - centres)
        if model.coupling_scale is not None:
            g = np.asarray(model.coupling_scale, dtype=float)
            m = m * g[self.section] * g
            m[self.section] = self.coupling * M[self.section, self.section] * model.rho ** abs(
                self.position - centres[self.section])
        return m


@dataclass
class WindingModel:
    """Parameters of the N-section winding (see the module docstring for units)."""

    L: np.ndarray
    Cs: np.ndarray
    Cg: np.ndarray
    rho: float
    r_dc: float
    f_eddy: float
    beta: float
    tan_c: float
    g1: float
    b1: float
    g2: float
    b2: float
    coupling_scale: np.ndarray | None = None  # per section, scales its mutuals to all others
    loops: list[ShortedLoop] = field(default_factory=list)

    @property
    def n(self) -> int:
        """Section count."""
        return int(len(self.L))

    def mutual(self) -> np.ndarray:
        """Low-frequency inductance matrix ``M`` (H), shape ``(N, N)``."""
        L = np.asarray(self.L, dtype=float)
        idx = np.arange(L.size)
        M = np.sqrt(np.outer(L, L)) * self.rho ** np.abs(idx[:, None] - idx[None, :])
        if self.coupling_scale is not None:
            g = np.asarray(self.coupling_scale, dtype=float)
            M = M * np.outer(g, g)
            M[idx, idx] = L
        return M

    def total_inductance(self) -> float:
        """End-to-end low-frequency inductance ``sum(M)`` in H."""
        return float(np.sum(self.mutual()))

    def copy(self, **changes) -> "WindingModel":
        """A copy with some fields replaced."""
        d = {k: (np.array(v, dtype=float) if isinstance(v, np.ndarray) else v) for k, v in asdict(self).items()}
        d["loops"] = [ShortedLoop(**lp) if isinstance(lp, dict) else lp for lp in d["loops"]]
        d.update(changes)
        return WindingModel(**d)

    def as_dict(self) -> dict:
        """JSON-ready parameters (lists of floats)."""
        out = {}
        for k, v in asdict(self).items():
            if isinstance(v, np.ndarray):
                out[k] = [float(x) for x in v]
            elif k == "loops":
                out[k] = [dict(lp) for lp in v]
            else:
                out[k] = v if v is None else float(v)
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "WindingModel":
        """Inverse of :meth:`as_dict`."""
        kw = dict(d)
        for k in ("L", "Cs", "Cg", "coupling_scale"):
            if kw.get(k) is not None:
                kw[k] = np.asarray(kw[k], dtype=float)
        kw["loops"] = [ShortedLoop(**lp) for lp in kw.get("loops", [])]
        return cls(**kw)


def admittance(model: WindingModel, f: np.ndarray) -> np.ndarray:
    """Two-port admittance matrix of the winding, S, shape ``(F, 2, 2)``.

    Port 1 is node 0, port 2 node ``N``, both against the core (ground).

    Parameters
    ----------
    model : WindingModel
        Parameters.
    f : numpy.ndarray
        Frequencies in Hz, shape ``(F,)``.
    """
    f = np.asarray(f, dtype=float)
    w = 2.0 * np.pi * f
    jw = 1j * w
    n = model.n
    L = np.asarray(model.L, dtype=float)
    mu = core_permeability(f, model.f_eddy, model.beta)
    M = model.mutual()
    zb = (jw * mu)[:, None, None] * M[None, :, :]
    idx = np.arange(n)
    zb[:, idx, idx] += model.r_dc * L / L.sum()
    for lp in model.loops:
        k = lp.section
        m = lp.mutuals(model)  # loop mutuals (H, before the core factor)
        zl = lp.resistance + jw * mu * M[k, k]
        zb -= ((jw * mu) ** 2 / zl)[:, None, None] * np.outer(m, m)[None, :, :]
    yb = np.linalg.inv(zb)
    cap = jw * (1.0 - 1j * model.tan_c)
    yb[:, idx, idx] += cap[:, None] * np.asarray(model.Cs, dtype=float)[None, :]
    # nodal matrix A^T Yb A with A[i, i] = 1, A[i, i+1] = -1
    Y = np.zeros((f.size, n + 1, n + 1), dtype=complex)
    Y[:, :n, :n] += yb
    Y[:, 1:, 1:] += yb
    Y[:, :n, 1:] -= yb
    Y[:, 1:, :n] -= yb
    nodes = np.arange(n + 1)
    Y[:, nodes, nodes] += cap[:, None] * np.asarray(model.Cg, dtype=float)[None, :]
    Y[:, 0, 0] += model.g1 + 1j * model.b1
    Y[:, n, n] += model.g2 + 1j * model.b2
    p = [0, n]
    if n == 1:
        return Y[:, p][:, :, p]
    inner = np.arange(1, n)
    ypp = Y[:, p][:, :, p]
    ypi = Y[:, p][:, :, inner]
    yii = Y[:, inner][:, :, inner]
    return ypp - ypi @ np.linalg.solve(yii, np.swapaxes(ypi, 1, 2))
