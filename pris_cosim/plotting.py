"""Plots of frequency responses (matplotlib imported lazily; every function takes ``ax=``)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the non-interactive Agg backend (imported lazily)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_response(
    frequency_hz: np.ndarray,
    values: np.ndarray,
    label: str = "",
    ax: Sequence[Any] | None = None,
    **style: Any,
) -> Sequence[Any]:
    """Magnitude (log-log) and phase (deg) of one complex response.

    Parameters
    ----------
    frequency_hz : array_like, Hz
    values : array_like, complex
    label : str
    ax : pair of matplotlib axes, optional
        (magnitude axis, phase axis); new ones when omitted.
    """
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(2, 1, sharex=True, figsize=(6, 5))
    mag_ax, ph_ax = ax
    mag_ax.loglog(frequency_hz, np.abs(values), label=label, **style)
    ph_ax.semilogx(frequency_hz, np.degrees(np.angle(values)), label=label, **style)
    mag_ax.set_ylabel("magnitude")
    ph_ax.set_ylabel("phase (deg)")
    ph_ax.set_xlabel("frequency (Hz)")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    return ax


def plot_responses(
    frequency_hz: np.ndarray,
    responses: Mapping[str, np.ndarray],
    path: str | Path | None = None,
    title: str = "",
    reference: Mapping[str, np.ndarray] | None = None,
    reference_frequency_hz: np.ndarray | None = None,
) -> Any:
    """A grid of magnitude/phase plots, one column per response; optionally saved as PNG.

    Parameters
    ----------
    frequency_hz : array_like, Hz
    responses : mapping
        Name to complex array.
    path : path-like, optional
        PNG file to write.
    title : str
    reference : mapping, optional
        Responses drawn dashed for comparison (e.g. measured data).
    reference_frequency_hz : array_like, optional
        Frequencies of ``reference`` (default: ``frequency_hz``).
    """
    plt = pyplot()
    names = list(responses)
    fig, axes = plt.subplots(2, len(names), sharex="col", figsize=(4.2 * len(names), 5.5), squeeze=False)
    for j, name in enumerate(names):
        col = (axes[0, j], axes[1, j])
        plot_response(frequency_hz, responses[name], label="model", ax=col)
        if reference is not None and name in reference:
            fr = frequency_hz if reference_frequency_hz is None else reference_frequency_hz
            plot_response(fr, reference[name], label="reference", ax=col, linestyle="--")
            axes[0, j].legend(fontsize="small")
        axes[0, j].set_title(name)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig
