"""A missing section of the winding found by the PRIS record's replay.

The record is made here by ngspice (:mod:`pris_records`: the deck written without the package): a winding of four
sections, the second of the thesis's Table 4.7 three-section winding made two (half its resistance each, twice
its series capacitance each, the inductances and couplings such that the two merged give back Table 4.7's
section 2 and its couplings, 1.6 nF from the new node to ground). The diagnosis is given the three-section
netlist of Table 4.7.
"""

import pytest
from conftest import needs_ngspice

from pris_cosim.circuits.netlist import parse_netlist
from pris_cosim.measured.formats import Waveforms

#: Section 2 of Table 4.7 as two sections: L2 + L2b + 2 k sqrt(L2 L2b) = 181 uH with k = 0.9; the couplings of
#: the two to L1 and L3 chosen so that the merged section's mutual inductances are Table 4.7's.
FOUR_SECTIONS = """* four sections: section 2 of Table 4.7 made two
R1 n1 x1 0.083
L1 x1 n2 181u
Cs1 n1 n2 0.97n
R2 n2 x2 0.0415
L2 x2 m2 47.63u
Cs2 n2 m2 1.94n
R2b m2 y2 0.0415
L2b y2 n3 47.63u
Cs2b m2 n3 1.94n
R3 n3 x3 0.083
L3 x3 0 181u
Cs3 n3 0 0.97n
Cg1 n1 0 0.8n
Cg2 n2 0 1.6n
Cgm m2 0 1.6n
Cg3 n3 0 1.6n
K12 L1 L2 0.8568
K12b L1 L2b 0.8568
K13 L1 L3 0.8729
K22b L2 L2b 0.9
K23 L2 L3 0.8347
K2b3 L2b L3 0.8347
"""


def _diagnose(rec):
    from pris_records import WINDING

    from estimation.diagnosis.waveform.replay import diagnose_pris_record

    w = Waveforms(rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"])
    return diagnose_pris_record(w, 150.0, 4e-3, 1e-6, circuit=parse_netlist(WINDING + ".end\n"), port="n1",
                                progress=False)


@pytest.mark.slow
@needs_ngspice
def test_a_section_the_netlist_merged_is_named_with_its_place():
    from pris_records import record

    out = _diagnose(record(noise=0.002, winding=FOUR_SECTIONS)).as_json()
    assert out["cause"] == "missing-section" and out["path"]["path"] == "exact-replay", out["steps"]
    step = next(s for s in out["steps"] if s["cause"] == "missing-section")
    assert step["model"].startswith("section 2 of the winding at n1 is two sections"), step
    assert step["gain"] > 0.5


@pytest.mark.slow
@needs_ngspice
def test_the_netlist_of_the_recorded_winding_names_no_section():
    """The three sections recorded, the same three given: the section candidates stay below the BIC rule."""
    from pris_records import record

    d = _diagnose(record(noise=0.002))
    assert d.causes == [] and d.drift == [], (d.steps, d.drift)
