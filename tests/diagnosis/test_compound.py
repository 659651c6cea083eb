"""Causes sought from the design values: compounds and a missing section against a design netlist.

The cases come from :func:`hidden_cases.design_case` (its own nodal solver,
hidden effects in other forms than the catalogue's, values of the truth
within 10 % of the design, 0.3 % noise); nothing here is made by the
diagnosis's code.
"""

import pytest

from estimation.diagnosis import diagnose_frequency
from estimation.diagnosis.diagnose import CAUSE_TIE_DBIC
from hidden_cases import design_case
from pris_cosim.circuits.netlist import parse_netlist


def _diagnose(causes, seed, **kw):
    case = design_case(causes, seed, **kw)
    d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                           port=case.port, progress=False, tolerance=0.2)
    return case, d


@pytest.mark.slow
@pytest.mark.long
def test_skin_effect_and_core_loss_named_together_without_drift():
    """The baseline alone moves values up to 100x; the second cause is refitted from the design values."""
    case, d = _diagnose(("skin-effect", "core-loss"), 700)
    assert sorted(d.causes) == ["core-loss", "skin-effect"], d.steps
    assert d.baseline_drift, "the baseline alone needs values far from the design"
    assert d.drift == [], d.drift
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
@pytest.mark.long
def test_missing_section_named_against_the_design():
    """The design merges two of the winding's seven sections; the baseline absorbs it into drifted capacitances, and
    the section is weighed against those values freed, both converged."""
    case, d = _diagnose(("missing-section",), 700)
    assert case.truth["sections"] == 7
    # the values the baseline moved (C2 x0.3, C6 x2.5, Cg2 x1.5) freed from the prior fit about as well as the split
    # does, converged both: where the data tell them apart by less than a tie (by the floating-point path, the BLAS
    # kernel), the answer may be that drift, with the section reported beside it
    if d.causes != ["missing-section"]:
        assert d.causes == [] and d.drift, d.steps
        assert any(a["cause"] == "missing-section" and a["delta_bic"] < CAUSE_TIE_DBIC
                   for a in d.cause_alternatives), d.cause_alternatives
        return
    assert d.drift == [], d.drift
    # the baseline reaches the noise only with values beyond the tolerance: the section brings it there within it
    assert d.baseline_drift, "the baseline alone needs values far from the design"
    assert d.best.cost <= 1.25 * d.noise["cost"]
    assert d.gain > 0.1


@pytest.mark.slow
@pytest.mark.long
def test_missing_section_found_when_the_design_stays_far_above_the_noise():
    """Two merged sections at the port; the design's first fit is about 300x the noise (refitted from the series
    capacitances' group fit, 1.35x with values far off the design). The split is found only by fitting its seeds
    through errors smoothed from a decade down (the seeds' resonances are tens of per cent off)."""
    case, d = _diagnose(("missing-section",), 702)
    assert case.truth["merged_sections"] == (1, 2)
    assert d.baseline_drift, "the baseline needs values far from the design"
    assert d.gain > 0.3
    assert d.causes == ["missing-section"], d.steps
    assert "section 1 " in d.best.structure, d.best.structure
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
@pytest.mark.long
def test_last_sections_merged_and_a_skin_effect_are_named_together():
    """The design merges the winding's last two sections (the last ends at ground), and a skin effect is hidden.

    The split alone is refused on held-out points (it takes the skin effect's share); it is tried again once the
    skin effect is named, and the two reach the noise together.
    """
    case, d = _diagnose(("missing-section", "skin-effect"), 700)
    assert case.truth["merged_sections"] == (6, 7) and case.truth["sections"] == 7
    assert sorted(d.causes) == ["missing-section", "skin-effect"], d.steps
    assert "section 6 " in d.best.structure, d.best.structure
    assert d.best.cost <= 1.25 * d.noise["cost"]
    assert d.drift == [], d.drift


@pytest.mark.slow
@pytest.mark.long
def test_missing_section_in_the_middle_of_a_design_all_off_by_ten_percent():
    """Sections 3 and 4 of seven merged; every split seed starts hundreds of times above the noise, and only the
    search through every seed of every split (two smoothing schedules) brings one to it."""
    case, d = _diagnose(("missing-section",), 701)
    assert case.truth["merged_sections"] == (3, 4)
    assert d.causes == ["missing-section"], d.steps
    assert "section 3 " in d.best.structure, d.best.structure
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
def test_single_skin_effect_reports_no_drift():
    """A value just beyond the tolerance in the final model is not freed to wander off and reported as drift."""
    case, d = _diagnose(("skin-effect",), 701)
    assert d.causes == ["skin-effect"], d.steps
    assert d.drift == [], d.drift


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.xfail(strict=False, reason=(
    "the split of section 3 fits below the right split of section 2 (its halves merged back put L3 at 1.68x the "
    "design) and takes most of the skin effect's share; beside it the skin effect removes 7 % of the cost (20 % "
    "needed): a structure named before an effect is not chosen again with it"))
def test_split_that_leaves_values_off_the_design_seeks_the_skin_effect():
    """Sections 2 and 3 of seven merged, and a skin effect (square-root form, 81 kHz). The split alone reaches the
    data's noise floor, but with C4 moved 2.4 tolerances and residuals correlated along frequency; the skin effect is
    sought after it and named, and no value is left off the design (before, six were reported off: the drift
    relaxation had freed them to take the skin effect's share)."""
    case, d = _diagnose(("missing-section", "skin-effect"), 702)
    assert case.truth["merged_sections"] == (2, 3) and case.truth["skin"]["kind"] == "sqrt"
    assert d.causes == ["missing-section", "skin-effect"], d.steps
    assert "section 2 " in d.best.structure, d.best.structure
    assert d.drift == [], d.drift
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
@pytest.mark.long
def test_missing_section_of_two_alike_sections_is_named():
    """Sections 3 and 4 of six merged, their values alike: the baseline stops at 2.4 x the floor with Cg3 at 2.4 x
    its design value. Only the plain split of the design (equal halves, equal capacitances) leads a local fit to the
    noise; the seeds that shared the capacitance unequally stopped at 7.6e-5, and the answer was `none`."""
    _section_named_at_the_noise(703, merged=(3, 4))


@pytest.mark.slow
@pytest.mark.long
def test_missing_section_held_out_past_a_sharp_resonance():
    """Sections 3 and 4 of seven merged. The baseline reaches 1.1 x the floor only with Cg4 at 0.3 x its design
    value; the split reaches the noise within the design (dBIC 287). Refitted on every other point, the split moved
    a sharp resonance by a fraction of a per cent, and one held-out point near its peak outweighed the split's gain
    on all the others: held-out gain -0.02, refused, answer `none` with three values reported off the design. Each
    held-out point now counts at most 5 noise standard deviations."""
    _section_named_at_the_noise(706, merged=(3, 4))


def _section_named_at_the_noise(seed, merged):
    """Design case ``seed`` with a missing section: the split of the merged sections named alone, at the noise, with
    no value off the design."""
    case, d = _diagnose(("missing-section",), seed)
    assert case.truth["merged_sections"] == merged
    assert d.causes == ["missing-section"], d.steps
    assert f"section {merged[0]} " in d.best.structure, d.best.structure
    assert d.drift == [], d.drift
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
@pytest.mark.long
def test_skin_effect_beside_a_strong_magnetising_change_is_not_named():
    """Skin effect (square-root form, 36 kHz) and a magnetising change (Cole-Cole, L down to 54 % above 72 kHz).
    The reference solver's own fit, the truth's sections with the magnetising change as the truth has it and every
    value free within twice the tolerance, reaches the truth to far below the noise: the skin effect cannot be told
    apart beside the magnetising change's loss, and the diagnosis names the magnetising change alone."""
    import numpy as np

    from detectability import best_baseline_fit

    case, d = _diagnose(("skin-effect", "magnetising-inductance"), 701)
    beside = best_baseline_fit(case, target="truth", structure="sections", keep="magnetising-inductance",
                               bound=2 * float(np.log(1.2)))
    assert not beside["detectable"] and beside["cost"] < 0.01 * beside["noise"], beside
    assert d.causes == ["magnetising-inductance"], d.steps
    assert d.drift == [], d.drift
