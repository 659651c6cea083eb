"""Report of a waveform diagnosis: ``report.md`` with the waveforms at an edge and the residuals.

Split from :mod:`estimation.diagnosis.waveform.source`, which computes the diagnosis.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from estimation.diagnosis.waveform.signals import SIGNALS, UNITS, _bit_samples, _edges

if TYPE_CHECKING:
    from estimation.diagnosis.waveform.source import WaveformDiagnosis


def _fmt(v: float, unit: str = "") -> str:
    if v is None:
        return "-"
    a = abs(v)
    if a == 0:
        return f"0 {unit}".strip()
    prefixes = [(1e6, "M"), (1e3, "k"), (1, ""), (1e-3, "m"), (1e-6, "u"), (1e-9, "n"), (1e-12, "p")]
    if unit:
        for s, p in prefixes:
            if a >= s:
                return f"{v / s:.4g} {p}{unit}"
        return f"{v:.4g} {unit}"
    return f"{v:.4g}"


_PARAM_UNITS = {"_ohm": "Ohm", "_h": "H", "_f": "F", "_hz": "Hz", "_percent": "%", "_percent_of_nominal": "%"}


def _param_text(name: str, value: float) -> str:
    for suffix in sorted(_PARAM_UNITS, key=len, reverse=True):
        if name.endswith(suffix):
            unit = _PARAM_UNITS[suffix]
            return f"{value:.3g} %" if unit == "%" else _fmt(value, unit)
    return f"{value:.4g}"


def write_report(diagnosis: WaveformDiagnosis, directory: str | os.PathLike) -> Path:
    """Write ``report.md`` and its figures (``waveforms_edge.png``, ``residuals.png``) into ``directory``.

    Returns
    -------
    pathlib.Path
        The report file.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    d = diagnosis
    ev = d.evidence
    figs = _plots(d, out)
    lines = ["# Waveform diagnosis of the PRIS source", ""]
    lines += [f"**Cause: `{d.cause}`** (gain {d.gain:.3f}: fraction of the baseline cost removed)", ""]
    if len(d.causes) > 1:
        lines += ["Causes named, in order: " + "; ".join(
            f"`{st['cause']}` (gain {st['gain']:.3f} of the cost left, dBIC {st['delta_bic']:.1f})" for st in d.steps)
                  + ".", ""]
    if d.noise:
        lines += [f"Noise floor {d.noise['cost']:.3g} (cost units); the final model's cost "
                  f"{d.extended.cost:.3g}" + (": " + ", ".join(f"{u['signal']} residual {u['above_noise']:.1f} x "
                                                                 "the noise" for u in d.unexplained)
                                               if d.unexplained else ", at the noise") + ".", ""]
    lines += ["Nominal source: " + ", ".join([f"R_pris = {_fmt(d.nominal['rpris'], 'Ohm')}",
                                             f"L_pris = {_fmt(d.nominal['lpris'], 'H')}",
                                             f"C_pris = {_fmt(d.nominal['cpris'], 'F')}"])
              + f"; fitted load {_fmt(ev['r_load_ohm']['extended'], 'Ohm')}.", ""]
    lines += [f"Record: {ev['samples']} samples at {_fmt(ev['fs_hz'], 'S/s')}, {ev['switching_edges']} switching "
              f"edges, bit length {_fmt(ev['bit_s'], 's')}.", ""]
    lines += [f"Cost: {ev['cost_definition']}.", ""]
    lines += ["## Candidates", "", "| cause | cost | gain | dBIC | parameters |", "|---|---|---|---|---|",
              f"| baseline | {d.baseline.cost:.4g} | 0 | 0 | R_load {_fmt(d.baseline.values['r_load'], 'Ohm')} |"]
    for c in d.candidates():
        params = ", ".join(f"{k} = {_param_text(k, v)}" for k, v in c["extra"].items())
        mark = " **(named)**" if d.best is not None and c["cause"] == d.best.cause else ""
        lines.append(f"| {c['cause']}{mark} | {c['cost']:.4g} | {c['gain']:.3f} | {c['delta_bic']:.1f} | {params} |")
    lines += ["", f"Rule: {ev['criterion']}.", ""]
    lines += ["## Residuals", "", "| signal | RMS before | after | before (% of signal RMS) | after (%) |",
              "|---|---|---|---|---|"]
    for s, r in ev["residual_rms"].items():
        lines.append(f"| {s} | {_fmt(r['before'], r['unit'])} | {_fmt(r['after'], r['unit'])} | "
                     f"{r['before_percent_of_signal_rms']:.3g} | {r['after_percent_of_signal_rms']:.3g} |")
    loc = ev["localisation"]
    lines += ["", f"Where the baseline residual sits: **{loc['where']}** — "
              f"{100 * loc['residual_share_near_edges_before']:.0f} % of its energy within "
              f"{_fmt(loc['edge_window_s'], 's')} after an edge, which is {100 * loc['time_share_near_edges']:.0f} % "
              "of the record."]
    if "residual_share_near_edges_after" in loc:
        lines[-1] += f" After the extension: {100 * loc['residual_share_near_edges_after']:.0f} %."
    lines += ["", "| time since edge | samples | residual RMS before | after |", "|---|---|---|---|"]
    for row in loc["profile_by_time_since_edge"]:
        to = _fmt(row["to_s"], "s") if row["to_s"] is not None else "end of bit"
        lines.append(f"| {_fmt(row['from_s'], 's')} - {to} | {row['samples']} | {row['rms_before']:.3g} | "
                     f"{row.get('rms_after', float('nan')):.3g} |")
    if ev.get("residual_spectrum_peak_hz"):
        lines += ["", f"Strongest peak of the baseline residual spectrum in the ringing band: "
                      f"{_fmt(ev['residual_spectrum_peak_hz'], 'Hz')}."]
    if "ringing" in ev:
        r = ev["ringing"]
        lines += ["", "## Switch ringing", "",
                  f"L_sw = {_fmt(r['lsw_h'], 'H')}, C_sw = {_fmt(r['csw_f'], 'F')}: ringing frequency "
                  f"{_fmt(r['f_ring_hz'], 'Hz')} ({r['relation']})."]
        if "f_ring_snubbed_hz" in r:
            lines[-1] += f" With the snubber: {_fmt(r['f_ring_snubbed_hz'], 'Hz')}."
        lines[-1] += (f" Optimal damping resistance of an RC snubber (thesis: R_s = sqrt(L_p / C_p) / 2): "
                      f"{_fmt(r['optimal_snubber_r_ohm'], 'Ohm')}.")
    lines += ["", "## Figures", ""] + [f"![{name}]({name})" for name in figs] + [""]
    path = out / "report.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def _plots(d: WaveformDiagnosis, out: Path) -> list[str]:
    from pris_cosim.plotting import pyplot

    plt = pyplot()

    t = d.time_s - d.time_s[0]
    h = float(t[1] - t[0])
    edges = _edges(d.v_bprbs)
    err = sum(((d.baseline.predicted[s] - d.measured[s]) / np.std(d.measured[s])) ** 2 for s in SIGNALS)
    bit = int(_bit_samples(d.v_bprbs))
    # the edge whose following bit carries the largest baseline residual
    scores = [float(np.sum(err[e:e + bit])) for e in edges]
    e0 = int(edges[int(np.argmax(scores))]) if edges.size else 0
    ext = d.extended
    extra = {} if d.best is None else d.best.extra.get("switch-ringing", d.best.extra)
    f_ring = extra.get("f_ring_observed_hz")
    short = max(int(round(5 / f_ring / h)), 20) if f_ring else max(bit // 8, 20)
    windows = [(max(0, e0 - bit // 10), min(t.size, e0 + bit)),
               (max(0, e0 - max(short // 8, 2)), min(t.size, e0 + short))]
    names = []
    fig, axes = plt.subplots(2, 2, figsize=(11, 6.5), squeeze=False)
    for col, (a, b) in enumerate(windows):
        for row, s in enumerate(SIGNALS):
            ax = axes[row][col]
            tt = t[a:b] * 1e6
            ax.plot(tt, d.measured[s][a:b], "k.", ms=2.5, label="measured")
            ax.plot(tt, d.baseline.predicted[s][a:b], "C0-", lw=1, label="baseline (nominal R, L, C)")
            if d.best is not None:
                ax.plot(tt, ext.predicted[s][a:b], "C3--", lw=1, label=f"extended ({d.cause})")
            ax.axvline(t[e0] * 1e6, color="0.7", lw=0.8)
            ax.set_ylabel(f"{s} ({UNITS[s]})")
            if row == 1:
                ax.set_xlabel("time (us)")
            if row == 0 and col == 0:
                ax.legend(fontsize=8)
    axes[0][0].set_title("one bit after the edge with the largest baseline error")
    axes[0][1].set_title("zoom on the edge")
    fig.tight_layout()
    fig.savefig(out / "waveforms_edge.png", dpi=110)
    plt.close(fig)
    names.append("waveforms_edge.png")
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    for row, s in enumerate(SIGNALS):
        ax = axes[row]
        ax.plot(t * 1e3, d.baseline.predicted[s] - d.measured[s], "C0-", lw=0.6, label="baseline residual")
        if d.best is not None:
            ax.plot(t * 1e3, ext.predicted[s] - d.measured[s], "C3-", lw=0.6, label=f"after {d.cause}")
        ax.set_ylabel(f"{s} residual ({UNITS[s]})")
        ax.legend(fontsize=8, loc="upper right")
    axes[1].set_xlabel("time (ms)")
    fig.tight_layout()
    fig.savefig(out / "residuals.png", dpi=110)
    plt.close(fig)
    names.append("residuals.png")
    return names
