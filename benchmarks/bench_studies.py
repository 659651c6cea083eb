"""Per-evaluation cost of each estimation approach and wall time of the quick two-section study.

Run: ``python benchmarks/bench_studies.py [--skip-study] [--json FILE]``

Measures, per population member (batches of 32 unless stated):

- two-section ``analytic`` (case 5 estimate: 969 PRBS lines, Zin + R2in);
- two-section ``welch-proxy`` (analytic responses through the Welch window);
- two-section ``simulated`` PRIS (case 2: 90 000 samples at 300 kHz, exact
  batched ZOH engine, Welch H1 of Zin and R2in);
- three-section ``time`` / ``emd`` / ``iemd`` (6930 samples at 11 MHz,
  current injection; EMD decomposes every estimate);
- three-section ``frequency`` (simulated PRBS12 at 2.5 MHz, Welch H1);

then the wall time of ``study two-section --quick`` and its ratio against
the thesis's runtimes (Table 4.5, minutes).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time

import numpy as np

from estimation import approaches as ap
from estimation.studies.three_section import study as three
from estimation.studies import two_section as two
from pris_cosim.models.builtin import get_model
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def per_eval(a: ap.Approach, P: int, repeats: int = 2, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    U = rng.uniform(0.2, 0.8, (P, a.n))
    a.cost_batch(U[:2])  # warm-up
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        a.cost_batch(U)
        best = min(best, (time.perf_counter() - t0) / P)
    return best


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--skip-study", action="store_true")
    p.add_argument("--json", metavar="FILE")
    args = p.parse_args(argv)
    out: dict[str, object] = {"per_eval_s": {}}
    res = out["per_eval_s"]
    a5, params, _ = two.build_approach("5")
    res["two-section analytic (case 5)"] = per_eval(a5, 256)
    a2, params, _ = two.build_approach("2")
    proxy = ap.WelchProxyFrequency(params, get_model("two-section").circuit, "in", two.SOURCE, a2.sim.fs,
                                   a2.welch.segment(a2.sim.n_samples), a2.bins, a2.specs, a2.target, a2.cost,
                                   half_width=2, sub=3)
    res["two-section welch-proxy (cases 1-4, global phase)"] = per_eval(proxy, 64)
    res["two-section simulated PRIS + Welch (case 2)"] = per_eval(a2, 32)
    for name in ("time", "iemd", "emd"):
        a = three.build_approach(name, "rmse")
        res[f"three-section {name}"] = per_eval(a, 32 if name != "emd" else 8, repeats=1)
    a = three.build_approach("frequency", "rmse")
    res["three-section frequency (simulated PRBS12)"] = per_eval(a, 16, repeats=1)
    for k, v in res.items():
        print(f"{k:<52} {v * 1e3:9.3f} ms per evaluation", file=sys.stderr)
    if not args.skip_study:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            summary = two.run(quick=True, out=tmp, progress=False)
            wall = time.perf_counter() - t0
        thesis_min = sum(v["runtime"] for v in two.THESIS_TABLE_4_5.values())
        out["two_section_quick_wall_s"] = wall
        out["two_section_runs_wall_s"] = {r["case"]: r["wall_s"] for r in summary["rows"]}
        out["thesis_runtime_min"] = {c: v["runtime"] for c, v in two.THESIS_TABLE_4_5.items()}
        out["speedup_total"] = thesis_min * 60.0 / wall
        out["speedup_per_case"] = {r["case"]: two.THESIS_TABLE_4_5[r["case"]]["runtime"] * 60.0 / r["wall_s"]
                                   for r in summary["rows"]}
        out["checks"] = summary["checks"]
        print(summary["table"], file=sys.stderr)
        print(f"quick two-section study: {wall:.1f} s wall; thesis {thesis_min} min of runs -> "
              f"{out['speedup_total']:.0f}x", file=sys.stderr)
    text = json.dumps(out, indent=1)
    results_io.write_raw("bench_studies", out, summary=__doc__.splitlines()[0])
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            fh.write(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
