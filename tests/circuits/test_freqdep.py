"""Frequency-dependent elements as passive R-L ladders."""

import numpy as np
import pytest

from pris_cosim.circuits import ngspice
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.freqdep import (core_loss_resistance, fit_inductance, fit_resistance,
    magnetising_inductance, replace_with_ladder, skin_resistance, thesis_skin_resistance)
from pris_cosim.frf.response import frequency_response, logspace_hz
from pris_cosim.models.builtin import get_model

from conftest import needs_ngspice


@pytest.mark.parametrize("a, b", [(0.5, 0.5), (2.0, 0.8), (9.0, 1.0)])
def test_skin_effect_fit_within_one_percent(a, b):
    f = logspace_hz(1e4, 3.5e5, 80)
    target = skin_resistance(f, 0.02, a, b, 1e4)
    lad = fit_resistance(lambda x: skin_resistance(x, 0.02, a, b, 1e4), 1e4, 3.5e5, 8)
    assert np.all(lad.r > 0) and np.all(lad.l > 0) and lad.r0 >= 0
    assert np.max(np.abs(lad.resistance(f) / target - 1)) < 0.01


def test_core_loss_and_magnetising_fits():
    f = logspace_hz(10, 1e4, 60)
    lad = fit_resistance(lambda x: core_loss_resistance(x, 7e4, 200.0), 10, 1e4, 10)
    assert np.max(np.abs(lad.resistance(f) / core_loss_resistance(f, 7e4, 200.0) - 1)) < 0.01
    lad = fit_inductance(lambda x: magnetising_inductance(x, 0.25, 3.0, 0.2), 10, 1e4, 8)
    assert np.max(np.abs(lad.inductance(f) / magnetising_inductance(f, 0.25, 3.0, 0.2) - 1)) < 0.01
    assert np.all(lad.l > 0) and lad.l0 > 0


def test_thesis_skin_formula_matches_plain_form():
    f = logspace_hz(1e3, 1e5, 10)
    # c = 1, f >> f0: R_lin (1 + a (f/f0 - 1)^b) -> R_lin (1 + a (f/f0)^b) up to the -1
    np.testing.assert_allclose(thesis_skin_resistance(f, 2.0, 0.3, 1.0, 1.0, 1e3), 2.0 * (1 + 0.3 * (f / 1e3 - 1)))


def test_passive_positive_real():
    lad = fit_resistance(lambda x: skin_resistance(x, 1.0, 3.0, 0.7, 1e3), 1e2, 1e5, 6, l0=1e-3)
    z = lad.impedance(logspace_hz(1, 1e8, 400))
    assert np.all(z.real >= 0)


def test_ladder_inside_circuit_gives_its_impedance():
    c = Circuit(title="R-L branch with capacitor", ports=["a"])
    c.add("R1", "a", "x", 0.5)
    c.add("L1", "x", "0", 1e-3)
    c.add("C1", "a", "0", 1e-9)
    lad = fit_resistance(lambda x: skin_resistance(x, 0.5, 2.0, 0.8, 1e3), 1e2, 1e5, 6)
    ext = replace_with_ladder(c, "R1", lad)
    f = logspace_hz(1e2, 1e5, 50)
    z = frequency_response(ext, "a", f)["Zin"]
    s = 2j * np.pi * f
    expected = 1 / (s * 1e-9 + 1 / (lad.impedance(f) + s * 1e-3))
    np.testing.assert_allclose(z, expected, rtol=1e-9)


def test_coupled_inductor_keeps_couplings():
    model = get_model("hv-4section")
    lad = fit_inductance(lambda x: magnetising_inductance(x, 0.2557, 1.5, 0.1), 10, 1e4, 5)
    ext = replace_with_ladder(model.circuit, "La1", lad)
    assert ext.element("La1").value == pytest.approx(lad.l0)
    assert any(k.nodes[0] == "La1" for k in ext.of_kind("K"))
    z = frequency_response(ext, "a1", [50.0, 500.0])["Zin"]
    assert np.all(np.isfinite(z))


def test_replace_rejects_capacitor():
    with pytest.raises(CircuitError, match="'Ca10': only resistors and inductors"):
        replace_with_ladder(get_model("hv-4section").circuit, "Ca10", fit_resistance(lambda f: f * 0 + 1, 1, 10, 2))


@needs_ngspice
def test_extended_circuit_against_ngspice():
    model = get_model("three-section")
    lad = fit_resistance(lambda x: skin_resistance(x, 0.083, 4.0, 0.6, 1e4), 1e3, 1e7, 6)
    ext = replace_with_ladder(model.circuit.with_values({}), "R1", lad)
    f, v = ngspice.ac_analysis(ext, "n1", ["n1"], 1e3, 1e7, points_per_decade=10)
    z = frequency_response(ext, "n1", f)["Zin"]
    assert np.max(np.abs(z - v[0]) / np.abs(v[0])) < 1e-6


def test_packaged_unit_ladders_equal_a_fresh_fit():
    """The ladders kept with the package (no optimiser at start-up) are the ones the fit gives now."""
    from pris_cosim.circuits.freqdep import TransformerEffects, fit_unit_ladders, unit_ladders

    f = np.logspace(0, 5.3, 60)
    for kept, fresh in zip(unit_ladders(TransformerEffects()), fit_unit_ladders(TransformerEffects())):
        assert np.allclose(kept.impedance(f), fresh.impedance(f), rtol=1e-12, atol=0)
