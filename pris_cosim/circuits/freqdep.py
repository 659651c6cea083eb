"""Frequency-dependent elements realised as R-L ladders, so they stay simulable.

The thesis's remedies for low-frequency misfit (2.4)-(2.6) are formulas in
``f``: a skin-effect winding resistance, a core-loss resistance and a
magnetising inductance that change with frequency. A formula cannot be
simulated in the time domain or put into an FMU; a network can. Here each
formula is fitted, over a frequency band, by a Foster R-L ladder

.. math:: Z(s) = R_0 + s L_0 + \\sum_k \\frac{s L_k R_k}{R_k + s L_k},

whose sections ``R_k || L_k`` have corner frequencies log-spaced over the
band; non-negative least squares keeps every element positive, so the result
is passive by construction. The ladder is inserted into a
:class:`~pris_cosim.circuits.circuit.Circuit` in place of the element it models.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from pris_cosim.circuits.circuit import GROUND, Circuit, Element
from pris_cosim.datafiles import DATA
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.expressions import Expression


# ---------------------------------------------------------------------- formulas
def skin_resistance(f: np.ndarray, r0: float, a: float, b: float, f0: float = 1e3) -> np.ndarray:
    """Winding resistance with skin effect, ``R0 (1 + a (f/f0)^b)`` (Ohm)."""
    return r0 * (1 + a * (np.asarray(f, float) / f0) ** b)


def thesis_skin_resistance(f: np.ndarray, r_linear: float, a: float, b: float, c: float, f0: float) -> np.ndarray:
    """Thesis (2.6): ``R_linear / c [1 + a (f/f0 - 1)^b]`` for ``f >= f0`` (Ohm); ``R_linear / c`` below."""
    x = np.clip(np.asarray(f, float) / f0 - 1, 0, None)
    return r_linear / c * (1 + a * x**b)


def core_loss_resistance(f: np.ndarray, a: float, b: float) -> np.ndarray:
    """Thesis (2.4): core-loss resistance ``a f / (f + b)`` (Ohm; ``b`` in Hz)."""
    f = np.asarray(f, float)
    return a * f / (f + b)


def magnetising_inductance(f: np.ndarray, l_linear: float, a: float, b: float) -> np.ndarray:
    """Thesis (2.5): ``a f^(-b) L_linear`` (H)."""
    return a * np.asarray(f, float) ** (-b) * l_linear


# ---------------------------------------------------------------------- ladder
@dataclass(frozen=True)
class FosterRL:
    """A series chain ``R0 + s L0`` plus parallel ``R_k || L_k`` sections.

    Attributes
    ----------
    r0 : float, Ohm
    l0 : float, H
    r, l : numpy.ndarray, Ohm, H
        Section values (zero-valued sections are dropped).
    """

    r0: float
    l0: float
    r: np.ndarray
    l: np.ndarray

    def impedance(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Complex impedance (Ohm) at the given frequencies (Hz)."""
        s = 2j * np.pi * np.asarray(frequency_hz, float)[:, None]
        sections = (s * self.l * self.r / (self.r + s * self.l)).sum(axis=1) if self.r.size else 0.0
        return self.r0 + s[:, 0] * self.l0 + sections

    def resistance(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Real part, Ohm."""
        return self.impedance(frequency_hz).real

    def inductance(self, frequency_hz: np.ndarray) -> np.ndarray:
        """Effective inductance ``Im Z / omega``, H."""
        f = np.asarray(frequency_hz, float)
        return self.impedance(f).imag / (2 * np.pi * f)

    @property
    def n_elements(self) -> int:
        return int(self.r0 > 0) + int(self.l0 > 0) + 2 * self.r.size


def _corners(fmin: float, fmax: float, n: int) -> np.ndarray:
    if not 0 < fmin < fmax:
        raise ValueError(f"need 0 < fmin < fmax (got {fmin}, {fmax})")
    if n < 1:
        raise ValueError(f"n_sections must be at least 1 (got {n})")
    return 2 * np.pi * np.logspace(np.log10(fmin) - 0.5, np.log10(fmax) + 0.5, n)


def fit_resistance(
    r_of_f: Callable[[np.ndarray], np.ndarray], fmin: float, fmax: float, n_sections: int = 8, l0: float = 0.0
) -> FosterRL:
    """Ladder whose resistance follows ``r_of_f`` over ``[fmin, fmax]`` (relative least squares).

    Section ``k`` contributes ``R_k (w/w_k)^2 / (1 + (w/w_k)^2)`` to the
    resistance with corner ``w_k = R_k / L_k``; ``R0`` and ``R_k`` come from
    NNLS, so all are non-negative.

    Parameters
    ----------
    r_of_f : callable
        Target resistance (Ohm) as a function of frequency (Hz).
    fmin, fmax : float, Hz
    n_sections : int
    l0 : float, H
        Series inductance kept in the chain (the branch's own inductance).
    """
    f = np.logspace(np.log10(fmin), np.log10(fmax), 200)
    target = np.asarray(r_of_f(f), float)
    if np.any(target < 0) or not np.all(np.isfinite(target)):
        raise ValueError("target resistance must be finite and non-negative over the band")
    wk = _corners(fmin, fmax, n_sections)
    x = (2 * np.pi * f[:, None] / wk) ** 2
    basis = np.column_stack([np.ones(f.size), x / (1 + x)])
    weight = 1 / np.maximum(target, 1e-30)[:, None]
    from scipy.optimize import nnls  # imported here: scipy.optimize costs half a second at start-up

    coef, _ = nnls(basis * weight, target * weight[:, 0], maxiter=50 * basis.shape[1])
    keep = coef[1:] > 1e-12 * max(coef.max(), 1e-300)
    r = coef[1:][keep]
    return FosterRL(float(coef[0]), float(l0), r, r / wk[keep])


def fit_inductance(
    l_of_f: Callable[[np.ndarray], np.ndarray], fmin: float, fmax: float, n_sections: int = 8, r0: float = 0.0
) -> FosterRL:
    """Ladder whose effective inductance follows a decreasing ``l_of_f`` over ``[fmin, fmax]``.

    Section ``k`` contributes ``L_k / (1 + (w/w_k)^2)``; ``L0`` is the
    high-frequency limit. Coefficients by NNLS (all non-negative).

    Parameters
    ----------
    l_of_f : callable
        Target inductance (H) as a function of frequency (Hz).
    fmin, fmax : float, Hz
    n_sections : int
    r0 : float, Ohm
        Series resistance kept in the chain.
    """
    f = np.logspace(np.log10(fmin), np.log10(fmax), 200)
    target = np.asarray(l_of_f(f), float)
    if np.any(target <= 0) or not np.all(np.isfinite(target)):
        raise ValueError("target inductance must be finite and positive over the band")
    wk = _corners(fmin, fmax, n_sections)
    x = (2 * np.pi * f[:, None] / wk) ** 2
    basis = np.column_stack([np.ones(f.size), 1 / (1 + x)])
    weight = 1 / target[:, None]
    from scipy.optimize import nnls  # imported here: scipy.optimize costs half a second at start-up

    coef, _ = nnls(basis * weight, target * weight[:, 0], maxiter=50 * basis.shape[1])
    keep = coef[1:] > 1e-12 * max(coef.max(), 1e-300)
    l = coef[1:][keep]
    return FosterRL(float(r0), float(coef[0]), l * wk[keep], l)


def relative_nnls(basis: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Non-negative coefficients ``c`` with ``basis @ c ~ target``, relative to ``|target|``, real and imaginary parts.

    Parameters
    ----------
    basis : numpy.ndarray
        ``(F, m)`` complex basis functions at the fitted frequencies.
    target : numpy.ndarray
        ``(F,)`` complex target (an impedance or admittance).

    Returns
    -------
    numpy.ndarray
        ``(m,)`` coefficients, all ``>= 0`` (columns equilibrated for the solve).
    """
    from scipy.optimize import nnls  # imported here: scipy.optimize costs half a second at start-up

    weight = 1 / np.maximum(np.abs(target), 1e-300)[:, None]
    a = np.vstack([(basis * weight).real, (basis * weight).imag])
    b = np.concatenate([(target * weight[:, 0]).real, (target * weight[:, 0]).imag])
    col = np.abs(a).max(axis=0)
    col[col == 0] = 1.0
    coef, _ = nnls(a / col, b, maxiter=50 * a.shape[1])
    return coef / col


def fit_impedance(
    z_of_f: Callable[[np.ndarray], np.ndarray], fmin: float, fmax: float, n_sections: int = 10
) -> FosterRL:
    """Ladder whose complex impedance follows ``z_of_f`` over ``[fmin, fmax]``.

    Every term of the ladder is linear in its resistance for a fixed corner
    frequency (``R_k (s/w_k) / (1 + s/w_k)``), so real and imaginary parts are
    fitted together by non-negative least squares, relative to ``|Z|``. Use it
    for causal targets such as the fractional skin-effect impedance
    ``R (1 + a (j f/f0)^b)``.

    Parameters
    ----------
    z_of_f : callable
        Target impedance (Ohm, complex) as a function of frequency (Hz).
    fmin, fmax : float, Hz
    n_sections : int
    """
    f = np.logspace(np.log10(fmin), np.log10(fmax), 200)
    target = np.asarray(z_of_f(f), complex)
    if not np.all(np.isfinite(target)) or np.any(target.real < 0):
        raise ValueError("target impedance must be finite with a non-negative real part over the band")
    wk = _corners(fmin, fmax, n_sections)
    s = 1j * 2 * np.pi * f[:, None]
    basis = np.column_stack([np.ones(f.size), s[:, 0], (s / wk) / (1 + s / wk)])
    coef = relative_nnls(basis, target)
    r = coef[2:]
    keep = r > 1e-12 * max(r.max(initial=0.0), 1e-300)
    return FosterRL(float(coef[0]), float(coef[1]), r[keep], r[keep] / wk[keep])


# ---------------------------------------------------------------------- insertion
def _series_inductor(circuit: Circuit, element: Element) -> Element | None:
    """The inductor in series with ``element`` through a node that joins only the two of them."""
    for node in element.nodes:
        others = [e for e in circuit.elements if e.kind != "K" and node in e.nodes and e.key != element.key]
        if node != GROUND and len(others) == 1 and others[0].kind == "L":
            return others[0]
    return None


def _is_coupled(circuit: Circuit, element: Element) -> bool:
    return any(element.key in (a.lower(), b.lower()) for a, b in (k.nodes for k in circuit.of_kind("K")))


def replace_with_ladder(circuit: Circuit, name: str, ladder: FosterRL) -> Circuit:
    """A copy of ``circuit`` with element ``name`` replaced by ``ladder`` between the same nodes.

    A resistor or an uncoupled inductor is removed and the chain takes its
    place (elements ``<name>_r0``, ``<name>_l0``, ``<name>_r1``/``<name>_l1`` ...,
    internal nodes ``<name>_n1`` ...); a resistor's series inductance ``l0``
    is added to an uncoupled inductor in series with it, or else kept as its
    own (uncoupled) chain element. A coupled inductor keeps its couplings:
    it stays in the chain with value ``ladder.l0`` and the sections are added
    in series with it (their extra inductance is then uncoupled).

    Raises
    ------
    CircuitError
        Unknown element, a capacitor or coupling, or an element given by an
        expression of other parameters.
    """
    element = circuit.element(name)
    if element.kind not in "RL":
        raise CircuitError(f"element {element.name!r}: only resistors and inductors can be made frequency dependent")
    coupled = element.kind == "L" and _is_coupled(circuit, element)
    prefix = element.name
    series_l = _series_inductor(circuit, element) if element.kind == "R" and ladder.l0 > 0 else None
    if series_l is not None and _is_coupled(circuit, series_l):
        series_l = None  # a coupled winding would take the ladder's inductance into its couplings
    chain: list[tuple[str, float]] = []
    if ladder.r0 > 0:
        chain.append(("R", ladder.r0))
    if ladder.l0 > 0 and not coupled and series_l is None:
        chain.append(("L", ladder.l0))
    sections = list(zip(ladder.r, ladder.l))
    n_series = len(chain) + len(sections) + (1 if coupled else 0)
    if n_series == 0:
        raise CircuitError(f"element {element.name!r}: the ladder is empty")
    a, b = element.nodes
    nodes = [a] + [f"{prefix}_n{i}".lower() for i in range(1, n_series)] + [b]
    out = Circuit(circuit.title, [], list(circuit.parameters), list(circuit.ports), list(circuit.probes), list(circuit.comments))
    for e in circuit.elements:
        if series_l is not None and e.key == series_l.key:
            total = e.value + ladder.l0 if isinstance(e.value, float) else Expression(f"({e.value.text.strip('{}')}) + {ladder.l0!r}")
            out.elements.append(replace(e, value=total))
            continue
        if e.key != element.key:
            out.elements.append(e)
            continue
        pos = 0
        if coupled:
            out.elements.append(replace(e, nodes=(nodes[0], nodes[1]), value=float(ladder.l0)))
            pos = 1
        for kind, value in chain:
            out.add(f"{kind}{prefix}_{kind.lower()}0", nodes[pos], nodes[pos + 1], value)
            pos += 1
        for k, (rk, lk) in enumerate(sections, start=1):
            out.add(f"R{prefix}_r{k}", nodes[pos], nodes[pos + 1], float(rk))
            out.add(f"L{prefix}_l{k}", nodes[pos], nodes[pos + 1], float(lk))
            pos += 1
    return out


# ---------------------------------------------------------------------- transformer effects
@dataclass(frozen=True)
class TransformerEffects:
    """Frequency-dependent winding and core effects of thesis (2.4)-(2.6), as ladder parameters.

    Attributes
    ----------
    skin_a, skin_b, skin_f0 : float, -, -, Hz
        Winding resistance ``R(f) = (R / skin_c) (1 + skin_a (j f / skin_f0)^skin_b)``:
        the causal form of (2.6) (``b = 1/2`` is the classical skin effect).
    skin_c : float
        ``R_linear / c`` of (2.6): the DC resistance is the linear value divided by ``c``.
    core_a_factor, core_b_hz : float, -, Hz
        Core-loss resistance (2.4) ``R_c(f) = a f / (f + b)`` with ``a = core_a_factor * R_c``.
    magnetising_b, magnetising_f_hz : float, -, Hz
        Core-loop inductance (2.5) ``L_c(f) = a f^(-b) L_c`` with ``a = magnetising_f_hz^b``:
        equal to the linear value at ``magnetising_f_hz``, larger below it.
    band_hz : tuple of float, Hz
        Band over which the ladders follow the formulas.
    sections : int
        Parallel R-L sections per ladder.
    """

    skin_a: float = 1.0
    skin_b: float = 0.5
    skin_f0: float = 1e3
    skin_c: float = 2.0
    core_a_factor: float = 2.0
    core_b_hz: float = 200.0
    magnetising_b: float = 0.05
    magnetising_f_hz: float = 1e5
    band_hz: tuple[float, float] = (1.0, 2e5)
    sections: int = 6


def _scaled(ladder: FosterRL, k: float) -> FosterRL:
    """The ladder with every impedance scaled by ``k`` (all R and L times ``k``)."""
    return FosterRL(ladder.r0 * k, ladder.l0 * k, ladder.r * k, ladder.l * k)


#: Unit ladders of the default :class:`TransformerEffects`, as :func:`fit_unit_ladders` computes them
#: (kept with the package so that building the built-in models needs no optimiser at start-up;
#: ``tests/circuits/test_freqdep.py`` checks the file against a fresh fit).
UNIT_LADDERS_FILE = DATA / "unit_ladders.json"


def fit_unit_ladders(effects: "TransformerEffects") -> tuple[FosterRL, FosterRL, FosterRL]:
    """The three ladders of ``effects`` for a unit element (1 Ohm, 1 Ohm, 1 H).

    Every target is proportional to its element's value (skin effect to the DC
    resistance, (2.4) to ``R_c``, the excess of (2.5) to ``L_c``) and the fits
    weight relative errors, so the ladder of any value is the unit ladder
    scaled by it.

    Returns
    -------
    tuple of FosterRL
        Skin-effect impedance, core-loss resistance, excess core-loop inductance.
    """
    e = effects
    fmin, fmax = e.band_hz
    n = e.sections
    skin = fit_impedance(lambda f: 1 + e.skin_a * (1j * f / e.skin_f0) ** e.skin_b, fmin, fmax, n)
    core = fit_resistance(lambda f: core_loss_resistance(f, e.core_a_factor, e.core_b_hz), fmin, fmax, n)
    fh = e.magnetising_f_hz
    excess = fit_inductance(lambda f: (f / fh) ** (-e.magnetising_b) - 1, fmin, fh / 3, n)
    return skin, core, excess


def _ladder_json(lad: FosterRL) -> dict:
    return {"r0": lad.r0, "l0": lad.l0, "r": [float(x) for x in lad.r], "l": [float(x) for x in lad.l]}


def _ladder_from_json(d: dict) -> FosterRL:
    return FosterRL(float(d["r0"]), float(d["l0"]), np.asarray(d["r"], float), np.asarray(d["l"], float))


@lru_cache(maxsize=16)
def unit_ladders(effects: "TransformerEffects") -> tuple[FosterRL, FosterRL, FosterRL]:
    """:func:`fit_unit_ladders`, read from :data:`UNIT_LADDERS_FILE` for the default effects."""
    if effects == TransformerEffects():
        try:
            table = json.loads(UNIT_LADDERS_FILE.read_text())
            if table.get("effects") == asdict(effects) | {"band_hz": list(effects.band_hz)}:
                return tuple(_ladder_from_json(table[k]) for k in ("skin", "core", "excess"))  # type: ignore[return-value]
        except (OSError, ValueError, KeyError, TypeError):
            pass
    return fit_unit_ladders(effects)


def write_unit_ladders(path: Path = UNIT_LADDERS_FILE) -> None:
    """Write the unit ladders of the default effects to ``path`` (JSON)."""
    e = TransformerEffects()
    skin, core, excess = fit_unit_ladders(e)
    table = {"effects": asdict(e) | {"band_hz": list(e.band_hz)}, "skin": _ladder_json(skin),
             "core": _ladder_json(core), "excess": _ladder_json(excess)}
    path.write_text(json.dumps(table, indent=1) + "\n")


def add_transformer_effects(
    circuit: Circuit,
    resistors: list[str],
    core_resistor: str | None = None,
    core_inductor: str | None = None,
    effects: TransformerEffects = TransformerEffects(),
) -> Circuit:
    """A numeric copy of ``circuit`` with (2.4)-(2.6) realised as passive R-L ladders.

    Every named winding resistor gets the skin-effect ladder, the core-loss
    resistor the ladder of (2.4), and the (coupled) core inductor keeps its
    value and couplings with the frequency-dependent excess of (2.5) in series.

    Parameters
    ----------
    circuit : Circuit
    resistors : list of str
        Winding resistors (Ohm).
    core_resistor, core_inductor : str, optional
        Core-loss resistor and core-loop inductor.
    effects : TransformerEffects

    Returns
    -------
    Circuit
        Element values are numbers (parameters resolved first).
    """
    values = circuit.resolve()
    out = circuit.with_values({e.name: values[e.key] for e in circuit.elements})
    skin, core, excess = unit_ladders(effects)
    for name in resistors:
        out = replace_with_ladder(out, name, _scaled(skin, float(values[name.lower()]) / effects.skin_c))
    if core_resistor is not None:
        out = replace_with_ladder(out, core_resistor, _scaled(core, float(values[core_resistor.lower()])))
    if core_inductor is not None:
        lc = float(values[core_inductor.lower()])
        ex = _scaled(excess, lc)
        out = replace_with_ladder(out, core_inductor, FosterRL(0.0, lc + ex.l0, ex.r, ex.l))
    return out
