"""A winding's last section split in two: its start node's capacitance to ground is shared out anew; and the
places a section may be missing from, counted by hand.

The last section of a cascade ends at ground, so its series capacitance is
a capacitance to ground at its start node, in parallel with the node's own.
A split that adds a capacitance ``Cs`` across the first half and ``Cg`` at the
new node puts ``Cs Cg / (Cs + Cg)`` (two capacitors in series) where that
capacitance was; the closed form is written out here.
"""

import math

import numpy as np
import pytest

from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.prior import design_prior
from estimation.diagnosis.causes.section_fits import structure_prior
from estimation.diagnosis.causes.sections import coupling_decay, find_chains, split_section
from estimation.diagnosis.causes.unmerge import Unmerged
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration
from pris_cosim.circuits.netlist import parse_netlist

NET = """* three sections, the last one ending at ground
R1 n1 x1 0.5
L1 x1 n2 1.5m
C1 n1 n2 1.2n
Cg1 n1 0 0.5n
R2 n2 x2 0.6
L2 x2 n3 1.4m
C2 n2 n3 1.3n
Cg2 n2 0 0.6n
R3 n3 x3 1.1
L3 x3 0 4.1m
C3 n3 0 0.7n
Cg3 n3 0 0.55n
K12 L1 L2 0.6
K13 L1 L3 0.35
K23 L2 L3 0.6
"""


def _last_split():
    c = parse_netlist(NET)
    chain = find_chains(c, ["n1"])[0]
    return c, chain, Unmerged(c, chain, len(chain.sections) - 1)


def _free(circuit):
    f = np.logspace(3, 6, 60)
    cfg = [Configuration("default", "n1", (), (Response("Zin"),))]
    return FrequencyFit(circuit, cfg, f, {"Zin": np.ones(f.size, complex)}).free


def test_last_section_seeds_keep_the_start_nodes_capacitance_to_ground():
    c, _, um = _last_split()
    cand = um.candidate.circuit
    added = um.first["C"]
    mid = next(n for n in cand.element(um.shunt).nodes if n != "0")
    assert added not in {e.name for e in c.elements} and set(cand.element(added).nodes) == {"n3", mid}
    free = _free(cand)
    values = cand.resolve(check=False)
    design_total = 0.7e-9 + 0.55e-9
    rows = um.seeds(free, np.zeros(0))
    checked = 0
    for row in rows:
        v = {n.lower(): float(values[n.lower()]) * np.exp(x) for n, x in zip(free, row)}
        cs, cg = v[added.lower()], v[um.shunt.lower()]
        total = v["c3"] + v["cg3"] + cs * cg / (cs + cg)
        if v["c3"] + v["cg3"] > 0.1 * design_total * 1.0001:  # not clipped at a tenth
            assert total == pytest.approx(design_total, rel=1e-9)
            checked += 1
    assert checked >= len(rows) // 2


def test_prior_frees_the_start_nodes_capacitance_only_when_a_capacitance_is_added_across_the_first_half():
    c, chain, um = _last_split()
    prior = design_prior({e.name: 1.0 for e in c.elements if e.kind in "RLC"}, 0.2, 1e-5, 200, 1, c)
    freed = set(prior.design) - prior.anchored(um.candidate.circuit)
    assert {"c3", "cg3", "r3", "l3"} <= freed and not freed & {"c2", "cg2", "c1", "cg1", "r1", "l1"}
    plain = split_section(c, chain, len(chain.sections) - 1, coupling_decay(c, [chain], c.resolve(check=False)), 1.0)
    assert not any(e.kind == "C" and "0" not in e.nodes and e.name in plain.new_elements for e in plain.circuit.elements)
    assert {"c3", "cg3"} <= prior.anchored(plain.circuit)


def test_first_seed_of_a_split_is_the_plain_split():
    """Equal halves, the series capacitance shared equally, the shunt as built: the candidate's own values, but for
    one common factor on the two halves' inductances (which keeps the section's total inductance)."""
    c = parse_netlist(NET)
    chain = find_chains(c, ["n1"])[0]
    um = Unmerged(c, chain, 1)
    free = [n.lower() for n in _free(um.candidate.circuit)]
    rows = um.seeds(free, np.zeros(0))
    halves = [free.index(um.first["L"].lower()), free.index(um.second["L"].lower())]
    others = [i for i in range(len(free)) if i not in halves]
    assert np.allclose(rows[0][others], 0.0, atol=1e-12)
    assert rows[0][halves[0]] == pytest.approx(rows[0][halves[1]], abs=1e-12)
    assert not any(np.allclose(r[others], 0.0, atol=1e-12) for r in rows[1:])


def test_a_three_section_winding_has_five_places_for_a_missing_section():
    """Three splits and the winding's two ends: the search weighs five places, and a missing section's BIC counts
    ``2 ln 5``."""
    assert math.isclose(structure_prior(parse_netlist(NET), ["n1"]), 2 * math.log(3 + 2))


def test_the_cause_bic_adds_the_prior_share_of_each_named_cause_once():
    c = parse_netlist(NET)
    f = np.logspace(3, 6, 40)
    cfg = [Configuration("default", "n1", (), (Response("Zin"),))]
    share = structure_prior(c, ["n1"])
    fit = FrequencyFit(c, cfg, f, {"Zin": np.full(f.size, 100.0 + 0j)}, cause_prior={"missing-section": share})
    r = fit.result(fit.start)
    assert r.cause_bic == r.bic  # the baseline names no cause
    r.causes = ["skin-effect", "missing-section"]
    assert math.isclose(r.cause_bic - r.bic, share)
    r.causes = ["skin-effect"]  # a cause with a single alternative shares nothing
    assert r.cause_bic == r.bic
