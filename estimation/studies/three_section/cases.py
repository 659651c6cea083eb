"""The three-section study's case (thesis 4.2.2): target, parameters, source settings, records, approaches, optimisers.

Shared by the study's stages (:mod:`estimation.studies.three_section.study`,
:mod:`~estimation.studies.three_section.frequency`, :mod:`~estimation.studies.three_section.unguided`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation import costs
from estimation.parameters import ParameterSet
from estimation.search.optimisers import Budget, minimize
from estimation.studies import cells, common
from estimation import modal
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.lab import timedomain as td
from pris_cosim.lab import virtual_lab as vl
from pris_cosim.models.builtin import get_model

NAME = "three-section"


PORT = "n1"


NAMES = ["Rs", "Cs", "Cg", "Ls", "k12", "k13", "k23"]


TARGET = {"Rs": 0.083, "Cs": 970e-12, "Cg": 1.6e-9, "Ls": 181e-6, "k12": 0.8792, "k13": 0.8729, "k23": 0.8564}


#: Scales (4.28).
SCALES = {"Rs": 1e-3, "Cs": 1e-12, "Cg": 1e-9, "Ls": 1e-6, "k12": 1e-2, "k13": 1e-2, "k23": 1e-2}


#: Table 4.8 (scaled bounds).
SCALED_BOUNDS = {"Rs": (1, 1000), "Cs": (1, 1000), "Cg": (1, 1000), "Ls": (1, 1000),
                 "k12": (85, 95), "k13": (85, 95), "k23": (85, 95)}


SOURCE_FRF = SourceSettings(vdc=100.0, prbs_order=12, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)


SOURCE_TIME = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)


FS_FRF = 2.5e6


FS_TIME = 11e6


#: Acquisitions of the time paths' record under noise, each one PRBS6 period from rest with its own noise,
#: averaged as an oscilloscope's averaging mode does: 16 x 6,930 samples, about the 102,375 samples of the
#: frequency path's single PRBS12 period, so that both paths see the same amount of data.
TIME_AVERAGES = 16


#: The measured-noise cell (``snr_db="adc"``): both paths' records acquired through the virtual lab's
#: measurement chain (:func:`pris_cosim.lab.virtual_lab.acquire_pris`): 100 kHz Chebyshev-I anti-alias filter,
#: 1 MS/s, differential probes, 5 mV RMS at the ADC input, 16 bits. The estimates replay the same filter
#: (:class:`estimation.approaches.PrisEngine` ``output_filter``) at the ADC's rate.
ADC = "adc"


ADC_CHAIN = vl.MeasurementChain()


#: Highest compared bin of the frequency path at the ADC cell (a fraction of the ADC's Nyquist frequency).
ADC_FMAX_FRACTION = 0.45


Level = float | str | None


def level_of(x: Any) -> Level:
    """A noise level as the study keys it: None (noise-free), an SNR in dB, or :data:`ADC`."""
    if x is None or (isinstance(x, str) and x.strip().lower() in ("none", "clean")):
        return None
    if isinstance(x, str) and x.strip().lower() == ADC:
        return ADC
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise common.StudyError(f"noise level must be an SNR in dB, 'none' or '{ADC}' (got {x!r})") from None
    if not math.isfinite(v):
        raise common.StudyError(f"noise level must be finite (got {x!r})")
    return v


def is_adc(level: Level) -> bool:
    """True for the measured-noise cell (:data:`ADC`)."""
    return isinstance(level, str) and level == ADC


def level_tag(level: Level) -> str:
    """``clean``, ``snr60`` or ``adc``: the level's part of run and case names."""
    return "clean" if level is None else ADC if is_adc(level) else f"snr{float(level):g}"


def _rate(level: Level, fs: float) -> float:
    return ADC_CHAIN.fs if is_adc(level) else fs


def _filter(level: Level) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    return vl.anti_alias_ss(ADC_CHAIN) if is_adc(level) and ADC_CHAIN.aa_cutoff_hz else None


def _chain_record(source: SourceSettings, seed: int | None, noise: bool = True, averages: int = 1
                  ) -> dict[str, np.ndarray]:
    w = vl.acquire_pris(get_model(NAME).circuit, PORT, source, ADC_CHAIN, seed=seed, noise=noise,
                        averages=averages)
    return {k: w[k] for k in ("time_s", "v_bprbs", "v_in", "i_in")}


def chain_sigma(v_clean: np.ndarray) -> float:
    """Noise standard deviation of one ADC acquisition of a voltage channel at the probe tip, V: the additive
    noise and the quantisation (``LSB^2 / 12``) times the probe's attenuation for that waveform's peak."""
    ch = ADC_CHAIN
    peak = float(np.max(np.abs(np.asarray(v_clean, float))))
    a = next((v for v in sorted(ch.probe_attenuations) if peak / v <= ch.headroom * ch.adc_range_v),
             max(ch.probe_attenuations))
    return math.sqrt(ch.noise_rms_v ** 2 + (ch.lsb_v ** 2 / 12.0 if ch.quantise else 0.0)) * a


F_MIN, F_MAX, N_POINTS = 2e3, 1e6, 200


APPROACHES = ["frequency", "time", "emd", "iemd"]


#: Resonance peaks of the target's Zin used by the frequency path's first stage: prominence (decades),
#: at most this many, weight of their log-frequency residuals against the 200 log-magnitude residuals.
PEAK_PROMINENCE, PEAK_COUNT, PEAK_WEIGHT = 0.3, 6, 100.0


#: A peak's prominence must also reach this many times the local noise of log10 |Zin| (modal.local_noise).
PEAK_NOISE_FACTOR = 8.0


OPTIMISERS = ["ga", "pso", "cma"]


#: Global phase of each optimiser name (the hybrid's first stage).
GLOBAL_METHODS = {"ga": "ga", "pso": "pso", "cma": "cma_es"}


DRIVES = ("bridge", "current")


#: Reference noise level of the Fisher information when a run has no noise, dB.
FISHER_SNR_DB = 40.0


#: Oscillatory modes the modal stage matches (the strongest).
MODAL_MODES = 3


#: Fewer modes than this in the record (e.g. behind an anti-alias filter) leave the modal stage too
#: little to match: the optimiser then runs on the approach's own cost, restarted.
MODAL_MIN_MODES = 2


#: Parameters profiled after the unguided voltage fit (the worst determined, in turn).
PROFILED = 3


#: Subspace identification of the target's modes from its whole record: state order and block rows.
SUBSPACE_ORDER, SUBSPACE_ROWS = 8, 400


#: A further mode is kept when its resonance height is at least this fraction of the previous one's.
MODE_HEIGHT_RATIO = 0.1


#: Samples of the frequency path's record given to the subspace model (10 ms at 2.5 MHz).
SUBSPACE_SAMPLES_FRF = 25_000


#: Noise floor of the frequency path's bin weights, decades of log10 |Zin|.
BIN_NOISE_FLOOR = 1e-3


# maximum-likelihood bin weights (parametric bootstrap at the estimate): draws, floor (decades)
ML_WEIGHT_DRAWS, ML_WEIGHT_FLOOR = 16, 1e-6


#: Weights of the log damping-ratio and log residue residuals of the modal stage (frequencies: 1).
MODAL_DAMPING_WEIGHT, MODAL_RESIDUE_WEIGHT = 0.01, 0.03


#: Half-width (unit-cube units) of the box around the voltage fit in which the local solver refines the
#: EMD and correlation costs: the refinement stays in the basin the first stages found.
LOCAL_BOX = 0.02


#: Weight of the mode-frequency constraint in the constrained voltage fit (own residuals: RMS units).
MODE_CONSTRAINT_WEIGHT = 1e3


METRICS = ["rmse", "correlation"]


SHOWN = NAMES


SLICE = ("Rs", "Ls")


def _thesis(errors: Sequence[float], cost: float, runtime: float) -> dict[str, Any]:
    return {"errors_percent": dict(zip(NAMES, errors)), "cost": cost, "runtime": runtime,
            "runtime_unit": "(unit not stated)"}


#: Thesis Table 4.9 (RMSE-type costs) and Table 4.10 (correlation costs, C given x 1e-3 there).
THESIS: dict[str, dict[str, Any]] = {
    "frequency/ga/rmse": _thesis([-299.2, -2.69, -3.61, 5.68, -8.83, 0.04, -4.70], 2.6098, 15.71),
    "frequency/pso/rmse": _thesis([-242.5, -3.09, 0.67, 2.55, -8.83, 0.03, -5.29], 2.5917, 29.89),
    "time/ga/rmse": _thesis([91.85, 95.31, -1512, 94.61, -5.06, -4.92, -6.45], 32.543, 4.51),
    "time/pso/rmse": _thesis([1.14, -1.91, -0.59, 1.73, -4.78, -3.15, 0.53], 1.0859, 12.33),
    "emd/ga/rmse": _thesis([-977.6, 66.44, -519.1, 77.94, -4.82, 2.15, -2.01], 1.0854, 3.26),
    "emd/pso/rmse": _thesis([36.90, -3.03, -59.55, 33.47, -5.03, 2.50, -0.50], 0.5516, 5.92),
    "iemd/ga/rmse": _thesis([34.56, 38.53, -761.1, 89.68, -8.79, -8.83, -1.52], 49.695, 6.42),
    "iemd/pso/rmse": _thesis([1.14, -1.91, -0.59, 1.73, -4.78, -3.15, 0.53], 0.5067, 8.33),
    "frequency/ga/correlation": _thesis([93.36, 36.21, -6890, -321.1, -0.824, -6.534, -6.758], 14.94e-3, 13.87),
    "frequency/pso/correlation": _thesis([45.23, -0.50, 37.50, -40.25, -3.73, -8.80, -6.70], 0.452e-3, 11.81),
    "time/ga/correlation": _thesis([-14.26, 12.30, -66.13, 36.26, -1.298, -6.792, -2.9295], 0.426e-3, 0.714),
    "time/pso/correlation": _thesis([83.13, 47.17, -723.1, 86.26, -4.85, -5.45, -8.03], 0.422e-3, 4.31),
    "emd/ga/correlation": _thesis([-543.24, 74.29, -155.5, 58.679, -8.605, -3.876, -4.442], 629e-3, 2.46),
    "emd/pso/correlation": _thesis([-941.4, 25.25, 37.50, -51.22, 0.42, -3.10, -0.41], 38.41e-3, 1.76),
    "iemd/ga/correlation": _thesis([98.79, 43.58, -46257, -452.49, -2.957, -6.1796, -10.935], 6016e-3, 2.43),
    "iemd/pso/correlation": _thesis([-84.61, 21.58, -3.74, -0.91, 0.67, 1.88, 0.74], 390e-3, 8.87),
}


def make_params() -> ParameterSet:
    """[Rs, Cs, Cg, Ls, k12, k13, k23] with the scales (4.28) and the bounds of Table 4.8."""
    model = get_model(NAME)
    bounds = {k: (SCALED_BOUNDS[k][0] * SCALES[k], SCALED_BOUNDS[k][1] * SCALES[k]) for k in NAMES}
    ps = ParameterSet.from_model(model, names=NAMES, bounds=bounds, passivity="repair")
    for k in NAMES:
        ps.set(k, theta_scale=SCALES[k], scale="log" if not k.startswith("k") else "linear")
    return ps


def _noise_seed(seed: int) -> int:
    return 10_007 + int(seed)


@functools.lru_cache(maxsize=8)
def _frequency_record(snr_db: Level, seed: int) -> dict[str, np.ndarray]:
    """The frequency path's record: one simulated PRBS12 period with the cell's noise (cached; do not modify);
    at the ADC cell acquired through the measurement chain at 1 MS/s."""
    if is_adc(snr_db):
        w = _chain_record(SOURCE_FRF, _noise_seed(seed))
    else:
        w = cells.add_noise(td.simulate_pris(get_model(NAME).circuit, PORT, SOURCE_FRF, FS_FRF, periods=1),
                            snr_db, _noise_seed(seed))
    for v in w.values():
        v.setflags(write=False)
    return w


def frequency_fs(snr_db: Level) -> float:
    """Sampling rate of the frequency path's record at a level, Hz."""
    return _rate(snr_db, FS_FRF)


def frequency_fmax(snr_db: Level) -> float:
    """Highest compared frequency of the frequency path at a level, Hz."""
    return min(F_MAX, ADC_FMAX_FRACTION * ADC_CHAIN.fs) if is_adc(snr_db) else F_MAX


def frequency_target(snr_db: Level = None, seed: int = 1
                     ) -> tuple[dict[str, np.ndarray], np.ndarray, int, ap.WelchSettings, np.ndarray]:
    """Target Zin from one simulated PRBS12 period (noise on ``v_in`` and ``i_in``), Welch H1 as the thesis."""
    w = _frequency_record(snr_db, seed)
    n = w["time_s"].size
    fs = frequency_fs(snr_db)
    welch = ap.WelchSettings()
    bins, f = ap.bin_frequencies(fs, welch.segment(n), F_MIN, frequency_fmax(snr_db), N_POINTS)
    _, resp, _ = ap.responses_from_waveforms(w, fs, [ap.ZIN_SPEC["Zin"]], welch, bins)
    return resp, f, n, welch, bins


def time_fs(snr_db: Level) -> float:
    """Sampling rate of the time paths' record at a level, Hz."""
    return _rate(snr_db, FS_TIME)


def time_target(snr_db: Level = None, seed: int = 1) -> dict[str, np.ndarray]:
    """Target waveforms: one PRBS6 period at 11 MHz; under noise (``snr_db`` on ``v_in`` and ``i_in`` of each
    acquisition) the mean of :data:`TIME_AVERAGES` acquisitions; at the ADC cell, the mean of as many
    acquisitions through the measurement chain at 1 MS/s."""
    if is_adc(snr_db):
        return _chain_record(SOURCE_TIME, _noise_seed(seed), averages=TIME_AVERAGES)
    w = td.simulate_pris(get_model(NAME).circuit, PORT, SOURCE_TIME, FS_TIME, periods=1)
    return cells.add_noise(w, snr_db, _noise_seed(seed), averages=TIME_AVERAGES)


class _BridgeDrive:
    """Estimate driven by the commanded bridge voltage through the source's series RLC (exact ZOH)."""

    sim: ap.PrisEngine

    def voltages(self, overrides: Any) -> np.ndarray:
        return self.sim.simulate(overrides)["v_in"]


class BridgeTime(_BridgeDrive, ap.TimeDomain):
    """Time approach (4.32)/(4.34) with the estimate in the PRIS arrangement (bridge-voltage drive)."""

    engine = "zoh-bridge"


class BridgeEMD(_BridgeDrive, ap.EMDApproach):
    """EMD approach (4.39)/(4.42) with the bridge-voltage drive."""

    engine = "zoh-bridge+emd"


class BridgeIEMD(_BridgeDrive, ap.IEMDApproach):
    """Inferred-EMD approach (4.45)/(4.46) with the bridge-voltage drive.

    Its residuals are the voltage residuals scaled by ``sum_r (1/psi_r) / sqrt(N)``,
    so that their root sum of squares is ``C^i_nrmse`` (see :func:`estimation.costs.iemd_nrmse`).
    """

    engine = "zoh-bridge+iemd"

    def _residuals(self, ev: Any) -> np.ndarray:
        g = self.cost.decomposer.cached(self.v_target)
        scale = float(np.sum(1.0 / costs.imf_ranges(g))) / math.sqrt(self.v_target.size)
        return (self.voltages(ev.overrides) - self.v_target) * scale


def build_approach(approach: str, metric: str, params: ParameterSet | None = None, snr_db: float | None = None,
                   seed: int = 1, drive: str = "bridge") -> ap.Approach:
    """One approach with one cost metric, target built here.

    Parameters
    ----------
    approach : {"frequency", "time", "emd", "iemd"}
    metric : {"rmse", "correlation"}
    params : ParameterSet, optional
    snr_db : float, optional
        Measurement noise on the target waveforms, dB (None: noise-free).
    seed : int
        Noise seed.
    drive : {"bridge", "current"}
        Time, EMD and IEMD: ``"bridge"`` simulates the estimate in the PRIS
        arrangement from the commanded bridge voltage (the true parameters
        reproduce the target exactly); ``"current"`` injects the target's
        sampled current held over each sample (thesis 4.2.3; biased by the
        discretisation, Fig. 4.14).
    """
    params = params or make_params()
    circuit = get_model(NAME).circuit
    if approach == "frequency":
        target, f, n, welch, bins = frequency_target(snr_db, seed)
        engine = ap.PrisEngine(circuit, PORT, SOURCE_FRF, frequency_fs(snr_db), n, probes=[],
                               output_filter=_filter(snr_db))
        cost = ap.frequency_cost("rmse" if metric == "rmse" else "correlation", ["Zin"])
        return ap.SimulatedFrequency(params, engine, [ap.ZIN_SPEC["Zin"]], welch, bins, target, cost, chunk=8)
    if approach in ("time", "emd", "iemd"):
        if drive not in DRIVES:
            raise common.StudyError(f"drive must be one of {', '.join(DRIVES)} (got {drive!r})")
        w = time_target(snr_db, seed)
        if drive == "bridge":
            eng: Any = ap.PrisEngine(circuit, PORT, SOURCE_TIME, time_fs(snr_db), w["time_s"].size, probes=[],
                                     output_filter=_filter(snr_db))
            cls: Any = {"time": BridgeTime, "emd": BridgeEMD, "iemd": BridgeIEMD}[approach]
        else:
            if is_adc(snr_db):
                raise common.StudyError("the current drive injects the recorded current; at the ADC cell the "
                                        "record is filtered, so only the bridge drive applies")
            eng = ap.InjectionEngine(circuit, PORT, w["i_in"], FS_TIME, hold="step")  # thesis 4.2.3: held samples
            cls = {"time": ap.TimeDomain, "emd": ap.EMDApproach, "iemd": ap.IEMDApproach}[approach]
        return cls(params, eng, w["v_in"], metric)
    raise common.StudyError(f"three-section approach must be one of {', '.join(APPROACHES)} (got {approach!r})")


def optimiser_settings(approach: str, optimiser: str, quick: bool) -> dict[str, Any]:
    """Optimiser plan of one cell: global method + local solver, budget, least-squares polish.

    The time-domain paths cost well under a millisecond per evaluation, so
    their global phases get tens of thousands of evaluations; the frequency
    path (a 102 375-sample simulation and Welch estimate per evaluation) and
    the EMD path (a decomposition per evaluation) get a few hundred to a few
    thousand. RMSE-type costs are then polished by the trust-region least
    squares on their residuals (:func:`common.least_squares_polish`).
    """
    if optimiser not in GLOBAL_METHODS:
        raise common.StudyError(f"optimiser must be one of {', '.join(GLOBAL_METHODS)} (got {optimiser!r})")
    pop, iters = (200, 100) if quick else (600, 200)
    polish, polish_time = (60, 60.0) if quick else (150, 600.0)
    if approach == "frequency":
        pop, iters = (30, 20) if quick else (100, 60)
        polish, polish_time = (25, 60.0) if quick else (40, 900.0)
    if approach == "emd":
        pop, iters = (12, 10) if quick else (100, 40)
        polish = 0
    glob: dict[str, Any]
    if optimiser == "ga":
        glob = {"pop_size": pop, "max_generations": iters}
    elif optimiser == "pso":
        glob = {"swarm_size": pop, "max_iter": iters}
    else:
        glob = {"restarts": 8}
    local = {"max_iter": 30 if quick else 200}
    evals = int(pop * (iters + 1) / 0.9)
    mglob = ({"pop_size": 100, "max_generations": 70} if optimiser == "ga" else
             {"swarm_size": 100, "max_iter": 70} if optimiser == "pso" else {"restarts": 4})
    return {"method": f"{GLOBAL_METHODS[optimiser]}+local",
            "options": {"global_options": glob, "local_options": local, "global_share": 0.9},
            "budget": Budget(max_evals=evals), "polish_iterations": polish, "polish_time_s": polish_time,
            "modal": {"restarts": (2 if approach == "emd" else 3) if quick else 8, "budget": Budget(max_evals=8000),
                      "constrained_iterations": 60 if quick else 150, "guide_restarts": 8 if quick else 16,
                      "options": {"global_options": mglob, "local_options": {"max_iter": 50}, "global_share": 0.9},
                      "own_local_evals": (60 if approach == "emd" else 2000) if quick else
                                         (1000 if approach == "emd" else 10000)},
            "frequency_proxy": {"restarts": 8 if quick else 16, "budget": Budget(max_evals=10000 if quick else 20000),
                                "candidates": 1 if quick else 4, "mapping_rounds": 2 if quick else 4,
                                "mapping_restarts": 3 if quick else 8, "mapping_polish": 12 if quick else 40}}


def _record_fs(w: dict[str, np.ndarray]) -> float:
    t = np.asarray(w["time_s"], float)
    return float(round(1.0 / (t[1] - t[0])))


def _strongest_modes(poles: np.ndarray, res: np.ndarray, fs: float, f_max: float | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f_p = poles.imag / (2 * np.pi)
    zeta = np.abs(poles.real) / np.maximum(np.abs(poles), 1e-300)
    top = fs / 5 if f_max is None else f_max
    cand = np.flatnonzero((poles.imag > 0) & (f_p > 1e3) & (f_p < top) & (zeta < 0.05))
    height = np.abs(res[cand]) / np.maximum(zeta[cand] * 2 * np.pi * f_p[cand] / fs, 1e-300)
    order = np.argsort(height)[::-1]
    keep: list[int] = []
    for i in order[:MODAL_MODES]:
        if len(keep) >= 2 and height[i] < MODE_HEIGHT_RATIO * height[keep[-1]]:
            break
        keep.append(int(i))
    sel = cand[keep]
    sel = sel[np.argsort(f_p[sel])]
    return f_p[sel], zeta[sel], np.abs(res[sel])


def _own_cost_stage(a: ap.Approach, x: np.ndarray, own_ls: bool, plan: dict[str, Any], seed: int
                    ) -> tuple[np.ndarray, int]:
    """The approach's own cost from the voltage fit ``x``: least squares on its residuals (RMSE-type time and
    IEMD costs), else the local solver inside a box of :data:`LOCAL_BOX` around ``x``; ``(x, evaluations)``."""
    if own_ls:
        p2 = common.least_squares_polish(a, x, max_nfev=plan["polish_iterations"], max_time_s=plan["polish_time_s"])
        return np.asarray(p2["x"]), int(p2["nfev"])
    box = modal.Box(x, LOCAL_BOX)
    r2 = minimize(lambda U: a.cost_batch(box.to_outer(U)), a.n, method="local", seed=seed,
                  x0=box.to_inner(x), budget=Budget(max_evals=plan["modal"]["own_local_evals"]),
                  options={"max_iter": 200})
    return box.to_outer(np.asarray(r2.x)[None])[0], int(r2.nfev)


def case_key(approach: str, optimiser: str, metric: str, snr_db: float | None = None) -> str:
    """``approach/optimiser/metric`` (the thesis tables' key), with ``@<SNR>dB`` under noise."""
    base = f"{approach}/{optimiser}/{metric}"
    return base if snr_db is None else f"{base}@{ADC}" if is_adc(snr_db) else f"{base}@{float(snr_db):g}dB"


def _log_zin(w: dict[str, np.ndarray], welch: ap.WelchSettings, bins: np.ndarray) -> np.ndarray:
    _, resp, _ = ap.responses_from_waveforms(w, _record_fs(w), [ap.ZIN_SPEC["Zin"]], welch, bins)
    return np.log10(np.maximum(np.abs(resp["Zin"]), 1e-300))
