"""Exact co-simulation of a source FMU and a winding FMU against the in-process exact engine."""

from __future__ import annotations

import argparse
import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from pris_cosim.cli import commands as cli
from pris_cosim.cli import sim as cli_sim
from pris_cosim.fmi import codegen, cosim, build as fmi
from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.fmi.cosim_exact import cosimulate_exact
from pris_cosim.measured.formats import read_waveform_csv
from pris_cosim.models.builtin import get_model

THREE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
FS = 10e6


@pytest.mark.parametrize("fs, periods", [(10e6, 2), (2.5e5, 1)])
def test_exact_coupling_equals_the_exact_engine(tmp_path, fs, periods):
    """No one-step delay: v_in and i_in equal the monolithic ZOH engine to rounding (fs/fclk = 100 and 2.5)."""
    three = get_model("three-section").circuit
    src = fmi.build_fmu(codegen.source_model(THREE, name="three_source"), tmp_path, write_modelica=False)
    dut = fmi.build_fmu(codegen.dut_model(three, "n1", name="three_dut"), tmp_path, write_modelica=False)
    ref = td.simulate_pris(three, "n1", THREE, fs, periods)
    with cosim.FmuRunner(src, "ModelExchange") as s, cosim.FmuRunner(dut, "ModelExchange") as d:
        w, err = cosimulate_exact(s, d, fs, ref["time_s"].size, probes=["v_n2", "v_n3"])
    np.testing.assert_array_equal(w["v_bprbs"], ref["v_bprbs"])
    for name in ("v_in", "i_in", "v_n2", "v_n3"):
        assert cosim.relative_rms(w[name], ref[name]) < 1e-9, name
    assert err < 1e-10


def _run_cli(argv: list[str], capsys) -> tuple[int, str, str]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    if "simulate" not in sub.choices:
        cli_sim.register(sub)
    args = parser.parse_args(argv)
    code = args.func(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_simulate_engine_cosim_reports_the_coupling_error(tmp_path, capsys):
    argv = ["simulate", "--model", "three-section", "--vdc", "100", "--prbs-order", "5", "--fclk", "100e3",
            "--rpris", "150", "--lpris", "4m", "--cpris", "1u", "--fs", "5e6", "--periods", "1", "--probe", "n3",
            "--json"]
    waves = {}
    for engine in ("numpy", "cosim"):
        code, stdout, _ = _run_cli(argv + ["--engine", engine, "--out", str(tmp_path / f"{engine}.csv")], capsys)
        assert code == 0 and stdout.count("\n") == 1
        info = json.loads(stdout)
        waves[engine] = read_waveform_csv(tmp_path / f"{engine}.csv")
    assert info["engine"] == "cosim" and 0 <= info["coupling_error"] < 1e-10
    assert cosim.relative_rms(waves["cosim"].v_in, waves["numpy"].v_in) < 1e-9
    assert cosim.relative_rms(waves["cosim"].v_out, waves["numpy"].v_out) < 1e-9  # the probe v(n3)


# ---------------------------------------------------------------------- a winding FMU written by hand
RLC_C = r"""
/* Hand-written FMI 2.0 Model Exchange FMU: node n with C to ground and R + L to ground, driven by i_in. */
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"
typedef struct { double x[2], u, R, L, C, t; const fmi2CallbackFunctions *cb; } M;
enum { V_IN = 0, I_IN = 1, R_ = 2, L_ = 3, C_ = 4, X0 = 5, X1 = 6, D0 = 7, D1 = 8 };
static void der(M *m, double *d) { d[0] = (m->u - m->x[1]) / m->C; d[1] = (m->x[0] - m->R * m->x[1]) / m->L; }
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { return fmi2OK; }
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *cb, fmi2Boolean vis, fmi2Boolean log) {
    M *m = calloc(1, sizeof(M)); m->R = 20.0; m->L = 1e-3; m->C = 2e-8; m->cb = cb; return m; }
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    ((M *)c)->t = t0; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { M *m = c; memset(m->x, 0, sizeof m->x); m->u = 0; return fmi2OK; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = c; double d[2]; size_t i; der(m, d);
    for (i = 0; i < n; i++) switch (vr[i]) {
        case V_IN: v[i] = m->x[0]; break; case I_IN: v[i] = m->u; break; case R_: v[i] = m->R; break;
        case L_: v[i] = m->L; break; case C_: v[i] = m->C; break; case X0: v[i] = m->x[0]; break;
        case X1: v[i] = m->x[1]; break; case D0: v[i] = d[0]; break; case D1: v[i] = d[1]; break;
        default: return fmi2Error; }
    return fmi2OK; }
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = c; size_t i;
    for (i = 0; i < n; i++) switch (vr[i]) {
        case I_IN: m->u = v[i]; break; case R_: m->R = v[i]; break; case L_: m->L = v[i]; break;
        case C_: m->C = v[i]; break; default: return fmi2Error; }
    return fmi2OK; }
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { return fmi2Error; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { return fmi2Error; }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
    const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[]) { return fmi2Error; }
fmi2Status fmi2EnterEventMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *e) { memset(e, 0, sizeof *e); return fmi2OK; }
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean a, fmi2Boolean *e, fmi2Boolean *t) {
    *e = fmi2False; *t = fmi2False; return fmi2OK; }
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real t) { ((M *)c)->t = t; return fmi2OK; }
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t n) {
    memcpy(((M *)c)->x, x, 2 * sizeof(double)); return fmi2OK; }
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real d[], size_t n) { der(c, d); return fmi2OK; }
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real z[], size_t n) { return fmi2OK; }
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    memcpy(x, ((M *)c)->x, 2 * sizeof(double)); return fmi2OK; }
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x[], size_t n) {
    x[0] = 1.0; x[1] = 1e-3; return fmi2OK; }
"""

RLC_XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="rlc" guid="{hand-written-rlc}" numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="rlc"><SourceFiles><File name="rlc.c"/></SourceFiles></ModelExchange>
  <ModelVariables>
    <ScalarVariable name="v_in" valueReference="0" causality="output" variability="continuous" initial="calculated"><Real/></ScalarVariable>
    <ScalarVariable name="i_in" valueReference="1" causality="input" variability="continuous"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="R" valueReference="2" causality="parameter" variability="fixed" initial="exact"><Real start="20"/></ScalarVariable>
    <ScalarVariable name="L" valueReference="3" causality="parameter" variability="fixed" initial="exact"><Real start="0.001"/></ScalarVariable>
    <ScalarVariable name="C" valueReference="4" causality="parameter" variability="fixed" initial="exact"><Real start="2e-8"/></ScalarVariable>
    <ScalarVariable name="v" valueReference="5" causality="local" variability="continuous" initial="exact"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="i" valueReference="6" causality="local" variability="continuous" initial="exact"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="der(v)" valueReference="7" causality="local" variability="continuous" initial="calculated"><Real derivative="6"/></ScalarVariable>
    <ScalarVariable name="der(i)" valueReference="8" causality="local" variability="continuous" initial="calculated"><Real derivative="7"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1" dependencies="6" dependenciesKind="dependent"/></Outputs>
    <Derivatives><Unknown index="8"/><Unknown index="9"/></Derivatives>
    <InitialUnknowns><Unknown index="1"/><Unknown index="8"/><Unknown index="9"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def hand_written_fmu(tmp_path_factory) -> Path:
    """The RLC winding FMU built from hand-written C with fmpy's CMake project (not our code generator)."""
    if shutil.which("cmake") is None or shutil.which("gcc") is None:
        pytest.skip("cmake or gcc is not installed: the hand-written reference FMU cannot be built")
    root = tmp_path_factory.mktemp("rlc")
    unzip = root / "rlc"
    (unzip / "sources").mkdir(parents=True)
    (unzip / "sources" / "rlc.c").write_text(RLC_C)
    (unzip / "modelDescription.xml").write_text(RLC_XML)
    fmi.compile_binary(unzip)
    path = root / "rlc.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        for p in sorted(q for q in unzip.rglob("*") if q.is_file()):
            zf.write(p, p.relative_to(unzip).as_posix())
    return path


def test_our_source_fmu_couples_exactly_with_a_hand_written_winding_fmu(tmp_path, hand_written_fmu):
    rlc = Circuit(title="RLC", ports=["n"])
    rlc.add("C1", "n", "0", 2e-8)
    rlc.add("R1", "n", "x", 20.0)
    rlc.add("L1", "x", "0", 1e-3)
    src = fmi.build_fmu(codegen.source_model(THREE, name="three_source"), tmp_path, write_modelica=False)
    ref = td.simulate_pris(rlc, "n", THREE, FS)
    with cosim.FmuRunner(src, "ModelExchange") as s, cosim.FmuRunner(hand_written_fmu, "ModelExchange") as d:
        w, err = cosimulate_exact(s, d, FS, ref["time_s"].size)
    for name in ("v_in", "i_in"):
        assert cosim.relative_rms(w[name], ref[name]) < 1e-9, name
    assert err < 1e-10
