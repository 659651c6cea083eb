"""The shipped SSP archives in other masters, at their own default step, against the monolithic FMU in fmpy.

Each archive ``fmus/<case>/<name>.ssp`` (the bridge split: the H-bridge FMU
drives the FMU of the series RLC and winding through the bridge voltage) is
run as a user of the master would: loaded from the archive, at the step of
its ``DefaultExperiment``, with the parameter set it carries. The reference
is the same folder's ``*_pris.fmu`` (source and winding in one network) run
by fmpy on the same grid. Masters: libcosim (``CosimExecution.from_ssp_file``,
integer nanosecond clock), ecos (``ecospy``, a clock that adds the step, so
its communication points drift from the multiples of the step) and fmpy's
own SSP master (``fmpy.ssp.simulation.simulate_ssp``, which starts every
connection at 0 and adds the step to its time). Each master runs in a
subprocess (libcosim, ecos) so that a crash fails one test.

The bridge voltage is constant over every step that divides the PRBS bit,
so a fixed-step master is exact: the tests ask for 1e-9 relative RMS on
``v_in`` and ``i_in`` (fmpy's SSP master: 1 %, for its first step with the
bridge voltage at 0).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

from pris_cosim.fmi import ecos_run, libcosim_run, ssp

ROOT = Path(__file__).resolve().parents[2]
SYSTEMS = sorted((ROOT / "fmus").glob("*/*.ssp"))
#: Shipped systems whose whole default experiment is short enough for the default test run.
QUICK = {"two_section"}


def _rel_rms(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - ref) ** 2) / np.mean(ref**2)))


def _monolithic(system: Path, stop: float, step: float) -> np.ndarray:
    pris = system.parent / f"{system.stem}_pris.fmu"
    return simulate_fmu(str(pris), stop_time=stop, output_interval=step, output=["v_in", "i_in", "v_bprbs"])


def _subprocess(tmp_path: Path, module: str, *args: str) -> dict[str, np.ndarray]:
    out = tmp_path / f"{module.rsplit('.', 1)[-1]}.npz"
    proc = subprocess.run([sys.executable, "-m", module, *args, "--out", str(out)], capture_output=True, text=True,
                          cwd=ROOT, timeout=1800)
    assert proc.returncode == 0, f"{module} failed ({proc.returncode}): {proc.stderr[-2000:]}"
    json.loads(proc.stdout.strip().splitlines()[-1])
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def _compare(result: dict[str, np.ndarray], ref: np.ndarray, n: int, step: float, limit: float) -> None:
    assert result["time_s"].size == n
    # a clock that adds the step drifts by rounding, up to about eps * t^2 / h at time t
    stop = n * step
    np.testing.assert_allclose(result["time_s"], ref["time"][1:], rtol=0,
                               atol=np.finfo(float).eps * stop * stop / step + 1e-15 * stop)
    for label, name in (("load.v_in", "v_in"), ("load.i_in", "i_in"), ("bridge.v_bprbs", "v_bprbs")):
        err = _rel_rms(result[label], ref[name][1:])
        assert err < limit, f"{label}: {err:.3g} relative RMS against the monolithic FMU"


def _window(system: Path, quick_bits: int | None) -> tuple[float, float, int]:
    stop, step = ssp.default_experiment(system)
    if quick_bits is not None:
        from fmpy.model_description import read_model_description

        md = read_model_description(str(system.parent / f"{system.stem}_bridge.fmu"))
        fclk = next(float(v.start) for v in md.modelVariables if v.name == "fclk")
        stop = min(stop, round(quick_bits / fclk / step) * step)
    return stop, step, round(stop / step)


def _cases(slow_unless_quick: bool) -> list:
    return [pytest.param(p, id=p.stem, marks=() if p.stem in QUICK or not slow_unless_quick else pytest.mark.slow)
            for p in SYSTEMS]


def test_shipped_archives_are_the_bridge_split():
    assert {p.stem for p in SYSTEMS} == {"two_section", "three_section"}
    for system in SYSTEMS:
        assert ssp.components(system) == ["bridge", "load"]
        assert "exact at any step that divides the bit" in ssp.read_ssd(system)


@pytest.mark.skipif(not libcosim_run.available(), reason=libcosim_run.INSTALL_HINT)
@pytest.mark.parametrize("system", _cases(True))
def test_libcosim_runs_each_shipped_archive_at_its_step_as_the_monolithic_fmu(tmp_path, system):
    """libcosim, whole default experiment (two-section 96,000 steps; three-section 511,875 steps, slow)."""
    stop, step, n = _window(system, None)
    lc = _subprocess(tmp_path, "pris_cosim.fmi.libcosim_run", "ssp", str(system))
    _compare(lc, _monolithic(system, stop, step), n, step, 1e-9)


@pytest.mark.skipif(not libcosim_run.available(), reason=libcosim_run.INSTALL_HINT)
def test_libcosim_runs_the_three_section_archive_over_its_first_bits(tmp_path):
    """The first 200 PRBS bits of the three-section archive (25,000 steps of 80 ns) in the default run."""
    system = ROOT / "fmus" / "three-section" / "three_section.ssp"
    stop, step, n = _window(system, 200)
    lc = _subprocess(tmp_path, "pris_cosim.fmi.libcosim_run", "ssp", str(system), "--stop", repr(stop))
    _compare(lc, _monolithic(system, stop, step), n, step, 1e-9)


@pytest.fixture(scope="module")
def ecos() -> None:
    if not ecos_run.available():
        pytest.skip(ecos_run.INSTALL_HINT)


@pytest.mark.parametrize("system", _cases(True))
def test_ecos_runs_each_shipped_archive_at_its_step_as_the_monolithic_fmu(tmp_path, ecos, system):
    """ecos adds the step to its clock: late in the experiment its communication points are off the multiples of
    the step by rounding, and the bridge FMU must still switch at the step that ends on a PRBS clock instant."""
    stop, step, n = _window(system, None)
    res = _subprocess(tmp_path, "pris_cosim.fmi.ecos_run", str(system))
    _compare(res, _monolithic(system, stop, step), n, step, 1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("system", SYSTEMS, ids=lambda p: p.stem)
def test_fmpy_ssp_master_runs_each_shipped_archive_within_one_percent(system):
    """fmpy's SSP master starts every connection at 0, so the load sees 0 V over the first step: within 1 %."""
    from fmpy.ssp.simulation import simulate_ssp

    stop, step, n = _window(system, None)
    res = simulate_ssp(str(system), stop_time=stop, step_size=step)
    ref = _monolithic(system, stop, step)
    for label, name in (("load.v_in", "v_in"), ("load.i_in", "i_in")):
        assert _rel_rms(res[label][:n], ref[name][1:]) < 0.01, label


@pytest.mark.skipif(not libcosim_run.available(), reason=libcosim_run.INSTALL_HINT)
def test_bridge_split_with_switch_parasitics_and_snubber_is_exact_in_libcosim(tmp_path):
    """The switch inductance and capacitance and the RC snubber go into the load: the bridge voltage stays the only
    coupling signal, piecewise constant, and libcosim at a step dividing the bit equals the monolithic FMU."""
    from dataclasses import replace

    from pris_cosim.fmi import codegen
    from pris_cosim.circuits.arrangement import SourceSettings
    from pris_cosim.fmi.build import build_fmu
    from pris_cosim.models.builtin import get_model

    settings = SourceSettings(vdc=100.0, prbs_order=5, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6,
                              rsnub=50.0, csnub=2e-9, lsw=1e-6, csw=1e-10)
    step, stop = 100e-9, 62 / 100e3  # 100 steps per bit, two PRBS5 periods
    dut = get_model("three-section").circuit
    models = {"bridge": codegen.bridge_model(settings, name="par_bridge"),
              "load": codegen.load_model(dut, "n1", settings, name="par_load"),
              "arrangement": codegen.arrangement_model(dut, "n1", settings, name="par_pris")}
    paths = {k: build_fmu(replace(m, experiment=(stop, step)), tmp_path, write_modelica=False)
             for k, m in models.items()}
    system = ssp.write_ssp(paths["bridge"], paths["load"], tmp_path / "par.ssp")
    lc = _subprocess(tmp_path, "pris_cosim.fmi.libcosim_run", "ssp", str(system))
    ref = simulate_fmu(str(paths["arrangement"]), stop_time=stop, output_interval=step,
                       output=["v_in", "i_in", "v_bprbs"])
    _compare(lc, ref, round(stop / step), step, 1e-9)
