"""Drift as reported: a whole group moved together, and values the data cannot place.

Every capacitance to ground of a winding at twice its design is one drift,
not a cause. Those data come from a small nodal solver written here (node
voltages and inductor currents of a coupled R-L-C cascade), which shares
nothing with the diagnosis.

A network with two identical branches from the port, each ending in a
capacitance to ground: by symmetry, the impedance at the port is the same
whichever of the two capacitances changed, so no diagnosis can tell them
apart, and a report that names only one of them claims more than the data
hold. Those data come from the independent reference nodal solver
(``refsolver``).
"""

import numpy as np
import pytest

from estimation.diagnosis import diagnose_frequency
from estimation.diagnosis.group_drift import value_groups
from estimation.diagnosis.report import write_report
from estimation.diagnosis.prior import design_prior
from pris_cosim.circuits.netlist import parse_netlist

import refsolver as ref

R = np.array([0.4, 0.5, 0.45])
L = np.array([3e-3, 2.5e-3, 3.5e-3])
CS = np.array([0.8e-9, 1.1e-9, 0.9e-9])
CG = np.array([0.6e-9, 1.0e-9, 1.2e-9])
RHO = 0.7


def _zin(f, R, L, Cs, Cg, rho):
    n = R.size
    K = rho ** np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    Lm = K * np.sqrt(np.outer(L, L))
    A = np.eye(n) - np.eye(n, k=-1)  # branch i from node i to node i+1 (ground past the last)
    out = []
    for fk in f:
        s = 2j * np.pi * fk
        Y = np.diag(s * Cg).astype(complex)
        for i in range(n):
            Y[i, i] += s * Cs[i]
            if i + 1 < n:
                Y[i + 1, i + 1] += s * Cs[i]
                Y[i, i + 1] -= s * Cs[i]
                Y[i + 1, i] -= s * Cs[i]
        M = np.block([[Y, A], [A.T, -(np.diag(R) + s * Lm)]])
        rhs = np.zeros(2 * n, complex)
        rhs[0] = 1
        out.append(np.linalg.solve(M, rhs)[0])
    return np.array(out)


def _netlist(R, L, Cs, Cg, rho):
    n = R.size
    node = lambda i: "0" if i >= n else f"n{i + 1}"  # noqa: E731
    lines = ["* design"]
    for i in range(n):
        lines += [f"R{i + 1} {node(i)} x{i + 1} {R[i]}", f"L{i + 1} x{i + 1} {node(i + 1)} {L[i]}",
                  f"C{i + 1} {node(i)} {node(i + 1)} {Cs[i]}", f"Cg{i + 1} {node(i)} 0 {Cg[i]}"]
    lines += [f"K{i + 1}{j + 1} L{i + 1} L{j + 1} {rho ** (j - i)}" for i in range(n) for j in range(i + 1, n)]
    return parse_netlist("\n".join(lines) + "\n")


def test_groups_by_role():
    net = _netlist(R, L, CS, CG, RHO)
    prior = design_prior({e.name: float(e.value) for e in net.elements if e.kind in "RLC"}, 0.2, 1e-5, 100, 1, net)
    groups = value_groups(prior, net, ["n1"])
    # C3 ends at ground beside Cg3: one value to the data, in the group of the capacitances to ground
    assert groups == {"Cg": ["Cg1", "Cg2", "C3", "Cg3"], "L": ["L1", "L2", "L3"], "R": ["R1", "R2", "R3"]}


@pytest.mark.slow
@pytest.mark.parametrize("factor", [2.0, 1.5])
def test_all_ground_capacitances_scaled_are_one_group_drift(factor):
    rng = np.random.default_rng(3)
    f = np.logspace(3, 6.5, 300)
    truth = [v * rng.uniform(0.93, 1.07, v.size) for v in (R, L, CS, CG)]
    z = _zin(f, truth[0], truth[1], truth[2], truth[3] * factor, RHO)
    z = z * np.exp(0.003 / np.sqrt(2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
    d = diagnose_frequency(f, {"Zin": z}, circuit=_netlist(R, L, CS, CG, RHO), port="n1", progress=False)
    assert d.causes == [], (d.cause, d.candidates())
    group = [x for x in d.drift if x.get("group")]
    assert group and group[0]["members"] == ["Cg1", "Cg2", "C3", "Cg3"] and group[0]["in_parallel"] == ["C3", "Cg3"]
    # the factor from the members without a parallel partner (C3 and Cg3 are one value to the data)
    assert abs(np.log(group[0]["ratio"] / factor)) < 0.1, d.drift
    assert not [x for x in d.drift if not x.get("group")], d.drift
    assert d.explained


BRANCHES = """* two identical branches from the port n1
R1 n1 a 2
L1 a n2 2m
R2 n1 b 2
L2 b n3 2m
C1 n1 n2 100p
C2 n1 n3 100p
Cg1 n1 0 200p
Cg2 n2 0 1n
Cg3 n3 0 1n
Rd2 n2 0 20k
Rd3 n3 0 20k
.end
"""


@pytest.mark.parametrize("ratio", [1.45, pytest.param(2.0, marks=pytest.mark.slow)])
def test_symmetric_capacitances_both_named(ratio, tmp_path):
    """Cg3 at ``ratio`` times its design (1.45: just beyond a 20 % tolerance; 2: far beyond), 0.5 % noise: the drift
    names one of Cg2 and Cg3 near ``ratio`` and the other as an alternative that fits as well."""
    f = np.geomspace(1e3, 2e6, 400)
    truth = ref.parse(BRANCHES)
    truth.set("Cg3", ratio * 1e-9)
    rng = np.random.default_rng(7)
    z = ref.impedance(truth, "n1", f) * np.exp(0.005 * (rng.standard_normal(f.size)
                                                        + 1j * rng.standard_normal(f.size)) / np.sqrt(2))
    d = diagnose_frequency(f, {"Zin": z}, circuit=parse_netlist(BRANCHES), port="n1", progress=False,
                           tolerance=0.2)
    assert d.causes == [], d.candidates()
    assert [x["name"] for x in d.drift] in (["Cg2"], ["Cg3"]), d.drift
    assert d.drift[0]["ratio"] == pytest.approx(ratio, rel=0.05)
    other = {"Cg2": "Cg3", "Cg3": "Cg2"}[d.drift[0]["name"]]
    alt = {a["name"]: a for a in d.drift_alternatives}
    assert other in alt, d.drift_alternatives
    assert alt[other]["ratio"] == pytest.approx(ratio, rel=0.05)
    assert abs(alt[other]["delta_bic"]) < 1.0  # exactly alike up to the fits' convergence
    text = write_report(d, tmp_path / "report").read_text()
    assert other in text.split("explained as well by")[1].split("\n")[0]
