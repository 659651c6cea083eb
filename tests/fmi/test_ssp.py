"""SSP 1.0 export of the PRIS arrangement (bridge and thesis splits): the archive read back with ElementTree."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import pytest
from fmpy.model_description import read_model_description

from pris_cosim.fmi import ssp
from pris_cosim.errors import CircuitError

ROOT = Path(__file__).resolve().parents[2]
TWO = ROOT / "fmus" / "two-section"
NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}


def _write(tmp_path: Path, **kw) -> Path:
    return ssp.write_ssp(TWO / "two_section_source.fmu", TWO / "two_section_dut.fmu", tmp_path / "two.ssp", **kw)


def _parameter_set(zf: zipfile.ZipFile, name: str) -> dict[str, float]:
    root = ElementTree.fromstring(zf.read(name))
    assert root.tag == f"{{{NS['ssv']}}}ParameterSet" and root.get("version") == "1.0"
    out = {}
    for p in root.find("ssv:Parameters", NS).findall("ssv:Parameter", NS):
        typed = p[0]
        assert typed.tag in (f"{{{NS['ssv']}}}Real", f"{{{NS['ssv']}}}Integer")
        out[p.get("name")] = float(typed.get("value"))
    return out


def test_archive_holds_components_connections_parameters_and_experiment(tmp_path):
    path = _write(tmp_path)
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        root = ElementTree.fromstring(zf.read("SystemStructure.ssd"))
        assert root.tag == f"{{{NS['ssd']}}}SystemStructureDescription"
        assert root.get("version") == "1.0" and root.get("name") == "two"
        system = root.find("ssd:System", NS)
        comps = {c.get("name"): c for c in system.find("ssd:Elements", NS).findall("ssd:Component", NS)}
        assert set(comps) == {"source", "dut"}
        fmus = {"source": TWO / "two_section_source.fmu", "dut": TWO / "two_section_dut.fmu"}
        for name, comp in comps.items():
            assert comp.get("source") in names and comp.get("source").startswith("resources/")
            assert zf.read(comp.get("source")) == fmus[name].read_bytes()
            md = read_model_description(str(fmus[name]))
            io = {v.name: v for v in md.modelVariables if v.causality in ("input", "output")}
            connectors = {c.get("name"): c for c in comp.find("ssd:Connectors", NS).findall("ssd:Connector", NS)}
            assert set(connectors) == set(io)
            for cname, c in connectors.items():
                assert c.get("kind") == io[cname].causality
                assert c.find("ssc:Real", NS).get("unit") == io[cname].unit
            bindings = comp.find("ssd:ParameterBindings", NS).findall("ssd:ParameterBinding", NS)
            assert len(bindings) == 1
            values = _parameter_set(zf, bindings[0].get("source"))
            starts = {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}
            assert values == starts
        links = {(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                 for c in system.find("ssd:Connections", NS).findall("ssd:Connection", NS)}
        assert links == {("source", "i_in", "dut", "i_in"), ("dut", "v_in", "source", "v_in")}
        units = {u.get("name") for u in root.find("ssd:Units", NS).findall("ssc:Unit", NS)}
        assert units == {"V", "A"}
        exp = root.find("ssd:DefaultExperiment", NS)
        algo = exp.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    md = read_model_description(str(fmus["source"]))
    assert float(exp.get("startTime")) == 0.0
    assert float(exp.get("stopTime")) == float(md.defaultExperiment.stopTime)
    assert float(algo.get("baseStepSize")) == float(md.defaultExperiment.stepSize) == 3125e-9
    assert ssp.default_experiment(path) == (0.3, 3125e-9)
    assert "Step guidance: fixed-step masters hold v_in and i_in" in root.get("description")


def test_values_replace_start_values_and_bad_names_are_refused(tmp_path):
    path = _write(tmp_path, experiment=(0.01, 1e-6), source_values={"vdc": 10.0}, dut_values={"R1": 20.0})
    with zipfile.ZipFile(path) as zf:
        assert _parameter_set(zf, "resources/two_section_source.ssv")["vdc"] == 10.0
        assert _parameter_set(zf, "resources/two_section_dut.ssv")["R1"] == 20.0
    assert ssp.default_experiment(path) == (0.01, 1e-6)
    with pytest.raises(CircuitError, match="no parameter named 'Rx'"):
        _write(tmp_path, dut_values={"Rx": 1.0})
    with pytest.raises(CircuitError, match="has no output 'i_in'"):
        ssp.write_ssp(TWO / "two_section_dut.fmu", TWO / "two_section_source.fmu", tmp_path / "swapped.ssp")


def test_build_fmu_refuses_ssp_without_the_source(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "build-fmu", "--model", "two-section", "--port", "in",
                           "--out", str(tmp_path), "--ssp"], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "pris-cosim build-fmu: error: --ssp needs --with-source (the system couples the source FMU and the DUT FMU)"]


def test_build_fmu_refuses_split_without_ssp(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "build-fmu", "--model", "two-section", "--port", "in",
                           "--out", str(tmp_path), "--with-source", "--split", "thesis"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        "pris-cosim build-fmu: error: --split needs --ssp (it chooses the FMUs of the SSP system)"]
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("split, kinds", [(None, ("bridge", "load")), ("thesis", ("source", "dut"))])
def test_build_fmu_writes_the_ssp_beside_the_fmus(tmp_path, split, kinds):
    proc = subprocess.run([sys.executable, "-m", "pris_cosim", "build-fmu", "--model", "three-section", "--port",
                           "n1", "--out", str(tmp_path), "--with-source", "--ssp", "--json"]
                          + (["--split", split] if split else []), capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert Path(out["ssp"]) == tmp_path / "three_section.ssp"
    with zipfile.ZipFile(out["ssp"]) as zf:
        assert {f"resources/three_section_{k}.{ext}" for k in kinds for ext in ("fmu", "ssv")} <= set(zf.namelist())
    assert ssp.components(out["ssp"]) == list(kinds)
    assert ssp.default_experiment(out["ssp"]) == (pytest.approx(4095 / 100e3), 80e-9)
    text = ssp.read_ssd(out["ssp"])
    if split == "thesis":  # the guidance names the arrangement's fastest period (1.13 us) and a thousandth of it
        assert "period of 1.13e-06 s" in text and "steps near 1.1e-09 s" in text
    else:
        assert "the default step 8e-08 s divides it (125 steps per bit)" in text


def test_bridge_split_archive_holds_one_connection_and_one_parameter_set_name(tmp_path):
    path = ssp.write_ssp(TWO / "two_section_bridge.fmu", TWO / "two_section_load.fmu", tmp_path / "b.ssp")
    assert ssp.detect_split(TWO / "two_section_bridge.fmu") == "bridge"
    assert ssp.detect_split(TWO / "two_section_source.fmu") == "thesis"
    with zipfile.ZipFile(path) as zf:
        root = ElementTree.fromstring(zf.read("SystemStructure.ssd"))
        links = {(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
                 for c in root.iter(f"{{{NS['ssd']}}}Connection")}
        assert links == {("bridge", "v_bprbs", "load", "v_bprbs")}
        names = {ElementTree.fromstring(zf.read(n)).get("name") for n in zf.namelist() if n.endswith(".ssv")}
    assert names == {ssp.PARAMETER_SET}
    assert ssp.recorded_outputs(path) == [("load", "v_in"), ("load", "i_in"), ("bridge", "v_bprbs")]
    with pytest.raises(CircuitError, match="has no input 'v_bprbs'"):
        ssp.write_ssp(TWO / "two_section_bridge.fmu", TWO / "two_section_dut.fmu", tmp_path / "x.ssp")


def test_step_guidance_names_the_bit_and_whether_the_step_divides_it():
    assert "(32 steps per bit)" in ssp.step_guidance("bridge", 3125e-9, 10e3)
    assert "does not divide it" in ssp.step_guidance("bridge", 3e-6, 10e3)
    text = ssp.step_guidance("thesis", 3125e-9, 10e3, fastest_period=170e-6)
    assert "period of 0.00017 s" in text and "steps near 1.7e-07 s" in text
    with pytest.raises(CircuitError, match="unknown split 'x'"):
        ssp.step_guidance("x", 1e-6, 1e3)


@pytest.mark.parametrize("folder, base", [("two-section", "two_section"), ("three-section", "three_section")])
def test_shipped_systems_hold_the_shipped_fmus(folder, base):
    """``fmus/<case>/<name>.ssp`` is current: its FMUs are the ones beside it, its values their start values."""
    path = ROOT / "fmus" / folder / f"{base}.ssp"
    with zipfile.ZipFile(path) as zf:
        for kind in ("bridge", "load"):
            fmu = ROOT / "fmus" / folder / f"{base}_{kind}.fmu"
            assert zf.read(f"resources/{fmu.name}") == fmu.read_bytes(), fmu.name
            md = read_model_description(str(fmu))
            starts = {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}
            assert _parameter_set(zf, f"resources/{fmu.stem}.ssv") == starts
    exp = read_model_description(str(ROOT / "fmus" / folder / f"{base}_bridge.fmu")).defaultExperiment
    assert ssp.default_experiment(path) == (float(exp.stopTime), float(exp.stepSize))
