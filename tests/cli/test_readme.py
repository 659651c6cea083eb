"""Every example command in the README runs as written, from a directory that holds only the shipped data.

The README's shell blocks are read, install and test commands are left out,
and each remaining command runs in a fresh directory with a ``pris_cosim``
link to the package (the README's paths are relative to the clone's root).
``echo ... > FILE`` lines belong to the command after them.  Commands that
take more than a few seconds carry the ``slow`` marker.
"""

from __future__ import annotations

import json
import shutil

import pytest

from readme_commands import README, readme_commands, run_readme_command

#: Commands quick enough for the default run (seconds each).
FAST = ("pris-cosim models", "pris-cosim frf ", "pris-cosim simulate ", "pris-cosim build-fmu ")
#: Commands that another test runs as written, from the same kind of directory, and checks further (not run twice).
RUN_ELSEWHERE = {"pris-cosim study hv-transformer --quick": "test_hv_transformer.py's quick_study fixture",
                 "pris-cosim study two-section --quick": "test_studies.py's acceptance test"}
#: Commands of minutes each (CI leaves them out with the other ``long`` tests).
LONG = ("pris-cosim study three-section",)


def _case(cmd: str):
    marks = [] if cmd.startswith(FAST) else [pytest.mark.slow]
    if cmd.startswith(LONG):
        marks.append(pytest.mark.long)
    return pytest.param(cmd, marks=marks, id=cmd.split("&&")[-1].strip()[:60])


def test_readme_has_the_two_first_screen_commands():
    text = README.read_text(encoding="utf-8")
    first = text[: text.index("## ")]
    assert 'python -m pip install -e . && pris-cosim' in first
    assert 'python -m pip install -e ".[test]" && python -m pytest' in first
    assert len(text.splitlines()) <= 260


@pytest.mark.parametrize("cmd", [_case(c) for c in readme_commands()])
def test_readme_example_runs(cmd, tmp_path):
    if "build-fmu" in cmd and shutil.which("cmake") is None:
        pytest.skip("building an FMU needs CMake and a C compiler (apt-get install cmake gcc)")
    for prefix, where in RUN_ELSEWHERE.items():
        if cmd.startswith(prefix):
            pytest.skip(f"run as written by {where}")
    proc = run_readme_command(cmd, tmp_path)
    assert proc.returncode == 0, f"{cmd}\n{proc.stderr[-3000:]}"
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    if "--json" in cmd:
        doc = json.loads(proc.stdout)
        assert isinstance(doc, dict) and doc
