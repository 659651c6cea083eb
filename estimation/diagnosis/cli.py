"""``pris-cosim diagnose``: registered with the main command line through an entry point."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from pris_cosim.cli.sim import si_value

from estimation.diagnosis.prior import DEFAULT_TOLERANCE
from estimation.diagnosis.report import parallel_note


def register(subparsers: Any) -> None:
    """Add the ``diagnose`` sub-command."""
    p = subparsers.add_parser("diagnose", help="name what the simulation gets wrong in measured data, and the gain of fixing it")
    p.add_argument("--measured", required=True, metavar="FILE", help="measured responses (CSV, Touchstone, .mat, real formats) or waveforms CSV")
    p.add_argument("--segment", metavar="NAME", help="segment of a multi-segment file (e.g. short, open)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--netlist", metavar="FILE", help="baseline netlist (with --port)")
    src.add_argument("--model", metavar="NAME", help="baseline built-in model")
    p.add_argument("--port", metavar="NODE", help="driven node of the baseline netlist")
    p.add_argument("--tolerance", type=_tolerance, default=DEFAULT_TOLERANCE, metavar="REL",
                   help="how far the netlist's or model's values (the design) may be from the truth, relative "
                   f"(default {DEFAULT_TOLERANCE:g}: a log-normal prior of that width on every value; values moved "
                   "beyond it are reported as drift; 'inf' leaves the values free)")
    p.add_argument("--rpris", type=si_value, help="nominal source resistance, Ohm (waveform data; 150, 4.7k ...)")
    p.add_argument("--lpris", type=si_value, help="nominal source inductance, H (waveform data; 4m, 0.004 ...)")
    p.add_argument("--cpris", type=si_value, help="nominal source capacitance, F (waveform data; 1u, 1e-6 ...)")
    p.add_argument("--rload", type=si_value, help="load resistance if known, Ohm (waveform data)")
    p.add_argument("--source-tolerance", type=_tolerance, default=0.01, metavar="REL",
                   help="how far the source's nominal --rpris --lpris --cpris may be from the truth, relative "
                   "(default 0.01, the instrument's own; waveform data replayed from the bridge voltage: a source "
                   "value moved beyond it is named as a source cause)")
    p.add_argument("--report", metavar="DIR", help="write report.md with plots into DIR")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    sf = p.add_argument_group("SFRA (a new sweep against a healthy fingerprint)")
    sf.add_argument("--reference", metavar="FILE", help="healthy sweep (.s2p, or an FRA instrument's CSV export); "
                    "gives the DL/T 911 factors and verdict of --measured against it, and with two-port sweeps "
                    "fits a winding model to it and names the change that explains --measured")
    sf.add_argument("--repeat", metavar="FILE", help="a second healthy sweep (.s2p or CSV): the spread of the healthy "
                    "pair per band, and the change judged against it")
    sf.add_argument("--no-model", action="store_true", help="SFRA: the standard's factors (and --repeat) only, no "
                    "winding model")
    sf.add_argument("--sections", type=_sections, metavar="N", help="force the section count of the reference model")
    sf.add_argument("--cache", metavar="DIR", help="reference-model cache (default $PRIS_COSIM_CACHE or "
                    "~/.cache/pris-cosim)")
    sf.add_argument("--no-cache", action="store_true", help="refit the reference model, do not use the cache")
    sf.add_argument("--model-out", metavar="FILE", help="write the fitted fault model as a Touchstone file (.s2p)")
    sf.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=cmd_diagnose)


def _tolerance(text: str) -> float:
    """``--tolerance``: a positive relative value (``0.2``, ``20%``) or ``inf``."""
    t = text.strip().lower()
    if t in ("inf", "infinity", "none", "free"):
        return float("inf")
    try:
        v = float(t[:-1]) / 100 if t.endswith("%") else si_value(t)
    except (ValueError, argparse.ArgumentTypeError):
        raise argparse.ArgumentTypeError(f"--tolerance must be a positive number or inf, got {text!r}") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"--tolerance must be a positive number or inf, got {text!r}")
    return v


def _sections(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sections must be an integer, got {text!r}") from None
    if not 1 <= n <= 40:
        raise argparse.ArgumentTypeError(f"--sections must be 1..40, got {n}")
    return n


def cmd_diagnose(args: argparse.Namespace) -> int:
    from pris_cosim.cli.common import _emit
    from pris_cosim.measured.formats import Waveforms, load_measured

    from estimation.diagnosis.fit import DiagnosisError

    if getattr(args, "reference", None) is not None:
        from estimation.diagnosis.sfra.cli import print_text, run_sfra

        out = run_sfra(args)
        if args.json:
            _emit(_plain(out))
        else:
            print_text(out)
            if args.report:
                print(f"report: {out['report']}", file=sys.stderr)
        return 0
    for opt in ("sections", "cache", "model_out", "repeat"):
        if getattr(args, opt, None) is not None:
            raise DiagnosisError(f"--{opt.replace('_', '-')} needs --reference")
    if getattr(args, "no_model", False):
        raise DiagnosisError("--no-model needs --reference")
    data = load_measured(args.measured, segment=args.segment)
    source_given = None not in (args.rpris, args.lpris, args.cpris)
    if isinstance(data, Waveforms) and source_given and (args.model or args.netlist or args.rload):
        # the whole arrangement replayed from the bridge voltage: source and winding (or known load) causes
        from estimation.diagnosis.waveform.command import diagnose_record

        diag = diagnose_record(data, args)
    elif isinstance(data, Waveforms) and (args.model or args.netlist):
        # a PRIS record of a winding: its input impedance diagnosed against the winding's design
        from pris_cosim.models.builtin import get_model
        from pris_cosim.circuits.netlist import read_netlist

        from estimation.diagnosis.report import write_report
        from estimation.diagnosis.waveform.winding import diagnose_winding_waveforms

        model = get_model(args.model) if args.model else None
        circuit = read_netlist(args.netlist) if args.netlist else None
        if circuit is not None and not args.port:
            raise DiagnosisError("a netlist baseline needs --port")
        diag = diagnose_winding_waveforms(data, model=model, circuit=circuit, port=args.port,
                                          tolerance=args.tolerance)
        diag.evidence["path"] = {"path": "h1", "why": "the source's nominal values (--rpris --lpris --cpris) "
                                 "not given: the winding's impedance from the H1 of v_in / i_in"}
        if args.report:
            write_report(diag, args.report, source=Path(args.measured).name + " (impedance from the PRIS record)")
    elif isinstance(data, Waveforms):
        if None in (args.rpris, args.lpris, args.cpris):
            raise DiagnosisError("waveform data needs the nominal source values --rpris --lpris --cpris (the source "
                                 "check on a resistive load), or --model / --netlist (a winding in the record)")
        from estimation.diagnosis.waveform.source import diagnose_waveforms
        from estimation.diagnosis.waveform.report import write_report as write_waveform_report

        diag = diagnose_waveforms(data, args.rpris, args.lpris, args.cpris, r_load=args.rload, progress=True)
        if args.report:
            write_waveform_report(diag, args.report)
    else:
        from pris_cosim.circuits.netlist import read_netlist
        from pris_cosim.models.builtin import get_model

        from estimation.diagnosis.diagnose import diagnose_frequency
        from estimation.diagnosis.report import write_report

        model = get_model(args.model) if args.model else None
        circuit = read_netlist(args.netlist) if args.netlist else None
        if circuit is not None and not args.port:
            raise DiagnosisError("a netlist baseline needs --port")
        diag = diagnose_frequency(data.frequency_hz, data.responses, model=model, circuit=circuit, port=args.port,
                                  tolerance=args.tolerance, uncertainty=getattr(data, "uncertainty", None) or None)
        if args.report:
            write_report(diag, args.report, source=Path(args.measured).name + (f" [{args.segment}]" if args.segment else ""))
    out = diag.as_json()
    if "path" not in out and isinstance(diag.evidence.get("path"), dict):
        out["path"] = diag.evidence["path"]  # which path a waveform record took, and why
    if isinstance(out.get("realisation"), dict):
        out["realisation"] = {k: v for k, v in out["realisation"].items() if k != "circuit"}
    if args.report:
        out["report"] = str(Path(args.report) / "report.md")
    if args.json:
        _emit(_plain(out))
    else:
        print(f"cause: {out['cause']}  gain: {out['gain']:.3f}")
        path = out.get("path")
        if isinstance(path, dict):
            print(f"path: {path.get('path')} ({path.get('why')})")
        if out.get("causes") and len(out["causes"]) > 1:
            print(f"causes: {' + '.join(out['causes'])}")
        if out.get("misfit"):
            print(f"  {out['misfit']}")
        for d in out.get("drift") or []:
            print(f"  drift {d['name']}: " + (f"{', '.join(d['members'])} together x{d['ratio']:.3g}" if d.get("group")
                  else f"design {d['design']:.4g}, fitted {d['fitted']:.4g} (x{d['ratio']:.3g})"))
            if d.get("parallel"):
                print(f"    ({parallel_note(d)})")
        for a in out.get("drift_alternatives") or []:
            print(f"  or {a['name']} alone: design {a['design']:.4g}, fitted {a['fitted']:.4g} (x{a['ratio']:.3g}, "
                  f"BIC {a['delta_bic']:+.1f})")
        for c in out.get("cause_alternatives") or []:
            print(f"  barely told from {c['cause']} (BIC {c['delta_bic']:+.1f})")
        for c in out["candidates"]:
            print(f"  {c['cause']:<24} cost {c['cost']:.4g}  gain {c['gain']:.3f}")
        if args.report:
            print(f"report: {out['report']}", file=sys.stderr)
    return 0


def _plain(obj: Any) -> Any:
    """JSON-safe copy: numpy scalars to floats, tuples to lists."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return _plain(obj.item())
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
