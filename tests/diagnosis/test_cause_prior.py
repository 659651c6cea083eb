"""A missing section is one of several places: its BIC counts its share of the cause's prior.

The places are counted by hand from the netlist (one winding of three
sections from the port to ground: three splits and the two ends), and the
cause's BIC is checked against the plain BIC plus ``2 ln M``.
"""

import math

import numpy as np

from estimation.diagnosis.causes.section_fits import structure_prior
from estimation.diagnosis.fit import FrequencyFit
from pris_cosim.circuits.netlist import parse_netlist
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration

NET = """* three sections from the port n1 to ground
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
K23 L2 L3 0.6
"""


def test_a_three_section_winding_has_five_places_for_a_missing_section():
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
