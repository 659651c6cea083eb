"""The same study command and seed give the same JSON numbers, whatever the number of workers."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from typing import Any

import pytest

#: Keys whose values are wall times or derived from them (or name the output directory).
_TIMING_KEYS = ("wall", "per_eval", "setup_s", "evals_per_s", "elapsed", "speedup", "table", "out")


def _differences(a: Any, b: Any, path: str = "") -> list[str]:
    """Paths where two JSON values differ (floats by more than 1e-12 relative), timing keys aside."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a if not any(t in k for t in _TIMING_KEYS) for d in _differences(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} against {len(b)} items"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _differences(x, y, f"{path}[{i}]")]
    if isinstance(a, float) or isinstance(b, float):
        if isinstance(a, (int, float)) and isinstance(b, (int, float)) and math.isfinite(a) and math.isfinite(b) \
                and abs(a - b) <= 1e-12 * max(abs(a), abs(b)):
            return []
        return [f"{path}: {a!r} against {b!r}"]
    return [] if a == b else [f"{path}: {a!r} against {b!r}"]


def _study(tmp_path, workers: int) -> dict:
    out = tmp_path / f"workers{workers}"
    proc = subprocess.run(
        [sys.executable, "-m", "pris_cosim", "study", "two-section", "--quick", "--cases", "1,4", "--seed", "1",
         "--workers", str(workers), "--quiet", "--json", "--out", str(out)],
        capture_output=True, text=True, timeout=300, env=dict(os.environ, PYTHONWARNINGS="error"))
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.mark.slow
def test_quick_two_section_study_same_numbers_with_one_and_two_workers(tmp_path):
    one, two = _study(tmp_path, 1), _study(tmp_path, 2)
    assert [r["case"] for r in one["rows"]] == ["1", "4"]
    diffs = _differences(one, two)
    assert not diffs, diffs[:10]
    # the comparison itself sees a change in the last digits
    changed = json.loads(json.dumps(two))
    changed["rows"][1]["cost"] = changed["rows"][1]["cost"] * (1 + 1e-9) + 1e-300
    assert _differences(one, changed)
