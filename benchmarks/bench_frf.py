"""Frequency-response throughput: fast (pole-residue) path vs dense solve vs ngspice AC.

``hv-6section`` over 1000 log-spaced frequencies (10 Hz - 1 MHz) and a
population of parameter sets drawn +-10 % around Table 5.12. Prints complex
response points per second (one response, Zhvoc; best of ``--repeat`` runs
after a warm-up that loads the compiled kernels) and the agreement between
the paths and with ngspice AC measured in the same run.
Run: ``python benchmarks/bench_frf.py [--population 1000] [--json FILE]``.
BLAS threads are pinned to one so the figures are per core.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from pris_cosim.circuits import ngspice  # noqa: E402
from pris_cosim.errors import NonPassiveWarning  # noqa: E402
from pris_cosim.frf.response import ResponseModel, logspace_hz  # noqa: E402
from pris_cosim.models.builtin import get_model  # noqa: E402
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=1000)
    ap.add_argument("--frequencies", type=int, default=1000)
    ap.add_argument("--dense-population", type=int, default=100, help="parameter sets timed on the dense path")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per path (the best is reported)")
    ap.add_argument("--json", metavar="FILE", help="also write the figures to FILE as JSON")
    args = ap.parse_args()
    warnings.simplefilter("ignore", NonPassiveWarning)

    model = get_model("hv-6section")
    circuit = model.circuit
    rm = ResponseModel(circuit, "b1")
    f = logspace_hz(10, 1e6, args.frequencies)
    rng = np.random.default_rng(0)
    base = circuit.resolve()
    names = [e.key for e in circuit.elements if e.kind in "RLC" and not e.key.startswith("rb")]
    P = args.population
    pop = {n: base[n] * rng.uniform(0.9, 1.1, P) for n in names}

    Pd = min(args.dense_population, P)
    sub = {k: v[:Pd] for k, v in pop.items()}
    rm.evaluate(f, {k: v[:64] for k, v in pop.items()}, method="fast")  # warm-up: load the compiled kernels
    rm.evaluate(f, {k: v[:64] for k, v in pop.items()}, method="dense")

    def best(fn) -> tuple[float, np.ndarray]:
        times, out = [], None
        for _ in range(max(1, args.repeat)):
            t = time.perf_counter()
            out = fn()
            times.append(time.perf_counter() - t)
        return min(times), out

    t_fast, fast = best(lambda: rm.evaluate(f, pop, method="fast")["Zin"])
    t_dense, dense = best(lambda: rm.evaluate(f, sub, method="dense")["Zin"])
    nodal = rm.mna.solve_dense(rm.values({k: v[:8] for k, v in pop.items()}), 2j * np.pi * f, rm._out_index)[:, 0, 0, :]
    err = np.max(np.abs(fast[:Pd] - dense) / np.abs(dense))
    err_nodal = max(np.max(np.abs(fast[:8] - nodal) / np.abs(nodal)), np.max(np.abs(dense[:8] - nodal) / np.abs(nodal)))
    result = {"case": "hv-6section Zhvoc", "frequencies": int(f.size), "population": P, "dense_population": Pd,
              "fast_s": t_fast, "dense_s": t_dense,
              "fast_points_per_s": P * f.size / t_fast, "dense_points_per_s": Pd * f.size / t_dense,
              "fast_dense_max_rel_diff": float(err), "vs_nodal_solve_max_rel_diff": float(err_nodal)}

    print(f"hv-6section Zhvoc, {f.size} frequencies, {circuit.nodes.__len__()} nodes, {len(circuit.inductors())} inductors")
    print(f"fast path : {P} parameter sets in {t_fast:.3f} s -> {P * f.size / t_fast:.3e} points/s")
    print(f"dense path: {Pd} parameter sets in {t_dense:.3f} s -> {Pd * f.size / t_dense:.3e} points/s")
    print(f"fast/dense speed ratio: {(P / t_fast) / (Pd / t_dense):.1f}x; max relative difference {err:.2e}; "
          f"both vs the full nodal solve {err_nodal:.2e}")

    if ngspice.available():
        t = time.perf_counter()
        fs, v = ngspice.ac_analysis(circuit, "b1", ["b1"], 10, 1e6, points_per_decade=args.frequencies // 5)
        t_ng = time.perf_counter() - t
        t = time.perf_counter()
        ours = rm.evaluate(fs)["Zin"]
        t_one = time.perf_counter() - t
        e = np.max(np.abs(ours - v[0]) / np.abs(v[0]))
        print(f"ngspice AC: 1 parameter set, {fs.size} points in {t_ng:.3f} s -> {fs.size / t_ng:.3e} points/s "
              f"(process start included)")
        print(f"fast path, same single set: {t_one * 1e3:.2f} ms; ratio vs ngspice {t_ng / t_one:.0f}x; "
              f"max relative difference {e:.2e}")
        result.update(ngspice_s=t_ng, ngspice_points_per_s=fs.size / t_ng, ngspice_max_rel_diff=float(e),
                      single_set_fast_s=t_one)
    else:
        print("ngspice not installed: skipped")
    results_io.write_raw("bench_frf", result, summary=__doc__.splitlines()[0])
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(result, fh, indent=1)


if __name__ == "__main__":
    main()
