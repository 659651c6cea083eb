"""The ``diagnose --reference HEALTHY.s2p --measured NEW.s2p`` path of the command line."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["is_sfra", "run_sfra"]


def is_sfra(args: argparse.Namespace) -> bool:
    """Whether the SFRA path applies: ``--reference`` given."""
    return getattr(args, "reference", None) is not None


def run_sfra(args: argparse.Namespace) -> dict[str, Any]:
    """Diagnose ``args.measured`` against ``args.reference``; returns the JSON object.

    Writes the report when ``args.report`` is set.  Progress on stderr unless ``--quiet``.

    Raises
    ------
    MeasuredDataError, DiagnosisError
        One-line input problems (the command line turns them into exit status 2).
    """
    from estimation.diagnosis.fit import DiagnosisError
    from pris_cosim.measured.touchstone import ports_from_extension

    from estimation.diagnosis.sfra.faults import diagnose_sweep
    from estimation.diagnosis.sfra.fingerprint import load_or_fit
    from estimation.diagnosis.sfra.indices import comparison_indices
    from estimation.diagnosis.sfra.sweep import load_sweep

    progress = not getattr(args, "quiet", False)
    for opt, path in (("--measured", args.measured), ("--reference", args.reference)):
        if ports_from_extension(path) is None and Path(path).suffix.lower() != ".ts":
            raise DiagnosisError(f"{path}: {opt} with --reference needs a two-port Touchstone file (.s2p)")
    if getattr(args, "segment", None):
        raise DiagnosisError("--segment does not apply to Touchstone sweeps")
    t0 = time.perf_counter()
    ref = load_sweep(args.reference)
    new = load_sweep(args.measured)
    fp = load_or_fit(ref, getattr(args, "cache", None), n_sections=getattr(args, "sections", None), progress=progress,
                     use_cache=not getattr(args, "no_cache", False))
    if progress:
        print(f"[sfra] diagnosing {Path(args.measured).name} ({fp.n_sections} sections)", file=sys.stderr, flush=True)
    diag = diagnose_sweep(fp, ref, new, progress=progress)
    out = diag.as_json()
    out["indices"] = comparison_indices(ref.frequency_hz, -ref.y[:, 1], -new.y[:, 1])
    out["measured"] = str(args.measured)
    out["reference"] = str(args.reference)
    out["seconds"] = time.perf_counter() - t0
    if getattr(args, "report", None):
        from estimation.diagnosis.sfra.report import write_report

        out["report"] = str(write_report(diag, out, args.report))
    if getattr(args, "model_out", None):
        from pris_cosim.measured.touchstone import write_touchstone
        from estimation.diagnosis.sfra.winding import admittance

        f = ref.frequency_hz
        write_touchstone(args.model_out, f, admittance(diag.fault_model, f), "Y", "RI", "Hz", 50.0,
                         [f"pris-cosim SFRA model: {diag.cause}, {fp.n_sections} sections"])
        out["model_out"] = str(args.model_out)
    return out


def print_text(out: dict[str, Any]) -> None:
    """Human-readable summary on stdout."""
    where = (f"  section {out['section']}/{out['model_order']} ({out['location']:.3f} from port 1)"
             if out.get("location") is not None else "")
    print(f"cause: {out['cause']}{where}  gain: {out['gain']:.3f}")
    sev = out.get("severity") or {}
    if sev.get("fault_resistance_ohm") is not None:
        print(f"  shorted fraction {sev['shorted_fraction']:.3f}, fault resistance {sev['fault_resistance_ohm']:.4g} Ohm "
              f"(referred to the section), {sev.get('kind')}")
    for c in out["candidates"]:
        print(f"  {c['cause']:<20} section {c['section']:>2}  gain {c['gain']:.3f}  dBIC {c['dBIC']:.1f}")
    for band, v in out["indices"].items():
        if v["cc"] is not None:
            print(f"  {band:<14} CC {v['cc']:.4f}  ASLE {v['asle']:.3f} dB  SD {v['sd']:.3f} dB")
