"""Diagnose the 16 shared inter-turn-short sweeps against the healthy reference.

Prints per sweep: cause, located section and fraction of the winding from
the port-1 end, kind (bolted or resistive, from the fitted loop resistance),
gain, the side margin (how much higher the weighted cost of the best fit on
the other half of the winding is, in the units of the BIC), wall time; the
reference-fit time; the Spearman rank correlation of the
located position against the tap position, per kind; and a summary (causes
named, kinds right, slowest sweep).  The tap positions come from the data's
README and are used here only to score the result.

With ``--standard``: the DL/T 911 factors of each sweep against the first
reference, the verdict, and the repeatability judgement against the second
reference (``reference_2317.s2p``); one row per sweep, the count of each
verdict, and the wall times of reading the sweeps and of the comparison.

Usage: ``python benchmarks/bench_sfra.py [DATA_DIR] [--cache DIR]``, ``python benchmarks/bench_sfra.py --standard [DATA_DIR]``
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from estimation.diagnosis.sfra.compare import FraTrace, standard_comparison  # noqa: E402
from estimation.diagnosis.sfra.faults import diagnose_sweep  # noqa: E402
from estimation.diagnosis.sfra.fingerprint import load_or_fit  # noqa: E402
from estimation.diagnosis.sfra.sweep import load_sweep  # noqa: E402
import results_io  # noqa: E402  (benchmarks/: results as JSON)

DEFAULT = ROOT / "pris_cosim" / "data" / "real" / "ipn_winding_interturn"
#: Position NN -> first shorted tap (from the data's README).
TAPS = {1: 3, 3: 15, 5: 27, 7: 39, 9: 51, 11: 63, 13: 75, 15: 87}


def main() -> int:
    if "--standard" in sys.argv[1:]:
        return standard([a for a in sys.argv[1:] if a != "--standard"])
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?", default=str(DEFAULT))
    ap.add_argument("--cache", default=None, help="reference-model cache directory")
    ap.add_argument("--no-cache", action="store_true", help="always refit the reference")
    a = ap.parse_args()
    d = Path(a.data)
    ref = load_sweep(d / "reference_23072517.s2p")
    t = time.perf_counter()
    fp = load_or_fit(ref, a.cache, use_cache=not a.no_cache)
    t_fit = time.perf_counter() - t
    print(f"reference: N = {fp.n_sections}, rms {fp.rms:.3f}, fit {fp.fit_seconds:.1f} s "
          f"({'cached, load ' + format(t_fit, '.2f') + ' s' if fp.cached else 'fitted now'})")
    out, named, kinds, walls, rows = {}, 0, 0, [], []
    for kind, pattern in (("bolted", "bolted/230725{:02d}.s2p"), ("resistive", "resistive/23{:02d}.s2p")):
        taps, locs = [], []
        for nn, tap in TAPS.items():
            p = d / pattern.format(nn)
            if not p.is_file():
                continue
            t = time.perf_counter()
            diag = diagnose_sweep(fp, ref, load_sweep(p), progress=False)
            wall = time.perf_counter() - t
            walls.append(wall)
            loc = diag.location()
            sev = diag.severity() or {}
            frac = loc["fraction"] if loc else float("nan")
            named += diag.cause == "shorted-turns"
            gains = np.asarray(diag.by_section.get(diag.cause, []), dtype=float)
            margin = float("nan")
            if loc and gains.size:
                centres = (np.arange(gains.size) + 0.5) / gains.size
                other = centres > 0.5 if loc["fraction"] < 0.5 else centres < 0.5
                margin = diag.baseline_cost * (gains[loc["section"] - 1] - gains[other].max())
            kinds += sev.get("kind") == kind
            print(f"{kind:<9} {p.name:<14} taps {tap:>2}-{tap + 2:<2}: {diag.cause:<14} section "
                  f"{loc['section'] if loc else '-':>2}/{fp.n_sections} location {frac:.3f}  "
                  f"{sev.get('kind', '-'):<9} R {sev.get('fault_resistance_ohm') or float('nan'):8.3g} Ohm  "
                  f"gain {diag.gain:.3f}  side margin {margin:7.0f}  {wall:.1f} s", flush=True)
            taps.append(tap)
            locs.append(frac)
            rows.append([kind, p.name, f"{tap}-{tap + 2}", diag.cause, loc["section"] if loc else "-", frac,
                         sev.get("kind", "-"), diag.gain, wall])
        ok = np.isfinite(locs)
        rho = spearmanr(np.asarray(taps)[ok], np.asarray(locs)[ok])[0] if ok.sum() > 2 else float("nan")
        out[kind] = rho
        print(f"{kind}: Spearman rank correlation of location vs tap = {rho:+.3f}")
    n = len(walls)
    print(f"summary: {named}/{n} named shorted-turns, {kinds}/{n} kinds right, Spearman "
          + ", ".join(f"{k} {v:+.3f}" for k, v in out.items())
          + f", per sweep {min(walls):.1f}-{max(walls):.1f} s (reference model "
          + ("cached)" if fp.cached else "fitted in this run)"))
    results_io.write_results("bench_sfra", summary=__doc__.splitlines()[0], tables=[
        results_io.table(f"Per sweep (reference model: {fp.n_sections} sections, rms {fp.rms:.3f}, "
                         + ("cached" if fp.cached else f"fitted in {fp.fit_seconds:.0f} s") + ")",
                         ["kind", "file", "taps", "cause", "section", "location (fraction)", "kind named", "gain",
                          "wall (s)"], rows),
        results_io.table("Summary", ["sweeps", "named shorted-turns", "kinds right", "Spearman bolted",
                                     "Spearman resistive", "slowest sweep (s)"],
                         [[n, named, kinds, out.get("bolted"), out.get("resistive"), max(walls)]])])
    return 0



def standard(argv: list[str]) -> int:
    """The DL/T 911 factors, verdicts and repeatability of the IPN sweeps (``--standard``), with wall times."""
    ap = argparse.ArgumentParser(description="DL/T 911 factors, verdicts and repeatability of the IPN sweeps")
    ap.add_argument("data", nargs="?", default=str(DEFAULT))
    args = ap.parse_args(argv)
    d = Path(args.data)
    t0 = time.perf_counter()
    ref, rep = (load_sweep(d / n) for n in ("reference_23072517.s2p", "reference_2317.s2p"))
    paths = sorted(p for p in d.rglob("*.s2p") if not p.name.startswith("reference_"))
    sweeps = [load_sweep(p) for p in paths]
    t_read = time.perf_counter() - t0

    def trace(s):
        return FraTrace(s.frequency_hz, s.voltage_ratio, s.source)

    t0 = time.perf_counter()
    rows = []
    for p, s in zip(paths, sweeps):
        std, r = standard_comparison(trace(ref), trace(s), trace(rep))
        rows.append((p, std["dlt911"], r))
    t_cmp = time.perf_counter() - t0
    std, _ = standard_comparison(trace(ref), trace(rep))
    g = std["dlt911"]
    print(f"second reference: R_LF {g['R_LF']:.3f}  R_MF {g['R_MF']:.3f}  R_HF {g['R_HF']:.3f}  -> {g['verdict']}")
    print(f"{'sweep':<28} {'R_LF':>7} {'R_MF':>7} {'R_HF':>7}  verdict   repeatability")
    for p, g, r in rows:
        print(f"{str(p.relative_to(d)):<28} {g['R_LF']:7.3f} {g['R_MF']:7.3f} {g['R_HF']:7.3f}  {g['verdict']:<8}  "
              f"{r['summary']}")
    print("verdicts:", dict(Counter(g["verdict"] for _, g, _ in rows)))
    print(f"wall time: read {len(paths) + 2} sweeps {t_read:.2f} s; factors, verdicts and repeatability of "
          f"{len(rows)} sweeps {t_cmp:.3f} s ({1e3 * t_cmp / max(1, len(rows)):.1f} ms per sweep)")
    return 0



if __name__ == "__main__":
    raise SystemExit(main())
