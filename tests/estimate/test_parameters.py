"""Estimation parameters: bounds, unit cube, ties, thesis scaling, passivity repair, identifiability."""

from __future__ import annotations

import numpy as np
import pytest

from estimation.parameters import (Parameter, ParameterSet, coupling_matrix, engineering_scale, identifiability,
    shrink_fraction)
from pris_cosim.models.builtin import get_model


@pytest.fixture(scope="module")
def hv4():
    return get_model("hv-4section")


# ---------------------------------------------------------------------- Parameter
def test_error_names_the_parameter():
    with pytest.raises(ValueError, match=r"^Parameter 'Rb': min 5 >= max 1$"):
        Parameter("Rb", 3.0, min=5.0, max=1.0)
    with pytest.raises(ValueError, match="Parameter 'Cs': log scale needs min > 0"):
        Parameter("Cs", 1e-9, min=0.0, max=1e-8, scale="log")
    with pytest.raises(ValueError, match="Parameter 'Ls': value 5 outside"):
        Parameter("Ls", 5.0, min=1.0, max=2.0)
    with pytest.raises(ValueError, match="Parameter 'k': a varying parameter needs finite bounds"):
        Parameter("k", 0.5)
    with pytest.raises(ValueError, match="Parameter 'x': scale must be"):
        Parameter("x", 1.0, 0.0, 2.0, scale="sine")


def test_log_scaling_maps_bounds_to_0_and_1_and_midpoint_to_geometric_mean():
    p = Parameter("C1", 1e-9, 1e-10, 1e-8, scale="log")
    assert p.to_unit(1e-10) == pytest.approx(0.0, abs=1e-15)
    assert p.to_unit(1e-8) == pytest.approx(1.0, abs=1e-15)
    assert p.from_unit(0.5) == pytest.approx(1e-9, rel=1e-14)
    lin = Parameter("k12", 0.5, 0.0, 0.9999)
    assert lin.to_unit(0.0) == 0.0 and lin.to_unit(0.9999) == 1.0
    assert lin.from_unit(0.5) == pytest.approx(0.49995, rel=1e-15)


# ---------------------------------------------------------------------- from_circuit
def test_hv4_has_33_varying_and_hv6_with_fixed_lc_has_43(hv4):
    assert len(ParameterSet.from_circuit(hv4.circuit).varying) == 33  # thesis Case Study 1: 33 parameters
    hv6 = get_model("hv-6section")
    by_circuit = ParameterSet.from_circuit(hv6.circuit, fixed=["Lc"])
    by_model = ParameterSet.from_model(hv6)
    assert len(by_circuit.varying) == len(by_model.varying) == 43  # Case Study 3: 43 parameters
    assert "Lc" not in by_model.varying and by_model["lc"].value == 100.0


def test_default_bounds_scales_and_thesis_theta_scale():
    ps = ParameterSet.from_circuit(get_model("three-section").circuit)
    assert ps.varying == ["Rs", "Cs", "Cg", "Ls", "k12", "k13", "k23"]  # (4.27)
    assert [ps[n].theta_scale for n in ps.varying] == pytest.approx([1e-3, 1e-12, 1e-9, 1e-6, 1e-2, 1e-2, 1e-2])  # (4.28)
    assert ps["Rs"].scale == "log" and (ps["Rs"].min, ps["Rs"].max) == pytest.approx((0.0083, 0.83))
    assert ps["k12"].scale == "linear" and (ps["k12"].min, ps["k12"].max) == (0.0, 0.9999)
    x = ps.to_scaled(ps.values())
    assert x == pytest.approx([83.0, 970.0, 1.6, 181.0, 87.92, 87.29, 85.64])
    assert ps.from_scaled(x)["Cs"] == pytest.approx(970e-12, rel=1e-14)
    assert engineering_scale(0.083) == 1e-3 and engineering_scale(4.475e3) == 1e3


def test_table_4_8_bounds_in_scaled_units():
    bounds = {"Rs": (1e-3, 1.0), "Cs": (1e-12, 1e-9), "Cg": (1e-9, 1e-6), "Ls": (1e-6, 1e-3),
              "k12": (0.85, 0.95), "k13": (0.85, 0.95), "k23": (0.85, 0.95)}
    ps = ParameterSet.from_circuit(get_model("three-section").circuit, bounds=bounds)
    expected = [[1, 1000]] * 4 + [[85, 95]] * 3
    assert ps.scaled_bounds() == pytest.approx(np.array(expected, float))


def test_relative_factor_bounds_and_errors_name_the_parameter(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit, bounds={"Rb": 2.0, "La1": (0.1, 1.0)})
    assert (ps["Rb"].min, ps["Rb"].max) == pytest.approx((4.475e3 / 2, 4.475e3 * 2))
    assert (ps["La1"].min, ps["La1"].max) == (0.1, 1.0)
    with pytest.raises(ValueError, match="Parameter 'Ka1b1': a coupling needs absolute bounds"):
        ParameterSet.from_circuit(hv4.circuit, bounds={"Ka1b1": 2.0})
    with pytest.raises(ValueError, match="Parameter 'Rb1'"):
        ParameterSet.from_circuit(hv4.circuit, fixed=["Rb1"])  # tied element, not independent


# ---------------------------------------------------------------------- unit cube
def test_round_trip_unit_values_unit(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit)
    u = np.random.default_rng(1).random((500, 33))
    back = ps.to_unit(ps.from_unit(u))
    assert back.shape == (500, 33)
    assert np.max(np.abs(back - u)) < 1e-12
    one = ps.from_unit(u[0])
    assert isinstance(one["Rb"], float)
    assert np.max(np.abs(ps.to_unit(one) - u[0])) < 1e-12


def test_default_values_are_the_circuit_values(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit)
    values = ps.values()
    assert values["Lb3"] == 2916.0 and values["Kb3b4"] == 0.9983
    u = ps.to_unit(values)
    assert np.all((u > 0) & (u < 1))


def test_overrides_feed_response_set_for_a_population(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit)
    u = np.vstack([ps.to_unit(ps.values()), np.random.default_rng(2).random((3, 33))])
    over = ps.overrides(u)
    assert all(np.shape(v) == (4,) for v in over.values())
    f = np.logspace(1, 4, 20)
    out = hv4.response_set(["LVOC"]).evaluate(f, over)
    nominal = hv4.response_set(["LVOC"]).evaluate(f)
    assert out["Zlvoc"].shape == (4, 20)
    np.testing.assert_allclose(out["Zlvoc"][0], nominal["Zlvoc"], rtol=1e-10)


# ---------------------------------------------------------------------- ties
def test_circuit_tie_three_section_cg1_is_half_cg():
    circuit = get_model("three-section").circuit
    ps = ParameterSet.from_circuit(circuit)
    u = np.random.default_rng(3).random((50, 7))
    values = circuit.resolve(ps.overrides(u))
    np.testing.assert_allclose(values["cg1"], ps.from_unit(u)["Cg"] / 2, rtol=1e-15)
    np.testing.assert_allclose(values["cg2"], ps.from_unit(u)["Cg"], rtol=1e-15)


def test_two_section_ties_give_the_thesis_vector():
    circuit = get_model("two-section").circuit
    ps = ParameterSet.from_circuit(circuit, ties={"C2": "C1", "R2": "R1"})
    assert ps.varying == ["R1", "C1", "L1", "L2", "M12"]  # (4.22) with M12 for k12
    values = ps.values(np.random.default_rng(4).random((10, 5)))
    np.testing.assert_array_equal(values["C2"], values["C1"])
    np.testing.assert_array_equal(values["R2"], values["R1"])


def test_hv6_like_core_coupling_tie_on_hv4(hv4):
    core = ["Kb1c", "Kb2c", "Kb3c", "Kb4c"]
    ps = ParameterSet.from_circuit(hv4.circuit, ties={k: "Ka1c" for k in core})
    assert len(ps.varying) == 29 and ps.tied == core
    u = np.random.default_rng(5).random((20, 29))
    over = ps.overrides(u)
    resolved = hv4.circuit.resolve(over)
    for k in core:
        np.testing.assert_array_equal(resolved[k.lower()], over["Ka1c"])


def test_ties_evaluate_in_dependency_order_and_report_cycles():
    ps = ParameterSet([
        Parameter("a", 0.0, expr="2*b"),       # declared before its input
        Parameter("b", 0.0, expr="c + 1"),
        Parameter("c", 1.0, 0.0, 10.0),
    ])
    v = ps.values(np.array([[0.5], [0.1]]))
    np.testing.assert_allclose(v["a"], 2 * (np.array([5.0, 1.0]) + 1))
    with pytest.raises(ValueError, match="Parameters 'x', 'y': tied expressions depend on each other"):
        ParameterSet([Parameter("x", 0.0, expr="y"), Parameter("y", 0.0, expr="x")]).values()
    with pytest.raises(ValueError, match="Parameter 'x': unknown name 'z'"):
        ParameterSet([Parameter("x", 0.0, expr="z")]).values()


# ---------------------------------------------------------------------- passivity
def _random_couplings(ps: ParameterSet, n: int, rng: np.random.Generator) -> np.ndarray:
    values = {k: np.full(n, v) for k, v in ps.values().items()}
    for name in ps.couplings:
        values[name] = rng.uniform(0.99, 0.9999, n)
    return ps.to_unit(values)


def test_repair_makes_1000_random_hv4_coupling_sets_positive_definite(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit)
    u = _random_couplings(ps, 1000, np.random.default_rng(6))
    before = hv4.circuit.smallest_inductance_eigenvalue(hv4.circuit.resolve(ps.values(u)))
    assert np.sum(before <= 0) > 500  # most random sets are unphysical
    ev = ps.evaluate(u)
    after = hv4.circuit.smallest_inductance_eigenvalue(hv4.circuit.resolve(ev.overrides))
    assert np.all(after > 0)
    np.testing.assert_array_equal(ev.repaired, before <= 0)
    # the shrink is the smallest one: lambda_min(K') lands on eps
    K = coupling_matrix(hv4.circuit, hv4.circuit.resolve(ev.overrides))
    lam = np.linalg.eigvalsh(K)[:, 0]
    np.testing.assert_allclose(lam[ev.repaired], ps.eps, rtol=1e-6)
    # the repaired values are consistent with the reported unit-cube point
    np.testing.assert_allclose(ps.from_unit(ev.unit)["Ka1b1"], ev.overrides["Ka1b1"], rtol=1e-12)


def test_repair_leaves_passive_sets_unchanged(hv4):
    ps = ParameterSet.from_circuit(hv4.circuit)
    nominal = ps.to_unit(ps.values())  # Table 5.4: positive definite
    u = np.vstack([nominal, _random_couplings(ps, 5, np.random.default_rng(7)), nominal])
    ev = ps.evaluate(u)
    assert not ev.repaired[0] and not ev.repaired[-1] and ev.repaired[1:-1].any()
    plain = ps.values(u)
    for name, value in plain.items():
        assert ev.overrides[name][0] == value[0] and ev.overrides[name][-1] == value[-1]
    np.testing.assert_array_equal(ev.unit[0], nominal)


def test_hv6_table_5_12_is_flagged_and_penalty_mode_does_not_repair():
    model = get_model("hv-6section")
    repair = ParameterSet.from_model(model)
    u = repair.to_unit(repair.values())
    ev = repair.evaluate(u)
    assert not ev.passive[0] and ev.repaired[0]
    assert model.circuit.smallest_inductance_eigenvalue(model.circuit.resolve(ev.overrides)) > 0
    # the tied core coupling Kc is shrunk as a parameter and in every element it drives
    assert ev.values["Kc"] == pytest.approx(0.9979 * (1 - ev.shrink[0]), rel=1e-14)
    penalty = ParameterSet.from_model(model, passivity="penalty")
    evp = penalty.evaluate(u)
    assert not evp.passive[0] and not evp.repaired[0]
    assert evp.overrides["Kc"] == 0.9979


def test_repair_of_circuit_parameter_couplings_three_section():
    circuit = get_model("three-section").circuit
    ps = ParameterSet.from_circuit(circuit)
    values = ps.values()
    values.update(k12=0.9999, k13=0.0, k23=0.9999)  # K not positive definite
    ev = ps.evaluate(ps.to_unit(values))
    assert ev.repaired[0]
    resolved = circuit.resolve(ev.overrides)
    assert circuit.smallest_inductance_eigenvalue(resolved) > 0
    assert resolved["k12"] == pytest.approx(ev.values["k12"], rel=1e-15)


def test_shrink_fraction_closed_form():
    lam = np.array([-0.5, 0.0, 1e-7, 0.3])
    t = shrink_fraction(lam, eps=1e-6)
    np.testing.assert_allclose((1 - t) * lam + t, [1e-6, 1e-6, 1e-6, 0.3], rtol=1e-9)
    assert t[-1] == 0.0


# ---------------------------------------------------------------------- identifiability
def test_identifiability_detects_a_product_pair():
    x = np.linspace(0.1, 2.0, 40)
    p = ParameterSet([Parameter("a", 1.0, 0.5, 2.0), Parameter("b", 1.0, 0.5, 2.0), Parameter("c", 1.0, 0.5, 2.0)])

    def residual(u):
        v = p.from_unit(u)
        return v["a"] * v["b"] * x + v["c"] * x**2

    report = identifiability(residual, p.varying, u0=np.full(3, 0.3))
    assert report.groups == [("a", "b")]
    assert [(a, b) for a, b, _ in report.correlated] == [("a", "b")]
    assert report.correlated[0][2] == pytest.approx(-1.0, abs=1e-6)
    assert not report.identifiable


def test_identifiability_of_a_well_posed_and_an_insensitive_problem():
    rng = np.random.default_rng(8)
    J = rng.normal(size=(50, 3))
    ok = identifiability(J, ["x", "y", "z"])
    assert ok.identifiable and ok.groups == [] and ok.correlated == []
    J[:, 1] = 0.0
    bad = identifiability(J, ["x", "y", "z"])
    assert bad.insensitive == ["y"] and bad.correlated == []


def test_identifiability_groups_do_not_depend_on_the_null_space_basis():
    J = np.random.default_rng(9).normal(size=(30, 5))
    J[:, 1] = 2 * J[:, 0]          # a and b enter only through a + 2 b
    J[:, 4] = J[:, 2] + J[:, 3]    # e duplicates c + d
    report = identifiability(J, ["a", "b", "c", "d", "e"])
    assert report.groups == [("a", "b"), ("c", "d", "e")]
