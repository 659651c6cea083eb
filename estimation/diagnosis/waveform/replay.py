"""A PRIS record diagnosed by replaying the whole arrangement from its bridge voltage: source and winding causes.

A record ``time_s, v_bprbs, v_in, i_in`` of the PRIS source driving a
winding (or a known load) is replayed exactly from ``v_bprbs``
(:mod:`.replay_record`: the periodic response sampled with the bridge's
zero-order hold, plus the free response of the slow modes); the source's and
the winding's values are fitted together (:mod:`.replay_fit`), the source's
held by the instrument's tolerance (``source_tolerance``, default 1 %), the
winding's by the design tolerance.

One catalogue for the arrangement
    source: ``series-resistance`` (``R`` freed), ``component-drift`` (``L``
    and ``C`` freed), ``switch-ringing`` (``L_sw`` in series with the bridge,
    ``C_sw`` across it); winding: the frequency catalogue's one-port causes
    (:func:`.catalogue.effect_variants`: every form, the best kept) and the
    structural ``missing-section`` (:mod:`.replay_sections`: every section of
    the design split in two and a section added at each end, each a new
    problem on its circuit; the structure's own values count as parameters
    of the BIC below).

Selection
    Forward: the candidate adding one cause to the current model with the
    lowest ``BIC = chi^2 / s^2 + k ln N`` (``chi^2`` the weighted residuals'
    and the priors' squares, ``N`` the residuals, ``k`` the parameters,
    ``s^2 = max(1, chi^2_current / N)``: residuals above the record's noise are
    taken as an error of unknown scale) is named when it lowers the BIC by
    ``min_delta_bic`` and, above the noise (``s^2 > 1``), removes at least
    ``min_gain`` of the objective. Backward: a named cause whose removal
    raises the BIC by less than ``min_delta_bic`` is dropped. Then the
    tolerance: a source value still held by its prior but fitted beyond
    ``source_tolerance`` names its cause (``series-resistance`` for a larger
    resistance, ``component-drift`` for the others), and a freed one fitted
    within it does not. Winding values beyond ``tolerance`` are the drift.

When the record cannot be replayed exactly (the bridge voltage does not
repeat, or switches between samples) the winding is diagnosed from the H1 of
``v_in / i_in`` (:mod:`.winding_waveform`); the answer's ``path`` says which
and why.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.measured.formats import Waveforms
from pris_cosim.models.builtin import Configuration, Model, Response

from estimation.diagnosis.causes.catalogue import effect_variants, winding_groups
from estimation.diagnosis.fit import DiagnosisError
from estimation.diagnosis.prior import DEFAULT_TOLERANCE, DesignPrior
from estimation.diagnosis.waveform.joint_fit import Part, ReplayFit, ReplayProblem
from estimation.diagnosis.waveform.replay_sections import CAUSE as SECTION_CAUSE
from estimation.diagnosis.waveform.replay_sections import best_section, section_structures
from estimation.diagnosis.waveform.record_spectra import PeriodicRecord, periodic_record
from estimation.diagnosis.result import DiagnosisOutcome
from estimation.diagnosis.waveform.signals import SIGNALS, UNITS

#: The arrangement's catalogue: the source's causes, then the winding's.
SOURCE_CAUSES = ("series-resistance", "component-drift", "switch-ringing")
WINDING_CAUSES = ("core-loss", "skin-effect", "magnetising-inductance", "stray-capacitance", "lead-inductance")
#: The winding's structural cause: a section more than the design (:mod:`.replay_sections`).
STRUCTURAL_CAUSES = (SECTION_CAUSE,)
#: Default relative tolerance of the source's nominal values (the instrument's own).
DEFAULT_SOURCE_TOLERANCE = 0.01
#: Evaluations of the short fit that screens each form of a cause (the best form is then refined).
SCREEN_NFEV = 4
#: Evaluations of a further cause's fit together with the causes named.
COMBO_NFEV = 25
_SRC_NAMES = {"r": "rpris", "l": "lpris", "c": "cpris", "lsw": "lsw", "csw": "csw"}


def _log(msg: str, progress: bool) -> None:
    if progress:
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)


@dataclass
class ReplayDiagnosis(DiagnosisOutcome):
    """Result of the arrangement's diagnosis (see :meth:`as_json`)."""

    baseline: ReplayFit
    best: ReplayFit | None
    fits: list[ReplayFit]
    nominal: dict[str, float] = field(default_factory=dict)
    drift: list[dict[str, Any]] = field(default_factory=list)
    tolerance: float = DEFAULT_TOLERANCE
    source_tolerance: float = DEFAULT_SOURCE_TOLERANCE
    path: dict[str, str] = field(default_factory=dict)

    @property
    def final(self) -> ReplayFit:
        return self.best if self.best is not None else self.baseline

    @property
    def gain(self) -> float:
        """Fraction of the baseline's objective (weighted residuals and priors) the named causes remove."""
        return 0.0 if self.best is None else max(0.0, 1 - self.best.objective / self.baseline.objective)

    def source_values(self, fit: ReplayFit) -> dict[str, float]:
        return {_SRC_NAMES[k]: v for k, v in fit.source.items()}

    def as_json(self) -> dict[str, Any]:
        """The frequency path's keys (``cause``, ``causes``, ``steps``, ``drift``, ``unexplained``,
        ``noise_floor``, ``gain``) plus ``path``, the fitted source and winding values and the evidence."""
        fin = self.final
        return {
            "cause": self.cause, "causes": list(self.causes), "steps": list(self.steps),
            "candidates": [{"cause": r.cause, "forms": [p.label for p in r.parts], "cost": r.cost,
                            "objective": r.objective, "gain": max(0.0, 1 - r.objective / self.baseline.objective),
                            "bic": r.bic, "delta_bic": self.baseline.bic - r.bic, "n_params": r.n_params,
                            "wall_s": r.wall_s} for r in self.fits],
            "drift": list(self.drift), "unexplained": list(self.unexplained),
            "noise_floor": self.noise.get("cost", 0.0), "noise": self.noise, "gain": self.gain,
            "baseline_cost": self.baseline.cost, "extended_cost": fin.cost, "tolerance": self.tolerance,
            "source_tolerance": self.source_tolerance, "path": dict(self.path),
            "source_nominal": dict(self.nominal), "source_values": self.source_values(fin),
            "baseline_source_values": self.source_values(self.baseline), "winding_values": dict(fin.winding),
            "fitted_extension": [{"form": p.label, **vals} for p, vals in
                                 zip([p for p in fin.parts if p.effect is not None], fin.extra)],
            "evidence": self.evidence, "wall_s": self.wall_s,
        }


def _significant(cur: ReplayFit, new: ReplayFit, min_delta_bic: float, min_gain: float) -> tuple[bool, float, float]:
    """Whether ``new`` beats ``cur``: its BIC drop (residuals scaled by ``s^2``) and its gain."""
    s2 = max(1.0, cur.rss / cur.n_residuals)
    dbic = (cur.objective - new.objective) / s2 - (new.n_params - cur.n_params) * math.log(cur.n_residuals)
    gain = 1 - new.objective / cur.objective
    return dbic >= min_delta_bic and (s2 <= 1.0 or gain >= min_gain), dbic, gain


class _Catalogue:
    """Builds and fits the problems of sets of parts."""

    def __init__(self, rec, circuit, configs, response, fixed, nominal, source_tolerance, tolerance, scale, design):
        self.args = (rec, circuit, configs, response, fixed, nominal, source_tolerance, tolerance)
        self.scale, self.design = scale, design
        self.prior = DesignPrior(design, tolerance, 1.0, {e.name.lower(): tuple(e.nodes) for e in circuit.elements})
        groups = winding_groups(circuit, [configs[0].port])
        self.variants: dict[str, list[Part]] = {c: [Part(c)] for c in SOURCE_CAUSES}
        for c in WINDING_CAUSES:
            vs = effect_variants(c, groups, circuit, float(rec.f[0]), True, scale, float(rec.f[-1]),
                                 level=math.isfinite(tolerance))
            if vs:
                self.variants[c] = [Part(c, e) for e in vs]
        self.structures = section_structures(circuit, configs[0].port)
        if self.structures:  # searched by :func:`.replay_sections.best_section`, not by forms
            self.variants[SECTION_CAUSE] = []
        self.progress = False

    def problem(self, parts: Sequence[Part]) -> ReplayProblem:
        """The record's problem with ``parts`` (a structural part brings its own circuit)."""
        return ReplayProblem(*self.args, parts, self.scale, self.design, self.prior.anchored)

    def fit(self, parts: Sequence[Part], start: ReplayFit | None, max_nfev: int = 40, screen: int = 2,
            theta: np.ndarray | None = None) -> ReplayFit:
        prob = self.problem(parts)
        t = time.perf_counter()
        r = prob.fit([theta] if theta is not None else prob.start_from(start), max_nfev=max_nfev, screen=screen)
        r.wall_s = time.perf_counter() - t
        return r

    def best_with(self, current: ReplayFit, cause: str) -> ReplayFit | None:
        """``current``'s parts plus the best form of ``cause``: every form screened by a short fit from
        ``current``, the best refined (unless none ends below ``current``); for the structural cause the best
        structure (:func:`.replay_sections.best_section`, None when none can be fitted)."""
        t = time.perf_counter()
        if cause == SECTION_CAUSE:
            return best_section(self.problem, current, self.structures, lambda m: _log(m, self.progress))
        forms = self.variants[cause]
        if len(forms) == 1:
            return self.fit(list(current.parts) + forms, current)
        short = [self.fit(list(current.parts) + [part], current, max_nfev=SCREEN_NFEV, screen=1) for part in forms]
        best = min(short, key=lambda r: r.objective)
        if best.objective >= current.objective:  # no form helps after its short fit: not refined
            best.wall_s = time.perf_counter() - t
            return best
        r = self.fit(best.parts, None, theta=best.theta)
        r.wall_s = time.perf_counter() - t
        return r


def diagnose_pris_record(
    w: Waveforms,
    rpris: float,
    lpris: float,
    cpris: float,
    model: Model | None = None,
    circuit: Circuit | None = None,
    port: str | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    source_tolerance: float = DEFAULT_SOURCE_TOLERANCE,
    min_delta_bic: float = 10.0,
    min_gain: float = 0.2,
    max_causes: int = 3,
    progress: bool = True,
) -> DiagnosisOutcome:
    """Diagnose a PRIS record of a winding (or a known load) and its source from the bridge voltage.

    Parameters
    ----------
    w : Waveforms
        ``time_s`` (s), ``v_bprbs`` (V, exact), ``v_in`` (V), ``i_in`` (A).
    rpris, lpris, cpris : float, Ohm, H, F
        The source's nominal values.
    model : Model, optional
        Built-in one-port model of the winding, or
    circuit, port : Circuit, str, optional
        the winding's (or load's) netlist and the node the source drives.
    tolerance : float
        Relative tolerance of the winding's design values (``inf``: free).
    source_tolerance : float
        Relative tolerance of the source's nominal values (default 0.01).
    min_delta_bic, min_gain, max_causes
        Selection thresholds (module docstring).
    progress : bool
        Progress lines on stderr.

    Returns
    -------
    ReplayDiagnosis, or the H1 path's Diagnosis when the record cannot be replayed exactly (``evidence["path"]``).
    """
    t0 = time.perf_counter()
    for name, v in (("rpris", rpris), ("lpris", lpris), ("cpris", cpris)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise DiagnosisError(f"--{name} must be a positive number (got {v!r})")
    if not (source_tolerance > 0):
        raise DiagnosisError(f"--source-tolerance must be a positive number or inf, got {source_tolerance!r}")
    if circuit is not None:
        if port is None:
            raise DiagnosisError("a netlist baseline needs --port")
        try:
            port = circuit.require_node(port, "port")
        except CircuitError as exc:
            raise DiagnosisError(f"baseline: {exc}") from None
        config = Configuration("default", port, (), (Response("Zin"),))
        model = Model("netlist", circuit.title, circuit, {"default": config})
    if model is None:
        raise DiagnosisError("the arrangement's replay needs the winding: --model or --netlist with --port")
    configs = list(model.configurations.values())
    names = [r.name for c in configs for r in c.responses if r.name.startswith("Z")]
    if len(configs) != 1 or not names:
        raise DiagnosisError(f"model {model.name!r} has several test configurations; a PRIS record gives one "
                             "input impedance: give a one-port model or a netlist with --port")
    rec, why = periodic_record(w)
    if rec is None:
        from estimation.diagnosis.waveform.winding import diagnose_winding_waveforms

        _log(f"H1 path: {why}", progress)
        d = diagnose_winding_waveforms(w, progress=progress, model=model if circuit is None else None,
                                       circuit=circuit, port=port, tolerance=tolerance)
        d.evidence["path"] = {"path": "h1", "why": why + "; the winding's impedance from the H1 of v_in / i_in "
                              "(the source's causes are not diagnosed)"}
        return d
    _log(f"exact replay: {why}; {rec.info['bins']} bins, {rec.info['band_hz'][0]:.4g} - "
         f"{rec.info['band_hz'][1]:.4g} Hz", progress)
    nominal = {"rpris": float(rpris), "lpris": float(lpris), "cpris": float(cpris)}
    circ = model.circuit
    probe = ReplayProblem(rec, circ, configs, names[0], model.fixed, nominal, source_tolerance, tolerance, [], 1.0, {})
    design = {n.lower(): float(v) for n, v in zip(probe.ff.free, probe.ff.start)}
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = float(np.median(np.abs(rec.Y[:, 0] / rec.Y[:, 1])))
    cat = _Catalogue(rec, circ, configs, names[0], model.fixed, nominal, source_tolerance, tolerance, scale, design)
    cat.progress = progress
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        try:
            return _select(cat, rec, nominal, why, min_delta_bic, min_gain, max_causes, progress, t0)
        except CircuitError as exc:
            raise DiagnosisError(f"baseline: {exc}") from None


def _select(cat: _Catalogue, rec: PeriodicRecord, nominal, why, min_delta_bic, min_gain, max_causes, progress, t0):
    baseline = cat.fit([], None, max_nfev=60)
    N = baseline.n_residuals
    _log(f"baseline: chi2/N {baseline.rss / N:.3g}, source R {baseline.source['r']:.4g} Ohm, L "
         f"{baseline.source['l']:.4g} H, C {baseline.source['c']:.4g} F ({baseline.wall_s:.1f} s)", progress)
    fits = [baseline]
    singles: dict[str, ReplayFit] = {}
    for cause in cat.variants:
        tc = time.perf_counter()
        r = cat.best_with(baseline, cause)
        if r is None:
            continue
        singles[cause] = r
        fits.append(r)
        ok, dbic, gain = _significant(baseline, r, min_delta_bic, min_gain)
        _log(f"{cause}: chi2/N {r.rss / N:.4g}, dBIC {dbic:.1f}, gain {gain:.3f} ({r.wall_s:.1f} s)", progress)
    current, steps = baseline, []
    pool = dict(singles)
    while pool and len(current.causes) < max_causes:
        best = min(pool.values(), key=lambda r: r.bic)
        ok, dbic, gain = _significant(current, best, min_delta_bic, min_gain)
        if not ok:
            break
        new = next(c for c in best.causes if c not in current.causes)
        added = next(p for p in best.parts if p.cause == new)
        steps.append({"cause": new, "gain": gain, "delta_bic": dbic, "cost": best.cost,
                      "total_gain": 1 - best.objective / baseline.objective, "form": added.label,
                      "model": _model(best)})
        _log(f"step {len(steps)}: {new} (gain {gain:.3f}, dBIC {dbic:.1f})", progress)
        current = best
        pool = {}
        if len(current.causes) >= max_causes:
            break
        for cause, single in singles.items():  # every cause not named (one may show only beside another)
            if cause in current.causes:
                continue
            # the form the cause took alone, refitted with those named
            r = cat.fit(list(current.parts) + [single.parts[-1]], current, max_nfev=COMBO_NFEV)
            _log(f"  with {cause}: chi2/N {r.rss / N:.4g} ({r.wall_s:.1f} s)", progress)
            fits.append(r)
            pool[cause] = r
    # backward check: each named cause against the model without it
    changed = True
    while changed and len(current.causes) > 1:
        changed = False
        for cause in list(current.causes):
            rest = [p for p in current.parts if p.cause != cause]
            r = cat.fit(rest, current)
            if not _significant(r, current, min_delta_bic, 0.0)[0]:
                _log(f"backward: {cause} dropped (dBIC {_significant(r, current, 0, 0)[1]:.1f})", progress)
                steps.append({"cause": cause, "dropped": True, "reason": "backward check"})
                current, changed = r, True
                break
    current, steps = _tolerance_check(cat, current, nominal, steps, progress)
    drift = cat.prior.drift({k: v for k, v in current.winding.items() if k in current.held})
    causes = current.causes
    steps = _with_values(steps, current, nominal)
    noise = {"cost": float(np.sum([np.sum(rec.sigma[:, j] ** 2) / np.sum(np.abs(rec.Y[:, j]) ** 2)
                                   for j in range(2)])),
             "per_signal": rec.info["noise_rms"], "method": rec.info["noise_method"],
             "note": "cost units: residual power over the signal's power on the replayed bins, summed over v_in, i_in"}
    d = ReplayDiagnosis(causes[0] if causes else "none", baseline, current if causes else None, fits,
                        causes=causes, steps=steps, noise=noise, nominal=nominal, drift=drift,
                        tolerance=cat.prior.tolerance, source_tolerance=cat.args[6],
                        path={"path": "exact-replay", "why": why})
    d.unexplained = _unexplained(rec, current)
    d.evidence = {"record": rec.info, "chi2_per_residual": {"baseline": baseline.rss / N, "final": current.rss / N},
                  "criterion": "forward selection and backward check by BIC = chi2 / s^2 + k ln N, s^2 = max(1, "
                               f"chi2/N); dBIC >= {min_delta_bic}, and gain >= {min_gain} above the noise; source "
                               "values beyond the source tolerance name their cause"}
    d.wall_s = time.perf_counter() - t0
    _log(f"cause: {d.cause} (gain {d.gain:.3f}) in {d.wall_s:.1f} s", progress)
    return d


def _model(fit: ReplayFit) -> str:
    """The winding model of ``fit`` as the frequency path names it: the structure, then the effects' forms."""
    return fit.structure + ("; " if fit.structure and any(p.effect for p in fit.parts) else "") + \
        ", ".join(p.effect.label for p in fit.parts if p.effect is not None)


def _tolerance_check(cat: _Catalogue, current: ReplayFit, nominal, steps, progress):
    """Source values beyond the source tolerance name their cause; freed ones within it do not."""
    tau = math.log1p(cat.args[6]) if math.isfinite(cat.args[6]) else math.inf
    nom = {"r": nominal["rpris"], "l": nominal["lpris"], "c": nominal["cpris"]}
    for _ in range(3):
        moved = {k: abs(math.log(current.source[k] / nom[k])) > tau * (1 + 1e-9) for k in nom}
        named = set(current.causes)
        add = []
        if moved["r"] and "series-resistance" not in named:
            add.append("series-resistance" if current.source["r"] > nom["r"] else "component-drift")
        if (moved["l"] or moved["c"]) and "component-drift" not in named:
            add.append("component-drift")
        drop = [c for c, keys in (("series-resistance", "r"), ("component-drift", "lc"))
                if c in named and not any(moved[k] for k in keys)]
        add = [c for c in dict.fromkeys(add) if c not in drop]
        if not add and not drop:
            break
        parts = [p for p in current.parts if p.cause not in drop] + [p for c in add for p in cat.variants[c]]
        for c in add:
            _log(f"{c}: source value beyond the source tolerance {cat.args[6]:g}", progress)
            steps.append({"cause": c, "reason": "source value beyond the source tolerance"})
        for c in drop:
            _log(f"{c} dropped: its values are within the source tolerance", progress)
            steps.append({"cause": c, "dropped": True, "reason": "values within the source tolerance"})
        current = cat.fit(parts, current)
    return current, steps


def _with_values(steps, fit: ReplayFit, nominal) -> list[dict[str, Any]]:
    """The steps with the final fit's values of each source cause."""
    src = fit.source
    vals = {"series-resistance": {"rpris": src["r"], "r_series_ohm": src["r"] - nominal["rpris"]},
            "component-drift": {"rpris": src["r"], "lpris": src["l"], "cpris": src["c"],
                                "l_drift_percent": 100 * (src["l"] / nominal["lpris"] - 1),
                                "c_drift_percent": 100 * (src["c"] / nominal["cpris"] - 1)},
            "switch-ringing": {"lsw": src.get("lsw"), "csw": src.get("csw"),
                               "f_ring_hz": (1 / (2 * math.pi * math.sqrt(src["lsw"] * src["csw"]))
                                             if "lsw" in src else None)}}
    shape = next((p for p in fit.parts if p.circuit is not None), None)
    if shape is not None:  # the structure's own values and couplings as fitted (no prior)
        vals[shape.cause] = {"structure": shape.how, **{k: v for k, v in fit.winding.items() if k not in fit.held}}
    out = []
    for s in steps:
        s = dict(s)
        if s["cause"] in vals and not s.get("dropped"):
            s["values"] = vals[s["cause"]]
        out.append(s)
    return out


def _unexplained(rec: PeriodicRecord, fit: ReplayFit, per_decade: float = 6.0, factor: float = 4.0
                 ) -> list[dict[str, Any]]:
    """Bands of a decade / ``per_decade`` whose weighted residual's mean square stands ``factor`` above one."""
    e = np.abs(fit.predicted - rec.Y) / rec.sigma
    bands = max(2, int(per_decade * math.log10(rec.f[-1] / rec.f[0])) + 1)
    edges = np.geomspace(rec.f[0], rec.f[-1] * (1 + 1e-12), bands)
    out = []
    for j, s in enumerate(SIGNALS):
        for lo, hi in zip(edges[:-1], edges[1:]):
            sel = (rec.f >= lo) & (rec.f < hi)
            if np.count_nonzero(sel) < 3:
                continue
            ms = float(np.mean(e[sel, j] ** 2))
            if ms > factor:
                out.append({"signal": s, "unit": UNITS[s], "band_hz": [float(lo), float(hi)], "above_noise": ms})
    out.sort(key=lambda b: -b["above_noise"])
    return out[:8]
