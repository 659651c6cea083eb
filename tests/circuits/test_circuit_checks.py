"""Physical and structural checks: each error names the element or node."""

import warnings

import numpy as np
import pytest

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError, NonPassiveError, NonPassiveWarning
from pris_cosim.frf.response import frequency_response
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import get_model
from pris_cosim.circuits.netlist import parse_netlist, read_netlist


def rlc() -> Circuit:
    return parse_netlist("* t\nR1 a b 10\nL1 b 0 1m\nC1 a 0 1n\nL2 a 0 2m\n")


@pytest.mark.parametrize("name, value, match", [
    ("R1", -1.0, "element 'R1': resistance must be positive"),
    ("R1", 0.0, "element 'R1': resistance must be positive"),
    ("L1", -1e-3, "element 'L1': inductance must be positive"),
    ("C1", 0.0, "element 'C1': capacitance must be positive"),
    ("C1", float("nan"), "element 'C1': value is not finite"),
])
def test_non_positive_values(name, value, match):
    with pytest.raises(CircuitError, match=match):
        rlc().resolve({name: value})


def test_population_checks_every_member():
    with pytest.raises(CircuitError, match="'R1'.*-2"):
        rlc().resolve({"R1": np.array([1.0, -2.0, 3.0])})


@pytest.mark.parametrize("k", [1.0, -1.0, 1.5])
def test_coupling_bounds(k):
    c = rlc()
    c.add("K1", "L1", "L2", k)
    with pytest.raises(CircuitError, match=r"element 'K1': coupling \|k\| must be below 1"):
        c.resolve()


def test_coupling_to_unknown_inductor():
    c = rlc()
    c.add("K1", "L1", "L9", 0.5)
    with pytest.raises(CircuitError, match="element 'K1': 'l9' is not an inductor"):
        c.check_topology()


def test_floating_node():
    c = rlc()
    c.add("R9", "x", "y", 1.0)
    with pytest.raises(CircuitError, match="node 'x' is floating"):
        c.check_topology()


def test_capacitor_voltage_source_loop():
    c = parse_netlist("* t\nV1 a 0 DC 1\nC1 a b 1n\nC2 b 0 1n\nR1 b 0 1k\n")
    with pytest.raises(CircuitError, match="element 'V1': voltage source closes a loop of capacitors"):
        c.check_topology()


def test_unknown_port_and_ratio_node():
    with pytest.raises(CircuitError, match="port 'zz' is not a node"):
        frequency_response(rlc(), "zz", [1.0])
    with pytest.raises(CircuitError, match="ratio node 'qq'"):
        frequency_response(rlc(), "a", [1.0], ratios=["qq"])


def test_inductor_only_node_is_reported():
    c = parse_netlist("* t\nL1 a b 1m\nL2 b 0 1m\nC1 a 0 1n\nR1 a 0 1k\n")
    with pytest.raises(CircuitError, match="node\\(s\\) b: no capacitive or resistive connection"):
        MNA(c, current_inputs=["a"]).state_space(c.resolve())


def test_table_5_4_is_passive(netlist_dir):
    c = read_netlist(netlist_dir / "hv_transformer_4section_table5_4.cir")
    lam = c.smallest_inductance_eigenvalue(c.resolve())
    assert lam == pytest.approx(3.9e-4, rel=0.01)  # models.md: about 3.9e-4 H


def test_table_5_12_is_not_passive(netlist_dir):
    for c in (read_netlist(netlist_dir / "hv_transformer_6section_table5_12.cir"), get_model("hv-6section").circuit):
        values = c.resolve()
        assert c.smallest_inductance_eigenvalue(values) == pytest.approx(-0.31, abs=0.01)
        with pytest.raises(NonPassiveError, match=r"smallest eigenvalue -0\.31"):
            c.check_passive(values, strict=True)
        with pytest.warns(NonPassiveWarning, match=r"-0\.31"):
            z = frequency_response(c, "b1", [50.0, 500.0])["Zin"]
        assert np.all(np.isfinite(z))


def test_passive_model_gives_no_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frequency_response(get_model("hv-4section").circuit, "a1", [100.0])


def test_parameter_cycle():
    with pytest.raises(CircuitError, match=r"<netlist>:2:10: parameters a, b depend on each other in a cycle"):
        parse_netlist("* t\n.param a={b} b={a}\nR1 x 0 {a}\n")  # refused where it is read


def test_unknown_override():
    with pytest.raises(CircuitError, match="unknown parameter or element 'nope'"):
        rlc().resolve({"nope": 1.0})


def test_passive_six_section_reproduces_table_5_12():
    """The re-estimated 6-section model is passive and follows Table 5.12's six responses (10 Hz - 10 kHz)."""
    passive = get_model("hv-6section-passive")
    assert passive.circuit.smallest_inductance_eigenvalue(passive.circuit.resolve()) > 1e-4
    f = np.logspace(1, 4, 300)
    ours = passive.response_set().evaluate(f)
    with pytest.warns(NonPassiveWarning):
        thesis = get_model("hv-6section").response_set().evaluate(f)
    for name in ours:
        err_db = 20 * np.log10(np.abs(ours[name] / thesis[name]))
        assert np.max(np.abs(err_db)) < 1.5 and np.sqrt(np.mean(err_db**2)) < 0.3, name
