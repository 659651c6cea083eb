"""FMI 3.0 FMUs: the same networks as the FMI 2.0 ones, equal to them in fmpy (CS and ME)."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.validation import validate_fmu

from pris_cosim.fmi import build as fmi
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.models.builtin import get_model

THREE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)


@pytest.fixture(scope="module")
def pairs(tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    out = tmp_path_factory.mktemp("fmu3")
    three = get_model("three-section").circuit
    v2 = fmi.build_pris_fmus(three, "n1", out / "fmi2", THREE, name="three")
    v3 = fmi.build_pris_fmus(three, "n1", out / "fmi3", THREE, name="three", fmi_version=3)
    return {k: (v2[k], v3[k]) for k in v2}


def test_fmi3_fmus_validate_and_hold_their_sources(pairs):
    for key, (_, path) in pairs.items():
        assert validate_fmu(str(path)) == [], key
        md = read_model_description(str(path))
        assert md.fmiVersion == "3.0" and md.coSimulation and md.modelExchange
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            build = zf.read("sources/buildDescription.xml").decode()
            text = zf.read("modelDescription.xml").decode()
        assert text.count('providesDirectionalDerivatives="true"') == 2
        assert text.count('canGetAndSetFMUState="true"') == 2
        assert 'fmiVersion="3.0"' in build and "sources/prc_fmi3.c" in names and "sources/model.c" in names
        assert any(n.startswith("binaries/x86_64-linux/") for n in names)


@pytest.mark.parametrize("key", ["arrangement", "dut", "source"])
@pytest.mark.parametrize("fmi_type", ["CoSimulation", "ModelExchange"])
def test_fmi3_equals_fmi2(pairs, key, fmi_type):
    v2, v3 = pairs[key]
    md = read_model_description(str(v2))
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    signal = None
    stop = 2e-4
    if inputs:
        t = np.linspace(0.0, stop, 201)
        value = 1e-3 * np.sign(np.sin(2 * np.pi * 3e4 * t)) if inputs[0] == "i_in" else 5.0 * np.sin(2 * np.pi * 3e4 * t)
        signal = np.array(list(zip(t, value)), dtype=[("time", float), (inputs[0], float)])
    kw = dict(fmi_type=fmi_type, stop_time=stop, output_interval=1e-7, output=outputs, input=signal,
              relative_tolerance=1e-9)
    a = simulate_fmu(str(v2), **kw)
    b = simulate_fmu(str(v3), **kw)
    assert a.size == b.size
    np.testing.assert_allclose(b["time"], a["time"], rtol=0, atol=1e-15)
    for name in outputs:
        scale = np.abs(a[name]).max()
        assert scale > 0 and np.abs(b[name] - a[name]).max() <= 1e-9 * scale, name


def test_build_fmu_command_writes_fmi3(tmp_path):
    out = subprocess.run([sys.executable, "-m", "pris_cosim", "build-fmu", "--model", "two-section", "--port", "in",
                          "--out", str(tmp_path), "--fmi-version", "3", "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    fmus = json.loads(out.stdout)["fmus"]
    assert [read_model_description(f).fmiVersion for f in fmus] == ["3.0"]
