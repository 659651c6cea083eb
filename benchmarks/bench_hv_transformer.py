"""Wall times of the hv-transformer study (thesis chapter 5.2) on this machine.

Run: ``python benchmarks/bench_hv_transformer.py [--quick-only | --full-only] [--out DIR] [--json FILE]``

Measures

1. the cost of one six-response evaluation (C_wnrmse on 151 points) per case,
   populations of 100;
2. ``study hv-transformer --quick`` (virtual lab quick records, cases 1, 2a,
   2b, 3 with Lambda 1, 5, 10 and three PSO seeds each), goal under 5 min;
3. Case Study 3 with the thesis's full sweep (Lambda = 1..20, PSO seeds 1..5
   then the local solver for each Lambda; 100 tasks' worth of PSO), on the
   local process pool (2 cores here), including the full-record virtual lab,
   goal under 10 min, against "dozens of hours" per run in the thesis (5.2.1).
   Prints the wall time, the response evaluations and adjoint Jacobians, the
   best unweighted cost and the machine's load average before and after.

Prints the figures and the ratios; ``--json`` also writes them.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from estimation.studies import hv_transformer as hv
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def per_eval_ms(data: str, case: str, P: int = 100) -> float:
    f, target = hv.comparison_data(data, 50)
    fit = hv.SixResponseFit(hv.case_spec(case), f, target)
    fun = fit.objective(1.0)
    U = np.random.default_rng(0).uniform(size=(P, fit.n))
    fun(U[:4])
    t0 = time.perf_counter()
    fun(U)
    return (time.perf_counter() - t0) / P * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick-only", action="store_true", help="skip the full Case Study 3 sweep")
    ap.add_argument("--full-only", action="store_true", help="skip the quick study (time only the full sweep)")
    ap.add_argument("--out", help="results directory (default: a temporary one)")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args()
    root = Path(args.out or tempfile.mkdtemp(prefix="bench-hv-"))
    figures: dict[str, object] = {}

    if not args.full_only:
        t0 = time.perf_counter()
        quick = hv.run(quick=True, out=root / "quick", progress=True)
        figures["quick_wall_s"] = time.perf_counter() - t0
        figures["quick_rows"] = {r["case"]: {"cost": r["cost"], "errors_db_lv": r["errors_db_lv"], "lambda": r["lambda"],
                                             "passive": r["passive"], "wall_s": r["wall_s"]} for r in quick["rows"]}
        figures["quick_checks"] = quick["checks"]
        data = str(root / "quick" / "measured.csv")
        figures["per_eval_ms"] = {c: per_eval_ms(data, c) for c in hv.CASES}
        print("per evaluation (six responses, 151 points, populations of 100): "
              + ", ".join(f"case {c} {v:.2f} ms" for c, v in figures["per_eval_ms"].items()), flush=True)
        print(f"study hv-transformer --quick: {figures['quick_wall_s']:.1f} s (goal 300 s)", flush=True)
        print(quick["table"], flush=True)

    if not args.quick_only:
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        full = hv.run(quick=False, out=root / "full-case3", cases=["3"], progress=True)
        wall = time.perf_counter() - t0
        load1 = os.getloadavg()
        row = full["rows"][0]
        figures["case3_full_wall_s"] = wall
        figures["case3_full"] = {"cost": row["cost"], "lambda": row["lambda"], "errors_db": row["errors_db"],
                                 "errors_db_lv": row["errors_db_lv"], "passive": row["passive"],
                                 "nfev": row["nfev"], "njev": row.get("njev", 0), "task_wall_s": row["wall_s"],
                                 "lab_wall_s": full["data"].get("wall_s"), "load_before": load0, "load_after": load1}
        thesis_h = 24.0  # "dozens of hours" per run (thesis 5.2.1): at least 24 h taken as the reference
        print(f"Case Study 3, full sweep (Lambda 1..20 x seeds 1..5 + local): {wall / 60:.1f} min on the local pool "
              f"(goal 10 min), of which {full['data'].get('wall_s', 0):.0f} s virtual lab; {row['nfev']} response "
              f"evaluations and {row.get('njev', 0)} adjoint Jacobians; best unweighted cost {row['cost']:.4f} at "
              f"Lambda {row['lambda']:g}, LV error {row['errors_db_lv']:.2f} dB, passive {row['passive']}; "
              f"load average {load0[0]:.2f} before, {load1[0]:.2f} after; thesis: dozens of hours per run, "
              f"so >= {thesis_h * 3600 / wall:.0f}x", flush=True)
        print(full["table"], flush=True)
    results_io.write_raw("bench_hv_transformer", figures, summary=__doc__.splitlines()[0])
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps({k: v for k, v in figures.items() if k.endswith("wall_s")}), file=sys.stderr)


if __name__ == "__main__":
    main()
