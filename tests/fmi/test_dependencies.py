"""Declared ``ModelStructure`` dependencies against the FMUs' measured behaviour.

The declaration is read from ``modelDescription.xml`` with ElementTree; the
expectation is measured on the compiled FMU through fmpy's Model Exchange
interface: every known (state, input, parameter) is moved on its own, at a
random operating point, and whatever output, state derivative or calculated
parameter moves with it depends on it. The FMU's C runtime assembles the
network from the element values itself, so this shares nothing with the
Python state-space code that writes the declaration.
"""

from __future__ import annotations

import ctypes
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model

from pris_cosim.fmi import codegen, build as fmi
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.circuits.circuit import Circuit

PARASITIC = SourceSettings(vdc=100.0, prbs_order=5, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6,
                           rsnub=50.0, csnub=2e-9, lsw=1e-6, csw=1e-10)


def _tied(port_capacitor: bool) -> Circuit:
    c = Circuit(title="tied RLC", ports=["a"], probes=["b"])
    c.add_parameter("R0", 1e3, "Ohm")
    c.add_parameter("Rt", "{2*R0 + 1}", "Ohm")
    c.add_parameter("C0", 1e-9, "F")
    c.add("R1", "a", "b", "{Rt}")
    c.add("C1", "b", "0", "{C0}")
    c.add("R2", "b", "0", 5e3)
    if port_capacitor:
        c.add("C2", "a", "0", "{C0/2}")
    c.add("L1", "b", "0", 1e-3)
    return c


ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """The shipped FMUs, and built ones for switch parasitics, ties and a port without a capacitor."""
    out = tmp_path_factory.mktemp("deps")
    models = {
        "parasitic_source": codegen.source_model(PARASITIC, name="dep_parasitic_source"),
        "tied_dut": codegen.dut_model(_tied(True), "a", name="dep_tied_dut"),
        "tied_feedthrough_dut": codegen.dut_model(_tied(False), "a", name="dep_tied_ft_dut"),
    }
    paths = {k: fmi.build_fmu(m, out, write_modelica=False) for k, m in models.items()}
    shipped = ROOT / "fmus"
    paths |= {"two_pris": shipped / "two-section" / "two_section_pris.fmu",
              "three_dut": shipped / "three-section" / "three_section_dut.fmu",
              "three_source": shipped / "three-section" / "three_section_source.fmu",
              "three_bridge": shipped / "three-section" / "three_section_bridge.fmu",
              "three_load": shipped / "three-section" / "three_section_load.fmu",
              "hv_lvoc_dut": shipped / "hv-4section-lvoc" / "hv_4section_LVOC_dut.fmu"}
    return paths


def declared(path: Path) -> dict[str, dict[str, set[str]]]:
    """``{"Outputs" | "Derivatives" | "InitialUnknowns": {unknown: {known, ...}}}`` as written in the XML."""
    with zipfile.ZipFile(path) as zf:
        root = ElementTree.fromstring(zf.read("modelDescription.xml"))
    names = [sv.get("name") for sv in root.find("ModelVariables")]
    out: dict[str, dict[str, set[str]]] = {}
    for section in ("Outputs", "Derivatives", "InitialUnknowns"):
        rows = {}
        for u in root.find("ModelStructure").findall(f"{section}/Unknown"):  # no Derivatives without states
            deps = u.get("dependencies")
            assert deps is not None, (path.name, section, names[int(u.get("index")) - 1])
            kinds = (u.get("dependenciesKind") or "").split()
            assert len(kinds) == len(deps.split()), (path.name, section)
            rows[names[int(u.get("index")) - 1]] = {names[int(i) - 1] for i in deps.split()}
        out[section] = rows
    return out


class _Probe:
    """One FMU in Model Exchange at t = 0: set parameters, states and input; read outputs and derivatives."""

    def __init__(self, path: Path, tmp: Path):
        self.md = read_model_description(str(path))
        self.fmu = FMU2Model(guid=self.md.guid, unzipDirectory=extract(str(path), str(tmp)),
                             modelIdentifier=self.md.modelExchange.modelIdentifier, instanceName="probe")
        self.fmu.instantiate()
        v = self.md.modelVariables
        self.vars = {x.name: x for x in v}
        self.states = [x.derivative.name for x in v if x.derivative is not None]
        self.derivs = [x.name for x in v if x.derivative is not None]
        self.inputs = [x.name for x in v if x.causality == "input"]
        self.outputs = [x.name for x in v if x.causality == "output"]
        self.calculated = [x.name for x in v if x.causality == "calculatedParameter"]
        self.params = [x.name for x in v if x.causality == "parameter"]
        self.initialized = False

    def start(self, params: dict[str, float]) -> None:
        if self.initialized:
            self.fmu.terminate()
            self.fmu.reset()
        self.fmu.setupExperiment(startTime=0.0)
        for name, value in params.items():
            var = self.vars[name]
            if var.type == "Integer":
                self.fmu.setInteger([var.valueReference], [int(value)])
            else:
                self.fmu.setReal([var.valueReference], [float(value)])
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.fmu.newDiscreteStates()
        self.fmu.enterContinuousTimeMode()
        self.fmu.setTime(0.0)
        self.initialized = True

    def evaluate(self, x: np.ndarray, u: np.ndarray) -> dict[str, float]:
        x = np.ascontiguousarray(x, dtype=float)
        dx = np.zeros_like(x)
        ptr = ctypes.POINTER(ctypes.c_double)
        self.fmu.setContinuousStates(x.ctypes.data_as(ptr), x.size)
        if self.inputs:
            self.fmu.setReal([self.vars[n].valueReference for n in self.inputs], list(u))
        self.fmu.getDerivatives(dx.ctypes.data_as(ptr), x.size)
        names = self.outputs + self.calculated
        values = self.fmu.getReal([self.vars[n].valueReference for n in names])
        return dict(zip(self.derivs, dx)) | dict(zip(names, values))

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def measured(path: Path, tmp: Path) -> dict[str, dict[str, set[str]]]:
    """Dependencies found by moving each known on its own at a random operating point."""
    rng = np.random.default_rng(7)
    p = _Probe(path, tmp)
    try:
        x0 = rng.uniform(0.5, 1.5, len(p.states)) * rng.choice([-1, 1], len(p.states))
        u0 = rng.uniform(0.5, 1.5, len(p.inputs))
        starts = {n: float(p.vars[n].start) for n in p.params}
        p.start(starts)
        base = p.evaluate(x0, u0)

        def moved(value: dict[str, float]) -> set[str]:
            return {k for k in base if abs(value[k] - base[k]) > 1e-9 * (abs(base[k]) + abs(value[k])) + 1e-300}

        effect: dict[str, set[str]] = {}
        for j, s in enumerate(p.states):
            x = x0.copy()
            x[j] *= 1.7
            effect[s] = moved(p.evaluate(x, u0))
        for j, n in enumerate(p.inputs):
            u = u0.copy()
            u[j] *= 1.7
            effect[n] = moved(p.evaluate(x0, u))
        runtime = dict(effect)
        for n in p.params:
            var = p.vars[n]
            if n == "prbs_seed":
                tries = [1]  # first bit 0: the bridge starts at -vdc instead of +vdc
            elif n == "prbs_order":
                # with the seed's top bit set only at the start order, the first bit differs between orders
                seeded = starts | {"prbs_seed": 2 ** (int(var.start) - 1)}
                p.start(seeded)
                ref = p.evaluate(x0, u0)
                p.start(seeded | {n: int(var.start) + 1})
                value = p.evaluate(x0, u0)
                effect[n] = {k for k in ref if value[k] != ref[k]}
                continue
            else:  # up or down, less where a move leaves the valid range (a coupling past 1)
                tries = [float(var.start) * f for f in (1.3, 0.7, 1.01, 0.99, 1.0001, 0.9999)]
            for value in tries:
                try:
                    p.start(starts | {n: value})
                except FMICallException:
                    continue
                effect[n] = moved(p.evaluate(x0, u0))
                break
            else:
                raise AssertionError(f"{path.name}: no valid value to move {n} to")
    finally:
        p.close()

    def invert(effects: dict[str, set[str]], unknowns: list[str]) -> dict[str, set[str]]:
        return {k: {known for known, hit in effects.items() if k in hit} for k in unknowns}

    return {"Outputs": invert(runtime, p.outputs), "Derivatives": invert(runtime, p.derivs),
            "InitialUnknowns": invert(effect, p.outputs + p.derivs + p.calculated)}


@pytest.mark.parametrize("key", ["two_pris", "three_dut", "three_source", "three_bridge", "three_load",
                                 "parasitic_source", "hv_lvoc_dut", "tied_dut", "tied_feedthrough_dut"])
def test_declared_dependencies_equal_the_measured_ones(fmus, key, tmp_path):
    want = measured(fmus[key], tmp_path)
    got = declared(fmus[key])
    for section in ("Outputs", "Derivatives", "InitialUnknowns"):
        assert set(got[section]) == set(want[section]), (key, section)
        for unknown, deps in want[section].items():
            assert got[section][unknown] == deps, (key, section, unknown)


def test_port_voltage_feedthrough_follows_the_port_capacitor(fmus):
    """With a capacitor at the port, v_in does not depend on i_in: a source FMU coupled to it forms no loop."""
    for key, feedthrough in (("tied_dut", False), ("tied_feedthrough_dut", True), ("three_dut", False)):
        deps = declared(fmus[key])
        for section in ("Outputs", "InitialUnknowns"):
            assert ("i_in" in deps[section]["v_in"]) == feedthrough, (key, section)
    src = declared(fmus["three_source"])
    assert "v_in" not in src["Outputs"]["i_in"] and "v_in" not in src["InitialUnknowns"]["i_in"]


def test_fmi3_declares_the_same_dependencies():
    """The FMI 3.0 model description lists the same dependencies, by value reference."""
    model = codegen.source_model(PARASITIC, name="dep3_source")
    xml2 = ElementTree.fromstring(fmi.render(model, 2)["modelDescription.xml"])
    xml3 = ElementTree.fromstring(fmi.render(model, 3)["modelDescription.xml"])
    names2 = [sv.get("name") for sv in xml2.find("ModelVariables")]
    by_vr3 = {v.get("valueReference"): v.get("name") for v in xml3.find("ModelVariables")}

    def rows2(section: str) -> dict[str, set[str]]:
        return {names2[int(u.get("index")) - 1]: {names2[int(i) - 1] for i in u.get("dependencies").split()}
                for u in xml2.find("ModelStructure").find(section)}

    def rows3(tag: str) -> dict[str, set[str]]:
        return {by_vr3[u.get("valueReference")]: {by_vr3[i] for i in u.get("dependencies").split()}
                for u in xml3.find("ModelStructure").findall(tag)}

    assert rows3("Output") == rows2("Outputs")
    assert rows3("ContinuousStateDerivative") == rows2("Derivatives")
    assert rows3("InitialUnknown") == rows2("InitialUnknowns")
