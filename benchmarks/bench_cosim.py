"""Co-simulation of the source FMU and the winding FMU: the exact master, and the coupling error of fixed-step masters.

Part ``exact``: PRIS case of thesis 4.2.2, three-section winding, PRBS of
order ``--order`` (default 12) at 100 kHz, sampled at ``--fs`` (default
10 MHz), one period. Rows: numpy ZOH engine, exact co-simulation (FMUs built
beforehand, cached; instantiation included), ngspice at
``--ngspice-max-step`` (default 20 ns), all measured in the same run. Errors
are relative RMS against the numpy engine.

Part ``coupling``: the shipped FMI 2.0 FMUs (``fmus/two-section``,
``fmus/three-section``) coupled by fixed-step masters at communication steps
from the FMUs' default step downwards: our Jacobi and Gauss-Seidel masters
(:func:`pris_cosim.fmi.cosim.cosimulate`), libcosim's fixed-step master (Jacobi,
through libcosimpy, when installed), and the exact master at the default step.
Errors are relative RMS on ``v_in`` and ``i_in`` against the monolithic FMU
(``*_pris.fmu``) run by fmpy on the same grid over the first PRBS bits (50
for two-section, 300 for three-section: five decay times of the slowest-damped
resonance, after which the error has reached its steady level). Below 4 ns
(three-section) only libcosim's Jacobi master runs: at every larger step its
errors equal our Jacobi master's to all digits shown. Wall times are
divided by that monolithic run's. A second table gives, per master, the
largest step of the ladder with both errors at most 1 %.

Part ``splits``: each way of cutting the arrangement into an SSP system
(``build-fmu --ssp --split bridge|thesis``) run as its archive says: the
shipped archive ``fmus/<case>/<name>.ssp`` (bridge split) and the thesis
split's archive written from the shipped source and DUT FMUs, each at its
default step over its whole default experiment, in every SSP master
available: libcosim (``libcosim_run``), ecos (``ecos_run``) and fmpy's SSP
master (``fmpy.ssp.simulation.simulate_ssp``). Errors are relative RMS on
``v_in`` and ``i_in`` against the monolithic FMU run by fmpy on the same
grid; written to ``benchmarks/results/bench_cosim_splits.json``.

    python benchmarks/bench_cosim.py [--part exact|coupling|splits|all] [--order 12] [--fs 1e7] [--no-ngspice]
                                     [--bits N] [--json FILE] [--masters libcosim,ecos,fmpy.ssp]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pris_cosim.fmi import codegen, cosim, ecos_run, build as fmi, libcosim_run, ssp
from pris_cosim.circuits import ngspice
from pris_cosim.lab import timedomain as td
from pris_cosim.fmi.cosim_exact import cosimulate_exact
from pris_cosim.models.builtin import get_model
from pris_cosim.fmi.thesis_cases import THREE_SECTION, TWO_SECTION

sys.path.insert(0, str(Path(__file__).resolve().parent))
from results_io import table, write_results  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: (case, FMU folder, base name, model, port, thesis case, steps in ns (whole ns dividing the PRBS bit),
#: PRBS bits of the window: at least five decay times of the slowest-damped resonance, so that the
#: error of the coupled system's shifted resonances has grown to its steady level; the smallest step
#: (ns) at which every master runs: below it only libcosim's Jacobi master, whose results equal our
#: Jacobi master's to the digits shown at every larger step)
COUPLING_CASES = (
    ("two-section", "two-section", "two_section", "two-section", "in", TWO_SECTION,
     (3125, 1600, 800, 625, 400, 200, 160, 125, 100), 50, 100),
    ("three-section", "three-section", "three_section", "three-section", "n1", THREE_SECTION,
     (80, 40, 25, 20, 10, 5, 4, 2, 1), 300, 4),
)
MASTERS = ("ours Jacobi", "ours Gauss-Seidel", "libcosim fixed-step (Jacobi)")
LIMIT = 0.01


def fastest_period(model: str, port: str, case) -> float:
    """Period (s) of the fastest oscillatory mode of the monolithic arrangement at its start values."""
    return ssp.fastest_period(codegen.arrangement_model(get_model(model).circuit, port, case.settings))


def coupling(bits: int | None, out_tables: list, figures: dict) -> None:
    """Coupling error of fixed-step masters against the monolithic FMU over a ladder of steps."""
    rows, guidance = [], []
    lc = libcosim_run.available()
    if not lc:
        print("libcosimpy is not installed: libcosim rows left out", file=sys.stderr)
    for name, folder, base, model, port, case, ladder, case_bits, all_down_to in COUPLING_CASES:
        src, dut, pris = (ROOT / "fmus" / folder / f"{base}_{k}.fmu" for k in ("source", "dut", "pris"))
        t_fast = fastest_period(model, port, case)
        stop = (bits or case_bits) / case.settings.fclk
        best: dict[str, int] = {}
        for h_ns in ladder:
            h = h_ns * 1e-9
            n = round(stop / h) + 1
            print(f"{name}: step {h_ns} ns ({n - 1} steps) ...", file=sys.stderr, flush=True)
            t0 = time.perf_counter()
            with cosim.FmuRunner(pris) as r:
                ref = r.run((n - 1) * h, h, output=["v_in", "i_in"])
            t_ref = time.perf_counter() - t0
            runs: dict[str, tuple[dict, float]] = {}
            ours = (("ours Jacobi", "jacobi"), ("ours Gauss-Seidel", "gauss-seidel"))
            if h_ns < all_down_to:
                ours = () if lc else ours[:1]
            for master, scheme in ours:
                t0 = time.perf_counter()
                with cosim.FmuRunner(src) as a, cosim.FmuRunner(dut) as b:
                    w = cosim.cosimulate(a, b, 1 / h, n, scheme=scheme)
                runs[master] = ({"v_in": w["v_in"][1:], "i_in": w["i_in"][1:]}, time.perf_counter() - t0)
            if lc:
                t0 = time.perf_counter()
                res, _ = libcosim_run.run_pair(src, dut, (n - 1) * h, h)
                runs[MASTERS[2]] = ({"v_in": res["dut.v_in"], "i_in": res["source.i_in"]},
                                    time.perf_counter() - t0)
            if h_ns == ladder[0]:
                t0 = time.perf_counter()
                with cosim.FmuRunner(src, "ModelExchange") as a, cosim.FmuRunner(dut, "ModelExchange") as b:
                    w, _ = cosimulate_exact(a, b, 1 / h, n)
                runs["ours exact (--engine cosim)"] = ({"v_in": w["v_in"][1:], "i_in": w["i_in"][1:]},
                                                       time.perf_counter() - t0)
            for master, (w, wall) in runs.items():
                ev = cosim.relative_rms(w["v_in"], ref["v_in"][1:])
                ei = cosim.relative_rms(w["i_in"], ref["i_in"][1:])
                rows.append([name, h_ns, h / t_fast, master, 100 * ev, 100 * ei, wall, wall / t_ref])
                print(f"  {master:30s} v_in {100 * ev:9.4f} %  i_in {100 * ei:9.4f} %  wall {wall:7.2f} s "
                      f"({wall / t_ref:5.2f} x monolithic)", flush=True)
                if master in MASTERS and max(ev, ei) <= LIMIT and master not in best:
                    best[master] = h_ns
        for master in MASTERS:
            if master == MASTERS[2] and not lc:
                continue
            h_ns, note = best.get(master), ""
            if h_ns is None and master == MASTERS[0] and MASTERS[2] in best:
                h_ns, note = best[MASTERS[2]], "from libcosim's Jacobi run (ours not run below 4 ns)"
            guidance.append([name, master, h_ns if h_ns else f"below {ladder[-1]}",
                             h_ns * 1e-9 / t_fast if h_ns else "", 1e6 * t_fast, note])
            if h_ns:
                key = f"{name}_{'jacobi' if 'Jacobi' in master else 'gauss_seidel'}_{master.split()[0]}_step_1pct"
                figures[key] = {"value": h_ns, "unit": "ns"}
    out_tables.append(table(
        "Coupling error of fixed-step masters against the monolithic FMU (shipped FMI 2.0 FMUs; first "
        + ", ".join(f"{bits or c[-2]} PRBS bits of {c[0]}" for c in COUPLING_CASES) + ")",
        ["case", "step (ns)", "step / fastest period", "master", "v_in error (%)", "i_in error (%)", "wall (s)",
         "wall / monolithic"], rows))
    out_tables.append(table(
        "Largest step of the ladder with v_in and i_in within 1 % RMS",
        ["case", "master", "step (ns)", "step / fastest period", "fastest period (us)", "note"], guidance))


SPLIT_MASTERS = ("libcosim", "ecos", "fmpy.ssp")


def _run_master(master: str, system: Path, tmp: Path) -> tuple[dict, float]:
    """One SSP archive at its default step over its default experiment; libcosim and ecos in a subprocess."""
    import subprocess

    stop, step = ssp.default_experiment(system)
    n = round(stop / step)
    if master == "fmpy.ssp":
        from fmpy.ssp.simulation import simulate_ssp

        t0 = time.perf_counter()
        res = simulate_ssp(str(system), stop_time=stop, step_size=step)
        wall = time.perf_counter() - t0
        return {name: np.asarray(res[name][:n]) for name in res.dtype.names if name != "time"}, wall
    module = {"libcosim": ["pris_cosim.fmi.libcosim_run", "ssp"], "ecos": ["pris_cosim.fmi.ecos_run"]}[master]
    out = tmp / f"{master}.npz"
    proc = subprocess.run([sys.executable, "-m", *module, str(system), "--out", str(out)], capture_output=True,
                          text=True, cwd=ROOT)
    if proc.returncode:
        raise RuntimeError(f"{master} failed on {system.name}: {proc.stderr.strip()[-500:]}")
    wall = json.loads(proc.stdout.strip().splitlines()[-1])["wall_s"]
    with np.load(out) as data:
        return {k: data[k] for k in data.files}, wall


def splits(masters: list[str], out_tables: list, figures: dict) -> None:
    """Error of each split's archive at its default step over its default experiment, in each SSP master."""
    available = {"libcosim": libcosim_run.available(), "ecos": ecos_run.available(), "fmpy.ssp": True}
    for m in masters:
        if not available[m]:
            print(f"{m} is not available: its rows are left out", file=sys.stderr)
    rows = []
    for name, folder, base, model, port, case, *_ in COUPLING_CASES:
        shipped = ROOT / "fmus" / folder
        with tempfile.TemporaryDirectory(prefix="bench-splits-") as tmp:
            tmp = Path(tmp)
            guidance = ssp.step_guidance("thesis", case.fmu_experiment[1], case.settings.fclk,
                                         fastest_period(model, port, case))
            systems = {"bridge": shipped / f"{base}.ssp",
                       "thesis": ssp.write_ssp(shipped / f"{base}_source.fmu", shipped / f"{base}_dut.fmu",
                                               tmp / f"{base}_thesis.ssp", name=base, split="thesis",
                                               guidance=guidance)}
            stop, step = ssp.default_experiment(systems["bridge"])
            t0 = time.perf_counter()
            with cosim.FmuRunner(shipped / f"{base}_pris.fmu") as r:
                ref = r.run(stop, step, output=["v_in", "i_in"])
            t_ref = time.perf_counter() - t0
            n = round(stop / step)
            for split, system in systems.items():
                (v_label, _), (i_label, _) = [(f"{c}.{v}", v) for c, v in ssp.recorded_outputs(system)[:2]]
                for master in masters:
                    if not available[master]:
                        continue
                    print(f"{name}, {split} split, {master}: {n} steps of {step * 1e9:g} ns ...", file=sys.stderr,
                          flush=True)
                    res, wall = _run_master(master, system, tmp)
                    ev = cosim.relative_rms(res[v_label][:n], ref["v_in"][1:])
                    ei = cosim.relative_rms(res[i_label][:n], ref["i_in"][1:])
                    rows.append([name, split, round(step * 1e9, 3), n, master, 100 * ev, 100 * ei, wall,
                                 wall / t_ref])
                    print(f"  v_in {100 * ev:.3g} %  i_in {100 * ei:.3g} %  wall {wall:.2f} s", flush=True)
                    figures[f"{name}_{split}_{master}_v_in_error"] = {"value": 100 * ev, "unit": "%"}
                    figures[f"{name}_{split}_{master}_i_in_error"] = {"value": 100 * ei, "unit": "%"}
    out_tables.append(table(
        "Each split's SSP archive at its default step over its whole default experiment, against the monolithic "
        "FMU in fmpy (relative RMS)",
        ["case", "split", "step (ns)", "steps", "master", "v_in error (%)", "i_in error (%)", "wall (s)",
         "wall / monolithic"], rows))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("exact", "coupling", "splits", "all"), default="all")
    ap.add_argument("--masters", default=",".join(SPLIT_MASTERS),
                    help="SSP masters of the splits part, comma-separated (default: all three)")
    ap.add_argument("--order", type=int, default=12)
    ap.add_argument("--fs", type=float, default=10e6)
    ap.add_argument("--ngspice-max-step", type=float, default=20e-9)
    ap.add_argument("--no-ngspice", action="store_true")
    ap.add_argument("--bits", type=int, help="PRBS bits of the coupling runs (default: 50 two-section, "
                                             "300 three-section)")
    ap.add_argument("--json", metavar="FILE", help="also write the exact part's rows here")
    args = ap.parse_args(argv)
    tables: list = []
    figures: dict = {}
    if args.part in ("exact", "all"):
        exact(args, tables)
    if args.part in ("splits", "all"):
        masters = [m.strip() for m in args.masters.split(",") if m.strip()]
        bad = sorted(set(masters) - set(SPLIT_MASTERS))
        if bad:
            print(f"bench_cosim: error: --masters: unknown master {bad[0]!r} (choose from "
                  f"{', '.join(SPLIT_MASTERS)})", file=sys.stderr)
            return 2
        split_tables: list = []
        split_figures: dict = {}
        splits(masters, split_tables, split_figures)
        write_results("bench_cosim_splits", tables=split_tables, figures=split_figures,
                      summary="each split's SSP archive (bridge, thesis) at its default step over its default "
                              "experiment in libcosim, ecos and fmpy's SSP master, against the monolithic FMU")
        if args.part == "splits":
            return 0
    if args.part in ("coupling", "all"):
        coupling(args.bits, tables, figures)
    write_results("bench_cosim", tables=tables, figures=figures,
                  summary="exact co-simulation against numpy and ngspice; coupling error of Jacobi and "
                          "Gauss-Seidel fixed-step masters (ours, libcosim) against the monolithic FMU")
    return 0


def exact(args: argparse.Namespace, tables: list) -> None:
    """The exact master against the numpy engine and ngspice (three-section, one PRBS period)."""
    s = THREE_SECTION.settings
    s = type(s)(**{**s.__dict__, "prbs_order": args.order})
    dut = get_model("three-section").circuit
    rows: dict[str, dict[str, float]] = {}
    t0 = time.perf_counter()
    ref = td.simulate_pris(dut, "n1", s, args.fs)
    rows["numpy"] = {"wall_s": time.perf_counter() - t0}
    with tempfile.TemporaryDirectory() as tmp:
        src = fmi.build_fmu(codegen.source_model(s, name="bench_source"), tmp, write_modelica=False)
        win = fmi.build_fmu(codegen.dut_model(dut, "n1", name="bench_dut"), tmp, write_modelica=False)
        t0 = time.perf_counter()
        with cosim.FmuRunner(src, "ModelExchange") as a, cosim.FmuRunner(win, "ModelExchange") as b:
            w, err = cosimulate_exact(a, b, args.fs, ref["time_s"].size)
        rows["cosim_exact"] = {"wall_s": time.perf_counter() - t0, "coupling_error": err,
                               "v_in_rel_rms": cosim.relative_rms(w["v_in"], ref["v_in"]),
                               "i_in_rel_rms": cosim.relative_rms(w["i_in"], ref["i_in"])}
    if not args.no_ngspice and ngspice.available():
        print("ngspice ...", file=sys.stderr)
        t0 = time.perf_counter()
        sp = td.pris_ngspice(dut, "n1", s, args.fs, max_step=args.ngspice_max_step)
        rows["ngspice"] = {"wall_s": time.perf_counter() - t0,
                           "v_in_rel_rms": cosim.relative_rms(sp["v_in"][:ref["v_in"].size], ref["v_in"])}
        rows["cosim_exact"]["speedup_vs_ngspice"] = rows["ngspice"]["wall_s"] / rows["cosim_exact"]["wall_s"]
    result = {"samples": int(ref["time_s"].size), "order": args.order, "fs": args.fs, "rows": rows}
    for name, row in rows.items():
        print(f"{name:12s} " + "  ".join(f"{k}={v:.3g}" for k, v in row.items()))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    base = rows["numpy"]["wall_s"]
    tables.append(table(
        f"Exact co-simulation, three-section, PRBS{args.order}, one period at {args.fs / 1e6:g} MHz "
        f"({result['samples']} samples)",
        ["engine", "wall (s)", "wall / numpy", "v_in rel. RMS vs numpy", "i_in rel. RMS vs numpy"],
        [[name, row["wall_s"], row["wall_s"] / base, row.get("v_in_rel_rms", ""), row.get("i_in_rel_rms", "")]
         for name, row in rows.items()]))


if __name__ == "__main__":
    raise SystemExit(main())
