"""Hidden-effect cases for the diagnosis, made without any of the diagnosis's code.

Networks are built and solved by :mod:`refsolver`; the hidden effects are
written in forms and parametrisations other than the catalogue's:

- skin effect: the exact internal impedance of a round wire
  ``Z/R_dc = (x/2) J0(x)/J1(x)``, ``x = (1 - j) sqrt(f / f_s)`` (causal), or
  a real-valued rise ``R_dc sqrt(1 + f / f_s)``, or thesis (2.6) written with
  its own scale, ``R_dc [1 + ((f - f_1) / f_2)^b]`` above ``f_1``;
- core loss: ``R_hf / (1 + f_b / f)`` (thesis (2.4) rearranged) or an
  eddy-current lamination ``R_hf sqrt(j f/f_e) tanh(sqrt(j f/f_e))`` ...;
- magnetising inductance: a Cole-Cole permeability
  ``r + (1 - r) / (1 + (j f / f_m)^alpha)`` (causal) or ``(f / f_r)^-beta``
  (thesis (2.5) rearranged) on the winding inductances;
- missing section: the true winding has one more section than the baseline
  (one-port: two adjacent sections of the truth merged in the baseline;
  two-winding: one section of the truth split in two).

Noise: magnitude and phase perturbed independently, ``|H| (1 + s n_1)``,
``arg H + s n_2``. Every case keeps the truth.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
from scipy.special import jv

import refsolver as rs

SINGLE = ("none", "skin-effect", "core-loss", "magnetising-inductance", "missing-section")
COMPOUND = (("skin-effect", "core-loss"), ("skin-effect", "magnetising-inductance"),
            ("skin-effect", "missing-section"), ("core-loss", "magnetising-inductance"),
            ("core-loss", "missing-section"), ("magnetising-inductance", "missing-section"))

_TABLE_5_4 = """
Ra1 a1 xa 117.3m
La1 xa 0 255.7m
Ca10 a1 0 177.9p
Rb1 b1 y1 4.475k
Lb1 y1 b2 879
Cb1 b1 b2 199.7p
Rb2 b2 y2 4.475k
Lb2 y2 b3 904.6
Cb2 b2 b3 143.4p
Rb3 b3 y3 4.475k
Lb3 y3 b4 2916
Cb3 b3 b4 441.4p
Rb4 b4 y4 4.475k
Lb4 y4 0 3972
Cb4 b4 0 188.2p
Cb12 b1 b3 604.7p
Cb34 b3 0 95.67p
Cb10 b1 0 85.25p
Cab1 a1 b3 54.7p
Lc c 0 308.6
Rc c 0 73.29k
K1 La1 Lb1 0.9947
K2 La1 Lb2 0.9969
K3 La1 Lb3 0.9989
K4 La1 Lb4 0.9981
K5 Lb1 Lb2 0.9943
K6 Lb1 Lb3 0.9952
K7 Lb1 Lb4 0.9985
K8 Lb2 Lb3 0.9981
K9 Lb2 Lb4 0.9976
K10 Lb3 Lb4 0.9983
K11 La1 Lc 0.9924
K12 Lb1 Lc 0.9921
K13 Lb2 Lc 0.9933
K14 Lb3 Lc 0.9943
K15 Lb4 Lc 0.9939
"""


@dataclass
class HiddenCase:
    """Measured-like responses with known hidden causes."""

    kind: str
    causes: tuple[str, ...]
    seed: int
    noise: float
    frequency_hz: np.ndarray
    measured: dict[str, np.ndarray]
    baseline_netlist: str = ""
    port: str = ""
    baseline_model: str = ""
    truth: dict = field(default_factory=dict)
    #: Networks kept for labelling (:mod:`detectability`): ``truth`` (with its frequency-dependent effects),
    #: ``sections`` (the truth's sections without them), ``baseline`` and ``merged`` (the baseline before and
    #: without its jitter); one-port and design cases: ``only:CAUSE``, the sections with that one effect.
    nets: dict = field(default_factory=dict, repr=False)

    @property
    def label(self) -> str:
        return "+".join(self.causes) if self.causes else "none"


# ------------------------------------------------------------------------------------------------ effects
def skin_factor(kind: str, f_s: float, extra: float = 0.5) -> callable:
    """``R(f) / R_dc`` of a hidden skin effect."""
    if kind == "bessel":
        def g(f):
            x = (1 - 1j) * np.sqrt(np.asarray(f) / f_s)
            small = np.abs(x) < 1e-3
            out = np.where(small, 1.0 + 0j, (x / 2) * jv(0, x) / np.where(small, 1, jv(1, x)))
            return out
        return g
    if kind == "sqrt":
        return lambda f: np.sqrt(1 + np.asarray(f) / f_s) + 0j
    if kind == "thesis":  # (2.6) with its own scale: R_dc [1 + ((f - f1)/f2)^b] above f1
        f1 = f_s / 20
        return lambda f: 1 + np.clip((np.asarray(f) - f1) / f_s, 0, None) ** extra + 0j
    raise ValueError(kind)


def core_resistance(kind: str, r_hf: float, f_b: float) -> callable:
    if kind == "real":
        return lambda f: r_hf / (1 + f_b / np.asarray(f)) + 0j
    if kind == "eddy":  # lamination eddy currents: R_hf * q tanh(q) / (1 + q tanh(q)), q = sqrt(j f / f_b)
        def g(f):
            q = np.sqrt(1j * np.asarray(f) / f_b)
            t = q * np.tanh(q)
            return r_hf * t / (1 + t)
        return g
    raise ValueError(kind)


def permeability(kind: str, f_m: float, beta: float) -> callable:
    """``L(f) / L_dc``: a Cole-Cole relaxation (``relax``) or thesis (2.5) rearranged (``power``)."""
    if kind == "relax":  # mu_inf/mu_s = 1 - 4 beta, spread alpha from the decade of f_m
        ratio = 1 - 4 * beta
        alpha = 0.6 + 0.3 * (np.log10(f_m) % 1)
        return lambda f: ratio + (1 - ratio) / (1 + (1j * np.asarray(f) / f_m) ** alpha)
    if kind == "power":
        return lambda f: (np.asarray(f) / f_m) ** (-beta) + 0j
    raise ValueError(kind)


def _scaled(v, g):
    return lambda f, v=v: v * g(f)


def _noisy(z: np.ndarray, s: float, rng: np.random.Generator) -> np.ndarray:
    return np.abs(z) * (1 + s * rng.standard_normal(z.size)) * np.exp(1j * (np.angle(z) + s * rng.standard_normal(z.size)))


# ------------------------------------------------------------------------------------------------ one-port
def _cascade(R, L, C, Cg, k) -> rs.Net:
    n = len(R)
    net = rs.Net()
    nodes = [f"n{i}" for i in range(1, n + 1)] + ["0"]
    for i in range(n):
        net.add(f"R{i + 1}", nodes[i], f"x{i + 1}", R[i])
        net.add(f"L{i + 1}", f"x{i + 1}", nodes[i + 1], L[i])
        net.add(f"C{i + 1}", nodes[i], nodes[i + 1], C[i])
        net.add(f"Cg{i + 1}", nodes[i], "0", Cg[i])
    for i, j in itertools.combinations(range(n), 2):
        net.add(f"K{i + 1}_{j + 1}", f"L{i + 1}", f"L{j + 1}", float(k[i, j]))
    return net


def _couplings(n: int, k0: float, length: float) -> np.ndarray:
    d = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    k = k0 * np.exp(-(d - 1) / length)
    np.fill_diagonal(k, 1.0)
    while np.linalg.eigvalsh(k).min() <= 1e-3:
        k = np.where(d > 0, k * 0.95, 1.0)
    return k


def one_port_case(causes: tuple[str, ...] | str, seed: int, noise: float = 0.003, sections: int | None = None,
                  points: int = 200) -> HiddenCase:
    """A winding cascade given as a netlist baseline (section counts 2-7) with hidden causes.

    1 kHz - 10 MHz; the baseline netlist's values are the truth's within 15 %.
    """
    causes = tuple(sorted(c for c in ((causes,) if isinstance(causes, str) else causes) if c != "none"))
    rng = np.random.default_rng([seed, 11] + [SINGLE.index(c) for c in causes])
    n = int(sections or rng.choice([2, 3, 5, 6, 7]))
    f = np.logspace(3, 7, points)
    missing = "missing-section" in causes
    nt = n + 1 if missing else n
    R = list(2.0 * rng.uniform(0.6, 1.5, nt) * 3 / nt)
    L = list(181e-6 * rng.uniform(0.7, 1.4, nt) * 3 / nt)
    C = list(970e-12 * rng.uniform(0.7, 1.4, nt) * nt / 3)
    Cg = list(1.6e-9 * rng.uniform(0.7, 1.4, nt) / nt * 3)
    k = _couplings(nt, rng.uniform(0.55, 0.8), rng.uniform(1.5, 4.0))
    truth_net = _cascade(R, L, C, Cg, k)
    nets = {"sections": truth_net.copy()}
    truth: dict = {"sections": nt}
    if missing:  # the baseline merges two adjacent sections of the truth
        j = int(rng.integers(0, n))
        M = k[j, j + 1] * np.sqrt(L[j] * L[j + 1])
        Rb = R[:j] + [R[j] + R[j + 1]] + R[j + 2:]
        Lb = L[:j] + [L[j] + L[j + 1] + 2 * M] + L[j + 2:]
        Cb = C[:j] + [C[j] * C[j + 1] / (C[j] + C[j + 1])] + C[j + 2:]
        Cgb = Cg[:j + 1] + Cg[j + 2:]
        kb = np.delete(np.delete(k, j + 1, 0), j + 1, 1)
        truth["merged_sections"] = (j + 1, j + 2)
    else:
        Rb, Lb, Cb, Cgb, kb = R, L, C, Cg, k
    jit = lambda v: [x * rng.uniform(0.85, 1.15) for x in v]  # noqa: E731
    nets["merged"] = _cascade(Rb, Lb, Cb, Cgb, kb)
    base_net = _cascade(jit(Rb), jit(Lb), jit(Cb), jit(Cgb), kb)
    nets["baseline"] = base_net.copy()
    _alone(nets, _one_port_effects(truth_net, causes, rng, f, truth))
    nets["truth"] = truth_net
    z = rs.impedance(truth_net, "n1", f)
    return HiddenCase("one-port", causes, seed, noise, f, {"Zin": _noisy(z, noise, rng)},
                      baseline_netlist=rs.to_spice(base_net, f"{n}-section cascade (baseline)"), port="n1", truth=truth,
                      nets=nets)


def _one_port_effects(truth_net: rs.Net, causes: tuple[str, ...], rng: np.random.Generator, f: np.ndarray,
                      truth: dict) -> dict[str, callable]:
    """Skin effect, magnetising change and core loss written into a cascade (in place).

    Returns each cause's writing (a function of a net), so that one effect
    can be written alone into another net with the same parameters.
    """
    write: dict[str, callable] = {}
    if "skin-effect" in causes:
        kind = str(rng.choice(["bessel", "sqrt", "thesis"]))
        f_s = float(10 ** rng.uniform(4.0, 5.0))
        extra = float(rng.uniform(0.4, 0.8))
        g = skin_factor(kind, f_s, extra)

        def skin(net: rs.Net, g=g) -> None:
            for name in net.names("R"):
                net.set(name, _scaled(net.get(name)[3], g))
        write["skin-effect"] = skin
        truth["skin"] = {"kind": kind, "f_s": f_s, "extra": extra}
    if "magnetising-inductance" in causes:
        kind = str(rng.choice(["relax", "power"]))
        beta = float(rng.uniform(0.04, 0.12))
        f_m = float(10 ** rng.uniform(4, 6)) if kind == "relax" else 1e3
        g = permeability(kind, f_m, beta)

        def magnetising(net: rs.Net, g=g) -> None:
            for name in net.names("L"):
                net.set(name, _scaled(net.get(name)[3], g))
        write["magnetising-inductance"] = magnetising
        truth["magnetising"] = {"kind": kind, "f_m": f_m, "beta": beta}
    for cause in ("skin-effect", "magnetising-inductance"):
        if cause in write:
            write[cause](truth_net)
    if "core-loss" in causes:
        kind = str(rng.choice(["real", "eddy"]))
        zmax = float(np.max(np.abs(rs.impedance(truth_net, "n1", f))))
        r_hf = zmax * 10 ** rng.uniform(-0.3, 0.3)
        f_b = float(10 ** rng.uniform(4.5, 6))
        rc = core_resistance(kind, r_hf, f_b)
        write["core-loss"] = lambda net, rc=rc: net.add("Rcore_hidden", "n1", "0", rc)
        write["core-loss"](truth_net)
        truth["core"] = {"kind": kind, "r_hf": r_hf, "f_b": f_b}
    return write


def _alone(nets: dict, write: dict[str, callable]) -> None:
    """``nets["only:CAUSE"]``: the truth's sections with that one hidden effect (its parameters as in the truth)."""
    for cause, w in write.items():
        net = nets["sections"].copy()
        w(net)
        nets[f"only:{cause}"] = net


DESIGN_SPREAD = 0.10  # the truth's values are the design's within 10 %


def design_case(causes: tuple[str, ...] | str, seed: int, noise: float = 0.003, drift: bool = False,
                points: int = 200, draw: int = 0) -> HiddenCase:
    """A winding built to a design: the baseline netlist is the design, the truth its values within 10 %.

    A 4- to 6-section cascade (1 kHz - 10 MHz); with a missing section the
    winding has one section more, two of which the design merges. With ``drift`` one
    capacitance of the truth is at twice its design value (a value off the
    design, not a catalogue cause: ``truth["drift"]`` names it). Hidden
    effects as in :func:`one_port_case`. ``draw`` > 0 makes another,
    independent draw for the same seed (a benchmark replaces a draw whose
    hidden effect the reference solver finds invisible at the noise:
    :mod:`detectability`); ``truth["draw"]`` records it.
    """
    causes = tuple(sorted(c for c in ((causes,) if isinstance(causes, str) else causes) if c != "none"))
    entropy = [seed, 33, int(drift)] + [SINGLE.index(c) for c in causes] + ([1000 + draw] if draw else [])
    rng = np.random.default_rng(entropy)
    n = int(rng.choice([4, 5, 6]))
    f = np.logspace(3, 7, points)
    missing = "missing-section" in causes
    nt = n + 1 if missing else n  # with a missing section the winding has one section more than its design
    R = list(1.5 * rng.uniform(0.7, 1.4, nt) * 4 / nt)
    L = list(2.5e-3 * rng.uniform(0.8, 1.3, nt) * 4 / nt)
    C = list(0.8e-9 * rng.uniform(0.8, 1.3, nt) * nt / 4)
    Cg = list(0.9e-9 * rng.uniform(0.8, 1.3, nt) * 4 / nt)
    k = _couplings(nt, rng.uniform(0.6, 0.8), rng.uniform(1.5, 4.0))
    truth: dict = {"sections": nt, "spread": DESIGN_SPREAD, **({"draw": draw} if draw else {})}
    if missing:  # the design merges two adjacent sections of the winding (series R and L, series C, one Cg)
        j = int(rng.integers(0, n))
        M = k[j, j + 1] * np.sqrt(L[j] * L[j + 1])
        design = _cascade(R[:j] + [R[j] + R[j + 1]] + R[j + 2:], L[:j] + [L[j] + L[j + 1] + 2 * M] + L[j + 2:],
                          C[:j] + [C[j] * C[j + 1] / (C[j] + C[j + 1])] + C[j + 2:], Cg[:j + 1] + Cg[j + 2:],
                          np.delete(np.delete(k, j + 1, 0), j + 1, 1))
        truth["merged_sections"] = (j + 1, j + 2)
    else:
        design = _cascade(R, L, C, Cg, k)
    jit = lambda v: [x * rng.uniform(1 - DESIGN_SPREAD, 1 + DESIGN_SPREAD) for x in v]  # noqa: E731
    Rt, Lt, Ct, Cgt = jit(R), jit(L), jit(C), jit(Cg)
    if drift:
        j = int(rng.integers(0, n))
        Ct[j] = 2 * C[j]
        truth["drift"] = [f"C{j + 1}"]  # (with a missing section, the name of the winding's section)
    truth_net = _cascade(Rt, Lt, Ct, Cgt, k)
    nets = {"baseline": design.copy(), "merged": design.copy(), "sections": truth_net.copy()}
    _alone(nets, _one_port_effects(truth_net, causes, rng, f, truth))
    nets["truth"] = truth_net
    z = rs.impedance(truth_net, "n1", f)
    return HiddenCase("design", causes, seed, noise, f, {"Zin": _noisy(z, noise, rng)},
                      baseline_netlist=rs.to_spice(design, f"{n}-section cascade (design)"), port="n1", truth=truth,
                      nets=nets)


# ------------------------------------------------------------------------------------------------ two-winding
def _split(net: rs.Net, r: str, l: str, c: str | None, a: str, b: str, k_in: float, shunt: float) -> None:
    """Split section (r, l, c) between nodes a, b into two halves (own construction)."""
    R, L = net.get(r)[3], net.get(l)[3]
    h = 1 / (2 * (1 + k_in))
    mid = f"m_{l.lower()}"
    net.set(r, R / 2)
    net.set(l, L * h)
    net.get(l)[2] = mid
    net.add(r + "h", mid, f"x_{mid}", R / 2)
    net.add(l + "h", f"x_{mid}", b, L * h)
    if c is not None:
        C = net.get(c)[3]
        net.set(c, 2 * C)
        net.get(c)[2] = mid
        net.add(c + "h", mid, b, 2 * C)
    net.add("Cg_" + mid, mid, "0", shunt)
    scale = np.sqrt((1 + k_in) / 2) * 0.999
    for e in list(net.elements):
        if e[0][0].upper() == "K" and l.lower() in (e[1].lower(), e[2].lower()):
            e[3] = e[3] * scale
            other = e[2] if e[1].lower() == l.lower() else e[1]
            net.add(e[0] + "h", l + "h", other, e[3])
    net.add("K_" + mid, l, l + "h", k_in)


def two_winding_case(causes: tuple[str, ...] | str, seed: int, noise: float = 0.003, group: str | None = None,
                     points: int = 150) -> HiddenCase:
    """The thesis's 4-section two-winding transformer (Table 5.4, values within 10 %) with hidden causes.

    Six responses, 10 Hz - 10 kHz; ``group`` (``lv``, ``hv``, ``all``) says
    which winding carries a skin effect or a magnetising change.
    """
    causes = tuple(sorted(c for c in ((causes,) if isinstance(causes, str) else causes) if c != "none"))
    rng = np.random.default_rng([seed, 22] + [SINGLE.index(c) for c in causes])
    f = np.logspace(1, 4, points)
    net = rs.parse(_TABLE_5_4)
    rb = rng.uniform(0.9, 1.1)
    for e in net.elements:
        kind = e[0][0].upper()
        if kind == "R":
            e[3] *= rb if e[0].lower().startswith("rb") else rng.uniform(0.9, 1.1)
        elif kind in "LC":
            e[3] *= rng.uniform(0.9, 1.1)
    group = group or str(rng.choice(["all", "lv", "hv"]))
    truth: dict = {"group": group}
    nets = {"baseline": net.copy(), "merged": net.copy()}
    lv_r, hv_r = ["Ra1"], ["Rb1", "Rb2", "Rb3", "Rb4"]
    lv_l, hv_l = ["La1"], ["Lb1", "Lb2", "Lb3", "Lb4"]
    pick = {"lv": (lv_r, lv_l), "hv": (hv_r, hv_l), "all": (lv_r + hv_r, lv_l + hv_l)}[group]
    if "missing-section" in causes:
        j = int(rng.integers(1, 5))
        nodes = ["b1", "b2", "b3", "b4", "0"]
        _split(net, f"Rb{j}", f"Lb{j}", f"Cb{j}" if j < 4 else None, nodes[j - 1], nodes[j], float(rng.uniform(0.995, 0.999)),
               float(rng.uniform(50e-12, 300e-12)))
        truth["split_hv_section"] = j
        if group != "all":
            pick = (pick[0] + ([f"Rb{j}h"] if group == "hv" else []), pick[1] + ([f"Lb{j}h"] if group == "hv" else []))
        else:
            pick = (pick[0] + [f"Rb{j}h"], pick[1] + [f"Lb{j}h"])
    nets["sections"] = net.copy()
    if "skin-effect" in causes:
        kind = str(rng.choice(["bessel", "sqrt", "thesis"]))
        f_s = float(10 ** rng.uniform(1.5, 2.5))
        g = skin_factor(kind, f_s, float(rng.uniform(0.4, 0.8)))
        for name in pick[0]:
            net.set(name, _scaled(net.get(name)[3], g))
        truth["skin"] = {"kind": kind, "f_s": f_s}
    if "magnetising-inductance" in causes:
        kind = str(rng.choice(["relax", "power"]))
        beta = float(rng.uniform(0.02, 0.06))
        f_m = float(10 ** rng.uniform(2, 3.5)) if kind == "relax" else 100.0
        g = permeability(kind, f_m, beta)
        for name in pick[1]:
            net.set(name, _scaled(net.get(name)[3], g))
        truth["magnetising"] = {"kind": kind, "f_m": f_m, "beta": beta}
    if "core-loss" in causes:
        kind = str(rng.choice(["real", "eddy"]))
        rc = net.get("Rc")[3]
        r_hf = rc * rng.uniform(1.5, 3.0)
        f_b = float(10 ** rng.uniform(1.5, 2.7))
        net.set("Rc", core_resistance(kind, r_hf, f_b))
        truth["core"] = {"kind": kind, "r_hf": r_hf, "f_b": f_b}
    nets["truth"] = net
    data = rs.two_winding_responses(net, f)
    return HiddenCase("two-winding", causes, seed, noise, f, {k: _noisy(v, noise, rng) for k, v in data.items()},
                      baseline_model="hv-4section", truth=truth, nets=nets)
