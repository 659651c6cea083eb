"""Command-line command ``lab``: the virtual laboratory of thesis 5.1 (added by :func:`register`).

``pris-cosim lab [--model NAME | --netlist FILE] --out FILE.csv [--quick] [--no-noise] [--seed N]
[--configs LVOC,LVSC,...] [--plots DIR] [--json]`` perturbs a two-winding
model in the six test configurations with the thesis's LV and HV PRIS
sources, measures through the anti-alias filter and the 16-bit ADC, and
writes the six estimated responses in the interfaces CSV format
(``frequency_hz,Zlvoc_mag,Zlvoc_phase_deg,Zlvoc_ln_sd,...``: ``NAME_ln_sd`` is
the standard deviation of ``ln|H|`` from the coherence; only frequencies the
PRBS excites are written, see :func:`pris_cosim.lab.virtual_lab.run_lab`). The default model is the
built-in ``hv-6section-freqdep`` (passive six-section transformer with the
frequency-dependent effects of (2.4)-(2.6)). ``--plots DIR`` writes the
measured-versus-analytic responses (Figs. 5.5 and 5.9 analogues), and the
waveforms and spectra of the LVOC records.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from pris_cosim.cli.common import UsageError, _emit

DEFAULT_MODEL = "hv-6section-freqdep"


def register(sub: Any) -> None:
    """Add the ``lab`` sub-command."""
    p = sub.add_parser("lab", help="virtual laboratory: the six PRIS-measured responses of a two-winding model")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--model", metavar="NAME", default=None, help=f"two-winding model (default {DEFAULT_MODEL})")
    src.add_argument("--netlist", metavar="FILE", help="netlist with nodes a1 (LV) and b1 (HV)")
    p.add_argument("--out", required=True, metavar="FILE.csv", help="responses CSV to write")
    p.add_argument("--quick", action="store_true", help="shorter PRBS (13/11 instead of 16/13), same clocks")
    p.add_argument("--no-noise", action="store_true", help="no ADC noise or quantisation (filter kept)")
    p.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    p.add_argument("--configs", metavar="LIST", help="comma-separated subset of LVOC,LVSC,HVOC,HVSC,LVHV,HVLV")
    p.add_argument("--plots", metavar="DIR", help="write response, waveform and spectrum plots here")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_lab)


def _model(args: argparse.Namespace) -> Any:
    from pris_cosim.circuits.netlist import read_netlist
    from pris_cosim.models.builtin import Model, get_model, two_winding_configurations

    if args.netlist:
        circuit = read_netlist(args.netlist)
        for node in ("a1", "b1"):
            circuit.require_node(node, f"two-winding terminal (netlist {args.netlist})")
        return Model(Path(args.netlist).stem, f"netlist {args.netlist}", circuit, two_winding_configurations())
    model = get_model(args.model or DEFAULT_MODEL)
    if "LVOC" not in model.configurations:
        raise UsageError(f"model {model.name!r} is not a two-winding model (no LVOC ... configurations)")
    return model


def cmd_lab(args: argparse.Namespace) -> int:
    """``lab``: write the six responses; with ``--json`` print ``out``, ``responses``, ``points``, ``wall_s``."""
    from pris_cosim.lab import virtual_lab as vl

    t0 = time.perf_counter()
    model = _model(args)
    configs = [c.strip().upper() for c in args.configs.split(",") if c.strip()] if args.configs else None
    for c in configs or ():
        if c not in vl.ALL_CONFIGS:
            raise UsageError(f"--configs: unknown configuration {c!r} (known: {', '.join(vl.ALL_CONFIGS)})")
    out = Path(args.out)
    if out.parent and not out.parent.exists():
        raise UsageError(f"--out: directory {out.parent} does not exist")
    print(f"virtual lab: {model.name}, {'quick' if args.quick else 'full'} records", file=sys.stderr, flush=True)
    keep = ["LVOC"] if args.plots and (configs is None or "LVOC" in configs) else False
    res = vl.run_lab(model, configs, seed=args.seed, noise=not args.no_noise, quick=args.quick, keep_records=keep)
    vl.write_lab_csv(out, res.measured)
    plots: list[str] = []
    if args.plots:
        plots += [str(p) for p in vl.plot_lab(res, model, args.plots)]
        for rec in res.records.values():
            plots += [str(p) for p in vl.plot_record(rec, args.plots)]
    summary = {"out": str(out), "model": model.name, "responses": list(res.measured.responses),
               "points": int(res.measured.frequency_hz.size), "plots": plots, "wall_s": time.perf_counter() - t0}
    if args.json:
        _emit(summary)
    else:
        print(f"{len(summary['responses'])} responses, {summary['points']} points -> {out} ({summary['wall_s']:.1f} s)")
    return 0
