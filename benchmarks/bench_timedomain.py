"""Wall time of the time-domain engines on the three-section PRIS case (prints figures; not a test).

Case (thesis 4.2.2, architecture.md): three-section winding, Vdc = 100 V,
Rpris = 150 Ohm, Lpris = 4 mH, Cpris = 1 uF, PRBS12 at 100 kHz, sampled at
10 MHz: one PRBS period is 409,500 samples (40.95 ms).

Engines: the numpy exact ZOH engine, the monolithic FMU run by fmpy
(co-simulation, one communication step per sample), the source + DUT FMUs
co-simulated by the Gauss-Seidel master, and ngspice (PWL bridge, ``uic``,
a maximum time step). Accuracy is the relative RMS difference against the
numpy engine.

Usage::

    python benchmarks/bench_timedomain.py [--order 12] [--ngspice-max-step 2e-8] [--no-ngspice] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pris_cosim import codegen, cosim, fmi, ngspice
from pris_cosim import timedomain as td
from pris_cosim.arrangement import SourceSettings
from pris_cosim.models import get_model


def timed(fn, repeat: int = 1):
    """(median wall time in s, last result) of ``repeat`` calls."""
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--order", type=int, default=12, help="PRBS order (default 12)")
    ap.add_argument("--fs", type=float, default=10e6, help="sampling frequency, Hz (default 10 MHz)")
    ap.add_argument("--ngspice-max-step", type=float, default=20e-9, help="ngspice maximum step, s (default 20 ns)")
    ap.add_argument("--no-ngspice", action="store_true", help="skip ngspice")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args(argv)

    dut = get_model("three-section").circuit
    s = SourceSettings(vdc=100.0, prbs_order=args.order, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    rows: dict[str, dict[str, float]] = {}

    t_np, ref = timed(lambda: td.simulate_pris(dut, "n1", s, args.fs), repeat=3)
    n = ref["time_s"].size
    rows["numpy"] = {"wall_s": t_np, "samples": n}
    print(f"case: three-section, PRBS{args.order} at 100 kHz, fs = {args.fs:g} Hz, {n} samples", file=sys.stderr)

    def err(w):
        return {f"err_{k}": cosim.relative_rms(w[k], ref[k]) for k in ("v_in", "i_in")}

    with tempfile.TemporaryDirectory() as tmp:
        model = codegen.arrangement_model(dut, "n1", s, name="bench_pris")
        t_build, path = timed(lambda: fmi.build_fmu(model, tmp, use_cache=False, write_modelica=False))
        with cosim.FmuRunner(path) as runner:
            t_fmu, w = timed(lambda: cosim.simulate_pris_fmu(runner, s, args.fs), repeat=2)
        rows["fmu"] = {"wall_s": t_fmu, "build_s": t_build, **err(w)}

        paths = fmi.build_pris_fmus(dut, "n1", tmp, s, name="bench")
        with cosim.FmuRunner(paths["source"]) as src, cosim.FmuRunner(paths["dut"]) as d:
            t_co, w = timed(lambda: cosim.cosimulate(src, d, args.fs, n, "gauss-seidel"))
        rows["cosim_gauss_seidel"] = {"wall_s": t_co, **err(w)}

    if not args.no_ngspice and ngspice.available():
        t_sp, w = timed(lambda: td.pris_ngspice(dut, "n1", s, args.fs, max_step=args.ngspice_max_step))
        rows[f"ngspice_{args.ngspice_max_step:g}s"] = {"wall_s": t_sp, **err(w)}

    print(f"{'engine':28s} {'wall_s':>9s} {'x numpy':>9s} {'err v_in':>10s} {'err i_in':>10s}")
    for name, r in rows.items():
        ev, ei = r.get("err_v_in", np.nan), r.get("err_i_in", np.nan)
        print(f"{name:28s} {r['wall_s']:9.3f} {r['wall_s'] / t_np:9.1f} {ev:10.2e} {ei:10.2e}")
    print(f"FMU build (cold, CMake + gcc): {rows['fmu']['build_s']:.2f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
