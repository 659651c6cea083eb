"""A small reference nodal solver, independent of the package: hidden effects for the diagnosis tests.

Written from scratch on purpose (it shares no code with ``pris_cosim`` or
the diagnosis catalogue): its own netlist reader, its own modified nodal
analysis solved densely at every frequency, element values that may be any
function of frequency (a resistance, inductance or capacitance, complex
allowed), and its own SPICE writer so that ngspice can check it.

Unknowns: node voltages and inductor currents. For a unit current injected
at ``port`` the system per frequency is::

    [ Y_RC(w)      A_L ] [v]   [e_port]
    [ -A_L^T   j w M(w)] [i] = [  0   ]

with ``M_ij = k_ij sqrt(L_i L_j)``.
"""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

Value = float | Callable[[np.ndarray], np.ndarray]
_SUFFIX = {"f": 1e-15, "p": 1e-12, "n": 1e-9, "u": 1e-6, "m": 1e-3, "k": 1e3, "meg": 1e6, "g": 1e9, "t": 1e12}


def number(text: str, params: dict[str, float] | None = None) -> float:
    """A SPICE number (``4.7k``, ``10nF``, ``1meg``) or a ``{expression}`` of ``params``."""
    t = text.strip()
    if t.startswith("{"):
        return float(eval(t[1:-1], {"__builtins__": {}, "sqrt": math.sqrt}, dict(params or {})))
    m = re.fullmatch(r"([-+]?[0-9.]+(?:e[-+]?\d+)?)(meg|[fpnumkgt])?[a-z]*", t.lower())
    if not m:
        raise ValueError(f"not a number: {text!r}")
    return float(m.group(1)) * _SUFFIX.get(m.group(2) or "", 1.0)


@dataclass
class Net:
    """Elements ``(name, a, b, value)``; for ``K`` the two inductor names and the coefficient."""

    elements: list[list] = field(default_factory=list)

    def add(self, name: str, a: str, b: str, value: Value) -> None:
        self.elements.append([name, a.lower(), b.lower(), value])

    def get(self, name: str) -> list:
        for e in self.elements:
            if e[0].lower() == name.lower():
                return e
        raise KeyError(name)

    def set(self, name: str, value: Value) -> None:
        self.get(name)[3] = value

    def copy(self) -> "Net":
        return Net([list(e) for e in self.elements])

    def names(self, kind: str) -> list[str]:
        return [e[0] for e in self.elements if e[0][0].upper() == kind]


def parse(text: str) -> Net:
    """R, L, C, K lines and ``.param`` of a netlist (other lines skipped)."""
    net, params = Net(), {}
    for raw in text.splitlines():
        line = raw.split(";")[0].strip()
        if not line or line.startswith("*"):
            continue
        if line.lower().startswith(".param"):
            for name, val in re.findall(r"(\w+)\s*=\s*(\{[^}]*\}|\S+)", line[6:]):
                params[name.lower()] = number(val, params)
            continue
        if line.startswith("."):
            continue
        w = line.split()
        if w[0][0].upper() in "RLCK":
            val = w[3]
            if val.startswith("{"):
                val = "{" + val[1:-1].lower() + "}"
            net.add(w[0], w[1], w[2], number(val, params))
    return net


def _value(v: Value, f: np.ndarray) -> np.ndarray:
    return np.broadcast_to(np.asarray(v(f) if callable(v) else v, complex), f.shape)


def node_voltages(net: Net, port: str, f: np.ndarray, shorts: Sequence[str] = ()) -> dict[str, np.ndarray]:
    """Node voltages (V per A) for a unit current into ``port``; ``shorts`` are tied to ground."""
    f = np.asarray(f, float)
    short = {s.lower() for s in shorts} | {"0"}
    nodes = sorted({n for e in net.elements if e[0][0].upper() != "K" for n in e[1:3]} - short)
    idx = {n: i for i, n in enumerate(nodes)}
    inductors = [e for e in net.elements if e[0][0].upper() == "L"]
    lidx = {e[0].lower(): j for j, e in enumerate(inductors)}
    N, m = len(nodes), len(inductors)
    w = 2 * np.pi * f
    K = np.zeros((f.size, N + m, N + m), complex)

    def stamp(a, b, y):
        ia, ib = idx.get(a), idx.get(b)
        if ia is not None:
            K[:, ia, ia] += y
        if ib is not None:
            K[:, ib, ib] += y
        if ia is not None and ib is not None:
            K[:, ia, ib] -= y
            K[:, ib, ia] -= y

    for name, a, b, v in net.elements:
        kind = name[0].upper()
        if kind == "R":
            stamp(a, b, 1 / _value(v, f))
        elif kind == "C":
            stamp(a, b, 1j * w * _value(v, f))
    lv = [_value(e[3], f) for e in inductors]
    M = np.zeros((f.size, m, m), complex)
    for j in range(m):
        M[:, j, j] = lv[j]
    for name, a, b, v in net.elements:
        if name[0].upper() == "K":
            i, j = lidx[a.lower()], lidx[b.lower()]
            M[:, i, j] = M[:, j, i] = _value(v, f) * np.sqrt(lv[i] * lv[j])
    for j, e in enumerate(inductors):
        a, b = e[1], e[2]
        if a in idx:
            K[:, idx[a], N + j] += 1
            K[:, N + j, idx[a]] -= 1
        if b in idx:
            K[:, idx[b], N + j] -= 1
            K[:, N + j, idx[b]] += 1
    K[:, N:, N:] = 1j * w[:, None, None] * M
    rhs = np.zeros((f.size, N + m, 1), complex)
    rhs[:, idx[port.lower()], 0] = 1.0
    x = np.linalg.solve(K, rhs)[:, :, 0]
    out = {n: x[:, i] for n, i in idx.items()}
    for s in short:
        out[s] = np.zeros(f.size, complex)
    return out


def impedance(net: Net, port: str, f: np.ndarray, shorts: Sequence[str] = ()) -> np.ndarray:
    """Driving-point impedance at ``port``, Ohm."""
    return node_voltages(net, port, f, shorts)[port.lower()]


def two_winding_responses(net: Net, f: np.ndarray, lv: str = "a1", hv: str = "b1") -> dict[str, np.ndarray]:
    """The six responses of thesis 5.1.2-5.1.3 (LVOC ... HVLV)."""
    a = node_voltages(net, lv, f)
    b = node_voltages(net, hv, f)
    return {"Zlvoc": a[lv], "Zlvsc": impedance(net, lv, f, [hv]), "Zhvoc": b[hv], "Zhvsc": impedance(net, hv, f, [lv]),
            "Rlvhv": a[hv] / a[lv], "Rhvlv": b[lv] / b[hv]}


def to_spice(net: Net, title: str = "reference network") -> str:
    """The network (constant values only) as SPICE text."""
    lines = [f"* {title}"]
    for name, a, b, v in net.elements:
        if callable(v):
            raise ValueError(f"{name}: frequency-dependent values have no SPICE form here")
        lines.append(f"{name} {a} {b} {float(np.real(v))!r}")
    return "\n".join(lines) + "\n"


def ngspice_impedance(net: Net, port: str, fmin: float, fmax: float, per_decade: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """``(f, Z)`` from ngspice's AC analysis of :func:`to_spice` (1 A injected at ``port``)."""
    exe = shutil.which("ngspice")
    if exe is None:
        raise FileNotFoundError("ngspice")
    deck = (to_spice(net) + f"Iprobe 0 {port} DC 0 AC 1\n.control\nset wr_singlescale\noption numdgt=16\n"
            f"ac dec {per_decade} {fmin!r} {fmax!r}\nwrdata out.txt v({port})\n.endc\n.end\n")
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "deck.cir").write_text(deck)
        subprocess.run([exe, "-b", "deck.cir"], cwd=tmp, capture_output=True, timeout=120, check=False)
        data = np.loadtxt(Path(tmp) / "out.txt", ndmin=2)
    return data[:, 0], data[:, 1] + 1j * data[:, 2]
