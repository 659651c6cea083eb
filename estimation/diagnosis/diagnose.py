"""Frequency-response diagnosis: fit the baseline, fit every extension, choose by BIC, measure the gain.

Selection: each extension is fitted together with the baseline's own values;
the one with the lowest Bayesian information criterion
``BIC = N ln(RSS/N) + k ln N`` wins only if it beats the baseline's BIC by
at least ``min_delta_bic`` (10: "very strong" evidence on Kass and
Raftery's scale) and removes at least ``min_gain`` of the baseline cost.
Otherwise the diagnosis is ``none``: nothing beyond noise. An extra
parameter therefore never wins by itself.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.circuit import Circuit
from pris_cosim.frf import Response
from pris_cosim.models import Configuration, Model, get_model, lumped_rlc

from .catalogue import CoreLoss, Extension, MissingSection, frequency_extensions
from ..resonances import count_parallel, find_resonances
from .evidence import band_table, localise, resonance_comparison
from .fit import DiagnosisError, FitResult, FrequencyFit, significant

MAX_BASELINE_RMS = 2.3  # complex-log RMS error (20 dB) beyond which the baseline "does not fit at all"


@dataclass
class Diagnosis:
    """Result of a diagnosis (see :meth:`as_json` for the command-line keys)."""

    cause: str
    baseline: FitResult
    best: FitResult | None
    fits: list[FitResult]
    frequency_hz: np.ndarray
    measured: dict[str, np.ndarray]
    evidence: dict[str, Any] = field(default_factory=dict)
    realisation: dict[str, Any] = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def gain(self) -> float:
        return 0.0 if self.best is None else 1 - self.best.cost / self.baseline.cost

    def candidates(self) -> list[dict[str, Any]]:
        rows = []
        for r in self.fits:
            rows.append({
                "cause": r.cause, "cost": r.cost, "gain": 1 - r.cost / self.baseline.cost, "bic": r.bic,
                "delta_bic": self.baseline.bic - r.bic, "n_params": r.n_params, "extra": r.extra,
                "wall_s": r.wall_s,
            })
        return rows

    def as_json(self) -> dict[str, Any]:
        return {
            "cause": self.cause,
            "candidates": self.candidates(),
            "baseline_cost": self.baseline.cost,
            "extended_cost": self.best.cost if self.best else self.baseline.cost,
            "gain": self.gain,
            "baseline_bic": self.baseline.bic,
            "fitted_extension": self.best.extra if self.best else {},
            "baseline_values": self.baseline.values,
            "extended_values": self.best.values if self.best else {},
            "evidence": self.evidence,
            "realisation": self.realisation,
            "wall_s": self.wall_s,
        }


def _log(msg: str, progress: bool) -> None:
    if progress:
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)


def lumped_from_data(f: np.ndarray, z: np.ndarray) -> list[Model]:
    """Starting lumped R-L-C models estimated from one-port data (several capacitance guesses)."""
    w = 2 * np.pi * f
    k = max(1, f.size // 20)
    l0 = float(np.median(z[:k].imag / w[:k]))
    if not l0 > 0:
        raise DiagnosisError("one-port data is not inductive at low frequency; give a baseline model")
    r0 = float(max(np.median(z[:k].real), 1e-6 * np.abs(z[0])))
    peak = f[int(np.argmax(np.abs(z)))]
    guesses = [peak, 3 * f[-1], 10 * f[-1]]
    return [lumped_rlc(r0, l0, 1 / ((2 * np.pi * fr) ** 2 * l0)) for fr in guesses]


def diagnose_frequency(
    frequency_hz: np.ndarray,
    measured: Mapping[str, np.ndarray],
    model: Model | None = None,
    circuit: Circuit | None = None,
    port: str | None = None,
    min_delta_bic: float = 10.0,
    min_gain: float = 0.2,
    progress: bool = True,
) -> Diagnosis:
    """Diagnose measured frequency responses against a baseline model.

    Parameters
    ----------
    frequency_hz : numpy.ndarray, Hz
    measured : mapping
        Response name (``Zin``, ``Zlvoc`` ...) to complex values.
    model : Model, optional
        Baseline with test configurations (two-winding models, built-ins).
    circuit, port : Circuit, str, optional
        Baseline given as a one-port netlist driven at ``port`` (response ``Zin``).
    min_delta_bic, min_gain : float
        Thresholds for naming a cause instead of ``none``.
    progress : bool
        Progress lines on stderr.

    Returns
    -------
    Diagnosis
    """
    t0 = time.perf_counter()
    f = np.asarray(frequency_hz, float)
    data = {k: np.asarray(v, complex) for k, v in measured.items()}
    if not data:
        raise DiagnosisError("no measured responses")
    if circuit is not None:
        if port is None:
            raise DiagnosisError("a netlist baseline needs --port")
        model = Model("netlist", circuit.title, circuit,
                      {"default": Configuration("default", port, (), (Response("Zin"),))})
    fixed = tuple(model.fixed) if model is not None else ()
    # ---- baseline
    if model is None:
        if len(data) != 1:
            raise DiagnosisError(f"no baseline given: one-port data expected, got responses {', '.join(data)}")
        name = next(iter(data))
        data = {"Zin": data[name]}
        starts = lumped_from_data(f, data["Zin"])
        fits = [FrequencyFit(m.circuit, list(m.configurations.values()), f, data).fit() for m in starts]
        best_i = int(np.argmin([r.cost for r in fits]))
        baseline = fits[best_i]
        model = Model("lumped-rlc", "Lumped R-L-C fitted to the data", baseline.circuit.with_values(baseline.values),
                      starts[best_i].configurations, family=("lumped",))
        _log(f"no baseline given: lumped R-L-C fitted (cost {baseline.cost:.4g})", progress)
    else:
        baseline = FrequencyFit(model.circuit, list(model.configurations.values()), f, data, fixed).fit()
        _log(f"baseline {model.name} fitted: cost {baseline.cost:.4g} in {baseline.wall_s:.1f} s", progress)
    worst = max(float(np.sqrt(np.mean(np.abs(e) ** 2))) for e in baseline.errors.values())
    if worst > MAX_BASELINE_RMS:
        raise DiagnosisError(
            f"the baseline does not fit the data at all (RMS error {20 / np.log(10) * worst:.1f} dB after fitting); "
            "check the port, the test configuration or the model"
        )
    fitted_model = Model(model.name, model.description, baseline.circuit.with_values(baseline.values),
                         model.configurations, model.fixed, model.family)
    values = fitted_model.circuit.resolve(check=False)
    impedance_scale = float(np.median([np.median(np.abs(v)) for k, v in data.items() if k.startswith("Z")] or [1.0]))
    # ---- candidates
    results: list[FitResult] = []
    for ext in frequency_extensions(fitted_model, f[0], f[-1]):
        t = time.perf_counter()
        if isinstance(ext, MissingSection):
            res = _fit_missing_section(ext, values, f, data, fixed)
        else:  # from the fitted baseline and from the nominal values (the baseline fit may have bent them)
            res = None
            for circuit in ((fitted_model.circuit, model.circuit) if model.circuit is not fitted_model.circuit
                            else (fitted_model.circuit,)):
                fit = FrequencyFit(circuit, list(model.configurations.values()), f, data, fixed, extension=ext)
                starts = ext.starts(fit.circuit, values, impedance_scale) if isinstance(ext, CoreLoss) else None
                trial = fit.fit(starts)
                if res is None or trial.cost < res.cost:
                    res = trial
        if res is None:
            continue
        results.append(res)
        _log(f"{ext.cause}: cost {res.cost:.4g}, gain {1 - res.cost / baseline.cost:.3f}, "
             f"dBIC {baseline.bic - res.bic:.1f} ({time.perf_counter() - t:.1f} s)", progress)
    # ---- selection: lowest BIC among the fits that reproduce the measured resonance count
    target_count = _parallel_count(f, data)
    matching = [r for r in results if _parallel_count(f, r.predicted) == target_count]
    pool = matching if matching and _parallel_count(f, baseline.predicted) != target_count else results
    best = min(pool, key=lambda r: r.bic) if pool else None
    chosen = None
    if best is not None and significant(baseline.bic, baseline.cost, best.bic, best.cost, min_delta_bic, min_gain):
        chosen = best
    diag = Diagnosis(chosen.cause if chosen else "none", baseline, chosen, results, f, data)
    diag.evidence = {
        "baseline_model": model.name,
        "localisation": localise(f, data, baseline.errors),
        "resonances": resonance_comparison(f, data, baseline.predicted),
        "bands_before": band_table(f, baseline.errors),
        "bands_after": band_table(f, chosen.errors) if chosen else [],
        "gain_per_response": ({n: 1 - float(np.mean(np.abs(chosen.errors[n]) ** 2) / np.mean(np.abs(baseline.errors[n]) ** 2))
                               for n in data} if chosen else {}),
        "criterion": (f"lowest BIC among the fits that reproduce the measured number of parallel resonances "
                      f"({target_count}) when the baseline does not; named only if dBIC >= {min_delta_bic} "
                      f"and gain >= {min_gain}"),
    }
    if chosen is not None:
        diag.realisation = _realise(chosen, fitted_model, f)
    diag.wall_s = time.perf_counter() - t0
    _log(f"cause: {diag.cause} (gain {diag.gain:.3f}) in {diag.wall_s:.1f} s", progress)
    return diag


def _parallel_count(f: np.ndarray, responses: Mapping[str, np.ndarray]) -> int:
    """Parallel resonances summed over the impedance responses."""
    return sum(count_parallel(find_resonances(f, v)) for k, v in responses.items() if k.startswith("Z"))


def _fit_missing_section(ext: MissingSection, values: Mapping[str, float], f: np.ndarray,
                         data: Mapping[str, np.ndarray], fixed: tuple[str, ...]) -> FitResult | None:
    best = None
    family = ext.model.family if ext.model else ()
    staged = []
    for circuit, _added in ext.candidates(values):
        if family and family[0] == "two-winding":
            configs = list(ext.model.configurations.values())
        else:
            configs = [Configuration("default", "n1", (), (Response("Zin"),))]
        try:  # a short fit from every start, then the best two refined
            first = FrequencyFit(circuit, configs, f, data, fixed).fit(max_nfev=60, cause="missing-section")
        except DiagnosisError:
            continue
        staged.append((first.cost, circuit.with_values(first.values), configs))
    staged.sort(key=lambda t: t[0])
    for _, circuit, configs in staged[:2]:
        res = FrequencyFit(circuit, configs, f, data, fixed).fit(max_nfev=300, cause="missing-section")
        if best is None or res.cost < best.cost:
            best = res
    return best


def _realise(chosen: FitResult, model: Model, f: np.ndarray) -> dict[str, Any]:
    """Time-domain realisation of the extension (ladders) and how closely it follows the formula fit."""
    exts = {e.cause: e for e in frequency_extensions(model, f[0], f[-1])}
    ext: Extension | None = exts.get(chosen.cause)
    if ext is None or isinstance(ext, MissingSection):
        return {"kind": "circuit", "elements": len(chosen.circuit.elements), "note": "a plain R-L-C-K circuit"}
    circuit = chosen.circuit.with_values(chosen.values)
    values = circuit.resolve(check=False)
    ladder = ext.realise(circuit, values, chosen.extra, float(f[0]), float(f[-1]))
    configs = list(model.configurations.values())
    fit = FrequencyFit(ladder, configs, f, {n: chosen.predicted[n] for n in chosen.predicted})
    pred = fit.predict(np.zeros(len(fit.free)))
    dev = max(float(np.max(np.abs(20 * np.log10(np.abs(pred[n] / chosen.predicted[n]))))) for n in pred)
    return {"kind": "ladder", "elements": len(ladder.elements), "max_deviation_db": dev,
            "note": "frequency-dependent elements realised as passive R-L ladders (simulable, FMU-ready)",
            "circuit": ladder}


def load_baseline(model_name: str | None) -> Model | None:
    return get_model(model_name) if model_name else None
