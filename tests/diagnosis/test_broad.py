"""Diagnosis of broad cases drawn from physics by code that shares nothing with it (:mod:`broad_cases`).

Each case is written as a user's file (CSV or Touchstone) with its design
netlist, read back and diagnosed against the design at a tolerance of 0.2.
The truth is the generator's: the causes named exactly, and where it lists
the drift, the values reported beyond the tolerance (a group's drift by its
members). The seeds below were fixed before any answer was looked at (seed 1
of each effect); ``bench_broad.py`` runs a hundred draws.
"""

from pathlib import Path

import numpy as np
import pytest

from broad_cases import (EFFECTS, VISIBLE, _log_z_and_gradient, _solve_many, draw, reported_drift, signature,
                         visible_draw, within_tolerance, write)

from estimation.diagnosis import diagnose_frequency
from estimation.diagnosis.verdict import FIT_FACTOR
from pris_cosim.circuits.netlist import read_netlist
from pris_cosim.measured.formats import load_measured


def _diagnose(case, folder: Path):
    data, net = write(case, folder)
    m = load_measured(str(data))
    return diagnose_frequency(m.frequency_hz, m.responses, circuit=read_netlist(str(net)), port=case.port,
                              progress=False, tolerance=0.2)


def _value_off_alone(seed: int, effect: str, name: str, folder: Path) -> None:
    """Draw ``seed`` of the benchmark's fixed seeds has ``name`` alone off the design: no cause, that drift only."""
    case = draw(seed)
    assert case.effect == effect and case.drift == [name]
    d = _diagnose(case, folder)
    assert not d.causes, (d.cause, d.candidates())
    assert reported_drift(d.drift, case.drift) == {name}, d.drift


def _skin_effect_alone(seed: int, folder: Path) -> None:
    """Draw ``seed`` of the benchmark's fixed seeds has the skin effect hidden: it alone is named, with no drift."""
    case = draw(seed)
    assert case.effect == "skin"
    d = _diagnose(case, folder)
    assert d.causes == ["skin-effect"], (d.cause, d.candidates())
    assert not d.drift, d.drift


def _first_with_sections(effect: str, sections: int) -> int:
    return next(s for s in range(1, 10_000) if draw(s, effect).netlist.count("\nL") == sections)


def test_batched_solve_and_its_gradient_agree_with_the_loop_and_differences():
    """The signature's winding (one batched solve, adjoint derivatives) against the generator's nodal solve, one
    frequency at a time, and against central differences."""
    from broad_cases import zin

    case = draw(1088)
    d, f = case.design, case.frequency_hz
    np.testing.assert_allclose(_solve_many(d.R, d.L, d.Cs, d.Cg, d.K, f)[0], zin(d, f), rtol=1e-10)
    v = np.concatenate([d.R, d.L, d.Cs, d.Cg])
    g = _log_z_and_gradient(v, d.K, f)[1]
    h = 1e-5
    for k in range(v.size):
        up, down = v.copy(), v.copy()
        up[k] *= np.exp(h)
        down[k] *= np.exp(-h)
        diff = (_log_z_and_gradient(up, d.K, f)[0] - _log_z_and_gradient(down, d.K, f)[0]) / (2 * h)
        assert np.max(np.abs(diff - g[:, k])) < 1e-4 * np.max(np.abs(g[:, k])), k


def test_signature_tells_hidden_effects_from_visible_ones():
    """Nothing hidden: no signature; a series capacitance at 1.8-3x: far above the noise; the skin effect of draw
    1089 (three sections, conductor radius one skin depth at 283 kHz): the resistances within the tolerance take it
    (0.1 in chi-square units, measured)."""
    assert signature(draw(1088)) < 1.0
    assert signature(draw(1014)) > 1e3 * VISIBLE
    assert signature(draw(1089)) < 0.1 * VISIBLE


@pytest.mark.slow
def test_a_seed_whose_draw_hides_its_effect_is_drawn_again_until_it_shows():
    """Draw 1383 (a skin effect) is hidden (its signature below ``VISIBLE``); its own draw is unchanged by the
    redraw index, the redraws are independent windings with the same effect, and the first that shows is taken."""
    own = draw(1383)
    assert signature(own) < VISIBLE
    assert np.array_equal(draw(1383, k=0).z, own.z)
    k, case, lam = visible_draw(1383)
    assert k > 0 and case.effect == own.effect == "skin" and case.causes == ["skin-effect"]
    assert lam >= VISIBLE
    assert not np.array_equal(case.frequency_hz, own.frequency_hz) or not np.array_equal(case.z, own.z)
    k_none, clean, lam_none = visible_draw(1300, "none")
    assert k_none == 0 and lam_none == 0.0 and clean.effect == "none"


def test_a_fault_at_the_last_node_that_the_design_within_tolerance_fits_is_hidden():
    """Draw 1158 (three sections, 0.1 % noise): Cg3 at 1.89x, in parallel with C3 (the last section ends at
    ground). Clipped to the tolerance the truth leaves a misfit of 1e7 noise units; followed onto the tolerance
    (the continuation) the others move together and a design model within it fits the clean response. The witness
    is checked with the generator's own nodal solve, one frequency at a time: every value within the tolerance and
    the misfit below the visible level."""
    from broad_cases import zin

    case = draw(1158)
    assert case.effect == "local" and case.drift == ["Cg3"]
    assert signature(case, steps=0) > 1e5 * VISIBLE
    lam, w = within_tolerance(case)
    d = case.design
    ratio = np.concatenate([w.R / d.R, w.L / d.L, w.Cs / d.Cs, w.Cg / d.Cg])
    assert np.all(np.abs(np.log(ratio)) <= np.log(1.2) + 1e-12)
    e = np.log(zin(w, case.frequency_hz)) - np.log(case.clean)
    e.imag = (e.imag + np.pi) % (2 * np.pi) - np.pi
    assert np.sum(np.abs(e) ** 2) / (case.noise ** 2 / 2) == pytest.approx(lam, rel=1e-6)
    assert lam < VISIBLE


@pytest.mark.slow
def test_an_effect_the_design_within_tolerance_fits_reports_no_drift(tmp_path):
    """Draw 1210 (five sections, 0.83 % noise): a skin effect that the design's model with every value within the
    tolerance fits to a few noise units (the generator's signature). The data then need no value beyond the
    tolerance, whatever basin the fit settles in: nothing in ``drift``, and no cause but the skin effect."""
    case = draw(1210)
    assert case.effect == "skin" and signature(case) < 0.5 * VISIBLE
    d = _diagnose(case, tmp_path)
    assert set(d.causes) <= {"skin-effect"} and not d.drift, (d.cause, d.drift)


@pytest.mark.slow
def test_clean_eight_section_design_on_500_points_is_none_without_drift(tmp_path):
    """Eight sections, 500 points, every value within 10 % of the design: ``none``, nothing in ``drift``, a model
    within twice the noise floor."""
    case = draw(_first_with_sections("none", 8), "none", points=500)
    d = _diagnose(case, tmp_path)
    assert d.cause == "none" and not d.causes, (d.cause, d.misfit)
    assert not d.drift, d.drift
    assert (d.best or d.baseline).cost <= FIT_FACTOR * d.noise["cost"]


#: Measured wrong, with the reason (docs/diagnosis-design.md, "Broad draws").
KNOWN_WRONG = {
    "split": "section 4 of six split: named core-loss beside five values moved (before the group's fit from the "
             "scaled design: unexplained at 3.46 x the noise floor); no split found from the fitted values",
}


@pytest.mark.slow
@pytest.mark.long
@pytest.mark.parametrize("effect", [pytest.param(e, marks=pytest.mark.xfail(reason=KNOWN_WRONG[e], strict=False))
                                    if e in KNOWN_WRONG else e for e in EFFECTS if e != "none"])
def test_broad_draw_of_each_effect(effect, tmp_path):
    case = draw(1, effect)
    d = _diagnose(case, tmp_path)
    if signature(case) < VISIBLE and not d.causes and not reported_drift(d.drift, case.drift):
        return  # the effect is hidden in the noise: nothing is what the data show
    assert sorted(d.causes) == sorted(case.causes), (case.name, d.cause, d.misfit, d.candidates())
    if case.drift is not None:
        assert reported_drift(d.drift, case.drift) == set(case.drift), (case.name, d.drift)


@pytest.mark.slow
@pytest.mark.long
def test_one_capacitance_to_ground_off_is_not_the_group(tmp_path):
    """Draw 1109 of the benchmark's fixed seeds (six sections, 851 points, 0.47 % noise): Cg2 alone is off the
    design. The group of the six capacitances to ground (x1.32) fits first, and Cg2 is then found on top of it;
    without the group Cg2 alone explains the data with a lower BIC: drift of Cg2, not of the group, no cause."""
    _value_off_alone(1109, "local", "Cg2", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_off_is_reported_alone_not_with_the_one_that_made_up_for_it(tmp_path):
    """Draw 1150 of the benchmark's fixed seeds (six sections, 207 points, 0.76 % noise): L6 alone at 0.46x its
    design. The fit spreads it (L6 0.57x, L4 0.71x), and each passes its own test at the edge with the other's prior
    in the way; weighed together, the data need L6 alone beyond the tolerance."""
    _value_off_alone(1150, "beyond", "L6", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_off_is_found_when_a_groups_fit_finds_the_better_optimum(tmp_path):
    """Draw 1124 of the benchmark's fixed seeds (four sections, 915 points, 1.0 % noise): L3 at 1.53x its design.
    The baseline's own fit stops at L3 x1.32 (1.06x the noise floor, so nothing seems wrong); the resistances'
    group fit, started from the design values scaled, reaches a BIC 393 lower with a factor of 1.04 (within the
    tolerance: the other values found the better optimum). The baseline refitted from it has L3 at about 1.4x,
    which the data need beyond the tolerance: drift of L3, no cause."""
    _value_off_alone(1124, "beyond", "L3", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_on_top_of_a_group_is_weighed_without_the_group(tmp_path):
    """Draw 1177 of the benchmark's fixed seeds (four sections, 912 points, 0.39 % noise): Cg2 alone at 1.93x its
    design. The group of capacitances to ground (x1.31) has a lower BIC than Cg2 alone from the one-value search,
    and Cg2 is then beyond the group's tolerance on top of it; refitted from there without the group, Cg2 alone
    is lower in BIC than the group with it: drift of Cg2, not of the group, no cause."""
    _value_off_alone(1177, "local", "Cg2", tmp_path)


@pytest.mark.slow
def test_a_drift_that_leaves_values_off_is_weighed_against_every_split(tmp_path):
    """Draw 1141 of the benchmark's fixed seeds (four sections, 1 % noise): section 2 is two sections. The group of
    capacitances to ground (x1.27) beats every single cause's fit, but its model keeps values more than two
    tolerances off the design, so it does not explain the data; every section split (from the fitted and the
    design values) is weighed against it first, and the missing section has the lower BIC."""
    case = draw(1141)
    assert case.effect == "split" and case.extra["split"] == 2
    d = _diagnose(case, tmp_path)
    assert d.causes == ["missing-section"]


@pytest.mark.slow
@pytest.mark.long
def test_a_split_is_weighed_by_bic_not_by_its_cost_alone(tmp_path):
    """Draw 1239 (seven sections, 1.65 % noise): section 2 is two sections, and the baseline reaches 1.2x the noise
    only with five values beyond the tolerance. The split with its couplings free fits a little lower than the one
    respaced (couplings on the winding's profile) but with 13 more parameters; ranked by cost it lost to the drift
    by BIC, ranked by BIC the respaced split wins: a missing section, no drift."""
    case = draw(1239)
    assert case.effect == "split" and case.extra["split"] == 2
    d = _diagnose(case, tmp_path)
    assert d.causes == ["missing-section"] and not d.drift, (d.cause, d.drift)


@pytest.mark.slow
@pytest.mark.long
def test_a_drift_that_beats_a_cause_within_the_design_is_weighed_against_every_split(tmp_path):
    """Draw 1396 of the untouched seeds 1300-1399 (six sections, 0.52 % noise): section 5 is two sections. The skin
    effect fits to the noise within the design, so no split was searched; Cg6 x3.6, with C5 and Cg4 beyond the
    tolerance as well, is lower in BIC than every cause and was the answer with nothing beside it. A drift that beats
    the cause within the design is weighed against every split, each value it reports a parameter: the split fits
    as well (lower in BIC, but moving a value far off), and is reported beside the drift."""
    case = draw(1396)
    assert case.effect == "split" and case.extra["split"] == 5
    d = _diagnose(case, tmp_path)
    assert not d.causes and "missing-section" in {a["cause"] for a in d.cause_alternatives}, \
        (d.cause, d.drift, d.cause_alternatives)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_off_is_sought_from_random_starts_when_a_section_fits_lower(tmp_path):
    """Draw 1234 (ten sections, 0.38 % noise): L9 alone at 2.26x its design. The noise floor is estimated 11 % above
    the noise, so the baseline (values spread over 11 beyond the tolerance) seems to fit; every local fit of one
    value stops about 14 % above the noise, and a split of section 1 fitted lower. The one-value search then fits
    each value from the design with random starts, as the baseline is: L9 alone reaches the noise and beats the
    split by BIC. No cause, L9's drift only."""
    _value_off_alone(1234, "beyond", "L9", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_off_alone_found_from_the_design_values_aligned(tmp_path):
    """Draw 1190 of the benchmark's fixed seeds (six sections, 788 points, 0.33 % noise): Cg3 alone at 2.2x its
    design. The model with Cg3 and C3 (x0.61) freed fits best; Cg3 alone with every other value in its box stops in
    another basin from the model's values and from the design's, and reaches the level of the truth's values only
    from the design's with the resonances aligned and realigned. Then Cg3 alone has the lower BIC."""
    _value_off_alone(1190, "local", "Cg3", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_split_found_from_the_design_values_when_its_seeds_are_aligned(tmp_path):
    """Draw 1117 of the benchmark's fixed seeds (eight sections, 0.17 % noise): section 1 is two sections. The
    baseline reaches the noise only with 13 values beyond the tolerance; the respaced split of the design's section
    1, its seeds' resonances moved onto the measured ones with the two sections' own values free, reaches the noise
    within the design (a seed fitted through smoothed errors alone stops at 49-376x the floor)."""
    case = draw(1117)
    assert case.effect == "split" and case.extra["split"] == 1
    d = _diagnose(case, tmp_path)
    assert d.causes == ["missing-section"]


@pytest.mark.slow
@pytest.mark.long
def test_a_split_at_the_noise_floor_is_named_on_its_evidence(tmp_path):
    """Draw 1132 of the benchmark's fixed seeds (three sections, 701 points, 0.12 % noise): section 3 is two
    sections. The baseline's data cost is below the noise floor, with six values beyond the tolerance (three of them
    more than two tolerances off); the split gains a few per cent of the cost and about 50 in BIC, almost all of it
    the values it brings back to the design. At the floor no share of the cost is asked of a cause (what is left
    there is the noise's), and the split is named."""
    case = draw(1132)
    assert case.effect == "split" and case.extra["split"] == 3
    d = _diagnose(case, tmp_path)
    assert d.causes == ["missing-section"]


@pytest.mark.slow
@pytest.mark.long
def test_a_skin_effect_absorbed_by_the_baseline_is_named_once_its_values_return(tmp_path):
    """Draw 1173 of the benchmark's fixed seeds (seven sections, 0.17 % noise): every resistance a round
    conductor's internal impedance. The baseline reaches the noise floor with eleven values beyond the tolerance,
    two of them more than two tolerances off, and the skin effect fitted from there gains half a per cent. Followed
    from those values back onto the tolerance, the skin effect's fit keeps the noise floor with every value in the
    box: the skin effect is named and nothing is reported as drift."""
    _skin_effect_alone(1173, tmp_path)


@pytest.mark.slow
def test_a_conductors_skin_effect_is_told_from_a_lamination_from_the_design_values_aligned(tmp_path):
    """Draw 1358 of the benchmark's fixed seeds (eight sections, 293 points, 0.32 % noise): every resistance a round
    conductor's internal impedance (Bessel), its corner at 16 kHz. The baseline reaches the noise with sixteen values
    beyond the tolerance, and every form of every loss reaches below the noise floor from there; what tells them
    apart is how far the values must move. Started from the design values with the resonances unaligned, the skin
    effect's forms stopped at 500x the floor and the lamination was named. Each form is now refined from the design
    values with its resonances moved onto the measured ones: the conductor's skin effect, the generator's own form
    (two parameters, as the lamination), is named, with no drift."""
    _skin_effect_alone(1358, tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_value_off_is_reported_alone_once_its_neighbours_return_onto_the_tolerance(tmp_path):
    """Draw 1120 of the benchmark's fixed seeds (five sections, 0.39 % noise): the capacitance to ground of node 2
    at 2.73x its design. The one-value search finds it, but the fit settles with the series capacitance of section
    3 beyond the tolerance as well, and held at its edge from there it loses. Followed back onto the tolerance with
    the capacitance to ground alone freed, the neighbour returns into the box at the noise floor: that value alone
    is reported."""
    _value_off_alone(1120, "local", "Cg2", tmp_path)


@pytest.mark.slow
@pytest.mark.long
def test_a_split_that_one_value_explains_as_well_is_mentioned_beside_it(tmp_path):
    """Draw 1152 of the benchmark's fixed seeds (four sections, 291 points, 1.3 % noise, Touchstone): one section
    split in two. One capacitance to ground off explains the record within 1 in BIC of the split. Either the split
    is named, or the value is reported with the split beside it as a cause the data barely tell from it."""
    case = draw(1152)
    assert case.effect == "split"
    d = _diagnose(case, tmp_path)
    tied = [c["cause"] for c in d.cause_alternatives]
    assert d.causes == ["missing-section"] or (not d.causes and "missing-section" in tied), (d.cause, tied, d.drift)


@pytest.mark.slow
@pytest.mark.long
def test_values_that_pass_for_each_other_are_not_a_finding_of_none(tmp_path):
    """Draw 1185 of the benchmark's fixed seeds (eight sections, 747 points, 0.83 % noise): section 1 is two
    sections. The baseline reaches the noise floor with the series capacitance and the resistance of section 1
    beyond the tolerance, and each, held at its edge, passes while the other makes up for it. With every value
    followed onto its tolerance box the data reject the fit by hundreds in BIC against the two freed: something
    the design lacks is at work. Every cause is at the noise only as the baseline is, so none explains the data
    within the design, and every section split is searched (C1 alone at 1.38x explains the data at the noise too):
    a split fits 8 % below the baseline, and the missing section is named."""
    case = draw(1185)
    assert case.effect == "split" and case.extra["split"] == 1
    d = _diagnose(case, tmp_path)
    assert d.causes == ["missing-section"], (d.cause, d.candidates(), d.drift)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1115, 1127])
def test_none_comes_with_every_value_within_the_tolerance(seed, tmp_path):
    """Clean draws of the benchmark's fixed seeds (the design within 10 % of the winding, nothing hidden) whose
    baseline reaches the noise floor with values just beyond the tolerance that the data do not need: the answer is
    ``none`` with no drift, and the model returned fits within twice the noise floor with every value within the
    tolerance."""
    case = draw(seed)
    assert case.effect == "none"
    d = _diagnose(case, tmp_path)
    assert d.cause == "none" and not d.drift and d.explained
    assert not d.baseline_drift, d.baseline_drift
    w = case.design
    design = {f"{k}{i + 1}": v for k, arr in (("R", w.R), ("L", w.L), ("C", w.Cs), ("Cg", w.Cg))
              for i, v in enumerate(arr)}
    ratios = {n: d.baseline.values[n] / v for n, v in design.items() if n in d.baseline.values}
    assert all(abs(np.log(r)) <= np.log1p(0.2) + 1e-6 for r in ratios.values()), ratios


@pytest.mark.slow
@pytest.mark.long
def test_a_weak_mode_is_aligned_and_the_fit_reaches_the_truths_level(tmp_path):
    """Draw 1174 of the benchmark's fixed seeds (seven sections, Cg5 x1.95, 964 points, 1.1 % noise) has a mode
    weakly observable at the port: a pole and a zero at 196.9 kHz, a wiggle of under 1 dB over two points. A model
    with that mode a few per cent away passes as at the noise (the data's floor estimate is 13 % high on this
    record) while it misses the record by about 14 % of the noise's variance, 290 in BIC. The model the diagnosis
    returns fits the record as closely as the truth itself does (the generator's own noise realisation,
    ``|ln(z / z_clean)|^2``), and the drift it reports is at Cg5 or its neighbour Cg4."""
    case = draw(1174)
    assert case.effect == "local" and case.drift == ["Cg5"]
    d = _diagnose(case, tmp_path)
    truth_cost = float(np.mean(np.abs(np.log(case.z / case.clean)) ** 2))
    final = d.best or d.baseline
    assert final.cost <= 1.03 * truth_cost, (final.cost, truth_cost)
    assert not d.causes and reported_drift(d.drift, case.drift) & {"Cg4", "Cg5"}, (d.cause, d.drift)


@pytest.mark.slow
def test_a_fit_at_the_noise_that_misses_a_weak_mode_is_realigned(tmp_path):
    """Draw 1123 of the benchmark's fixed seeds (six sections, 973 points, 0.14 % noise, a skin effect far below the
    noise): the data's floor estimate is 20 % above the noise's variance, and a model with its sixth mode at 145 kHz
    instead of 160 kHz passed as at the noise with L5 reported off. The model returned fits the record as closely
    as the truth itself (the generator's noise realisation), with no value beyond the tolerance."""
    case = draw(1123)
    assert case.effect == "skin" and signature(case) < 1.0
    d = _diagnose(case, tmp_path)
    truth_cost = float(np.mean(np.abs(np.log(case.z / case.clean)) ** 2))
    assert (d.best or d.baseline).cost <= 1.03 * truth_cost
    assert not d.causes and not d.drift, (d.cause, d.drift)


@pytest.mark.slow
@pytest.mark.long
def test_a_split_that_beats_a_value_off_by_less_than_the_naming_margin_is_no_finding(tmp_path):
    """Draw 1382 of the untouched seeds 1300-1399 (ten sections, 282 points, 0.42 % noise): L10 alone at 0.57x its
    design, no cause. The best of the twelve places a section could be missing (a split of section 1) fits below the
    noise the truth's own values leave, 11.8 lower in BIC than the baseline; counted as one of twelve places it is
    7 lower, and weighed against L10 freed from the prior less than the 10 that name a cause. No cause is named,
    L10 is reported, and the missing section is mentioned beside it."""
    case = draw(1382)
    assert case.effect == "beyond" and case.drift == ["L10"]
    d = _diagnose(case, tmp_path)
    assert not d.causes, (d.cause, d.candidates())
    assert reported_drift(d.drift, case.drift) == {"L10"}, d.drift
