"""The default recipe of ``pris-cosim estimate``: global search, local solve, least-squares polish, restarts.

The studies showed what finds winding parameters reliably (two-section
study, thesis Table 4.5; three-section study, Tables 4.9/4.10):

1. a global search on a cheap, smooth stand-in of the cost -- the analytic
   frequency responses (for time, EMD and IEMD records: against the Welch H1
   responses of the record itself, at the bins where its coherence is at
   least 0.99; for a record replayed by its bridge voltage, the arrangement's
   sampled responses and ringing modes against the record's own map,
   :mod:`estimation.bridge_response`) -- a genetic algorithm followed by the
   local solver (L-BFGS-B), sized to the number of parameters ``n``: population
   ``max(100, 40 n)`` (at most 300), 100 generations; a stand-in that asks for
   them (``least_squares_starts``; its cost the sum of squares of its residuals;
   the bridge stand-in: 100 when a circuit of the search space rings above
   ``fs / 2``) is also descended
   by Levenberg-Marquardt from that many Latin-hypercube starts at once
   (40 iterations), the lowest end kept -- the ringing modes of a record sampled
   below twice their frequency leave one narrow basin per alias branch;
2. a trust-region least-squares polish on the approach's own residuals
   (Jacobian-scaled, :func:`estimation.search.local_search.least_squares_polish`,
   ``30 + 10 n`` evaluations of the residuals),
   which moves the weakly sensitive resistances that the summed cost hides;
3. ``restarts`` independent seeds (3 up to 12 parameters, 2 above), and more
   (up to ``max_restarts``, ``2 restarts + 2``) while fewer than two have
   brought the residual RMS down to three times the data's noise floor (or,
   when the best fit shows the data's noise reading to be signal -- modes
   above the Nyquist frequency --, to the larger of 1.5 times the best RMS and
   three times its residual's own noise, :func:`estimation.verdict.residual_noise`); the
   lowest own cost is kept and the others tell whether the answer is unique
   (:mod:`estimation.verdict`); when the verdict finds the best one short of
   its minimum (a Gauss-Newton step would still move a parameter), it is
   polished once more with twice the evaluations.

:func:`default_plan` gives the sizes; :func:`run_plan` runs the recipe and
returns the estimate with its verdict. A config's ``"optimiser"`` replaces
stage 1 (``"optimiser": "ga+local"`` etc. with its ``"options"``); the
polish and restarts stay.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation.search.optimisers import Budget, minimize
from estimation.parameters import ParameterSet
from estimation.recipe import End, Outcome, Start, run_recipe
from estimation.resonances import refine_resonances

#: Ties assumed when a config names neither parameters nor ties: the thesis's estimation vectors
#: (two-section 4.1.3: R2 = R1, C2 = C1) and, for the 4-section cascade, the uniform winding of the
#: three-section study (4.2: equal sections) with the model's own coupling law, a coupling decaying
#: geometrically with the distance between sections (K13 = K12^2, K14 = K12^3, Fig. 2.6). One port
#: impedance cannot tell 22 free values apart.
DEFAULT_TIES: dict[str, dict[str, str]] = {
    "two-section": {"R2": "R1", "C2": "C1"},
    "cascade-4": {**{f"{e}{i}": f"{e}1" for e in ("R", "L", "C", "Cg") for i in (2, 3, 4)},
                  "K23": "K12", "K34": "K12", "K13": "K12**2", "K24": "K12**2", "K14": "K12**3"},
}

#: Models whose default estimation vector is another model's free values that they keep: the virtual
#: laboratory's truth realises the frequency-dependent effects (2.4)-(2.6) as R-L ladders whose shapes
#: stay fixed; the estimate moves the winding's lumped values.
DEFAULT_BASE: dict[str, str] = {"hv-6section-freqdep": "hv-6section-passive"}

#: Bounds assumed when a config names no parameters: the thesis's search spaces (three-section:
#: Table 4.8, R, L, C over three decades, couplings 0.85 .. 0.95). Other models: a tenth to ten
#: times each value, couplings 0 .. 0.9999.
DEFAULT_BOUNDS: dict[str, dict[str, tuple[float, float]]] = {
    "three-section": {"Rs": (1e-3, 1.0), "Cs": (1e-12, 1e-9), "Cg": (1e-9, 1e-6), "Ls": (1e-6, 1e-3),
                      "k12": (0.85, 0.95), "k13": (0.85, 0.95), "k23": (0.85, 0.95)},
}

#: Bins of the record's own Welch H1 used by the stand-in cost: coherence at least this.
COHERENCE_MIN = 0.99

#: Resonance stage of a frequency-response target: smallest prominence of a peak of log10 |Zin|
#: (decades), at most this many peaks, weight of their log-frequency residuals.
PEAK_PROMINENCE, PEAK_COUNT, PEAK_WEIGHT = 0.3, 8, 100.0


#: Levenberg-Marquardt iterations of each stage-1 least-squares start (:func:`_least_squares_starts`).
LSQ_ITERATIONS = 40


def _least_squares_starts(proxy: ap.Approach, x: np.ndarray, f: float, starts: int, seed: int, iterations: int,
                          max_time_s: float | None = None) -> tuple[np.ndarray, float, int, str]:
    """Stage 1's second search: Levenberg-Marquardt on the stand-in's residuals from many starts at once.

    The stand-in of a record whose ringing modes lie above the Nyquist
    frequency has a narrow basin per alias branch of those modes (a mode at
    ``f`` and one at ``k fs +- f`` ring alike in the samples); a population
    method settles in one branch. ``starts`` Latin-hypercube points and the
    global search's answer are each descended (:func:`estimation.search.local_search.batched_least_squares`);
    the lowest end replaces the answer when it is lower.

    Returns
    -------
    x, cost, evaluations, note
    """
    from estimation.search.local_search import batched_least_squares
    from estimation.search.population import _latin_hypercube

    X0 = np.vstack([x[None], _latin_hypercube(np.random.default_rng(seed), int(starts), x.size)])
    X, c, nfev = batched_least_squares(proxy.residuals, X0, iterations=iterations, max_time_s=max_time_s)
    i = int(np.argmin(c))
    if c[i] < f:
        return X[i], float(c[i]), nfev, f"least-squares starts: {starts} + 1, best {c[i]:.4g} (was {f:.4g})"
    return x, f, nfev, f"least-squares starts: {starts} + 1, none below {f:.4g}"


def default_plan(n: int, per_eval_s: float | None = None) -> dict[str, Any]:
    """Sizes of the default recipe for ``n`` parameters.

    Returns
    -------
    dict
        ``method``, ``options`` (GA population and generations, local
        iterations), ``budget`` (evaluations per restart), ``restarts``,
        ``polish_iterations``.
    """
    pop = int(min(300, max(100, 40 * n)))
    gens = 100
    restarts = 3 if n <= 12 else 2
    return {"method": "ga+local",
            "options": {"global_options": {"pop_size": pop, "max_generations": gens},
                        "local_options": {"max_iter": 200}, "global_share": 0.85},
            "budget": Budget(max_evals=int(pop * (gens + 1) / 0.85)),
            "restarts": restarts, "max_restarts": 2 * restarts + 2, "polish_iterations": 30 + 10 * n}


class ApproachKind:
    """A built-in model or netlist scored by an approach: the stages of :func:`estimation.recipe.run_recipe`.

    - start ``k``: the plan's global search (``plan["method"]``, seed ``seed + k``) on the stand-in
      ``proxy`` (or the approach), then, when the stand-in asks for them, the Levenberg-Marquardt
      starts of :func:`_least_squares_starts`;
    - descend: the trust-region least-squares polish on the approach's own residuals
      (``plan["polish_iterations"]`` evaluations; the final polish twice that).

    Parameters
    ----------
    approach : Approach
        The reported and polished cost.
    params : ParameterSet
    data : numpy.ndarray
        The compared data (noise floor and scale of the verdict).
    plan : mapping
        :func:`default_plan` keys.
    proxy : Approach, optional
        Stand-in cost of stage 1.
    seed : int
        Restart ``k`` uses seed ``seed + k``.
    time_limit_s : float, optional
        Wall-time limit of the whole recipe (each restart's global search gets a share of what is left).
    """

    def __init__(self, approach: ap.Approach, params: ParameterSet, data: np.ndarray, plan: Mapping[str, Any],
                 proxy: ap.Approach | None = None, seed: int = 1, time_limit_s: float | None = None):
        self.approach, self.params, self._data, self.plan = approach, params, data, dict(plan)
        self.first = proxy or approach
        self.seed, self.time_limit_s, self.t0 = int(seed), time_limit_s, time.perf_counter()
        self.verdict_options: dict[str, Any] = {}

    def _left(self) -> float | None:
        if self.time_limit_s is None:
            return None
        return max(1.0, self.time_limit_s - (time.perf_counter() - self.t0))

    def data(self) -> np.ndarray:
        return self._data

    def residuals(self, U: np.ndarray) -> np.ndarray:
        return self.approach.residuals(U)

    def start(self, k: int) -> Start:
        plan, first = self.plan, self.first
        budget = plan["budget"]
        left = self._left()
        if left is not None:
            budget = Budget(max_evals=budget.max_evals, max_time_s=left / max(1, int(plan["restarts"]) - k))
        r1 = minimize(first.cost_batch, first.n, method=plan["method"], seed=self.seed + k, budget=budget,
                      options=dict(plan["options"]))
        x, f1, msg = np.asarray(r1.x, float), float(r1.fun), r1.message
        runs = {"stand-in search" if first is not self.approach else "global search": int(r1.nfev)}
        starts = int(plan.get("least_squares_starts", getattr(first, "least_squares_starts", 0)))
        if starts > 0:
            x, f1, n_ms, note = _least_squares_starts(
                first, x, f1, starts, self.seed + k, int(plan.get("least_squares_iterations", LSQ_ITERATIONS)),
                self._left())
            runs["least-squares starts"] = int(n_ms)
            msg = f"{msg}; {note}"
        return Start(x, f1, runs, msg, {"seed": self.seed + k})

    def descend(self, starts: Sequence[tuple[int, Start]]) -> list[End]:
        from estimation.search.local_search import least_squares_polish

        out = []
        for _, s in starts:
            x, runs, msg = s.x, dict(s.runs), s.message
            if int(self.plan["polish_iterations"]) > 0:
                pol = least_squares_polish(self.approach, x, max_nfev=int(self.plan["polish_iterations"]),
                                           max_time_s=self._left())
                x, runs["least squares"] = np.asarray(pol["x"], float), int(pol["nfev"])
                msg = f"{msg}; then least squares: {pol['message']}"
            out.append(End(x, float(self.approach.cost_batch(x[None])[0]), runs, msg))
        return out

    def polish(self, x: np.ndarray) -> tuple[np.ndarray, float, int, str] | None:
        from estimation.search.local_search import least_squares_polish

        if int(self.plan["polish_iterations"]) <= 0:
            return None
        pol = least_squares_polish(self.approach, x, max_nfev=2 * int(self.plan["polish_iterations"]))
        z = np.asarray(pol["x"], float)
        return z, float(self.approach.cost_batch(z[None])[0]), int(pol["nfev"]), str(pol["message"])


def run_plan(approach: ap.Approach, params: ParameterSet, data: np.ndarray, seed: int = 1,
             plan: Mapping[str, Any] | None = None, proxy: ap.Approach | None = None,
             time_limit_s: float | None = None, progress: bool = True,
             noise: float | None = None) -> Outcome:
    """Run the recipe on ``approach`` (stage 1 on ``proxy`` when given) and judge the answer.

    The stages are :class:`ApproachKind`'s, in the order and with the restart rule of
    :func:`estimation.recipe.run_recipe`.

    Parameters
    ----------
    approach : Approach
        The cost that is reported and polished (its residuals define the verdict).
    params : ParameterSet
    data : numpy.ndarray
        The compared data, for the noise floor and scale of the verdict.
    seed : int
        Restart ``k`` uses seed ``seed + k``.
    plan : mapping, optional
        :func:`default_plan` keys (default: sized to ``approach.n``).
    proxy : Approach, optional
        Stand-in cost of stage 1.
    time_limit_s : float, optional
        Wall-time limit of the whole recipe (restarts stop starting after it).
    progress : bool
        One line per restart on stderr.
    noise : float, optional
        Known noise standard deviation of the residuals.

    Returns
    -------
    Outcome
    """
    plan = dict(plan or default_plan(approach.n))
    kind = ApproachKind(approach, params, data, plan, proxy=proxy, seed=seed, time_limit_s=time_limit_s)
    return run_recipe(kind, int(plan["restarts"]), int(plan.get("max_restarts", plan["restarts"])), noise=noise,
                      time_limit_s=time_limit_s, progress=progress)


def default_band(model: Any, configuration: Any, override_values: Mapping[str, float] | None = None
                 ) -> tuple[float, float]:
    """Default comparison band of a model: from a fifth of its slowest to five times its fastest mode, Hz.

    The two-section model keeps the thesis's 20 Hz - 9 kHz (4.1.2). Otherwise
    the modes are the eigenvalues of the configuration's state matrix (current
    drive at its port, shorts applied) at the model's values.
    """
    from pris_cosim.circuits.mna import MNA

    if model.name == "two-section":
        return 20.0, 9e3
    circuit = model.circuit
    shorted = circuit.shorted(configuration.shorts) if configuration.shorts else circuit
    mna = MNA(shorted, current_inputs=[configuration.port])
    A = np.asarray(mna.state_space(shorted.resolve(dict(override_values or {}), check=False)).A, float)
    lam = np.linalg.eigvals(A.reshape(A.shape[-2:]))
    f = np.abs(lam) / (2 * np.pi)
    f = f[np.isfinite(f) & (f > 0)]
    if not f.size:
        return 10.0, 1e6
    return float(max(f.min() / 5, 1e-3)), float(f.max() * 5)


def resonance_proxy(approach: ap.Approach, params: ParameterSet, circuit: Any, configuration: Any
                    ) -> ap.Approach | None:
    """Stage-1 stand-in of a frequency-response target with sharp resonances: log-magnitude plus resonance frequencies.

    A winding's input impedance has resonances far sharper than the compared
    grid; the log-magnitude cost alone has several valleys of nearly equal
    depth there (a resonance matched by different capacitance, inductance and
    coupling combinations, thesis 4.2, Fig. 4.19). The peaks of the target's
    ``|Zin|`` (prominence at least :data:`PEAK_PROMINENCE` decades, refined by a
    parabola in log frequency) are the poles of the input impedance: the
    eigenvalues of the configuration's state matrix with a current drive at its
    port. The stand-in adds, per target peak, ``PEAK_WEIGHT * ln(f_peak / f_mode)``
    to the nearest mode of the estimate (:class:`estimation.modal.ResonanceProxy`).

    Returns None when the approach compares no input impedance or the target has no such peak.
    """
    from types import SimpleNamespace

    from pris_cosim.circuits.mna import MNA

    from estimation import modal

    target = getattr(approach, "target", None)
    f = getattr(approach, "f", None)
    names = [r.name for r in configuration.responses if r.node is None]
    if target is None or f is None or not names or names[0] not in target or np.size(f) < 5:
        return None
    f = np.asarray(f, float)
    order = np.argsort(f)
    lf = np.log10(f[order])
    # peaks on a uniform log-frequency grid (the target's own points, interpolated in log magnitude)
    grid = np.linspace(lf[0], lf[-1], max(lf.size, 2 * lf.size))
    mag = np.interp(grid, lf, np.log10(np.maximum(np.abs(np.asarray(target[names[0]]))[order], 1e-300)))
    peaks = 10 ** modal.response_peaks(grid, 10 ** mag, PEAK_PROMINENCE, PEAK_COUNT)
    if not peaks.size:
        return None
    peaks = refine_resonances(f[order], np.asarray(target[names[0]])[order], peaks)
    shorted = circuit.shorted(configuration.shorts) if configuration.shorts else circuit
    engine = SimpleNamespace(circuit=shorted, mna=MNA(shorted, current_inputs=[configuration.port]))
    guide = modal.ModalGuide(params, engine, peaks, np.ones_like(peaks), damping_weight=0.0)  # type: ignore[arg-type]
    return modal.ResonanceProxy(approach, guide, PEAK_WEIGHT)


def waveform_specs(configuration: Any, channels: Mapping[str, np.ndarray]) -> list[ap.ResponseSpec]:
    """Waveform recipes of the configuration's responses that the record's channels can form.

    ``Zin`` is ``v_in / i_in``; a ratio ``(V(node) - V(minus)) / V(port)`` is
    ``(v_node - v_minus) / v_in`` when those probe channels are in the record.
    """
    specs = []
    for r in configuration.responses:
        if r.node is None:
            specs.append(ap.ResponseSpec(r.name, "i_in", "v_in"))
            continue
        a = "v_in" if r.node == configuration.port else f"v_{r.node}"
        b = None if r.minus in (None, "0") else ("v_in" if r.minus == configuration.port else f"v_{r.minus}")
        if a in channels and (b is None or b in channels):
            specs.append(ap.ResponseSpec(r.name, "v_in", a if b is None else f"{a}-{b}"))
    return specs


def waveform_proxy(params: ParameterSet, response_set: Any, i_in: np.ndarray, v_in: np.ndarray, fs: float,
                   fmin: float, fmax: float, points: int = 200, configuration: Any = None,
                   probes: Mapping[str, np.ndarray] | None = None) -> ap.AnalyticFrequency | None:
    """Stand-in cost for a waveform record: analytic responses against the record's own Welch H1 responses.

    ``Zin`` and, with ``configuration`` and ``probes`` (``v_<node>`` channels),
    every voltage ratio of the configuration the record can form. Only bins
    where the record's coherence (quarter-record segments) is at least
    :data:`COHERENCE_MIN` are compared; None when fewer than 10 remain.
    """
    n = int(np.size(i_in))
    welch = ap.WelchSettings()
    nper = welch.segment(n)
    df = fs / nper
    lo, hi = max(fmin, 2 * df), min(fmax, fs / 4)
    if not hi > lo:
        return None
    bins, f = ap.bin_frequencies(fs, nper, lo, hi, points)
    w = {"i_in": np.asarray(i_in, float), "v_in": np.asarray(v_in, float),
         **{k: np.asarray(v, float) for k, v in (probes or {}).items()}}
    spec = waveform_specs(configuration, w) if configuration is not None else [ap.ZIN_SPEC["Zin"]]
    _, resp, _ = ap.responses_from_waveforms(w, fs, spec, welch, bins)
    f_c, _, coh = ap.responses_from_waveforms(w, fs, spec, ap.WelchSettings(nperseg=max(8, n // 4)))
    masks = {r: (np.interp(f, f_c, coh[r]) >= COHERENCE_MIN) & np.isfinite(resp[r]) & (np.abs(resp[r]) > 0)
             for r in resp}
    masks = {r: m for r, m in masks.items() if m.sum() >= 10}
    if not masks:
        return None
    cost = ap.frequency_cost("sse", list(masks), masks)
    return ap.AnalyticFrequency(params, response_set, f, {r: resp[r] for r in masks}, cost)


class RecordDrive:
    """Mixin: the estimate in the PRIS arrangement driven by the commanded bridge voltage.

    The compared voltages are ``v_in`` (the cost of the thesis's time, EMD and
    IEMD approaches) and, for the residuals (least-squares polish, verdict), also
    every probe voltage the record holds (``probe_targets``): a record of the port
    alone cannot tell the sections of a winding apart (thesis Fig. 4.9).
    """

    sim: ap.PrisEngine
    probe_targets: dict[str, np.ndarray]

    def voltages(self, overrides: Any) -> np.ndarray:
        return self.sim.simulate(overrides)["v_in"]

    def _residuals(self, ev: Any) -> np.ndarray:
        w = self.sim.simulate(ev.overrides)
        parts = [w["v_in"] - self.v_target]  # type: ignore[attr-defined]
        parts += [w[k] - v for k, v in self.probe_targets.items() if k in w]
        return np.concatenate(parts, axis=-1)


class RecordTime(RecordDrive, ap.TimeDomain):
    """Time approach (4.32) with the bridge-voltage drive and the probe voltages in the residuals."""

    engine = "zoh-bridge"

    def _costs(self, ev: Any) -> np.ndarray:
        P = ev.unit.shape[0] if np.ndim(ev.unit) == 2 else 1
        out = np.empty(P)
        # every recorded waveform, the residuals and their squares, per parameter set
        chunk = ap.rows_per_chunk(self.v_target.size, 3 * (len(self.probe_targets) + 2) + 2, self.chunk)
        for a in range(0, P, chunk):
            sub = {k: (v[a:a + chunk] if np.ndim(v) else v) for k, v in ev.overrides.items()}
            r = self._residuals(type("E", (), {"overrides": sub})())
            with np.errstate(invalid="ignore", over="ignore"):
                c = np.sqrt(np.mean(r ** 2, axis=-1))
            out[a:a + chunk] = np.where(np.isfinite(c), c, np.inf)
        return out


class RecordEMD(RecordDrive, ap.EMDApproach):
    """EMD approach (4.39) on ``v_in`` with the bridge-voltage drive; residuals as :class:`RecordTime`."""

    engine = "zoh-bridge+emd"


class RecordIEMD(RecordDrive, ap.IEMDApproach):
    """IEMD approach (4.45) on ``v_in`` with the bridge-voltage drive; residuals as :class:`RecordTime`."""

    engine = "zoh-bridge+iemd"


def frequency_data(approach: ap.Approach) -> np.ndarray:
    """log10 magnitudes of a frequency approach's target (decades), concatenated."""
    return np.concatenate([np.log10(np.abs(np.asarray(v))) for v in approach.target.values()])  # type: ignore[attr-defined]


__all__ = ["DEFAULT_BASE", "DEFAULT_BOUNDS", "default_band", "RecordTime", "RecordEMD", "RecordIEMD", "waveform_specs", "DEFAULT_TIES", "default_plan", "run_plan", "Outcome", "waveform_proxy", "frequency_data", "COHERENCE_MIN",
           "resonance_proxy", "refine_resonances"]
