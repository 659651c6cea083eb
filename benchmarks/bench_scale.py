"""Time and peak memory of ``pris-cosim frf`` as the netlist grows.

Each size runs in its own process (peak resident set from a small wrapper
process's ``resource.getrusage`` of its one child), on RC chains (R series, C shunt) and on
R-L / C ladders, at 200 frequencies. The continued-fraction impedance of the
RC chain is the accuracy reference.

Usage::

    nice python benchmarks/bench_scale.py [--sizes 100,1000,10000] [--points 200]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def rc_chain(elements: int) -> str:
    n = max(1, elements // 2)
    lines = [f"* RC chain, {n} sections", "*@ port n0"]
    for k in range(1, n + 1):
        lines += [f"R{k} n{k - 1} n{k} 10", f"C{k} n{k} 0 1n"]
    return "\n".join(lines) + "\n"


def rlc_ladder(elements: int) -> str:
    n = max(1, elements // 3)
    lines = [f"* R-L / C ladder, {n} sections", "*@ port n0"]
    for k in range(1, n + 1):
        lines += [f"R{k} n{k - 1} x{k} 0.5", f"L{k} x{k} n{k} 2u", f"C{k} n{k} 0 300p"]
    return "\n".join(lines) + "\n"


def rc_reference(elements: int, f: np.ndarray) -> np.ndarray:
    n = max(1, elements // 2)
    s = 2j * np.pi * f
    z = 10 + 1 / (s * 1e-9)
    for _ in range(n - 1):
        z = 10 + 1 / (s * 1e-9 + 1 / z)
    return z


def run(text: str, points: int, workdir: Path) -> tuple[float, float, dict]:
    path = workdir / "net.cir"
    path.write_text(text)
    cmd = [sys.executable, "-m", "pris_cosim", "frf", "--netlist", str(path), "--port", "n0",
           "--fmin", "10", "--fmax", "1e7", "--points", str(points), "--json"]
    wrapper = ("import resource, subprocess, sys; p = subprocess.run(sys.argv[1:]); "
               "sys.stderr.write(f'@@{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}\\n'); sys.exit(p.returncode)")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", wrapper, *cmd], capture_output=True, text=True,
                          env=dict(os.environ, OPENBLAS_NUM_THREADS="1"))
    wall = time.perf_counter() - t0
    if proc.returncode:
        raise SystemExit(f"frf failed: {proc.stderr.strip()}")
    peak = float(proc.stderr.rsplit("@@", 1)[1]) / 2**10
    return wall, peak, json.loads(proc.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100,1000,10000", help="element counts (ascending)")
    ap.add_argument("--points", type=int, default=200)
    args = ap.parse_args()
    sizes = sorted(int(x) for x in args.sizes.split(","))
    print(f"{'circuit':>10} {'elements':>9} {'unknowns':>9} {'wall s':>8} {'peak MiB':>9} {'max rel err':>12}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind, build in (("rc-chain", rc_chain), ("rlc-ladder", rlc_ladder)):
            for size in sizes:
                text = build(size)
                wall, peak, out = run(text, args.points, Path(tmp))
                unknowns = len({w for line in text.splitlines()[2:] for w in line.split()[1:3]} - {"0"})
                unknowns += text.count("\nL")
                err = ""
                if kind == "rc-chain":
                    f = np.array(out["frequency_hz"])
                    z = np.array(out["responses"]["Zin"]["re"]) + 1j * np.array(out["responses"]["Zin"]["im"])
                    ref = rc_reference(size, f)
                    err = f"{np.max(np.abs(z - ref) / np.abs(ref)):.2e}"
                print(f"{kind:>10} {size:>9} {unknowns:>9} {wall:8.2f} {peak:9.0f} {err:>12}", flush=True)
                rows.append([kind, size, unknowns, wall, peak, err or "-"])
    print("wall s: the whole command (start-up, reading, solve, JSON); peak MiB: resident set of that process")
    results_io.write_results("bench_scale", summary=__doc__.splitlines()[0], tables=[results_io.table(
        f"`pris-cosim frf --json` at {args.points} frequencies; wall: the whole command; peak: its resident set",
        ["circuit", "elements", "unknowns", "wall (s)", "peak (MiB)", "max relative error vs continued fraction"],
        rows)])


if __name__ == "__main__":
    main()
