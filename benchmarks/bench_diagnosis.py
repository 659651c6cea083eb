"""Diagnosis benchmark: confusion matrix over generated cases with one hidden effect each.

One-port cascades (2-3 sections) and the two-winding hv-4section model, each
cause drawn with a random strength and seed, 0.3 % complex noise. Prints the
confusion matrix (true cause x named cause), the gains and the wall time per
case. Runs through the project's executor (local processes) and keeps every
finished case in ``--out`` so an interrupted run resumes.

Run: ``python benchmarks/bench_diagnosis.py --one-port 8 --two-winding 2``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from estimation.diagnosis.synthetic import FREQUENCY_CAUSES
from estimation.executor import ResultsStore, Task, run_tasks


def run_case(kind: str, cause: str, seed: int) -> dict:
    """Generate one case and diagnose it (top-level so worker processes can run it)."""
    from estimation.diagnosis import diagnose_frequency
    from estimation.diagnosis.synthetic import one_port_case, two_winding_case

    make = one_port_case if kind == "one-port" else two_winding_case
    case = make(cause, seed)
    t = time.perf_counter()
    d = diagnose_frequency(case.frequency_hz, case.measured, model=case.baseline, progress=False)
    return {"kind": kind, "true": cause, "named": d.cause, "gain": d.gain, "strength": case.strength,
            "wall_s": time.perf_counter() - t}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--one-port", type=int, default=8, help="seeds per cause, one-port cascades")
    ap.add_argument("--two-winding", type=int, default=2, help="seeds per cause, two-winding model")
    ap.add_argument("--out", default="results/bench_diagnosis")
    ap.add_argument("--executor", default="processes")
    args = ap.parse_args()
    tasks = []
    for kind, n in (("one-port", args.one_port), ("two-winding", args.two_winding)):
        for cause in FREQUENCY_CAUSES:
            for seed in range(1, n + 1):
                tasks.append(Task(f"{kind}-{cause}-{seed}", run_case, {"kind": kind, "cause": cause, "seed": seed},
                                  label=f"{kind} {cause} seed {seed}"))
    t0 = time.perf_counter()
    results = run_tasks(tasks, executor=args.executor, store=ResultsStore(args.out), progress=True)
    wall = time.perf_counter() - t0
    causes = list(FREQUENCY_CAUSES)
    for kind in ("one-port", "two-winding"):
        rows = [r for r in results if r["kind"] == kind]
        if not rows:
            continue
        m = np.zeros((len(causes), len(causes)), int)
        for r in rows:
            m[causes.index(r["true"]), causes.index(r["named"]) if r["named"] in causes else 0] += 1
        print(f"\n{kind}: {len(rows)} cases, named right {np.trace(m)}/{len(rows)}")
        width = max(len(c) for c in causes)
        print(" " * (width + 2) + "  ".join(f"{c[:10]:>10}" for c in causes))
        for i, c in enumerate(causes):
            print(f"{c:>{width}}  " + "  ".join(f"{v:>10d}" for v in m[i]))
        gains = [r["gain"] for r in rows if r["true"] != "none" and r["named"] == r["true"]]
        walls = [r["wall_s"] for r in rows]
        print(f"gain (right, with an effect): min {min(gains, default=float('nan')):.3f}, "
              f"median {np.median(gains) if gains else float('nan'):.3f}")
        print(f"wall per case: median {np.median(walls):.1f} s, max {max(walls):.1f} s")
        false_alarms = sum(1 for r in rows if r["true"] == "none" and r["named"] != "none")
        print(f"false alarms on clean data: {false_alarms}/{sum(1 for r in rows if r['true'] == 'none')}")
    print(f"\ntotal wall {wall:.0f} s for {len(results)} cases")


if __name__ == "__main__":
    main()
