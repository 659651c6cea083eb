"""The ``diagnose --reference HEALTHY --measured NEW [--repeat HEALTHY2]`` path of the command line (SFRA)."""

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

    Two-port Touchstone sweeps get the winding-model diagnosis (unless ``--no-model``); every input,
    Touchstone or an instrument's CSV export, gets the DL/T 911 factors and verdict on the voltage ratio
    ``V_resp / V_ref`` and, with ``--repeat``, the repeatability judgement.  Writes the report when
    ``args.report`` is set.  Progress on stderr unless ``--quiet``.

    Raises
    ------
    MeasuredDataError, DiagnosisError
        One-line input problems (the command line turns them into exit status 2).
    """
    from estimation.diagnosis.fit import DiagnosisError

    from estimation.diagnosis.sfra.compare import FraTrace, is_touchstone, load_trace, standard_comparison
    from estimation.diagnosis.sfra.indices import DEFINITIONS, comparison_indices
    from estimation.diagnosis.sfra.sweep import load_sweep

    progress = not getattr(args, "quiet", False)
    if getattr(args, "segment", None):
        raise DiagnosisError("--segment does not apply to SFRA sweeps")
    t0 = time.perf_counter()
    roles = [("--reference", args.reference), ("--measured", args.measured)]
    if getattr(args, "repeat", None):
        roles.append(("--repeat", args.repeat))
    sweeps, traces = {}, {}
    for opt, path in roles:
        if is_touchstone(path):
            sw = load_sweep(path)
            sweeps[opt] = sw
            traces[opt] = FraTrace(sw.frequency_hz, sw.voltage_ratio, str(path))
        else:
            traces[opt] = load_trace(path)
    ref_t, new_t, rep_t = traces["--reference"], traces["--measured"], traces.get("--repeat")
    two_port = "--reference" in sweeps and "--measured" in sweeps
    no_model = bool(getattr(args, "no_model", False))
    if not two_port:
        csv = [opt for opt, _ in roles[:2] if opt not in sweeps]
        reason = (f"not fitted: {' and '.join(csv)} {'is' if len(csv) == 1 else 'are'} a voltage-ratio trace "
                  "(CSV); the winding model needs two-port sweeps (.s2p) for --reference and --measured")
        for opt in ("sections", "model_out"):
            if getattr(args, opt, None) is not None:
                raise DiagnosisError(f"--{opt.replace('_', '-')} needs two-port sweeps (.s2p) for --reference and "
                                     f"--measured ({' and '.join(csv)}: CSV)")
    elif no_model:
        reason = "not fitted (--no-model)"
        if getattr(args, "model_out", None):
            raise DiagnosisError("--model-out needs the winding model; leave out --no-model")
    else:
        reason = None
    std, rep = standard_comparison(ref_t, new_t, rep_t)
    diag = None
    if reason is None:
        from estimation.diagnosis.sfra.faults import diagnose_sweep
        from estimation.diagnosis.sfra.fingerprint import load_or_fit

        ref, new = sweeps["--reference"], sweeps["--measured"]
        fp = load_or_fit(ref, getattr(args, "cache", None), n_sections=getattr(args, "sections", None),
                         progress=progress, use_cache=not getattr(args, "no_cache", False))
        if progress:
            print(f"[sfra] diagnosing {Path(args.measured).name} ({fp.n_sections} sections)", file=sys.stderr,
                  flush=True)
        diag = diagnose_sweep(fp, ref, new, progress=progress)
        out = diag.as_json()
        if ref.frequency_hz.shape == new.frequency_hz.shape:
            out["indices"] = comparison_indices(ref.frequency_hz, -ref.y[:, 1], -new.y[:, 1])
        response = "-Y21, the end-to-end admittance of the two-port sweep"
    else:
        from estimation.diagnosis.sfra.compare import on_grid

        out = {"cause": None, "model_diagnosis": reason}
        h_new, inside = on_grid(ref_t.frequency_hz, new_t)
        out["indices"] = comparison_indices(ref_t.frequency_hz[inside], ref_t.h[inside], h_new[inside])
        response = "V_resp/V_ref"
    out["indices_definitions"] = {"response": response, **DEFINITIONS}
    out["standard_indices"] = std
    if rep is not None:
        out["repeatability"] = rep
    out["measured"] = str(args.measured)
    out["reference"] = str(args.reference)
    out["seconds"] = time.perf_counter() - t0
    if getattr(args, "report", None):
        if diag is not None:
            from estimation.diagnosis.sfra.report import write_report

            out["report"] = str(write_report(diag, out, args.report, repeat=rep_t))
        else:
            from estimation.diagnosis.sfra.report_fra import write_comparison_report

            out["report"] = str(write_comparison_report(out, ref_t, new_t, rep_t, args.report))
    if getattr(args, "model_out", None) and diag is not None:
        from pris_cosim.measured.touchstone import write_touchstone

        from estimation.diagnosis.sfra.winding import admittance

        f = sweeps["--reference"].frequency_hz
        write_touchstone(args.model_out, f, admittance(diag.fault_model, f), "Y", "RI", "Hz", 50.0,
                         [f"pris-cosim SFRA model: {diag.cause}, {diag.fingerprint.n_sections} sections"])
        out["model_out"] = str(args.model_out)
    return out


def print_text(out: dict[str, Any]) -> None:
    """Human-readable summary on stdout (the model's answer first when there is one)."""
    d = out["standard_indices"]["dlt911"]

    def r(x):
        return "-" if x is None else f"{x:.2f}"

    if out.get("cause") is not None:
        where = (f"  section {out['section']}/{out['model_order']} ({out['location']:.3f} "
                 f"± {out.get('location_std') or 0.0:.3f} from port 1)" if out.get("location") is not None else "")
        print(f"cause: {out['cause']}{where}  gain: {out['gain']:.3f}")
        sev = out.get("severity") or {}
        if sev.get("fault_resistance_ohm") is not None:
            print(f"  shorted fraction {sev['shorted_fraction']:.3f}, fault resistance "
                  f"{sev['fault_resistance_ohm']:.4g} Ohm (referred to the section), {sev.get('kind')}")
        for c in out["candidates"]:
            print(f"  {c['cause']:<20} section {c['section']:>2}  gain {c['gain']:.3f}  dBIC {c['dBIC']:.1f}")
    print(f"DL/T 911: {d['verdict'] or 'not determined'}  (R_LF {r(d['R_LF'])}, R_MF {r(d['R_MF'])}, "
          f"R_HF {r(d['R_HF'])}; {d['note']})")
    if out.get("repeatability"):
        print(f"repeatability: {out['repeatability']['summary']}")
    if out.get("cause") is None:
        print(f"winding model: {out.get('model_diagnosis')}")
    for band, v in out.get("indices", {}).items():
        if v["cc"] is not None:
            print(f"  {band:<14} CC {v['cc']:.4f}  ASLE {v['asle']:.3f} dB  SD {v['sd']:.3f} dB")
