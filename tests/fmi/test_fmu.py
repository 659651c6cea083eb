"""Generated FMUs: validation, CS and ME runs, equality with the numpy engine, C runtime checks."""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from fmpy.model_description import read_model_description
from fmpy.validation import validate_fmu

from pris_cosim.fmi import codegen, cosim, build as fmi
from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import BRIDGE, SourceSettings, pris_arrangement
from pris_cosim.errors import NonPassiveError
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import get_model
from pris_cosim.signals.perturbation import LFSR, lfsr_prbs

THREE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
TWO = SourceSettings(vdc=30.0, prbs_order=4, fclk=10e3, rpris=31.8e3, lpris=2.53, cpris=10e-9)
PARASITIC = SourceSettings(vdc=100.0, prbs_order=5, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6,
                           rsnub=50.0, csnub=2e-9, lsw=1e-6, csw=1e-10)
C_DIR = Path(codegen.__file__).parent / "c"


def max_rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / np.abs(b).max())


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    """Every FMU used here, built once (and reused from the content-hash cache across sessions)."""
    out = tmp_path_factory.mktemp("fmus")
    three = get_model("three-section").circuit
    hv = get_model("hv-4section")
    lvsc = hv.configuration("LVSC")
    paths = {f"three_{k}": v for k, v in fmi.build_pris_fmus(three, "n1", out, THREE, name="three").items()}
    paths["two_arrangement"] = fmi.build_fmu(
        codegen.arrangement_model(get_model("two-section").circuit, "in", TWO, name="two_section_pris"), out)
    paths["hv_dut"] = fmi.build_fmu(codegen.dut_model(hv.circuit, lvsc.port, lvsc.shorts, name="hv_lvsc_dut"), out)
    paths["parasitic_source"] = fmi.build_fmu(codegen.source_model(PARASITIC, name="parasitic_source"), out)
    paths["parasitic_arrangement"] = fmi.build_fmu(
        codegen.arrangement_model(three, "n1", PARASITIC, name="parasitic_pris"), out)
    return paths


def test_every_fmu_validates_and_has_both_interfaces(fmus):
    for name, path in fmus.items():
        assert validate_fmu(str(path)) == [], name
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
        assert "sources/model.c" in names, name
        assert "sources/buildDescription.xml" not in names, name  # FMI 2.0 lists its sources in the description
        with cosim.FmuRunner(path) as runner:
            md = runner.model_description
        assert md.coSimulation is not None and md.modelExchange is not None
        assert path.with_suffix(".mo").is_file(), name


def test_every_fmu_runs_as_co_simulation_and_model_exchange(fmus):
    for name, path in fmus.items():
        for fmi_type in ("CoSimulation", "ModelExchange"):
            with cosim.FmuRunner(path, fmi_type) as runner:
                inputs = [v for v in runner.model_description.modelVariables if v.causality == "input"]
                signal = None
                if inputs:  # a constant input: 1 mA into a DUT, 5 V at a source terminal
                    value = 1e-3 if inputs[0].name == "i_in" else 5.0
                    signal = np.array([(0.0, value), (1.0, value)], dtype=[("time", float), (inputs[0].name, float)])
                res = runner.run(2e-5, 1e-7, input=signal, relative_tolerance=1e-8)
            outputs = [v.name for v in runner.model_description.modelVariables if v.causality == "output"]
            assert res["time"][-1] == pytest.approx(2e-5), (name, fmi_type)
            for o in outputs:
                assert np.all(np.isfinite(res[o])) and np.abs(res[o]).max() > 0, (name, fmi_type, o)


@pytest.mark.parametrize("key, dut, port, settings", [
    ("three_arrangement", "three-section", "n1", THREE),
    ("two_arrangement", "two-section", "in", TWO),
    ("parasitic_arrangement", "three-section", "n1", PARASITIC),
])
def test_monolithic_fmu_equals_numpy_engine(fmus, key, dut, port, settings):
    fs = 10 * settings.fclk if key == "two_arrangement" else 100 * settings.fclk
    ref = td.simulate_pris(get_model(dut).circuit, port, settings, fs)
    with cosim.FmuRunner(fmus[key]) as runner:
        w = cosim.simulate_pris_fmu(runner, settings, fs)
    assert w["time_s"].size == ref["time_s"].size
    for name in ("v_in", "i_in", "v_bprbs"):
        assert max_rel(w[name], ref[name]) < 1e-9, name


def test_fmu_splits_steps_at_switching_instants(fmus):
    """fs = 2.5 f_clk: every other bit boundary falls inside a communication step."""
    fs = 2.5 * THREE.fclk
    ref = td.simulate_pris(get_model("three-section").circuit, "n1", THREE, fs, periods=2)
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        w = cosim.simulate_pris_fmu(runner, THREE, fs, periods=2)
    for name in ("v_in", "i_in", "v_bprbs"):
        assert max_rel(w[name], ref[name]) < 1e-9, name


def test_model_exchange_with_time_events_matches_exact_solution(fmus):
    fs = 10e6
    ref = td.simulate_pris(get_model("three-section").circuit, "n1", THREE, fs)
    stop = ref["time_s"][-1]
    with cosim.FmuRunner(fmus["three_arrangement"], "ModelExchange") as runner:
        res = runner.run(stop, 1 / fs, output=["v_in", "i_in", "v_bprbs"], relative_tolerance=1e-9,
                         record_events=False)
    for name in ("v_in", "i_in"):
        got = np.interp(ref["time_s"], res["time"], res[name])
        err = np.sqrt(np.mean((got - ref[name]) ** 2) / np.mean(ref[name] ** 2))
        assert err < 1e-4, name  # CVode at rtol 1e-9 against the exact ZOH solution


def test_dut_fmu_equals_current_injection(fmus):
    three = get_model("three-section").circuit
    fs = 10e6
    i = td.simulate_pris(three, "n1", THREE, fs)["i_in"]
    ref = td.simulate_current_injection(three, "n1", i, fs)
    with cosim.FmuRunner(fmus["three_dut"]) as runner:
        w = cosim.run_dut_fmu(runner, i, fs)
    for name in ("v_in", "v_n2", "v_n3"):
        assert max_rel(w[name], ref[name]) < 1e-9, name


def test_dut_fmu_with_shorts_equals_current_injection(fmus):
    hv = get_model("hv-4section")
    cfg = hv.configuration("LVSC")
    fs = 1e6
    i = np.where(lfsr_prbs(7) == 1, 1e-3, -1e-3).repeat(5)
    ref = td.simulate_current_injection(hv.circuit, cfg.port, i, fs, shorts=cfg.shorts)
    with cosim.FmuRunner(fmus["hv_dut"]) as runner:
        w = cosim.run_dut_fmu(runner, i, fs)
    assert "v_b1" not in w  # the shorted HV terminal is no output
    for name in ("v_in", "v_b2", "v_b4"):
        assert max_rel(w[name], ref[name]) < 1e-9, name


@pytest.mark.parametrize("key, settings", [("three_source", THREE), ("parasitic_source", PARASITIC)])
def test_source_fmu_equals_numpy(fmus, key, settings):
    """Source FMU driving a given terminal voltage vs the ZOH engine on the same network."""
    fs = 100 * settings.fclk
    model = codegen.source_model(settings)
    ss = model.mna.state_space(model.circuit.resolve())
    n = 2000
    v_dut = 20.0 * np.sin(2 * np.pi * 37e3 * np.arange(n) / fs)
    bits = lfsr_prbs(settings.prbs_order, 1)
    bridge = np.where(bits[np.arange(n) // 100] == 1, settings.vdc, -settings.vdc)
    x, _ = td.simulate_pwc(ss, np.column_stack([bridge, v_dut]), 1 / fs)
    i_ref = x[:, model.mna.states.index("i(Lpris)")]
    with cosim.FmuRunner(fmus[key]) as runner:
        runner.initialize()
        fmu = runner.instance
        got = np.empty(n)
        for k in range(n):
            fmu.setReal([runner.vr("v_in")], [v_dut[k]])
            got[k] = fmu.getReal([runner.vr("i_in")])[0]
            assert fmu.getReal([runner.vr("v_bprbs")])[0] == bridge[k]
            fmu.doStep(k / fs, 1 / fs)
    assert max_rel(got, i_ref) < 1e-9


@pytest.mark.parametrize("order, seed", [(2, None), (3, 5), (5, None), (7, 0b1010101), (8, None), (12, None),
                                         (16, 0xACE1), (31, None), (32, None)])
def test_c_lfsr_equals_signals_lfsr(fmus, order, seed):
    n = min(2**order - 1, 3000) + 7  # past the end of short periods
    bits = LFSR(order, seed).next_bits(n)
    with cosim.FmuRunner(fmus["three_source"]) as runner:
        res = runner.run((n - 1) / THREE.fclk, 1 / THREE.fclk, output=["v_bprbs"],
                         start_values={"prbs_order": order, "prbs_seed": seed or 0})
    np.testing.assert_array_equal(res["v_bprbs"][:n] > 0, bits == 1)


@pytest.mark.parametrize("values, words", [
    ({"Rs": -1.0}, ["R1", "{Rs}", "resistance must be positive"]),
    ({"k12": 1.0}, ["K12", "coupling |k| must be below 1"]),
    ({"k12": 0.99, "k13": 0.99, "k23": 0.0}, ["not positive definite", "L3"]),
    ({"Lpris": -4e-3}, ["Lpris", "inductance must be positive"]),
    ({"prbs_order": 1}, ["prbs_order"]),
])
def test_invalid_parameters_are_rejected_with_a_message(fmus, values, words):
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        with pytest.raises(cosim.FmuError) as info:
            runner.run(1e-5, 1e-7, start_values=values)
        for w in words:
            assert w in str(info.value)
        ok = runner.run(1e-5, 1e-7)  # the instance recovers after reset
        assert np.all(np.isfinite(ok["v_in"]))


@pytest.mark.slow
def test_rebuilds_from_its_own_sources(fmus, tmp_path):
    src = fmus["three_arrangement"]
    unzip = tmp_path / "fmu"
    with zipfile.ZipFile(src) as zf:
        zf.extractall(unzip)
    shutil.rmtree(unzip / "binaries")
    md = read_model_description(str(unzip))
    assert md.coSimulation.modelIdentifier == "three_pris"
    assert sorted(md.buildConfigurations[0].sourceFileSets[0].sourceFiles) == sorted(codegen.c_source_files())
    fmi.compile_binary(unzip)
    with cosim.FmuRunner(unzip) as rebuilt, cosim.FmuRunner(src) as original:
        a = cosim.simulate_pris_fmu(rebuilt, THREE, 1e6)
        b = cosim.simulate_pris_fmu(original, THREE, 1e6)
    np.testing.assert_array_equal(a["v_in"], b["v_in"])


def test_runner_reuse_gives_identical_runs(fmus):
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        a = cosim.simulate_pris_fmu(runner, THREE, 1e6)
        b = cosim.simulate_pris_fmu(runner, THREE, 1e6, start_values={"Rs": 0.2})
        c = cosim.simulate_pris_fmu(runner, THREE, 1e6)
    np.testing.assert_array_equal(a["v_in"], c["v_in"])
    assert max_rel(b["v_in"], a["v_in"]) > 1e-6
    ref = td.simulate_pris(get_model("three-section").circuit, "n1", THREE, 1e6, overrides={"Rs": 0.2})
    assert max_rel(b["v_in"], ref["v_in"]) < 1e-9


def test_non_passive_circuit_is_not_built(tmp_path):
    m = get_model("hv-6section")
    cfg = m.configuration("LVOC")
    with pytest.raises(NonPassiveError, match="not passive"):
        fmi.build_pris_fmus(m.circuit, cfg.port, tmp_path, THREE)
    assert not list(tmp_path.iterdir())


def test_modelica_text_names_every_element(fmus):
    text = fmus["three_arrangement"].with_suffix(".mo").read_text()
    assert text.startswith("model three_pris") and text.rstrip().endswith("end three_pris;")
    for name in ("Cg1", "C12", "R1", "Rpris", "Lpris", "Cpris", "Vbridge", "M_L1_L2_L3"):
        assert name in text
    assert "Modelica.Electrical.Analog.Basic.M_Transformer" in text
    assert text.count("(") == text.count(")")


# ---------------------------------------------------------------------- C runtime
@pytest.fixture(scope="module")
def c_expm(tmp_path_factory):
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    lib = tmp_path_factory.mktemp("expm") / "libprc_expm.so"
    subprocess.run(["gcc", "-O2", "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-shared", "-fPIC",
                    str(C_DIR / "prc_expm.c"), str(C_DIR / "prc_linalg.c"), "-o", str(lib), "-lm"], check=True)
    dll = ctypes.CDLL(str(lib))
    dp = ctypes.POINTER(ctypes.c_double)

    def expm(A: np.ndarray) -> np.ndarray:
        A = np.ascontiguousarray(A, dtype=float)
        n = A.shape[0]
        E = np.empty_like(A)
        work = np.empty(9 * n * n)
        ipiv = np.empty(n, dtype=np.int32)
        status = dll.prc_expm(n, A.ctypes.data_as(dp), E.ctypes.data_as(dp), work.ctypes.data_as(dp),
                              ipiv.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        assert status == 0
        return E

    return expm


@pytest.mark.parametrize("norm", [1e-4, 1e-2, 0.2, 1.0, 3.0, 10.0, 100.0])
def test_c_expm_equals_scipy_on_random_matrices(c_expm, norm):
    rng = np.random.default_rng(int(norm * 1000) % 97)
    A = rng.standard_normal((9, 9))
    A *= norm / np.abs(A).sum(axis=0).max()
    ref = scipy.linalg.expm(A)
    assert max_rel(c_expm(A), ref) < 1e-12


@pytest.mark.parametrize("h", [1e-9, 1e-7, 1e-6, 1e-5])
def test_c_expm_equals_scipy_on_pris_discretisation(c_expm, h):
    """The augmented matrix [[A h, B h], [0, 0]] of the three-section arrangement (stiff)."""
    c = pris_arrangement(get_model("three-section").circuit, "n1", THREE)
    ss = MNA(c, voltage_inputs=[BRIDGE]).state_space(c.resolve())
    n = ss.A.shape[1]
    aug = np.zeros((n + 1, n + 1))
    aug[:n, :n] = ss.A[0] * h
    aug[:n, n:] = ss.B[0] * h
    assert max_rel(c_expm(aug), scipy.linalg.expm(aug)) < 1e-12


def test_parameter_ties_are_evaluated_in_the_fmu(tmp_path):
    """A tied parameter is a calculatedParameter; changing its base re-evaluates the tie in C."""
    from pris_cosim.circuits.circuit import Circuit

    c = Circuit(title="tied RLC", ports=["a"], probes=["b"])
    c.add_parameter("R0", 1e3, "Ohm")
    c.add_parameter("Rt", "{2*R0 + sqrt(R0)**2 - R0}", "Ohm")  # = 2 R0
    c.add_parameter("C0", 1e-9, "F")
    c.add("R1", "a", "b", "{Rt}")
    c.add("C1", "b", "0", "{C0}")
    c.add("C2", "a", "0", "{C0/2}")
    c.add("L1", "b", "0", 1e-3)
    path = fmi.build_fmu(codegen.dut_model(c, "a", name="tied_dut"), tmp_path)
    assert validate_fmu(str(path)) == []
    fs = 1e7
    i = np.where(lfsr_prbs(6) == 1, 1e-3, -1e-3).repeat(20)
    ref = td.simulate_current_injection(c, "a", i, fs, overrides={"R0": 3e3, "L1": 2e-3})
    with cosim.FmuRunner(path) as runner:
        md = {v.name: v for v in runner.model_description.modelVariables}
        assert md["Rt"].causality == "calculatedParameter" and md["L1"].causality == "parameter"
        w = cosim.run_dut_fmu(runner, i, fs, start_values={"R0": 3e3, "L1": 2e-3})
        assert runner.instance.getReal([runner.vr("Rt")])[0] == pytest.approx(6e3, rel=1e-15)
    assert max_rel(w["v_in"], ref["v_in"]) < 1e-9 and max_rel(w["v_b"], ref["v_b"]) < 1e-9


# ---------------------------------------------------------------------- what FMI importers rely on
LOADER_C = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <string.h>
/* Opens an FMU binary the way the FMI Library does (RTLD_NOW | RTLD_LOCAL) in a process without libm. */
static int libm_loaded(void) {
    char line[4096];
    int found = 0;
    FILE *f = fopen("/proc/self/maps", "r");
    if (!f) return -1;
    while (fgets(line, sizeof line, f)) if (strstr(line, "/libm.so") || strstr(line, "/libm-")) found = 1;
    fclose(f);
    return found;
}
int main(int argc, char **argv) {
    int i;
    void *h;
    if (libm_loaded() != 0) { printf("libm is loaded before the FMU\n"); return 3; }
    h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) { printf("%s\n", dlerror()); return 1; }
    for (i = 2; i < argc; i++) if (!dlsym(h, argv[i])) { printf("missing %s\n", argv[i]); return 2; }
    printf("ok\n");
    return 0;
}
"""
FMI2_FUNCTIONS = ["fmi2Instantiate", "fmi2DoStep", "fmi2NewDiscreteStates", "fmi2GetDirectionalDerivative",
                  "fmi2GetFMUstate", "fmi2SerializeFMUstate"]
SHIPPED = sorted((Path(__file__).parents[2] / "fmus").rglob("*.fmu"))


def _binary(fmu: Path, into: Path) -> Path:
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(into)
    return next((into / "binaries").rglob("*.so"))


@pytest.mark.parametrize("which", ["built", "shipped"])
def test_binaries_link_what_they_use(fmus, tmp_path, which):
    """``ldd -r`` finds no undefined symbol, and a process without libm opens each binary with RTLD_LOCAL."""
    if shutil.which("ldd") is None or shutil.which("gcc") is None:
        pytest.skip("ldd or gcc is not installed")
    loader = tmp_path / "loader"
    (tmp_path / "loader.c").write_text(LOADER_C)
    subprocess.run(["gcc", "-o", str(loader), str(tmp_path / "loader.c")], check=True)  # no -lm
    paths = list(fmus.values()) if which == "built" else SHIPPED
    assert paths
    for k, fmu in enumerate(paths):
        so = _binary(fmu, tmp_path / str(k))
        ldd = subprocess.run(["ldd", "-r", str(so)], capture_output=True, text=True)
        assert "undefined symbol" not in ldd.stdout + ldd.stderr, (fmu.name, ldd.stdout + ldd.stderr)
        assert "libm.so" in ldd.stdout, fmu.name
        run = subprocess.run([str(loader), str(so), *FMI2_FUNCTIONS], capture_output=True, text=True)
        assert run.returncode == 0 and run.stdout.strip() == "ok", (fmu.name, run.stdout)


@pytest.mark.parametrize("key", ["two_arrangement", "three_arrangement", "parasitic_arrangement"])
def test_model_exchange_equals_co_simulation(fmus, key):
    """fmpy's CVODE across the announced PRBS time events equals the exact ZOH co-simulation to 1e-4."""
    path = fmus[key]
    md = read_model_description(str(path))
    stop, step = float(md.defaultExperiment.stopTime), float(md.defaultExperiment.stepSize)
    with cosim.FmuRunner(path) as runner:
        cs = runner.run(stop, step, output=["v_in", "i_in", "v_bprbs"])
    with cosim.FmuRunner(path, "ModelExchange") as runner:
        me = runner.run(stop, step, output=["v_in", "i_in", "v_bprbs"], solver="CVode", relative_tolerance=1e-8,
                        record_events=False)
    assert me["time"].size == cs["time"].size
    np.testing.assert_allclose(me["time"], cs["time"], rtol=0, atol=1e-12 * stop)
    for name in ("v_in", "i_in"):
        assert max_rel(me[name], cs[name]) < 1e-4, name
    np.testing.assert_array_equal(me["v_bprbs"], cs["v_bprbs"])


def test_model_exchange_announces_switching_instants(fmus):
    path = fmus["three_arrangement"]
    with cosim.FmuRunner(path, "ModelExchange") as runner:
        fmu = runner.instance
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        *_, values_changed, defined, next_time = fmu.newDiscreteStates()
        assert defined and next_time == pytest.approx(1 / THREE.fclk, rel=1e-15)
        changed = []
        for bit in range(1, 2**THREE.prbs_order):
            fmu.enterContinuousTimeMode()
            fmu.setTime(bit / THREE.fclk)
            fmu.completedIntegratorStep()
            fmu.enterEventMode()
            *_, values_changed, defined, next_time = fmu.newDiscreteStates()
            assert defined and next_time == pytest.approx((bit + 1) / THREE.fclk, rel=1e-12)
            changed.append(values_changed)
    bits = np.tile(lfsr_prbs(THREE.prbs_order, 1), 2)
    assert changed == list(bits[1:2**THREE.prbs_order] != bits[:2**THREE.prbs_order - 1])
    assert any(changed) and not all(changed)


def _started(runner: cosim.FmuRunner, stop: float | None = None) -> None:
    fmu = runner.instance
    fmu.setupExperiment(startTime=0.0, stopTime=stop)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


def test_bad_values_are_refused_with_the_reason(fmus):
    from fmpy.fmi1 import FMICallException

    with cosim.FmuRunner(fmus["three_source"]) as runner:
        _started(runner)
        for bad in (np.nan, np.inf, -np.inf):
            with pytest.raises(FMICallException):
                runner.instance.setReal([runner.vr("v_in")], [bad])
            assert "value of 'v_in' is not finite" in runner.messages[-1]
        runner.instance.doStep(0.0, 1e-6)
        assert np.isfinite(runner.instance.getReal([runner.vr("i_in")])[0])
    with cosim.FmuRunner(fmus["three_dut"]) as runner:  # the run-time rebuild keeps the last good values
        _started(runner)
        with pytest.raises(FMICallException):
            runner.instance.setReal([runner.vr("Rs")], [-1.0])
        assert "resistance must be positive" in runner.messages[-1]
        runner.instance.setReal([runner.vr("i_in")], [1e-3])
        runner.instance.doStep(0.0, 1e-6)
        assert np.isfinite(runner.instance.getReal([runner.vr("v_in")])[0])
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        with pytest.raises(cosim.FmuError, match="fclk.*more than the limit"):
            runner.run(0.4, 1e-3, start_values={"fclk": 1e9})
        with pytest.raises(cosim.FmuError, match="outside its range"):
            runner.run(1e-5, 1e-7, start_values={"fclk": 1e12})
        runner.fresh()
        with pytest.raises(FMICallException):
            runner.instance.setupExperiment(startTime=1.0, stopTime=0.5)
        assert "stop time 0.5 s is before the start time 1 s" in runner.messages[-1]


def test_model_exchange_refuses_time_going_backwards(fmus):
    from fmpy.fmi1 import FMICallException

    with cosim.FmuRunner(fmus["three_arrangement"], "ModelExchange") as runner:
        _started(runner)
        fmu = runner.instance
        fmu.newDiscreteStates()
        fmu.enterContinuousTimeMode()
        fmu.setTime(2e-6)
        fmu.setTime(1e-6)  # a rejected integrator step may go back up to the last completed step
        fmu.setTime(2e-6)
        fmu.completedIntegratorStep()
        with pytest.raises(FMICallException):
            fmu.setTime(1.5e-6)
        assert "before the last completed step or event" in runner.messages[-1]


def test_model_description_declares_what_importers_need(fmus):
    for name, path in fmus.items():
        md = read_model_description(str(path))
        variables = md.modelVariables
        assert md.defaultExperiment is not None and float(md.defaultExperiment.stopTime) > 0, name
        for v in variables:
            assert v.description, (name, v.name)
            if v.causality == "parameter":
                assert v.min is not None and v.max is not None, (name, v.name)
                assert float(v.min) <= float(v.start) <= float(v.max), (name, v.name)
        states = [v.derivative for v in variables if v.derivative is not None]
        assert states and all(s.nominal is not None and float(s.nominal) > 0 for s in states), name
        for v in variables:
            if v.name in ("Rs", "R1", "L1", "C1", "k12", "Lpris") and v.causality == "parameter":
                assert v.variability == "tunable", (name, v.name)
        for flag in ("canGetAndSetFMUstate", "canSerializeFMUstate", "providesDirectionalDerivative"):
            assert getattr(md.coSimulation, flag) and getattr(md.modelExchange, flag), (name, flag)
        for u in md.outputs + md.derivatives + md.initialUnknowns:
            assert u.dependencies is not None, (name, u.variable.name)
        assert {u.variable.name for u in md.outputs} <= {u.variable.name for u in md.initialUnknowns}, name


def test_output_dependencies_follow_the_state_space_form(fmus):
    """The DUT port voltage has direct feedthrough exactly when no capacitor sits at the port."""
    for key in ("three_dut", "hv_dut"):
        md = read_model_description(str(fmus[key]))
        i_in = next(v for v in md.modelVariables if v.name == "i_in")
        model = {"three_dut": lambda: codegen.dut_model(get_model("three-section").circuit, "n1"),
                 "hv_dut": lambda: codegen.dut_model(get_model("hv-4section").circuit, "a1",
                                                     get_model("hv-4section").configuration("LVSC").shorts)}[key]()
        ss = model.mna.state_space(model.circuit.resolve())
        for u in md.outputs:
            node = u.variable.name[2:] if u.variable.name != "v_in" else model.port
            row = model.mna.nodes.index(node)
            assert (i_in in u.dependencies) == bool(np.any(ss.D[0, row] != 0)), (key, u.variable.name)
            states = {v.name for v in u.dependencies if v is not i_in}
            expected = {model.mna.states[j] for j in np.flatnonzero(ss.C[0, row])}
            assert states == expected, (key, u.variable.name)


def test_fmu_state_rollback_and_serialisation_repeat_a_step_exactly(fmus):
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        _started(runner)
        fmu = runner.instance
        vr = [runner.vr("v_in"), runner.vr("i_in"), runner.vr("v_bprbs")]
        h = 0.37 / THREE.fclk
        for k in range(20):
            fmu.doStep(k * h, h)
        saved = fmu.getFMUstate()
        blob = fmu.serializeFMUstate(saved)
        first = []
        for k in range(20, 60):
            fmu.doStep(k * h, h)
            first.append(fmu.getReal(vr))
        for restore in (saved, fmu.deSerializeFMUstate(blob)):
            fmu.setFMUstate(restore)
            again = []
            for k in range(20, 60):
                fmu.doStep(k * h, h)
                again.append(fmu.getReal(vr))
            np.testing.assert_array_equal(again, first)
        fmu.freeFMUstate(saved)


def test_directional_derivatives_equal_the_state_space_matrices(fmus):
    """d(der x)/d(x, u) = A, B and d(outputs)/d(x, u) = C, D of the Python reduction."""
    three = get_model("three-section").circuit
    model = codegen.dut_model(three, "n1", name="three_dut")
    values = three.resolve({"Rs": 0.3})
    ss = model.mna.state_space(values)
    with cosim.FmuRunner(fmus["three_dut"], "ModelExchange") as runner:
        fmu = runner.instance
        fmu.setupExperiment(startTime=0.0)
        fmu.setReal([runner.vr("Rs")], [0.3])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        states = [runner.vr(s) for s in model.mna.states]
        ders = [runner.vr(f"der({s})") for s in model.mna.states]
        outs = [runner.vr(v.name) for v in (o.variable for o in model.outputs)]
        rows = [model.mna.nodes.index(model.port)] + [model.mna.nodes.index(v.name[2:])
                                                     for v in (o.variable for o in model.outputs[1:])]
        knowns = states + [runner.vr("i_in")]
        J = np.column_stack([fmu.getDirectionalDerivative(ders + outs, knowns, list(e))
                             for e in np.eye(len(knowns))])
    ref = np.block([[ss.A[0], ss.B[0]], [ss.C[0, rows], ss.D[0, rows]]])
    np.testing.assert_allclose(J, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())


def test_tunable_element_values_reassemble_the_model(fmus):
    """Rs set after initialisation gives the same waveform as Rs set as a start value."""
    fs = 1e6
    ref = td.simulate_pris(get_model("three-section").circuit, "n1", THREE, fs, overrides={"Rs": 0.2})
    with cosim.FmuRunner(fmus["three_arrangement"]) as runner:
        _started(runner)
        fmu = runner.instance
        fmu.setReal([runner.vr("Rs")], [0.2])
        n = ref["time_s"].size
        got = np.empty(n)
        for k in range(n):
            got[k] = fmu.getReal([runner.vr("v_in")])[0]
            fmu.doStep(k / fs, 1 / fs)
    assert max_rel(got, ref["v_in"]) < 1e-9
