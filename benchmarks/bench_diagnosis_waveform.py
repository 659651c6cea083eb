"""Accuracy and wall time of the waveform diagnosis on generated cases (prints figures; not a test).

Cases: the thesis's source check (3.3; PRBS4, four periods at 10 kHz, nominal
57.1 Ohm, 1 mH, 4 uF, a 15.3 Ohm load) with one hidden effect drawn at
random per case (``series-resistance``, ``component-drift``,
``switch-ringing``) or none, 0.3 % noise; plus the thesis's own measured
values diagnosed with the nominal ones. Prints the confusion matrix (true
cause x named cause), per-case gain and wall time.

With ``--recorded``: the arrangement's exact replay on the recorded PRIS
cases of ``tests/data/pris_records`` (the source on a 15 Ohm load: a series
resistance, drifted L and C, nothing, switch ringing; the three-section
winding: nothing, 330 pF across the port), diagnosed by
:func:`estimation.diagnosis.waveform.replay.diagnose_pris_record`; per case
the truth, the causes named, the fitted source values, the wall time and the
process's CPU time.

Usage::

    python benchmarks/bench_diagnosis_waveform.py [--per-cause 6] [--seed0 100] [--json FILE]
    python benchmarks/bench_diagnosis_waveform.py --recorded [NAME ...]
    python benchmarks/bench_diagnosis_waveform.py --sections

With ``--sections``: the replay's wall and CPU time with and without its
``missing-section`` candidate, on two ngspice records of 12,600 samples
(``tests/pris_records.py``: PRBS6 at 100 kHz, 10 MS/s, two periods, the 4.2.2
source, 0.2 % noise on ``v_in`` and ``i_in``): the three-section winding of
thesis Table 4.7 (nothing hidden) and ``FOUR_SECTIONS`` (its section 2 made
two), both diagnosed against the three-section netlist. Needs ngspice.
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from estimation.diagnosis.waveform.source import diagnose_waveforms
from estimation.diagnosis.waveform.synthetic import WAVEFORM_CASE_CAUSES, thesis_case, waveform_case
from pris_cosim.circuits.netlist import read_netlist
from pris_cosim.measured.formats import Waveforms
from pris_cosim.models.builtin import get_model

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "pris_records"
CASES = [  # name, baseline, source (R, L, C), truth
    ("source_series_r", "load", (57.1, 1e-3, 4e-6), ["series-resistance"]),
    ("source_drift", "load", (57.1, 1e-3, 4e-6), ["component-drift"]),
    ("source_none", "load", (57.1, 1e-3, 4e-6), []),
    ("source_ringing", "load", (57.1, 1e-3, 4e-6), ["series-resistance", "switch-ringing"]),
    ("three_section_ngspice_10MHz", "three-section", (150.0, 4e-3, 1e-6), []),
    ("three_section_stray_10MHz", "three-section", (150.0, 4e-3, 1e-6), ["stray-capacitance"]),
]


def recorded(only: list[str]) -> int:
    """The recorded PRIS cases replayed from their bridge voltage; one line each, then the count right."""
    from estimation.diagnosis.waveform.replay import diagnose_pris_record

    args_only = only
    todo = [c for c in CASES if not args_only or c[0] in args_only]
    if not todo:
        print(f"no case named {' '.join(args_only)} (cases: {', '.join(c[0] for c in CASES)})", file=sys.stderr)
        return 2
    right = 0
    for name, base, (r, l, c), truth in todo:
        with gzip.open(DATA / f"{name}.csv.gz", "rt") as fh:
            a = np.loadtxt(io.StringIO(fh.read()), delimiter=",", skiprows=1)
        w = Waveforms(a[:, 0], a[:, 1], a[:, 2], a[:, 3])
        kw = (dict(model=get_model(base)) if base != "load"
              else dict(circuit=read_netlist(DATA / "ho_load15.cir"), port="p"))
        t0, c0 = time.perf_counter(), time.process_time()
        d = diagnose_pris_record(w, r, l, c, progress=False, **kw)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        ok = sorted(d.causes) == sorted(truth)
        right += ok
        src = d.as_json()["source_values"]
        print(f"{'ok' if ok else 'NO'} {name:30s} truth {truth or ['none']} said {d.causes or ['none']} "
              f"R {src['rpris']:.4g} L {src['lpris']:.4g} C {src['cpris']:.4g} | {w.n_samples} samples, "
              f"wall {wall:.1f} s, cpu {cpu:.1f} s", flush=True)
    print(f"{right}/{len(todo)} right")
    return 0



def sections() -> int:
    """The replay with and without its missing-section candidate (module docstring, ``--sections``)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from pris_records import FOUR_SECTIONS, WINDING, record

    import estimation.diagnosis.waveform.replay as replay
    from pris_cosim.circuits.netlist import parse_netlist
    from pris_cosim.measured.formats import Waveforms

    records = {"three sections recorded": record(noise=0.002),
               "four sections recorded": record(noise=0.002, winding=FOUR_SECTIONS)}
    structures = replay.section_structures
    for label, search in (("with missing-section", structures), ("without", lambda circuit, port: [])):
        replay.section_structures = search
        for name, rec in records.items():
            w = Waveforms(rec["time_s"], rec["v_bprbs"], rec["v_in"], rec["i_in"])
            t, c = time.perf_counter(), time.process_time()
            d = replay.diagnose_pris_record(w, 150.0, 4e-3, 1e-6, circuit=parse_netlist(WINDING + ".end\n"),
                                            port="n1", progress=False)
            model = next((s.get("model", "") for s in d.steps if s["cause"] == "missing-section"), "")
            print(f"{label:21s} {name:24s} causes {d.causes or ['none']} {model} | wall "
                  f"{time.perf_counter() - t:.1f} s, CPU {time.process_time() - c:.1f} s", flush=True)
    replay.section_structures = structures
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-cause", type=int, default=6, help="cases per cause (default 6: 24 cases)")
    ap.add_argument("--seed0", type=int, default=100, help="first seed")
    ap.add_argument("--noise", type=float, default=0.003, help="relative noise (default 0.003)")
    ap.add_argument("--json", help="write the per-case rows to this file")
    ap.add_argument("--recorded", nargs="*", metavar="NAME",
                    help="the recorded PRIS cases replayed from the bridge voltage instead (all, or the ones named)")
    ap.add_argument("--sections", action="store_true",
                    help="the replay with and without its missing-section candidate on two ngspice records instead")
    args = ap.parse_args(argv)
    if args.sections:
        return sections()
    if args.recorded is not None:
        return recorded(args.recorded)
    rows = []
    jobs = [(c, args.seed0 + i) for i in range(args.per_cause) for c in WAVEFORM_CASE_CAUSES]
    jobs.append(("thesis", 0))
    for cause, seed in jobs:
        case = thesis_case(seed, args.noise) if cause == "thesis" else waveform_case(cause, seed, noise=args.noise)
        t0 = time.perf_counter()
        d = diagnose_waveforms(case.waveforms, **case.nominal, **case.diagnose_kwargs, progress=False)
        wall = time.perf_counter() - t0
        row = {"true": cause, "seed": seed, "strength": case.strength, "named": d.cause, "causes": d.causes,
               "gain": d.gain,
               "samples": case.waveforms.n_samples, "wall_s": wall, "extension": d.best.extra if d.best else {}}
        rows.append(row)
        print(f"{cause:18s} seed {seed:4d} strength {case.strength:.2f} samples {row['samples']:6d} -> "
              f"{'+'.join(d.causes) or 'none':18s} gain {d.gain:.3f}  {wall:6.1f} s", flush=True)
    named = ("none",) + tuple(c for c in WAVEFORM_CASE_CAUSES if c != "none")
    truths = named + ("thesis",)
    print("\nconfusion matrix (rows: hidden cause, columns: named cause)")
    print(f"{'':18s}" + "".join(f"{n:>19s}" for n in named))
    for t in truths:
        counts = [sum(1 for r in rows if r["true"] == t and r["named"] == n) for n in named]
        if sum(counts):
            print(f"{t:18s}" + "".join(f"{c:19d}" for c in counts))
    gen = [r for r in rows if r["true"] != "thesis"]
    correct = sum(r["true"] == r["named"] for r in gen)
    alone = sum(r["causes"] == ([] if r["true"] == "none" else [r["true"]]) for r in gen)
    print(f"\nnamed alone (no further cause added by forward selection): {alone}/{len(gen)}")
    print(f"\naccuracy {correct}/{len(gen)}; gain of correctly named causes: min "
          f"{min([r['gain'] for r in gen if r['true'] == r['named'] and r['named'] != 'none'] or [float('nan')]):.3f}")
    for t in truths:
        w = [r["wall_s"] for r in rows if r["true"] == t]
        if w:
            print(f"wall time {t:18s} median {statistics.median(w):6.1f} s  max {max(w):6.1f} s")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1, default=float)
    return 0 if correct == len(gen) else 1


if __name__ == "__main__":
    sys.exit(main())
