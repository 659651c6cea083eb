"""Figures of the three-section study: convergence over seeds, 1-D search spaces, 2-D cost slices."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def trace_band(traces: Sequence[Sequence[Sequence[float]]], points: int = 80
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Median, minimum and maximum over seeds of best-cost-versus-evaluations step curves.

    Parameters
    ----------
    traces : sequence
        Per seed, a list of ``[evaluations, best cost]`` pairs (increasing).

    Returns
    -------
    evaluations, median, low, high : numpy.ndarray
        On a common log-spaced grid up to the longest trace; a seed's value
        past its last evaluation stays at its last best cost.
    """
    usable = [np.asarray(t, float) for t in traces if len(t)]
    if not usable:
        empty = np.zeros(0)
        return empty, empty, empty, empty
    top = max(t[-1, 0] for t in usable)
    start = min(t[0, 0] for t in usable)
    grid = np.unique(np.geomspace(max(start, 1.0), max(top, 1.0), points))
    vals = []
    for t in usable:
        i = np.searchsorted(t[:, 0], grid, side="right") - 1
        v = np.where(i >= 0, t[np.clip(i, 0, None), 1], np.nan)
        vals.append(v)
    V = np.array(vals)
    with np.errstate(all="ignore"):
        ok = np.any(np.isfinite(V), axis=0)
        grid, V = grid[ok], V[:, ok]
        return grid, np.nanmedian(V, axis=0), np.nanmin(V, axis=0), np.nanmax(V, axis=0)


def convergence_figure(rows: Sequence[Mapping[str, Any]], approach: str, path: str | Path) -> Path:
    """Best cost against evaluations (median line, min-max band over seeds) of one approach's cells."""
    from pris_cosim.plotting import pyplot

    plt = pyplot()
    metrics = sorted({r["cost_function"] for r in rows if r["approach"] == approach})
    fig, axes = plt.subplots(1, max(1, len(metrics)), figsize=(6 * max(1, len(metrics)), 4.2), squeeze=False)
    for ax, metric in zip(axes[0], metrics):
        for r in rows:
            if r["approach"] != approach or r["cost_function"] != metric:
                continue
            x, med, lo, hi = trace_band(r.get("traces", []))
            if not x.size:
                continue
            label = r["case"].split("/", 1)[1]
            (line,) = ax.plot(x, med, label=f"{label} (success {r.get('success_rate', 0):.0%})")
            ax.fill_between(x, lo, hi, color=line.get_color(), alpha=0.2)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cost evaluations")
        ax.set_ylabel(f"best {metric} cost")
        ax.set_title(f"{approach}: median and range over seeds")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def slice_figure(space: Mapping[str, Any], path: str | Path) -> Path:
    """2-D slice of the RMSE-type cost over two parameters around the target (log colour scale)."""
    from pris_cosim.plotting import pyplot

    plt = pyplot()
    sl = space["slice"]
    g = 100 * np.asarray(sl["relative_change"], float)
    C = np.asarray(sl["costs"], float)
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    with np.errstate(divide="ignore"):
        Z = np.log10(np.where(C > 0, C, np.nan))
    m = ax.pcolormesh(g, g, Z.T, shading="nearest")
    fig.colorbar(m, ax=ax, label=f"log10 {sl['metric']} cost")
    ax.plot([0], [0], "w+", ms=12)
    ax.set_xlabel(f"{sl['parameters'][0]} change [%]")
    ax.set_ylabel(f"{sl['parameters'][1]} change [%]")
    ax.set_title(f"{space['approach']}: cost slice")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_all(rows: Sequence[Mapping[str, Any]], spaces: Sequence[Mapping[str, Any]], out: Path) -> list[str]:
    """All figures of a study run into ``out``; returns their paths."""
    from estimation.plotting import search_space_figure

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for approach in sorted({r["approach"] for r in rows}):
        clean = [r for r in rows if r.get("snr_db") is None]
        paths.append(convergence_figure(clean, approach, out / f"convergence_{approach}.png"))
    for sp in spaces:
        paths.append(search_space_figure(sp, out / f"search_space_{sp['approach']}.png"))
        if "slice" in sp:
            paths.append(slice_figure(sp, out / f"slice_Rs_Ls_{sp['approach']}.png"))
    return [str(p) for p in paths]
