"""Couplings freed by a missing section (closed forms)."""

import numpy as np

from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.causes.sections import coupling_decay, find_chains, split_section
from pris_cosim.models.builtin import get_model


def _fit(model, couplings=(), effects=()):
    f = np.logspace(1, 4, 120)
    cfg = list(model.configurations.values())
    return FrequencyFit(model.circuit, cfg, f, {"Zlvoc": np.ones(f.size, complex)}, effects=effects,
                        couplings=couplings)


def test_freed_coupling_is_fitted_in_log_leakage_and_stays_in_0_1():
    model = get_model("hv-4section")
    fit = _fit(model, couplings=["Kb1b2", "Kb2b3"])
    assert fit.free[-2:] == ["Kb1b2", "Kb2b3"] and fit.nc == len(fit.free)
    k0 = np.array([0.9943, 0.9981])  # Table 5.4
    x = np.zeros(fit.nc)
    x[-2:] = [np.log(2.0), -np.log(4.0)]  # leakage doubled, quartered
    v = fit.overrides(x)
    assert np.isclose(v["Kb1b2"], 1 - 2 * (1 - k0[0])) and np.isclose(v["Kb2b3"], 1 - (1 - k0[1]) / 4)
    lo, hi = fit.bounds()
    for edge in (lo, hi):
        k = fit.values_of(edge[: fit.nc])[-2:]
        assert np.all((k >= 0) & (k < 1))
    assert "Kb1b2" not in _fit(model).free  # couplings stay fixed unless named


def test_split_section_names_the_couplings_it_touches():
    circuit = get_model("hv-4section").circuit
    chains = find_chains(circuit, ["a1", "b1"])
    hv = next(c for c in chains if c.port == "b1")
    cand = split_section(circuit, hv, 1, coupling_decay(circuit, chains, circuit.resolve(check=False)))
    # Lb2 couples to La1, Lb1, Lb3, Lb4 and Lc; its new half to those five and to Lb2
    assert len(cand.couplings) == 11
    new_l = next(n for n in cand.new_elements if n.upper().startswith("L"))
    for name in cand.couplings:
        assert {"lb2", new_l.lower()} & {n.lower() for n in cand.circuit.element(name).nodes}



def test_a_respaced_split_counts_every_coupling_along_the_lengthened_winding():
    """A winding whose couplings decay as ``rho^d`` (a Kac-Murdock-Szego matrix), section 2 of 4 made two,
    respaced: the five sections' couplings are ``rho^d`` over the five positions (written out here), and the
    split section's own inductance (the halves with their mutual) is kept."""
    from estimation.diagnosis.causes.unmerge import Unmerged
    from pris_cosim.circuits.netlist import parse_netlist

    rho, n = 0.6, 4
    lines = ["* four sections"]
    node = lambda i: "0" if i >= n else f"n{i + 1}"  # noqa: E731
    for i in range(n):
        lines += [f"R{i + 1} {node(i)} x{i + 1} 0.5", f"L{i + 1} x{i + 1} {node(i + 1)} {2 + i}m",
                  f"C{i + 1} {node(i)} {node(i + 1)} 1n", f"Cg{i + 1} {node(i)} 0 0.5n"]
    lines += [f"K{i + 1}{j + 1} L{i + 1} L{j + 1} {rho ** (j - i)}" for i in range(n) for j in range(i + 1, n)]
    circuit = parse_netlist("\n".join(lines) + "\n")
    chain = find_chains(circuit, ["n1"])[0]
    um = Unmerged(circuit, chain, 1, respaced=True)
    c = um.candidate.circuit
    values = c.resolve(check=False)
    position = {"l1": 0, "l2": 1, um.second["L"].lower(): 2, "l3": 3, "l4": 4}
    for k in c.of_kind("K"):
        a, b = (x.lower() for x in k.nodes)
        assert np.isclose(float(values[k.key]), rho ** abs(position[a] - position[b]), rtol=1e-9), k.name
    l1, l2 = float(values["l2"]), float(values[um.second["L"].lower()])
    assert np.isclose(l1 + l2 + 2 * rho * np.sqrt(l1 * l2), 3e-3)
    plain = Unmerged(circuit, chain, 1).candidate.circuit.resolve(check=False)
    assert np.isclose(float(plain["k14"]), rho ** 3)  # not respaced: the design's couplings kept
