"""The frequency path of the three-section study (thesis 4.2.4): analytic proxy, resonances, bin weights, stages.

The simulated path (a PRBS12 period through the arrangement and a Welch H1
estimate, about 55 ms per evaluation) is searched through a cheap analytic
proxy (:func:`analytic_proxy`, 40 us) guided by the target's resonances
(:func:`resonance_proxy`), then polished on the simulated path; under noise
the bins are weighted and bias corrected from a bootstrap of the noise read
off the record (:func:`ml_bin_weights`), and the proxy is corrected by output
space mapping (:func:`run_frequency_staged`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation.parameters import ParameterSet
from estimation.studies import cells, common
from estimation import modal
from estimation.studies.three_section.cases import (BIN_NOISE_FLOOR, F_MIN, FS_FRF, ML_WEIGHT_DRAWS, ML_WEIGHT_FLOOR,
    NAME, NAMES, PEAK_COUNT, PEAK_NOISE_FACTOR, PEAK_PROMINENCE, PEAK_WEIGHT, PORT, SOURCE_FRF, SUBSPACE_ORDER,
    SUBSPACE_ROWS, SUBSPACE_SAMPLES_FRF, TARGET, Level, _frequency_record, _log_zin, _strongest_modes, case_key,
    frequency_fmax, frequency_fs)
from pris_cosim.models.builtin import get_model


def analytic_proxy(a: ap.SimulatedFrequency, params: ParameterSet) -> ap.AnalyticFrequency:
    """The estimate's analytic ``Zin`` at the compared bins' frequencies against the target's Welch estimate.

    About 40 us per evaluation (the simulated path: about 60 ms). Its cost at the
    true parameters is not zero (the Hann-windowed Welch estimate smooths the
    sharp resonances), but its lowest minima lie within a few percent of the truth.
    """
    f = a.bins * a.sim.fs / a.welch.segment(a.sim.n_samples)
    return ap.AnalyticFrequency(params, get_model(NAME).response_set(), f, a.target,
                                ap.frequency_cost("rmse", list(a.target)))


def frequency_peaks(snr_db: Level = None, seed: int = 1) -> np.ndarray:
    """Resonance frequencies (Hz) of the target's ``Zin``: peaks of its Welch estimate on every bin in the band.

    The Welch bins are 49 Hz apart (parabolic refinement between them); the peaks
    agree with the analytic ``Zin``'s to 1e-4..5e-4 (the 200 compared bins are 3 % apart).
    """
    w = _frequency_record(snr_db, seed)
    fs, fmax = frequency_fs(snr_db), frequency_fmax(snr_db)
    welch = ap.WelchSettings()
    seg = welch.segment(w["time_s"].size)
    bins = np.arange(int(math.ceil(F_MIN * seg / fs)), int(fmax * seg / fs) + 1)
    f, resp, _ = ap.responses_from_waveforms(w, fs, [ap.ZIN_SPEC["Zin"]], welch, bins)
    return modal.response_peaks(bins * fs / seg, resp["Zin"], PEAK_PROMINENCE, PEAK_COUNT,
                                noise_factor=PEAK_NOISE_FACTOR)


def frequency_record_modes(snr_db: Level = None, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Mode frequencies (Hz) of the frequency path's record (noisy as the target), from a subspace model.

    The first :data:`SUBSPACE_SAMPLES_FRF` samples of the PRBS12 record, from the commanded
    bridge voltage to ``v_in`` (:func:`modal.subspace_model`, as :func:`record_modes`):
    the arrangement's modes, which a single Welch estimate no longer shows as peaks
    once the noise dominates the current above about 100 kHz.
    """
    w = _frequency_record(snr_db, seed)
    fs = frequency_fs(snr_db)
    n = int(round(SUBSPACE_SAMPLES_FRF * fs / FS_FRF))
    A, b, c, _ = modal.subspace_model(w["v_bprbs"][:n], w["v_in"][:n], SUBSPACE_ORDER, min(SUBSPACE_ROWS, n // 6))
    poles, res = modal.discrete_modes(A, b, c, fs)
    f, z, _ = _strongest_modes(poles, res, fs, frequency_fmax(snr_db))
    return f, z


def bin_weights(snr_db: Level, seed: int, bins: np.ndarray) -> np.ndarray:
    """Weights of the compared bins: ``s0 / sqrt(s_k^2 + s0^2)``, ``s_k`` the local noise of the target's
    ``log10 |Zin|`` (:func:`modal.local_noise` over every Welch bin), ``s0`` = :data:`BIN_NOISE_FLOOR` decades.

    Noise-free data give weights of 1 (the thesis's unweighted cost); under noise the
    noise-dominated bins count less (weighted least squares, the maximum-likelihood
    form for independent Gaussian bin errors).
    """
    w = _frequency_record(snr_db, seed)
    fs = frequency_fs(snr_db)
    welch = ap.WelchSettings()
    seg = welch.segment(w["time_s"].size)
    fine = np.arange(int(math.ceil(F_MIN * seg / fs)), int(frequency_fmax(snr_db) * seg / fs) + 1)
    _, resp, _ = ap.responses_from_waveforms(w, fs, [ap.ZIN_SPEC["Zin"]], welch, fine)
    sd = modal.local_noise(np.log10(np.maximum(np.abs(resp["Zin"]), 1e-300)))
    s_k = np.interp(np.asarray(bins, float), fine.astype(float), sd)
    return BIN_NOISE_FLOOR / np.sqrt(s_k ** 2 + BIN_NOISE_FLOOR ** 2)


def ml_bin_weights(a: ap.SimulatedFrequency, params: ParameterSet, x: np.ndarray, record: Mapping[str, np.ndarray],
                   draws: int = ML_WEIGHT_DRAWS, floor: float = ML_WEIGHT_FLOOR
                   ) -> tuple[np.ndarray, np.ndarray, str]:
    """Maximum-likelihood bin weights ``1 / s_k`` from a parametric bootstrap at the estimate ``x``.

    The noise of the record is read off the data: the RMS of the voltage and
    current left once the estimate's simulated waveforms are subtracted. The
    estimate's waveforms with ``draws`` draws of white noise of those RMS values
    give the spread ``s_k`` of ``log10 |Zin|`` at each compared bin (the
    construction of the Cramer-Rao bound, :func:`cell_bound`, at the estimate
    instead of the truth). Weights ``1 / sqrt(s_k^2 + floor^2)``, scaled to a
    median of 1.

    The same draws give the noise's bias of each bin, ``mean(log10 |Zin|
    noisy) - log10 |Zin| clean``: the H1 estimate is biased low where the
    current's noise is comparable to the current (an errors-in-variables
    effect), and the log of a noisy magnitude is biased too. The fit subtracts
    it from the target's residuals (bootstrap bias correction).

    Returns
    -------
    weights : numpy.ndarray
        ``(F,)``.
    bias : numpy.ndarray
        ``(F,)`` decades.
    note : str
        The noise read off the record.
    """
    ev = params.evaluate(np.asarray(x, float)[None])
    sim = a.sim.simulate(ev.overrides)
    model = {k: np.asarray(v)[0] if np.ndim(v) == 2 else np.asarray(v) for k, v in sim.items()}
    model["time_s"] = np.asarray(record["time_s"])
    sig = {k: float(np.std(np.asarray(record[k]) - model[k])) for k in ("v_in", "i_in")}

    def noisy(w: Mapping[str, np.ndarray], seed: int) -> dict[str, np.ndarray]:
        rng = np.random.default_rng(seed)
        out = dict(w)
        for k, sd in sig.items():
            out[k] = np.asarray(w[k]) + rng.normal(0.0, sd, np.shape(w[k]))
        return out

    def response(w: Mapping[str, np.ndarray]) -> np.ndarray:
        return _log_zin(w, a.welch, a.bins)

    draws_v = np.array([response(noisy(model, 90_001 + d)) for d in range(draws)])
    spread = np.std(draws_v, axis=0, ddof=1)
    bias = np.mean(draws_v, axis=0) - response(model)
    wts = 1.0 / np.sqrt(spread ** 2 + floor ** 2)
    wts = wts / float(np.median(wts))
    note = (f"noise read off the record: {sig['v_in']:.3g} V, {sig['i_in']:.3g} A RMS; per-bin spread over {draws} "
            f"draws median {np.median(spread):.3g}, max {np.max(spread):.3g} decades; bias median "
            f"{np.median(bias):.2g}, largest {bias[np.argmax(np.abs(bias))]:.2g} decades")
    return wts, bias, note


def resonance_proxy(a: ap.SimulatedFrequency, params: ParameterSet, snr_db: Level = None, seed: int = 1,
                    weights: np.ndarray | None = None, offset: np.ndarray | None = None) -> modal.ResonanceProxy:
    """First stage of the frequency path: :func:`analytic_proxy` plus the target's resonance frequencies.

    Noise-free: the peaks of the target's Welch ``Zin`` (:func:`frequency_peaks`) against
    the poles of the estimate's input impedance. Under noise: the arrangement's modes
    from the record (:func:`frequency_record_modes`) against the estimate's
    arrangement modes, and the proxy's residuals weighted by ``weights``.
    ``offset`` (log10 magnitudes per bin) is added to the analytic residuals
    before the weights: the space-mapping correction of :func:`run_frequency_staged`.
    """
    circuit = get_model(NAME).circuit
    proxy: ap.Approach = analytic_proxy(a, params)
    if offset is not None:
        proxy = modal.Shifted(proxy, offset)
    if snr_db is None:
        f_t = frequency_peaks(snr_db, seed)
        engine: Any = ap.InjectionEngine(circuit, PORT, np.zeros(2), FS_FRF)
    else:
        f_t, _ = frequency_record_modes(snr_db, seed)
        engine = ap.PrisEngine(circuit, PORT, SOURCE_FRF, FS_FRF, 2, probes=[])
        if weights is not None:
            proxy = modal.Weighted(proxy, weights)
    guide = modal.ModalGuide(params, engine, f_t, np.ones_like(f_t), damping_weight=0.0)
    return modal.ResonanceProxy(proxy, guide, PEAK_WEIGHT)


def run_frequency_staged(a: ap.SimulatedFrequency, params: ParameterSet, optimiser: str, quick: bool, seed: int,
                          snr_db: Level, plan: dict[str, Any], cost_at_target: float, t0: float
                          ) -> dict[str, Any]:
    """Frequency path, RMSE: global restarts on the analytic proxy, then the simulated cost's least squares.

    The log-magnitude cost has several valleys of nearly equal depth (the two
    sharp resonances matched by different (Cs, Ls, k) combinations); a global
    run of a few hundred simulated evaluations stops in one of them. Here the
    chosen optimiser runs ``restarts`` times on the analytic proxy
    (:func:`analytic_proxy`; thousands of evaluations each), every result is
    polished by least squares on the proxy's residuals, and the ``candidates``
    lowest distinct proxy minima are polished by least squares on the
    simulated path's residuals; the lowest simulated cost is kept.

    Under noise the bins are then weighted by the inverse of their spread and
    corrected for the noise's bias, both from a bootstrap of the noise read off
    the record at that estimate (:func:`ml_bin_weights`), and polished again.
    Last, ``mapping_rounds`` rounds of output space mapping: the proxy plus its
    difference from the simulated path at the best point (the Welch window's
    smoothing of the resonances, which biases the bare proxy's minima) is
    optimised again and its minimum polished on the simulated path, while that
    lowers the cost.
    """
    fp = plan["frequency_proxy"]
    weights = bin_weights(snr_db, seed, a.bins) if snr_db is not None else None
    proxy = resonance_proxy(a, params, snr_db, seed, weights)
    fit: ap.Approach = a if weights is None else modal.Weighted(a, weights)
    found: list[tuple[float, np.ndarray]] = []
    nfev_proxy, trace, notes = 0, [], []
    for k in range(fp["restarts"]):
        r1, _ = common.optimise(proxy, plan["method"], 1000 * seed + k, fp["budget"], plan["modal"]["options"])
        nfev_proxy += int(r1.nfev)
        found.append((float(r1.fun), np.asarray(r1.x)))
    found.sort(key=lambda t: t[0])
    starts: list[tuple[float, np.ndarray]] = []
    for c, x in found:
        if all(np.max(np.abs(x - y)) > 1e-3 for _, y in starts):
            starts.append((c, x))
        if len(starts) == fp["candidates"]:
            break
    best_x, best_c, nfev = starts[0][1], math.inf, 0
    for i, (c_proxy, x) in enumerate(starts):
        pol = common.least_squares_polish(fit, x, max_nfev=plan["polish_iterations"],
                                          max_time_s=plan["polish_time_s"])
        c = float(fit.cost_batch(np.asarray(pol["x"])[None])[0])
        nfev += int(pol["nfev"]) + 1
        trace.append([float(nfev_proxy + nfev), min(c, best_c)])
        notes.append(f"candidate {i + 1}: proxy cost {c_proxy:.3g}, simulated cost {c:.4g} ({pol['message']})")
        if c < best_c:
            best_x, best_c = np.asarray(pol["x"]), c
    analytic = analytic_proxy(a, params)

    def space_mapping(fine: ap.Approach, fit: ap.Approach, w: np.ndarray | None, x: np.ndarray, c_x: float,
                      tag: str) -> tuple[np.ndarray, float, int]:
        """Output space mapping: the proxy corrected by its difference from the simulated path at ``x``."""
        nonlocal nfev, nfev_proxy
        done = 0
        for rnd in range(fp.get("mapping_rounds", 0)):
            ev = params.evaluate(x[None])
            offset = fine._residuals(ev)[0] - analytic._residuals(ev)[0]
            nfev += 1
            if not np.all(np.isfinite(offset)):
                break
            mapped = resonance_proxy(a, params, snr_db, seed, w, offset)
            found_m: list[tuple[float, np.ndarray]] = []
            for k in range(fp.get("mapping_restarts", fp["restarts"])):
                r1, _ = common.optimise(mapped, plan["method"], 1000 * seed + 100 * (rnd + 1) + k, fp["budget"],
                                        plan["modal"]["options"])
                nfev_proxy += int(r1.nfev)
                found_m.append((float(r1.fun), np.asarray(r1.x)))
            c_m, x_m = min(found_m, key=lambda q: q[0])
            pol = common.least_squares_polish(fit, x_m, max_nfev=fp.get("mapping_polish", plan["polish_iterations"]),
                                              max_time_s=plan["polish_time_s"])
            c = float(fit.cost_batch(np.asarray(pol["x"])[None])[0])
            nfev += int(pol["nfev"]) + 1
            done += 1
            trace.append([float(nfev_proxy + nfev), min(c, c_x)])
            notes.append(f"{tag}space mapping {rnd + 1}: corrected proxy cost {c_m:.3g}, simulated cost {c:.4g}")
            if c >= c_x * (1 - 1e-6):
                break
            x, c_x = np.asarray(pol["x"]), c
        return x, c_x, done

    rounds = 0
    ml_note = ""
    if snr_db is None:
        best_x, best_c, rounds = space_mapping(a, fit, weights, best_x, best_c, "")
    else:
        # maximum-likelihood weights from the noise read off the record, then the same stages again
        w_ml, bias, ml_note = ml_bin_weights(a, params, best_x, _frequency_record(snr_db, seed))
        nfev += ML_WEIGHT_DRAWS + 1
        fine: ap.Approach = modal.Shifted(a, -bias)
        fit = modal.Weighted(fine, w_ml)
        pol = common.least_squares_polish(fit, best_x, max_nfev=plan["polish_iterations"],
                                          max_time_s=plan["polish_time_s"])
        nfev += int(pol["nfev"]) + 1
        best_x = np.asarray(pol["x"])
        best_c = float(fit.cost_batch(best_x[None])[0])
        notes.append(f"maximum-likelihood weights ({ml_note}): simulated cost {best_c:.4g}")
        best_x, best_c, rounds = space_mapping(fine, fit, w_ml, best_x, best_c, "ML ")
    cost_at_target = float(fit.cost_batch(params.to_unit({k: TARGET[k] for k in NAMES})[None])[0])
    values = params.values(best_x)
    est = {k: float(values[k]) for k in NAMES}
    errors = common.errors_percent(est, TARGET)
    wall = time.perf_counter() - t0
    method = (f"{fp['restarts']} x [{plan['method']} on the analytic proxy -> least squares] -> least squares "
              f"on the simulated residuals from the {len(starts)} lowest"
              + ("; maximum-likelihood bin weights and bias correction from the noise read off the record, "
                 "least squares" if ml_note else "")
              + f"; {rounds} space-mapping round(s) (the proxy corrected by its difference from the simulated "
                "path at the best point); lowest cost kept")
    return {
        "study": NAME, "case": case_key("frequency", optimiser, "rmse", snr_db), "approach": "frequency",
        "optimiser": optimiser, "cost_function": "rmse", "snr_db": snr_db, "drive": "bridge", "engine": a.engine,
        "errors_percent": errors, "estimate": est, "success": cells.success(errors),
        "success_rate": float(cells.success(errors)), "within_10pct": int(sum(abs(e) < 10 for e in errors.values())),
        "non_identifiable": [], "cost": best_c, "cost_at_target": cost_at_target, "wall_s": wall,
        "nfev": nfev + nfev_proxy, "evaluations": nfev + nfev_proxy, "simulated_evaluations": nfev,
        "proxy_evaluations": nfev_proxy, "evals_per_s": (nfev + nfev_proxy) / max(wall, 1e-9),
        "per_eval_s": a.stats.per_eval_s, "optimiser_message": "; ".join(notes), "method": method, "trace": trace,
        "settings": {"quick": quick, "seed": seed, "method": method, "proxy_restarts": fp["restarts"],
                     "proxy_max_evals": fp["budget"].max_evals, "proxy_options": plan["modal"]["options"],
                     "candidates": fp["candidates"], "polish_iterations": plan["polish_iterations"]},
    }
