"""Cost-function benchmark of the three-section study: every cell over seeds and noise levels.

Run: ``python benchmarks/bench_cost_functions.py [--seeds 3] [--snr-db [none,]60,40,20[,adc]]
[--optimisers ga,pso,cma] [--approaches frequency,time,emd,iemd] [--full] [--out DIR]``

Every approach (frequency, time, EMD, IEMD) x optimiser (GA, PSO, CMA-ES;
each followed by the local solver, RMSE-type costs then by a least-squares
polish) x cost function (RMSE-type, correlation) x noise level (each
``--snr-db``; ``none`` in the list adds the noise-free cells, ``adc`` the cell measured through the virtual
lab's chain: 100 kHz anti-alias filter, 1 MS/s, 16-bit ADC with its noise) is run from ``--seeds`` seeds with the
quick budgets
of ``pris-cosim study three-section --quick`` (``--full``: the full ones).

Writes into ``--out`` (default ``bench-cost-functions``):

- ``cost_functions.csv``: one line per cell: success rate (a seed succeeds
  when every parameter is within ``max(5 %, 3 x its Cramer-Rao bound)``;
  noise-free: within 5 %), the success rate within 5 % alone, median signed
  error per parameter and the worst parameter's median |error|, the bound of
  each parameter (relative one-sigma, %, for that approach's data at that
  SNR, :func:`estimation.studies.three_section.study.cell_bound`) and the
  efficiency (median |error| over seeds / bound) per parameter with its
  median and maximum over the parameters, median evaluations, evaluations
  per second, median and total wall time;
- ``cost_functions.md``: the same as Markdown tables, one per noise level,
  plus the headline table (every approach and cost function, success rate,
  worst median error and median efficiency at each noise level);
- ``benchmarks/results/bench_cost_functions.json`` (through
  ``results_io``; ``--results PATH`` writes elsewhere);
- the study's figures and ``study.json`` (resumable: a rerun skips stored runs).

Wall times depend on the machine's load; they are printed as measured.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

from estimation.studies.three_section import study as three

try:
    from results_io import table, write_results
except ImportError:  # run as a module from the repository root
    from benchmarks.results_io import table, write_results


def _level(r: dict[str, Any]) -> str:
    lv = r.get("snr_db")
    return "noise-free" if lv is None else "ADC (1 MS/s, 16 bit)" if three.is_adc(lv) else f"{lv:g} dB"


def _level_order(r: dict[str, Any]) -> tuple[int, float]:
    """Noise-free first, then SNRs from high to low, the ADC cell last."""
    lv = r.get("snr_db")
    return (0, 0.0) if lv is None else (2, 0.0) if three.is_adc(lv) else (1, -float(lv))


def _num(x: Any, digits: int = 3) -> Any:
    """Rounded number, or an empty cell for a missing or non-finite one."""
    if x is None or not isinstance(x, (int, float)) or not math.isfinite(x):
        return ""
    return round(float(x), digits)


def _g(x: Any, fmt: str = ".3g") -> str:
    return "-" if x is None or not isinstance(x, (int, float)) or not math.isfinite(x) else format(x, fmt)


def _failures(r: dict[str, Any]) -> str:
    """Missed seeds by kind: ``cost`` (the cost is no higher at the estimate than at the truth: its minimum
    lies beyond the limit) / ``search`` (a lower valley was not found)."""
    f = r.get("failures") or {}
    return "-" if not f else f"{f.get('cost', 0)}/{f.get('search', 0)}"


def csv_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for r in rows:
        med = r["errors_percent_median"]
        bound = r.get("bound_percent") or {}
        eff = r.get("efficiency") or {}
        line = {"approach": r["approach"], "optimiser": r["optimiser"], "cost_function": r["cost_function"],
                "noise": _level(r), "seeds": len(r["seeds"]), "success_rate": round(r["success_rate"], 3),
                "success_rate_5pct": round(r.get("success_rate_5pct", r["success_rate"]), 3),
                "worst_abs_error_percent_median": round(r["abs_error_percent_max_median"], 3),
                "efficiency_median": _num(r.get("efficiency_median")),
                "efficiency_max": _num(r.get("efficiency_max")),
                "misses_cost": (r.get("failures") or {}).get("cost", 0),
                "misses_search": (r.get("failures") or {}).get("search", 0)}
        line.update({f"median_error_percent_{k}": round(med[k], 3) for k in three.NAMES})
        line.update({f"bound_percent_{k}": _num(bound.get(k), 4) for k in three.NAMES})
        line.update({f"efficiency_{k}": _num(eff.get(k)) for k in three.NAMES})
        line.update({"evaluations_median": r["evaluations"], "evals_per_s": round(r["evals_per_s"], 1),
                     "wall_s_median": round(r["wall_s"], 2), "wall_s_total": round(r["wall_s_total"], 2),
                     "cpu_s_total": round(r.get("cpu_s_total", 0.0), 2),
                     "non_identifiable": " ".join(r.get("non_identifiable", []))})
        out.append(line)
    return out


def markdown(rows: list[dict[str, Any]], seeds: int, wall: float) -> str:
    levels = []
    for r in rows:
        if _level(r) not in levels:
            levels.append(_level(r))
    opts = sorted({r["optimiser"] for r in rows})
    lines = ["# Three-section cost-function benchmark", "",
             f"{seeds} seed(s) per cell. A seed succeeds when every parameter is within max(5 %, 3 x its "
             "Cramer-Rao bound) of the target (noise-free: within 5 %). Errors are medians over seeds (signed, %); "
             "bound: relative one-sigma Cramer-Rao bound (%) of the data the approach compares, at that SNR; "
             f"efficiency: median |error| / bound. Wall {wall:.0f} s in total.", ""]
    for o in opts:
        lines += [f"## Headline ({o} + local): worst parameter's median |error| %, success rate, "
                  "median efficiency over the parameters", "",
                  "| approach | cost | " + " | ".join(levels) + " |",
                  "|---|---|" + "---|" * len(levels)]
        for a in three.APPROACHES:
            for m in three.METRICS:
                cells = {(_level(r)): r for r in rows if r["approach"] == a and r["cost_function"] == m
                         and r["optimiser"] == o}
                if not cells:
                    continue
                vals = []
                for lv in levels:
                    if lv not in cells:
                        vals.append("-")
                        continue
                    c = cells[lv]
                    txt = f"{c['abs_error_percent_max_median']:.3g} % ({c['success_rate']:.0%})"
                    if c.get("efficiency_median") is not None:
                        txt += f", eff {_g(c.get('efficiency_median'))}"
                    vals.append(txt)
                lines.append(f"| {a} | {m} | " + " | ".join(vals) + " |")
        lines.append("")
    for lv in levels:
        lines += ["", f"## {lv}", "",
                  "| approach | optimiser | cost | success | within 5 % | " + " | ".join(three.NAMES)
                  + " | eff. median | eff. max | misses (cost/search) | evaluations | evals/s | wall s |",
                  "|---|---|---|---|---|" + "---|" * len(three.NAMES) + "---|---|---|---|---|---|"]
        bound_rows = {}
        for r in rows:
            if _level(r) != lv:
                continue
            med = r["errors_percent_median"]
            lines.append(f"| {r['approach']} | {r['optimiser']} | {r['cost_function']} | {r['success_rate']:.0%} | "
                         f"{r.get('success_rate_5pct', r['success_rate']):.0%} | "
                         + " | ".join(f"{med[k]:.3g}" for k in three.NAMES)
                         + f" | {_g(r.get('efficiency_median'))} | {_g(r.get('efficiency_max'))}"
                         + f" | {_failures(r)} | {r['evaluations']} | {r['evals_per_s']:.0f} | {r['wall_s']:.1f} |")
            if r.get("bound_percent"):
                kind = "frequency" if r["approach"] == "frequency" else "time, EMD, IEMD"
                bound_rows[kind] = r["bound_percent"]
        if bound_rows:
            lines += ["", f"Cramer-Rao bound at {lv} (relative one-sigma, %) and the success limit "
                          "max(5 %, 3 x bound):", "",
                      "| data of | " + " | ".join(three.NAMES) + " |", "|---|" + "---|" * len(three.NAMES)]
            for kind, b in bound_rows.items():
                lines.append(f"| {kind}: bound | " + " | ".join(_g(b[k]) for k in three.NAMES) + " |")
                lines.append(f"| {kind}: limit | " + " | ".join(_g(max(5.0, 3 * b[k])) for k in three.NAMES) + " |")
    return "\n".join(lines) + "\n"


def json_tables(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The cells as one results_io table (errors, bounds and efficiencies per parameter)."""
    cols = (["approach", "optimiser", "cost", "noise", "seeds", "success rate", "success rate within 5 %",
             "worst median |error| (%)", "median efficiency", "max efficiency"]
            + [f"median error {k} (%)" for k in three.NAMES] + [f"bound {k} (%)" for k in three.NAMES]
            + [f"efficiency {k}" for k in three.NAMES]
            + ["misses (cost/search)", "evaluations (median)", "wall median (s)", "processor time (s)"])
    out = []
    for r in rows:
        b, e, med = r.get("bound_percent") or {}, r.get("efficiency") or {}, r["errors_percent_median"]
        out.append([r["approach"], r["optimiser"], r["cost_function"], _level(r), len(r["seeds"]),
                    round(r["success_rate"], 3), round(r.get("success_rate_5pct", r["success_rate"]), 3),
                    round(r["abs_error_percent_max_median"], 3), _num(r.get("efficiency_median")),
                    _num(r.get("efficiency_max"))]
                   + [round(med[k], 3) for k in three.NAMES] + [_num(b.get(k), 4) for k in three.NAMES]
                   + [_num(e.get(k)) for k in three.NAMES]
                   + [_failures(r), r["evaluations"], round(r["wall_s"], 2), round(r.get("cpu_s_total", 0.0), 1)])
    return [table("Three-section cost-function cells (success: every parameter within max(5 %, 3 x bound))",
                  cols, out)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--snr-db", default="60,40,20",
                   help="noise levels, dB; 'none' adds the noise-free cells, 'adc' the cell measured through "
                        "the virtual lab's chain (e.g. none,60,40,20,adc)")
    p.add_argument("--optimisers", default=",".join(three.OPTIMISERS))
    p.add_argument("--approaches", default=",".join(three.APPROACHES))
    p.add_argument("--metrics", default=",".join(three.METRICS))
    p.add_argument("--full", action="store_true")
    p.add_argument("--workers", type=int)
    p.add_argument("--out", default="bench-cost-functions")
    p.add_argument("--results", help="results_io JSON path (default benchmarks/results/bench_cost_functions.json)")
    p.add_argument("--merge", nargs="*", default=[], metavar="DIR",
                   help="also tabulate the rows of earlier runs (their study.json), e.g. other approaches")
    args = p.parse_args(argv)
    items = [x.strip().lower() for x in args.snr_db.split(",") if x.strip()]
    try:
        levels = [three.level_of(x) for x in items if x not in ("none", "clean")]
    except three.common.StudyError:
        p.error(f"--snr-db takes SNRs in dB, 'none' for the noise-free cells and 'adc' for the measured "
                f"cell (got {args.snr_db!r})")
    t0 = time.perf_counter()
    summary = three.run(quick=not args.full, out=args.out, workers=args.workers, seeds=args.seeds,
                        snr_db=levels, optimisers=[o for o in args.optimisers.split(",") if o],
                        approaches=[a for a in args.approaches.split(",") if a],
                        metrics=[m for m in args.metrics.split(",") if m], search=False, progress=True,
                        noise_free=any(x in ("none", "clean") for x in items))
    wall = time.perf_counter() - t0
    rows = list(summary["rows"])
    for d in args.merge:
        rows += json.loads((Path(d) / "study.json").read_text(encoding="utf-8"))["rows"]
    order = {a: i for i, a in enumerate(three.APPROACHES)}
    rows.sort(key=lambda r: (_level_order(r), order[r["approach"]],
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
    noisy = [r for r in rows if r.get("snr_db") is not None and r["cost_function"] == "rmse"]
    met = sum(r["success_rate"] >= 2 / 3 - 1e-9 for r in noisy)
    run_sum = float(sum(r.get("wall_s_total", 0.0) for r in rows))
    cpu_sum = float(sum(r.get("cpu_s_total", 0.0) for r in rows))
    summary_line = (f"three-section study, {args.seeds} seed(s), SNR {args.snr_db} dB, optimisers "
                    f"{args.optimisers}: {met}/{len(noisy)} noisy RMSE-type cells succeed on at least 2/3 of "
                    f"the seeds (max(5 %, 3 x Cramer-Rao bound)); wall {wall:.0f} s this invocation, "
                    f"{run_sum:.0f} s of wall and {cpu_sum:.0f} s of processor time summed over the runs "
                    "tabulated (stored runs included)")
    path = write_results("bench_cost_functions", json_tables(rows), summary=summary_line,
                         figures={"wall_s": {"value": round(wall, 1), "unit": "s"},
                                  "run_wall_sum_s": {"value": round(run_sum, 1), "unit": "s"},
                                  "run_cpu_sum_s": {"value": round(cpu_sum, 1), "unit": "s"}}, path=args.results)
    print(f"wrote {out / 'cost_functions.csv'}, {out / 'cost_functions.md'} and {path} (wall {wall:.0f} s)",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
