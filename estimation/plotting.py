"""Figures of the estimation studies (matplotlib imported lazily; every function takes ``ax=``)."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any


def search_space_axes(space: Mapping[str, Any], metric: str, ax: Any = None) -> Any:
    """Cost versus relative change of each shown parameter (one panel of thesis Figs. 4.19-4.22).

    Parameters
    ----------
    space : mapping
        From :func:`estimation.studies.three_section.study.search_space`.
    metric : str
        ``"rmse"`` or ``"correlation"``.
    ax : matplotlib Axes, optional
    """
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots()
    rel = [100 * r for r in space["relative_change"]]
    for name, costs in space["costs"][metric].items():
        ax.plot(rel, costs, label=name)
    ax.set_xlabel("distance from target parameter [%]")
    ax.set_ylabel(f"{space['approach']} {metric} cost")
    ax.legend()
    ax.grid(True, alpha=0.3)
    return ax


def search_space_figure(space: Mapping[str, Any], path: str | Path) -> Path:
    """Both metrics of one approach side by side, written to ``path`` (PNG)."""
    from pris_cosim.plotting import pyplot

    plt = pyplot()

    metrics = list(space["costs"])
    fig, axes = plt.subplots(1, len(metrics), figsize=(5.5 * len(metrics), 4), squeeze=False)
    for ax, m in zip(axes[0], metrics):
        search_space_axes(space, m, ax=ax)
        ax.set_title(f"{space['approach']}: {m}")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
