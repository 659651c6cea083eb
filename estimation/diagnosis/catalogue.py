"""The catalogue of frequency-response causes and the model extension each one adds.

Every extension names the cause (as in the command line's ``cause``), its
extra parameters with bounds and starting points, and how it changes
element values with frequency. Each also builds a time-domain realisation
(passive R-L ladders, :mod:`pris_cosim.freqdep`) so the extended model can be
simulated and exported as an FMU.

- ``skin-effect``: every winding resistance becomes the impedance
  ``R_i (1 + a (j f/f0)^b)`` (a, b shared). Its real part rises as
  ``R_i (1 + a cos(pi b/2) (f/f0)^b)``; its reactance is the internal
  inductance that falls as the current crowds to the surface. This causal
  fractional form (b = 1/2 is the classical skin effect) is what a passive
  ladder realises; a real-only R(f) is not causal.
- ``core-loss``: the core-loss resistance follows (2.4) ``a f / (f + b)``;
  a circuit without one gets a shunt core-loss resistance at the port.
- ``magnetising-inductance``: every winding inductance ``L_i (f/f0)^(-b)``
  (the thesis's (2.5) with its scale ``a`` absorbed by refitting ``L_i``).
- ``missing-section``: one more section in the winding cascade (two more in
  a two-winding model's HV winding, keeping its symmetry).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from pris_cosim.circuit import GROUND, Circuit
from pris_cosim.freqdep import core_loss_resistance, fit_impedance, fit_inductance, fit_resistance, replace_with_ladder
from pris_cosim.models import Model, cascade, two_winding


@dataclass(frozen=True)
class ExtraParameter:
    """An extension parameter: name, bounds and starting values (log-scaled when ``log``)."""

    name: str
    lower: float
    upper: float
    starts: tuple[float, ...]
    log: bool = True
    description: str = ""


def winding_resistors(circuit: Circuit) -> list[str]:
    """Resistors in series with an inductor through an internal node (the R of an ``R + sL`` branch)."""
    degree: dict[str, int] = {}
    for e in circuit.elements:
        if e.kind != "K":
            for n in e.nodes:
                degree[n] = degree.get(n, 0) + 1
    inductor_nodes = {n for e in circuit.inductors() for n in e.nodes}
    out = []
    for e in circuit.of_kind("R"):
        if any(n != GROUND and degree.get(n) == 2 and n in inductor_nodes for n in e.nodes):
            out.append(e.name)
    return out


def core_loss_resistor(circuit: Circuit) -> str | None:
    """A resistor in parallel with an inductor (the core-loss loop ``Lc || Rc``), if any."""
    for r in circuit.of_kind("R"):
        for l in circuit.inductors():
            if set(r.nodes) == set(l.nodes):
                return r.name
    return None


def winding_inductors(circuit: Circuit) -> list[str]:
    """Inductors that are part of an ``R + sL`` winding branch (core-loop inductors excluded)."""
    rc = core_loss_resistor(circuit)
    core_l = {l.name for l in circuit.inductors() if rc and set(l.nodes) == set(circuit.element(rc).nodes)}
    return [l.name for l in circuit.inductors() if l.name not in core_l]


@dataclass
class Extension:
    """Base class: a named cause with extra parameters."""

    cause: str = "none"
    parameters: list[ExtraParameter] = field(default_factory=list)
    note: str = ""

    def prepare(self, circuit: Circuit) -> Circuit:
        """Structural change (added elements); default none."""
        return circuit

    def per_frequency(self, circuit: Circuit, values: Mapping[str, float], f: np.ndarray, p: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Element values that vary with frequency (name -> array over ``f``)."""
        return {}

    def realise(self, circuit: Circuit, values: Mapping[str, float], p: Mapping[str, float], fmin: float, fmax: float) -> Circuit:
        """A time-domain circuit (ladders) equivalent over ``[fmin, fmax]``."""
        return circuit


@dataclass
class SkinEffect(Extension):
    f0: float = 1.0

    def __post_init__(self) -> None:
        self.cause = "skin-effect"
        self.parameters = [
            ExtraParameter("a", 1e-4, 1e4, (1e-3, 0.3, 10.0), description="resistance rise at f0 (x R)"),
            ExtraParameter("b", 0.1, 1.0, (0.5,), log=False, description="frequency exponent"),
        ]

    def _targets(self, circuit: Circuit) -> list[str]:
        return winding_resistors(circuit)

    def per_frequency(self, circuit, values, f, p):
        factor = 1 + p["a"] * (1j * f / self.f0) ** p["b"]
        return {name: values[name.lower()] * factor for name in self._targets(circuit)}

    def realise(self, circuit, values, p, fmin, fmax):
        out = circuit
        for name in self._targets(circuit):
            r = values[name.lower()]
            lad = fit_impedance(lambda x, r=r: r * (1 + p["a"] * (1j * x / self.f0) ** p["b"]), fmin, fmax, 12)
            out = replace_with_ladder(out, name, lad)
        return out


@dataclass
class CoreLoss(Extension):
    fmid: float = 1.0

    def __post_init__(self) -> None:
        self.cause = "core-loss"
        self.parameters = [
            ExtraParameter("a", 1e-3, 1e12, (), description="high-frequency core-loss resistance (Ohm)"),
            ExtraParameter("b", 1e-3, 1e12, (), description="corner frequency (Hz)"),
        ]

    def prepare(self, circuit: Circuit) -> Circuit:
        if core_loss_resistor(circuit) is not None:
            return circuit
        c = circuit.copy()
        c.add("Rcore", c.ports[0] if c.ports else c.nodes[0], GROUND, 1.0)
        return c

    def starts(self, circuit: Circuit, values: Mapping[str, float], impedance_scale: float) -> list[dict[str, float]]:
        rc = core_loss_resistor(circuit)
        base = values[rc.lower()] if rc and rc != "Rcore" else 30 * impedance_scale
        starts = [{"a": base * m, "b": self.fmid * g} for m in (1.0, 10.0) for g in (0.1, 1.0, 10.0)]
        return starts + [{"a": 1e11, "b": self.fmid}]  # effectively no core loss: never worse than the baseline

    def _resistor(self, circuit: Circuit) -> str:
        return core_loss_resistor(circuit) or "Rcore"

    def per_frequency(self, circuit, values, f, p):
        return {self._resistor(circuit): core_loss_resistance(f, p["a"], p["b"])}

    def realise(self, circuit, values, p, fmin, fmax):
        lad = fit_resistance(lambda x: core_loss_resistance(x, p["a"], p["b"]), fmin, fmax, 10)
        return replace_with_ladder(circuit, self._resistor(circuit), lad)


@dataclass
class MagnetisingInductance(Extension):
    f0: float = 1.0

    def __post_init__(self) -> None:
        self.cause = "magnetising-inductance"
        self.parameters = [ExtraParameter("b", 0.0, 1.0, (1e-4, 0.02, 0.04, 0.07, 0.1, 0.2), log=False,
                                          description="exponent of (2.5)")]

    def per_frequency(self, circuit, values, f, p):
        factor = (f / self.f0) ** (-p["b"])
        return {name: values[name.lower()] * factor for name in winding_inductors(circuit)}

    def realise(self, circuit, values, p, fmin, fmax):
        out = circuit
        for name in winding_inductors(circuit):
            lv = values[name.lower()]
            lad = fit_inductance(lambda x, lv=lv: lv * (x / self.f0) ** (-p["b"]), fmin, fmax, 8)
            out = replace_with_ladder(out, name, lad)
        return out


@dataclass
class MissingSection(Extension):
    """One more winding section: built from the model family, split from a fitted section."""

    model: Model | None = None

    def __post_init__(self) -> None:
        self.cause = "missing-section"
        self.parameters = []

    def candidates(self, values: Mapping[str, float]) -> list[tuple[Circuit, set[str]]]:
        """Starting circuits with one more section, and the names of the new section's elements.

        Starts: each existing section split into two halves, and a typical
        section appended at the neutral end over a grid of L and C. The second
        item of each pair lists the new elements, fitted alone first.
        """
        fam = self.model.family if self.model else ()
        out: list[tuple[Circuit, dict[str, float]]] = []
        if fam and fam[0] == "lumped":
            r, l, c = values["r1"], values["l1"], values["c1"]
            for share in (0.5, 0.8, 0.95):
                m = cascade(2, R=[r * share, r * (1 - share)], L=[l * share, l * (1 - share)],
                            C=[c / share, c / (1 - share)], Cg=[c * 1e-3, c * 1e-3], k=0.0)
                out.append((m.circuit, {"R2", "L2", "C2"}))
        elif fam and fam[0] == "cascade":
            n, neutral = fam[1], fam[2]
            R = [values[f"r{i}"] for i in range(1, n + 1)]
            L = [values[f"l{i}"] for i in range(1, n + 1)]
            C = [values[f"c{i}"] for i in range(1, n + 1)]
            n_cg = n + 1 if neutral == "open" else n
            Cg = [values[f"cg{i}"] for i in range(1, n_cg + 1)]
            rho = _nearest_neighbour_coupling(values, n)
            starts = []
            for j in range(n):  # split section j into two halves
                starts.append((R[:j] + [R[j] / 2] * 2 + R[j + 1:], L[:j] + [L[j] / 2] * 2 + L[j + 1:],
                               C[:j] + [2 * C[j]] * 2 + C[j + 1:], Cg[:j + 1] + [Cg[j]] + Cg[j + 1:]))
            for ls in (0.3, 1.0, 3.0):  # append a typical section at the neutral end
                for cs in (0.3, 1.0, 3.0):
                    starts.append((R + [float(np.mean(R))], L + [float(np.mean(L)) * ls], C + [float(np.mean(C)) * cs],
                                   Cg + [float(np.mean(Cg))]))
            new = {f"R{n + 1}", f"L{n + 1}", f"C{n + 1}", f"Cg{n + 1}"}
            for R2, L2, C2, Cg2 in starts:
                out.append((cascade(n + 1, R=R2, L=L2, C=C2, Cg=Cg2[: n_cg + 1], k=rho, neutral=neutral).circuit, new))
        elif fam and fam[0] == "two-winding":
            out += self._two_winding(values)
        return out

    def _two_winding(self, values: Mapping[str, float]) -> list[tuple[Circuit, set[str]]]:
        _, N, cab2, tied = self.model.family
        v = {k: float(x) for k, x in values.items()}
        lb = [v[f"lb{i}"] for i in range(1, N + 1)]
        cb = [v[f"cb{i}"] for i in range(1, N + 1)]
        M = N + 2
        new: dict[str, float] = {"Ra1": v["ra1"], "La1": v["la1"], "Ca10": v["ca10"], "Rb": v["rb1"],
                                 "Cb10": v["cb10"], "Cab1": v.get("cab1", 1e-12), "Lc": v["lc"], "Rc": v["rc"]}
        # split the first and last HV sections in two (keeps the midpoint in the middle)
        lb2 = [lb[0] / 2, lb[0] / 2] + lb[1:-1] + [lb[-1] / 2, lb[-1] / 2]
        cb2 = [2 * cb[0], 2 * cb[0]] + cb[1:-1] + [2 * cb[-1], 2 * cb[-1]]
        for i in range(M):
            new[f"Lb{i + 1}"], new[f"Cb{i + 1}"] = lb2[i], cb2[i]
        new[f"Cb1{M // 2}"] = v[f"cb1{N // 2}"]
        new[f"Cb{M // 2 + 1}{M}"] = v[f"cb{N // 2 + 1}{N}"]
        mean_k = float(np.mean([x for k, x in v.items() if k.startswith("kb")])) if any(k.startswith("kb") for k in v) else 0.99
        mean_ka = float(np.mean([x for k, x in v.items() if k.startswith("ka1b")]))
        core = float(np.mean([x for k, x in v.items() if k.endswith("c") and k.startswith("k")]))
        windings = ["a1"] + [f"b{i}" for i in range(1, M + 1)]
        for i, x in enumerate(windings):
            for y in windings[i + 1:]:
                new[f"K{x}{y}"] = mean_ka if x == "a1" else mean_k
            new[f"K{x}c"] = core
        new["Kc"] = core
        if cab2:
            new["Cab2"] = v.get("cab2", 1e-12)
        added = {f"Lb{i}" for i in (1, 2, M - 1, M)} | {f"Cb{i}" for i in (1, 2, M - 1, M)}
        return [(two_winding(M, new, cab2=cab2, tied_core_coupling=tied).circuit, added)]


def _nearest_neighbour_coupling(values: Mapping[str, float], n: int) -> float:
    """Mean coupling between adjacent sections of a cascade (its ``rho``), 0.5 when uncoupled."""
    ks = [values.get(f"k{i}{i + 1}", values.get(f"k{i}_{i + 1}")) for i in range(1, n)]
    ks = [k for k in ks if k is not None]
    return float(np.mean(ks)) if ks else 0.5


def frequency_extensions(model: Model | None, fmin: float, fmax: float) -> list[Extension]:
    """The frequency-response catalogue for a baseline (missing-section only for known families)."""
    f0 = float(fmin)
    exts: list[Extension] = [SkinEffect(f0=f0), CoreLoss(fmid=float(np.sqrt(fmin * fmax))), MagnetisingInductance(f0=f0)]
    if model is not None and model.family:
        exts.append(MissingSection(model=model))
    return exts


def as_dict(p: Sequence[ExtraParameter], x: Sequence[float]) -> dict[str, float]:
    return {q.name: float(v) for q, v in zip(p, x)}
