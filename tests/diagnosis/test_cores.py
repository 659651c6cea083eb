"""The helper process of a diagnosis (:mod:`estimation.diagnosis.cores`): same results, snapshots, safe start."""

from __future__ import annotations

import functools
import json
import multiprocessing
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from estimation.diagnosis import cores
from estimation.diagnosis.fit import DiagnosisError

ROOT = Path(__file__).resolve().parents[2]
needs_helper = pytest.mark.skipif(not cores.helper_wanted(), reason="no second core or no fork server here")


@needs_helper
def test_shared_map_keeps_the_order_and_uses_the_helper():
    items = [(i, i + 1) for i in range(9)]
    batch = cores.SharedBatch(sum, items)
    assert batch.shared
    assert batch.result() == [a + b for a, b in items]
    assert cores.shared_map(abs, [-3, 2, -1]) == [3, 2, 1]


@needs_helper
def test_the_helper_sees_the_items_as_they_were_when_handed_over():
    items = [np.arange(3.0) for _ in range(4)]
    batch = cores.SharedBatch(np.sum, items)
    helper = cores._get_helper()
    deadline = time.monotonic() + 60
    while helper.bounds[1] == len(items) and time.monotonic() < deadline:  # the helper has taken the last
        time.sleep(0.01)
    for a in items:  # changed after the hand-over: the helper's items are snapshots
        a += 10.0
    out = batch.result()
    assert out[-1] == 3.0  # the helper's first, on the values handed over (the others: on either)
    assert all(v in (3.0, 33.0) for v in out)


@needs_helper
def test_a_cancelled_batch_leaves_the_helper_free():
    abandoned = cores.SharedBatch(time.sleep, [0.2] * 6)
    assert abandoned.shared
    abandoned.cancel()
    batch = cores.SharedBatch(abs, [-1, -2, -3, -4])
    assert batch.shared  # the helper takes the next batch once it has finished the item it was running
    assert batch.result() == [1, 2, 3, 4]


@needs_helper
def test_a_batch_within_an_item_runs_where_the_item_runs():
    nested = functools.partial(cores.shared_map, abs)
    assert cores.shared_map(nested, [[-1, -2], [-3, -4], [-5], [-6, -7, -8]]) == [[1, 2], [3, 4], [5], [6, 7, 8]]
    assert cores.shared_map(abs, [-1, -2, -3]) == [1, 2, 3]  # and the helper is free again


@needs_helper
def test_a_batch_finishes_here_when_the_helper_dies():
    batch = cores.SharedBatch(time.sleep, [0.2] * 8)
    assert batch.shared
    cores._helper.proc.kill()
    try:
        assert batch.result() == [None] * 8  # every item run, here
        assert cores._broken and not cores.helper_wanted()  # given up for the rest of the process
    finally:
        cores._broken = False  # (the other tests: a new helper)
    assert cores.shared_map(abs, [-1, -2, -3]) == [1, 2, 3] and cores._helper.proc.is_alive()


def test_switched_off_by_the_environment(monkeypatch):
    monkeypatch.setenv(cores.JOBS_VARIABLE, "1")
    assert not cores.helper_wanted()
    batch = cores.SharedBatch(abs, [-1, -2, -3])
    assert not batch.shared and batch.result() == [1, 2, 3]


@pytest.mark.parametrize("value", ["abc", "0", "-2", "1.5"])
def test_a_bad_setting_is_refused_with_its_name(monkeypatch, value):
    monkeypatch.setenv(cores.JOBS_VARIABLE, value)
    with pytest.raises(DiagnosisError, match=cores.JOBS_VARIABLE):
        cores.helper_wanted()


def _wanted_in_daemon(queue) -> None:
    queue.put(cores.helper_wanted())


def test_no_helper_in_a_daemonic_process():
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_wanted_in_daemon, args=(queue,), daemon=True)
    proc.start()
    wanted = queue.get(timeout=60)
    proc.join(timeout=60)
    assert wanted is False


@needs_helper
def test_a_script_without_a_main_guard_runs_once(tmp_path):
    marker = tmp_path / "runs.txt"
    script = tmp_path / "unguarded.py"
    script.write_text(textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        with open({str(marker)!r}, "a") as fh:
            fh.write("run\\n")
        from estimation.diagnosis import cores
        batch = cores.SharedBatch(abs, [-1, -2, -3, -4])
        assert batch.shared
        print(batch.result())
    """))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[1, 2, 3, 4]"
    assert marker.read_text().splitlines() == ["run"]


_DIAGNOSE = """
import json, sys
sys.path[:0] = [{tests!r}, {root!r}]
import hidden_cases as hc
from estimation.diagnosis import diagnose_frequency
from pris_cosim.circuits.netlist import parse_netlist

case = hc.one_port_case(("skin-effect",), 7, sections=3)
d = diagnose_frequency(case.frequency_hz, case.measured, circuit=parse_netlist(case.baseline_netlist), port="n1",
                       progress=False)
final = d.best or d.baseline
print(json.dumps({{"causes": d.causes, "cost": final.cost, "baseline": d.baseline.cost,
                  "values": final.values, "drift": [x["name"] for x in d.drift]}}))
"""


@pytest.mark.slow
@pytest.mark.long
@needs_helper
def test_a_diagnosis_is_the_same_with_and_without_the_helper(tmp_path):
    """The independent generator's one-port skin-effect case (three sections), diagnosed in two fresh processes."""
    script = tmp_path / "diagnose_case.py"
    script.write_text(_DIAGNOSE.format(tests=str(ROOT / "tests"), root=str(ROOT)))
    runs = {}
    for jobs in ("1", "2"):
        env = {**__import__("os").environ, cores.JOBS_VARIABLE: jobs}
        out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, env=env)
        assert out.returncode == 0, out.stderr[-2000:]
        runs[jobs] = json.loads(out.stdout.strip().splitlines()[-1])
    assert runs["1"] == runs["2"]
    assert runs["1"]["causes"] == ["skin-effect"]
