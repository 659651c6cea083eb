"""Analytic Jacobian of the diagnosis fits (nodal adjoint) against central differences of the responses.

The responses come from the state-space reduction and its eigen-decomposition
(:meth:`estimation.diagnosis.network.ProbedConfiguration.transfer`); the
analytic columns from the full nodal system's adjoint, or from the same
eigen-decomposition through reciprocity. Central differences of the first
check both derivative routes.
"""

import hidden_cases as hc
import numpy as np
import pytest

from estimation.diagnosis.causes import catalogue as cat
from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.prior import DesignPrior
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration, get_model
from pris_cosim.circuits.netlist import parse_netlist


def _central(fit: FrequencyFit, x: np.ndarray, h: float) -> np.ndarray:
    cols = []
    for j in range(fit.nc):
        e = np.zeros(x.size)
        e[j] = h
        cols.append((fit.residuals(x + e) - fit.residuals(x - e)) / (2 * h))
    return np.array(cols).T


def _moved(fit: FrequencyFit, seed: int = 1) -> np.ndarray:
    """A start vector with every circuit value moved by about 10 %."""
    x = fit.start_vectors()[0]
    x[: fit.nc] += 0.1 * np.random.default_rng(seed).standard_normal(fit.nc)
    lo, hi = fit.bounds()
    return np.clip(x, lo + 1e-3, hi - 1e-3)


def _one_port():
    case = hc.one_port_case(("skin-effect",), 7, sections=4, points=120)
    circuit = parse_netlist(case.baseline_netlist)
    f = case.frequency_hz
    data = {"Zin": next(iter(case.measured.values()))}
    return circuit, [Configuration("default", case.port, (), (Response("Zin"),))], f, data


def _one_port_effects(f: np.ndarray, scale: float) -> list:
    w = 2 * np.pi * f[-1]
    return [
        [],
        [cat.SkinEffect(form="causal", f_ref=f[0])],
        [cat.SkinEffect(form="thesis", f_ref=f[0])],
        [cat.SkinEffect(form="relaxation", f_ref=f[0], f_max=f[-1])],
        [cat.CoreLoss(form="causal", f_ref=f[0])],
        [cat.MagnetisingInductance(form="causal", f_ref=f[0])],
        [cat.MagnetisingInductance(form="relaxation", f_ref=f[0], f_max=f[-1])],
        [cat.StrayCapacitance(form="causal", group="port", f_ref=f[-1], c_scale=1 / (w * scale))],
        [cat.LeadInductance(form="causal", group="port", f_ref=f[-1], l_scale=scale / w, r_scale=scale)],
        [cat.SkinEffect(form="causal", f_ref=f[0]), cat.CoreLoss(form="thesis", f_ref=f[0]),
         cat.StrayCapacitance(form="causal", group="port", f_ref=f[-1], c_scale=1 / (w * scale))],
        [cat.SkinEffect(form="causal", f_ref=f[0], level=True)],
        [cat.MagnetisingInductance(form="causal", f_ref=f[0], level=True)],
        [cat.MagnetisingInductance(form="thesis", f_ref=f[0], level=True)],
        [cat.MagnetisingInductance(form="relaxation", f_ref=f[0], f_max=f[-1], level=True)],
    ]


@pytest.mark.parametrize("which", range(14))
def test_one_port_circuit_columns_match_central_differences(which):
    circuit, cfg, f, data = _one_port()
    scale = float(np.median(np.abs(data["Zin"])))
    effects = _one_port_effects(f, scale)[which]
    design = FrequencyFit(circuit, cfg, f, data)
    prior = DesignPrior({n.lower(): v for n, v in zip(design.free, design.start)}, 0.2, 1e-4)
    fit = FrequencyFit(circuit, cfg, f, data, effects=effects, scale=scale, prior=prior)
    fit.analytic_jacobian = True
    assert any(e.kind == "K" for e in fit.circuit.elements)  # mutual inductances between the sections
    x = _moved(fit)
    J = fit.jacobian(x)
    assert J.shape == (fit.residuals(x).size, x.size)
    ref = _central(fit, x, 1e-6)
    assert np.max(np.abs(J[:, : fit.nc] - ref)) <= 1e-6 * np.max(np.abs(ref))
    fit.analytic_jacobian = False  # the effects' columns are the same forward differences either way
    assert np.allclose(fit.jacobian(x)[:, fit.nc:], J[:, fit.nc:], rtol=0, atol=1e-9 * np.max(np.abs(J)))


def test_smoothed_errors_and_the_nodal_solve_give_the_same_columns():
    circuit, cfg, f, data = _one_port()
    fit = FrequencyFit(circuit, cfg, f, data, effects=[cat.SkinEffect(form="causal", f_ref=f[0])])
    fit.analytic_jacobian = True
    x = _moved(fit, seed=2)
    fit.smooth(0.03)
    J = fit.jacobian(x)
    assert np.max(np.abs(J[:, : fit.nc] - _central(fit, x, 1e-6))) <= 1e-6 * np.max(np.abs(J[:, : fit.nc]))
    for m in fit.models:  # without the kept eigen-decomposition: one nodal solve per frequency
        m._kept = None
    assert np.allclose(fit.jacobian(x), J, rtol=0, atol=1e-9 * np.max(np.abs(J)))


@pytest.mark.parametrize("couplings", [(), ("Kb1b2", "Ka1b1")])
def test_six_responses_with_a_parameter_couplings_and_voltage_ratios(couplings):
    model = get_model("hv-4section")  # Rb is a .param shared by the HV sections
    case = hc.two_winding_case(("magnetising-inductance",), 3, group="hv", points=60)
    cfg = list(model.configurations.values())
    effects = [cat.MagnetisingInductance(form="causal", f_ref=case.frequency_hz[0], group="hv")]
    fit = FrequencyFit(model.circuit, cfg, case.frequency_hz, case.measured, tuple(model.fixed), effects=effects,
                       scale=100.0, couplings=couplings)
    fit.analytic_jacobian = True
    assert "Rb" in fit.free and {r for m in fit.models for r in m._impedances} < set(case.measured)
    x = _moved(fit, seed=3)
    J = fit.jacobian(x)[:, : fit.nc]
    # the responses' own rounding (eigenvectors of a stiff network) needs a larger step
    ref = _central(fit, x, 1e-4)
    assert np.max(np.abs(J - ref)) <= 1e-5 * np.max(np.abs(ref))


@pytest.mark.parametrize("which", [10, 11, 12])
def test_level_columns_match_central_differences(which):
    """The free levels' columns (``c`` of the causal skin form, ``k`` of the magnetising forms) against central
    differences."""
    circuit, cfg, f, data = _one_port()
    scale = float(np.median(np.abs(data["Zin"])))
    effects = _one_port_effects(f, scale)[which]
    fit = FrequencyFit(circuit, cfg, f, data, effects=effects, scale=scale)
    x = _moved(fit)
    x[-1] = np.log(1.3)  # the level, off 1
    J = fit.jacobian(x)[:, -1]
    e = np.zeros(x.size)
    e[-1] = 1e-5
    ref = (fit.residuals(x + e) - fit.residuals(x - e)) / 2e-5
    assert np.max(np.abs(ref)) > 0 and np.max(np.abs(J - ref)) <= 1e-3 * np.max(np.abs(ref))
