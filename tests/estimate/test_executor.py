"""Study runner: serial / process pool / real Dask cluster, incremental atomic storage, resume."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest

from estimation.search import executor as ex
from estimation.search import optimisers as opt
from estimation.search.executor import ResultsStore, Task, TaskError, run_tasks

# --------------------------------------------------------------------------- #
# Task functions: top level, so workers can import them by name
# --------------------------------------------------------------------------- #


def rastrigin(U):
    X = 10.24 * U - 6.42
    return 10.0 * X.shape[1] + np.sum(X**2 - 10.0 * np.cos(2.0 * np.pi * X), axis=1)


def optimise(method: str, seed: int) -> dict:
    """A small estimation run; wall time dropped so the result is deterministic."""
    result = opt.minimize(rastrigin, 3, method, seed=seed, budget=opt.Budget(max_evals=3000))
    record = result.to_dict()
    del record["wall_s"]
    return record


def counted(x: int, marker_dir: str, delay: float = 0.0) -> dict:
    """Square ``x`` after ``delay`` seconds, leaving one marker file per execution.

    A file ``FAIL-<x>`` in ``marker_dir`` makes it raise (a failing run); a file
    ``STOP-<x>`` makes it raise KeyboardInterrupt (the user pressing Ctrl-C).
    """
    directory = Path(marker_dir)
    (directory / f"ran-{x}-{uuid.uuid4().hex}").touch()
    if (directory / f"FAIL-{x}").exists():
        raise RuntimeError(f"simulated failure in task {x}")
    if (directory / f"STOP-{x}").exists():
        raise KeyboardInterrupt
    time.sleep(delay)
    return {"x": x, "y": x * x, "pid": os.getpid(), "vector": np.arange(3) * x}


def unstorable() -> object:
    return object()


def executions(marker_dir: Path) -> dict[int, int]:
    counts: dict[int, int] = {}
    for path in marker_dir.glob("ran-*"):
        x = int(path.name.split("-")[1])
        counts[x] = counts.get(x, 0) + 1
    return counts


def counted_tasks(marker_dir: Path, count: int, delay: float = 0.0) -> list[Task]:
    extra = {"delay": delay} if delay else {}
    return [Task(f"t{x}", counted, {"x": x, "marker_dir": str(marker_dir), **extra}, label=f"case {x}")
            for x in range(count)]


def optimise_tasks() -> list[Task]:
    return [
        Task(f"{method}-{seed}", optimise, {"method": method, "seed": seed}, label=f"seed {seed} {method}")
        for method in ("pso", "ga", "pso+local")
        for seed in (1, 2)
    ]


def assert_complete_files_only(store_dir: Path) -> None:
    """No temporary or partial files; every stored run parses."""
    for path in store_dir.rglob("*"):
        assert not path.name.startswith(".") and not path.name.endswith(".tmp"), path
    for path in (store_dir / "runs").glob("*.json"):
        assert json.loads(path.read_text())["id"] == path.stem


@pytest.fixture
def markers(tmp_path: Path) -> Path:
    directory = tmp_path / "markers"
    directory.mkdir()
    return directory


# --------------------------------------------------------------------------- #
# Backends
# --------------------------------------------------------------------------- #


@pytest.fixture(scope="module")
def serial_results(tmp_path_factory) -> list:
    return run_tasks(optimise_tasks(), executor="serial", store=tmp_path_factory.mktemp("serial"), progress=False)


def test_serial_results_are_the_optimiser_results(serial_results):
    direct = [optimise(t.kwargs["method"], t.kwargs["seed"]) for t in optimise_tasks()]
    assert serial_results == json.loads(json.dumps(direct))


def test_process_pool_matches_serial(serial_results, tmp_path):
    store = ResultsStore(tmp_path / "pool")
    results = run_tasks(optimise_tasks(), executor="processes", workers=2, store=store, progress=False)
    assert results == serial_results
    assert {r["pid"] for r in store.records()} - {os.getpid()}  # really ran in other processes
    assert all(r["backend"].startswith("processes") for r in store.records())
    assert_complete_files_only(store.directory)


def test_real_dask_cluster(serial_results, markers, tmp_path):
    from distributed import LocalCluster

    counting = counted_tasks(markers, 6)
    (markers / "FAIL-4").touch()
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        address = cluster.scheduler_address
        store = ResultsStore(tmp_path / "dask")
        results = run_tasks(optimise_tasks(), executor=address, store=store, progress=False)
        # a failing run on the cluster, then a resume that repeats only that run
        with pytest.raises(TaskError, match="t4"):
            run_tasks(counting, executor=address, store=tmp_path / "resume", progress=False, on_error="continue")
        (markers / "FAIL-4").unlink()
        resumed = run_tasks(counting, executor=address, store=tmp_path / "resume", progress=False)
    assert results == serial_results
    records = store.records()
    assert all(r["backend"] == f"dask {address}" for r in records)
    assert os.getpid() not in {r["pid"] for r in records}
    assert_complete_files_only(store.directory)
    assert [r["y"] for r in resumed] == [x * x for x in range(6)]
    assert executions(markers) == {0: 1, 1: 1, 2: 1, 3: 1, 4: 2, 5: 1}


def test_user_supplied_executor_is_left_open(tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=2) as pool:
        results = run_tasks(counted_tasks(tmp_path, 3), executor=pool, progress=False)
        assert pool.submit(int, "7").result() == 7  # still usable
    assert [r["y"] for r in results] == [0, 1, 4]
    assert results[2]["vector"] == [0, 2, 4]  # numpy converted as stored


# --------------------------------------------------------------------------- #
# Storage, interruption and resume
# --------------------------------------------------------------------------- #


def test_raise_starts_nothing_new_but_keeps_runs_in_flight(markers, tmp_path):
    from concurrent.futures import ThreadPoolExecutor

    (markers / "FAIL-1").touch()
    tasks = [Task(f"t{x}", counted, {"x": x, "marker_dir": str(markers), "delay": 0.3}) for x in range(6)]
    with ThreadPoolExecutor(max_workers=2) as pool, pytest.raises(TaskError):
        run_tasks(tasks, executor=pool, store=tmp_path / "s", progress=False)
    # t1 fails at once while t0 is still running: nothing else starts, t0 finishes and is kept
    assert executions(markers) == {0: 1, 1: 1}
    assert ResultsStore(tmp_path / "s").ids() == ["t0"]


def test_resume_after_a_failing_task(markers, tmp_path):
    store_dir = tmp_path / "store"
    tasks = counted_tasks(markers, 8)
    (markers / "FAIL-5").touch()
    with pytest.raises(TaskError, match="t5") as caught:
        run_tasks(tasks, executor="serial", store=store_dir, progress=False)
    assert list(caught.value.failures) == ["t5"]
    assert "simulated failure" in caught.value.failures["t5"]
    assert caught.value.results[:5] == [ResultsStore(store_dir).load(f"t{x}")["result"] for x in range(5)]
    assert ResultsStore(store_dir).ids() == [f"t{x}" for x in range(5)]  # stopped at the failure
    assert "simulated failure" in (store_dir / "errors" / "t5.txt").read_text()

    (markers / "FAIL-5").unlink()
    results = run_tasks(tasks, executor="serial", store=store_dir, progress=False)
    assert [r["y"] for r in results] == [x * x for x in range(8)]
    assert executions(markers) == {0: 1, 1: 1, 2: 1, 3: 1, 4: 1, 5: 2, 6: 1, 7: 1}
    assert not (store_dir / "errors" / "t5.txt").exists()
    assert_complete_files_only(store_dir)


def test_resume_after_interrupt(markers, tmp_path):
    store_dir = tmp_path / "store"
    tasks = counted_tasks(markers, 6)
    (markers / "STOP-3").touch()
    with pytest.raises(KeyboardInterrupt):
        run_tasks(tasks, executor="serial", store=store_dir, progress=False)
    assert ResultsStore(store_dir).ids() == ["t0", "t1", "t2"]
    (markers / "STOP-3").unlink()
    results = run_tasks(tasks, executor="serial", store=store_dir, progress=False)
    assert [r["x"] for r in results] == list(range(6))
    assert executions(markers) == {0: 1, 1: 1, 2: 1, 3: 2, 4: 1, 5: 1}


def test_process_pool_continue_on_error_then_resume(markers, tmp_path):
    store_dir = tmp_path / "store"
    tasks = counted_tasks(markers, 6)
    (markers / "FAIL-2").touch()
    with pytest.raises(TaskError) as caught:
        run_tasks(tasks, executor="processes", workers=2, store=store_dir, progress=False, on_error="continue")
    assert list(caught.value.failures) == ["t2"]
    assert caught.value.results[2] is None and caught.value.results[5]["y"] == 25
    assert ResultsStore(store_dir).ids() == ["t0", "t1", "t3", "t4", "t5"]
    (markers / "FAIL-2").unlink()
    results = run_tasks(tasks, executor="processes", workers=2, store=store_dir, progress=False)
    assert [r["y"] for r in results] == [x * x for x in range(6)]
    assert executions(markers) == {0: 1, 1: 1, 2: 2, 3: 1, 4: 1, 5: 1}
    assert_complete_files_only(store_dir)


def test_all_stored_runs_nothing(markers, tmp_path, capsys):
    tasks = counted_tasks(markers, 3)
    first = run_tasks(tasks, executor="serial", store=tmp_path / "s", progress=False)
    again = run_tasks(tasks, executor="processes", store=tmp_path / "s")  # no pool is even started
    assert first == again and executions(markers) == {0: 1, 1: 1, 2: 1}
    assert "all already stored" in capsys.readouterr().err


def test_failed_write_leaves_old_file_and_no_partial_file(tmp_path, monkeypatch):
    store = ResultsStore(tmp_path)
    store.save({"id": "a", "result": 1})
    before = (tmp_path / "runs" / "a.json").read_text()

    def broken_replace(src, dst):
        raise OSError("disk full (simulated)")

    monkeypatch.setattr(ex.os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        store.save({"id": "a", "result": 2})
    with pytest.raises(OSError, match="disk full"):
        store.save({"id": "b", "result": 3})
    monkeypatch.undo()
    assert (tmp_path / "runs" / "a.json").read_text() == before
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == ["a.json"]
    assert_complete_files_only(tmp_path)
    assert ResultsStore(tmp_path).load("a")["result"] == 1


def test_interrupted_write_leftover_is_ignored(tmp_path):
    store = ResultsStore(tmp_path)
    store.save({"id": "a", "result": 1})
    (tmp_path / "runs" / ".b.json.x1y2.tmp").write_text('{"id": "b", "res')  # a write cut short by a kill
    assert ResultsStore(tmp_path).ids() == ["a"]


def test_csv_is_regenerated_from_runs(markers, tmp_path):
    run_tasks(counted_tasks(markers, 4), executor="serial", store=tmp_path / "s", progress=False)
    with open(tmp_path / "s" / "results.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [row["id"] for row in rows] == ["t0", "t1", "t2", "t3"]
    assert [int(row["result.y"]) for row in rows] == [0, 1, 4, 9]
    assert [row["kwargs.x"] for row in rows] == ["0", "1", "2", "3"]
    assert json.loads(rows[3]["result.vector"]) == [0, 3, 6]
    assert rows[1]["label"] == "case 1" and rows[1]["fn"] == "estimate.test_executor:counted"


def test_stored_run_with_other_arguments_is_refused(markers, tmp_path):
    run_tasks(counted_tasks(markers, 2), executor="serial", store=tmp_path / "s", progress=False)
    changed = [Task("t1", counted, {"x": 7, "marker_dir": str(markers)})]
    with pytest.raises(ValueError, match="stored run 't1'.*different fn or kwargs"):
        run_tasks(changed, executor="serial", store=tmp_path / "s", progress=False)


def test_corrupt_run_file_is_named(tmp_path):
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / "a.json").write_text("{not json")
    with pytest.raises(ValueError, match="a.json"):
        ResultsStore(tmp_path)


# --------------------------------------------------------------------------- #
# Progress and validation
# --------------------------------------------------------------------------- #


def test_progress_lines(markers, tmp_path, capsys):
    tasks = counted_tasks(markers, 4)
    run_tasks(tasks[:2], executor="serial", store=tmp_path / "s")
    run_tasks(tasks, executor="serial", store=tmp_path / "s")
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("2 task(s): 0 already stored, 2 to run on serial")
    assert err[1].startswith("[1/2] case 0 done in ") and err[1].endswith(" s")
    assert err[3].startswith("4 task(s): 2 already stored, 2 to run on serial")
    assert err[4].startswith("[3/4] case 2 done in ") and err[5].startswith("[4/4] case 3 done in ")


def test_unstorable_result_is_a_task_failure(tmp_path):
    with pytest.raises(TaskError, match="cannot store a object as JSON"):
        run_tasks([Task("u", unstorable)], executor="serial", store=tmp_path, progress=False)
    assert ResultsStore(tmp_path).ids() == []


def _nested():
    def inner():
        return 1

    return inner


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: Task("a", lambda: 1), "top-level function"),
        (lambda: Task("a", _nested()), "top-level function"),
        (lambda: Task("a/b", unstorable), "task id"),
        (lambda: Task(".hidden", unstorable), "task id"),
        (lambda: Task("a", counted, {"x": object()}), "kwargs cannot be stored"),
        (lambda: run_tasks([Task("a", unstorable), Task("a", unstorable)]), "duplicate task id 'a'"),
        (lambda: run_tasks([Task("a", unstorable)], executor="gpu"), "executor must be"),
        (lambda: run_tasks([Task("a", unstorable)], executor="processes", workers=0), "workers"),
        (lambda: run_tasks([Task("a", unstorable)], on_error="ignore"), "on_error"),
        (lambda: run_tasks(["a"]), "Task objects"),
    ],
)
def test_bad_arguments_name_the_problem(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_without_store_results_are_still_json_normalised(markers):
    results = run_tasks(counted_tasks(markers, 2), executor="serial", progress=False)
    assert results[1]["vector"] == [0, 1, 2]


# --------------------------------------------------------------------------- #
# Checksums, claims and the interruption message
# --------------------------------------------------------------------------- #


def test_tampered_or_damaged_run_is_refused_naming_the_file(markers, tmp_path):
    run_tasks(counted_tasks(markers, 2), executor="serial", store=tmp_path / "s", progress=False)
    path = tmp_path / "s" / "runs" / "t1.json"
    text = path.read_text()
    assert '"sha256"' in text
    path.write_text(text.replace('"y": 1', '"y": 2'))  # a changed value, still valid JSON
    with pytest.raises(ValueError, match=r"stored run .*t1\.json fails its checksum") as caught:
        ResultsStore(tmp_path / "s")
    assert "\n" not in str(caught.value)
    flipped = bytearray(text.encode())
    flipped[text.index('"x": 1') + 5] ^= 0x02  # one bit: 1 -> 3
    path.write_bytes(bytes(flipped))
    with pytest.raises(ValueError, match="fails its checksum"):
        ResultsStore(tmp_path / "s")
    path.write_text(text.replace('"sha256"', '"other"'))
    with pytest.raises(ValueError, match="has no checksum"):
        ResultsStore(tmp_path / "s")


def test_a_claimed_task_is_busy_for_another_store_until_released(tmp_path):
    a, b = ResultsStore(tmp_path), ResultsStore(tmp_path)
    assert a.claim("x") == "claimed"
    assert b.claim("x") == "busy"
    a.save({"id": "x", "result": 5})
    a.release("x")
    assert b.claim("x")["result"] == 5  # stored meanwhile: taken, not run again
    assert b.claim("y") == "claimed"
    b.release_all()
    assert a.claim("y") == "claimed"


def test_interrupt_message_counts_stored_runs(markers, tmp_path):
    (markers / "STOP-2").touch()
    with pytest.raises(ex.Interrupted) as caught:
        run_tasks(counted_tasks(markers, 4), executor="serial", store=tmp_path / "s", progress=False)
    assert str(caught.value) == (f"interrupted: 2 of 4 runs stored in {tmp_path / 's'}; "
                                 f"run the same command again to resume")


def test_abort_ends_the_pool_s_management_thread_before_returning(markers):
    """After an abort (Ctrl-C) nothing of the pool is left running to race the interpreter's exit.

    The pool's management thread closes its wake-up pipe once it sees the
    workers gone, while the exit hook of ``concurrent.futures`` writes to that
    pipe: left running, the two raced and printed "OSError: [Errno 9] Bad file
    descriptor" after the one-line message, now and then on a loaded machine.
    """
    pool = ex._process_pool(1)
    backend = ex._FuturesBackend(pool, owned=True, name="processes", workers=1)
    backend.submit(counted_tasks(markers, 1, delay=30)[0])
    t_end = time.monotonic() + 60
    while not list(markers.glob("ran-*")) and time.monotonic() < t_end:  # the task has started in the worker
        time.sleep(0.05)
    t0 = time.monotonic()
    backend.abort()
    assert time.monotonic() - t0 < 10
    manager = getattr(pool, "_executor_manager_thread", None)
    assert manager is None or not manager.is_alive()
    wakeup = getattr(pool, "_executor_manager_thread_wakeup", None)
    assert wakeup is None or getattr(wakeup, "_closed", True)


# --------------------------------------------------------------------------- #
# A real study (two-section, quick, cases 4 and 1): killed, resumed, run twice at once, reproducible
# --------------------------------------------------------------------------- #

STUDY = [sys.executable, "-m", "pris_cosim", "study", "two-section", "--quick", "--cases", "4,1", "--json"]
_VOLATILE = ("wall_s", "per_eval_s", "setup_s", "speedup", "runtime", "evals_per_s", "time_s", "out", "table")


def _start(out: Path, workers: int) -> subprocess.Popen:
    return subprocess.Popen(STUDY + ["--workers", str(workers), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def _finish(proc: subprocess.Popen, timeout: float = 120) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err


def _stable(obj):
    """The study's answer without wall times and paths."""
    if isinstance(obj, dict):
        return {k: _stable(v) for k, v in obj.items() if not any(w in k for w in _VOLATILE)}
    if isinstance(obj, list):
        return [_stable(v) for v in obj]
    return obj


def _assert_same(a, b, path="rows"):
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _assert_same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-300), path
    else:
        assert a == b, path


def _wait_for_runs(out: Path, count: int, proc: subprocess.Popen, timeout: float = 90) -> None:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if len(list((out / "runs").glob("*.json"))) >= count:
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError(f"no stored run in {out} after {timeout} s")


def _group_gone(pgid: int, timeout: float) -> bool:
    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


@pytest.fixture(scope="module")
def killed_then_resumed(tmp_path_factory):
    """The study on two workers, its main process killed by SIGKILL after the first stored run, then resumed.

    Returns what the test of the kill checks and the resumed answer (the reference of the other tests).
    """
    out = tmp_path_factory.mktemp("killed") / "out"
    proc = _start(out, 2)
    _wait_for_runs(out, 1, proc)
    t0 = time.monotonic()
    proc.kill()  # the main process only, as the OOM killer or a batch scheduler does
    proc.communicate(timeout=5)  # EOF on stdout and stderr: nothing else holds the pipes
    pipes_s = time.monotonic() - t0
    gone = _group_gone(proc.pid, 5 - pipes_s)
    stored = ResultsStore(out).ids()  # complete files that pass their checksums
    code, stdout, stderr = _finish(_start(out, 2))
    assert code == 0, stderr
    return {"pipes_s": pipes_s, "gone": gone, "stored": stored, "resume_err": stderr,
            "rows": _stable(json.loads(stdout)["rows"])}


@pytest.mark.slow
def test_sigkill_of_the_main_process_ends_its_workers_and_frees_the_pipes(killed_then_resumed):
    assert killed_then_resumed["pipes_s"] < 5 and killed_then_resumed["gone"], "workers outlived the main process"
    assert len(killed_then_resumed["stored"]) >= 1
    assert f"{len(killed_then_resumed['stored'])} already stored" in killed_then_resumed["resume_err"]


@pytest.mark.slow
def test_ctrl_c_to_the_group_stops_with_one_line_and_resume_gives_the_same_answer(tmp_path, killed_then_resumed):
    out = tmp_path / "out"
    proc = _start(out, 1)
    _wait_for_runs(out, 1, proc)
    os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C on a terminal: main process, fork server and workers
    code, stdout, stderr = _finish(proc, timeout=60)  # generous: a loaded machine stops the group slowly
    if code == 0:  # the second run ended before the signal arrived (a loaded machine): nothing to interrupt
        pytest.skip("both runs finished before the interrupt arrived")
    assert code == 130 and stdout == ""
    last = stderr.strip().splitlines()[-1]
    assert last == f"pris-cosim study: interrupted: 1 of 2 runs stored in {out}; run the same command again to resume"
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr
    assert _group_gone(proc.pid, 20)
    stored = (out / "runs" / "two-section-case4-quick-seed1.json").read_text()
    code, stdout, stderr = _finish(_start(out, 1))
    assert code == 0, stderr
    assert "1 already stored, 1 to run" in stderr
    assert (out / "runs" / "two-section-case4-quick-seed1.json").read_text() == stored  # not run again
    # the same numbers on one worker as on two, resumed at different points
    _assert_same(_stable(json.loads(stdout)["rows"]), killed_then_resumed["rows"])


_SHARE = """
import json, sys
from estimation.search.executor import run_tasks
from estimate.test_executor import counted_tasks
from pathlib import Path
results = run_tasks(counted_tasks(Path(sys.argv[1]), 6, delay=0.3), executor="serial", store=sys.argv[2])
print(json.dumps(results))
"""


@pytest.mark.slow
def test_two_runs_on_one_directory_share_the_tasks(markers, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[1]), *sys.path])}
    procs = [subprocess.Popen([sys.executable, "-c", _SHARE, str(markers), str(tmp_path / "s")], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outputs = [p.communicate(timeout=60) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outputs
    first, second = (json.loads(out) for out, _ in outputs)
    assert first == second and [r["y"] for r in first] == [x * x for x in range(6)]
    assert executions(markers) == {x: 1 for x in range(6)}  # every task computed once in all
    errs = outputs[0][1] + outputs[1][1]
    assert errs.count("done in") == 6 and errs.count("stored by another run") == 6, errs
