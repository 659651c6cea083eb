"""Estimation through FMUs of another shape than the ladder: four coupled sections, a current in, two voltages out.

The FMUs are written here (:mod:`tests.foreign_fmus`: their own network equations stepped with scipy's matrix
exponential) and built with pythonfmu (FMI 2.0) and, where it is installed, pythonfmu3 (FMI 3.0); their
records are made by stepping them with fmpy's slave classes under a held PRBS of order 9. Nothing of
pris-cosim makes the expected data. The records vary what a user's would: one PRBS period or two, another
sampling rate and clock, noise-free and with 0.5 % noise. Every estimate runs as a ``pris-cosim estimate``
subprocess (a pythonfmu FMU may crash the process that frees it).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonfmu", reason="pythonfmu (a test extra) builds the FMUs of these tests")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import foreign_fmus as ff  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


def _has(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The four-section FMU built with pythonfmu (FMI 2.0) and, where installed, pythonfmu3 (FMI 3.0)."""
    root = tmp_path_factory.mktemp("shapes")
    names = ["four_section"] + (["four_section_fmi3"] if _has("pythonfmu3") else [])
    return {name: ff.build(name, root / name) for name in names}


def _estimate(cfg: dict, folder: Path, extra: tuple[str, ...] = ()) -> tuple[dict, str]:
    path = folder / "cfg.json"
    path.write_text(json.dumps(cfg))
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(path), "--json",
                        "--out", str(folder / "out"), "--workers", "2", *extra], cwd=REPO, capture_output=True,
                       text=True)
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("{")), None)
    assert line is not None, p.stderr[-3000:]
    return json.loads(line), p.stderr


def _cfg(name: str, fmu: str, rec: str, free: dict[str, tuple[float, float]]) -> dict:
    """A user's config: free values between the given multiples of the truth, the rest known."""
    m = ff.MODELS[name]
    truth = m["truth"]
    ties = {k: e for k, e in m["ties"].items() if e in free}  # a shared value that is known is set directly
    values = {k: v for k, v in ff._fmu_values(truth, m["ties"]).items() if k not in free and k not in ties}
    return {"fmu": fmu, "input": m["input"], "output": m["outputs"][0], "outputs": m["outputs"][1:],
            "parameters": {k: {"min": lo * truth[k], "max": hi * truth[k]} for k, (lo, hi) in free.items()},
            "ties": ties, "values": values,
            "target": {"kind": "waveforms-csv", "path": rec, "values": truth}, "seed": 1}


#: Free values of the estimates: the four inductances, the shared series and ground capacitances, the middle coupling.
FREE = {"L1": (0.4, 2.5), "L2": (0.4, 2.5), "L3": (0.4, 2.5), "L4": (0.4, 2.5), "Cs": (0.4, 2.5),
        "Cg": (0.4, 2.5), "k23": (0.5, 2.0)}

#: Record conditions (sampling rate, samples per PRBS bit, PRBS periods of 511 bits).
RECORDS = {
    "one-period-4MHz-200kHz": {"fs": 4e6, "hold": 20, "periods": 1},
    "two-periods-2MHz-250kHz": {"fs": 2e6, "hold": 8, "periods": 2},
}


CASES = [  # (FMU, record): both FMI versions, one PRBS period and two, two sampling rates and clocks
    ("four_section", "one-period-4MHz-200kHz"),
    ("four_section_fmi3", "two-periods-2MHz-250kHz"),
]


#: (FMU, record) x (noise, tolerance %): CI runs each FMU once and each noise once (one FMI 2 record with noise, the
#: FMI 3 record without); the other two combinations are long runs only
SHAPES = [pytest.param(n, r, noise, tol, id=f"{n}-{r}-{nid}",
                       marks=() if (k == 0) == (noise > 0) else pytest.mark.long)
          for k, (n, r) in enumerate(CASES)
          for noise, tol, nid in ((0.0, 1.0, "noise-free"), (0.005, 5.0, "noise-0.5pct"))]


@pytest.mark.slow
@pytest.mark.parametrize("name,record,noise,tol", SHAPES)
def test_four_sections_estimated(built, tmp_path, name, record, noise, tol):
    """Seven values of a four-section FMU (current in, two voltages out) within 1 % noise-free and 5 % at
    0.5 % noise, converged, from records of one or two PRBS periods at two sampling rates and clocks."""
    if name not in built:
        pytest.skip("pythonfmu3 is not installed")
    r = RECORDS[record]
    rec = ff.record(name, built[name], tmp_path / "r.csv", fs=r["fs"], n=511 * r["hold"] * r["periods"],
                    hold=r["hold"], noise=noise)
    a, _ = _estimate(_cfg(name, str(built[name]), str(rec), FREE), tmp_path)
    worst = max(abs(e) for e in a["errors_percent"].values())
    assert worst < tol, (a["errors_percent"], a["convergence_reason"])
    assert a["converged"], a["convergence_reason"]
    assert a["verdict"]["restarts"]["agreeing"] >= 2 and a["uncertainty"] is not None


def test_config_errors_name_key_entry_and_choices(built, tmp_path):
    """A bad output or tie names the key, the entry and what is valid; a coupling bound of 2.5 is clipped
    with a one-line warning; relative paths are taken from the config's folder."""
    from estimation.fmu.estimate import make_setup
    from estimation.fmu.model import FmuSetupError

    name = "four_section"
    folder = tmp_path / "cfgdir"
    folder.mkdir()
    rec = ff.record(name, built[name], folder / "r.csv", fs=4e6, n=600, hold=20)
    cfg = _cfg(name, str(built[name]), rec.name, {"L1": (0.5, 2.0), "Cs": (0.5, 2.0)})
    with pytest.raises(FmuSetupError, match=r"config key 'outputs': 'v_5' .*\(outputs: v_1, v_4\)"):
        make_setup({**cfg, "outputs": ["v_5"]}, folder)
    values = {k: v for k, v in cfg["values"].items() if k != "Cg1"}
    with pytest.raises(FmuSetupError, match=r"config key 'ties': 'Cg1': .*Cs\*.*it may use"):
        make_setup({**cfg, "values": values, "ties": {**cfg["ties"], "Cg1": "Cs*"}}, folder)
    with pytest.raises(FmuSetupError, match=r"config key 'ties': 'Cg1': 'Cx' .*it may use"):
        make_setup({**cfg, "values": values, "ties": {**cfg["ties"], "Cg1": "2*Cx"}}, folder)
    # the config in its own folder, run from the repository: its relative record path is found there
    values = {k: v for k, v in cfg["values"].items() if k != "k23"}
    (folder / "c.json").write_text(json.dumps({**cfg, "fmu": os.path.relpath(built[name], folder), "values": values,
                                               "budget": {"simulations": 1},  # refused once the files are read
                                               "parameters": {**cfg["parameters"], "k23": {"min": 0.1, "max": 2.5}}}))
    p = subprocess.run([sys.executable, "-m", "pris_cosim", "estimate", "--config", str(folder / "c.json")],
                       cwd=REPO, capture_output=True, text=True)
    assert p.returncode == 2 and p.stderr.count("\n") == 2, p.stderr
    warn, err = p.stderr.splitlines()
    assert warn.startswith("warning: config key 'parameters': 'k23'") and "clipped to [0.1, 0.999]" in warn
    assert "config key 'budget'" in err and "not found" not in err


def test_failed_runs_by_reason(built):
    """Runs the FMU refuses (an indefinite inductance matrix) are counted by reason, the instance recovers."""
    from estimation.fmu.model import FmuModel

    m = ff.MODELS["four_section"]
    truth = ff.fmu_truth("four_section")
    u = np.full(200, 0.01)
    with FmuModel(built["four_section"], list(truth), m["outputs"], input="i_drive", hold="zoh") as fm:
        for _ in range(3):
            assert fm.simulate({**truth, "k12": 0.97, "k23": 0.95}, 4e6, 200, u) is None
            assert fm.simulate(truth, 4e6, 200, u) is not None
    (reason, row), = fm.failure_reasons.items()
    assert row["runs"] == 3 and row["at"]["k12"] == 0.97
    assert reason == "inductance matrix not positive definite", reason  # the FMU's own message


#: One worker runs this module under ``pytest -n 2 --dist loadgroup``: its module fixtures are computed once.
pytestmark = pytest.mark.xdist_group("estimate_fmu_shapes")
