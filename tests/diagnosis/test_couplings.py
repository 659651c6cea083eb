"""Couplings freed by a missing section (closed forms)."""

import numpy as np

from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.causes.sections import coupling_decay, find_chains, split_section
from pris_cosim.models.builtin import get_model


def _fit(model, couplings=(), effects=()):
    f = np.logspace(1, 4, 120)
    cfg = list(model.configurations.values())
    return FrequencyFit(model.circuit, cfg, f, {"Zlvoc": np.ones(f.size, complex)}, effects=effects,
                        couplings=couplings)


def test_freed_coupling_is_fitted_in_log_leakage_and_stays_in_0_1():
    model = get_model("hv-4section")
    fit = _fit(model, couplings=["Kb1b2", "Kb2b3"])
    assert fit.free[-2:] == ["Kb1b2", "Kb2b3"] and fit.nc == len(fit.free)
    k0 = np.array([0.9943, 0.9981])  # Table 5.4
    x = np.zeros(fit.nc)
    x[-2:] = [np.log(2.0), -np.log(4.0)]  # leakage doubled, quartered
    v = fit.overrides(x)
    assert np.isclose(v["Kb1b2"], 1 - 2 * (1 - k0[0])) and np.isclose(v["Kb2b3"], 1 - (1 - k0[1]) / 4)
    lo, hi = fit.bounds()
    for edge in (lo, hi):
        k = fit.values_of(edge[: fit.nc])[-2:]
        assert np.all((k >= 0) & (k < 1))
    assert "Kb1b2" not in _fit(model).free  # couplings stay fixed unless named


def test_split_section_names_the_couplings_it_touches():
    circuit = get_model("hv-4section").circuit
    chains = find_chains(circuit, ["a1", "b1"])
    hv = next(c for c in chains if c.port == "b1")
    cand = split_section(circuit, hv, 1, coupling_decay(circuit, chains, circuit.resolve(check=False)))
    # Lb2 couples to La1, Lb1, Lb3, Lb4 and Lc; its new half to those five and to Lb2
    assert len(cand.couplings) == 11
    new_l = next(n for n in cand.new_elements if n.upper().startswith("L"))
    for name in cand.couplings:
        assert {"lb2", new_l.lower()} & {n.lower() for n in cand.circuit.element(name).nodes}

