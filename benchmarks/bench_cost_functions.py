"""Cost-function benchmark of the three-section study: every cell over seeds and noise levels.

Run: ``python benchmarks/bench_cost_functions.py [--seeds 3] [--snr-db 60,40,20]
[--optimisers ga,pso,cma] [--approaches frequency,time,emd,iemd] [--full] [--out DIR]``

Every approach (frequency, time, EMD, IEMD) x optimiser (GA, PSO, CMA-ES;
each followed by the local solver, RMSE-type costs then by a least-squares
polish) x cost function (RMSE-type, correlation) x noise level (noise-free
and each ``--snr-db``) is run from ``--seeds`` seeds with the quick budgets
of ``pris-cosim study three-section --quick`` (``--full``: the full ones).

Writes into ``--out`` (default ``bench-cost-functions``):

- ``cost_functions.csv``: one line per cell: success rate (every parameter
  within 5 %), median signed error per parameter and the worst parameter's
  median |error|, median evaluations, evaluations per second, median and
  total wall time;
- ``cost_functions.md``: the same as Markdown tables, one per noise level,
  plus the headline table (PSO, every approach and cost function, success
  rate and worst median error at each noise level);
- the study's figures and ``study.json`` (resumable: a rerun skips stored runs).

Wall times depend on the machine's load; they are printed as measured.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path
from typing import Any

from estimation.studies import three_section as three


def _level(r: dict[str, Any]) -> str:
    return "noise-free" if r.get("snr_db") is None else f"{r['snr_db']:g} dB"


def csv_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for r in rows:
        med = r["errors_percent_median"]
        line = {"approach": r["approach"], "optimiser": r["optimiser"], "cost_function": r["cost_function"],
                "noise": _level(r), "seeds": len(r["seeds"]), "success_rate": round(r["success_rate"], 3),
                "worst_abs_error_percent_median": round(r["abs_error_percent_max_median"], 3)}
        line.update({f"median_error_percent_{k}": round(med[k], 3) for k in three.NAMES})
        line.update({"evaluations_median": r["evaluations"], "evals_per_s": round(r["evals_per_s"], 1),
                     "wall_s_median": round(r["wall_s"], 2), "wall_s_total": round(r["wall_s_total"], 2),
                     "non_identifiable": " ".join(r.get("non_identifiable", []))})
        out.append(line)
    return out


def markdown(rows: list[dict[str, Any]], seeds: int, wall: float) -> str:
    levels = []
    for r in rows:
        if _level(r) not in levels:
            levels.append(_level(r))
    lines = ["# Three-section cost-function benchmark", "",
             f"{seeds} seed(s) per cell; success = every parameter within 5 % of the target; "
             f"errors are medians over seeds (signed, %); wall {wall:.0f} s in total.", "",
             "## Headline (PSO + local; worst parameter's median |error| %, success rate)", "",
             "| approach | cost | " + " | ".join(levels) + " |",
             "|---|---|" + "---|" * len(levels)]
    for a in three.APPROACHES:
        for m in three.METRICS:
            cells = {(_level(r)): r for r in rows if r["approach"] == a and r["cost_function"] == m
                     and r["optimiser"] == "pso"}
            if not cells:
                continue
            vals = [f"{cells[lv]['abs_error_percent_max_median']:.3g} % ({cells[lv]['success_rate']:.0%})"
                    if lv in cells else "-" for lv in levels]
            lines.append(f"| {a} | {m} | " + " | ".join(vals) + " |")
    for lv in levels:
        lines += ["", f"## {lv}", "",
                  "| approach | optimiser | cost | success | " + " | ".join(three.NAMES)
                  + " | evaluations | evals/s | wall s |",
                  "|---|---|---|---|" + "---|" * len(three.NAMES) + "---|---|---|"]
        for r in rows:
            if _level(r) != lv:
                continue
            med = r["errors_percent_median"]
            lines.append(f"| {r['approach']} | {r['optimiser']} | {r['cost_function']} | {r['success_rate']:.0%} | "
                         + " | ".join(f"{med[k]:.3g}" for k in three.NAMES)
                         + f" | {r['evaluations']} | {r['evals_per_s']:.0f} | {r['wall_s']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--snr-db", default="60,40,20")
    p.add_argument("--optimisers", default=",".join(three.OPTIMISERS))
    p.add_argument("--approaches", default=",".join(three.APPROACHES))
    p.add_argument("--metrics", default=",".join(three.METRICS))
    p.add_argument("--full", action="store_true")
    p.add_argument("--workers", type=int)
    p.add_argument("--out", default="bench-cost-functions")
    p.add_argument("--merge", nargs="*", default=[], metavar="DIR",
                   help="also tabulate the rows of earlier runs (their study.json), e.g. other approaches")
    args = p.parse_args(argv)
    levels = [float(x) for x in args.snr_db.split(",") if x.strip()]
    t0 = time.perf_counter()
    summary = three.run(quick=not args.full, out=args.out, workers=args.workers, seeds=args.seeds,
                        snr_db=levels, optimisers=[o for o in args.optimisers.split(",") if o],
                        approaches=[a for a in args.approaches.split(",") if a],
                        metrics=[m for m in args.metrics.split(",") if m], search=False, progress=True)
    wall = time.perf_counter() - t0
    rows = list(summary["rows"])
    for d in args.merge:
        rows += json.loads((Path(d) / "study.json").read_text(encoding="utf-8"))["rows"]
    order = {a: i for i, a in enumerate(three.APPROACHES)}
    rows.sort(key=lambda r: (r.get("snr_db") is not None, -(r.get("snr_db") or 0), order[r["approach"]],
                             r["optimiser"], r["cost_function"]))
    out = Path(args.out)
    lines = csv_rows(rows)
    with open(out / "cost_functions.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lines[0]))
        w.writeheader()
        w.writerows(lines)
    md = markdown(rows, args.seeds, wall)
    (out / "cost_functions.md").write_text(md, encoding="utf-8")
    print(md)
    print(f"wrote {out / 'cost_functions.csv'} and {out / 'cost_functions.md'} ({wall:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
