"""``pris-cosim estimate`` with its defaults on ten random targets per built-in model.

Each target draws every parameter of the default estimation vector
log-uniformly within a factor ``--spread`` of its nominal value and inside
the default bounds (couplings uniformly within +-2 %). Its responses (every configuration of the model, on the default
band, 200 log-spaced points) come from the admittance-matrix solver in
``tests/estimate/test_defaults.py``, which shares nothing with the
estimation's state-space and pole-residue paths. The estimate then runs with
the defaults of ``estimate`` (no budget, optimiser or bounds given).

For each model the script prints how many targets were estimated within
``--tolerance`` percent on every parameter, how many of those the verdict
called converged, and -- the property that matters -- how many answers were
*right or said they were not*: every parameter within tolerance, or
``converged: false``, or the wrong parameters named as not identifiable.

Run: ``python benchmarks/bench_estimate_defaults.py [--models two-section,three-section] [--targets 10]``
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from estimate.test_defaults import draw_target, target_responses, write_responses  # noqa: E402

from estimation import cli  # noqa: E402
from estimation.estimate import default_band  # noqa: E402
from pris_cosim.models.builtin import get_model  # noqa: E402
import results_io  # noqa: E402  (benchmarks/: results as JSON)

MODELS = ["two-section", "three-section", "cascade-4", "hv-4section", "hv-4section-cab2a", "hv-4section-cab2b",
          "hv-6section-passive"]


def run_model(name: str, targets: int, spread: float, tol: float, tmp: Path) -> dict:
    model = get_model(name)
    cfg0 = next(iter(model.configurations.values()))
    lo, hi = default_band(model, cfg0)
    f = np.logspace(math.log10(lo), math.log10(hi), 200)
    rng = np.random.default_rng(2026)
    rows = []
    for i in range(targets):
        t, full = draw_target(model, rng, spread)
        path = tmp / f"{name}-{i}.csv"
        write_responses(path, f, target_responses(model, full, f))
        t0 = time.perf_counter()
        out = cli.run_estimate({"model": name, "target": {"kind": "responses-csv", "path": str(path)},
                                "frequency": {"points": 200}, "seed": i + 1}, progress=False)
        wall = time.perf_counter() - t0
        est = out["estimate"]
        err = {k: abs(est[k] - t[k]) / abs(t[k]) * 100 for k in est if k in t and t[k] != 0}
        wrong = [k for k, e in err.items() if not e < tol]
        honest = not wrong or out["converged"] is False or all(k in out["non_identifiable"] for k in wrong)
        rows.append({"target": i, "max_error_percent": max(err.values()), "wrong": wrong,
                     "converged": out["converged"], "honest": honest, "wall_s": wall,
                     "non_identifiable": out["non_identifiable"]})
        print(f"  {name} target {i}: worst {max(err.values()):.2e} %, converged {out['converged']}, "
              f"right-or-says-so {honest}, {wall:.1f} s", file=sys.stderr)
    return {"model": name, "parameters": len(cli._parameter_set(model, {}).varying), "targets": targets,
            "within_tolerance": sum(not r["wrong"] for r in rows),
            "converged_and_within": sum((not r["wrong"]) and r["converged"] for r in rows),
            "right_or_says_so": sum(r["honest"] for r in rows),
            "median_wall_s": float(np.median([r["wall_s"] for r in rows])), "rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--targets", type=int, default=10)
    ap.add_argument("--spread", type=float, default=2.0, help="values within nominal / spread .. nominal * spread")
    ap.add_argument("--tolerance", type=float, default=1.0, help="percent")
    ap.add_argument("--json", metavar="FILE")
    args = ap.parse_args()
    results = []
    with tempfile.TemporaryDirectory() as d:
        for name in args.models.split(","):
            results.append(run_model(name.strip(), args.targets, args.spread, args.tolerance, Path(d)))
    print(f"{'model':22s} {'params':>6s} {'within tol':>10s} {'conv+within':>11s} {'right or says so':>16s} {'median s':>9s}")
    for r in results:
        print(f"{r['model']:22s} {r['parameters']:6d} {r['within_tolerance']:>7d}/{r['targets']:<2d} "
              f"{r['converged_and_within']:>8d}/{r['targets']:<2d} {r['right_or_says_so']:>13d}/{r['targets']:<2d} "
              f"{r['median_wall_s']:9.1f}")
    results_io.write_results("bench_estimate_defaults", summary=__doc__.splitlines()[0], tables=[results_io.table(
        f"Default estimates on {args.targets} random targets per model (spread x{args.spread}, tolerance {args.tolerance} %)",
        ["model", "parameters", "within tolerance", "converged and within", "right or says it is not", "median wall (s)"],
        [[r["model"], r["parameters"], f"{r['within_tolerance']}/{r['targets']}",
          f"{r['converged_and_within']}/{r['targets']}", f"{r['right_or_says_so']}/{r['targets']}",
          r["median_wall_s"]] for r in results])])
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
