"""Diagnosis on broad cases drawn from physics by code that shares nothing with it, and its speed.

    python benchmarks/bench_broad.py [--draws N] [--first SEED] [--effect EFFECT] [--visible] [--speed-only]
                                     [--out FILE]

Cases: :mod:`broad_cases` (3-10 section windings solved by their own nodal
equations; skin effect from a round conductor's Bessel solution, core loss
from a lamination's ``tanh(q)/q``, every capacitance to ground scaled, one
local capacitance fault, a split section, one value beyond the tolerance, or
nothing; grids from 100 Hz-10 kHz to 1-10 MHz with 200-1000 points, 0.1-2 %
noise, CSV or Touchstone). The seeds are ``first .. first + draws - 1``, fixed
before any answer was looked at (default 1000 ..). Each case is written to a
temporary folder, read back as a user's file and diagnosed against its design
netlist (tolerance 0.2). A case is right when the causes named equal the
truth's and, where the truth gives the drift, the values reported beyond the
tolerance equal it (a group's drift: the members of the group reported).
Some draws hide their effect: the design's model within the tolerance fits
them (:func:`broad_cases.signature`, measured without the diagnosis); the
table counts those apart, and a second share takes such a draw as right
when it is answered with nothing (no cause, no drift). A third share counts
a draw as right when the truth is named among the alternatives the report
gives beside its answer, in the place of one named: the data fit them as well,
and the report says it cannot tell which. With ``--visible`` a seed whose own
draw hides its effect is replaced by its first independent draw that shows
it (:func:`broad_cases.visible_draw`: the seed's generator drawn again, the
same effect; decided from the generator's solver alone, before any diagnosis
sees the draw); its row is marked ``seed/k``.

Prints one row per draw, then the share right, the false alarms (a cause
named on a draw with none), the clean draws with drift reported, and the
speed target: one 8-section one-port netlist on 500 points. With ``--out``
each draw's row is appended to that JSON-lines file as it finishes, and a
run started again with the same file skips the draws already in it (a long
run resumes after an interruption); the table covers every row in the file
for the seeds asked.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from broad_cases import EFFECTS, VISIBLE, draw, reported_drift, signature, visible_draw, write  # noqa: E402

from estimation.diagnosis import diagnose_frequency  # noqa: E402
from pris_cosim.measured.formats import load_measured  # noqa: E402
from pris_cosim.circuits.netlist import read_netlist  # noqa: E402


def run(seed: int, effect: str | None, folder: Path, k: int = 0) -> dict:
    """Draw ``k`` of ``seed`` (:func:`broad_cases.draw`) diagnosed: its row of the table."""
    case = draw(seed, effect, k=k)
    data, net = write(case, folder)
    m = load_measured(str(data))
    t = time.perf_counter()
    d = diagnose_frequency(m.frequency_hz, m.responses, circuit=read_netlist(str(net)), port=case.port,
                           progress=False, tolerance=0.2)
    wall = time.perf_counter() - t
    said, drift = sorted(d.causes), reported_drift(d.drift, case.drift)
    ok = said == sorted(case.causes) and (case.drift is None or drift == set(case.drift))
    return {"seed": seed, "draw": k, "effect": case.effect, "sections": case.netlist.count("\nL"),
            "points": case.frequency_hz.size, "noise": case.noise, "fmt": case.fmt, "truth": case.causes,
            "truth_drift": case.drift, "said": d.cause,
            "causes": said, "drift": sorted(drift), "gain": d.gain, "ok": ok, "wall": wall,
            "signature": signature(case), "cause_alternatives": sorted({a["cause"] for a in d.cause_alternatives}),
            "drift_alternatives": sorted(reported_drift(d.drift_alternatives, case.drift))}


def _excused(r: dict) -> bool:
    """Right, or the effect hidden in the noise (:data:`broad_cases.VISIBLE`) and nothing named or reported."""
    return r["ok"] or (r["signature"] < VISIBLE and not r["causes"] and not r["drift"])


def _among_alternatives(r: dict) -> bool:
    """Right once the alternatives the report names beside its answer count (the data fit them as well): each cause
    and drifted value of the truth named, or named as an alternative in the place of one named."""
    def held(truth: list[str], said: list[str], alternatives: list[str]) -> bool:
        return sorted(said) == sorted(truth) or (len(said) == len(truth) and set(truth) <= set(said) | set(alternatives))
    return r["ok"] or (held(r["truth"], r["causes"], r.get("cause_alternatives", []))
                       and (r["truth_drift"] is None or held(r["truth_drift"], r["drift"],
                                                             r.get("drift_alternatives", []))))


def speed(folder: Path) -> float:
    """Seconds of one diagnosis of an 8-section one-port netlist on 500 points (a clean draw)."""
    seed = next(s for s in range(1, 10_000) if draw(s, "none").netlist.count("\nL") == 8)
    case = draw(seed, "none", points=500)
    data, net = write(case, folder)
    m = load_measured(str(data))
    t = time.perf_counter()
    d = diagnose_frequency(m.frequency_hz, m.responses, circuit=read_netlist(str(net)), port="n1", progress=False)
    wall = time.perf_counter() - t
    print(f"speed case (seed {seed}, {case.fmt}, nothing hidden): {d.cause}, drift "
          f"{sorted(reported_drift(d.drift)) or 'none'}")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--first", type=int, default=1000)
    ap.add_argument("--effect", choices=EFFECTS)
    ap.add_argument("--speed-only", action="store_true")
    ap.add_argument("--out", type=Path, help="JSON-lines file of the draws' rows (appended; resumed from)")
    ap.add_argument("--visible", action="store_true",
                    help="a seed whose own draw hides its effect in the noise is replaced by its first draw that "
                         "shows it (broad_cases.visible_draw, decided before the diagnosis)")
    a = ap.parse_args()
    done: dict[tuple[int, int], dict] = {}
    if a.out is not None and a.out.exists():
        for line in a.out.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                if a.effect is None or r["effect"] == a.effect:
                    done[r["seed"], r.get("draw", 0)] = r
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        rows = []
        if not a.speed_only:
            print(f"{'seed':>7} {'effect':9} {'n':>2} {'pts':>4} {'noise':>6} fmt | truth | said | drift | gain | s")
            for seed in range(a.first, a.first + a.draws):
                k = 0
                if a.visible:
                    own = done.get((seed, 0))
                    if own is None or own.get("signature", 0.0) < VISIBLE and own["effect"] != "none":
                        # the draw taken before (rows of a seed's redraws are only written for the one that shows)
                        k = (min((j for s_, j in done if s_ == seed and j > 0), default=0)
                             or visible_draw(seed, a.effect)[0])
                r = done.get((seed, k))
                if r is None:
                    r = run(seed, a.effect, folder, k)
                    if a.out is not None:
                        with a.out.open("a") as fh:
                            fh.write(json.dumps(r) + "\n")
                if "signature" not in r:  # a row from before the signature was measured
                    r["signature"] = signature(draw(seed, a.effect, k=k))
                rows.append(r)
                print(f"{r['seed']:5d}{'/' + str(k) if k else '  '} {r['effect']:9} {r['sections']:2d} "
                      f"{r['points']:4d} {r['noise']:6.2%} "
                      f"{r['fmt']:3} | {','.join(r['truth']) or 'none'} {r['truth_drift'] or ''} | "
                      f"{'ok' if r['ok'] else 'NO'} {','.join(r['causes']) or r['said']} | {','.join(r['drift'])} | "
                      f"{r['gain']:.3f} | {r['wall']:.0f}"
                + ("" if r["ok"] or not _excused(r) else f" (hidden: signature {r['signature']:.2g})"), flush=True)
            clean = [r for r in rows if r["effect"] == "none"]
            alarms = sum(bool(r["causes"]) for r in rows if not r["truth"])
            hidden = [r for r in rows if r["effect"] != "none" and r["signature"] < VISIBLE]
            print(f"right {sum(r['ok'] for r in rows)}/{len(rows)}; effects hidden in the noise {len(hidden)} "
                  f"(signature < {VISIBLE:g}: the design's model within the tolerance fits them); right or hidden and "
                  f"answered none {sum(_excused(r) for r in rows)}/{len(rows)}; right or named among the "
                  f"alternatives the report gives {sum(_among_alternatives(r) for r in rows)}/{len(rows)}, with the "
                  f"hidden draws {sum(_among_alternatives(r) or _excused(r) for r in rows)}/{len(rows)}")
            print(f"false alarms {alarms} "
                  f"(of {sum(not r['truth'] for r in rows)} draws without a cause); clean draws with drift "
                  f"{sum(bool(r['drift']) for r in clean)}/{len(clean)}")
            print("right by effect: " + ", ".join(
                f"{e} {sum(r['ok'] for r in rows if r['effect'] == e)}/{sum(r['effect'] == e for r in rows)}"
                for e in EFFECTS if any(r["effect"] == e for r in rows)))
            walls = np.array([r["wall"] for r in rows])
            eight = np.array([r["wall"] for r in rows if r["sections"] == 8])
            print(f"wall per draw: median {np.median(walls):.0f} s, 90th percentile {np.percentile(walls, 90):.0f} s"
                  + (f"; 8-section draws ({eight.size}): median {np.median(eight):.0f} s, longest {eight.max():.0f} s"
                     if eight.size else ""))
        print(f"speed: 8-section one-port netlist, 500 points: {speed(folder):.1f} s")


if __name__ == "__main__":
    main()
