"""FMU-in-the-loop benchmark: truth scores of the record replays, and FMU estimates with wide bounds.

Run from the checkout: ``python benchmarks/bench_estimate_fmu.py [--cases two,three] [--approach time]
[--design N] [--restarts N] [--simulations N] [--workers N] [--out DIR]``

A foreign FMU: ``python benchmarks/bench_estimate_fmu.py --ladder DIR`` with ``DIR`` holding
``ThreeSectionLadder.fmu`` (a pythonfmu FMU: voltage ``u_drive`` behind ``R_src`` in, ``i_port``
and ``v_port`` out), ``record.csv``, ``record_noisy.csv`` and ``truth.json``. Printed per record:
the truth's replay score under each input hold, the hold chosen from the data, and the estimate of
six free values (``L_a``, ``L_b``, ``L_c``, ``C_a``, ``C_b``, ``k_ab``, bounds 0.2x .. 5x the truth;
the others set through ``"values"``): per-parameter errors, FMU runs, wall time, the verdict. Each
estimate runs as a ``pris-cosim estimate`` subprocess (a pythonfmu FMU may crash its host when freed).
``--records`` picks the records (default both).

The peer, run for real: ``--ladder DIR --peers [--peer-venv PATH] [--peer-wall S] [--peer-maxiter N]``
creates a throwaway virtual environment outside the repository (default: a new temporary directory),
``pip install``s estim8 there (``--peer-package``) and, after our estimate of each record, runs
``benchmarks/peers/estim8_driver.py`` with that environment's Python: estim8's differential evolution
polished by L-BFGS-B on the same FMU, record, free values and bounds, one process, capped at
``--peer-wall`` seconds (default 900); ``--peer-reuse`` takes the peer's answers stored in ``--out``
by an earlier run instead of running it again (ours always runs). Printed and written to ``bench_estimate_fmu_peers.json``:
per-parameter errors, FMU runs (ours also in whole-record equivalents), wall times, ours beside theirs,
the ratio of runs and whether ours is within 2 % where theirs is not with at most a tenth of their runs.

A four-section winding FMU built here: ``python benchmarks/bench_estimate_fmu.py --four [--fmi3]
[--four-noise 0,0.005]`` builds the four-section FMU of ``tests/foreign_fmus.py`` with pythonfmu (or
pythonfmu3: FMI 3.0), records it with fmpy (a PRBS of order 9 at 200 kHz sampled at 4 MHz, two periods:
20,440 samples; current ``i_drive`` in, ``v_1`` and ``v_4`` out) and estimates nine values: ``L1`` ..
``L4``, a shared ``Cs`` and ``Cg`` through ``ties``, ``k12``, ``k23``, ``k34`` (bounds a third to three
times the truth; the couplings clipped below 1), as a ``pris-cosim estimate`` subprocess on two workers.
Printed per record: errors, FMU runs (whole-record equivalents), wall time, the verdict.

For every case the prebuilt arrangement FMU (``fmus/*/..._pris.fmu``) makes
a 1 MHz record with fmpy's ``simulate_fmu`` (two-section: 50 ms, the peers'
comparison record; three-section: 10 ms). Printed:

1. truth scores -- the RMS error of the true model replayed from the record,
   relative to the signal RMS -- with the sampled current held (the old
   replay), held linearly (first-order hold), and with the recorded bridge
   voltage through the source's R-L-C;
2. the FMU estimate (``pris-cosim estimate`` with ``"fmu"``: the same
   arrangement FMU in the loop, time approach by default) with bounds 0.1x
   .. 10x the truth for R, L, C (two-section: R1, C1, L1, L2, M12 with the
   thesis ties R2 = R1, C2 = C1; three-section: Rs, Cs, Cg, Ls and the
   couplings k12, k13, k23 within 0.85 .. 0.95, thesis Table 4.8): parameter
   errors, FMU runs (failed ones), wall time, the verdict.

Wall times depend on the machine's load; they are printed as measured.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

CASES = {
    "two": {"model": "two-section", "port": "in", "fmu": "fmus/two-section/two_section_pris.fmu", "duration": 0.05,
            "truth": {"R1": 10.0, "C1": 1e-9, "L1": 10.0, "L2": 100.0, "M12": 30.0}, "ties": {"R2": "R1", "C2": "C1"}},
    "three": {"model": "three-section", "port": "n1", "fmu": "fmus/three-section/three_section_pris.fmu",
              "duration": 0.01, "truth": {"Rs": 0.083, "Cs": 9.7e-10, "Cg": 1.6e-9, "Ls": 1.81e-4, "k12": 0.8792,
                                          "k13": 0.8729, "k23": 0.8564}, "ties": {}},
}


def record(fmu: Path, fs: float, duration: float) -> dict[str, np.ndarray]:
    from pris_cosim.fmi.cosim import FmuRunner

    n = int(round(fs * duration))
    with FmuRunner(fmu) as r:
        names = [v.name for v in r.model_description.modelVariables if v.causality == "output"]
        res = r.run(stop_time=(n - 1) / fs, output_interval=1 / fs, output=names)
    out = {k: np.asarray(res[k][:n], float) for k in names}
    out["time_s"] = np.arange(n) / fs
    return out


def rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b ** 2)))


def truth_scores(case: dict, w: dict[str, np.ndarray], fs: float) -> dict[str, float]:
    from estimation import approaches as ap
    from estimation.drives import RecordBridgeEngine
    from pris_cosim.models.builtin import get_model
    from pris_cosim.fmi.thesis_cases import THREE_SECTION, TWO_SECTION

    circuit = get_model(case["model"]).circuit
    settings = TWO_SECTION.settings if case["model"] == "two-section" else THREE_SECTION.settings
    out = {}
    for hold in ("step", "linear"):
        v = ap.InjectionEngine(circuit, case["port"], w["i_in"], fs, hold=hold).simulate({})[0]
        out[f"current, {hold} hold"] = rel(v, w["v_in"])
    b = RecordBridgeEngine(circuit, case["port"], settings, fs, w["v_bprbs"]).simulate({})
    out["bridge voltage"] = rel(b["v_in"][0], w["v_in"])
    return out


def bounds(truth: dict[str, float]) -> dict[str, dict[str, float]]:
    return {k: ({"min": 0.85, "max": 0.95, "scale": "linear"} if k.startswith("k") else {"min": v / 10, "max": v * 10})
            for k, v in truth.items()}


LADDER_FREE = ("L_a", "L_b", "L_c", "C_a", "C_b", "k_ab")


def ladder_replay(d: Path, truth: dict[str, float], record: Path) -> dict[str, float]:
    """Truth replay scores of the ladder FMU (worst output RMS error over the output RMS) per input hold."""
    from estimation.fmu.model import FmuModel
    from estimation.fmu.problem import read_record

    outs = ["i_port", "v_port"]
    w = read_record(record, ["u_drive"] + outs)
    fs = (w["time_s"].size - 1) / (w["time_s"][-1] - w["time_s"][0])
    scores = {}
    for hold in ("zoh", "linear"):
        with FmuModel(d / "ThreeSectionLadder.fmu", list(truth), outs, input="u_drive", hold=hold, substeps=2) as m:
            y = m.simulate(truth, fs, w["time_s"].size, w["u_drive"])
        scores[hold] = max(rel(y[k], w[o]) for k, o in enumerate(outs))
    return scores


def ladder_truth(d: Path, rec: str) -> tuple[dict[str, float], tuple[str, ...]]:
    """The true values of one ladder record and its free values: the ``truth*.json`` that names the record
    (``"record"``), else ``truth.json`` with :data:`LADDER_FREE`."""
    for path in sorted(d.glob("truth*.json")):
        doc = json.loads(path.read_text())
        if doc.get("record") == rec:
            return doc["truth"], tuple(doc.get("free", LADDER_FREE))
    return json.loads((d / "truth.json").read_text())["truth"], LADDER_FREE


def ladder_config(d: Path, rec: str, truth: dict[str, float], a: argparse.Namespace,
                  free: tuple[str, ...] = LADDER_FREE) -> dict:
    """The ``pris-cosim estimate`` configuration of the ladder FMU: the ``free`` values, the others set."""
    params = {k: {"min": 0.2 * truth[k], "max": min(5 * truth[k], 0.99) if k.startswith("k") else 5 * truth[k]}
              for k in free}
    cfg = {"fmu": str(d / "ThreeSectionLadder.fmu"), "input": "u_drive", "output": "i_port",
           "outputs": ["v_port"], "parameters": params,
           "values": {k: v for k, v in truth.items() if k not in free},
           "target": {"kind": "waveforms-csv", "path": str(d / rec), "values": truth}, "seed": 1}
    budget = {k: v for k, v in (("design", a.design), ("restarts", a.restarts), ("simulations", a.simulations))
              if v is not None}
    if budget:
        cfg["budget"] = budget
    return cfg


def ladder_estimate(a: argparse.Namespace, d: Path, rec: str, truth: dict[str, float], out: Path,
                    free: tuple[str, ...] = LADDER_FREE) -> dict | None:
    """Run ``pris-cosim estimate`` on one ladder record in a subprocess; its JSON answer, or None on failure."""
    import subprocess

    cpath = out / f"ladder-{Path(rec).stem}.json"
    cpath.write_text(json.dumps(ladder_config(d, rec, truth, a, free), indent=1))
    cmd = [sys.executable, "-m", "pris_cosim", "estimate", "--config", str(cpath), "--json",
           "--out", str(out / f"ladder-{Path(rec).stem}")]
    if a.workers:
        cmd += ["--workers", str(a.workers)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE, text=True)
    wall = time.perf_counter() - t0
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("{")), None)
    if line is None:
        print(f"   estimate failed (exit {p.returncode})")
        return None
    res = json.loads(line)
    worst = max(abs(e) for e in res["errors_percent"].values())
    print(f"   input hold: {res['input_hold']} ({res['input_hold_reason']})")
    print(f"   worst error {worst:.3g} %, {res['fmu_simulations']} FMU runs "
          f"({res['fmu_record_equivalents']:.0f} whole-record equivalents), {res['wall_s']:.1f} s "
          f"(process {wall:.1f} s, exit {p.returncode}), converged {res['converged']}")
    print(f"   verdict: {res['convergence_reason']}; non-identifiable: {res['non_identifiable'] or 'none'}")
    for k, e in res["errors_percent"].items():
        sd = (res["uncertainty"] or (res.get("local_curvature") or {}).get("values", {})).get(k, float("nan"))
        print(f"     {k:>5} {res['estimate'][k]:12.5g}  {e:+10.4f} %  (1-sigma {100 * sd:.2g} %)")
    for r in res["restarts"]:
        stages = ", ".join(f"{s['stage']}: {s['runs']}" for s in r.get("runs_per_stage") or [])
        print(f"   restart {r['restart']}: cost {r['cost']:.3g}, {r['simulations']} runs ({stages})")
    res["worst_percent"], res["process_wall_s"] = worst, wall
    return res


PEER_DRIVER = REPO / "benchmarks" / "peers" / "estim8_driver.py"


def peer_python(a: argparse.Namespace) -> Path:
    """The Python of a throwaway virtual environment holding estim8 (created and filled when missing)."""
    import subprocess
    import tempfile
    import venv

    root = Path(a.peer_venv) if a.peer_venv else Path(tempfile.mkdtemp(prefix="pris-cosim-peer-"))
    if REPO in root.resolve().parents or root.resolve() == REPO:
        raise SystemExit(f"--peer-venv {root}: the peer's environment must lie outside the repository")
    py = root / "bin" / "python"
    if not py.exists():
        print(f"== creating the peer's environment {root}", flush=True)
        venv.create(root, with_pip=True)
    probe = subprocess.run([str(py), "-c", "import estim8"], capture_output=True)
    if probe.returncode:
        print(f"== pip install {a.peer_package} into {root}", flush=True)
        subprocess.run([str(py), "-m", "pip", "install", "-q", a.peer_package], check=True)
    return py


def peer_estimate(a: argparse.Namespace, py: Path | None, d: Path, rec: str, out: Path) -> dict:
    """Run the peer (estim8, differential evolution polished by L-BFGS-B) on one ladder record."""
    import os
    import subprocess

    res_path, prog = out / f"peer-{Path(rec).stem}.json", out / f"peer-{Path(rec).stem}-progress.json"
    if a.peer_reuse and res_path.exists():
        doc = json.loads(res_path.read_text())
        doc.setdefault("worst_percent", max((abs(e) for e in doc["errors_percent"].values()), default=float("nan")))
        doc.setdefault("process_wall_s", doc.get("wall_s", float("nan")))
        print(f"   peer {doc.get('peer', 'estim8')}: reused {res_path} (run {doc.get('date', 'earlier')}): worst error "
              f"{doc['worst_percent']:.3g} %, {doc['runs']} FMU runs, {doc.get('wall_s', float('nan')):.1f} s "
              f"({doc['stopped']})", flush=True)
        return doc
    py = py or peer_python(a)
    for f in (res_path, prog):
        f.unlink(missing_ok=True)
    cmd = [str(py), str(PEER_DRIVER), "--fmu", str(d / "ThreeSectionLadder.fmu"), "--record", str(d / rec),
           "--truth", str(d / "truth.json"), "--input", "u_drive", "--outputs", "i_port,v_port",
           "--free", ",".join(LADDER_FREE), "--maxiter", str(a.peer_maxiter), "--popsize", str(a.peer_popsize),
           "--wall", str(a.peer_wall), "--out", str(res_path), "--progress", str(prog)]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONWARNINGS="ignore")
    env.pop("PYTHONPATH", None)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                       timeout=a.peer_wall + 600)
    wall = time.perf_counter() - t0
    if not res_path.exists():  # the FMU may crash the host when freed: read what was reached
        doc = json.loads(prog.read_text()) if prog.exists() else {"runs": 0, "best": {}}
        doc.update(stopped=f"process ended with exit {p.returncode} before its answer", estimate=doc["best"])
        truth = json.loads((d / "truth.json").read_text())["truth"]
        doc["errors_percent"] = {k: 100 * (v - truth[k]) / truth[k] for k, v in doc["best"].items()}
        print(p.stderr[-2000:])
    else:
        doc = json.loads(res_path.read_text())
    doc["process_wall_s"] = wall
    doc["worst_percent"] = max((abs(e) for e in doc["errors_percent"].values()), default=float("nan"))
    doc["date"] = time.strftime("%Y-%m-%d %H:%M")
    res_path.write_text(json.dumps(doc, indent=1))  # kept for --peer-reuse
    print(f"   peer {doc.get('peer', 'estim8')}: worst error {doc['worst_percent']:.3g} %, {doc['runs']} FMU runs, "
          f"{doc.get('wall_s', wall):.1f} s ({doc['stopped']}); truth cost {doc.get('truth_cost', float('nan')):.3g}, "
          f"end cost {doc.get('cost', float('nan')):.3g}", flush=True)
    return doc


def ladder_peers(a: argparse.Namespace, d: Path, truth: dict[str, float], out: Path) -> int:
    """Ours beside the peer's on the same FMU and records: per-parameter errors, FMU runs, wall times."""
    import os

    from benchmarks.results_io import table, write_results

    py = None if a.peer_reuse else peer_python(a)
    rows, err_rows, summary, loads = [], [], {}, []
    for rec in a.records.split(","):
        print(f"== {d.name}/{rec}: pris-cosim estimate", flush=True)
        ours = ladder_estimate(a, d, rec, truth, out)
        loads.append(os.getloadavg()[0])
        if ours is None:
            return 1
        print(f"== {d.name}/{rec}: peer", flush=True)
        peer = peer_estimate(a, py, d, rec, out)
        loads.append(os.getloadavg()[0])
        ratio_runs = ours["fmu_simulations"] / max(peer["runs"], 1)
        ratio_eq = ours["fmu_record_equivalents"] / max(peer["runs"], 1)
        met = ours["worst_percent"] <= 2.0 < peer["worst_percent"] and ratio_eq <= 0.1
        print(f"   runs: ours {ours['fmu_simulations']} window runs = {ours['fmu_record_equivalents']:.0f} "
              f"whole-record equivalents; peer {peer['runs']} whole-record runs; ratio {ratio_eq:.3f} "
              f"(window runs {ratio_runs:.2f})", flush=True)
        for k in LADDER_FREE:
            err_rows.append([rec, k, truth[k], ours["errors_percent"][k], peer["errors_percent"].get(k, float("nan"))])
        rows.append([rec, "pris-cosim", ours["worst_percent"], ours["fmu_simulations"],
                     round(ours["fmu_record_equivalents"], 1), round(ours["wall_s"], 1), str(ours["converged"])])
        rows.append([rec, f"{peer.get('peer', 'estim8')} (DE + L-BFGS-B)", peer["worst_percent"], peer["runs"],
                     peer["runs"], round(peer.get("wall_s", peer["process_wall_s"]), 1), peer["stopped"]])
        summary[rec] = {"ours": {k: ours[k] for k in ("worst_percent", "errors_percent", "fmu_simulations",
                                                      "fmu_record_equivalents", "wall_s", "converged")},
                        "peer": peer, "ratio_record_equivalents": ratio_eq, "ratio_window_runs": ratio_runs,
                        "target_met": bool(met)}
        print(f"   target (ours within 2 %, the peer not, at most a tenth of its runs in whole-record equivalents): "
              f"{'met' if summary[rec]['target_met'] else 'not met'}", flush=True)
    (out / "ladder-peers-summary.json").write_text(json.dumps(summary, indent=1))
    write_results(a.peer_results, tables=[
        table("Foreign FMU (three-section ladder, 2 MHz record, six free values, bounds 0.2x..5x): pris-cosim beside "
              "estim8", ["record", "estimator", "worst error (%)", "FMU runs", "whole-record equivalents", "wall (s)",
                         "converged / stopped"], rows),
        table("Per-parameter errors, pris-cosim beside estim8", ["record", "parameter", "truth", "pris-cosim (%)",
                                                                 "estim8 (%)"], err_rows),
        table("FMU runs, pris-cosim over estim8", ["record", "window runs ratio", "whole-record equivalents ratio",
                                                   "target met"],
              [[r, s["ratio_window_runs"], s["ratio_record_equivalents"], str(s["target_met"])]
               for r, s in summary.items()])],
        summary=f"pris-cosim estimate and estim8 (scipy DE + L-BFGS-B, one process, wall cap "
                f"{max(float(s['peer'].get('wall_cap_s', a.peer_wall)) for s in summary.values()):g} s) on the "
                f"same foreign FMU and record; 1-minute load average during the runs {min(loads):.1f}..{max(loads):.1f} "
                "on a shared 2-core machine")
    return 0


def ladder(a: argparse.Namespace, out: Path) -> int:
    """Estimate the foreign ladder FMU from its two records (see the module docstring)."""
    from benchmarks.results_io import table, write_results

    d = Path(a.ladder).resolve()
    truth = json.loads((d / "truth.json").read_text())["truth"]
    if a.peers:
        return ladder_peers(a, d, truth, out)
    rows, errs_rows, summary = [], [], {}
    for rec in a.records.split(","):
        truth, free = ladder_truth(d, rec)
        scores = ladder_replay(d, truth, d / rec)
        print(f"== {d.name}/{rec}: truth replay, zero-order hold {scores['zoh']:.3g}, linear {scores['linear']:.3g} "
              "of the output RMS", flush=True)
        res = ladder_estimate(a, d, rec, truth, out, free)
        if res is None:
            return 1
        worst = res["worst_percent"]
        rows.append([rec, scores["zoh"], scores["linear"], res["input_hold"].split(" ")[0], worst,
                     res["fmu_simulations"], round(res["fmu_record_equivalents"], 1), round(res["wall_s"], 1),
                     str(res["converged"]), ", ".join(res["non_identifiable"]) or "none"])
        errs_rows += [[rec, k, truth[k], res["estimate"][k], e,
                       100 * (res["uncertainty"] or (res.get("local_curvature") or {}).get("values", {})).get(k, float("nan"))]
                      for k, e in res["errors_percent"].items()]
        summary[rec] = {"worst_percent": worst, "errors_percent": res["errors_percent"],
                        "fmu_simulations": res["fmu_simulations"], "wall_s": res["wall_s"],
                        "converged": res["converged"], "truth_replay": scores, "input_hold": res["input_hold"]}
    (out / "ladder-summary.json").write_text(json.dumps(summary, indent=1))
    write_results("bench_estimate_fmu_ladder", tables=[
        table("Foreign FMU (pythonfmu three-section ladder, 2 MHz record): six free values, bounds 0.2x..5x",
              ["record", "truth replay, zoh", "truth replay, linear", "hold chosen", "worst error (%)", "FMU runs",
               "whole-record equivalents", "wall (s)", "converged", "non-identifiable"], rows),
        table("Per-parameter errors", ["record", "parameter", "truth", "estimate", "error (%)", "1-sigma (%)"],
              errs_rows)],
        summary="pris-cosim estimate with a foreign (pythonfmu) FMU in the loop: a three-section ladder, "
                "noise-free and 0.5 % noise records; wall times on a shared, loaded 2-core machine")
    return 0


FOUR_FREE = ("L1", "L2", "L3", "L4", "Cs", "Cg", "k12", "k23", "k34")


def four(a: argparse.Namespace, out: Path) -> int:
    """The four-section, nine-value case (module docstring)."""
    import subprocess

    sys.path.insert(0, str(REPO / "tests"))
    import foreign_fmus as ff

    name = "four_section_fmi3" if a.fmi3 else "four_section"
    m = ff.MODELS[name]
    t0 = time.perf_counter()
    fmu = ff.build(name, out / name)
    print(f"== four sections ({'FMI 3.0, pythonfmu3' if a.fmi3 else 'FMI 2.0, pythonfmu'}): built in "
          f"{time.perf_counter() - t0:.1f} s")
    summary = {}
    for noise in [float(x) for x in a.four_noise.split(",")]:
        t1 = time.perf_counter()
        rec = ff.record(name, fmu, out / f"{name}-{noise:g}.csv", fs=4e6, n=20440, hold=20, noise=noise)
        truth = m["truth"]
        cfg = {"fmu": str(fmu), "input": m["input"], "output": m["outputs"][0], "outputs": m["outputs"][1:],
               "parameters": {k: {"min": truth[k] / 3, "max": truth[k] * 3} for k in FOUR_FREE},
               "ties": m["ties"], "values": {k: v for k, v in truth.items() if k not in FOUR_FREE},
               "target": {"kind": "waveforms-csv", "path": str(rec), "values": truth}, "seed": 1}
        path = out / f"{name}-{noise:g}.json"
        path.write_text(json.dumps(cfg, indent=1))
        print(f"   record: 20,440 samples, noise {100 * noise:g} % ({time.perf_counter() - t1:.1f} s)", flush=True)
        cmd = [sys.executable, "-m", "pris_cosim", "estimate", "--config", str(path), "--json",
               "--out", str(out / f"{name}-{noise:g}-run"), "--workers", str(a.workers or 2)]
        import resource

        t2 = time.perf_counter()
        c0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        p = subprocess.run(cmd, cwd=REPO, stdout=subprocess.PIPE, text=True)
        wall = time.perf_counter() - t2
        c1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (c1.ru_utime - c0.ru_utime) + (c1.ru_stime - c0.ru_stime)  # the estimate and its reaped workers
        line = next((ln for ln in p.stdout.splitlines() if ln.startswith("{")), None)
        if line is None:
            print(f"   estimate failed (exit {p.returncode})")
            continue
        res = json.loads(line)
        worst = max(abs(e) for e in res["errors_percent"].values())
        print(f"   noise {100 * noise:g} %: worst error {worst:.3g} %, {res['fmu_simulations']} FMU runs "
              f"({res['fmu_record_equivalents']:.0f} whole-record equivalents, {res['failed_evaluations']} failed), "
              f"wall {wall:.0f} s (CPU {cpu:.0f} s; load average {os.getloadavg()[0]:.1f}), "
              f"converged {res['converged']}: {res['convergence_reason']}")
        for k, e in res["errors_percent"].items():
            print(f"     {k:>4} {res['estimate'][k]:12.5g}  {e:+10.4f} %")
        for f in res.get("failed_runs", []):
            print(f"     failed: {f}")
        summary[f"noise-{noise:g}"] = {"errors_percent": res["errors_percent"], "worst_percent": worst,
                                       "fmu_simulations": res["fmu_simulations"],
                                       "fmu_record_equivalents": res["fmu_record_equivalents"], "wall_s": wall,
                                       "cpu_s": cpu,
                                       "converged": res["converged"], "reason": res["convergence_reason"],
                                       "failed_runs": res.get("failed_runs", [])}
    (out / f"{name}-summary.json").write_text(json.dumps(summary, indent=1))
    return 0


def main(argv: list[str] | None = None) -> int:
    from estimation.cli import run_estimate

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cases", default="two,three")
    p.add_argument("--approach", default="time")
    p.add_argument("--design", type=int)
    p.add_argument("--restarts", type=int)
    p.add_argument("--simulations", type=int)
    p.add_argument("--workers", type=int)
    p.add_argument("--first-window", type=int, help="samples of the first continuation window")
    p.add_argument("--fs", type=float, default=1e6, help="sampling frequency of the records, Hz (default 1 MHz)")
    p.add_argument("--duration", type=float, help="record length, s (default: 50 ms two-section, 10 ms three-section)")
    p.add_argument("--design-score", choices=["window", "frequency"], help="what ranks the design points")
    p.add_argument("--probes", action="store_true", help="also compare the internal node voltages (v_mid; v_n2, v_n3)")
    p.add_argument("--ladder", metavar="DIR", help="estimate the foreign ladder FMU in DIR (see the docstring)")
    p.add_argument("--records", default="record.csv,record_noisy.csv", help="ladder records to estimate")
    p.add_argument("--four", action="store_true", help="the four-section, nine-value case (see the docstring)")
    p.add_argument("--fmi3", action="store_true", help="--four: the FMI 3.0 build (pythonfmu3)")
    p.add_argument("--four-noise", default="0", help="--four: noise levels of the records, e.g. 0,0.005")
    p.add_argument("--peers", action="store_true",
                   help="with --ladder: also run estim8 on the same FMU and records (throwaway environment)")
    p.add_argument("--peer-venv", metavar="PATH", help="the peer's virtual environment (default: a new temp dir)")
    p.add_argument("--peer-package", default="estim8", help="what pip installs there (default estim8)")
    p.add_argument("--peer-reuse", action="store_true",
                   help="reuse the peer's stored answers in --out (from an earlier --peers run) instead of running it")
    p.add_argument("--peer-wall", type=float, default=900.0, help="wall-time cap of each peer estimate, s")
    p.add_argument("--peer-maxiter", type=int, default=100, help="the peer's differential-evolution generations")
    p.add_argument("--peer-popsize", type=int, default=15, help="the peer's population factor (scipy's popsize)")
    p.add_argument("--peer-results", default="bench_estimate_fmu_peers",
                   help="name of the --peers result file in benchmarks/results (default bench_estimate_fmu_peers)")
    p.add_argument("--out", default="bench-estimate-fmu")
    p.add_argument("--json", action="store_true", help="also print one JSON object with everything")
    a = p.parse_args(argv)
    out = Path(a.out).resolve()  # configurations name their files by absolute paths
    out.mkdir(parents=True, exist_ok=True)
    if a.ladder:
        return ladder(a, out)
    if a.four:
        return four(a, out)
    fs = a.fs
    summary = {}
    for name in a.cases.split(","):
        case = CASES[name]
        t0 = time.perf_counter()
        duration = a.duration or case["duration"]
        w = record(REPO / case["fmu"], fs, duration)
        rec = out / f"{name}.csv"
        probes = [k for k in w if k.startswith("v_") and k not in ("v_in", "v_bprbs")] if a.probes else []
        cols = ["v_bprbs", "v_in", "i_in"] + probes
        np.savetxt(rec, np.column_stack([w["time_s"]] + [w[c] for c in cols]), delimiter=",",
                   header=",".join(["time_s"] + cols), comments="", fmt="%.17g")
        scores = truth_scores(case, w, fs)
        print(f"== {case['model']}: {Path(case['fmu']).name}, {duration * 1e3:g} ms at {fs / 1e6:g} MHz "
              f"(record {time.perf_counter() - t0:.1f} s)")
        for k, v in scores.items():
            print(f"   truth score, {k:<22} {v:.3g} of the signal RMS")
        budget = {k: v for k, v in (("design", a.design), ("restarts", a.restarts), ("simulations", a.simulations))
                  if v is not None}
        cfg = {"fmu": str(REPO / case["fmu"]), "output": "v_in", "outputs": probes, "approach": a.approach, "seed": 1,
               "parameters": bounds(case["truth"]), "ties": case["ties"], "budget": budget,
               "target": {"kind": "waveforms-csv", "path": str(rec), "values": case["truth"]}}
        if a.design_score:
            cfg["design_score"] = a.design_score
        if a.first_window:
            cfg["first_window"] = a.first_window
        tag = f"{name}-{a.approach}{'-probes' if probes else ''}-{fs / 1e6:g}MHz-{duration * 1e3:g}ms"
        res = run_estimate(cfg, progress=True, out=str(out / tag), workers=a.workers)
        worst = max(abs(e) for e in res["errors_percent"].values())
        print(f"   FMU estimate ({a.approach}, compared: {', '.join(['v_in'] + probes)}): worst error {worst:.3g} %, {res['fmu_simulations']} FMU runs "
              f"({res['failed_evaluations']} failed; {res['fmu_record_equivalents']:.0f} whole-record equivalents), {res['wall_s']:.1f} s, cost {res['cost']:.3g}, "
              f"converged {res['converged']}" + ("" if res["converged"] else f" ({res['convergence_reason']})"))
        for k, e in res["errors_percent"].items():
            sd = (res["uncertainty"] or (res.get("local_curvature") or {}).get("values", {})).get(k, float("nan"))
            print(f"     {k:>4} {res['estimate'][k]:12.5g}  {e:+10.4f} %  (1-sigma {100 * sd:.2g} %)")
        summary[tag] = {"truth_scores": scores, "errors_percent": res["errors_percent"], "worst_percent": worst,
                         "fmu_simulations": res["fmu_simulations"],
                        "fmu_record_equivalents": res["fmu_record_equivalents"], "failed_evaluations": res["failed_evaluations"],
                         "wall_s": res["wall_s"], "converged": res["converged"], "cost": res["cost"]}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    if a.json:
        print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
