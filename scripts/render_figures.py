"""Render ``docs/figures.md`` from the benchmarks' JSON results (``benchmarks/results/*.json``).

Every measured figure the documentation quotes comes from a benchmark run:
each ``benchmarks/bench_*.py`` writes its result file through
``benchmarks/results_io.py``, and this script turns all of them into one
Markdown page.  Run it after a benchmark::

    python scripts/render_figures.py [--results benchmarks/results] [--out docs/figures.md]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any, Iterator

ROOT = Path(__file__).resolve().parents[1]


def fmt(x: Any) -> str:
    """A table cell: numbers with four significant digits, text as it is."""
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, int):
        return f"{x:,}" if abs(x) >= 10_000 else str(x)
    if isinstance(x, float):
        if not math.isfinite(x):
            return str(x)
        if x == 0:
            return "0"
        if 1e-3 <= abs(x) < 1e5:
            return f"{x:.4g}"
        return f"{x:.3e}"
    if isinstance(x, (list, tuple)):
        if len(x) <= 6 and all(not isinstance(v, (dict, list)) for v in x):
            return ", ".join(fmt(v) for v in x)
        return f"[{len(x)} values]"
    return str(x).replace("|", "\\|").replace("\n", " ")


def flatten(data: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """``(dotted key, leaf value)`` pairs of nested dicts (lists of scalars stay leaves)."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield from flatten(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(data, list) and data and all(isinstance(v, dict) for v in data) and len(data) <= 50:
        for i, v in enumerate(data):
            yield from flatten(v, f"{prefix}[{i}]")
    else:
        yield prefix, data


def render_table(t: dict[str, Any]) -> list[str]:
    lines = [f"**{t.get('title', '')}**", "", "| " + " | ".join(t["columns"]) + " |",
             "|" + "---|" * len(t["columns"])]
    lines += ["| " + " | ".join(fmt(c) for c in row) + " |" for row in t["rows"]]
    return lines + [""]


def render(doc: dict[str, Any], source: str) -> list[str]:
    m = doc.get("machine", {})
    lines = [f"## {doc.get('benchmark', source)}", ""]
    if doc.get("summary"):
        lines += [doc["summary"], ""]
    load = m.get("load_average_1min")
    lines += [f"Run `{doc.get('command', '')}` on {doc.get('date', '?')} ({m.get('cores', '?')} cores, "
              f"Python {m.get('python', '?')}"
              + (f", load average {load:g} when written" if load is not None else "")
              + f"); result file `{source}`.", ""]
    for t in doc.get("tables", []):
        lines += render_table(t)
    if doc.get("figures"):
        lines += render_table({"title": "Headline figures", "columns": ["figure", "value", "unit"],
                               "rows": [[k, v.get("value"), v.get("unit", "")] for k, v in doc["figures"].items()]})
    if "data" in doc and not doc.get("tables"):
        rows = [[k, v] for k, v in flatten(doc["data"])]
        lines += render_table({"title": "Measured", "columns": ["quantity", "value"], "rows": rows})
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures.md"))
    args = ap.parse_args(argv)
    folder = Path(args.results)
    files = sorted(folder.glob("*.json"))
    lines = ["# Measured figures", "",
             "Rendered by `scripts/render_figures.py` from the benchmarks' result files in",
             "`benchmarks/results/`; nothing here is typed by hand. Re-run a benchmark",
             "(`python benchmarks/bench_<name>.py`), then this script, to refresh a section.", ""]
    lines += [f"- [{f.stem}](#{f.stem.replace('_', '_')})" for f in files] + [""]
    for f in files:
        try:
            doc = json.loads(f.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            print(f"error: {f}: not a readable result file ({exc})", file=sys.stderr)
            return 2
        lines += render(doc, f"benchmarks/results/{f.name}")
    out = Path(args.out)
    out.write_text("\n".join(lines).rstrip() + "\n", encoding="utf-8")
    print(f"wrote {out} from {len(files)} result files", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
