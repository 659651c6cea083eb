"""Peak memory and evaluation rate of a time-domain cost over one full PRBS12 period.

The three-section winding of thesis 4.2.2 driven by a current record of
409,501 samples (PRBS12 at 100 kHz, 10 MHz sampling), seven parameters (Table
4.8), a population of 256 parameter sets scored by the time approach (4.32).
Each setting runs in a fresh process so that its peak resident memory is its
own. ``--chunk-bytes`` rows compare the memory-bounded chunks with one chunk
of the whole population (how populations were scored before).

Run: ``python benchmarks/bench_estimation_memory.py [--population 256] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import results_io  # benchmarks/: results as JSON

CHILD = r"""
import os, sys, time, resource, json
import numpy as np
from estimation import approaches as ap
from estimation.parameters import ParameterSet
from pris_cosim.models.builtin import get_model
ap.CHUNK_BYTES = int(sys.argv[1])
P = int(sys.argv[2])
model = get_model("three-section")
fs, n = 10e6, 409_501
rng = np.random.default_rng(0)
i = np.sign(rng.standard_normal(n)) * 0.5  # a two-level current record, 0.5 A
eng = ap.InjectionEngine(model.circuit, "n1", i, fs)
v = eng.simulate({})[0]
params = ParameterSet.from_model(model, names=["Rs", "Cs", "Cg", "Ls", "k12", "k13", "k23"])
cost = ap.TimeDomain(params, eng, v, "rmse")
U = rng.uniform(0.3, 0.7, (P, len(params.names)))
cost.cost_batch(U[:2])
t = time.perf_counter()
c = cost.cost_batch(U)
dt = time.perf_counter() - t
print(json.dumps({"evals_per_s": P / dt, "wall_s": dt, "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "finite": int(np.isfinite(c).sum())}))
"""


def run(chunk_bytes: int, population: int) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    p = subprocess.run([sys.executable, "-c", CHILD, str(chunk_bytes), str(population)], capture_output=True,
                       text=True, env=env, timeout=3600)
    if p.returncode:
        return {"error": (p.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(p.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=256)
    ap.add_argument("--json", metavar="FILE")
    ap.add_argument("--unbounded", action="store_true", help="also run one chunk of the whole population (needs ~8 GB)")
    args = ap.parse_args()
    rows = {"bounded (256 MiB chunks)": run(256 * 2**20, args.population)}
    if args.unbounded:
        rows["one chunk of the whole population"] = run(2**62, args.population)
    for name, r in rows.items():
        if "error" in r:
            print(f"{name:36s} failed: {r['error']}")
        else:
            print(f"{name:36s} {r['evals_per_s']:8.1f} evaluations/s  peak {r['peak_mib']:7.0f} MiB")
    results_io.write_raw("bench_estimation_memory", {"population": args.population, "samples": 409_501, "rows": rows},
                         summary=__doc__.splitlines()[0])
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"population": args.population, "samples": 409_501, "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()
