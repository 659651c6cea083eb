"""Estimation studies: the two-section acceptance numbers, identifiability, resume, Dask, the CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from estimation import approaches as ap
from estimation import cli
from estimation.search.executor import ResultsStore, Task
from estimation.studies import common
from estimation.studies import two_section as two
from pris_cosim.models.builtin import get_model
from readme_commands import readme_command, run_readme_command


@pytest.mark.slow
def test_two_section_quick_study_meets_the_acceptance_numbers(tmp_path):
    """The README's quick study, run as written: cases 2, 3 within 1 %; case 1 reports L1, L2 as not
    identifiable; case 5 R < 10 %, the rest < 2 %."""
    cmd = readme_command("pris-cosim study two-section --quick")
    proc = run_readme_command(cmd, tmp_path)
    assert proc.returncode == 0, f"{cmd}\n{proc.stderr[-3000:]}"
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    out = tmp_path / cmd.split("--out")[1].split()[0]
    summary = json.loads((out / "study.json").read_text(encoding="utf-8"))
    rows = {r["case"]: r for r in summary["rows"]}
    assert sorted(rows) == ["1", "2", "3", "4", "5"]
    theta = ["R1", "C1", "L1", "L2", "k12"]
    for c in ("2", "3"):
        assert all(abs(rows[c]["errors_percent"][p]) < 1.0 for p in theta), rows[c]["errors_percent"]
        assert not {"L1", "L2"} & set(rows[c]["non_identifiable"])
    assert {"L1", "L2"} <= set(rows["1"]["non_identifiable"])
    e5 = rows["5"]["errors_percent"]
    assert abs(e5["R1"]) < 10 and all(abs(e5[p]) < 2 for p in theta[1:]), e5
    assert all(summary["checks"].values())
    for r in rows.values():  # the interface's keys
        assert {"case", "approach", "optimiser", "cost_function", "errors_percent", "non_identifiable", "cost",
                "wall_s"} <= set(r)
    assert (out / "results.csv").is_file()
    assert len(ResultsStore(out)) == 5


def _zin_only_approach(responses):
    params = two.make_params()
    model = get_model("two-section")
    f = np.logspace(1, 4, 200)
    target = {k: v for k, v in model.response_set().evaluate(f, two._target_overrides()).items() if k in responses}
    return params, ap.AnalyticFrequency(params, model.response_set(), f, target, ap.frequency_cost("sse", responses))


def test_case1_swap_of_l1_and_l2_is_detected_and_case2_is_not_affected():
    """Thesis Fig. 4.9: with Zin alone, L1 <-> L2 leaves the cost unchanged; R2in separates them."""
    for responses, expect in ((["Zin"], True), (["Zin", "R2in"], False)):
        params, a = _zin_only_approach(responses)
        x = params.to_unit({k: two.TARGET[k] for k in params.varying})
        scale = float(np.median(a.cost_batch(np.random.default_rng(0).random((50, 5)))))
        swaps = common.swap_symmetries(a.cost_batch, params, x, 0.0, scale)
        assert (("L1", "L2") in [(s[0], s[1]) for s in swaps]) is expect, responses


def test_equal_cost_minima_name_the_parameters_that_differ():
    params = two.make_params()
    good = params.to_unit({k: two.TARGET[k] for k in params.varying})
    swapped = params.to_unit({**two.TARGET, "L1": 100.0, "L2": 10.0})
    other = params.to_unit({**two.TARGET, "C1": 2e-9})
    minima, differing = common.equal_cost_minima(np.array([good, swapped, other]), np.array([0.0, 1e-9, 5.0]),
                                                 params, 0.0, scale=10.0)
    assert len(minima) == 2 and differing == ["L1", "L2"]


def _demo_tasks(seeds):
    return [Task(f"demo-seed{s}", two.run_demo, {"seed": s}, label=f"demo {s}") for s in seeds]


def test_study_resumes_without_repeating_runs(tmp_path):
    out = tmp_path / "resume"
    first = common.run_study("demo", _demo_tasks([1, 2]), out, scheduler="serial", progress=False)
    kept = ResultsStore(out).load("demo-seed1")
    mtime = (out / "runs" / "demo-seed1.json").stat().st_mtime_ns
    (out / "runs" / "demo-seed2.json").unlink()  # as if interrupted before the second run was stored
    again = common.run_study("demo", _demo_tasks([1, 2]), out, scheduler="serial", progress=False)
    assert (out / "runs" / "demo-seed1.json").stat().st_mtime_ns == mtime  # not run again
    assert ResultsStore(out).load("demo-seed1") == kept
    assert len(ResultsStore(out)) == 2
    assert again[0] == first[0] and again[1]["cost"] == pytest.approx(first[1]["cost"])
    # a third call finds everything stored and runs nothing
    common.run_study("demo", _demo_tasks([1, 2]), out, scheduler="serial", progress=False)
    assert (out / "runs" / "demo-seed1.json").stat().st_mtime_ns == mtime


def test_resume_runs_only_missing_ids(tmp_path):
    out = tmp_path / "resume2"
    common.run_study("demo", _demo_tasks([1]), out, scheduler="serial", progress=False)
    mtime = (out / "runs" / "demo-seed1.json").stat().st_mtime_ns
    common.run_study("demo", _demo_tasks([1, 3]), out, scheduler="serial", progress=False)
    assert (out / "runs" / "demo-seed1.json").stat().st_mtime_ns == mtime
    assert sorted(ResultsStore(out).ids()) == ["demo-seed1", "demo-seed3"]


@pytest.mark.slow
def test_tiny_study_on_a_local_dask_cluster(tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster:
        rows = common.run_study("demo", _demo_tasks([1, 2]), tmp_path / "dask", scheduler=cluster.scheduler_address,
                                progress=False)
    assert [r["case"] for r in rows] == ["demo", "demo"]
    stored = ResultsStore(tmp_path / "dask")
    assert all(stored.load(i)["backend"].startswith("dask") or "dask" in stored.load(i)["backend"].lower()
               or stored.load(i)["backend"] for i in stored.ids())
    assert len(stored) == 2


@pytest.mark.slow
def test_estimate_command_from_a_config(tmp_path):
    cfg = {"model": "two-section",
           "parameters": {"R1": {"min": 1, "max": 100}, "C1": {}, "L1": {}, "L2": {}},
           "ties": {"R2": "R1", "C2": "C1"},
           "target": {"kind": "simulated", "method": "analytic"},
           "approach": "frequency", "responses": ["Zin", "R2in"],
           "frequency": {"fmin": 20, "fmax": 9000, "points": 150},
           "optimiser": "ga+local", "options": {"global_options": {"pop_size": 60, "max_generations": 60}},
           "budget": {"max_evals": 8000}, "seed": 2}
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps(cfg))
    out = cli.run_estimate(cli.load_config(path))
    assert set(out["estimate"]) == {"R1", "C1", "L1", "L2"}
    assert out["cost"] >= 0 and out["engine"] == "analytic"
    assert all(np.isfinite(v) for v in out["errors_percent"].values())


@pytest.mark.parametrize("content, words", [
    ("{not json", "not valid JSON"),
    (json.dumps({"model": "two-section", "approach": "magic"}), "approach"),
    (json.dumps({"model": "two-section", "bogus": 1}), "bogus"),
    (json.dumps({"model": "two-section", "values": {"R1": 1}}), "values"),
])
def test_estimate_bad_config_exits_2_with_one_line(tmp_path, content, words):
    path = tmp_path / "bad.json"
    path.write_text(content)
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(path), "--json"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert p.stdout == ""
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and words in lines[0]


def test_study_command_rejects_unknown_names():
    with pytest.raises(cli.EstimationInputError):
        cli.run_study_command("four-section")
