"""Wall time of the time-domain engines and of ``simulate`` end to end on the three-section PRIS case.

Case (thesis 4.2.2, architecture.md): three-section winding, Vdc = 100 V,
Rpris = 150 Ohm, Lpris = 4 mH, Cpris = 1 uF, PRBS12 at 100 kHz, sampled at
10 MHz: one PRBS period is 409,500 samples (40.95 ms).

Engine rows (in-process, compute only): the numpy exact ZOH engine, the
monolithic FMU run by fmpy (one communication step per sample), the source +
DUT FMUs co-simulated by the Gauss-Seidel master, and ngspice (PWL bridge,
``uic``, a maximum time step) as the reference, measured in the same run.
Accuracy is the relative RMS difference against the numpy engine.

End-to-end rows run the whole ``pris-cosim simulate`` command in a fresh
process (start-up, compute and the written file included) and record its
wall time and peak memory: PRBS12 to ``.npz``, ``.mat`` and ``.csv``, and
long records (PRBS14 and PRBS16, 6.5 million samples) in every format to
show the bounded memory and the linear time. The co-simulation engine gets
its end-to-end row when ``simulate --engine cosim`` exists (:func:`cosim_row`
is the hook).

Usage::

    python benchmarks/bench_timedomain.py [--order 12] [--ngspice-max-step 2e-8] [--no-ngspice]
        [--no-long] [--no-fmu] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pris_cosim.circuits import ngspice
from pris_cosim.lab import timedomain as td
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.models.builtin import get_model
import results_io  # noqa: E402  (benchmarks/: results as JSON)

#: Runs a command and prints its wall time and the peak resident memory of the command (KiB).
_MEASURE = (
    "import resource, subprocess, sys, time\n"
    "t = time.perf_counter()\n"
    "r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)\n"
    "w = time.perf_counter() - t\n"
    "print(r.returncode, w, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, repr(r.stderr[-300:]))\n"
)


def timed(fn, repeat: int = 1):
    """(median wall time in s, last result) of ``repeat`` calls."""
    times, result = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def relative_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def simulate_command(out: Path, order: int, fs: float, engine: str = "numpy") -> list[str]:
    """The ``pris-cosim simulate`` command line of the case (PRBS ``order``) writing ``out``."""
    return [sys.executable, "-m", "pris_cosim", "simulate", "--model", "three-section", "--port", "n1",
            "--vdc", "100", "--prbs-order", str(order), "--fclk", "100k", "--rpris", "150", "--lpris", "4m",
            "--cpris", "1u", "--fs", f"{fs:g}", "--periods", "1", "--out", str(out), "--engine", engine]


def end_to_end(cmd: list[str], repeat: int = 1) -> dict[str, float] | None:
    """Median wall time (s) and largest peak memory (MiB) of a command run in a fresh process."""
    walls, peaks = [], []
    for _ in range(repeat):
        res = subprocess.run([sys.executable, "-c", _MEASURE, *cmd], capture_output=True, text=True, check=True)
        code, wall, peak, err = res.stdout.split(maxsplit=3)
        if int(code) != 0:
            print(f"  failed ({code}): {err}", file=sys.stderr)
            return None
        walls.append(float(wall))
        peaks.append(int(peak) / 1024)
    return {"wall_s": statistics.median(walls), "peak_mib": max(peaks)}


def cosim_row(tmp: Path, order: int, fs: float) -> dict[str, float] | None:
    """End-to-end row of ``simulate --engine cosim`` (source FMU + winding FMU through the master).

    Returns None (row skipped) while the command does not offer that engine.
    """
    probe = subprocess.run([sys.executable, "-m", "pris_cosim", "simulate", "--help"], capture_output=True, text=True)
    engines = re.search(r"--engine \{([^}]*)\}", probe.stdout)
    if not engines or "cosim" not in engines.group(1).split(","):
        return None
    return end_to_end(simulate_command(tmp / "cosim.npz", order, fs, engine="cosim"))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--order", type=int, default=12, help="PRBS order (default 12)")
    ap.add_argument("--fs", type=float, default=10e6, help="sampling frequency, Hz (default 10 MHz)")
    ap.add_argument("--ngspice-max-step", type=float, default=20e-9, help="ngspice maximum step, s (default 20 ns)")
    ap.add_argument("--no-ngspice", action="store_true", help="skip ngspice")
    ap.add_argument("--no-fmu", action="store_true", help="skip the FMU engines")
    ap.add_argument("--no-long", action="store_true", help="skip the long-record (PRBS14/16) end-to-end rows")
    ap.add_argument("--repeat", type=int, default=5, help="repeats of the numpy engine and of end-to-end runs")
    ap.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = ap.parse_args(argv)

    dut = get_model("three-section").circuit
    s = SourceSettings(vdc=100.0, prbs_order=args.order, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)
    rows: dict[str, dict[str, float]] = {}

    td.simulate_pris(dut, "n1", s, args.fs)  # warm-up (imports, caches)
    t_np, ref = timed(lambda: td.simulate_pris(dut, "n1", s, args.fs), repeat=max(args.repeat, 3) * 4)
    n = ref["time_s"].size
    rows["numpy"] = {"wall_s": t_np, "samples": n}
    print(f"case: three-section, PRBS{args.order} at 100 kHz, fs = {args.fs:g} Hz, {n} samples", file=sys.stderr)

    def err(w):
        return {f"err_{k}": relative_rms(w[k], ref[k]) for k in ("v_in", "i_in")}

    e2e: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        if not args.no_fmu:
            from pris_cosim.fmi import codegen, cosim, build as fmi

            model = codegen.arrangement_model(dut, "n1", s, name="bench_pris")
            t_build, path = timed(lambda: fmi.build_fmu(model, tmp, use_cache=False, write_modelica=False))
            with cosim.FmuRunner(path) as runner:
                t_fmu, w = timed(lambda: cosim.simulate_pris_fmu(runner, s, args.fs), repeat=2)
            rows["fmu"] = {"wall_s": t_fmu, "build_s": t_build, **err(w)}
            paths = fmi.build_pris_fmus(dut, "n1", tmp, s, name="bench")
            with cosim.FmuRunner(paths["source"]) as src, cosim.FmuRunner(paths["dut"]) as d:
                t_co, w = timed(lambda: cosim.cosimulate(src, d, args.fs, n, "gauss-seidel"))
            rows["cosim_gauss_seidel"] = {"wall_s": t_co, **err(w)}

        print("end to end (fresh process each) ...", file=sys.stderr)
        for fmt in ("npz", "mat", "csv"):
            r = end_to_end(simulate_command(tmp / f"w.{fmt}", args.order, args.fs), repeat=args.repeat)
            if r:
                e2e[f"simulate_prbs{args.order}_{fmt}"] = r
        r = end_to_end([sys.executable, "-c", "import numpy"], repeat=args.repeat)
        if r:
            e2e["python_import_numpy"] = r
        r = cosim_row(tmp, args.order, args.fs)
        if r:
            e2e[f"simulate_prbs{args.order}_cosim_npz"] = r
        if not args.no_long:
            for order in (14, 16):
                for fmt in ("npz", "mat", "csv"):
                    print(f"  PRBS{order} .{fmt} ...", file=sys.stderr)
                    r = end_to_end(simulate_command(tmp / f"long.{fmt}", order, args.fs))
                    if r:
                        r["samples"] = td.record_samples(SourceSettings(prbs_order=order, fclk=100e3), args.fs)
                        e2e[f"simulate_prbs{order}_{fmt}"] = r
                    (tmp / f"long.{fmt}").unlink(missing_ok=True)

    ref_name = None
    if not args.no_ngspice and ngspice.available():
        print("ngspice ...", file=sys.stderr)
        t_sp, w = timed(lambda: td.pris_ngspice(dut, "n1", s, args.fs, max_step=args.ngspice_max_step))
        ref_name = f"ngspice_{args.ngspice_max_step:g}s"
        rows[ref_name] = {"wall_s": t_sp, **err(w)}

    t_ref = rows[ref_name]["wall_s"] if ref_name else float("nan")
    print(f"{'engine (compute only)':28s} {'wall_s':>9s} {'x numpy':>9s} {'ngspice/x':>10s} {'err v_in':>10s} {'err i_in':>10s}")
    for name, r in rows.items():
        r["ngspice_ratio"] = t_ref / r["wall_s"]
        ev, ei = r.get("err_v_in", np.nan), r.get("err_i_in", np.nan)
        print(f"{name:28s} {r['wall_s']:9.4f} {r['wall_s'] / t_np:9.1f} {r['ngspice_ratio']:10.1f} {ev:10.2e} {ei:10.2e}")
    if "fmu" in rows:
        print(f"FMU build (cold, CMake + gcc): {rows['fmu']['build_s']:.2f} s")
    print(f"\n{'end to end (fresh process)':28s} {'wall_s':>9s} {'peak MiB':>9s} {'ngspice/x':>10s}")
    for name, r in e2e.items():
        r["ngspice_ratio"] = t_ref / r["wall_s"]
        print(f"{name:28s} {r['wall_s']:9.3f} {r['peak_mib']:9.0f} {r['ngspice_ratio']:10.1f}")
    results_io.write_raw("bench_timedomain", {"case": {"prbs_order": args.order, "fs_hz": args.fs, "samples": n},
                                              "engines": rows, "end_to_end": e2e, "reference": ref_name},
                         summary=__doc__.splitlines()[0])
    if args.json:
        Path(args.json).write_text(json.dumps({"case": {"prbs_order": args.order, "fs_hz": args.fs, "samples": n},
                                               "engines": rows, "end_to_end": e2e, "reference": ref_name},
                                              indent=2, allow_nan=False if ref_name else True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
