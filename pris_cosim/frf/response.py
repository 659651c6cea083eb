"""Analytic frequency responses of any circuit, batched over frequency and parameter sets.

Two paths give the same numbers:

- ``method="dense"``: one direct solve per frequency and parameter set, no
  eigenvectors: the balanced Hessenberg form of the exact state space
  (Laub's method, ``O(n^2)`` per frequency), or the full nodal system when
  the circuit has no state-space form (robust, the reference);
- ``method="fast"``: one eigen-decomposition of the state matrix per
  parameter set gives poles and residues, then every frequency costs O(n).

Responses are named as in the measured-data files: ``Zin`` (driving-point
impedance at the port, Ohm) and ``V_<node>`` (voltage ratio V(node)/V(port)).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from pris_cosim.circuits.circuit import Circuit, Numeric
from pris_cosim.errors import CircuitError
from pris_cosim.frf.kernels import hessenberg_solve, pole_residue_sum, pole_sum
from pris_cosim.circuits.mna import MNA, StateSpace
from pris_cosim.frf.sparse_ac import SparseMNA, use_sparse


@dataclass(frozen=True)
class PolesResidues:
    """Pole-residue form ``H(s) = sum_k r_k / (s - p_k) + d`` of a batch of responses.

    Attributes
    ----------
    poles : numpy.ndarray
        ``(P, n)`` complex, rad/s.
    residues : numpy.ndarray
        ``(P, ny, n)`` complex, one row per output (unit input current).
    direct : numpy.ndarray
        ``(P, ny)`` real feed-through.
    """

    poles: np.ndarray
    residues: np.ndarray
    direct: np.ndarray

    def evaluate(self, s: np.ndarray, chunk: int = 256) -> np.ndarray:
        """Values at complex frequencies ``s`` (rad/s); shape ``(P, ny, F)``."""
        return pole_sum(self.poles, self.residues, self.direct, s, chunk)


def poles_residues(ss: StateSpace, input_index: int = 0) -> tuple[PolesResidues, np.ndarray]:
    """Diagonalise a batch of state-space models for one input.

    Returns
    -------
    PolesResidues
        For every output of ``ss``.
    numpy.ndarray
        ``(P,)`` condition number estimate of the eigenvector matrices; large
        values flag (near-)defective systems where the dense path is safer.
    """
    lam, V = np.linalg.eig(ss.A)
    b = ss.B[:, :, input_index : input_index + 1]
    with np.errstate(all="ignore"):  # a singular V (defective A) shows as an infinite condition number below
        try:
            Vi = np.linalg.inv(V)
        except np.linalg.LinAlgError:
            Vi = np.full_like(V, np.nan)
    w = np.linalg.solve(V, b.astype(complex))[:, :, 0] if np.all(np.isfinite(Vi)) else (Vi @ b)[:, :, 0]
    # (P, n): left eigenvectors times the input (a solve is more accurate than the inverse when V is ill conditioned)
    cv = ss.C @ V  # (P, ny, n)
    residues = cv * w[:, None, :]
    cond = np.linalg.norm(V, axis=(1, 2)) * np.linalg.norm(Vi, axis=(1, 2))
    return PolesResidues(lam, residues, ss.D[:, :, input_index]), cond


@dataclass(frozen=True)
class Response:
    """One named response of a driven circuit.

    Parameters
    ----------
    name : str
        Response name (``Zin``, ``Zlvoc``, ``Rlvhv``, ``V_mid`` ...).
    node : str, optional
        ``None`` for the driving-point impedance V(port)/I (Ohm); otherwise
        the voltage ratio ``(V(node) - V(minus)) / V(port)``.
    minus : str, optional
        Second node of a differential ratio (ground when omitted).
    """

    name: str
    node: str | None = None
    minus: str | None = None


class ResponseModel:
    """Frequency responses of one circuit driven by a current at one port.

    Compile once, evaluate many times (an optimiser's inner loop).

    Parameters
    ----------
    circuit : Circuit
        The network.
    port : str
        Driven node (current injected from ground).
    ratios : sequence of str
        Nodes for voltage ratios ``V(node)/V(port)``, named ``V_<node>``.
    shorts : sequence of str
        Nodes tied to ground for this test configuration.
    responses : sequence of Response, optional
        Explicit responses instead of ``Zin`` plus ``ratios``.
    """

    def __init__(
        self,
        circuit: Circuit,
        port: str,
        ratios: Sequence[str] = (),
        shorts: Sequence[str] = (),
        responses: Sequence[Response] | None = None,
    ):
        self.source_circuit = circuit
        self.circuit = circuit.shorted(shorts) if shorts else circuit
        self.port = self.circuit.require_node(port, "port")
        if responses is None:
            responses = [Response("Zin")] + [Response(f"V_{self.circuit.require_node(n, 'ratio node')}", n) for n in ratios]
        self.responses = list(responses)
        self.names = [r.name for r in self.responses]
        nodes = [self.port]
        for r in self.responses:
            for n in (r.node, r.minus):
                if n is None:
                    continue
                n = self.circuit.require_node(n, f"node of response {r.name!r}")
                if n != "0" and n not in nodes:
                    nodes.append(n)
        self.mna = (SparseMNA if use_sparse(self.circuit) else MNA)(self.circuit, current_inputs=[self.port])
        self._out_nodes = nodes
        self._out_index = [self.mna.nodes.index(n) for n in nodes]

    def _combine(self, z: np.ndarray) -> dict[str, np.ndarray]:
        """Responses from transfer impedances ``z`` of shape (P, nodes, F)."""
        pos = {n: i for i, n in enumerate(self._out_nodes)}

        def volt(n: str | None) -> np.ndarray | float:
            n = None if n is None else self.circuit.require_node(n)
            return 0.0 if n in (None, "0") else z[:, pos[n]]

        out: dict[str, np.ndarray] = {}
        with np.errstate(divide="ignore", invalid="ignore"):
            for r in self.responses:
                out[r.name] = z[:, 0] if r.node is None else (volt(r.node) - volt(r.minus)) / z[:, 0]
        return out

    def values(self, overrides: Mapping[str, Numeric] | None = None, strict_passive: bool = False) -> dict[str, Numeric]:
        """Resolved element values, checked; warns (or raises) when not passive."""
        values = self.circuit.resolve(overrides)
        self.circuit.check_passive(values, strict=strict_passive)
        return values

    def poles_residues(self, overrides: Mapping[str, Numeric] | None = None) -> PolesResidues:
        """Pole-residue form of the port impedance and the transfer impedances to the ratio nodes."""
        values = self.values(overrides)
        ss = self.mna.state_space(values).select([f"v({n})" for n in self._out_nodes])
        return poles_residues(ss)[0]

    def evaluate(
        self,
        frequency_hz: Sequence[float] | np.ndarray,
        overrides: Mapping[str, Numeric] | None = None,
        method: str = "fast",
    ) -> dict[str, np.ndarray]:
        """Complex responses at the given frequencies.

        Parameters
        ----------
        frequency_hz : array_like, Hz
            Frequencies (positive).
        overrides : mapping, optional
            Parameter or element values; arrays of length P evaluate a population.
        method : {"fast", "dense"}
            Pole-residue evaluation or dense solve per frequency.

        Returns
        -------
        dict
            Response name to complex array, shape ``(F,)`` when every value is
            scalar, else ``(P, F)``. ``Zin`` in Ohm, ratios dimensionless.
        """
        f = np.asarray(frequency_hz, dtype=float)
        if f.ndim != 1 or f.size == 0 or np.any(~np.isfinite(f)) or np.any(f <= 0):
            raise CircuitError("frequencies must be a non-empty 1-D array of positive numbers (Hz)")
        values = self.values(overrides)
        scalar = all(np.ndim(v) == 0 for v in values.values())
        s = 2j * np.pi * f
        if method == "dense":
            z = self._dense(values, s)
        elif method == "fast":
            z = self._fast(values, s)
        else:
            raise CircuitError(f"unknown method {method!r} (use 'fast' or 'dense')")
        out = self._combine(z)
        return {k: v[0] if scalar else v for k, v in out.items()}

    def evaluate_grid(
        self,
        frequency_hz: Sequence[float] | np.ndarray,
        overrides: Mapping[str, Numeric] | None = None,
        per_frequency: Mapping[str, np.ndarray] | None = None,
    ) -> dict[str, np.ndarray]:
        """Responses with element values that change with frequency (dense solve per point).

        Parameters
        ----------
        frequency_hz : array_like, Hz
            ``F`` frequencies.
        overrides : mapping, optional
            Parameter or element values: scalars or length-P arrays.
        per_frequency : mapping, optional
            Element name to values over frequency, shape ``(F,)`` or ``(P, F)``:
            a skin-effect resistance R(f), an inductance L(f). Resistor values
            may be complex (a frequency-dependent impedance).

        Returns
        -------
        dict
            Response name to complex array, ``(F,)`` for scalar inputs, else ``(P, F)``.
        """
        f = np.asarray(frequency_hz, dtype=float)
        values = self.values(overrides)
        scalar = all(np.ndim(v) == 0 for v in values.values())
        grid = {k: (np.asarray(v)[:, None] if np.ndim(v) == 1 else v) for k, v in values.items()}
        for name, v in (per_frequency or {}).items():
            arr = np.asarray(v)
            if arr.shape[-1:] != f.shape:
                raise CircuitError(f"per-frequency values of {name!r}: last axis must have {f.size} values, got {arr.shape}")
            key = name.lower()
            if key not in grid:
                raise CircuitError(f"per-frequency values given for unknown element {name!r}")
            grid[key] = arr
            scalar = scalar and arr.ndim == 1
        z = self.mna.solve_grid(grid, 2j * np.pi * f, self._out_index)[:, :, :, 0]  # (P, F, nodes)
        out = self._combine(np.moveaxis(z, 2, 1))
        return {k: v[0] if scalar else v for k, v in out.items()}

    def _dense(self, values: Mapping[str, Numeric], s: np.ndarray) -> np.ndarray:
        """Direct solve per frequency: the Hessenberg form of the exact state space, else the nodal system."""
        if isinstance(self.mna, MNA):
            try:
                ss = self.mna.state_space(values).select([f"v({n})" for n in self._out_nodes])
            except CircuitError:  # no state-space form (improper): the full nodal system
                ss = None
            if ss is not None and np.isrealobj(ss.A) and ss.A.shape[1] > 0:
                return hessenberg_solve(ss.A, ss.B[:, :, 0], ss.C, ss.D[:, :, 0], s.imag)
        return self.mna.solve_dense(values, s, self._out_index)[:, :, 0, :]

    def _fast(self, values: Mapping[str, Numeric], s: np.ndarray) -> np.ndarray:
        try:
            ss = self.mna.state_space(values).select([f"v({n})" for n in self._out_nodes])
        except CircuitError:  # improper (e.g. Z = R + sL driven by a current): no state space, solve densely
            return self.mna.solve_dense(values, s, self._out_index)[:, :, 0, :]
        pr, cond = poles_residues(ss)
        if np.isrealobj(ss.A):  # conjugate pole pairs in real arithmetic (compiled for large batches)
            z = pole_residue_sum(pr.poles, pr.residues, pr.direct, s.imag)
        else:
            z = pr.evaluate(s)
        bad = np.flatnonzero(~(cond < 1e10))
        if bad.size:  # nearly defective eigenvectors: fall back to the dense solve there
            sub = {k: (np.asarray(v)[bad] if np.ndim(v) else v) for k, v in values.items()}
            z[bad] = self.mna.solve_dense(sub, s, self._out_index)[:, :, 0, :]
        return z


def frequency_response(
    circuit: Circuit,
    port: str,
    frequency_hz: Sequence[float] | np.ndarray,
    ratios: Sequence[str] = (),
    shorts: Sequence[str] = (),
    overrides: Mapping[str, Numeric] | None = None,
    method: str = "fast",
) -> dict[str, np.ndarray]:
    """One-call form of :class:`ResponseModel` (compile and evaluate).

    Parameters
    ----------
    circuit : Circuit
    port : str
        Driven node.
    frequency_hz : array_like, Hz
    ratios : sequence of str
        Nodes for ``V_<node>`` ratios.
    shorts : sequence of str
        Nodes tied to ground.
    overrides : mapping, optional
        Parameter or element values (floats or length-P arrays).
    method : {"fast", "dense"}

    Returns
    -------
    dict
        ``Zin`` (Ohm) and ``V_<node>`` complex arrays.
    """
    return ResponseModel(circuit, port, ratios, shorts).evaluate(frequency_hz, overrides, method)


def logspace_hz(fmin: float, fmax: float, points: int) -> np.ndarray:
    """``points`` log-spaced frequencies from ``fmin`` to ``fmax`` (Hz), validated."""
    if not (np.isfinite(fmin) and np.isfinite(fmax) and 0 < fmin < fmax):
        raise CircuitError(f"need 0 < fmin < fmax (got fmin={fmin}, fmax={fmax})")
    if int(points) < 1:
        raise CircuitError(f"points must be at least 1 (got {points})")
    return np.logspace(np.log10(fmin), np.log10(fmax), int(points)) if points > 1 else np.array([float(fmin)])


__all__ = ["Response", "ResponseModel", "PolesResidues", "frequency_response", "logspace_hz", "poles_residues"]
