"""The exported Modelica texts compile and simulate in an independent Modelica compiler (rumoca, from PyPI).

The Modelica Standard Library is not installed here, so the test supplies
the few MSL 4 classes the texts use (``tests/data/modelica/msl_subset.mo``,
their defining equations written out: Kirchhoff pins, R, C, L, the mutual
inductance matrix of ``M_Transformer``, signal sources). rumoca flattens the
texts, reduces the DAE and integrates it with its own solver; the results are
compared with the exact ZOH engine.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pris_cosim.fmi import codegen
from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.fmi.modelica import modelica_text
from pris_cosim.models.builtin import get_model
from pris_cosim.signals.perturbation import lfsr_prbs

rumoca = pytest.importorskip("rumoca", reason="no Modelica compiler: pip install rumoca (the 'test' extra)")

THREE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
TWO = SourceSettings(vdc=30.0, prbs_order=4, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9)
MSL_SUBSET = Path(__file__).parents[1] / "data" / "modelica" / "msl_subset.mo"


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("modelica")
    (root / "Modelica").mkdir()
    shutil.copyfile(MSL_SUBSET, root / "Modelica" / "package.mo")
    return rumoca.Session(roots=[str(root)])


def _simulate(session, model: codegen.NetworkModel, stop: float, fs: float, inputs=None) -> dict[str, np.ndarray]:
    text = modelica_text(model)
    top, prefix = model.identifier, ""
    if inputs:  # a constant input bound by an enclosing model (rumoca takes no time-varying inputs yet)
        binds = "".join(f"  m.{k} = {float(v)!r};\n" for k, v in inputs.items())
        text += f"model wrapped\n  {model.identifier} m;\nequation\n{binds}end wrapped;\n"
        top, prefix = "wrapped", "m."
    compiled = session.loads(text, model=top)
    config = rumoca.SimConfig(solver="bdf", rtol=1e-10, atol=1e-12, dt=1 / fs)
    res = compiled.simulate((0.0, stop), config=config)
    t = np.asarray(res.time)
    data = res.to_numpy()
    grid = np.arange(int(round(stop * fs)) + 1) / fs
    rows = np.searchsorted(t, grid * (1 + 1e-12), side="right") - 1  # the value after any event at a grid time
    assert np.abs(t[rows] - grid).max() < 1e-9 / fs
    names = [n[len(prefix):] if n.startswith(prefix) else n for n in res.names]
    return {n: data[names.index(n)][rows] for n in ("v_in", "i_in", "v_bprbs") if n in names}


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_source_and_arrangement_texts_use_when_and_pre():
    for model in (codegen.source_model(THREE), codegen.arrangement_model(get_model("three-section").circuit, "n1",
                                                                         THREE)):
        text = modelica_text(model)
        assert "algorithm" not in text and "pre(reg)" in text and "when sample(1 / fclk, 1 / fclk)" in text


@pytest.mark.parametrize("dut, port, settings, stop, fs", [("three-section", "n1", THREE, 2e-4, 1e7),
                                                           ("two-section", "in", TWO, 1.4e-3, 1e6)])
def test_arrangement_text_equals_the_exact_engine(session, dut, port, settings, stop, fs):
    circuit = get_model(dut).circuit
    got = _simulate(session, codegen.arrangement_model(circuit, port, settings, name="arr"), stop, fs)
    ref = td.simulate_pris(circuit, port, settings, fs)
    n = got["v_in"].size
    np.testing.assert_array_equal(got["v_bprbs"], ref["v_bprbs"][:n])  # the when/pre LFSR is the PRBS
    assert _rel(got["v_in"], ref["v_in"][:n]) < 1e-6
    assert _rel(got["i_in"], ref["i_in"][:n]) < 1e-6


def test_source_text_equals_the_exact_engine(session):
    fs, stop = 1e7, 1e-4
    model = codegen.source_model(THREE, name="src")
    got = _simulate(session, model, stop, fs, inputs={"v_in": 0.0})
    ss = model.mna.state_space(model.circuit.resolve())
    n = got["i_in"].size
    bits = lfsr_prbs(THREE.prbs_order, 1)
    bridge = np.where(bits[(np.arange(n) * THREE.fclk / fs).astype(int) % bits.size] == 1, THREE.vdc, -THREE.vdc)
    x, _ = td.simulate_pwc(ss, np.column_stack([bridge, np.zeros(n)]), 1 / fs)
    i_ref = x[:, model.mna.states.index("i(Lpris)")]
    np.testing.assert_array_equal(got["v_bprbs"], bridge)
    assert _rel(got["i_in"], i_ref) < 1e-6


def test_dut_text_equals_current_injection(session):
    fs, stop = 1e7, 5e-5
    circuit = get_model("three-section").circuit
    got = _simulate(session, codegen.dut_model(circuit, "n1", name="dut"), stop, fs, inputs={"i_in": 1e-3})
    n = got["v_in"].size
    ref = td.simulate_current_injection(circuit, "n1", np.full(n, 1e-3), fs)
    assert _rel(got["v_in"], ref["v_in"]) < 1e-6


def test_bridge_text_gives_the_prbs(session):
    fs, stop = 1e7, 1e-4
    got = _simulate(session, codegen.bridge_model(THREE, name="bri"), stop, fs)
    n = got["v_bprbs"].size
    bits = lfsr_prbs(THREE.prbs_order, 1)
    bridge = np.where(bits[(np.arange(n) * THREE.fclk / fs).astype(int) % bits.size] == 1, THREE.vdc, -THREE.vdc)
    np.testing.assert_array_equal(got["v_bprbs"], bridge)


def test_load_text_equals_the_arrangement_driven_by_a_constant_bridge_voltage(session):
    fs, stop = 1e7, 5e-5
    circuit = get_model("three-section").circuit
    got = _simulate(session, codegen.load_model(circuit, "n1", THREE, name="lod"), stop, fs,
                    inputs={"v_bprbs": 5.0})
    arr = codegen.arrangement_model(circuit, "n1", THREE)
    n = got["v_in"].size
    x, y = td.simulate_pwc(arr.mna.state_space(arr.circuit.resolve()), np.full((n, 1), 5.0), 1 / fs)
    assert _rel(got["i_in"], x[:, arr.mna.states.index("i(Lpris)")]) < 1e-6
    assert _rel(got["v_in"], y[:, arr.mna.nodes.index("n1")]) < 1e-6
