"""Wall time and round-trip accuracy of the virtual lab (thesis 5.1) on hv-4section (prints; not a test).

For each mode (quick: PRBS13 at 20 kHz + PRBS11 at 2 kHz; full: PRBS16 + PRBS13,
the thesis's) the six-response lab is run twice: with the default noise and
quantisation (timed per configuration, both clocks, simulation + Welch + synthesis)
and noise-free (round trip: max |dB| and |phase| error against the analytic
responses over 10 Hz - 10 kHz, and 10 - 100 kHz).

Usage::

    python benchmarks/bench_virtual_lab.py [--modes quick full] [--json FILE] [--plots DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

from pris_cosim.lab import virtual_lab as vl
from pris_cosim.models.builtin import get_model
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--modes", nargs="+", default=["quick", "full"], choices=["quick", "full"])
    ap.add_argument("--model", default="hv-4section")
    ap.add_argument("--json", default=None)
    ap.add_argument("--plots", default=None, help="directory for the Fig. 5.5/5.9 analogues (noisy run)")
    args = ap.parse_args(argv)
    model = get_model(args.model)
    report: dict[str, dict] = {}
    for mode in args.modes:
        quick = mode == "quick"
        t0 = time.perf_counter()
        noisy = vl.run_lab(model, quick=quick, noise=True, seed=0, keep_records=["LVSC"] if args.plots else False)
        t_noisy = time.perf_counter() - t0
        t0 = time.perf_counter()
        clean = vl.run_lab(model, quick=quick, noise=False)
        t_clean = time.perf_counter() - t0
        rt = vl.round_trip_errors(clean.measured, model, 10.0, 10e3)
        rt_hi = vl.round_trip_errors(clean.measured, model, 10e3, 100e3)
        rt_noisy = vl.round_trip_errors(noisy.measured, model, 10.0, 10e3)
        report[mode] = {
            "per_config_wall_s": noisy.wall_s, "lab_wall_s_noisy": t_noisy, "lab_wall_s_noise_free": t_clean,
            "round_trip_10Hz_10kHz": rt, "round_trip_10kHz_100kHz": rt_hi, "noisy_error_10Hz_10kHz": rt_noisy,
        }
        print(f"== {mode}: six-response lab {t_noisy:.1f} s (noisy), {t_clean:.1f} s (noise-free)")
        print("   per configuration (both clocks): " + ", ".join(f"{c} {s:.2f} s" for c, s in noisy.wall_s.items()))
        print(f"   {'response':8s} {'clean dB':>9s} {'clean deg':>9s} | {'>10k dB':>8s} {'>10k deg':>8s} |"
              f" {'noisy dB':>8s} {'noisy deg':>9s}")
        for n in rt:
            print(f"   {n:8s} {rt[n][0]:9.3f} {rt[n][1]:9.2f} | {rt_hi[n][0]:8.3f} {rt_hi[n][1]:8.2f} |"
                  f" {rt_noisy[n][0]:8.3f} {rt_noisy[n][1]:9.2f}")
        if args.plots:
            paths = vl.plot_lab(noisy, model, args.plots, stem=f"virtual_lab_{mode}")
            paths += vl.plot_record(noisy.records[("LVSC", "high")], args.plots, stem=f"virtual_lab_{mode}_lvsc_high")
            print("   plots: " + ", ".join(str(p) for p in paths))
        sys.stdout.flush()
    results_io.write_raw("bench_virtual_lab", report, summary=__doc__.splitlines()[0])
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
