"""The extended model as a circuit of constant R, L, C, K: simulable in the time domain and exportable as an FMU."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from pris_cosim.errors import CircuitError, NonPassiveWarning
from pris_cosim.frf.response import ResponseModel
from pris_cosim.models.builtin import Configuration

from estimation.diagnosis.causes.catalogue import winding_groups
from estimation.diagnosis.fit import FitResult, configuration_ports, group_names

#: A realisation within these of the fitted formulas counts as faithful.
MAX_DEVIATION_DB = 0.5
MAX_DEVIATION_DEG = 3.0


def realise_extended(fit: FitResult, configurations: Sequence[Configuration], f: np.ndarray) -> dict[str, Any]:
    """Realise every effect of ``fit`` (ladders, lead, fixture branches) in its fitted circuit.

    Returns
    -------
    dict
        ``kind`` (``circuit`` or ``ladder``), ``elements``, ``circuit``, per
        effect its ``formula`` and ``note``, ``max_deviation_db`` /
        ``max_deviation_deg`` of the realised circuit's responses from the
        fitted model over the band, and ``realisable`` (within 0.5 dB and 3 deg).
    """
    circuit = fit.fitted_circuit()
    if not fit.effects:
        return {"kind": "circuit", "elements": len(circuit.elements), "circuit": circuit, "realisable": True,
                "max_deviation_db": 0.0, "max_deviation_deg": 0.0, "effects": [],
                "note": "a plain R-L-C-K circuit" + (f" ({fit.structure})" if fit.structure else "")}
    ports = configuration_ports(configurations)
    names = group_names(configurations)
    groups = winding_groups(circuit, ports, names)
    order = sorted(zip(fit.effects, fit.params), key=lambda t: t[0].group == "port")
    notes = []
    unrealised = False
    for eff, p in order:
        try:
            circuit, note = eff.realise(circuit, groups, p, float(f[0]), float(f[-1]))
        except (RuntimeError, ValueError, CircuitError) as exc:  # no passive network found for this formula
            unrealised = True
            note = f"no passive network found ({exc}); the formula is reported, the circuit leaves it out"
        notes.append({"cause": eff.cause, "form": eff.form, "group": eff.group, "formula": eff.formula(p),
                      "note": note})
    dev_db = dev_deg = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NonPassiveWarning)
        for cfg in configurations:
            wanted = [r for r in cfg.responses if r.name in fit.predicted]
            if not wanted:
                continue
            got = ResponseModel(circuit, cfg.port, shorts=cfg.shorts, responses=wanted).evaluate(f)
            for n, v in got.items():
                e = np.log(v / fit.predicted[n])
                dev_db = max(dev_db, float(np.max(np.abs(e.real))) * 20 / np.log(10))
                dev_deg = max(dev_deg, float(np.degrees(np.max(np.abs(e.imag)))))
    ok = dev_db <= MAX_DEVIATION_DB and dev_deg <= MAX_DEVIATION_DEG and not unrealised
    note = "frequency-dependent elements realised as passive networks (simulable, FMU-ready)"
    if not ok:
        note = ("the fitted formulas are not realised faithfully by a passive network (a real-valued R(f) or L(f) "
                "has no causal realisation); the formulas are reported, the circuit approximates them")
    return {"kind": "ladder", "elements": len(circuit.elements), "circuit": circuit, "effects": notes,
            "max_deviation_db": dev_db, "max_deviation_deg": dev_deg, "realisable": ok, "note": note}
