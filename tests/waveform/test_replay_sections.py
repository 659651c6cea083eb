"""A missing section of the winding found by the PRIS record's replay.

The record is made here by ngspice (:mod:`pris_records`: the deck written without the package) of
:data:`pris_records.FOUR_SECTIONS`, the second section of the thesis's Table 4.7 three-section winding made two;
the diagnosis is given the three-section netlist of Table 4.7.
"""

import pytest
from conftest import needs_ngspice

from pris_cosim.circuits.netlist import parse_netlist
from pris_cosim.measured.formats import Waveforms


def _diagnose(rec):
    from pris_records import WINDING

    from estimation.diagnosis.waveform.replay import diagnose_pris_record

    w = Waveforms(rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"])
    return diagnose_pris_record(w, 150.0, 4e-3, 1e-6, circuit=parse_netlist(WINDING + ".end\n"), port="n1",
                                progress=False)


@pytest.mark.slow
@needs_ngspice
def test_a_section_the_netlist_merged_is_named_with_its_place():
    from pris_records import FOUR_SECTIONS, record

    out = _diagnose(record(noise=0.002, winding=FOUR_SECTIONS)).as_json()
    assert out["cause"] == "missing-section" and out["path"]["path"] == "exact-replay", out["steps"]
    step = next(s for s in out["steps"] if s["cause"] == "missing-section")
    assert step["model"].startswith("section 2 of the winding at n1 is two sections"), step
    assert step["gain"] > 0.5
    assert step["values"]["structure"] == step["model"]


@pytest.mark.slow
@needs_ngspice
def test_the_netlist_of_the_recorded_winding_names_no_section():
    """The three sections recorded, the same three given: the section candidates stay below the BIC rule."""
    from pris_records import record

    d = _diagnose(record(noise=0.002))
    assert d.causes == [] and d.drift == [], (d.steps, d.drift)
