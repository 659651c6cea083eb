"""One page per diagnosis: Markdown with PNG plots a user can check."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pris_cosim.circuits.netlist import write_netlist
from pris_cosim.plotting import pyplot

from estimation.diagnosis.result import Diagnosis


def plot_fits(diag: Diagnosis, path: Path) -> Path:
    """Measured, baseline and extended responses: magnitude and phase per response."""
    plt = pyplot()
    names = list(diag.measured)
    fig, axes = plt.subplots(2, len(names), figsize=(4.6 * len(names), 6), squeeze=False, sharex="col")
    f = diag.frequency_hz
    for j, n in enumerate(names):
        series = [("measured", diag.measured[n], dict(color="k", lw=2.2, alpha=0.45)),
                  ("baseline", diag.baseline.predicted[n], dict(color="tab:red", lw=1.2))]
        if diag.best is not None:
            series.append((f"extended ({diag.cause})", diag.best.predicted[n], dict(color="tab:blue", lw=1.2, ls="--")))
        for label, z, style in series:
            axes[0, j].loglog(f, np.abs(z), label=label, **style)
            axes[1, j].semilogx(f, np.degrees(np.angle(z)), **style)
        axes[0, j].set_title(n)
        axes[1, j].set_xlabel("frequency (Hz)")
        for a in axes[:, j]:
            a.grid(True, which="both", alpha=0.3)
    axes[0, 0].set_ylabel("magnitude")
    axes[1, 0].set_ylabel("phase (deg)")
    axes[0, 0].legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_residuals(diag: Diagnosis, path: Path) -> Path:
    """Residuals before and after: magnitude error (dB) and phase error (deg) against frequency."""
    plt = pyplot()
    names = list(diag.measured)
    fig, axes = plt.subplots(2, len(names), figsize=(4.6 * len(names), 5.5), squeeze=False, sharex="col")
    f = diag.frequency_hz
    for j, n in enumerate(names):
        runs = [("baseline", diag.baseline.errors[n], "tab:red")]
        if diag.best is not None:
            runs.append((f"extended ({diag.cause})", diag.best.errors[n], "tab:blue"))
        for label, e, color in runs:
            axes[0, j].semilogx(f, 20 / np.log(10) * e.real, color=color, label=label, lw=1)
            axes[1, j].semilogx(f, np.degrees(e.imag), color=color, lw=1)
        axes[0, j].set_title(n)
        axes[1, j].set_xlabel("frequency (Hz)")
        for a in axes[:, j]:
            a.axhline(0, color="k", lw=0.5)
            a.grid(True, which="both", alpha=0.3)
    axes[0, 0].set_ylabel("model / measured (dB)")
    axes[1, 0].set_ylabel("phase error (deg)")
    axes[0, 0].legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def parallel_note(d: dict) -> str:
    """One drifted value's parallel partners: the terminals see only their combination (no full stop)."""
    c = d["combined"]
    return (f"{d['name']} is in parallel with {', '.join(d['parallel'])}: the data tell only their combination, "
            f"{_fmt(c['design'])} -> {_fmt(c['fitted'])} (x{c['ratio']:.3g}), not which of them is off")


def drift_lines(data: dict) -> list[str]:
    """Markdown: the design tolerance and the values the final fit moved beyond it (the drift table)."""
    tol = data.get("tolerance", float("inf"))
    if tol is None or not np.isfinite(tol):
        return ["Values fitted freely (no design tolerance).", ""]
    lines = ["## Drift from the design", ""]
    drift = data.get("drift") or []
    if not drift:
        lines += [f"Every value of the final model is within the design tolerance ({tol:.0%}).", ""]
    else:
        lines += [f"Values the final model moved beyond the design tolerance ({tol:.0%}): the design value is wrong, "
                  "or the model lacks an effect these values absorb.", "",
                  "| value | design | fitted | ratio |", "|---|---|---|---|"]
        lines += [f"| {d['name']}: {', '.join(d['members'])} | each its design | each x{d['ratio']:.3g} | {d['ratio']:.3g} |"
                  if d.get("group") else f"| {d['name']} | {_fmt(d['design'])} | {_fmt(d['fitted'])} | {d['ratio']:.3g} |"
                  for d in drift]
        lines.append("")
        lines += [parallel_note(d) + "." for d in drift if d.get("parallel")]
        if any(d.get("parallel") for d in drift):
            lines.append("")
        alt = data.get("drift_alternatives") or []
        if alt:
            lines += ["The data are explained as well by one of these values off instead (one at a time; the "
                      "response measured does not tell which): "
                      + ", ".join(f"{d['name']} x{d['ratio']:.3g} (BIC +{d['delta_bic']:.1f})" for d in alt) + ".", ""]
    base = data.get("baseline_drift") or []
    if base and data.get("causes"):
        lines += ["Without the causes named, the baseline needed: "
                  + ", ".join(f"{d['name']} x{d['ratio']:.3g}" for d in base) + ".", ""]
    return lines


def write_report(diag: Diagnosis, directory: str | Path, source: str = "") -> Path:
    """Write ``report.md``, ``fits.png``, ``residuals.png``, ``diagnosis.json`` (and the extended netlist).

    Parameters
    ----------
    diag : Diagnosis
    directory : path-like
        Created if missing.
    source : str
        Name of the measured file, for the heading.

    Returns
    -------
    pathlib.Path
        The Markdown file.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    plot_fits(diag, out / "fits.png")
    plot_residuals(diag, out / "residuals.png")
    data = diag.as_json()
    realisation = data.get("realisation", {})
    circuit = realisation.pop("circuit", None) if isinstance(realisation, dict) else None
    if circuit is not None:
        write_netlist(circuit, out / "extended.cir")
    elif diag.best is not None:
        write_netlist(diag.best.circuit.with_values(diag.best.values), out / "extended.cir")
    (out / "diagnosis.json").write_text(json.dumps(data, indent=1, default=float))
    ev = diag.evidence
    lines = [f"# Diagnosis{': ' + source if source else ''}", ""]
    prior = np.isfinite(data.get("tolerance", np.inf) or np.inf)
    lines += [f"**Cause: `{diag.cause}`** — gain {diag.gain:.3f} (fraction of the baseline cost removed on the measured "
              "data" + (", each cost counting the design prior's penalty" if prior else "") + ").", ""]
    pen = (f" + prior penalty {_fmt(diag.baseline.penalty)}" if prior else "")
    pen_ext = (f" + {_fmt(diag.best.penalty)}" if prior and diag.best else "")
    lines += [f"Baseline: `{ev.get('baseline_model', '')}`, cost {_fmt(diag.baseline.cost)}{pen}; "
              f"extended cost {_fmt(diag.best.cost) + pen_ext if diag.best else '-'}; noise floor "
              f"{_fmt(diag.noise.get('cost', 0.0))}. Selection: {ev.get('criterion', '')}.", ""]
    if data.get("causes") and len(data["causes"]) > 1:
        lines += ["Causes named, in order: " + ", ".join(f"`{c}`" for c in data["causes"]) + ".", ""]
    tie = data.get("cause_alternatives") or []
    if tie and data.get("causes"):
        lines += [f"The data tell `{data['causes'][0]}` only barely from "
                  + ", ".join(f"`{c['cause']}` (BIC {c['delta_bic']:+.1f} alone)" for c in tie)
                  + ": less than 2 in BIC, not worth more than a bare mention.", ""]
    elif tie and data.get("drift"):
        lines += ["The data tell the drift above only barely from "
                  + ", ".join(f"`{c['cause']}` (BIC {c['delta_bic']:+.1f})" for c in tie)
                  + ": a cause is named over a drift when it is lower in BIC by 10 (\"very strong\"), and a drift "
                  "lower by less than 2 is not worth more than a bare mention.", ""]
    if not data.get("explained", True):
        lines += [("No cause tried explains the data" if not data.get("causes") else "The causes named do not explain "
                   "all of the data") + f": the returned model stays above twice the noise floor. {data.get('misfit', '')}"
                  + (f" Best candidate tried: `{data['best_tried']}`." if data.get("best_tried") else ""), ""]
        if data.get("unexplained"):
            lines += ["| response | band (Hz) | RMS / noise | mag dB / phase deg |", "|---|---|---|---|"]
            lines += [f"| {b['response']} | {_fmt(b['band_hz'][0])} - {_fmt(b['band_hz'][1])} | {b['above_noise']:.3g} | "
                      f"{b['mag_rms_db']:.2f} / {b['phase_rms_deg']:.2f} |" for b in data["unexplained"]]
            lines.append("")
    lines += drift_lines(data)
    loc = ev.get("localisation", {})
    if loc:
        shares = ", ".join(f"{k} {v:.0%}" for k, v in sorted(loc["shares"].items(), key=lambda kv: -kv[1]) if v > 0.005)
        lines += [f"Where the baseline misfit sits: **{loc['region']}** ({shares}).", ""]
    lines += ["## Candidates", "", "| cause | parameters | cost | gain | ΔBIC | fitted extension |", "|---|---|---|---|---|---|"]
    for c in data["candidates"]:
        extra = ", ".join(f"{k} = {_fmt(v)}" for k, v in c["extra"].items())
        lines.append(f"| {c['cause']} | {c['n_params']} | {_fmt(c['cost'])} | {c['gain']:.3f} | {c['delta_bic']:.1f} | {extra} |")
    lines += ["", "![fits](fits.png)", "", "![residuals](residuals.png)", ""]
    if ev.get("gain_per_response"):
        lines += ["## Gain per response", "", "| response | gain |", "|---|---|"]
        lines += [f"| {k} | {v:.3f} |" for k, v in ev["gain_per_response"].items()]
        lines.append("")
    lines += ["## Residual per band", "", "| response | band (Hz) | before: mag dB / phase deg | after: mag dB / phase deg |",
              "|---|---|---|---|"]
    after = {(r["response"], tuple(r["band_hz"])): r for r in ev.get("bands_after", [])}
    for r in ev.get("bands_before", []):
        a = after.get((r["response"], tuple(r["band_hz"])))
        post = f"{a['mag_rms_db']:.2f} / {a['phase_rms_deg']:.2f}" if a else "-"
        lines.append(f"| {r['response']} | {_fmt(r['band_hz'][0])} - {_fmt(r['band_hz'][1])} | "
                     f"{r['mag_rms_db']:.2f} / {r['phase_rms_deg']:.2f} | {post} |")
    lines += ["", "## Resonances (parallel, Hz)", "", "| response | measured | baseline |", "|---|---|---|"]
    for n, r in ev.get("resonances", {}).items():
        lines.append(f"| {n} | {', '.join(_fmt(x) for x in r['measured_parallel_hz'])} | "
                     f"{', '.join(_fmt(x) for x in r['model_parallel_hz'])} |")
    if isinstance(realisation, dict) and realisation:
        lines += ["", "## Time-domain realisation", "",
                  f"{realisation.get('note', '')}: {realisation.get('elements', '')} elements"
                  + (f", within {realisation['max_deviation_db']:.2g} dB of the fitted formula over the band"
                     if "max_deviation_db" in realisation else "") + ". Netlist: `extended.cir`."]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path
