"""The FMUs and the SSP export in libcosim (the Open Simulation Platform's co-simulation library).

libcosim is an independent FMI importer and master: it loads the FMUs with
the FMI Library, steps them on an integer nanosecond clock and couples them
with its fixed-step (Jacobi) master. These tests keep to FMI 2.0 there:
libcosim has no FMI 3.0 support, and libcosimpy ends the process when an FMI
3.0 FMU is added. Each libcosim run happens in a subprocess
(``python -m pris_cosim.fmi.libcosim_run``), so that a crash in the library
fails one test instead of ending the test session.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy.model_description import read_model_description

from pris_cosim.fmi import cosim, libcosim_run, ssp
from pris_cosim.fmi.cosim_exact import cosimulate_exact

pytestmark = pytest.mark.skipif(
    not libcosim_run.available(),
    reason="libcosimpy is not installed (libcosim, the Open Simulation Platform's co-simulation library; "
           "pip install libcosimpy)")

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "fmus").glob("*/*.fmu"))
TWO = ROOT / "fmus" / "two-section"
THREE = ROOT / "fmus" / "three-section"


def libcosim(tmp_path: Path, *args: str) -> dict[str, np.ndarray]:
    out = tmp_path / f"libcosim-{len(list(tmp_path.glob('libcosim-*')))}.npz"
    proc = subprocess.run([sys.executable, "-m", "pris_cosim.fmi.libcosim_run", *args, "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, f"libcosim run failed ({proc.returncode}): {proc.stderr[-2000:]}"
    json.loads(proc.stdout.strip().splitlines()[-1])
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def peak_rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))


@pytest.mark.parametrize("fmu", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_fmu_runs_in_libcosim_as_fmpy_does(tmp_path, fmu):
    """Co-Simulation in libcosim equals fmpy to 1e-9 of the peak, over 2000 default steps, on the same grid."""
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "2.0"
    step = float(md.defaultExperiment.stepSize)
    step_ns = round(step * 1e9)
    assert step_ns == pytest.approx(step * 1e9, abs=1e-6)  # the default step is on libcosim's clock
    stop = 2000 * step_ns * 1e-9
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    values = {name: 1e-3 if name == "i_in" else 5.0 for name in inputs}
    lc = libcosim(tmp_path, "fmu", str(fmu), "--stop", repr(stop), "--step-ns", str(step_ns),
                  *[f"--set={k}={v!r}" for k, v in values.items()])
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    with cosim.FmuRunner(fmu) as runner:
        ref = runner.run(stop, step_ns * 1e-9, output=outputs, start_values=values)
    assert lc["time_s"].size == 2000 and ref["time"].size == 2001
    np.testing.assert_allclose(lc["time_s"], ref["time"][1:], rtol=0, atol=1e-15)
    for name in outputs:
        assert np.abs(ref[name]).max() > 0, name
        assert peak_rel(lc[name], ref[name][1:]) < 1e-9, name


def _exact(source: Path, dut: Path, fs: float, n: int, source_values: dict) -> dict[str, np.ndarray]:
    with cosim.FmuRunner(source, "ModelExchange") as s, cosim.FmuRunner(dut, "ModelExchange") as d:
        w, _ = cosimulate_exact(s, d, fs, n, source_values=source_values)
    return w


def _jacobi(source: Path, dut: Path, fs: float, n: int, source_values: dict) -> dict[str, np.ndarray]:
    with cosim.FmuRunner(source) as s, cosim.FmuRunner(dut) as d:
        return cosim.cosimulate(s, d, fs, n, scheme="jacobi", source_values=source_values)


def test_ssp_export_loads_in_libcosim_and_runs_as_the_jacobi_master(tmp_path):
    """``CosimExecution.from_ssp_file`` runs the exported system: its connections, the .ssv values (vdc changed
    here) and the default step. libcosim's fixed-step master is Jacobi coupling: the result equals our Jacobi
    master on the same grid, and differs from the exact co-simulation by the coupling error of that step."""
    stop, step = 0.02, 3125e-9
    path = ssp.write_ssp(TWO / "two_section_source.fmu", TWO / "two_section_dut.fmu", tmp_path / "two.ssp",
                         experiment=(stop, step), source_values={"vdc": 10.0})
    lc = libcosim(tmp_path, "ssp", str(path))
    n = round(stop / step) + 1
    jac = _jacobi(TWO / "two_section_source.fmu", TWO / "two_section_dut.fmu", 1 / step, n, {"vdc": 10.0})
    assert lc["time_s"].size == n - 1
    for lc_name, name in (("dut.v_in", "v_in"), ("source.i_in", "i_in")):
        assert peak_rel(lc[lc_name], jac[name][1:]) < 1e-9, name
    exact = _exact(TWO / "two_section_source.fmu", TWO / "two_section_dut.fmu", 1 / step, n, {"vdc": 10.0})
    assert np.abs(exact["v_bprbs"]).max() == 10.0
    # the coupling guidance (fmus/README.md): Jacobi at the default step is 22.8 % off on v_in, 20.6 % on i_in
    assert 0.18 < cosim.relative_rms(lc["dut.v_in"], exact["v_in"][1:]) < 0.28
    assert 0.16 < cosim.relative_rms(lc["source.i_in"], exact["i_in"][1:]) < 0.26


def _guidance_check(tmp_path: Path, folder: str, base: str, step_ns: int, bits: int, grid_ns: int) -> None:
    src, dut = ROOT / "fmus" / folder / f"{base}_source.fmu", ROOT / "fmus" / folder / f"{base}_dut.fmu"
    md = read_model_description(str(src))
    fclk = next(float(v.start) for v in md.modelVariables if v.name == "fclk")
    stop = bits / fclk
    path = ssp.write_ssp(src, dut, tmp_path / f"{base}.ssp")
    lc = libcosim(tmp_path, "ssp", str(path), "--stop", repr(stop), "--step-ns", str(step_ns))
    k = grid_ns // step_ns  # compare on a coarser grid, where the exact master is cheap
    n = round(stop / (grid_ns * 1e-9)) + 1
    exact = _exact(src, dut, 1e9 / grid_ns, n, {})
    for lc_name, name in (("dut.v_in", "v_in"), ("source.i_in", "i_in")):
        assert cosim.relative_rms(lc[lc_name][k - 1::k], exact[name][1:]) < 0.01, name


@pytest.mark.slow
def test_libcosim_at_the_guidance_step_is_within_one_percent_two_section(tmp_path):
    """At the largest step that the coupling guidance gives for 1 % with a Jacobi master (two-section: 160 ns,
    50 PRBS bits), libcosim running the SSP export is within 1 % RMS of the exact co-simulation."""
    _guidance_check(tmp_path, "two-section", "two_section", 160, 50, 1600)


@pytest.mark.slow
def test_libcosim_at_the_guidance_step_is_within_one_percent_three_section(tmp_path):
    """Three-section: 1 ns over 100 PRBS bits (a million libcosim steps)."""
    _guidance_check(tmp_path, "three-section", "three_section", 1, 100, 80)


@pytest.mark.parametrize("system", sorted((ROOT / "fmus").glob("*/*.ssp")), ids=lambda p: p.stem)
def test_shipped_ssp_runs_in_libcosim_at_its_default_step(tmp_path, system):
    """The shipped systems load as they are, with the step of their default experiment."""
    stop, step = ssp.default_experiment(system)
    lc = libcosim(tmp_path, "ssp", str(system), "--stop", repr(200 * step))
    assert lc["time_s"].size == 200
    np.testing.assert_allclose(lc["time_s"], np.arange(1, 201) * step, rtol=1e-12)
    assert np.abs(lc["load.v_in"]).max() > 0 and np.abs(lc["load.i_in"]).max() > 0


def test_fmi3_fmus_are_refused_before_libcosim_sees_them(tmp_path):
    """libcosimpy ends the process (segmentation fault) when an FMI 3.0 FMU is added: refused with one line."""
    import zipfile

    fake = tmp_path / "fmi3.fmu"
    with zipfile.ZipFile(fake, "w") as zf:
        zf.writestr("modelDescription.xml", '<?xml version="1.0"?><fmiModelDescription fmiVersion="3.0" '
                                            'modelName="m" instantiationToken="x"/>')
    proc = subprocess.run([sys.executable, "-m", "pris_cosim.fmi.libcosim_run", "fmu", str(fake), "--stop", "1e-6",
                           "--step-ns", "100", "--out", str(tmp_path / "r.npz")], capture_output=True, text=True,
                          cwd=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "libcosim_run: error: fmi3.fmu: FMI 3.0 FMU; libcosim runs FMI 2.0 FMUs only"
