"""Grouped responses of several test configurations (one network per set of shorts) and their adjoint
sensitivities, against the per-configuration responses and central finite differences."""

import numpy as np
import pytest

from pris_cosim.errors import CircuitError
from pris_cosim.models.groups import GroupedResponseSet
from pris_cosim.frf.kernels import pole_residue_sum
from pris_cosim.models.builtin import get_model


@pytest.mark.parametrize("name", ["hv-4section", "hv-6section-passive", "hv-4section-cab2b"])
def test_grouped_responses_equal_the_per_configuration_ones(name):
    m = get_model(name)
    ref = m.response_set()
    grouped = GroupedResponseSet(m.circuit, ref.configurations)
    assert len(grouped.groups) == 3  # open, LV driven with HV shorted, HV driven with LV shorted
    assert grouped.names == ref.names
    f = np.logspace(1, 5, 61)
    a, b = ref.evaluate(f), grouped.evaluate(f)
    for k in ref.names:
        assert b[k].shape == (61,)
        assert np.max(np.abs(b[k] / a[k] - 1)) < 1e-8
    rng = np.random.default_rng(0)
    lb = {f"Lb{i}": m.circuit.resolve()[f"lb{i}"] * rng.uniform(0.5, 2, 5) for i in (1, 2)}
    a, b = ref.evaluate(f, lb), grouped.evaluate(f, lb)
    for k in ref.names:
        assert b[k].shape == (5, 61)
        assert np.max(np.abs(b[k] / a[k] - 1)) < 1e-8
    d = grouped.evaluate(f, lb, method="dense")
    for k in ref.names:
        assert np.max(np.abs(d[k] / a[k] - 1)) < 1e-6
    with pytest.raises(CircuitError, match="unknown method"):
        grouped.evaluate(f, method="eig")


def test_sensitivities_match_central_differences():
    m = get_model("hv-6section-passive")
    grouped = GroupedResponseSet(m.circuit, m.response_set().configurations)
    base = {k: float(v) for k, v in m.circuit.resolve().items()}
    names = ["Rb", "Ra1", "Cb3", "Cab1", "Lb2", "La1", "Kc", "Ka1b1", "Kb2b5"]  # a tied parameter and elements
    f = np.logspace(1, 4, 31)
    over = {"Rb": 4992.0, "Kc": 0.9945}
    start = {**over, **{k: base[k.lower()] for k in names if k not in over}}
    rel = np.array([1e-5 if not k.startswith("K") else 1e-8 for k in names])  # couplings near 1: sharp curvature
    steps = np.array([start[k] for k in names]) * rel
    upper = {k: np.array([start[k] + (steps[i] / 2 if j == i else 0.0) for j in range(len(names))])
             for i, k in enumerate(names)}
    lower = {k: np.array([start[k] - (steps[i] / 2 if j == i else 0.0) for j in range(len(names))])
             for i, k in enumerate(names)}
    z0, jac = grouped.sensitivities(f, start, upper, steps, lower)
    _, one_sided = grouped.sensitivities(f, start, upper, steps / 2)
    ref = grouped.evaluate(f, start)
    for i, k in enumerate(names):
        up, down = dict(start), dict(start)
        up[k] = start[k] + 10 * steps[i]
        down[k] = start[k] - 10 * steps[i]
        # the dense solve: differences of eigen-decompositions are noisy at the 1e-8 level
        zp, zm = grouped.evaluate(f, up, method="dense"), grouped.evaluate(f, down, method="dense")
        for r in grouped.names:
            if i == 0:
                assert np.max(np.abs(z0[r] / ref[r] - 1)) < 1e-7
            fd = (zp[r] - zm[r]) / (20 * steps[i])
            scale = np.max(np.abs(fd / ref[r]))
            err = np.max(np.abs((jac[r][:, i] - fd) / ref[r]))
            assert err < 1e-4 * scale + 1e-6 / start[k], (k, r, err, scale)
            err = np.max(np.abs((one_sided[r][:, i] - fd) / ref[r]))
            assert err < 1e-2 * scale + 1e-6 / start[k], (k, r, err, scale)  # one-sided: coarser


def test_pole_residue_sum_compiled_on_request_equals_numpy():
    rng = np.random.default_rng(1)
    p = -rng.uniform(1, 10, (3, 2)) + 1j * rng.uniform(1, 100, (3, 2))
    poles = np.concatenate([p, p.conj(), -rng.uniform(1, 5, (3, 1))], axis=1)
    r = rng.normal(size=(3, 2, 2)) + 1j * rng.normal(size=(3, 2, 2))
    residues = np.concatenate([r, r.conj(), rng.normal(size=(3, 2, 1)) + 0j], axis=2)
    direct = rng.normal(size=(3, 2))
    w = np.logspace(0, 3, 20)
    a = pole_residue_sum(poles, residues, direct, w, compiled=True)
    b = pole_residue_sum(poles, residues, direct, w, compiled=False)
    assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
