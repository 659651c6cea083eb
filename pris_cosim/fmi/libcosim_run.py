"""Run FMUs and SSP systems in libcosim, the Open Simulation Platform's co-simulation library (libcosimpy).

libcosim steps every FMU as FMI 2.0 Co-Simulation with its fixed-step
master: all FMUs step from ``t`` to ``t + h`` at once, each with the others'
outputs at ``t`` (Jacobi coupling), on an integer nanosecond clock. libcosim
has no FMI 3.0 support (libcosimpy 0.0.6 ends the process when an FMI 3.0
FMU is added), so only FMI 2.0 FMUs go in.

A crash inside libcosim ends the Python process; callers that must survive
one (tests, benchmarks) run this module as a command in a subprocess::

    python -m pris_cosim.fmi.libcosim_run fmu FILE.fmu --stop 1e-3 --step-ns 100 --set i_in=1e-3 --out r.npz
    python -m pris_cosim.fmi.libcosim_run pair SOURCE.fmu DUT.fmu --stop 1e-3 --step-ns 80 --out r.npz
    python -m pris_cosim.fmi.libcosim_run ssp SYSTEM.ssp [--stop 1e-3] [--step-ns 80] --out r.npz

Each writes an ``.npz`` with ``time_s`` (the communication points after the
start, ``h, 2h, ..., stop``) and one array per recorded variable
(``name`` for one FMU, ``component.name`` for a system), and prints the
wall time of the simulation as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pris_cosim.errors import CircuitError

#: How to install the package when it is missing.
INSTALL_HINT = "libcosimpy is not installed (pip install libcosimpy)"


def available() -> bool:
    """Whether libcosimpy can be imported (it ships libcosim's shared library)."""
    try:
        import libcosimpy  # noqa: F401
    except Exception:
        return False
    return True


def _lib():
    try:
        from libcosimpy.CosimEnums import CosimVariableType
        from libcosimpy.CosimExecution import CosimExecution
        from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
        from libcosimpy.CosimObserver import CosimObserver
        from libcosimpy.CosimSlave import CosimLocalSlave
    except ImportError:
        raise RuntimeError(INSTALL_HINT) from None
    log_output_level(CosimLogLevel.ERROR)
    return CosimExecution, CosimLocalSlave, CosimObserver, CosimVariableType


def _ns(seconds: float) -> int:
    ns = float(seconds) * 1e9
    if abs(ns - round(ns)) > 1e-6 * max(1.0, abs(ns)):
        raise ValueError(f"{seconds!r} s is not a whole number of nanoseconds (libcosim's clock)")
    return int(round(ns))


def _check_fmi2(path: Path) -> None:
    import zipfile
    from xml.etree import ElementTree

    with zipfile.ZipFile(path) as zf:
        version = ElementTree.fromstring(zf.read("modelDescription.xml")).get("fmiVersion", "")
    if not version.startswith("2."):
        raise ValueError(f"{path.name}: FMI {version} FMU; libcosim runs FMI 2.0 FMUs only")


class _Execution:
    """A libcosim execution with time-series recording of chosen real variables."""

    def __init__(self, execution, observer_cls, var_type, samples: int) -> None:
        self.ex = execution
        self.real = var_type.REAL
        self.integer = var_type.INTEGER
        self.obs = observer_cls.create_time_series(buffer_size=int(samples) + 16)
        self.ex.add_observer(self.obs)
        self.recorded: list[tuple[str, int, int]] = []

    def variables(self, index: int) -> dict[str, tuple[int, int]]:
        return {v.name.decode(): (v.reference, v.type) for v in self.ex.slave_variables(index)}

    def set_start(self, index: int, values: Mapping[str, float]) -> None:
        variables = self.variables(index)
        for name, value in values.items():
            if name not in variables:
                raise ValueError(f"no variable {name!r} in component {index}")
            ref, vtype = variables[name]
            if int(vtype) == int(self.integer.value):
                self.ex.integer_initial_value(index, ref, int(value))
            else:
                self.ex.real_initial_value(index, ref, float(value))

    def record(self, label: str, index: int, name: str) -> None:
        ref = self.variables(index)[name][0]
        if not self.obs.start_time_series(index, ref, self.real):
            raise RuntimeError(f"libcosim cannot record {label}")
        self.recorded.append((label, index, ref))

    def run(self, stop_ns: int, step_ns: int) -> tuple[dict[str, np.ndarray], float]:
        n = stop_ns // step_ns
        t0 = time.perf_counter()
        if not self.ex.simulate_until(stop_ns):
            raise RuntimeError(f"libcosim stopped before {stop_ns} ns: {self.ex.status()}")
        wall = time.perf_counter() - t0
        out: dict[str, np.ndarray] = {}
        times = None
        for label, index, ref in self.recorded:
            tp, _, values = self.obs.time_series_real_samples(index, ref, from_step=1, sample_count=n)
            if len(values) != n:
                raise RuntimeError(f"libcosim returned {len(values)} samples of {label}, expected {n}")
            out[label] = np.asarray(values, dtype=float)
            times = np.asarray(tp, dtype=float) * 1e-9
        out["time_s"] = times if times is not None else np.arange(1, n + 1) * step_ns * 1e-9
        return out, wall


def run_fmu(fmu: str | Path, stop: float, step: float, start_values: Mapping[str, float] | None = None,
            outputs: Sequence[str] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """One FMI 2.0 FMU as Co-Simulation in libcosim.

    Parameters
    ----------
    fmu : path
    stop, step : float, s
        Whole numbers of nanoseconds, ``stop`` a multiple of ``step``.
    start_values : mapping, optional
        Values of parameters and inputs (inputs then stay constant).
    outputs : sequence of str, optional
        Variables to record (default: every output).

    Returns
    -------
    dict, float
        ``time_s`` and the recorded variables at ``h, 2h, ..., stop``; the wall time in s.
    """
    Execution, Slave, Observer, VarType = _lib()
    path = Path(fmu)
    _check_fmi2(path)
    stop_ns, step_ns = _ns(stop), _ns(step)
    run = _Execution(Execution.from_step_size(step_ns), Observer, VarType, stop_ns // step_ns)
    index = run.ex.add_local_slave(Slave(fmu_path=str(path.resolve()), instance_name="fmu"))
    if start_values:
        run.set_start(index, start_values)
    if outputs is None:
        from fmpy.model_description import read_model_description

        outputs = [v.name for v in read_model_description(str(path)).modelVariables if v.causality == "output"]
    for name in outputs:
        run.record(name, index, name)
    return run.run(stop_ns, step_ns)


def run_pair(source: str | Path, dut: str | Path, stop: float, step: float,
             source_values: Mapping[str, float] | None = None, dut_values: Mapping[str, float] | None = None,
             ) -> tuple[dict[str, np.ndarray], float]:
    """The PRIS source FMU coupled to a DUT FMU in libcosim's fixed-step (Jacobi) master.

    Returns ``time_s``, ``source.i_in``, ``source.v_bprbs`` and ``dut.v_in`` at
    ``h, 2h, ..., stop``, and the wall time in s.
    """
    Execution, Slave, Observer, VarType = _lib()
    stop_ns, step_ns = _ns(stop), _ns(step)
    for p in (source, dut):
        _check_fmi2(Path(p))
    run = _Execution(Execution.from_step_size(step_ns), Observer, VarType, stop_ns // step_ns)
    s = run.ex.add_local_slave(Slave(fmu_path=str(Path(source).resolve()), instance_name="source"))
    d = run.ex.add_local_slave(Slave(fmu_path=str(Path(dut).resolve()), instance_name="dut"))
    vs, vd = run.variables(s), run.variables(d)
    run.ex.connect_real_variables(s, vs["i_in"][0], d, vd["i_in"][0])
    run.ex.connect_real_variables(d, vd["v_in"][0], s, vs["v_in"][0])
    run.set_start(s, source_values or {})
    run.set_start(d, dut_values or {})
    for label, index, name in (("source.i_in", s, "i_in"), ("source.v_bprbs", s, "v_bprbs"), ("dut.v_in", d, "v_in")):
        run.record(label, index, name)
    return run.run(stop_ns, step_ns)


def run_ssp(ssp: str | Path, stop: float | None = None, step: float | None = None,
            record: Sequence[tuple[str, str]] | None = None,
            ) -> tuple[dict[str, np.ndarray], float]:
    """An SSP system (``.ssp`` archive or ``.ssd``) loaded by ``CosimExecution.from_ssp_file``.

    Parameters
    ----------
    ssp : path
    stop : float, s, optional
        Default: the system's default experiment.
    step : float, s, optional
        Default: the step of the system's default experiment.
    record : sequence of (component, variable), optional
        Default: the terminal voltage and current and the bridge voltage
        (:func:`pris_cosim.fmi.ssp.recorded_outputs`).

    Returns
    -------
    dict, float
        ``time_s`` and ``component.variable`` arrays; the wall time in s.
    """
    Execution, _, Observer, VarType = _lib()
    from pris_cosim.fmi.ssp import default_experiment, recorded_outputs

    exp_stop, exp_step = default_experiment(ssp)
    if record is None:
        record = recorded_outputs(ssp)
    stop_ns = _ns(stop if stop is not None else exp_stop)
    step_ns = _ns(step if step is not None else exp_step)
    ex = (Execution.from_ssp_file(str(Path(ssp).resolve())) if step is None
          else Execution.from_ssp_file(str(Path(ssp).resolve()), step_ns))
    run = _Execution(ex, Observer, VarType, stop_ns // step_ns)
    for comp, name in record:
        run.record(f"{comp}.{name}", run.ex.slave_index_from_instance_name(comp), name)
    return run.run(stop_ns, step_ns)


def _values(items: Sequence[str]) -> dict[str, float]:
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        out[name] = float(value)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pris_cosim.fmi.libcosim_run", description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("fmu", "pair", "ssp"))
    ap.add_argument("files", nargs="+")
    ap.add_argument("--stop", type=float)
    ap.add_argument("--step-ns", type=int)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--dut-set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    step = None if args.step_ns is None else args.step_ns * 1e-9
    try:
        if args.what == "fmu":
            res, wall = run_fmu(args.files[0], args.stop, step, _values(args.set))
        elif args.what == "pair":
            res, wall = run_pair(args.files[0], args.files[1], args.stop, step, _values(args.set),
                                 _values(args.dut_set))
        else:
            res, wall = run_ssp(args.files[0], args.stop, step)
    except (ValueError, RuntimeError, OSError, CircuitError) as exc:
        print(f"libcosim_run: error: {exc}", file=sys.stderr)
        return 2
    np.savez(args.out, **res)
    print(json.dumps({"wall_s": wall, "samples": int(res["time_s"].size)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
