"""The figures page is rendered from the benchmarks' result files, each of which is well formed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
RESULTS = REPO / "benchmarks" / "results"


def test_every_result_file_is_well_formed():
    for f in RESULTS.glob("*.json"):
        doc = json.loads(f.read_text())
        assert doc["benchmark"] == f.stem, f
        assert {"date", "machine", "tables"} <= doc.keys(), f
        for t in doc["tables"]:
            assert all(len(row) == len(t["columns"]) for row in t["rows"]), (f, t["title"])


def test_figures_page_renders_every_result(tmp_path):
    out = tmp_path / "figures.md"
    proc = subprocess.run([sys.executable, str(REPO / "scripts" / "render_figures.py"), "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    for f in RESULTS.glob("*.json"):
        assert f"## {f.stem}" in text
    assert "nan" not in text.lower().split("|")
