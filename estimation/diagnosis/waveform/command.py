"""``pris-cosim diagnose`` on a PRIS record with the source's nominal values: the arrangement's replay."""

from __future__ import annotations

import argparse
from pathlib import Path

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.measured.formats import Waveforms

from estimation.diagnosis.fit import DiagnosisError
from estimation.diagnosis.result import DiagnosisOutcome


def diagnose_record(data: Waveforms, args: argparse.Namespace) -> DiagnosisOutcome:
    """Run :func:`.replay.diagnose_pris_record` for the command's options (``--rload`` alone: a resistor load).

    Raises
    ------
    DiagnosisError
        A netlist without ``--port``, a non-positive ``--rload``.
    """
    from pris_cosim.models.builtin import get_model
    from pris_cosim.circuits.netlist import read_netlist

    from estimation.diagnosis.waveform.replay import diagnose_pris_record

    model = get_model(args.model) if args.model else None
    circuit, port = None, args.port
    if args.netlist:
        circuit = read_netlist(args.netlist)
        if not port:
            raise DiagnosisError("a netlist baseline needs --port")
    elif model is None:
        if not args.rload > 0:
            raise DiagnosisError(f"--rload must be positive (got {args.rload!r})")
        from estimation.diagnosis.waveform.record_spectra import periodic_record

        rec, why = periodic_record(data)
        if rec is None:  # the source check on the load in the time domain (switching between samples honoured)
            from estimation.diagnosis.waveform.source import diagnose_waveforms
            from estimation.diagnosis.waveform.report import write_report as write_waveform_report

            diag = diagnose_waveforms(data, args.rpris, args.lpris, args.cpris, r_load=args.rload)
            diag.evidence["path"] = {"path": "time-domain", "why": why + "; the source on the known load "
                                     "simulated sample by sample"}
            if args.report:
                write_waveform_report(diag, args.report)
            return diag
        circuit = Circuit(title="known resistive load")
        circuit.add("Rload", "p", "0", float(args.rload))
        port = "p"
    diag = diagnose_pris_record(data, args.rpris, args.lpris, args.cpris, model=model, circuit=circuit, port=port,
                                tolerance=args.tolerance, source_tolerance=args.source_tolerance)
    if args.report:
        from estimation.diagnosis.report import write_report

        if hasattr(diag, "frequency_hz"):
            write_report(diag, args.report, source=Path(args.measured).name + " (impedance from the PRIS record)")
        else:
            _write_replay_report(diag, args.report, Path(args.measured).name)
    return diag


def _write_replay_report(diag, folder: str, source: str) -> None:
    """A short ``report.md``: the path, the causes with their values, the drift."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    j = diag.as_json()
    rows = [f"# Diagnosis of {source}", "", f"Path: {j['path']['path']} ({j['path']['why']}).", "",
            f"Cause: **{j['cause']}**, gain {j['gain']:.3f}.", ""]
    for s in j["steps"]:
        rows.append(f"- {s['cause']}{' (dropped)' if s.get('dropped') else ''}: {s.get('reason', '')} "
                    f"{s.get('values', '')}")
    for d in j["drift"]:
        rows.append(f"- drift {d['name']}: design {d['design']:.4g}, fitted {d['fitted']:.4g}")
    rows += ["", "Source values: " + ", ".join(f"{k} {v:.4g}" for k, v in j["source_values"].items())]
    (out / "report.md").write_text("\n".join(rows) + "\n")
