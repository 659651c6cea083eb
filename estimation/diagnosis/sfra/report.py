"""Markdown report with figures for an SFRA diagnosis (matplotlib, Agg backend)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from estimation.diagnosis.sfra.faults import SfraDiagnosis
from estimation.diagnosis.sfra.fingerprint import model_y
from estimation.diagnosis.sfra.indices import BANDS

__all__ = ["write_report"]

_BAND_COLOURS = ("#f2f2f2", "#e3ecf7", "#f7efe3", "#ececec")


def _shade(ax) -> None:
    for (name, lo, hi), colour in zip(BANDS, _BAND_COLOURS):
        ax.axvspan(max(lo, 1e-3), min(hi, 1e9), color=colour, zorder=0, lw=0)


def _response_figure(diag: SfraDiagnosis, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    f = diag.reference.frequency_hz
    curves = [
        ("reference (measured)", -1.0 / diag.reference.y[:, 1], dict(color="0.35", lw=1.0)),
        ("new sweep (measured)", -1.0 / diag.measured.y[:, 1], dict(color="tab:red", lw=1.0)),
        ("reference model", -1.0 / model_y(diag.fingerprint.model, f)[:, 1], dict(color="tab:blue", ls="--", lw=1.2)),
    ]
    if diag.cause != "none":
        curves.append((f"fault model ({diag.cause})", -1.0 / model_y(diag.fault_model, f)[:, 1],
                       dict(color="tab:green", ls="--", lw=1.2)))
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for ax in (a1, a2):
        _shade(ax)
    for label, z, style in curves:
        a1.loglog(f, np.abs(z), label=label, **style)
        a2.semilogx(f, np.degrees(np.angle(z)), **style)
    a1.set_ylabel("|Z end to end| (Ohm)")
    a2.set_ylabel("phase (deg)")
    a2.set_xlabel("frequency (Hz)")
    a2.set_ylim(-190, 190)
    a1.set_xlim(f[0], f[-1])
    a1.legend(fontsize=8, loc="lower right")
    for name, lo, hi in BANDS:
        mid = np.sqrt(max(lo, f[0]) * min(hi, f[-1]))
        a1.text(mid, 0.97, name, transform=a1.get_xaxis_transform(), ha="center", va="top", fontsize=7, color="0.3")
    a1.set_title(f"{Path(diag.measured.source).name} against {Path(diag.reference.source).name}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _winding_figure(diag: SfraDiagnosis, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    n = diag.fingerprint.n_sections
    loc = diag.location()
    hit = loc["section"] if loc else None
    gains = diag.by_section.get(diag.cause, [])
    fig, ax = plt.subplots(figsize=(3.2, 0.5 * n + 1.6))
    for k in range(1, n + 1):
        y = n - k  # section 1 (port-1 end) at the top
        colour = "tab:red" if k == hit else "#d9d9d9"
        ax.add_patch(Rectangle((0.2, y + 0.08), 0.6, 0.84, facecolor=colour, edgecolor="k"))
        text = f"section {k}"
        if gains and k - 1 < len(gains):
            text += f"  gain {gains[k - 1]:.2f}"
        ax.text(0.9, y + 0.5, text, va="center", fontsize=8)
    if loc is not None:
        y = n * (1.0 - loc["fraction"])  # the fitted position along the winding
        s = n * loc.get("fraction_std", 0.0)
        ax.axhspan(max(0.0, y - 2 * s), min(float(n), y + 2 * s), xmin=0.12, xmax=0.4, color="tab:blue", alpha=0.25,
                   lw=0)
        ax.errorbar([0.0], [y], yerr=[[min(2 * s, y)], [min(2 * s, n - y)]], fmt="none", ecolor="tab:blue",
                    capsize=4, lw=1.5)
        ax.plot([0.1, 0.9], [y, y], color="k", lw=2)
    ax.text(0.5, n + 0.15, "port 1", ha="center", va="bottom", fontsize=9)
    ax.text(0.5, -0.15, "port 2", ha="center", va="top", fontsize=9)
    ax.set_xlim(-0.3, 2.2)
    ax.set_ylim(-0.8, n + 0.8)
    ax.axis("off")
    title = diag.cause if hit is None else f"{diag.cause}: section {hit}/{n}"
    if loc is not None:
        title += f"\nposition {loc['fraction']:.3f} ± {loc.get('fraction_std', 0.0):.3f}\n(1 std; bar: ± 2 std)"
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_report(diag: SfraDiagnosis, out: dict, directory: str | os.PathLike, repeat=None) -> Path:
    """Write ``report.md``, ``fra.png``, ``response.png`` and ``winding.png`` into ``directory``.

    Parameters
    ----------
    diag : SfraDiagnosis
        The diagnosis.
    out : dict
        Its JSON object (with the indices, the DL/T 911 factors and the repeatability).
    directory : str or os.PathLike
        Created if missing.
    repeat : estimation.diagnosis.sfra.compare.FraTrace, optional
        The second healthy sweep, drawn in ``fra.png``.

    Returns
    -------
    pathlib.Path
        Path of ``report.md``.
    """
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    from estimation.diagnosis.sfra.compare import FraTrace
    from estimation.diagnosis.sfra.report_fra import fra_figure, fra_markdown

    ref = FraTrace(diag.reference.frequency_hz, diag.reference.voltage_ratio, diag.reference.source)
    new = FraTrace(diag.measured.frequency_hz, diag.measured.voltage_ratio, diag.measured.source)
    fra_figure(d / "fra.png", ref, new, repeat, (out.get("standard_indices") or {}).get("dlt911"))
    _response_figure(diag, d / "response.png")
    _winding_figure(diag, d / "winding.png")
    fp = diag.fingerprint
    lines = [
        "# SFRA fault diagnosis",
        "",
        f"- new sweep: `{diag.measured.source}`",
        f"- reference: `{diag.reference.source}`",
        f"- reference model: {fp.n_sections} sections (resonances counted: {fp.resonances}; "
        f"tried N = {', '.join(str(t['n']) for t in fp.tried)}), weighted rms {fp.rms:.2f}",
        "",
        f"**Cause: {diag.cause}**, gain {diag.gain:.3f}",
        "",
    ]
    if out.get("location") is not None:
        lines.append(f"Location: section {out['section']} of {fp.n_sections}, "
                     f"{out['location']:.3f} ± {out.get('location_std') or 0.0:.3f} (one standard deviation) of the "
                     "winding from the port-1 end.")
    if out.get("severity"):
        sev = {k: v for k, v in out["severity"].items() if v is not None}
        lines.append("Severity: " + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                                              for k, v in sev.items()) + ".")
    lines += ["", "| candidate | section | gain | dBIC |", "|---|---|---|---|"]
    for c in out["candidates"]:
        lines.append(f"| {c['cause']} | {c['section']} | {c['gain']:.3f} | {c['dBIC']:.1f} |")
    lines += [""] + fra_markdown(out)
    lines += ["", "![FRA traces, DL/T 911 bands, difference](fra.png)", "",
              "![end-to-end response and models](response.png)", "", "![winding](winding.png)", ""]
    path = d / "report.md"
    path.write_text("\n".join(lines))
    return path
