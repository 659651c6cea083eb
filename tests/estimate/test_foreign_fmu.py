"""Estimation through FMUs that another tool built (pythonfmu), from records that fmpy made.

The FMUs and their records come from :mod:`tests.foreign_fmus` (pythonfmu
sources written here, fmpy's ``simulate_fmu`` with a held PRBS): nothing of
pris-cosim makes the expected data. Every estimate runs as a
``pris-cosim estimate`` subprocess, because a pythonfmu FMU may crash the
process that frees it.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonfmu", reason="pythonfmu (a test extra) builds the foreign FMUs of these tests")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import foreign_fmus as ff  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The FMUs whose builder is installed (pythonfmu; pythonfmu3 for the FMI 3.0 one), built once per module."""
    import importlib.util

    root = tmp_path_factory.mktemp("foreign")
    return {name: ff.build(name, root / name) for name, m in ff.MODELS.items()
            if importlib.util.find_spec(m.get("builder", "pythonfmu")) is not None}


def _estimate(cfg: dict, tmp: Path) -> dict:
    path = tmp / "cfg.json"
    path.write_text(json.dumps(cfg))
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(path), "--json",
                        "--quiet", "--out", str(tmp / "out"), "--workers", "2"], cwd=REPO, capture_output=True,
                       text=True)
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("{")), None)
    assert line is not None, p.stderr[-2000:]
    return json.loads(line)


def _cfg(name: str, fmu: Path, rec: Path, free: dict[str, tuple[float, float]]) -> dict:
    m = ff.MODELS[name]
    truth = m["truth"]
    params = {}
    for k, (lo, hi) in free.items():
        params[k] = {"min": lo * truth[k], "max": hi * truth[k]}
    return {"fmu": str(fmu), "input": m["input"], "output": m["outputs"][0], "outputs": m["outputs"][1:],
            "parameters": params, "values": {k: v for k, v in truth.items() if k not in free},
            "target": {"kind": "waveforms-csv", "path": str(rec), "values": truth}, "seed": 1}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ff.MODELS))
def test_held_record_replays_exactly_at_the_truth(built, tmp_path, name):
    """A held PRBS input is read as held (zero-order hold) and the truth then replays the record to 1e-9."""
    from estimation.fmu.model import FmuModel
    from estimation.holds import decide_hold

    if name not in built:
        pytest.skip(f"{ff.MODELS[name].get('builder')} is not installed")
    m = ff.MODELS[name]
    w = ff.read(ff.record(name, built[name], tmp_path / "r.csv", n=1024))
    hold, reason = decide_hold(w[m["input"]], m["input"])
    assert hold == "zoh" and "2 distinct levels" in reason
    fs = 1.0 / (w["time_s"][1] - w["time_s"][0])
    scores = {}
    for h in ("zoh", "linear"):
        truth = ff.fmu_truth(name)
        with FmuModel(built[name], list(truth), m["outputs"], input=m["input"], hold=h) as fm:
            y = fm.simulate(truth, fs, w["time_s"].size, w[m["input"]])
        scores[h] = max(float(np.sqrt(np.mean((y[k] - w[o]) ** 2) / np.mean(w[o] ** 2)))
                        for k, o in enumerate(m["outputs"]))
    assert scores["zoh"] < 1e-9, scores
    assert scores["linear"] > 1e-2, scores  # the held edges smeared by a linear replay


CASES = {
    # current in, voltage out (two outputs compared): inductances, coupling and a capacitance free
    "coupled_pair": {"L1": (0.3, 3.0), "L2": (0.3, 3.0), "C1": (0.3, 3.0), "C2": (0.3, 3.0)},
    # voltage in behind a known source resistance, current out
    "pi_network": {"Ca": (0.3, 3.0), "L": (0.3, 3.0), "Cb": (0.3, 3.0), "RL": (0.3, 3.0)},
}


@pytest.mark.slow
@pytest.mark.parametrize("noise,tol", [(0.0, 1.0), (0.005, 5.0)], ids=["noise-free", "noise-0.5pct"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_foreign_fmu_estimated(built, tmp_path, name, noise, tol):
    """Four free values of a pythonfmu FMU within 1 % (noise-free) and 5 % (0.5 % noise), hold chosen as zoh."""
    rec = ff.record(name, built[name], tmp_path / "r.csv", noise=noise)
    a = _estimate(_cfg(name, built[name], rec, CASES[name]), tmp_path)
    assert a["input_hold"].startswith("zoh"), a["input_hold"]
    worst = max(abs(e) for e in a["errors_percent"].values())
    assert worst < tol, (a["errors_percent"], a["convergence_reason"])
    assert a["fmu_simulations"] > 0 and all(r["runs_per_stage"] for r in a["restarts"])


#: One worker runs this module under ``pytest -n 2 --dist loadgroup``: its module fixtures are computed once.
pytestmark = pytest.mark.xdist_group("estimate_foreign_fmu")
