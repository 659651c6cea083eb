"""Plots of perturbation-signal spectra (thesis Fig. 2.14).

matplotlib is imported inside the functions so that importing this module
stays cheap and works without a display.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from pris_cosim.signals.perturbation import hbridge_waveform, pris_ideal, prbs_psd_theory
from pris_cosim.signals.spectral import welch_psd

__all__ = ["plot_psd_comparison", "figure_2_14"]


def plot_psd_comparison(
    signals: Mapping[str, np.ndarray],
    fs: float,
    *,
    nperseg: int | None = None,
    overlays: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None,
    normalize: bool = False,
    title: str | None = None,
    ax=None,
):
    """Plot Welch PSDs (Hann, 62.5 % overlap) of several signals in dB.

    Parameters
    ----------
    signals : mapping of str to array_like
        Legend label -> samples (all sampled at ``fs``).
    fs : float, Hz
        Sampling frequency.
    nperseg : int, optional
        Welch segment length in samples; default half of each record.
    overlays : mapping of str to callable, optional
        Legend label -> function of frequency (Hz) giving a PSD in the signal's
        unit squared per Hz, drawn dashed on the Welch grid of the first signal
        (e.g. :func:`pris_cosim.signals.perturbation.prbs_psd_theory`).
    normalize : bool, optional
        If True each curve is shown relative to its own maximum (dB re peak),
        which compares spectral shapes of signals in different units.
    title : str, optional
        Axes title.
    ax : matplotlib.axes.Axes, optional
        Axes to draw into; a new figure is created if omitted.

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots()
    grid = None
    for label, x in signals.items():
        f, psd = welch_psd(x, fs, nperseg)
        grid = f if grid is None else grid
        ax.semilogx(f[1:], _db(psd[1:], normalize), label=label)
    for label, func in (overlays or {}).items():
        ax.semilogx(grid[1:], _db(func(grid[1:]), normalize), "--", color="k", lw=1, label=label)
    ax.set_xlabel("Frequency [Hz]")
    ax.set_ylabel("PSD [dB re peak]" if normalize else "PSD [dB/Hz]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize="small")
    if title:
        ax.set_title(title)
    return ax


def _db(psd: np.ndarray, normalize: bool) -> np.ndarray:
    psd = np.maximum(psd, np.finfo(float).tiny)
    return 10 * np.log10(psd / psd.max() if normalize else psd)


def figure_2_14(
    path: str | Path,
    *,
    order: int = 12,
    periods: int = 2,
    fs: float = 500e3,
    f_clk: float = 10e3,
    tau1: float = 100e-6,
    tau2: float = 20e-6,
    vdc: float = 1.0,
) -> Path:
    """Write a PNG reproducing thesis Fig. 2.14 (PRIS spectra).

    Panels: (a) PRIS vs PRBS spectral shapes, with the sinc**2 theory of the
    PRBS; (b) effect of f_clk; (c) effect of the impulse rise time constant;
    (d) effect of the impulse fall time constant.  Each parameter is varied by
    the factors 1/2, 1 and 2 (rise: 1/4, 1, 2.5) around the defaults.

    Parameters
    ----------
    path : str or pathlib.Path
        Output PNG file.
    order : int, optional
        PRBS order n.
    periods : int, optional
        PRBS periods simulated at the reference ``f_clk``; other clock
        frequencies use proportionally more or fewer periods.
    fs : float, Hz, optional
        Sampling frequency.
    f_clk : float, Hz, optional
        Reference PRBS clock frequency.
    tau1 : float, s, optional
        Reference decay (fall) time constant of (2.16).
    tau2 : float, s, optional
        Reference rise time constant of (2.16).
    vdc : float, V, optional
        PRBS level and PRIS impulse amplitude U.

    Returns
    -------
    pathlib.Path
        The written file.

    Notes
    -----
    With (2.16) written as ``U[exp(-t/tau1) - exp(-t/tau2)]`` and tau1 > tau2
    as (2.18)-(2.19) give, tau1 is the fall and tau2 the rise constant.  The
    thesis text discussing Fig. 2.14 (after Mwaniki et al.) calls the rise
    constant tau1 and the fall constant tau2; panels (c) and (d) follow that
    discussion's meaning (rise, then fall) and label the symbols of this
    module.
    """
    from matplotlib.figure import Figure

    nperseg = 2 ** int(np.log2(fs / f_clk * 128))  # ~128 bits per Welch segment

    def pris(fc: float, t1: float, t2: float) -> np.ndarray:
        n_periods = max(1, round(periods * fc / f_clk))  # same record length for every f_clk
        return pris_ideal(order, fc, fs, t1, t2, vdc, n_periods)[1]

    fig = Figure(figsize=(11, 8), layout="tight")
    axes = fig.subplots(2, 2, sharex=True)
    ax_a, ax_b, ax_c, ax_d = axes.ravel()
    prbs = hbridge_waveform(order, f_clk, fs, vdc, periods)[1]
    plot_psd_comparison(
        {"PRIS": pris(f_clk, tau1, tau2), "PRBS": prbs},
        fs,
        nperseg=nperseg,
        overlays={"PRBS theory": lambda f: prbs_psd_theory(f, f_clk, vdc)},
        normalize=True,
        title="(a) PRIS vs PRBS",
        ax=ax_a,
    )
    ax_a.set_ylim(-40, 3)
    for ax, title, curves in (
        (ax_b, "(b) clock frequency $f_{clk}$",
         {f"{fc / 1e3:g} kHz": pris(fc, tau1, tau2) for fc in (f_clk / 2, f_clk, 2 * f_clk)}),
        (ax_c, r"(c) rise time constant $\tau_2$",
         {f"{t2 * 1e6:g} µs": pris(f_clk, tau1, t2) for t2 in (tau2 / 4, tau2, 2.5 * tau2)}),
        (ax_d, r"(d) fall time constant $\tau_1$",
         {f"{t1 * 1e6:g} µs": pris(f_clk, t1, tau2) for t1 in (tau1 / 2, tau1, 2 * tau1)}),
    ):
        plot_psd_comparison(curves, fs, nperseg=nperseg, title=title, ax=ax)
        ax.set_ylim(top=ax.get_ylim()[1], bottom=ax.get_ylim()[1] - 60)
    for ax in axes.ravel():
        ax.axvline(f_clk / 3, color="grey", ls=":", lw=1)
        ax.axvline(f_clk, color="grey", ls="-.", lw=1)
        ax.set_xlim(f_clk / 100, 5 * f_clk)
    path = Path(path)
    fig.savefig(path, dpi=120)
    return path
