"""Every example command in the README runs as written, from a directory that holds only the shipped data.

The README's shell blocks are read, install and test commands are left out,
and each remaining command runs in a fresh directory with a ``pris_cosim``
link to the package (the README's paths are relative to the clone's root).
``echo ... > FILE`` lines belong to the command after them.  Commands that
take more than a few seconds carry the ``slow`` marker.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
#: Commands quick enough for the default run (seconds each).
FAST = ("pris-cosim models", "pris-cosim frf ", "pris-cosim simulate ", "pris-cosim build-fmu ")


def readme_commands() -> list[str]:
    """The README's example commands, install and test commands removed."""
    commands, pending = [], []
    for block in re.findall(r"```bash\n(.*?)```", README.read_text(encoding="utf-8"), re.S):
        for raw in block.splitlines():
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            parts = [p.strip() for p in line.split("&&")]
            parts = [re.sub(r"\s+#.*$", "", p) for p in parts if not p.startswith("python -m pip install")]
            parts = [p for p in parts if p and not p.startswith("python -m pytest")]
            if not parts:
                continue
            if all(p.startswith("echo ") for p in parts):
                pending += parts
                continue
            commands.append(" && ".join(pending + parts))
            pending = []
    return commands


def _case(cmd: str):
    marks = [] if cmd.startswith(FAST) else [pytest.mark.slow]
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
    (tmp_path / "pris_cosim").symlink_to(REPO / "pris_cosim", target_is_directory=True)
    env = dict(os.environ, PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
               MPLBACKEND="Agg")
    proc = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, f"{cmd}\n{proc.stderr[-3000:]}"
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    if "--json" in cmd:
        doc = json.loads(proc.stdout)
        assert isinstance(doc, dict) and doc
