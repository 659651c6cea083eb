"""Exact co-simulation of the source FMU and the winding FMU against the numpy engine and ngspice.

PRIS case of thesis 4.2.2: three-section winding, PRBS of order ``--order``
(default 12) at 100 kHz, sampled at ``--fs`` (default 10 MHz), one period.
Rows: numpy ZOH engine, exact co-simulation (FMUs built beforehand, cached;
instantiation included), ngspice at ``--ngspice-max-step`` (default 20 ns),
all measured in the same run. Errors are relative RMS against the numpy engine.

    python benchmarks/bench_cosim.py [--order 12] [--fs 1e7] [--no-ngspice] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from pris_cosim import codegen, cosim, fmi, ngspice
from pris_cosim import timedomain as td
from pris_cosim.cosim_exact import cosimulate_exact
from pris_cosim.models import get_model
from pris_cosim.thesis_cases import THREE_SECTION


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--order", type=int, default=12)
    ap.add_argument("--fs", type=float, default=10e6)
    ap.add_argument("--ngspice-max-step", type=float, default=20e-9)
    ap.add_argument("--no-ngspice", action="store_true")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args(argv)
    s = THREE_SECTION.settings
    s = type(s)(**{**s.__dict__, "prbs_order": args.order})
    dut = get_model("three-section").circuit
    rows: dict[str, dict[str, float]] = {}
    t0 = time.perf_counter()
    ref = td.simulate_pris(dut, "n1", s, args.fs)
    rows["numpy"] = {"wall_s": time.perf_counter() - t0}
    with tempfile.TemporaryDirectory() as tmp:
        src = fmi.build_fmu(codegen.source_model(s, name="bench_source"), tmp, write_modelica=False)
        win = fmi.build_fmu(codegen.dut_model(dut, "n1", name="bench_dut"), tmp, write_modelica=False)
        t0 = time.perf_counter()
        with cosim.FmuRunner(src, "ModelExchange") as a, cosim.FmuRunner(win, "ModelExchange") as b:
            w, err = cosimulate_exact(a, b, args.fs, ref["time_s"].size)
        rows["cosim_exact"] = {"wall_s": time.perf_counter() - t0, "coupling_error": err,
                               "v_in_rel_rms": cosim.relative_rms(w["v_in"], ref["v_in"]),
                               "i_in_rel_rms": cosim.relative_rms(w["i_in"], ref["i_in"])}
    if not args.no_ngspice and ngspice.available():
        print("ngspice ...", file=sys.stderr)
        t0 = time.perf_counter()
        sp = td.pris_ngspice(dut, "n1", s, args.fs, max_step=args.ngspice_max_step)
        rows["ngspice"] = {"wall_s": time.perf_counter() - t0,
                           "v_in_rel_rms": cosim.relative_rms(sp["v_in"][:ref["v_in"].size], ref["v_in"])}
        rows["cosim_exact"]["speedup_vs_ngspice"] = rows["ngspice"]["wall_s"] / rows["cosim_exact"]["wall_s"]
    result = {"samples": int(ref["time_s"].size), "order": args.order, "fs": args.fs, "rows": rows}
    for name, row in rows.items():
        print(f"{name:12s} " + "  ".join(f"{k}={v:.3g}" for k, v in row.items()))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
