"""The design values as a prior: how far a fit may move the netlist's or model's values, and what moved beyond.

A netlist or a built-in model holds the design values of a winding; the
real winding differs from them by a manufacturing tolerance. Every fit of a
diagnosis against a design adds to its cost a log-normal penalty per circuit
value,

``J = cost + lambda * sum_i ln^2(v_i / d_i) / (2 tau^2)``,  ``tau = ln(1 + tolerance)``,

with ``lambda = sigma^2 / (N R)`` (noise variance per response ``sigma^2``,
``N`` frequencies, ``R`` responses), so that ``N R / sigma^2 * J`` is the
negative log posterior of Gaussian noise and the log-normal prior: the
penalty counts in nats, on the same scale as the data. Information criteria
are computed on the penalised cost (:attr:`.fit.FitResult.bic`).

A value the best fit moved beyond the tolerance (``|ln(v/d)| > tau``) is a
*drift*: the design's value is wrong, or the fit moved it to absorb an effect
the model lacks. Either way it is reported, and a fit that reaches the noise
only by drifting is not taken as an explanation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit

#: Default tolerance of the design values (relative): a documented, finite prior.
DEFAULT_TOLERANCE = 0.2
#: Smallest noise RMS per response (complex log) used for the prior's weight: data without noise still get a prior.
MIN_NOISE_RMS = 1e-3


@dataclass(frozen=True)
class DesignPrior:
    """Log-normal prior of the circuit values around the design.

    Parameters
    ----------
    design : mapping
        Lower-case value name to design value (SI units). Names not in it
        (elements a cause adds) carry no prior.
    tolerance : float
        Relative tolerance; ``tau = ln(1 + tolerance)`` is the prior's
        standard deviation of ``ln v``.
    weight : float
        ``lambda`` of the module docstring (cost units per nat).
    """

    design: Mapping[str, float]
    tolerance: float
    weight: float
    topology: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    @property
    def tau(self) -> float:
        return math.log1p(self.tolerance)

    def scale(self) -> float:
        """Factor turning ``ln(v/d)`` into a residual whose square is the penalty in cost units."""
        return math.sqrt(self.weight / 2.0) / self.tau

    def anchored(self, circuit: Circuit) -> set[str]:
        """Lower-case names of the values of ``circuit`` the prior applies to.

        A structural change (a section split or added) changes the nodes of
        some elements and rescales the series elements of the section it
        touches: those (the elements whose nodes differ from the design's,
        new elements, and the resistors and inductors joined to a changed
        inductor) carry no prior; every other design value does.

        A section that ended at ground and is split with a capacitance added
        across its first half no longer does: its series capacitance was a
        capacitance to ground at its start node, in parallel with (and
        indistinguishable from) the node's own, and the added capacitance
        (in series with the new node's) takes its share of it. The
        capacitances to ground at that node then carry no prior either.
        """
        names = set(self.design)
        if not self.topology:
            return names
        changed, opened = set(), set()
        for e in circuit.elements:
            key = e.name.lower()
            if key in self.topology and tuple(e.nodes) != self.topology[key]:
                changed.add(key)
                if e.kind == "L" and GROUND in self.topology[key] and GROUND not in e.nodes:
                    opened |= set(self.topology[key]) - {GROUND}
        nodes = {n for e in circuit.elements if e.name.lower() in changed and e.kind == "L" for n in e.nodes}
        nodes.discard(GROUND)
        for e in circuit.elements:
            if e.kind in "RL" and nodes & set(e.nodes):
                changed.add(e.name.lower())
        # the start node of a split section that ended at ground: through its series resistor, if any
        start = set(opened)
        for e in circuit.elements:
            design_nodes = self.topology.get(e.name.lower(), ())
            if e.kind == "R" and opened & set(design_nodes):
                start |= set(design_nodes) - {GROUND}
        start = {n for n in start if any(e.kind == "C" and e.name.lower() not in self.topology and n in e.nodes
                                         and GROUND not in e.nodes for e in circuit.elements)}
        for e in circuit.elements:
            design_nodes = self.topology.get(e.name.lower(), ())
            if e.kind == "C" and GROUND in design_nodes and start & set(design_nodes) and tuple(e.nodes) == design_nodes:
                changed.add(e.name.lower())
        return names - changed

    def drift(self, values: Mapping[str, float]) -> list[dict[str, float | str]]:
        """Values moved beyond the tolerance: name, design, fitted, ratio and the prior's sigmas (largest first)."""
        rows = []
        for name, v in values.items():
            d = self.design.get(name.lower())
            if d is None or d <= 0 or v <= 0:
                continue
            r = v / d
            if abs(math.log(r)) > self.tau * (1 + 1e-9):
                rows.append({"name": name, "design": float(d), "fitted": float(v), "ratio": float(r),
                             "sigmas": float(abs(math.log(r)) / self.tau)})
        rows.sort(key=lambda x: -x["sigmas"])
        return rows


def design_prior(design: Mapping[str, float], tolerance: float, noise_cost: float, n_frequencies: int,
                 n_responses: int, circuit: Circuit | None = None) -> DesignPrior | None:
    """The prior of a diagnosis, or ``None`` for ``tolerance = inf`` (values free).

    Parameters
    ----------
    design : mapping
        Value name to design value.
    tolerance : float
        Relative tolerance (> 0).
    noise_cost : float
        Noise floor of the data (:func:`.evidence.noise_floor`), cost units.
    n_frequencies, n_responses : int
    circuit : Circuit, optional
        The design circuit (its element nodes tell structural changes apart).
    """
    if not tolerance > 0:
        raise ValueError(f"tolerance must be positive, got {tolerance!r}")
    if math.isinf(tolerance):
        return None
    sigma2 = max(noise_cost / max(n_responses, 1), MIN_NOISE_RMS ** 2)
    weight = sigma2 / (n_frequencies * max(n_responses, 1))
    return DesignPrior({k.lower(): float(v) for k, v in design.items() if np.isfinite(v) and v > 0},
                       float(tolerance), weight,
                       {e.name.lower(): tuple(e.nodes) for e in circuit.elements} if circuit is not None else {})
