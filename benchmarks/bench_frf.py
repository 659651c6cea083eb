"""Frequency-response throughput: fast (pole-residue) path vs dense solve vs ngspice AC.

``hv-6section`` over 1000 log-spaced frequencies (10 Hz - 1 MHz) and a
population of parameter sets drawn +-10 % around Table 5.12. Prints complex
response points per second (one response, Zhvoc) and the agreement between
the paths. Run: ``python benchmarks/bench_frf.py [--population 1000]``.
BLAS threads are pinned to one so the figures are per core.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from pris_cosim import ngspice  # noqa: E402
from pris_cosim.errors import NonPassiveWarning  # noqa: E402
from pris_cosim.frf import ResponseModel, logspace_hz  # noqa: E402
from pris_cosim.models import get_model  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=1000)
    ap.add_argument("--frequencies", type=int, default=1000)
    ap.add_argument("--dense-population", type=int, default=100, help="parameter sets timed on the dense path")
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

    rm.evaluate(f[:10], {k: v[:2] for k, v in pop.items()})  # warm-up
    t = time.perf_counter()
    fast = rm.evaluate(f, pop, method="fast")["Zin"]
    t_fast = time.perf_counter() - t

    Pd = min(args.dense_population, P)
    sub = {k: v[:Pd] for k, v in pop.items()}
    t = time.perf_counter()
    dense = rm.evaluate(f, sub, method="dense")["Zin"]
    t_dense = time.perf_counter() - t
    err = np.max(np.abs(fast[:Pd] - dense) / np.abs(dense))

    print(f"hv-6section Zhvoc, {f.size} frequencies, {circuit.nodes.__len__()} nodes, {len(circuit.inductors())} inductors")
    print(f"fast path : {P} parameter sets in {t_fast:.3f} s -> {P * f.size / t_fast:.3e} points/s")
    print(f"dense path: {Pd} parameter sets in {t_dense:.3f} s -> {Pd * f.size / t_dense:.3e} points/s")
    print(f"fast/dense speed ratio: {(P / t_fast) / (Pd / t_dense):.1f}x; max relative difference {err:.2e}")

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
    else:
        print("ngspice not installed: skipped")


if __name__ == "__main__":
    main()
