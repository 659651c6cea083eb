"""DL/T 911 factors, verdicts and repeatability of the IPN sweeps, and their wall times.

Reads the two healthy references and the shorts of
``pris_cosim/data/real/ipn_winding_interturn/`` (or DATA_DIR, every ``*.s2p``
below it), computes the factors of each sweep against the first reference,
the verdict, and the repeatability judgement against the second reference;
prints one row per sweep, the count of each verdict, and the wall times of
reading the sweeps and of the comparison.

Usage: ``python benchmarks/bench_sfra_dlt911.py [DATA_DIR]``
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from estimation.diagnosis.sfra.compare import FraTrace, standard_comparison  # noqa: E402
from estimation.diagnosis.sfra.sweep import load_sweep  # noqa: E402

DEFAULT = ROOT / "pris_cosim" / "data" / "real" / "ipn_winding_interturn"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", nargs="?", default=str(DEFAULT))
    args = ap.parse_args()
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
