"""Wall time and errors of the lumped-network fits of the real measured data.

Fits the small transformer's three loads jointly (constant winding
resistance, then skin-effect ladders) and the 03PK10 admittance ladder,
and prints per fit the wall time, the RMS magnitude (dB) and phase (deg)
errors, the short-circuit resistance rise and the admittance peaks.
Run: ``python benchmarks/bench_real_fits.py [--data DIR] [--global-evals N]``.
BLAS threads are pinned to one so the figures are per core.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

from estimation import real_fits as rf  # noqa: E402
from estimation.studies.real_data import GLOBAL_EVALS, data_dir  # noqa: E402
import results_io  # noqa: E402  (benchmarks/: results as JSON)


def _errors(fit: rf.FitResult) -> str:
    return ", ".join(f"{k} {fit.extra['errors_db'][k]:.3f} dB / {fit.extra['phase_errors_deg'][k]:.2f} deg"
                     for k in fit.extra["errors_db"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="directory of the real data (default: the study's)")
    ap.add_argument("--global-evals", type=int, default=GLOBAL_EVALS, help="swarm evaluations before least squares")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    folder = Path(args.data) if args.data else data_dir()

    rows = []
    small = rf.read_small_transformer(folder / rf.SMALL_FILE)
    for evals in (0, args.global_evals):
        fit = rf.fit_small_transformer(small, seed=args.seed, global_evals=evals)
        rows.append([f"small transformer, constant R, swarm {evals}", fit.wall_s, fit.nfev, _errors(fit)])
        print(f"small transformer, constant R, swarm {evals:5d}: {fit.wall_s:6.2f} s, {fit.nfev:5d} sets; {_errors(fit)}")
    skin = rf.fit_small_transformer_skin(small, fit)
    rows.append(["small transformer, skin-effect ladders", skin.wall_s, skin.nfev, _errors(skin)])
    print(f"small transformer, skin-effect ladders:      {skin.wall_s:6.2f} s, {skin.nfev:5d} sets; {_errors(skin)}")
    print(f"  a = {skin.values['a']:.3g}, b = {skin.values['b']:.3f} (f0 = {rf.SKIN_F0_HZ:g} Hz)")
    sc = rf.short_circuit_resistance(small, fit, skin)
    print(f"  Re Z_short rise {sc['f_low_hz']:.3g} -> {sc['f_high_hz']:.3g} Hz: measured x{sc['rise']['measured']:.2f}, "
          f"constant-R model x{sc['rise']['constant_r']:.2f}, skin ladders x{sc['rise']['skin']:.2f}")

    adm = rf.read_admittance(folder / rf.ADMITTANCE_FILE)
    for evals in (0, args.global_evals):
        afit = rf.fit_admittance(adm, seed=args.seed, global_evals=evals)
        rows.append([f"03PK10 ladder, swarm {evals}", afit.wall_s, afit.nfev, _errors(afit)])
        print(f"03PK10 ladder, swarm {evals:5d}:                 {afit.wall_s:6.2f} s, {afit.nfev:5d} sets; {_errors(afit)}")
    print("  peaks measured (MHz): " + ", ".join(f"{p / 1e6:.4f}" for p in afit.extra["peaks_measured_hz"]))
    print("  peaks fitted   (MHz): " + ", ".join(f"{p / 1e6:.4f}" for p in afit.extra["peaks_fitted_hz"]))
    print("  errors (%):           " + ", ".join(f"{e:+.2f}" for e in afit.extra["peak_errors_percent"]))
    print(f"  passive: {afit.passive}")
    results_io.write_results("bench_real_fits", summary=__doc__.splitlines()[0], tables=[
        results_io.table("Fits of the real measurements (pris_cosim/data/real)",
                         ["fit", "wall (s)", "parameter sets", "RMS errors per response"], rows),
        results_io.table("Short-circuit resistance rise and 03PK10 peaks",
                         ["quantity", "value"],
                         [[f"Re Z_short rise {sc['f_low_hz']:.3g} -> {sc['f_high_hz']:.3g} Hz, measured", sc["rise"]["measured"]],
                          ["same, constant-R model", sc["rise"]["constant_r"]],
                          ["same, skin-effect ladders", sc["rise"]["skin"]],
                          ["03PK10 peaks measured (MHz)", [x / 1e6 for x in afit.extra["peaks_measured_hz"]]],
                          ["03PK10 peaks fitted (MHz)", [x / 1e6 for x in afit.extra["peaks_fitted_hz"]]],
                          ["peak errors (%)", list(afit.extra["peak_errors_percent"])],
                          ["passive", afit.passive]])])


if __name__ == "__main__":
    main()
