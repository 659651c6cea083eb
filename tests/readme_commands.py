"""The README's example commands, and how to run one as a user would: from a directory holding only the shipped data."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def readme_commands() -> list[str]:
    """The README's example commands, install and test commands removed.

    ``echo ... > FILE`` lines belong to the command after them.
    """
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


def readme_command(prefix: str) -> str:
    """The one README command that starts with ``prefix``."""
    found = [c for c in readme_commands() if c.startswith(prefix)]
    assert len(found) == 1, f"README commands starting with {prefix!r}: {found}"
    return found[0]


def run_readme_command(cmd: str, cwd: Path) -> subprocess.CompletedProcess:
    """Run ``cmd`` with bash in ``cwd``, which gets a ``pris_cosim`` link to the package (the README's paths are
    relative to the clone's root)."""
    link = cwd / "pris_cosim"
    if not link.exists():
        link.symlink_to(REPO / "pris_cosim", target_is_directory=True)
    env = dict(os.environ, PATH=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]),
               MPLBACKEND="Agg")
    return subprocess.run(["bash", "-c", cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=3600)
