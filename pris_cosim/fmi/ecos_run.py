"""Run SSP systems in ecos, a co-simulation engine with an SSP loader (on the package index as ``ecospy``).

ecos steps every FMU as FMI 2.0 Co-Simulation with a fixed-step (Jacobi)
master on a floating-point clock (it adds the step to its time), and applies
one ``.ssv`` parameter set, chosen by name, at initialisation: the archives
name every set :data:`pris_cosim.fmi.ssp.PARAMETER_SET`.

``ecospy``'s shared library needs ``libtbb.so.12`` (from the ``tbb``
package), which the loader does not find on its own: :func:`load` opens it
first, globally, so that ``ecospy`` resolves against it (the same as
preloading it with ``LD_PRELOAD``).

A crash inside ecos ends the Python process; callers that must survive one
(tests, benchmarks) run this module as a command in a subprocess::

    python -m pris_cosim.fmi.ecos_run SYSTEM.ssp [--stop 1e-3] [--step-ns 80] --out r.npz

It writes an ``.npz`` with ``time_s`` (the communication points after the
start, ``h, 2h, ..., stop``) and one array per recorded variable
(``component.name``), and prints the wall time of the simulation as JSON.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import sys
import sysconfig
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pris_cosim.errors import CircuitError

#: How to install what is missing.
INSTALL_HINT = "ecospy is not installed, or libtbb.so.12 is not found (pip install ecospy tbb)"
TBB_NAME = "libtbb.so.12"


def tbb_library() -> Path | None:
    """``libtbb.so.12`` of the ``tbb`` package (installed into the environment's ``lib``), or None."""
    candidates = [Path(sysconfig.get_config_var("LIBDIR") or ""), Path(sys.prefix) / "lib",
                  Path(sys.exec_prefix) / "lib"]
    try:
        from importlib.metadata import files

        candidates += [Path(f.locate()).parent for f in files("tbb") or () if f.name == TBB_NAME]
    except Exception:
        pass
    return next((d / TBB_NAME for d in candidates if (d / TBB_NAME).is_file()), None)


def load():
    """Open ``libtbb.so.12`` globally and import ``ecospy``; returns ``ecospy.EcosSimulation``.

    Raises
    ------
    RuntimeError
        ecospy or libtbb is missing (:data:`INSTALL_HINT`).
    """
    tbb = tbb_library()
    try:
        if tbb is not None:
            ctypes.CDLL(str(tbb), mode=ctypes.RTLD_GLOBAL)
        from ecospy import EcosSimulation
    except (ImportError, OSError):
        raise RuntimeError(INSTALL_HINT) from None
    return EcosSimulation


def available() -> bool:
    """Whether ecospy imports with libtbb found (checked in a subprocess, so a failed load leaves no trace here)."""
    import subprocess

    proc = subprocess.run([sys.executable, "-c", "from pris_cosim.fmi.ecos_run import load; load()"],
                          capture_output=True, text=True, cwd=str(Path(__file__).resolve().parents[1]))
    return proc.returncode == 0


def run_ssp(ssp: str | Path, stop: float | None = None, step: float | None = None,
            record: Sequence[tuple[str, str]] | None = None) -> tuple[dict[str, np.ndarray], float]:
    """An SSP archive in ecos at a fixed step, its parameter set :data:`~pris_cosim.fmi.ssp.PARAMETER_SET` applied.

    Parameters
    ----------
    ssp : path
    stop : float, s, optional
        Default: the system's default experiment.
    step : float, s, optional
        Default: the step of the system's default experiment.
    record : sequence of (component, variable), optional
        Default: :func:`pris_cosim.fmi.ssp.recorded_outputs`.

    Returns
    -------
    dict, float
        ``time_s`` and ``component.variable`` arrays at ``h, 2h, ..., stop``; the wall time in s.
    """
    from pris_cosim.fmi.ssp import PARAMETER_SET, default_experiment, recorded_outputs

    Simulation = load()
    exp_stop, exp_step = default_experiment(ssp)
    stop = float(exp_stop if stop is None else stop)
    step = float(exp_step if step is None else step)
    n = round(stop / step)
    if n < 1 or abs(n * step - stop) > 1e-9 * step:
        raise ValueError(f"stop {stop!r} s is not a whole number of steps of {step!r} s")
    record = list(record or recorded_outputs(ssp))
    sim = Simulation(step_size=step, ssp_path=str(Path(ssp).resolve()))
    try:
        if not sim.init(parameter_set=PARAMETER_SET):
            raise RuntimeError(f"ecos could not initialise {Path(ssp).name} with parameter set {PARAMETER_SET!r}")
        names = [f"{comp}::{var}" for comp, var in record]
        get = sim.get_real
        values = np.empty((n, len(names)))
        times = np.empty(n)
        t0 = time.perf_counter()
        for k in range(n):
            times[k] = sim.step(1)
            values[k] = [get(name) for name in names]
        wall = time.perf_counter() - t0
        sim.terminate()
    finally:
        sim.free()
    out = {f"{comp}.{var}": values[:, j] for j, (comp, var) in enumerate(record)}
    out["time_s"] = times
    return out, wall


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pris_cosim.fmi.ecos_run", description=__doc__.splitlines()[0])
    ap.add_argument("ssp")
    ap.add_argument("--stop", type=float)
    ap.add_argument("--step-ns", type=float)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    step = None if args.step_ns is None else args.step_ns * 1e-9
    try:
        res, wall = run_ssp(args.ssp, args.stop, step)
    except (ValueError, RuntimeError, OSError, CircuitError) as exc:
        print(f"ecos_run: error: {exc}", file=sys.stderr)
        return 2
    np.savez(args.out, **res)
    print(json.dumps({"wall_s": wall, "samples": int(res["time_s"].size)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
