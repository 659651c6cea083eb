"""The FRA part of the SFRA report: traces with the DL/T 911 bands, their difference, the factor table.

Used by :func:`estimation.diagnosis.sfra.report.write_report` (with a fitted model) and
by :func:`write_comparison_report` (the comparison alone, e.g. of CSV exports).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from estimation.diagnosis.sfra.compare import FraTrace, on_grid
from estimation.diagnosis.sfra.dlt911 import BANDS

__all__ = ["fra_figure", "fra_markdown", "write_comparison_report"]

_COLOURS = {"LF": "#e3ecf7", "MF": "#f7efe3", "HF": "#e8f4e4"}
_NAMES = {"LF": "LF 1-100 kHz", "MF": "MF 100-600 kHz", "HF": "HF 0.6-1 MHz"}


def _shade(ax) -> None:
    for key, lo, hi in BANDS:
        ax.axvspan(lo, hi, color=_COLOURS[key], zorder=0, lw=0)


def fra_figure(path: str | os.PathLike, ref: FraTrace, new: FraTrace, repeat: FraTrace | None = None,
               dlt911: dict | None = None) -> None:
    """Magnitude (dB) and phase (deg) of the traces with the DL/T 911 bands shaded, and the difference in dB.

    Parameters
    ----------
    path : str or os.PathLike
        PNG file written.
    ref, new, repeat : FraTrace
        Reference, new sweep and (optional) second healthy sweep; plotted on the reference's frequencies.
    dlt911 : dict, optional
        The factors, printed in the band labels.
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    f = ref.frequency_hz
    h_new, in_new = on_grid(f, new)
    curves = [("reference", ref.h, np.ones(f.size, bool), dict(color="0.3", lw=1.0)),
              ("new sweep", h_new, in_new, dict(color="tab:red", lw=1.0))]
    if repeat is not None:
        h_rep, in_rep = on_grid(f, repeat)
        curves.append(("repeat (healthy)", h_rep, in_rep, dict(color="tab:blue", lw=0.9, ls="--")))
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(9, 9), sharex=True, gridspec_kw={"height_ratios": [3, 2, 2]})
    for ax in (a1, a2, a3):
        _shade(ax)
        ax.grid(True, which="both", lw=0.3, alpha=0.5)
    x_ref = 20 * np.log10(np.abs(ref.h))
    for label, h, m, style in curves:
        a1.semilogx(f[m], 20 * np.log10(np.abs(h[m])), label=label, **style)
        a2.semilogx(f[m], np.degrees(np.angle(h[m])), **style)
        if label != "reference":
            a3.semilogx(f[m], 20 * np.log10(np.abs(h[m])) - x_ref[m], label=f"{label} - reference", **style)
    a3.axhline(0.0, color="0.3", lw=0.6)
    a1.set_ylabel("|V_resp / V_ref| (dB)")
    a2.set_ylabel("phase (deg)")
    a2.set_ylim(-190, 190)
    a3.set_ylabel("difference (dB)")
    a3.set_xlabel("frequency (Hz)")
    a1.set_xlim(f[0], f[-1])
    a1.legend(fontsize=8, loc="lower left")
    a3.legend(fontsize=8, loc="lower left")
    for i, (key, lo, hi) in enumerate(BANDS):
        if hi < f[0] or lo > f[-1]:
            continue
        mid = np.sqrt(max(lo, f[0]) * min(hi, f[-1]))
        text = _NAMES[key]
        r = (dlt911 or {}).get(f"R_{key}")
        if r is not None:
            text += f"\nR = {r:.2f}"
        a1.text(mid, 0.97 - 0.12 * (i % 2), text, transform=a1.get_xaxis_transform(), ha="center", va="top",
                fontsize=7, color="0.2")
    title = f"{Path(new.source).name} against {Path(ref.source).name}"
    if dlt911 is not None:
        title += f": DL/T 911 verdict {dlt911.get('verdict') or 'not determined'}"
    a1.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _f(x, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def fra_markdown(out: dict) -> list[str]:
    """Markdown lines: the DL/T 911 table and verdict, the repeatability table, the indices' definitions."""
    std = out.get("standard_indices") or {}
    d = std.get("dlt911") or {}
    lines = ["## DL/T 911 relative factors", "",
             f"Response: {d.get('response', 'V_resp/V_ref')}. "
             "R = -lg(1 - LR), LR the centred correlation of the dB curves in the band; R = 10 when 1 - LR < 1e-10.",
             ""]
    if std.get("grid"):
        lines += [f"Grid: {std['grid']}.", ""]
    rep = std.get("dlt911_repeat")
    head = "| band | points | R (new vs reference) |" + (" R (repeat vs reference) |" if rep else "")
    lines += [head, "|---|---|---|" + ("---|" if rep else "")]
    for key, lo, hi in BANDS:
        row = f"| {_NAMES[key]} | {d.get('points', {}).get(key, 0)} | {_f(d.get('R_' + key), '.3f')} |"
        if rep:
            row += f" {_f(rep.get('R_' + key), '.3f')} |"
        lines.append(row)
    lines += ["", f"**Verdict: {d.get('verdict') or 'not determined'}** ({d.get('note', '')})."]
    if rep:
        lines.append(f"The repeat against the reference: {rep.get('verdict') or 'not determined'}.")
    r = out.get("repeatability")
    if r:
        lines += ["", "## Repeatability", "",
                  f"Second healthy sweep: `{r['repeat']}`. Change judged against the spread of the healthy pair "
                  "(F test of the dB differences at 99 %, independent points by Bartlett's formula).", "",
                  "| band | SD repeat (dB) | SD new (dB) | ratio of variances | limit | judgement |",
                  "|---|---|---|---|---|---|"]
        for key, _, _ in BANDS:
            b = r["bands"].get(key)
            if b is None:
                lines.append(f"| {_NAMES[key]} | - | - | - | - | not covered |")
                continue
            lines.append(f"| {_NAMES[key]} | {b['repeat']['sd_db']:.3f} | {b['new']['sd_db']:.3f} | "
                         f"{_f(b['ratio'], '.3g')} | {b['limit']:.3g} | {b['judgement']} |")
        lines += ["", f"Summary: {r['summary']}."]
    defs = out.get("indices_definitions") or {}
    if out.get("indices"):
        lines += ["", "## CC, ASLE, SD per band", "",
                  f"Response: {defs.get('response', '')}. "
                  + "; ".join(f"{k.upper()} = {v['formula']} ({'centred' if v['centred'] else 'uncentred'})"
                              for k, v in defs.items() if isinstance(v, dict)) + ".", "",
                  "| band | points | CC | ASLE (dB) | SD (dB) |", "|---|---|---|---|---|"]
        for band, v in out["indices"].items():
            lines.append(f"| {band} | {v['points']} | {_f(v['cc'], '.4f')} | {_f(v['asle'], '.3f')} | "
                         f"{_f(v['sd'], '.3f')} |")
    return lines


def write_comparison_report(out: dict, ref: FraTrace, new: FraTrace, repeat: FraTrace | None,
                            directory: str | os.PathLike) -> Path:
    """``report.md`` and ``fra.png`` of a comparison without a fitted model; returns the path of ``report.md``."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    fra_figure(d / "fra.png", ref, new, repeat, (out.get("standard_indices") or {}).get("dlt911"))
    lines = ["# SFRA comparison", "", f"- new sweep: `{new.source}`", f"- reference: `{ref.source}`"]
    if repeat is not None:
        lines.append(f"- repeat: `{repeat.source}`")
    if out.get("model_diagnosis"):
        lines += ["", f"Winding model: {out['model_diagnosis']}."]
    lines += [""] + fra_markdown(out) + ["", "![FRA traces, DL/T 911 bands, difference](fra.png)", ""]
    path = d / "report.md"
    path.write_text("\n".join(lines))
    return path
