"""Diagnosis benchmark: confusion matrix over hidden-effect cases made by an independent generator, and speed.

Cases come from ``tests/hidden_cases.py`` (a reference nodal solver of its
own, hidden effects in other forms than the catalogue's: see there):

- one-port windings given as netlists with 2, 3, 5, 6 or 7 sections
  (counts no built-in family has among them), single causes and compound
  (two causes) cases, 0.3 % noise;
- the thesis's two-winding transformer (six responses, 10 Hz - 10 kHz),
  single causes, effects on one winding only (LV or HV), compound cases;
- clean cases at 1 % noise (a false alarm is any named cause).

The design-anchored family uses, for each case, the first draw whose
hidden causes show above the noise (:mod:`design_draws`, the reference
solver's check run on every case before the diagnosis sees it: a draw
whose effect the design's values absorb within twice the tolerance is
replaced by the next draw of its seed).

A missing section is also labelled *detectable* or not, independently of
the diagnosis (:mod:`detectability`: the baseline's structure fitted to the
truth's sections without noise by the reference solver; undetectable when
that fit is within the noise), and so is any other single cause the
diagnosis did not name (the baseline's structure fitted to the whole
truth), and the other effect of a compound case with a missing section when
only the section was named (the truth's own sections fitted to the whole
truth), and, on one port, the other effect of a compound of two effects
named as one of them (the truth's sections with the named effect in the
truth's own form fitted to the whole truth); the counts are given both ways.

Prints the confusion matrix (true cause set x named cause set), the counts
named right per group, false alarms, and the wall times; then the speed of
one one-port and one six-response diagnosis with the fast path against the
same candidate fitted through the dense per-frequency solve
(:meth:`pris_cosim.frf.response.ResponseModel.evaluate_grid`), measured in this run.
Runs through the project's executor (local processes) and keeps every
finished case in ``--out`` so an interrupted run resumes.

Run: ``python benchmarks/bench_diagnosis.py [--quick] [--out results/bench_diagnosis]``
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent / "tests"
for p in (str(HERE), str(TESTS), str(HERE.parent)):
    if p not in sys.path:
        sys.path.insert(0, p)
# worker processes run this checkout's code (not another installed copy)
os.environ["PYTHONPATH"] = os.pathsep.join([str(HERE.parent), str(HERE), str(TESTS), os.environ.get("PYTHONPATH", "")])

import design_family  # noqa: E402  (beside this script)
from design_family import DESIGN_FAMILY, DESIGN_SEEDS, task_id  # noqa: E402,F401


def run_case(kind: str, causes: list[str], seed: int, noise: float = 0.003, group: str | None = None,
             sections: int | None = None, drift: bool = False, draw: int = 0) -> dict:
    """Generate one hidden-effect case and diagnose it (top-level so worker processes can run it)."""
    import hidden_cases as hc

    _jacobian_from_environment()

    from estimation.diagnosis import diagnose_frequency
    from pris_cosim.models.builtin import get_model
    from pris_cosim.circuits.netlist import parse_netlist

    if kind == "design":
        case = hc.design_case(tuple(causes), seed, noise=noise, drift=drift, draw=draw)
        t = time.perf_counter()
        d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                               port=case.port, progress=False, tolerance=0.2)
    elif kind == "one-port":
        case = hc.one_port_case(tuple(causes), seed, noise=noise, sections=sections)
        t = time.perf_counter()
        d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist),
                               port=case.port, progress=False)
    else:
        case = hc.two_winding_case(tuple(causes), seed, noise=noise, group=group)
        t = time.perf_counter()
        d = diagnose_frequency(case.frequency_hz, case.measured, model=get_model(case.baseline_model), progress=False)
    wall = time.perf_counter() - t
    # can the baseline's structure reproduce the truth within the noise at all? (a missing section always; another
    # single cause when nothing was named)
    from detectability import DESIGN_BOUND, best_baseline_fit

    section = None
    if kind == "design":
        # within twice the tolerance (beyond it a fit is drift, not an explanation); the drifted value free
        box = {"bound": DESIGN_BOUND, "free": tuple(case.truth.get("drift", ()))}
        if "missing-section" in causes:
            section = best_baseline_fit(case, **box)
        elif len(causes) == 1 and causes[0] != "none" and not d.causes:
            section = best_baseline_fit(case, target="truth", **box)
    elif "missing-section" in causes:
        section = best_baseline_fit(case)
    elif len(causes) == 1 and causes[0] != "none" and not d.causes:
        section = best_baseline_fit(case, target="truth")
    # a compound case's other effect, missed while its section was named: can the truth's own sections, values free,
    # reach the truth with every effect within the noise (the effect then undetectable once the section is there)?
    effect = None
    if "missing-section" in causes and len(causes) > 1 and d.causes == ["missing-section"]:
        effect = best_baseline_fit(case, target="truth", structure="sections",
                                   **(box if kind == "design" else {}))
        effect["asked"] = "+".join(c for c in causes if c != "missing-section")
    # a compound of two effects named as one of them: can the truth's sections with that one effect (the truth's own
    # form and parameters), values free, reach the truth within the noise (the other then undetectable beside it)?
    elif (kind in ("design", "one-port") and len(causes) == 2 and "missing-section" not in causes
          and len(d.causes) == 1 and d.causes[0] in causes):
        effect = best_baseline_fit(case, target="truth", structure="sections", keep=d.causes[0],
                                   **(box if kind == "design" else {}))
        effect["asked"] = next(c for c in causes if c != d.causes[0])
    return {"section_fit": section, "effect_fit": effect, "kind": kind, "true": case.label, "named": "+".join(sorted(d.causes)) or "none",
            "order": d.causes, "gain": d.gain, "wall_s": wall, "noise": noise, "truth": case.truth,
            "steps": d.steps, "groups": [e.group for e in (d.best.effects if d.best else [])],
            "candidates": {c["cause"]: round(c["gain"], 4) for c in d.candidates()},
            "drift": [x["name"] for x in d.drift], "true_drift": case.truth.get("drift", []),
            "drift_accepts": {t: sorted(_parallel_partners(case.baseline_netlist).get(t.lower(), {t.lower()}))
                              for t in case.truth.get("drift", [])}}


def _parallel_partners(netlist: str) -> dict[str, set[str]]:
    """Per element (lower-case name), the elements of the netlist of its kind across the same two nodes, itself
    included (coupled inductors left out): the terminals see only their combination, so a drift reported on any of
    them reports the true one. Read from the SPICE text here, not by the diagnosis's parser."""
    rows = [ln.split() for ln in netlist.splitlines() if ln.strip() and ln.strip()[0] not in "*.+"]
    coupled = {w.lower() for r in rows if r[0][0].upper() == "K" for w in r[1:3]}
    ground = {"0", "gnd"}
    groups: dict[tuple, set[str]] = {}
    for r in rows:
        if r[0][0].upper() in "RLC" and r[0].lower() not in coupled:
            ends = frozenset("0" if n.lower() in ground else n.lower() for n in r[1:3])
            groups.setdefault((r[0][0].upper(), ends), set()).add(r[0].lower())
    return {name: members for members in groups.values() for name in members}


def _jacobian_from_environment() -> None:
    """Analytic Jacobian columns in the fits when ``--analytic-jacobian`` set ``BENCH_ANALYTIC_JACOBIAN``."""
    if os.environ.get("BENCH_ANALYTIC_JACOBIAN") == "1":
        from estimation.diagnosis import fit

        fit.ANALYTIC_JACOBIAN = True




def design_cases(quick: bool, draws: bool = True) -> list[dict]:
    """The design-anchored family, with the draws :mod:`design_draws` chose where ``draws``."""
    from design_draws import load_draws

    return design_family.design_cases(quick, load_draws() if draws else None)


def named_right(r: dict, detectable_only: bool = False) -> bool:
    """Causes named as hidden, and for a design case every drifted value reported (none reported otherwise); a
    value in parallel with the drifted one (:func:`_parallel_partners`) reports it.

    ``detectable_only``: the causes expected are the detectable ones (:func:`_expected`).
    """
    if (_expected(r) if detectable_only else r["true"]) != r["named"]:
        return False
    if r["kind"] != "design":
        return True
    reported = {n.lower() for n in r.get("drift", [])}
    accepts = r.get("drift_accepts") or {}
    return (all(reported & set(accepts.get(t, [t.lower()])) for t in r.get("true_drift", []))
            and (bool(r.get("true_drift")) or not r.get("drift")))


def cases(quick: bool) -> list[dict]:
    """The benchmark's case list (at least 60, at least 15 compound)."""
    from hidden_cases import COMPOUND, SINGLE

    out = design_cases(quick)
    seeds = 2 if quick else 4
    for cause in SINGLE:
        for s in range(seeds):
            out.append({"kind": "one-port", "causes": [cause], "seed": s})
    for pair in COMPOUND:
        for s in range(1 if quick else 2):
            out.append({"kind": "one-port", "causes": list(pair), "seed": 100 + s})
    for s in range(2 if quick else 6):
        out.append({"kind": "one-port", "causes": ["none"], "seed": 200 + s, "noise": 0.01})
    for cause in SINGLE:
        for s in range(1 if quick else 2):
            out.append({"kind": "two-winding", "causes": [cause], "seed": 300 + s, "group": "all"})
    for cause in ("skin-effect", "magnetising-inductance"):
        for g in ("lv", "hv"):
            out.append({"kind": "two-winding", "causes": [cause], "seed": 400, "group": g})
    for pair in COMPOUND[: 3 if quick else 6]:
        out.append({"kind": "two-winding", "causes": list(pair), "seed": 500, "group": "all"})
    for s in range(1 if quick else 2):
        out.append({"kind": "two-winding", "causes": ["none"], "seed": 600 + s, "noise": 0.01})
    return out


def speed(progress: bool = True) -> dict:
    """Wall time of one one-port and one six-response diagnosis, and the fast path against the dense path."""
    import hidden_cases as hc

    from estimation.diagnosis import diagnose_frequency
    from estimation.diagnosis.causes.catalogue import SkinEffect
    from estimation.diagnosis.fit import FrequencyFit
    from pris_cosim.frf.response import ResponseModel
    from pris_cosim.models.builtin import get_model
    from pris_cosim.circuits.netlist import parse_netlist

    _jacobian_from_environment()

    def cpu() -> float:
        t = os.times()
        return t.user + t.system

    from estimation.diagnosis.cores import helper_available

    out = {"load_before": os.getloadavg()[0], "helper": helper_available()}
    one = hc.one_port_case(("skin-effect",), 7, sections=5)
    t, c = time.perf_counter(), cpu()
    diagnose_frequency(one.frequency_hz, one.measured, circuit=parse_netlist(one.baseline_netlist), port="n1",
                       progress=False)
    out["one_port_s"], out["one_port_cpu_s"] = time.perf_counter() - t, cpu() - c
    two = hc.two_winding_case(("skin-effect",), 7, group="hv", points=200)
    model = get_model("hv-4section")
    t, c = time.perf_counter(), cpu()
    diagnose_frequency(two.frequency_hz, two.measured, model=model, progress=False)
    out["six_response_s"], out["six_response_cpu_s"] = time.perf_counter() - t, cpu() - c
    out["load_after"] = os.getloadavg()[0]
    # one candidate's responses for a Jacobian's worth of parameter sets: fast path against dense solves
    fit = FrequencyFit(model.circuit, list(model.configurations.values()), two.frequency_hz, two.measured,
                       effects=[SkinEffect(form="causal", f_ref=10.0)])
    X = np.vstack([fit.start_vectors()[0]] * (fit.nc + 3))
    X[1:, :] += 1e-6 * np.eye(X.shape[1])[: X.shape[0] - 1]
    t = time.perf_counter()
    fast = fit.predict_batch(X)
    out["fast_batch_s"] = time.perf_counter() - t
    t = time.perf_counter()
    over = fit.overrides(X[0])
    values = fit.circuit.resolve(over)
    p = {"a": np.exp(X[:, -2]), "b": X[:, -1]}
    fac = SkinEffect(form="causal", f_ref=10.0).factor(two.frequency_hz, p)
    worst = 0.0
    for cfg in model.configurations.values():
        rm = ResponseModel(fit.circuit, cfg.port, shorts=cfg.shorts, responses=cfg.responses)
        per = {n: values[n.lower()] * fac for n in fit.groups.resistors["all"]}
        dense = rm.evaluate_grid(two.frequency_hz, over, per)
        for k, v in dense.items():
            worst = max(worst, float(np.max(np.abs(fast[k][-1] / v[-1] - 1))))
    out["dense_batch_s"] = time.perf_counter() - t
    out["fast_vs_dense_max_rel"] = worst
    return out


def main() -> None:
    from estimation.search.executor import ResultsStore, Task, run_tasks

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer seeds (about 35 cases)")
    ap.add_argument("--out", default="results/bench_diagnosis")
    ap.add_argument("--executor", default="processes")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--no-speed", action="store_true", help="skip the timed single diagnoses")
    ap.add_argument("--only", nargs="+", default=None, metavar="TEXT",
                    help="run only the cases whose id contains one of these texts (e.g. missing-section none)")
    ap.add_argument("--analytic-jacobian", action="store_true",
                    help="analytic Jacobian columns of the circuit values (estimation.diagnosis.fit.ANALYTIC_JACOBIAN)")
    args = ap.parse_args()
    if args.analytic_jacobian:
        os.environ["BENCH_ANALYTIC_JACOBIAN"] = "1"  # read by the worker processes too
    todo = cases(args.quick)
    if args.only:
        todo = [c for c in todo if any(t in task_id(c) for t in args.only)]
        if not todo:
            ap.error(f"--only: no case id contains any of {', '.join(args.only)}")
    tasks = [Task(task_id(c), run_case, c, label=task_id(c)) for c in todo]
    t0 = time.perf_counter()
    results = run_tasks(tasks, executor=args.executor, store=ResultsStore(args.out), progress=True,
                        workers=args.workers, on_error="continue")
    wall = time.perf_counter() - t0
    labels = sorted({r["true"] for r in results} | {r["named"] for r in results},
                    key=lambda s: (s.count("+"), s != "none", s))
    counts = Counter((r["true"], r["named"]) for r in results)
    short = {lab: "+".join(w[:4] for w in lab.replace("-", " ").replace("+", " + ").split() if w != "+")
             .replace("+++", "+") for lab in labels}
    width = max(len(lab) for lab in labels)
    print(f"\nconfusion matrix over {len(results)} cases (rows: hidden causes, columns: named causes)")
    print(" " * (width + 2) + " ".join(f"{short[lab][:9]:>9}" for lab in labels))
    for t in labels:
        row = [counts.get((t, n), 0) for n in labels]
        if sum(row):
            print(f"{t:>{width}}  " + " ".join(f"{v:>9d}" for v in row))
    print("\ncolumn key: " + ", ".join(f"{short[lab]} = {lab}" for lab in labels))
    design = [r for r in results if r["kind"] == "design"]
    results = [r for r in results if r["kind"] != "design"]
    families = {
        "design-anchored (all)": design,
        "design: clean, within tolerance": [r for r in design if r["true"] == "none" and not r["true_drift"]],
        "design: a value drifted, no cause": [r for r in design if r["true"] == "none" and r["true_drift"]],
        "design: one cause": [r for r in design if "+" not in r["true"] and r["true"] != "none"],
        "design: two causes": [r for r in design if "+" in r["true"]],
        "design: cause and a drifted value": [r for r in design if r["true"] != "none" and r["true_drift"]],
    }
    groups = {
        "single causes": [r for r in results if "+" not in r["true"] and r["true"] != "none"],
        "compound (two causes)": [r for r in results if "+" in r["true"]],
        "one winding only": [r for r in results if r["kind"] == "two-winding" and r["truth"].get("group") in ("lv", "hv")
                             and r["true"] != "none"],
        "netlist baselines (one-port)": [r for r in results if r["kind"] == "one-port" and r["true"] != "none"],
        "missing section": [r for r in results if "missing-section" in r["true"]],
        "missing section, detectable": [r for r in results if "missing-section" in r["true"] and _detectable(r)],
        "missing section, undetectable": [r for r in results if "missing-section" in r["true"] and not _detectable(r)],
        "undetectable (any cause)": [r for r in results if not _detectable(r)],
        "clean at 0.3 %": [r for r in results if r["true"] == "none" and r["noise"] < 0.005],
        "clean at 1 %": [r for r in results if r["true"] == "none" and r["noise"] >= 0.005],
    }
    print()
    rows_out = []
    if design:
        right = sum(named_right(r, detectable_only=True) for r in design)
        print(f"{'design-anchored, detectable causes':34s} named right {right:3d}/{len(design)}  (a cause is "
              "undetectable when the design's structure, its values within twice the tolerance, fits the truth "
              "without noise to within the noise: tests/detectability.py)")
        rows_out.append(["design-anchored (all), only detectable causes expected", right, len(design),
                         round(100 * right / len(design), 1),
                         round(float(np.median([r["wall_s"] for r in design])), 1)])
    for name, rows in list(families.items()) + list(groups.items()):
        if rows:
            right = sum(named_right(r) for r in rows)
            print(f"{name:34s} named right {right:3d}/{len(rows)}  median wall "
                  f"{np.median([r['wall_s'] for r in rows]):.1f} s")
            rows_out.append([name, right, len(rows), round(100 * right / len(rows), 1),
                             round(float(np.median([r["wall_s"] for r in rows])), 1)])
    for r in design:
        if not named_right(r):
            print(f"  design miss: {r['true']} (drift {r['true_drift']}) named {r['named']} "
                  f"(drift {r['drift']}, gain {r['gain']:.3f})")
    design_alarms = [r for r in design if r["true"] == "none" and r["named"] != "none"]
    print(f"design-anchored false alarms: {len(design_alarms)}/{sum(r['true'] == 'none' for r in design)} "
          "(clean or drift-only cases)")
    alarms = [r for r in results if r["true"] == "none" and r["named"] != "none"]
    print(f"false alarms on clean data: {len(alarms)}/{sum(r['true'] == 'none' for r in results)}")
    print(f"all cases named right: {sum(r['true'] == r['named'] for r in results)}/{len(results)}")
    print(f"named right, counting only the detectable causes: {sum(_expected(r) == r['named'] for r in results)}/"
          f"{len(results)} (a cause is undetectable when the baseline's structure, fitted to the truth without "
          "noise by the reference solver, is within the noise, tests/detectability.py: an undetectable single "
          "cause is expected as none, an undetectable missing section of a compound case is left out)")
    for kind in ("one-port", "two-winding"):
        w = [r["wall_s"] for r in results if r["kind"] == kind]
        if w:
            print(f"wall per {kind} case: median {np.median(w):.1f} s, max {max(w):.1f} s "
                  f"(cases run {args.workers or os.cpu_count()} at a time)")
    print(f"total wall {wall:.0f} s for {len(results)} cases (stored cases are not rerun)")
    s = None
    if not args.no_speed:
        s = speed()
        print(f"\nspeed ({'analytic' if args.analytic_jacobian else 'difference'} Jacobian columns of the circuit "
              f"values), one diagnosis at a time (a helper process on the second core: {s['helper']}): one-port "
              f"(5-section netlist, 200 points) {s['one_port_s']:.1f} s wall, {s['one_port_cpu_s']:.1f} s processor in "
              f"this process (goal 10 s wall); six responses (hv-4section, 200 points) {s['six_response_s']:.1f} s "
              f"wall, {s['six_response_cpu_s']:.1f} s processor in this process (goal 60 s); "
              f"load average {s['load_before']:.1f} before, {s['load_after']:.1f} after")
        print(f"one Jacobian's worth of responses ({len(model_rows())} responses): fast path {s['fast_batch_s'] * 1e3:.0f} ms, "
              f"dense per-frequency solve {s['dense_batch_s'] * 1e3:.0f} ms (ratio "
              f"{s['dense_batch_s'] / s['fast_batch_s']:.1f}x), agreement {s['fast_vs_dense_max_rel']:.1e}")
    from results_io import table, write_results

    tables = [table("Cases named right, per family (design-anchored: tolerance 0.2, truth within 10 % of the design)",
                    ["family", "named right", "cases", "%", "median wall (s)"], rows_out)]
    if s is not None:
        tables.append(table(f"Speed, one diagnosis at a time ({'analytic' if args.analytic_jacobian else 'difference'}"
                            f" Jacobian columns; load average {s['load_before']:.1f} before, "
                            f"{s['load_after']:.1f} after)", ["diagnosis", "wall (s)", "processor, this process (s)", "goal (s)"],
                            [["one-port, 5-section netlist, 200 points", round(s["one_port_s"], 1),
                              round(s["one_port_cpu_s"], 1), 10],
                             ["six responses, hv-4section, 200 points", round(s["six_response_s"], 1),
                              round(s["six_response_cpu_s"], 1), 60]]))
    d_right = sum(named_right(r) for r in design)
    write_results("bench_diagnosis", tables=tables,
                  summary=f"design-anchored family {d_right}/{len(design)} named right, "
                          f"{len(design_alarms)} false alarms; hidden-effect cases "
                          f"{sum(named_right(r) for r in results)}/{len(results)}")


def _expected(r: dict) -> str:
    """The causes a diagnosis can be expected to name: the true ones without an undetectable one."""
    effect = r.get("effect_fit")
    if effect and not effect["detectable"]:  # one effect of a compound case, undetectable given the other cause
        asked = (set(effect["asked"].split("+")) if effect.get("asked")
                 else {c for c in r["true"].split("+") if c != "missing-section"})
        return "+".join(sorted(c for c in r["true"].split("+") if c not in asked)) or "none"
    if _detectable(r):
        return r["true"]
    rest = [c for c in r["true"].split("+") if c != "missing-section" and "+" in r["true"]]
    return "+".join(sorted(rest)) or "none"  # an undetectable single cause: none expected


def _detectable(r: dict) -> bool:
    """False for a missing section that no network of the baseline's structure can tell from the truth, or for the
    other effect of a compound case that the truth's own sections (with the other effect named) reach within the
    noise."""
    fit = r.get("section_fit")
    effect = r.get("effect_fit")
    return (True if not fit else bool(fit["detectable"])) and (True if not effect else bool(effect["detectable"]))


def model_rows() -> list[str]:
    return ["Zlvoc", "Zlvsc", "Zhvoc", "Zhvsc", "Rlvhv", "Rhvlv"]


if __name__ == "__main__":
    main()
