"""Which draw of each design-anchored case shows its hidden causes above the noise.

A design case (:func:`hidden_cases.design_case`) hides one or two causes in
a winding whose values are the design's within 10 %. Some draws hide an
effect that no diagnosis can see: the design's own structure, its values
within twice the design tolerance, reproduces the truth within the noise (a
skin effect of the Bessel form at a few tens of kHz is absorbed by the
series resistances and inductances). Such a draw tests nothing but the
noise, so the benchmark replaces it with the next draw of the same seed.

For every case of :data:`bench_diagnosis.DESIGN_FAMILY` that hides a
cause, draws 0, 1, 2, ... are checked with
:func:`detectability.effects_shown` (the reference solver, no code of the
diagnosis) until every hidden cause of the draw shows; the draw used is
written to ``benchmarks/results/design_draws.json``, which
:mod:`bench_diagnosis` reads. Clean and drift-only cases hide nothing and
keep draw 0. Every case is checked, whatever the diagnosis made of it.

Run: ``python benchmarks/design_draws.py [--workers 2] [--out results/design_draws]``
(about 70 minutes on two cores; finished cases are kept in ``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
for p in (str(HERE), str(HERE.parent / "tests"), str(HERE.parent)):
    if p not in sys.path:
        sys.path.insert(0, p)

#: Draws tried per case before giving up (the case then keeps draw 0 and is reported).
MAX_DRAWS = 6

#: Where the draws used are written (read by :mod:`bench_diagnosis`).
DRAWS_FILE = HERE / "results" / "design_draws.json"


def check_case(causes: list[str], seed: int, drift: bool) -> dict:
    """Walk the draws of one case until every hidden cause shows (top-level for worker processes)."""
    import hidden_cases as hc
    from detectability import effects_shown

    tried = []
    for draw in range(MAX_DRAWS):
        case = hc.design_case(tuple(causes), seed, drift=drift, draw=draw)
        shown = effects_shown(case)
        tried.append({c: {"cost": v["cost"], "noise": v["noise"], "detectable": v["detectable"]}
                      for c, v in shown.items()})
        if all(v["detectable"] for v in shown.values()):
            return {"draw": draw, "tried": tried}
    return {"draw": None, "tried": tried}


def load_draws(path: Path = DRAWS_FILE) -> dict[str, int]:
    """Task id -> draw to use (draw 0 for a case not listed)."""
    if not path.exists():
        return {}
    doc = json.loads(path.read_text())
    return {k: int(v) for k, v in doc.get("data", {}).get("draws", {}).items()}


def _outcome(k: int, replaced_by: int | None, shows: list[bool]) -> str:
    """What became of draw ``k`` of a case (``replaced_by``: the draw used instead of draw 0, if any)."""
    if replaced_by is not None:
        return "used" if k == replaced_by else "replaced"
    if shows[0]:
        return "used" if k == 0 else "not shown"
    return f"used: no draw of {len(shows)} shows every cause" if k == 0 else "not shown"


def main() -> None:
    from design_family import design_cases, task_id
    from estimation.search.executor import ResultsStore, Task, run_tasks
    from results_io import table, write_results

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/design_draws")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--only", nargs="+", default=None, metavar="TEXT", help="cases whose id contains one of these")
    ap.add_argument("--collect", action="store_true",
                    help="run nothing: write the draws of the cases already checked in --out")
    args = ap.parse_args()
    todo = [c for c in design_cases(quick=False) if c["causes"] != ["none"]]
    if args.only:
        todo = [c for c in todo if any(t in task_id(c) for t in args.only)]
    tasks = [Task(task_id(c), check_case, {"causes": c["causes"], "seed": c["seed"], "drift": c["drift"]})
             for c in todo]
    if args.collect:
        runs = Path(args.out) / "runs"
        stored = {p.stem: json.loads(p.read_text()).get("result") for p in runs.glob("*.json")}
        done = {t.id: stored[t.id] for t in tasks if isinstance(stored.get(t.id), dict)}
    else:
        results = run_tasks(tasks, store=ResultsStore(args.out), workers=args.workers, progress=True,
                            on_error="continue")
        done = {t.id: r for t, r in zip(tasks, results) if isinstance(r, dict)}
    old = json.loads(DRAWS_FILE.read_text()).get("data", {}) if DRAWS_FILE.exists() else {}
    checked = {**old.get("checked", {}), **{i: r["tried"] for i, r in done.items()}}
    shows = {i: [all(v["detectable"] for v in t.values()) for t in tried] for i, tried in checked.items()}
    # the draw used: the first that shows every cause (draw 0 when none does)
    draws = {i: s.index(True) for i, s in shows.items() if True in s and s.index(True) > 0}
    never = sorted(i for i, s in shows.items() if True not in s)
    rows = [[i, k, ", ".join(f"{c} {v['cost'] / v['noise']:.3g}" for c, v in t.items()),
             _outcome(k, draws.get(i), shows[i])]
            for i in sorted(checked) for k, t in enumerate(checked[i])]
    write_results("design_draws", [table(
        "Design-anchored draws: each hidden cause's best fit without it, over the noise (below 1: invisible)",
        ["case", "draw", "cost / noise per cause", "outcome"], rows)],
        summary=f"{len(checked)} design cases with hidden causes checked, {len(draws)} draws replaced"
                + (f", {len(never)} never shown" if never else ""), data={"draws": draws, "checked": checked})
    print(f"{len(checked)} cases checked, {len(draws)} replaced: {sorted(draws)}; never shown: {never}")


if __name__ == "__main__":
    main()
