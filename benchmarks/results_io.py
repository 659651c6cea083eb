"""Benchmark results as JSON: every benchmark writes ``benchmarks/results/<name>.json``.

``scripts/render_figures.py`` renders ``docs/figures.md`` from these files, so
no measured figure is typed by hand.  A result file holds

- ``benchmark``: the script's name; ``command``: how it was run;
- ``date`` (UTC, ISO 8601), ``machine`` (cores, platform, Python, the 1-minute
  load average when the result was written: figures under load are slower);
- ``summary``: one line for the figures page;
- ``tables``: a list of ``{"title", "columns", "rows"}`` (rows are lists of
  cells: numbers or text), rendered as Markdown tables in that order;
- ``figures``: optional ``{name: {"value", "unit"}}`` of headline numbers;
- ``data``: optional free-form result (nested dicts and lists), rendered as
  a flattened key/value table when a benchmark has no tables of its own.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import sys
from pathlib import Path
from typing import Any, Sequence

RESULTS_DIR = Path(__file__).resolve().parent / "results"


def table(title: str, columns: Sequence[str], rows: Sequence[Sequence[Any]]) -> dict[str, Any]:
    """One table of a result file.

    Parameters
    ----------
    title : str
        Heading shown above the table.
    columns : sequence of str
        Column headings, units in the heading (for example ``"wall (s)"``).
    rows : sequence of sequences
        One list of cells per row; numbers are formatted when rendered.
    """
    return {"title": title, "columns": list(columns), "rows": [list(r) for r in rows]}


def write_results(name: str, tables: Sequence[dict[str, Any]], summary: str = "",
                  figures: dict[str, dict[str, Any]] | None = None,
                  path: str | os.PathLike[str] | None = None, data: Any = None) -> Path:
    """Write one benchmark's results (atomically) and return the file's path.

    Parameters
    ----------
    name : str
        Benchmark name, for example ``"bench_cosim"``; the file is ``<name>.json``.
    tables : sequence of dict
        Tables made with :func:`table`.
    summary : str, optional
        One line describing what was measured and on what.
    figures : dict, optional
        Headline numbers ``{name: {"value": float, "unit": str}}``.
    path : path-like, optional
        Where to write instead of ``benchmarks/results/<name>.json``.
    data : object, optional
        Free-form result kept beside the tables (``data``; see :func:`write_raw`).
    """
    out = Path(path) if path is not None else RESULTS_DIR / f"{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    doc = {
        "benchmark": name,
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "date": _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat(),
        "machine": {"cores": os.cpu_count(), "platform": platform.platform(),
                    "python": platform.python_version(),
                    "load_average_1min": round(os.getloadavg()[0], 2)},
        "summary": summary,
        "tables": list(tables),
        "figures": figures or {},
    }
    if data is not None:
        doc["data"] = json.loads(json.dumps(data, default=_plain))
    tmp = out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=1, default=_plain) + "\n")
    tmp.replace(out)
    return out


def write_raw(name: str, data: Any, summary: str = "") -> Path:
    """Write a benchmark's free-form result (nested dicts/lists of numbers and text).

    Parameters
    ----------
    name : str
        Benchmark name; the file is ``benchmarks/results/<name>.json``.
    data : object
        The result as the benchmark builds it; ``docs/figures.md`` shows it
        flattened (``a.b.c = value``).
    summary : str, optional
        One line describing what was measured.
    """
    return write_results(name, tables=[], summary=summary, data=data)


def _plain(x: Any) -> Any:
    """JSON form of numpy scalars and arrays."""
    if hasattr(x, "tolist"):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
