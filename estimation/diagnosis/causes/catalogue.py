"""The catalogue of frequency-response causes: each a change of branch impedances with frequency.

Every cause comes in the thesis's form, exactly as printed (real-valued
element values, :mod:`pris_cosim.circuits.freqdep`), and in causal forms (complex
impedances that a passive network can realise): a constant-phase (power-law)
form, and relaxation forms: for the skin effect one with a corner frequency
below which the resistance keeps its low-frequency value (a power law holds
only far above the corner, where the skin depth is below the conductor's
size), for the magnetising inductance and a core loop's loss a distribution
of relaxation times. All forms name the same cause; the diagnosis fits them and keeps the
best. With several windings each cause is tried per winding group (``lv``
only, ``hv`` only, ``all``).

Levels. The thesis's forms have a level besides their shape: ``c_Rs`` of
(2.6) (``R_linear`` is the resistance where it was measured, ``R_linear / c``
the one below ``f0``) and ``a_Lo`` of (2.5). With a design prior
(:mod:`.prior`; ``level``, within ``1/LEVEL_RANGE .. LEVEL_RANGE``) the
magnetising forms (2.5) and causal, and the causal skin form, have a free
level: the prior anchors the circuit values at the design's, which are
effective values at some frequency of the band, and a form equal to them at
``f_ref`` (the lowest frequency of the data) would make the fit move them
beyond the tolerance. Without a prior a level and the circuit values are not
separable, and it is pinned (``c = 1``, ``a = f_ref^b``, ``k = 1``). The
thesis skin form (2.6) keeps ``c = 1`` (with ``c`` free it converged to a
worse fit on a design case); the relaxation forms equal the circuit value at
low frequency and keep no level. With a prior the magnetising relaxation also
gets its width exponent (Havriliak-Negami instead of Davidson-Cole): the
anchored circuit values cannot bend to a dispersion wider than the form's,
while without them the wider form also takes a conductor's eddy losses (on a
measured short-circuit impedance it displaced the skin effect).

``skin-effect``
    thesis (2.6): ``R(f) = R_linear / c [1 + a (f/f0 - 1)^b]`` for
    ``f >= f0`` (``R_linear / c`` below; ``R_linear / c`` is the fitted
    circuit resistance, so ``c = 1``); causal:
    ``R / c (1 + a (j f/f_ref)^b)`` (``c = 1`` unless free; ``b = 1/2`` is the
    classical skin effect; its reactance is the internal inductance);
    relaxation: ``R (1 + a [(1 + j f/f_c)^b - 1])``: ``R`` up to
    about ``f_c`` (skin depth comparable with the conductor), then the
    power law; ``a = 1, b = 1/2`` is close to a round wire's Bessel impedance;
    conductor (:class:`ConductorSkin`): that impedance itself,
    ``R [1 - a + a (x/2) J0(x)/J1(x)]``, ``x = (1 - j) sqrt(f/f_c)``.
``core-loss``
    thesis (2.4): ``R_c(f) = a f / (f + b)``; causal: ``a (j f/b) / (1 + j f/b)``
    (``a`` in parallel with ``a / (2 pi b)`` H: one relaxation time);
    relaxation (Davidson-Cole): ``a [1 - (1 + j f/b)^(-beta)]``, a
    distribution of relaxation times, the causal form for ``beta = 1``; like
    it, inductive at low frequency. Eddy currents in a lamination diffuse into
    the sheet, and its impedance approaches ``a`` as ``1/sqrt(f)``: ``beta``
    near ``1/2``, which one relaxation time cannot follow. (A width exponent,
    Havriliak-Negami, would give the low-frequency side a constant phase,
    the magnetising forms' share: on the virtual lab's chain it took the
    magnetising change.) A circuit without a core-loss
    resistor (one in parallel with an inductor) gets one at the port, in the
    thesis's and the one-pole forms only (the distributed form is a core's:
    at the port of a short-circuit measurement it took the winding's skin
    effect).
    A winding on a laminated core without a core loop (a ladder's sections
    only) also has the lamination form: the classical eddy-current law on
    every winding inductance and its mutuals,
    ``L [1 - d + d tanh(q)/q]``, ``q = (1 + j) sqrt(f/f_c)/2``, ``d`` the
    share of the flux in the core (:class:`LaminationLoss`).
``magnetising-inductance``
    thesis (2.5): ``L(f) = a f^(-b) L_linear`` (``a = k f_ref^b``, so
    ``L(f_ref) = k L_linear``; ``k = 1`` unless the level is free); causal:
    ``k L (j f/f_ref)^(-b)`` (``k = 1`` unless the level is free; its loss
    angle is ``b pi/2``); in both ``b <= 1/2``, the eddy-current limit of a
    lamination's permeability (a steeper constant-phase element is mainly a
    loss, named as core loss); relaxation (the core's permeability dispersing
    above a corner, Havriliak-Negami):
    ``L [1 - d + d (1 + (j f/f_c)^a)^(-b)]``, ``L`` below the corner,
    ``L (1 - d)`` far above it; ``a`` widens the dispersion symmetrically
    (Cole-Cole for ``b = 1``), ``b`` skews it (Davidson-Cole for ``a = 1``,
    the form without a design prior). Applied to the
    winding inductances with their mutuals (``M_ij`` scales with
    ``sqrt(L_i L_j)``), and (group ``core``) to the core loop's inductance
    ``Lc`` of ``Lc || Rc``: lossless (2.5) always, the causal form only with
    free levels (a design prior; without one its loss takes the share of a
    core loss).
``stray-capacitance``
    one-port data: a lossy fixture capacitance across the port, the causal
    constant-phase admittance ``Y = w0 C (j f/f0)^alpha`` (``alpha = 1`` an
    ideal capacitor, below 1 a dielectric loss of angle ``(1 - alpha) 90 deg``).
``lead-inductance``
    one-port data: a series lead ``R_l + j w L_l`` between the instrument and the port.

``missing-section`` is structural (see :mod:`.sections`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import jve

from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.circuits.freqdep import (FosterRL, core_loss_resistance, fit_impedance, fit_inductance,
    fit_resistance, magnetising_inductance, replace_with_ladder, thesis_skin_resistance)

from estimation.diagnosis.causes.sections import find_chains

#: Causes of the frequency-response catalogue, in the order they are listed.
FREQUENCY_CAUSES = ("skin-effect", "core-loss", "magnetising-inductance", "missing-section", "stray-capacitance",
                    "lead-inductance")


@dataclass(frozen=True)
class ExtraParameter:
    """An extension parameter: name, bounds and starting values (log-scaled when ``log``)."""

    name: str
    lower: float
    upper: float
    starts: tuple[float, ...]
    log: bool = True
    description: str = ""


@dataclass(frozen=True)
class Groups:
    """Winding resistors and inductors of a circuit by group (``all``, ``lv``, ``hv`` or a port name)."""

    resistors: dict[str, tuple[str, ...]]
    inductors: dict[str, tuple[str, ...]]
    core_resistor: str | None
    port: str


def winding_groups(circuit: Circuit, ports: Sequence[str], names: Mapping[str, str] | None = None) -> Groups:
    """Group the winding elements by chain (see :func:`.sections.find_chains`).

    Parameters
    ----------
    circuit : Circuit
    ports : sequence of str
        Driven nodes; the first is the port of one-port effects.
    names : mapping, optional
        Port node to group name (``{"a1": "lv", "b1": "hv"}``); default the node name.
    """
    chains = find_chains(circuit, ports)
    res: dict[str, tuple[str, ...]] = {}
    ind: dict[str, tuple[str, ...]] = {}
    for ch in chains:
        g = (names or {}).get(ch.port, ch.port)
        res[g] = tuple(ch.resistors)
        ind[g] = tuple(ch.inductors)
    if len(chains) > 1:
        res = {k: v for k, v in res.items() if v}
        ind = {k: v for k, v in ind.items() if v}
    res["all"] = tuple(r for ch in chains for r in ch.resistors)
    ind["all"] = tuple(i for ch in chains for i in ch.inductors)
    core = core_loop_inductor(circuit)
    if core is not None and core not in ind["all"]:
        ind["core"] = (core,)
    return Groups(res, ind, core_loss_resistor(circuit), circuit.require_node(ports[0]) if ports else "")


def core_loss_resistor(circuit: Circuit) -> str | None:
    """A resistor in parallel with an inductor (the core-loss loop ``Lc || Rc``), if any."""
    for r in circuit.of_kind("R"):
        for l in circuit.inductors():
            if set(r.nodes) == set(l.nodes):
                return r.name
    return None


def core_loop_inductor(circuit: Circuit) -> str | None:
    """The inductor of the core-loss loop ``Lc || Rc`` (the magnetising branch), if any."""
    rc = core_loss_resistor(circuit)
    if rc is None:
        return None
    nodes = set(circuit.element(rc).nodes)
    return next((l.name for l in circuit.inductors() if set(l.nodes) == nodes), None)


def _p(p: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    return np.asarray(p[name], float).reshape(-1, 1)


def _col(values: Mapping[str, np.ndarray | float], name: str) -> np.ndarray:
    return np.asarray(values[name.lower()], float).reshape(-1, 1)


@dataclass
class Effect:
    """One variant of a cause: its form, its winding group and its parameters.

    Subclasses give :meth:`branch_changes` (impedance changes of R or L
    branches) or :meth:`port_map` (a change at the port), the formula text and
    a time-domain realisation.
    """

    cause: str = "none"
    form: str = "causal"
    group: str = "all"
    parameters: list[ExtraParameter] = field(default_factory=list)
    f_ref: float = 1.0
    #: Highest frequency of the data, Hz (bounds the corner frequencies of relaxation forms).
    f_max: float = 0.0
    #: Give the forms a free level where they take one (``c`` of the causal skin form, ``k`` of the thesis and
    #: causal magnetising forms). Only with a design prior: without one the level and the circuit values are
    #: not separable.
    level: bool = False

    @property
    def label(self) -> str:
        """``cause`` with its form and group, e.g. ``skin-effect (2.6) [hv]``."""
        form = self.thesis_eq if self.form == "thesis" else self.form
        return f"{self.cause} ({form}) [{self.group}]"

    thesis_eq = ""

    def prepare(self, circuit: Circuit, groups: Groups, scale: float) -> Circuit:
        """Structural change needed by the effect (default none)."""
        return circuit

    def fixed(self, circuit: Circuit, groups: Groups) -> list[str]:
        """Circuit values the effect replaces (kept out of the fit)."""
        return []

    def branches(self, circuit: Circuit, groups: Groups) -> list[str]:
        """R or L elements whose impedance the effect changes."""
        return []

    def branch_changes(self, circuit: Circuit, groups: Groups, values: Mapping[str, np.ndarray], f: np.ndarray,
                       p: Mapping[str, np.ndarray]) -> list[tuple[list[str], np.ndarray]]:
        """Impedance changes ``(names, dZ)`` with ``dZ`` of shape ``(P, F, m, m)``, Ohm."""
        return []

    def value_names(self, circuit: Circuit, groups: Groups) -> set[str]:
        """Lower-case names of the circuit values :meth:`branch_changes` reads: the branches and the couplings
        between them (default)."""
        names = {n.lower() for n in self.branches(circuit, groups)}
        return names | {k.key for k in circuit.of_kind("K") if {n.lower() for n in k.nodes} <= names}

    def port_map(self, z: np.ndarray, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """Impedance seen at the instrument for port impedance ``z`` (P, F); default unchanged."""
        return z

    def port_slope(self, z: np.ndarray, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """Derivative of :meth:`port_map` with respect to the port impedance (``port_map`` is analytic in ``z``).

        Default: a central difference in ``z``; effects with a port map give the closed form.
        """
        if type(self).port_map is Effect.port_map:
            return np.ones_like(z)
        h = 1e-6 * np.where(z != 0, z, 1.0)
        return (self.port_map(z + h, f, p) - self.port_map(z - h, f, p)) / (2 * h)

    def applies(self, circuit: Circuit, groups: Groups) -> bool:
        return bool(self.branches(circuit, groups))

    def nested_in(self, other: "Effect") -> bool:
        """This variant is a special case of ``other`` (same cause and group, ``other``'s form with some of its
        parameters fixed); default never."""
        return False

    def formula(self, p: Mapping[str, float]) -> str:
        return ""

    def realise(self, circuit: Circuit, groups: Groups, p: Mapping[str, float], fmin: float, fmax: float
                ) -> tuple[Circuit, str]:
        """A circuit of constant R, L, C, K realising the effect over ``[fmin, fmax]``, and a note."""
        return circuit, ""


#: Steepest fall of a core's permeability, ``L ~ f^(-b)``, that the power-law magnetising forms take: the eddy-current
#: (diffusion) limit of a lamination, whose permeability falls as ``(j f)^(-1/2)`` far above its corner (loss angle
#: 45 deg). A constant-phase "inductance" with a larger loss angle is more resistive than inductive: a loss, which
#: ``core-loss`` names (on the virtual lab's chain an exponent of 0.6 on the core loop took the core loss's share).
MAX_PERMEABILITY_EXPONENT = 0.5

#: A free level (``c`` of the causal skin form, ``k`` of the magnetising forms) stays within this factor of 1.
LEVEL_RANGE = 4.0

_LEVEL_C = ExtraParameter("c", 1 / LEVEL_RANGE, LEVEL_RANGE, (1.0,),
                          description="c_Rs: R_linear / R at low frequency (level)")


def _band_top(e: Effect) -> float:
    """Highest frequency of the data (four decades above ``f_ref`` when not given), Hz."""
    return e.f_max if e.f_max > e.f_ref else 1e4 * e.f_ref


def _corner_range(e: Effect) -> tuple[float, float]:
    """Bounds of a relaxation form's corner frequency: a decade and a half beyond the data on either side, Hz."""
    return e.f_ref / 30, _band_top(e) * 30


def _corner_starts(e: Effect) -> tuple[float, ...]:
    """Starting corner frequencies: near the bottom, the middle and the top of the data's band, Hz."""
    hi = _band_top(e)
    return (3 * e.f_ref, float(np.sqrt(e.f_ref * hi)), hi / 3)


def _diag(names: Sequence[str], dz: np.ndarray) -> list[tuple[list[str], np.ndarray]]:
    """Diagonal changes ``dz`` (P, F, m) as one block."""
    P, F, m = dz.shape
    block = np.zeros((P, F, m, m), complex)
    idx = np.arange(m)
    block[:, :, idx, idx] = dz
    return [(list(names), block)]


# ---------------------------------------------------------------------------------------------- skin effect
@dataclass
class SkinEffect(Effect):
    def __post_init__(self) -> None:
        self.cause = "skin-effect"
        self.thesis_eq = "2.6"
        if self.form == "thesis":
            self.parameters = [
                ExtraParameter("a", 1e-4, 1e5, (0.01, 0.3, 3.0), description="a_Rs: rise factor"),
                ExtraParameter("b", 0.2, 2.5, (0.5, 1.0), log=False, description="b_Rs: exponent"),
                ExtraParameter("f0", self.f_ref / 30, self.f_ref * 3e3, (self.f_ref / 3, self.f_ref * 3),
                               description="f0: frequency of R_linear, Hz"),
            ]
        elif self.form == "relaxation":
            lo, hi = _corner_range(self)
            self.parameters = [
                ExtraParameter("a", 1e-3, 1e4, (0.3, 3.0), description="amplitude of the rise (x R)"),
                ExtraParameter("b", 0.2, 1.0, (0.5,), log=False, description="high-frequency exponent"),
                ExtraParameter("fc", lo, hi, _corner_starts(self), description="corner frequency, Hz"),
            ]
        else:
            self.parameters = [
                ExtraParameter("a", 1e-4, 1e4, (1e-3, 0.3, 10.0), description="resistance rise at f_ref (x R)"),
                ExtraParameter("b", 0.1, 1.0, (0.5,), log=False, description="frequency exponent"),
            ]
            if self.level:
                self.parameters.append(_LEVEL_C)

    def branches(self, circuit, groups):
        return list(groups.resistors.get(self.group, ()))

    def factor(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """``R(f) / R`` (P, F)."""
        if self.form == "thesis":
            return thesis_skin_resistance(f[None, :], 1.0, _p(p, "a"), _p(p, "b"), 1.0, _p(p, "f0")).astype(complex)
        if self.form == "relaxation":
            return 1 + _p(p, "a") * ((1 + 1j * f[None, :] / _p(p, "fc")) ** _p(p, "b") - 1)
        c = _p(p, "c") if "c" in p else 1.0
        return (1 + _p(p, "a") * (1j * f[None, :] / self.f_ref) ** _p(p, "b")) / c

    def branch_changes(self, circuit, groups, values, f, p):
        names = self.branches(circuit, groups)
        fac = self.factor(f, p) - 1
        dz = np.stack([_col(values, n) * fac for n in names], axis=-1)
        return _diag(names, dz)

    def formula(self, p):
        c = p.get("c", 1.0)
        if self.form == "thesis":
            return (f"R(f) = R_linear/c [1 + a (f/f0 - 1)^b] for f >= f0 (thesis 2.6), c = 1, a = {p['a']:.4g}, "
                    f"b = {p['b']:.4g}, f0 = {p['f0']:.4g} Hz")
        if self.form == "relaxation":
            return (f"Z_R(f) = R [1 + a ((1 + j f/f_c)^b - 1)], a = {p['a']:.4g}, b = {p['b']:.4g}, "
                    f"f_c = {p['fc']:.4g} Hz")
        lead = "R/c [1 + a" if "c" in p else "R [1 + a"
        tail = f", c = {c:.4g}" if "c" in p else ""
        return f"Z_R(f) = {lead} (j f/{self.f_ref:.4g} Hz)^b], a = {p['a']:.4g}, b = {p['b']:.4g}{tail}"

    def realise(self, circuit, groups, p, fmin, fmax):
        values = circuit.resolve(check=False)
        out = circuit
        pp = {k: np.array([v]) for k, v in p.items()}
        for name in self.branches(circuit, groups):
            r = float(values[name.lower()])
            if self.form == "thesis":
                lad = fit_resistance(lambda x, r=r: r * self.factor(np.atleast_1d(x), pp)[0].real, fmin, fmax, 12)
            else:
                lad = fit_impedance(lambda x, r=r: r * self.factor(np.atleast_1d(x), pp)[0], fmin, fmax, 12)
            out = replace_with_ladder(_numeric(out, name), name, lad)
        note = ("a real-valued R(f) has no causal realisation: the ladder follows its resistance and adds its own "
                "reactance" if self.form == "thesis" else "passive R-L ladders in place of the winding resistances")
        return out, note


@dataclass
class ConductorSkin(SkinEffect):
    """The skin effect of a round conductor: the field's exact diffusion into the wire.

    A wire of radius ``r`` carrying the current has the internal impedance
    ``R_dc (x/2) J0(x)/J1(x)``, ``x = (1 - j) r / delta``, with the skin depth
    ``delta = r`` at the corner ``f_c`` (``r/delta = sqrt(f/f_c)``; e.g.
    Ramo, Whinnery and Van Duzer, *Fields and Waves in Communication
    Electronics*, 3rd ed., 1994, sec. 5.12). Far below ``f_c`` it is ``R_dc``
    and the internal inductance ``R_dc / (4 pi f_c)``; far above, both grow as
    ``sqrt(f)`` at equal resistance and reactance. A share ``a`` of each
    winding resistance is the wire's (the rest, a lead's or a joint's, stays
    flat; ``a`` above one is the proximity of the other turns, which scales
    the rise): ``Z_R(f) = R [1 - a + a (x/2) J0(x)/J1(x)]``. The relaxation
    form's ``(1 + j f/f_c)^b`` follows this curve within 2-3 % of the
    impedance over the corner; the resistance of a winding at its
    resonances is what their damping measures, and at a percent of noise
    that difference is seen.
    """

    def __post_init__(self) -> None:
        self.cause = "skin-effect"
        self.form = "conductor"
        lo, hi = _corner_range(self)
        self.parameters = [
            ExtraParameter("a", 1e-3, 10.0, (1.0,), description="share of the resistance in the wire (x R)"),
            ExtraParameter("fc", lo, hi, _corner_starts(self), description="corner (skin depth = radius), Hz"),
        ]

    def factor(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """``Z_R(f) / R`` (P, F)."""
        x = (1 - 1j) * np.sqrt(f[None, :] / _p(p, "fc"))
        a = _p(p, "a")
        return 1 - a + a * (x / 2) * jve(0, x) / jve(1, x)  # the exponential scalings of jve cancel in the ratio

    def formula(self, p):
        return (f"Z_R(f) = R [1 - a + a (x/2) J0(x)/J1(x)], x = (1 - j) sqrt(f/f_c) (round conductor), "
                f"a = {p['a']:.4g}, f_c = {p['fc']:.4g} Hz")


# ---------------------------------------------------------------------------------------------- core loss
@dataclass
class CoreLoss(Effect):
    def __post_init__(self) -> None:
        self.cause = "core-loss"
        self.thesis_eq = "2.4"
        self.parameters = [
            ExtraParameter("a", 1e-3, 1e12, (1e6,), description="a_Ro: high-frequency core-loss resistance, Ohm"),
            ExtraParameter("b", 1e-3, 1e12, (1e3,), description="b_Ro: corner frequency, Hz"),
        ]
        if self.form == "relaxation":  # Davidson-Cole: a distributed (eddy-current, diffusive) dispersion
            self.parameters.append(ExtraParameter("beta", 0.2, 1.0, (0.5,), log=False,
                                                  description="exponent of the approach to a"))

    def resistor(self, circuit: Circuit, groups: Groups) -> str:
        # found on the circuit the groups were taken from: a realised ladder's R || L sections are not the core loop
        return groups.core_resistor or "Rcore"

    def nested_in(self, other: Effect) -> bool:
        """The causal form (one relaxation time) is the relaxation form with ``beta = 1``."""
        return (isinstance(other, CoreLoss) and self.form == "causal" and other.form == "relaxation"
                and self.group == other.group)

    def prepare(self, circuit, groups, scale):
        if core_loss_resistor(circuit) is not None or circuit.has_element("Rcore"):
            return circuit
        c = circuit.copy()
        c.add("Rcore", groups.port or c.nodes[0], GROUND, 1e3 * scale)
        return c

    def fixed(self, circuit, groups):
        return [self.resistor(circuit, groups)]

    def branches(self, circuit, groups):
        return [self.resistor(circuit, groups)]

    def applies(self, circuit, groups):
        return True

    def starts(self, circuit: Circuit, values: Mapping[str, float], scale: float, fmin: float, fmax: float
               ) -> list[dict[str, float]]:
        rc = core_loss_resistor(circuit)
        base = float(values[rc.lower()]) if rc and rc != "Rcore" else 30 * scale
        fmid = float(np.sqrt(fmin * fmax))
        starts = [{"a": base * m, "b": fmid * g} for m in (1.0, 10.0) for g in (0.01, 0.1, 1.0, 10.0)]
        starts += [{"a": 1e11, "b": fmid}]  # effectively no core loss: never worse than the baseline
        if self.form == "relaxation":  # from the diffusive shape (a lamination's is close to beta = 1/2)
            starts = [{**s, "beta": 0.5} for s in starts]
        return starts

    def resistance(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """``R_c(f)`` (P, F), complex for the causal form."""
        if self.form == "thesis":
            return core_loss_resistance(f[None, :], _p(p, "a"), _p(p, "b")).astype(complex)
        x = 1j * f[None, :] / _p(p, "b")
        if self.form == "relaxation":
            return _p(p, "a") * (1 - (1 + x) ** (-_p(p, "beta")))
        return _p(p, "a") * x / (1 + x)

    def branch_changes(self, circuit, groups, values, f, p):
        name = self.resistor(circuit, groups)
        dz = self.resistance(f, p) - _col(values, name)
        return _diag([name], dz[..., None])

    def formula(self, p):
        if self.form == "thesis":
            return f"R_c(f) = a f / (f + b) (thesis 2.4), a = {p['a']:.4g} Ohm, b = {p['b']:.4g} Hz"
        if self.form == "relaxation":
            return (f"Z_c(f) = a [1 - (1 + j f/b)^(-beta)] (Davidson-Cole), a = {p['a']:.4g} Ohm, "
                    f"b = {p['b']:.4g} Hz, beta = {p['beta']:.4g}")
        return f"Z_c(f) = a (j f/b) / (1 + j f/b), a = {p['a']:.4g} Ohm, b = {p['b']:.4g} Hz"

    def realise(self, circuit, groups, p, fmin, fmax):
        name = self.resistor(circuit, groups)
        if self.form == "thesis":
            lad = fit_resistance(lambda x: core_loss_resistance(x, p["a"], p["b"]), fmin, fmax, 10)
            note = ("a real-valued R_c(f) has no causal realisation: the ladder follows its resistance and adds its "
                    "own reactance")
        elif self.form == "relaxation":
            pp = {k: np.array([v]) for k, v in p.items()}
            lad = fit_impedance(lambda x: self.resistance(np.atleast_1d(x), pp)[0], fmin, fmax, 12)
            note = "Z_c(f) realised by a passive R-L ladder (parallel R-L sections in series) over the band"
        else:
            lad = FosterRL(0.0, 0.0, np.array([p["a"]]), np.array([p["a"] / (2 * np.pi * p["b"])]))
            note = "R_c(f) realised exactly by a in parallel with a / (2 pi b)"
        return replace_with_ladder(_numeric(circuit, name), name, lad), note


@dataclass
class LaminationLoss(Effect):
    """Eddy-current loss of a laminated core in the winding inductances it carries (no core loop in the circuit).

    The flux in a lamination of thickness ``t`` diffuses into the sheet: its
    permeability is ``mu tanh(q)/q``, ``q = (1 + j) t / (2 delta)``, with the
    skin depth ``delta = t`` at the corner ``f_c`` (``t/delta = sqrt(f/f_c)``;
    the classical eddy-current law of a lamination, e.g. Bertotti, *Hysteresis
    in Magnetism*, 1998, ch. 12). A share ``d`` of each inductance's flux is in
    the core, the rest in air: ``L(f) = L [1 - d + d tanh(q)/q]``, on every
    winding inductance and their mutuals. A loss, not a change of the
    magnetising level: ``L(f) = L`` far below ``f_c`` and the core's loss
    angle reaches 45 deg above it.
    """

    def __post_init__(self) -> None:
        self.cause = "core-loss"
        self.form = "lamination"
        lo, hi = _corner_range(self)
        self.parameters = [
            ExtraParameter("d", 1e-3, 1.0, (0.5, 0.95), log=False, description="share of the flux in the core"),
            ExtraParameter("fc", lo, hi, _corner_starts(self), description="corner (skin depth = lamination), Hz"),
        ]

    def applies(self, circuit, groups):
        return groups.core_resistor is None and bool(groups.inductors.get(self.group))

    def branches(self, circuit, groups):
        return MagnetisingInductance.branches(self, circuit, groups)

    def scale(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """``L(f) / L`` (P, F)."""
        q = (1 + 1j) * 0.5 * np.sqrt(f[None, :] / _p(p, "fc"))
        e = np.exp(-2 * q)
        d = _p(p, "d")
        return 1 - d + d * (1 - e) / ((1 + e) * q)  # tanh(q) without overflow (Re q > 0)

    def branch_changes(self, circuit, groups, values, f, p):
        return MagnetisingInductance.branch_changes(self, circuit, groups, values, f, p)

    def formula(self, p):
        return (f"L(f) = L [1 - d + d tanh(q)/q], q = (1 + j) sqrt(f/f_c)/2 (lamination), d = {p['d']:.4g}, "
                f"f_c = {p['fc']:.4g} Hz")

    def realise(self, circuit, groups, p, fmin, fmax):
        pp = {k: np.array([v]) for k, v in p.items()}

        def ladder(lv: float) -> FosterRL:
            lad = fit_impedance(lambda x: 2j * np.pi * x * lv * self.scale(np.atleast_1d(x), pp)[0], fmin, fmax, 14)
            # all the flux in the core (d = 1): no inductance is left in series, but a coupled inductor keeps its
            # couplings on it; a ten-thousandth of it changes the ladder by 1e-4 of j w L over the band
            return replace(lad, l0=max(lad.l0, LAMINATION_SERIES_FLOOR * lv))

        out = _inductances_as_ladders(circuit, groups.inductors.get(self.group, ()), ladder)
        return out, ("winding inductances as R-L ladders following the lamination's eddy-current law; coupled "
                     "inductors keep their couplings on the ladder's series inductance")


#: Least series inductance of a lamination's realised ladder, relative to the inductance it replaces.
LAMINATION_SERIES_FLOOR = 1e-4


# ---------------------------------------------------------------------------------------------- magnetising
@dataclass
class MagnetisingInductance(Effect):
    def __post_init__(self) -> None:
        self.cause = "magnetising-inductance"
        self.thesis_eq = "2.5"
        if self.form == "relaxation":  # Havriliak-Negami dispersion of the core's permeability
            lo, hi = _corner_range(self)
            self.parameters = [
                ExtraParameter("d", 1e-3, 0.95, (0.05, 0.3), description="fall of L above the corner (x L)"),
                ExtraParameter("b", 0.2, 1.0, (0.5,), log=False, description="asymmetry exponent"),
            ] + ([ExtraParameter("a", 0.3, 1.0, (0.8,), log=False, description="width exponent")] if self.level else [])
            self.parameters.append(ExtraParameter("fc", lo, hi, _corner_starts(self), description="corner frequency, Hz"))
            return
        lo = 0.0 if self.form == "thesis" else 1e-4
        self.parameters = [ExtraParameter("b", lo, MAX_PERMEABILITY_EXPONENT, (0.005, 0.02, 0.05, 0.1, 0.2),
                                          log=False, description="b_Lo: exponent")]
        if self.form in ("thesis", "causal") and self.level:
            self.parameters.append(ExtraParameter("k", 1 / LEVEL_RANGE, LEVEL_RANGE, (1.0,),
                                                  description="L(f_ref) / L_linear (a_Lo = k f_ref^b)"))

    def branches(self, circuit, groups):
        group = set(n.lower() for n in groups.inductors.get(self.group, ()))
        if not group:
            return []
        coupled = set(group)
        for k in circuit.of_kind("K"):
            a, b = (n.lower() for n in k.nodes)
            if a in group or b in group:
                coupled |= {a, b}
        return [l.name for l in circuit.inductors() if l.key in coupled]

    def applies(self, circuit, groups):
        return bool(groups.inductors.get(self.group))

    def scale(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        """``L(f) / L`` (P, F)."""
        if self.form == "thesis":
            b = _p(p, "b")
            k = _p(p, "k") if "k" in p else 1.0
            return magnetising_inductance(f[None, :], 1.0, k * self.f_ref ** b, b).astype(complex)
        if self.form == "relaxation":
            d = _p(p, "d")
            a = _p(p, "a") if "a" in p else 1.0
            return 1 - d + d * (1 + (1j * f[None, :] / _p(p, "fc")) ** a) ** (-_p(p, "b"))
        k = _p(p, "k") if "k" in p else 1.0
        return k * (1j * f[None, :] / self.f_ref) ** (-_p(p, "b"))

    def branch_changes(self, circuit, groups, values, f, p):
        names = self.branches(circuit, groups)
        group = set(n.lower() for n in groups.inductors.get(self.group, ()))
        sub = Circuit(elements=[circuit.element(n) for n in names] +
                      [k for k in circuit.of_kind("K") if all(x.lower() in {n.lower() for n in names} for x in k.nodes)])
        L = sub.inductance_matrix({e.key: np.asarray(values[e.key], float) for e in sub.elements})
        L = L.reshape((-1,) + L.shape[-2:])  # (P, m, m)
        g = self.scale(f, p)  # (P, F)
        d = np.ones(g.shape + (len(names),), complex)
        for j, n in enumerate(names):
            if n.lower() in group:
                d[..., j] = np.sqrt(g)
        s = 2j * np.pi * f[None, :, None, None]
        dz = s * (d[..., :, None] * L[:, None] * d[..., None, :] - L[:, None])
        return [(names, dz)]

    def formula(self, p):
        if self.form == "thesis":
            if "k" in p:
                return (f"L(f) = a f^(-b) L_linear (thesis 2.5), b = {p['b']:.4g}, a = k f_ref^b = "
                        f"{p['k'] * self.f_ref ** p['b']:.4g} (k = {p['k']:.4g}, f_ref = {self.f_ref:.4g} Hz)")
            return (f"L(f) = a f^(-b) L_linear (thesis 2.5), b = {p['b']:.4g}, a = f_ref^b = "
                    f"{self.f_ref ** p['b']:.4g} (f_ref = {self.f_ref:.4g} Hz)")
        if self.form == "relaxation":
            if "a" not in p:
                return (f"L(f) = L [1 - d + d (1 + j f/f_c)^(-b)] (Davidson-Cole), d = {p['d']:.4g}, b = {p['b']:.4g}, "
                        f"f_c = {p['fc']:.4g} Hz")
            return (f"L(f) = L [1 - d + d (1 + (j f/f_c)^a)^(-b)] (Havriliak-Negami), d = {p['d']:.4g}, "
                    f"a = {p['a']:.4g}, b = {p['b']:.4g}, f_c = {p['fc']:.4g} Hz")
        if "k" in p:
            return f"Z_L(f) = j w L k (j f/{self.f_ref:.4g} Hz)^(-b), b = {p['b']:.4g}, k = {p['k']:.4g}"
        return f"Z_L(f) = j w L (j f/{self.f_ref:.4g} Hz)^(-b), b = {p['b']:.4g}"

    def realise(self, circuit, groups, p, fmin, fmax):
        pp = {k: np.array([v]) for k, v in p.items()}

        def ladder(lv: float) -> FosterRL:
            if self.form == "thesis":
                return fit_inductance(lambda x: lv * self.scale(np.atleast_1d(x), pp)[0].real, fmin, fmax, 8)
            return fit_impedance(lambda x: 2j * np.pi * x * lv * self.scale(np.atleast_1d(x), pp)[0], fmin, fmax, 10)

        out = _inductances_as_ladders(circuit, groups.inductors.get(self.group, ()), ladder)
        note = ("winding inductances as R-L ladders; coupled inductors keep their couplings on the ladder's series "
                "inductance, the sections are uncoupled")
        if self.form == "thesis":
            note = "a real-valued L(f) has no causal realisation; " + note
        return out, note


# ---------------------------------------------------------------------------------------------- port effects
@dataclass
class StrayCapacitance(Effect):
    """A lossy capacitance across the port (fixture, leads): constant-phase admittance."""

    c_scale: float = 1e-12

    def __post_init__(self) -> None:
        self.cause = "stray-capacitance"
        self.parameters = [
            ExtraParameter("c", self.c_scale * 1e-3, self.c_scale * 1e3, (self.c_scale * 0.1, self.c_scale),
                           description="capacitance at f0, F"),
            ExtraParameter("alpha", 0.3, 1.0, (0.7, 0.95), log=False, description="constant-phase exponent"),
        ]

    def applies(self, circuit, groups):
        return True

    def admittance(self, f: np.ndarray, p: Mapping[str, np.ndarray]) -> np.ndarray:
        w0 = 2 * np.pi * self.f_ref
        return w0 * _p(p, "c") * (1j * f[None, :] / self.f_ref) ** _p(p, "alpha")

    def port_map(self, z, f, p):
        return z / (1 + z * self.admittance(f, p))

    def port_slope(self, z, f, p):
        return 1 / (1 + z * self.admittance(f, p)) ** 2

    def formula(self, p):
        loss = (1 - p["alpha"]) * 90
        return (f"Y(f) = 2 pi f0 C (j f/f0)^alpha across the port, C = {p['c']:.4g} F, alpha = {p['alpha']:.4g} "
                f"(loss angle {loss:.3g} deg), f0 = {self.f_ref:.4g} Hz")

    def realise(self, circuit, groups, p, fmin, fmax):
        from estimation.diagnosis.causes.ladders import fit_admittance_rc

        c = circuit.copy()
        pp = {k: np.array([v]) for k, v in p.items()}
        branches = fit_admittance_rc(lambda x: self.admittance(np.atleast_1d(x), pp)[0], fmin, fmax)
        port = groups.port
        for i, (r, cap) in enumerate(branches, start=1):
            if r > 0:
                node = f"stray_n{i}"
                c.add(f"Rstray{i}", port, node, r)
                c.add(f"Cstray{i}", node, GROUND, cap)
            else:
                c.add(f"Cstray{i}", port, GROUND, cap)
        return c, "constant-phase admittance realised by parallel series-R-C branches across the port"


@dataclass
class LeadInductance(Effect):
    """A series lead between the instrument and the port: ``R_l + j w L_l``."""

    l_scale: float = 1e-9
    r_scale: float = 1e-3

    def __post_init__(self) -> None:
        self.cause = "lead-inductance"
        self.parameters = [
            ExtraParameter("l", self.l_scale * 1e-4, self.l_scale * 1e3, (self.l_scale * 0.01, self.l_scale * 0.3),
                           description="lead inductance, H"),
            ExtraParameter("r", self.r_scale * 1e-4, self.r_scale * 1e3, (self.r_scale * 0.01,),
                           description="lead resistance, Ohm"),
        ]

    def applies(self, circuit, groups):
        return True

    def port_map(self, z, f, p):
        return z + _p(p, "r") + 2j * np.pi * f[None, :] * _p(p, "l")

    def port_slope(self, z, f, p):
        return np.ones(np.broadcast_shapes(np.shape(z), (1, f.size)), complex)

    def formula(self, p):
        return f"Z_lead = R_l + j w L_l, R_l = {p['r']:.4g} Ohm, L_l = {p['l']:.4g} H"

    def realise(self, circuit, groups, p, fmin, fmax):
        port = groups.port
        inner = "lead_port"
        c = Circuit(circuit.title, [replace(e, nodes=tuple(inner if n == port else n for n in e.nodes))
                                    if e.kind != "K" else e for e in circuit.elements],
                    list(circuit.parameters), list(circuit.ports), list(circuit.probes), list(circuit.comments))
        c.add("Rlead", port, "lead_mid", p["r"])
        c.add("Llead", "lead_mid", inner, p["l"])
        return c, "series lead R-L between the terminal and the winding"


def _inductances_as_ladders(circuit: Circuit, names: Sequence[str], ladder: Callable[[float], FosterRL]) -> Circuit:
    """``circuit`` with each inductor of ``names`` replaced by ``ladder(L)`` (its resolved inductance ``L``, H)."""
    values = circuit.resolve(check=False)
    out = circuit
    for name in names:
        out = replace_with_ladder(_numeric(out, name), name, ladder(float(values[name.lower()])))
    return out


def _numeric(circuit: Circuit, name: str) -> Circuit:
    """The circuit with element ``name`` given its resolved numeric value (ladders replace numbers only)."""
    v = float(circuit.resolve(check=False)[name.lower()])
    return circuit.with_values({name: v})


def effect_variants(cause: str, groups: Groups, circuit: Circuit, f_ref: float, one_port: bool,
                    scale: float = 1.0, f_max: float = 1.0, level: bool = False) -> list[Effect]:
    """Every form and group of ``cause`` that applies to ``circuit`` (with free levels when ``level``)."""
    out: list[Effect] = []
    names = [g for g in groups.resistors if g != "all"]
    group_list = (names + ["all"]) if len(names) > 1 else ["all"]
    for form in ("thesis", "causal", "relaxation"):
        if cause == "skin-effect":
            out += [SkinEffect(form=form, group=g, f_ref=f_ref, f_max=f_max, level=level) for g in group_list]
        elif cause == "magnetising-inductance":
            out += [MagnetisingInductance(form=form, group=g, f_ref=f_ref, f_max=f_max, level=level) for g in group_list]
            # the core loop's own inductance: lossless (2.5); with free levels (a design prior) also the causal
            # form, whose loss angle b pi/2 the design's core-loss resistance cannot take
            if "core" in groups.inductors and (form == "thesis" or (form == "causal" and level)):
                out.append(MagnetisingInductance(form=form, group="core", f_ref=f_ref, f_max=f_max,
                                                 level=level))
        # the distributed form is a magnetic core's (its loop Lc || Rc); a resistor added at the port of a circuit
        # without one is a shunt loss, in the thesis's form and with one relaxation time only
        elif cause == "core-loss" and (form != "relaxation" or groups.core_resistor is not None):
            out.append(CoreLoss(form=form, group="all", f_ref=f_ref, f_max=f_max))
    # a winding on a laminated core without a core loop: the core's loss is in the winding inductances themselves
    if cause == "core-loss" and groups.core_resistor is None:
        out.append(LaminationLoss(group="all", f_ref=f_ref, f_max=f_max))
    # the conductor's own diffusion: a round wire's exact skin effect
    if cause == "skin-effect":
        out += [ConductorSkin(group=g, f_ref=f_ref, f_max=f_max) for g in group_list]
    if one_port and cause == "stray-capacitance":
        w = 2 * np.pi * f_max
        out.append(StrayCapacitance(form="causal", group="port", f_ref=f_max, c_scale=1 / (w * scale)))
    if one_port and cause == "lead-inductance":
        w = 2 * np.pi * f_max
        out.append(LeadInductance(form="causal", group="port", f_ref=f_max, l_scale=scale / w, r_scale=scale))
    return [e for e in out if e.applies(circuit, groups)]
