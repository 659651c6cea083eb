"""The shipped FMUs run by an importer we did not write: the Reference-FMUs ``fmusim``.

``fmusim`` (Modelica Association) reads the model description with its own XML
parser, loads the binary with ``dlopen`` and drives Co-Simulation and Model
Exchange (CVODE) through the FMI API. ``scripts/build_fmusim.sh`` builds it;
the tests find it on PATH or through ``PRIS_FMUSIM`` and skip with the reason
when it is absent.
"""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

FMUS = sorted((Path(__file__).resolve().parents[2] / "fmus").glob("*/*.fmu"))
FMUSIM = os.environ.get("PRIS_FMUSIM") or shutil.which("fmusim")

pytestmark = pytest.mark.skipif(not FMUSIM, reason="fmusim not found (scripts/build_fmusim.sh builds it; "
                                                   "set PRIS_FMUSIM or put it on PATH)")


def _run(fmu: Path, kind: str, out: Path, stop: float, extra: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    cmd = [FMUSIM, "--interface-type", kind, "--log-level", "warning", "--stop-time", repr(stop),
           "--output-file", str(out), *extra, str(fmu)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, (fmu.name, kind, res.stdout[-500:], res.stderr[-500:])
    assert "[Error]" not in res.stdout + res.stderr, (fmu.name, kind, res.stdout[-500:])
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data.size > 10 and all(np.isfinite(data[n]).all() for n in data.dtype.names)
    return {n: data[n] for n in data.dtype.names}


def _stop(fmu: Path) -> float:
    """A short experiment: a few hundred PRBS bits of the FMU's own clock."""
    return 2e-3 if "two_section" in fmu.name else 2e-4


@pytest.mark.parametrize("fmu", FMUS, ids=[f.name for f in FMUS])
def test_fmusim_runs_every_shipped_fmu_as_cs_and_me(tmp_path, fmu):
    cs = _run(fmu, "cs", tmp_path / "cs.csv", _stop(fmu))
    me = _run(fmu, "me", tmp_path / "me.csv", _stop(fmu), ("--solver", "cvode", "--tolerance", "1e-9"))
    if not fmu.name.endswith("_pris.fmu"):
        return
    # ME records both sides of each event; keep the value after it, then compare on the CS grid.
    t, first = np.unique(me["time"][::-1], return_index=True)
    last = len(me["time"]) - 1 - first
    for name in ("v_in", "i_in"):
        m = np.interp(cs["time"], t, me[name][last])
        scale = np.max(np.abs(cs[name]))
        assert scale > 0
        assert np.max(np.abs(m - cs[name])) <= 1e-4 * scale, (fmu.name, name)


def test_fmusim_runs_fmi3_builds(tmp_path):
    from pris_cosim.cli.commands import main

    assert main(["build-fmu", "--model", "two-section", "--port", "in", "--with-source", "--fmi-version", "3",
                 "--out", str(tmp_path / "fmi3")]) == 0
    built = sorted((tmp_path / "fmi3").glob("*.fmu"))
    assert len(built) == 3
    for fmu in built:
        cs = _run(fmu, "cs", tmp_path / "cs.csv", 2e-3)
        me = _run(fmu, "me", tmp_path / "me.csv", 2e-3, ("--solver", "cvode", "--tolerance", "1e-9"))
        assert set(cs) == set(me)
