"""The independent generator's design cases: a seed's draws (``draw``) are reproducible and independent."""

import numpy as np

from hidden_cases import design_case


def test_draw_zero_is_the_seeds_case_and_another_draw_another_winding():
    a, b = design_case(("skin-effect",), 702), design_case(("skin-effect",), 702, draw=0)
    assert a.baseline_netlist == b.baseline_netlist and np.array_equal(a.measured["Zin"], b.measured["Zin"])
    assert "draw" not in a.truth
    c, d = design_case(("skin-effect",), 702, draw=2), design_case(("skin-effect",), 702, draw=2)
    assert c.truth["draw"] == 2 and np.array_equal(c.measured["Zin"], d.measured["Zin"])
    assert c.baseline_netlist != a.baseline_netlist
