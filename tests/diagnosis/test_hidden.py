"""Diagnosis names causes hidden by the independent generator (``hidden_cases``, reference nodal solver).

The hidden effects are written in forms other than the catalogue's (thesis
(2.6) with its own scale, a real-valued square-root rise) and the baselines
are netlists, so nothing here shares code with the fits.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

from estimation.diagnosis import diagnose_frequency
from pris_cosim.circuits.netlist import parse_netlist

from hidden_cases import one_port_case


def _diagnose(case):
    return diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                              port=case.port, progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [pytest.param(1, marks=pytest.mark.long), 2])
def test_netlist_cascade_skin_effect_is_named(seed):
    """A 4-section netlist cascade whose resistances rise with frequency (real-valued, thesis-like forms)."""
    case = one_port_case("skin-effect", seed, sections=4)
    d = _diagnose(case)
    assert d.causes[:1] == ["skin-effect"], (case.truth, d.candidates())
    assert d.gain >= 0.5
    assert all(c["gain"] > 0 for c in d.candidates())  # a fit worse than the baseline is never a candidate


def test_clean_cascade_no_false_alarm():
    case = one_port_case("none", 2, sections=5)
    d = _diagnose(case)
    assert d.cause == "none" and d.causes == [], d.candidates()


@pytest.mark.slow
@pytest.mark.long
def test_skin_effect_and_missing_section_without_a_core_loss_beside_them():
    """Seven sections, the last two merged in the netlist, and a thesis-like skin effect (its own scale: the rise
    starts at f_s / 20). Forward selection names core loss before the section (the split is refused beside the skin
    effect alone, 2.6x the noise); with the section, the skin effect refitted from its own starts makes the core
    loss redundant, and the backward check drops it."""
    case = one_port_case(("skin-effect", "missing-section"), 101)
    assert case.truth["skin"]["kind"] == "thesis" and case.truth["merged_sections"] == (6, 7)
    d = _diagnose(case)
    assert sorted(d.causes) == ["missing-section", "skin-effect"], d.steps
    assert any(s.get("dropped") and s["cause"] == "core-loss" for s in d.steps), d.steps
    assert "section 6 " in d.best.structure, d.best.structure
    assert d.best.cost <= 1.25 * d.noise["cost"]


@pytest.mark.slow
def test_cli_json_has_steps_and_noise_floor(tmp_path):
    case = one_port_case("skin-effect", 2, sections=4)
    net = tmp_path / "cascade.cir"
    net.write_text(case.baseline_netlist)
    z = case.measured["Zin"]
    data = tmp_path / "z.csv"
    rows = ["frequency_hz,Zin_mag,Zin_phase_deg"] + [f"{f:.17g},{abs(v):.17g},{np.degrees(np.angle(v)):.17g}"
                                                    for f, v in zip(case.frequency_hz, z)]
    data.write_text("\n".join(rows) + "\n")
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "diagnose", "--measured", str(data), "--netlist",
                           str(net), "--port", case.port, "--json"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["cause"] == "skin-effect" and out["causes"][0] == "skin-effect"
    assert {"steps", "noise_floor", "unexplained"} <= set(out)
    assert all(c["gain"] > 0 for c in out["candidates"]) and out["gain"] >= 0.5


@pytest.mark.slow
@pytest.mark.long
def test_two_winding_thesis_skin_effect_on_hv_only():
    """hv-4section, six responses: R(f) of the HV sections in thesis (2.6)'s real-valued form, own scale."""
    from hidden_cases import two_winding_case
    from pris_cosim.models.builtin import get_model

    case = two_winding_case("skin-effect", 2, group="hv")
    assert case.truth["skin"]["kind"] == "thesis"
    d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model),
                           causes=["skin-effect", "magnetising-inductance"], progress=False)
    assert d.causes == ["skin-effect"], d.candidates()
    assert d.gain >= 0.9 and all(c["gain"] > 0 for c in d.candidates())


@pytest.mark.slow
@pytest.mark.long
def test_two_winding_missing_section_is_named_to_the_noise():
    """hv-4section, six responses: one HV section of the truth split in two (the generator's own construction,
    the split section's couplings changed). Named ``missing-section`` alone, with the misfit left within three
    times the generator's noise (magnitude and phase each perturbed by 0.3 %: ``2 s^2`` per response)."""
    from hidden_cases import two_winding_case
    from pris_cosim.models.builtin import get_model

    case = two_winding_case("missing-section", 300, group="all")
    assert "split_hv_section" in case.truth
    d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model), progress=False)
    assert d.causes == ["missing-section"], (d.steps, d.candidates())
    noise_cost = len(case.measured) * 2 * case.noise ** 2
    assert d.best.cost <= 3 * noise_cost, (d.best.cost, noise_cost, d.best.structure)


@pytest.mark.slow
@pytest.mark.long
def test_two_winding_lamination_core_loss_is_named_alone():
    """hv-4section, six responses: the core-loss resistance of the truth is a lamination's eddy-current impedance
    (``R q tanh q / (1 + q tanh q)``, ``q = sqrt(j f / f_b)``, the generator's own form). One relaxation time leaves
    1.3 x the noise, which a new section took (named with it before); the distributed form reaches the noise alone."""
    from hidden_cases import two_winding_case
    from pris_cosim.models.builtin import get_model

    case = two_winding_case("core-loss", 301, group="all")
    assert case.truth["core"]["kind"] == "eddy"
    d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model), progress=False)
    assert d.causes == ["core-loss"], (d.steps, d.candidates())
    noise_cost = len(case.measured) * 2 * case.noise ** 2
    assert d.best.cost <= 3 * noise_cost, (d.best.cost, noise_cost, d.best.structure)


@pytest.mark.slow
@pytest.mark.long
def test_two_winding_magnetising_change_and_missing_section_are_named_together():
    """hv-4section, six responses: the truth's magnetising inductance relaxes with frequency (the generator's own
    form) and one HV section is split in two. Named first in its causal form, the magnetising change left the new
    section a held-out gain of 0.13 and the section was refused; once its form is chosen again, the section is
    measured again against that model and both are named, to within three times the generator's noise."""
    from hidden_cases import two_winding_case
    from pris_cosim.models.builtin import get_model

    case = two_winding_case(("magnetising-inductance", "missing-section"), 500, group="all")
    assert "split_hv_section" in case.truth and case.truth["magnetising"]["kind"] == "relax"
    d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model), progress=False)
    assert sorted(d.causes) == ["magnetising-inductance", "missing-section"], (d.steps, d.candidates())
    noise_cost = len(case.measured) * 2 * case.noise ** 2
    assert d.best.cost <= 3 * noise_cost, (d.best.cost, noise_cost, d.best.structure)


@pytest.mark.slow
@pytest.mark.long
def test_two_winding_skin_effect_found_beside_a_lamination_core_loss_in_a_form_the_baseline_ranked_low():
    """hv-4section, six responses: a round wire's skin effect (Bessel impedance, ``f_s`` 135 Hz) on every winding and
    a lamination's core loss. Core loss is named first; the skin effect on every winding in its relaxation form,
    fifth of nine forms and groups on the baseline, is found beside it by the short fits that rank the forms, and
    the two reach the noise with no section added."""
    from hidden_cases import two_winding_case
    from pris_cosim.models.builtin import get_model

    case = two_winding_case(("skin-effect", "core-loss"), 500, group="all")
    assert case.truth["skin"]["kind"] == "bessel" and case.truth["core"]["kind"] == "eddy"
    d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model), progress=False)
    assert sorted(d.causes) == ["core-loss", "skin-effect"], (d.steps, d.candidates())
    noise_cost = len(case.measured) * 2 * case.noise ** 2
    assert d.best.cost <= 3 * noise_cost, (d.best.cost, noise_cost, d.best.structure)
