"""Analytic frequency responses against independent references.

References: values quoted in models.md (ngspice and hand-derived mesh
matrices agree on them), ngspice AC analysis of the same netlists, the
thesis's three-section 7x7 mesh matrix (4.24) evaluated numerically, and
the orders of (2.2)/(2.3) for N-section cascades.
"""

import numpy as np
import pytest

from pris_cosim.circuits import ngspice
from pris_cosim.frf.response import ResponseModel, frequency_response, logspace_hz
from pris_cosim.models.builtin import cascade, get_model
from pris_cosim.circuits.netlist import read_netlist

from conftest import needs_ngspice


def rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b)))


@pytest.mark.parametrize("method", ["fast", "dense"])
def test_two_section_models_md_values(netlist_dir, method):
    c = read_netlist(netlist_dir / "two_section_table4_2.cir")
    z = frequency_response(c, "in", [10.0, 1e3, 1e5], method=method)["Zin"]
    np.testing.assert_allclose(np.abs(z), [10686.02, 319612.3, 3185.12], rtol=1e-6)


@pytest.mark.parametrize("method", ["fast", "dense"])
def test_three_section_models_md_values(netlist_dir, method):
    c = read_netlist(netlist_dir / "three_section_table4_7.cir")
    z = frequency_response(c, "n1", [1e3, 1e5], method=method)["Zin"]
    np.testing.assert_allclose(np.abs(z), [9.3493, 5033.12], rtol=1e-5)


def test_three_section_mesh_matrix_4_24():
    """Zin = det(Z)/cofactor(7,7) of the thesis's 7x7 mesh matrix, (4.5) and (4.24)."""
    p = dict(Rs=0.083, Cs=970e-12, Cg=1.6e-9, Ls=181e-6, k12=0.8792, k13=0.8729, k23=0.8564)
    f = logspace_hz(1e2, 1e7, 60)
    R, L, Cs = p["Rs"], p["Ls"], p["Cs"]
    Cg1, Cg2, Cg3 = p["Cg"] / 2, p["Cg"], p["Cg"]
    M12, M13, M23 = (p[k] * L for k in ("k12", "k13", "k23"))
    zin = []
    for s in 2j * np.pi * f:
        def x(c):
            return 1 / (s * c)

        Z = np.array([
            [R + s * L + x(Cs), s * M12, s * M13, -x(Cs), 0, 0, 0],
            [s * M12, R + s * L + x(Cs), s * M23, 0, -x(Cs), 0, 0],
            [s * M13, s * M23, R + s * L + x(Cs), 0, 0, -x(Cs), 0],
            [-x(Cs), 0, 0, x(Cs) + x(Cg1) + x(Cg2), -x(Cg2), 0, -x(Cg1)],
            [0, -x(Cs), 0, -x(Cg2), x(Cs) + x(Cg2) + x(Cg3), -x(Cg3), 0],
            [0, 0, -x(Cs), 0, -x(Cg3), x(Cs) + x(Cg3), 0],
            [0, 0, 0, -x(Cg1), 0, 0, x(Cg1)],
        ], dtype=complex)
        zin.append(np.linalg.det(Z) / np.linalg.det(Z[:6, :6]))
    ours = frequency_response(get_model("three-section").circuit, "n1", f)["Zin"]
    assert rel(ours, zin) < 1e-8


def test_fast_equals_dense_on_every_model():
    f = logspace_hz(10, 1e6, 300)
    for name in ["two-section", "three-section", "cascade-6", "cascade-5-open", "hv-4section", "hv-4section-cab2a",
                 "hv-4section-cab2b"]:
        rs = get_model(name).response_set()
        fast, dense = rs.evaluate(f, method="fast"), rs.evaluate(f, method="dense")
        for key in fast:
            assert rel(fast[key], dense[key]) < 1e-7, (name, key)


def test_population_equals_one_by_one():
    rng = np.random.default_rng(1)
    m = get_model("hv-4section")
    rs = m.response_set(["LVOC", "HVSC", "LVHV"])
    f = logspace_hz(10, 1e5, 50)
    P = 5
    over = {"La1": 0.2557 * rng.uniform(0.8, 1.2, P), "Rb": 4475 * rng.uniform(0.5, 2, P),
            "Cab1": 54.7e-12 * rng.uniform(0.5, 2, P)}
    batch = rs.evaluate(f, over)
    for p in range(P):
        single = rs.evaluate(f, {k: float(v[p]) for k, v in over.items()})
        for key in batch:
            assert batch[key].shape == (P, f.size)
            assert rel(batch[key][p], single[key]) < 1e-12


def test_two_winding_models_match_reference_netlists(netlist_dir):
    """The built-in models and the independently written netlists describe the same networks."""
    f = logspace_hz(10, 1e6, 120)
    for name, file in [("hv-4section", "hv_transformer_4section_table5_4.cir"),
                       ("hv-6section", "hv_transformer_6section_table5_12.cir")]:
        model, ref = get_model(name), read_netlist(netlist_dir / file)
        with pytest.warns(UserWarning) if name == "hv-6section" else _nullcontext():
            for cfg in model.configurations.values():
                resp = cfg.responses[0]
                ours = model.response_set([cfg.name]).evaluate(f)[resp.name]
                theirs = frequency_response(ref, cfg.port, f, ratios=[resp.node] if resp.node else [], shorts=cfg.shorts)
                theirs = theirs[f"V_{resp.node}"] if resp.node else theirs["Zin"]
                assert rel(ours, theirs) < 1e-8, (name, cfg.name)


class _nullcontext:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


def _peaks(f, mag):
    i = np.flatnonzero((mag[1:-1] > mag[:-2]) & (mag[1:-1] > mag[2:])) + 1
    return f[i]


def _dips(f, mag):
    return _peaks(f, 1 / mag)


def test_two_winding_resonances_as_described():
    """models.md: LVOC parallel near 50 Hz and series near 1 kHz; HVOC parallel near 60-70 Hz;
    HVSC main parallel at 1 kHz; LV-to-HV ratio near 400 at low frequency (nominal 1:435)."""
    f = logspace_hz(10, 2e4, 4000)
    r = get_model("hv-4section").response_set().evaluate(f)
    lvoc = np.abs(r["Zlvoc"])
    assert 35 < _peaks(f, lvoc)[0] < 70
    assert 700 < _dips(f, lvoc)[0] < 1400
    assert 45 < _peaks(f, np.abs(r["Zhvoc"]))[0] < 80
    hvsc = np.abs(r["Zhvsc"])
    assert 800 < f[np.argmax(hvsc)] < 1250
    assert 300 < np.abs(r["Rlvhv"][0]) < 450


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_cascade_orders_2_2_and_2_3(n):
    """Neutral open: Zin of order 2N/(2N+1) with a pole at s = 0; grounded: (2N-1)/2N, finite DC value."""
    f = np.array([1e-3, 1e-2, 1e10, 1e11])
    open_, grounded = cascade(n, neutral="open"), cascade(n)
    for model, order in ((open_, 2 * n + 1), (grounded, 2 * n)):
        rm = ResponseModel(model.circuit, "n1")
        pr = rm.poles_residues()
        assert pr.poles.shape[1] == order
    zo = frequency_response(open_.circuit, "n1", f)["Zin"]
    zg = frequency_response(grounded.circuit, "n1", f)["Zin"]
    # open neutral: capacitive at DC (|Z| ~ 1/f), so numerator degree = denominator - 1 at s -> 0 too
    assert abs(zo[0] / zo[1]) == pytest.approx(10, rel=1e-3)
    # grounded: DC resistance = sum of section resistances
    assert zg[0].real == pytest.approx(n * 0.083, rel=1e-4)
    # both: relative degree one at high frequency (|Z| ~ 1/f)
    for z in (zo, zg):
        assert abs(z[2] / z[3]) == pytest.approx(10, rel=1e-3)


CASES = [
    ("two_section_table4_2.cir", "in", ["mid"], []),
    ("three_section_table4_7.cir", "n1", ["n2", "n3"], []),
    ("hv_transformer_4section_table5_4.cir", "a1", ["b1", "b3"], []),
    ("hv_transformer_4section_table5_4.cir", "a1", [], ["b1"]),
    ("hv_transformer_4section_table5_4.cir", "b1", ["a1"], []),
    ("hv_transformer_4section_table5_4.cir", "b1", [], ["a1"]),
    ("hv_transformer_6section_table5_12.cir", "b1", ["a1"], []),
    ("hv_transformer_6section_table5_12.cir", "a1", [], ["b1"]),
]


@needs_ngspice
@pytest.mark.filterwarnings("ignore::pris_cosim.errors.NonPassiveWarning")
@pytest.mark.parametrize("file, port, ratios, shorts", CASES)
@pytest.mark.parametrize("method", ["fast", "dense"])
def test_against_ngspice_ac(netlist_dir, file, port, ratios, shorts, method):
    c = read_netlist(netlist_dir / file)
    f, v = ngspice.ac_analysis(c.shorted(shorts), port, [port] + ratios, 10.0, 1e6, points_per_decade=20)
    ours = frequency_response(c, port, f, ratios=ratios, shorts=shorts, method=method)
    assert rel(ours["Zin"], v[0]) < 1e-6
    for j, node in enumerate(ratios, start=1):
        assert rel(ours[f"V_{node}"], v[j] / v[0]) < 1e-6
