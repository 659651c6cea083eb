"""Lumped-network fits of real measured transformer data.

Two public data sets (``<shared>/data/real``, see its README) are fitted by
circuits built with :class:`pris_cosim.circuits.circuit.Circuit`, so every fitted
model can be simulated, exported as a netlist or built as an FMU like any
other circuit of the project.

Small transformer (``small_transformer_3_loads.csv``)
    Input impedance with three secondary loads (0.2 pF "open", 5 mOhm
    "short", 49.5 Ohm).  One two-winding circuit, :func:`small_transformer_circuit`,
    is built three times with the same parameter names and only the load
    element changed, and the three segments are fitted *jointly*: every
    winding parameter is shared, the loads are known.
Distribution transformer (``distribution_transformer_admittance_03PK10.txt``)
    Input admittance with three sharp admittance peaks (series resonances)
    near 0.93, 1.23 and 1.83 MHz, fitted by :func:`admittance_ladder_circuit`.

Both fits minimise the complex-log misfit ``log H_model - log H_measured``
(real part: log-magnitude error in neper; imaginary part: phase error in
rad) by trust-region least squares on the unit cube of an
:class:`estimation.parameters.ParameterSet` (log scaling of every value),
after an optional short particle-swarm stage, from starting values read off
the data by simple physics (:func:`small_transformer_start`,
:func:`admittance_start`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit, Parameter
from pris_cosim.frf.response import ResponseModel
from pris_cosim.measured.formats import MeasuredDataError, MeasuredResponses, read_mag_phase_rows, read_multisegment_csv

from estimation.search.optimisers import Budget, minimize
from estimation.parameters import ParameterSet

SMALL_FILE = "small_transformer_3_loads.csv"
ADMITTANCE_FILE = "distribution_transformer_admittance_03PK10.txt"

#: Secondary loads of the small-transformer file: segment alias -> (case name, element name, value in Ohm or F).
SMALL_LOADS: dict[str, tuple[str, str, float]] = {
    "open": ("small-open", "Cload", 0.2e-12),
    "short": ("small-short", "Rload", 5e-3),
    "49.5": ("small-49.5", "Rload", 49.5),
}

#: Band of the small-transformer fit, Hz: from the first point to a little above the
#: open-circuit resonance (2.2 MHz); above about 5 MHz the short-circuit impedance
#: shows the next (distributed) resonance, which no two-winding lumped model has.
SMALL_BAND_HZ = (1e4, 5e6)

#: Band of the admittance fit, Hz.  Above about 4.9 MHz the measured admittance
#: has a phase beyond -90 deg (Re Y < 0, a delay of the measurement set-up):
#: no passive network follows it there, so the fit stops below.
ADMITTANCE_BAND_HZ = (25e3, 4.8e6)


# ====================================================================== data
def _require_file(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.is_file():
        raise MeasuredDataError(p, "file not found" if not p.exists() else "not a regular file")
    return p


def read_small_transformer(path: str | os.PathLike[str]) -> dict[str, MeasuredResponses]:
    """The three load segments of the small-transformer file.

    Parameters
    ----------
    path : str or os.PathLike
        ``small_transformer_3_loads.csv`` (multi-segment ``FREQUENCY [Hz],MAG [O],PHASE [deg]``).

    Returns
    -------
    dict
        Keys ``"open"``, ``"short"``, ``"49.5"``; values hold ``Zin`` in Ohm.

    Raises
    ------
    MeasuredDataError
        Missing file, wrong format or a missing segment (one line naming the file).
    """
    p = _require_file(path)
    out = {}
    for alias in SMALL_LOADS:
        try:
            data = read_multisegment_csv(p, alias)
        except MeasuredDataError:
            raise
        except (ValueError, KeyError) as exc:  # e.g. no such segment: keep the file name in the message
            raise MeasuredDataError(p, f"segment {alias!r}: {exc}") from None
        if "Zin" not in data:
            raise MeasuredDataError(p, f"segment {alias!r} holds no impedance column")
        out[alias] = data
    return out


def read_admittance(path: str | os.PathLike[str]) -> MeasuredResponses:
    """The 03PK10 admittance (``Yin`` in S at ``k * 25 kHz``, DC row dropped).

    Raises
    ------
    MeasuredDataError
        Missing file or wrong format (one line naming the file).
    """
    p = _require_file(path)
    try:
        return read_mag_phase_rows(p)
    except MeasuredDataError:
        raise
    except ValueError as exc:
        raise MeasuredDataError(p, str(exc)) from None


# ====================================================================== circuits
#: Parameters of the small-transformer family: name -> (unit, description).
SMALL_PARAMETERS: dict[str, tuple[str, str]] = {
    "R1": ("Ohm", "primary winding resistance"),
    "L1": ("H", "primary self-inductance"),
    "R2": ("Ohm", "secondary winding resistance"),
    "L2": ("H", "secondary self-inductance"),
    "sigma": ("", "leakage factor 1 - k of the coupling K12"),
    "Rc": ("Ohm", "core-loss resistance across the primary"),
    "C1": ("F", "primary winding capacitance to ground"),
    "C2": ("F", "secondary winding capacitance to ground"),
    "C12": ("F", "inter-winding capacitance"),
}


def small_transformer_circuit(values: Mapping[str, float], load: str = "open") -> Circuit:
    """Two-winding lumped model of the small transformer with one secondary load.

    Topology (port ``p``, secondary terminal ``o``)::

        p -R1- a -L1- 0          Rc, C1: p-0      C12: p-o
        s -L2- 0,  s -R2- o      C2: o-0          load: o-0
        K12 couples L1 and L2 with k = 1 - sigma

    The coupling is written through the leakage factor ``sigma = 1 - k``
    (a circuit parameter, fitted on a log scale): the short-circuit
    inductance ``~ 2 sigma L1`` is then proportional to one parameter, and
    ``0 < k < 1`` (a positive-definite inductance matrix) holds for every
    ``sigma`` in ``(0, 1)``.

    Parameters
    ----------
    values : mapping
        Every name of :data:`SMALL_PARAMETERS`, SI units (Ohm, H, F; ``sigma`` dimensionless).
    load : {"open", "short", "49.5"}
        Secondary load: 0.2 pF capacitor ``Cload``, 5 mOhm or 49.5 Ohm resistor ``Rload``.

    Returns
    -------
    Circuit
        Port ``p``; all three loads give circuits with the same parameter names.
    """
    if load not in SMALL_LOADS:
        raise ValueError(f"unknown load {load!r} (use one of {', '.join(SMALL_LOADS)})")
    missing = [k for k in SMALL_PARAMETERS if k not in values]
    if missing:
        raise ValueError(f"missing value of {missing[0]!r}")
    c = Circuit(f"small transformer, {load} load", ports=["p"])
    for name, (unit, text) in SMALL_PARAMETERS.items():
        c.parameters.append(Parameter(name, float(values[name]), unit, text))
    c.add("R1", "p", "a", "{R1}")
    c.add("L1", "a", "0", "{L1}")
    c.add("Rc", "p", "0", "{Rc}")
    c.add("C1", "p", "0", "{C1}")
    c.add("L2", "s", "0", "{L2}")
    c.add("R2", "s", "o", "{R2}")
    c.add("K12", "L1", "L2", "{1 - sigma}")
    c.add("C2", "o", "0", "{C2}")
    c.add("C12", "p", "o", "{C12}")
    _, element, value = SMALL_LOADS[load]
    c.add(element, "o", "0", value)
    return c


def admittance_ladder_circuit(values: Mapping[str, float], branches: int = 3) -> Circuit:
    """Parallel-branch ladder for a winding's input admittance.

    ``Y(s) = s C0 + 1/R0 + sum_k 1 / (R_k + s L_k + 1/(s C_k))``: a shunt
    capacitance and conductance (the winding's capacitance to ground and
    its dielectric/core loss) in parallel with one series R-L-C branch per
    admittance peak.  This (Foster) form is chosen over a cascade ladder
    because each branch maps to one measured resonance -- its
    ``1/sqrt(L_k C_k)`` is the peak frequency, ``R_k`` its height and
    ``L_k`` its width -- which gives starting values straight from the data
    and keeps the parameters identifiable; with every element positive it
    is passive by construction.  The admittance minima between the peaks
    follow from the branches themselves.

    Parameters
    ----------
    values : mapping
        ``C0``, ``R0`` and ``R<k>``, ``L<k>``, ``C<k>`` for ``k = 1..branches`` (Ohm, H, F).
    branches : int
        Number of series branches.

    Returns
    -------
    Circuit
        Port ``p`` (the admittance is ``1 / Zin``).
    """
    c = Circuit(f"admittance ladder, {branches} branches", ports=["p"])
    c.add("C0", "p", "0", float(values["C0"]))
    c.add("R0", "p", "0", float(values["R0"]))
    for k in range(1, branches + 1):
        c.add(f"R{k}", "p", f"b{k}", float(values[f"R{k}"]))
        c.add(f"L{k}", f"b{k}", f"c{k}", float(values[f"L{k}"]))
        c.add(f"C{k}", f"c{k}", "0", float(values[f"C{k}"]))
    return c


# ====================================================================== starting values
def _nearest(f: np.ndarray, f0: float) -> int:
    return int(np.argmin(np.abs(np.log(f / f0))))


def small_transformer_start(data: Mapping[str, MeasuredResponses]) -> dict[str, float]:
    """Starting values of the small-transformer model from the measured curves.

    - ``L1``: open-circuit inductance ``Im Z / omega`` at the lowest frequency;
    - ``L2 = L1 R_load / Re Z``: the 49.5 Ohm load seen through the turns
      ratio where the loaded impedance is most resistive;
    - ``sigma = L_sc / (2 L1)``: short-circuit (leakage) inductance at 100 kHz;
    - ``R1 = R2 = Re Z_sc / 2`` at the lowest frequency (R2 scaled by the turns ratio);
    - ``Rc``: open-circuit ``|Z|`` at its peak (the parallel resonance);
    - ``C1 = C2 = C12 = C / 3`` with ``C = 1 / (omega_r^2 L1)`` at that peak.

    Returns
    -------
    dict
        Name to value, SI units.
    """
    zo, fo = data["open"]["Zin"], data["open"].frequency_hz
    zs, fs = data["short"]["Zin"], data["short"].frequency_hz
    zr, fr = data["49.5"]["Zin"], data["49.5"].frequency_hz
    l1 = float(zo[0].imag / (2 * math.pi * fo[0]))
    mid = (fr > 3e4) & (fr < 3e6)
    i = int(np.argmin(np.abs(np.angle(zr[mid]))))
    ratio2 = float(SMALL_LOADS["49.5"][2] / zr[mid][i].real)  # (N2/N1)^2
    j = _nearest(fs, 1e5)
    lsc = float(zs[j].imag / (2 * math.pi * fs[j]))
    rsc = float(zs[0].real)
    k = int(np.argmax(np.abs(zo)))
    c_total = float(1.0 / ((2 * math.pi * fo[k]) ** 2 * l1))
    return {"R1": rsc / 2, "L1": l1, "R2": rsc / 2 * ratio2, "L2": l1 * ratio2, "sigma": lsc / (2 * l1),
            "Rc": float(np.abs(zo[k])), "C1": c_total / 3, "C2": c_total / 3, "C12": c_total / 3}


def admittance_start(data: MeasuredResponses, branches: int = 3) -> dict[str, float]:
    """Starting values of the ladder from the admittance peaks.

    The ``branches`` most prominent peaks of ``|Y|`` give, per branch,
    ``R_k = 1 / |Y_peak|``, the quality factor ``Q_k = f_k / (3 dB width)``,
    ``L_k = Q_k R_k / omega_k`` and ``C_k = 1 / (omega_k^2 L_k)``; ``C0`` is
    a hundredth of ``Im Y / omega`` at the lowest frequency (the branch
    capacitances carry most of it), ``1/R0`` the measured conductance there.

    Returns
    -------
    dict
        Name to value, SI units.
    """
    from estimation.resonances import find_resonances

    f, y = data.frequency_hz, data["Yin"]
    peaks = [r for r in find_resonances(f, y, min_prominence_db=3.0) if r.kind == "parallel"]
    peaks = sorted(sorted(peaks, key=lambda r: -r.prominence_db)[:branches], key=lambda r: r.frequency_hz)
    if len(peaks) < branches:
        raise ValueError(f"found {len(peaks)} admittance peaks, need {branches}")
    out: dict[str, float] = {}
    mag = np.abs(y)
    for k, r in enumerate(peaks, start=1):
        i = int(np.argmin(np.abs(f - r.frequency_hz)))
        above = mag >= mag[i] / math.sqrt(2)
        lo, hi = i, i
        while lo > 0 and above[lo - 1]:
            lo -= 1
        while hi < f.size - 1 and above[hi + 1]:
            hi += 1
        width = max(f[hi] - f[lo], f[1] - f[0])
        w = 2 * math.pi * r.frequency_hz
        rk = 1.0 / mag[i]
        lk = (r.frequency_hz / width) * rk / w
        out[f"R{k}"], out[f"L{k}"], out[f"C{k}"] = rk, lk, 1.0 / (w**2 * lk)
    c_low = float(y[0].imag / (2 * math.pi * f[0]))
    out["C0"] = 0.01 * c_low  # the branches carry the low-frequency capacitance; the fit may raise it
    out["R0"] = 1.0 / max(float(y[0].real), 1e-12)
    return out


# ====================================================================== fitting
@dataclass
class FitResult:
    """Outcome of one fit.

    Attributes
    ----------
    values : dict
        Fitted parameter values, SI units.
    start : dict
        Starting values.
    cost : float
        Sum of squared complex-log residuals at the optimum.
    nfev : int
        Model evaluations (parameter sets).
    wall_s : float, s
    passive : bool
        Every R, L, C positive and the inductance matrix positive definite.
    extra : dict
        Fit-specific results (errors, resonances, band).
    """

    values: dict[str, float]
    start: dict[str, float]
    cost: float
    nfev: int
    wall_s: float
    passive: bool
    extra: dict[str, Any] = field(default_factory=dict)


def log_residuals(model: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Complex-log misfit as real residuals ``[ln|m/d|, angle(m/d)]`` along the last axis.

    Parameters
    ----------
    model : numpy.ndarray
        ``(..., F)`` complex model response.
    measured : numpy.ndarray
        ``(F,)`` complex measured response (same units).

    Returns
    -------
    numpy.ndarray
        ``(..., 2F)``: log-magnitude errors (neper) then phase errors (rad, wrapped to (-pi, pi]).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.log(model / measured)
    r = np.concatenate([q.real, q.imag], axis=-1)
    return np.where(np.isfinite(r), r, 1e3)


def rms_db(model: np.ndarray, measured: np.ndarray) -> float:
    """RMS of ``20 log10 |model / measured|``, dB."""
    return float(np.sqrt(np.mean((20 * np.log10(np.abs(model / measured))) ** 2)))


def rms_phase_deg(model: np.ndarray, measured: np.ndarray) -> float:
    """RMS of the wrapped phase difference, degrees."""
    return float(np.sqrt(np.mean(np.degrees(np.angle(model / measured)) ** 2)))


def fit_unit_cube(
    residuals: Callable[[np.ndarray], np.ndarray],
    params: ParameterSet,
    seed: int = 1,
    global_evals: int = 0,
    max_nfev: int = 200,
    step: float = 1e-7,
) -> tuple[np.ndarray, float, int]:
    """Least-squares fit over the unit cube of ``params``, started at the parameters' values.

    Trust-region least squares (``x_scale="jac"``, one batched
    forward-difference population per Jacobian) from the start; with
    ``global_evals > 0`` a seeded ``pso+local`` search (started from that
    optimum) is polished the same way and the better of the two is kept.

    Parameters
    ----------
    residuals : callable
        ``residuals(U) -> (P, M)`` real residuals for ``(P, n)`` unit-cube points.
    params : ParameterSet
        Bounds and scaling; its current values are the start.
    seed : int
        Seed of the optional particle-swarm stage.
    global_evals : int
        Evaluations of a ``pso+local`` stage seeded with the start (0: none).
    max_nfev : int
        Iterations of the trust-region least squares.
    step : float
        Forward-difference step on the unit cube (one batched population per Jacobian).

    Returns
    -------
    x : numpy.ndarray
        Best unit-cube point.
    cost : float
        Sum of squared residuals there.
    nfev : int
        Parameter sets evaluated.
    """
    from scipy.optimize import least_squares

    n = len(params.varying)
    count = [0]

    def batch(U: np.ndarray) -> np.ndarray:
        count[0] += U.shape[0]
        return residuals(np.clip(U, 0.0, 1.0))

    def jac(u: np.ndarray) -> np.ndarray:
        h = np.where(u + step <= 1.0, step, -step)
        r = batch(np.vstack([u, u + np.diag(h)]))
        return ((r[1:] - r[0]) / h[:, None]).T

    def polish(u0: np.ndarray) -> tuple[np.ndarray, float]:
        out = least_squares(lambda u: batch(u[None])[0], u0, jac=jac, bounds=(0.0, 1.0), x_scale="jac",
                            method="trf", max_nfev=max_nfev, ftol=1e-12, xtol=1e-12, gtol=1e-12)
        cands = [(float(np.sum(batch(v[None])[0] ** 2)), i, v) for i, v in enumerate((out.x, u0))]
        f, _, v = min(cands, key=lambda c: (c[0], c[1]))
        return v, f

    x, f = polish(np.clip(params.to_unit(params.values()), 0.0, 1.0))
    if global_evals > 0:
        res = minimize(lambda U: np.sum(batch(U) ** 2, axis=1), n, "pso+local", seed=seed,
                       budget=Budget(max_evals=int(global_evals)), x0=x)
        xg, fg = polish(np.clip(np.asarray(res.x, float), 0.0, 1.0))
        if fg < f:
            x, f = xg, fg
    return x, f, count[0]


# ====================================================================== small transformer
class SmallTransformerModel:
    """Joint responses of the three loaded small-transformer circuits.

    Parameters
    ----------
    start : mapping
        Values for :func:`small_transformer_circuit` (also the parameters' start).
    loads : sequence of str
        Loads fitted together (default all three).
    """

    def __init__(self, start: Mapping[str, float], loads: Sequence[str] = tuple(SMALL_LOADS)):
        self.loads = list(loads)
        self.circuits = {ld: small_transformer_circuit(start, ld) for ld in self.loads}
        self.models = {ld: ResponseModel(c, "p") for ld, c in self.circuits.items()}

    def impedances(self, frequency_hz: Mapping[str, np.ndarray], overrides: Mapping[str, Any]) -> dict[str, np.ndarray]:
        """``Zin`` (Ohm) per load at its frequencies; ``(F,)`` or ``(P, F)`` by the overrides."""
        return {ld: self.models[ld].evaluate(frequency_hz[ld], overrides)["Zin"] for ld in self.loads}


def small_parameter_set(start: Mapping[str, float], factor: float = 10.0) -> ParameterSet:
    """Parameters of the small-transformer fit: every value from ``start / factor`` to ``start * factor``, log scale.

    ``sigma`` is capped at 0.5 (k >= 0.5).
    """
    circuit = small_transformer_circuit(start, "open")
    bounds: dict[str, Any] = {"sigma": (start["sigma"] / factor, min(start["sigma"] * factor, 0.5))}
    bounds.update({k: factor for k in SMALL_PARAMETERS if k != "sigma"})
    return ParameterSet.from_circuit(circuit, names=list(SMALL_PARAMETERS), bounds=bounds)


def fit_small_transformer(
    data: Mapping[str, MeasuredResponses],
    band_hz: tuple[float, float] = SMALL_BAND_HZ,
    seed: int = 1,
    global_evals: int = 0,
    max_nfev: int = 200,
    start: Mapping[str, float] | None = None,
) -> FitResult:
    """Fit the two-winding model to the open, short and 49.5 Ohm segments jointly.

    Parameters
    ----------
    data : mapping
        :func:`read_small_transformer` output (or synthetic data of the same form).
    band_hz : (float, float), Hz
        Fitted band.
    seed : int
        Seed of the optional swarm stage.
    global_evals : int
        Swarm evaluations before the least squares (0: least squares only).
    max_nfev : int
        Least-squares iterations.
    start : mapping, optional
        Starting values (default :func:`small_transformer_start`).

    Returns
    -------
    FitResult
        ``extra`` holds ``band_hz``, per-load ``errors_db`` and
        ``phase_errors_deg`` (over the band).
    """
    t0 = time.perf_counter()
    start = dict(start or small_transformer_start(data))
    sel = {ld: data[ld].select(*band_hz) for ld in SMALL_LOADS}
    freq = {ld: d.frequency_hz for ld, d in sel.items()}
    meas = {ld: d["Zin"] for ld, d in sel.items()}
    model = SmallTransformerModel(start)
    params = small_parameter_set(start)
    weight = {ld: 1.0 / math.sqrt(freq[ld].size) for ld in SMALL_LOADS}

    def residuals(U: np.ndarray) -> np.ndarray:
        z = model.impedances(freq, params.evaluate(U).overrides)
        return np.concatenate([weight[ld] * log_residuals(z[ld], meas[ld]) for ld in SMALL_LOADS], axis=1)

    x, cost, nfev = fit_unit_cube(residuals, params, seed, global_evals, max_nfev)
    values = {k: float(v) for k, v in params.values(x).items()}
    z = model.impedances(freq, values)
    extra = {
        "band_hz": list(band_hz),
        "errors_db": {ld: rms_db(z[ld], meas[ld]) for ld in SMALL_LOADS},
        "phase_errors_deg": {ld: rms_phase_deg(z[ld], meas[ld]) for ld in SMALL_LOADS},
    }
    return FitResult(values, start, cost, nfev, time.perf_counter() - t0, _passive(model.circuits["open"], values), extra)


def _passive(circuit: Circuit, values: Mapping[str, float]) -> bool:
    """Every R, L, C positive and the inductance matrix positive definite."""
    el = circuit.resolve(values, check=False)
    ok = all(float(el[e.key]) > 0 for e in circuit.of_kind("R", "L", "C"))
    ok = ok and all(abs(float(el[e.key])) < 1 for e in circuit.of_kind("K"))
    return bool(ok and (not circuit.of_kind("L") or float(np.min(circuit.smallest_inductance_eigenvalue(el))) > 0))


# ====================================================================== skin effect
#: Reference frequency of the skin-effect factor, Hz.
SKIN_F0_HZ = 1e4


def skin_factor(frequency_hz: np.ndarray, a: Any, b: Any, f0: float = SKIN_F0_HZ) -> np.ndarray:
    """Causal skin-effect factor ``1 + a (j f / f0)^b`` (dimensionless; broadcasts ``(P,)`` a, b to ``(P, F)``).

    Its real part ``1 + a cos(pi b / 2) (f/f0)^b`` is the resistance rise; its
    imaginary part the falling internal inductance.  A winding resistance
    ``R`` becomes the impedance ``R * skin_factor``.
    """
    f = np.asarray(frequency_hz, float)
    a, b = np.asarray(a, float)[..., None], np.asarray(b, float)[..., None]
    return 1 + a * (1j * f / f0) ** b


def fit_small_transformer_skin(
    data: Mapping[str, MeasuredResponses],
    base: FitResult,
    band_hz: tuple[float, float] = SMALL_BAND_HZ,
    max_nfev: int = 100,
    ladder_sections: int = 10,
) -> FitResult:
    """Refit with both winding resistances given the skin-effect factor, then realise it as R-L ladders.

    ``R_i -> R_i (1 + a (j f/f0)^b)`` with ``a``, ``b`` shared by the two
    windings (:func:`skin_factor`, ``f0 = 10 kHz``), every other value as in
    the constant-resistance model, all refitted from ``base`` by least
    squares (responses by a dense solve per frequency).  The fitted formula
    is then realised by a passive Foster R-L ladder per winding
    (:func:`pris_cosim.circuits.freqdep.fit_impedance`,
    :func:`pris_cosim.circuits.freqdep.replace_with_ladder`), and the errors are
    those of that ladder circuit, a plain :class:`~pris_cosim.circuits.circuit.Circuit`.

    Parameters
    ----------
    data : mapping
        :func:`read_small_transformer` output.
    base : FitResult
        The constant-resistance fit (start values).
    band_hz : (float, float), Hz
    max_nfev : int
        Least-squares iterations.
    ladder_sections : int
        Sections per ladder.

    Returns
    -------
    FitResult
        ``values`` include ``a`` and ``b``; ``extra`` holds ``errors_db``,
        ``phase_errors_deg`` (ladder circuit), ``formula_errors_db`` and the
        ladder ``circuits`` (one per load).
    """
    from pris_cosim.circuits.freqdep import fit_impedance

    from estimation.parameters import Parameter as EstParameter

    t0 = time.perf_counter()
    sel = {ld: data[ld].select(*band_hz) for ld in SMALL_LOADS}
    freq = {ld: d.frequency_hz for ld, d in sel.items()}
    meas = {ld: d["Zin"] for ld, d in sel.items()}
    start = {**base.values, "R1": base.values["R1"] / 2, "R2": base.values["R2"] / 2}
    model = SmallTransformerModel(start)
    params = small_parameter_set(start)
    params.passivity = "none"  # k = 1 - sigma < 1 by construction; a, b are not circuit names
    params.add(EstParameter("a", 0.5, 1e-3, 1e2, scale="log", description="resistance rise factor at f0"))
    params.add(EstParameter("b", 0.6, 0.2, 1.0, scale="linear", description="skin-effect exponent"))
    weight = {ld: 1.0 / math.sqrt(freq[ld].size) for ld in SMALL_LOADS}

    def impedances(over: Mapping[str, Any]) -> dict[str, np.ndarray]:
        circ = {k: v for k, v in over.items() if k not in ("a", "b")}
        out = {}
        for ld in SMALL_LOADS:
            fac = skin_factor(freq[ld], over["a"], over["b"])
            per = {"R1": np.asarray(over["R1"])[..., None] * fac, "R2": np.asarray(over["R2"])[..., None] * fac}
            out[ld] = model.models[ld].evaluate_grid(freq[ld], circ, per)["Zin"]
        return out

    def residuals(U: np.ndarray) -> np.ndarray:
        z = impedances(params.evaluate(U).overrides)
        return np.concatenate([weight[ld] * log_residuals(z[ld], meas[ld]) for ld in SMALL_LOADS], axis=1)

    x, cost, nfev = fit_unit_cube(residuals, params, max_nfev=max_nfev)
    values = {k: float(v) for k, v in params.values(x).items()}
    zf = impedances(values)
    lo, hi = band_hz
    circuits = {}
    for ld in SMALL_LOADS:
        c = small_transformer_circuit(values, ld)
        for r in ("R1", "R2"):
            rv = values[r]
            lad = fit_impedance(lambda f, rv=rv: rv * skin_factor(f, values["a"], values["b"]), lo, hi, ladder_sections)
            c = _realise_ladder(c, r, lad)
        circuits[ld] = c
    zl = {ld: ResponseModel(circuits[ld], "p").evaluate(freq[ld])["Zin"] for ld in SMALL_LOADS}
    extra = {
        "band_hz": list(band_hz),
        "errors_db": {ld: rms_db(zl[ld], meas[ld]) for ld in SMALL_LOADS},
        "phase_errors_deg": {ld: rms_phase_deg(zl[ld], meas[ld]) for ld in SMALL_LOADS},
        "formula_errors_db": {ld: rms_db(zf[ld], meas[ld]) for ld in SMALL_LOADS},
        "circuits": circuits,
    }
    passive = all(_passive(c, {}) for c in circuits.values())
    return FitResult(values, start, cost, nfev, time.perf_counter() - t0, passive, extra)


# ====================================================================== admittance ladder
def admittance_parameter_set(start: Mapping[str, float], branches: int = 3, factor: float = 100.0) -> ParameterSet:
    """Every ladder value from ``start / factor`` to ``start * factor``, log scale."""
    circuit = admittance_ladder_circuit(start, branches)
    return ParameterSet.from_circuit(circuit, bounds=factor)


def admittance_peaks(frequency_hz: np.ndarray, values: np.ndarray, min_prominence_db: float = 3.0) -> list[float]:
    """Frequencies (Hz) of the peaks of ``|Y|``, refined by a parabola through the top three points (log |Y|)."""
    from estimation.resonances import find_resonances

    f = np.asarray(frequency_hz, float)
    db = 20 * np.log10(np.abs(values))
    out = []
    for r in find_resonances(f, values, min_prominence_db=min_prominence_db, smooth_decades=0.0):
        if r.kind != "parallel":
            continue
        i = int(np.argmin(np.abs(f - r.frequency_hz)))
        if 0 < i < f.size - 1:
            y0, y1, y2 = db[i - 1], db[i], db[i + 1]
            den = y0 - 2 * y1 + y2
            shift = 0.5 * (y0 - y2) / den if den < 0 else 0.0
            out.append(float(f[i] + shift * (f[i + 1] - f[i - 1]) / 2))
        else:
            out.append(float(f[i]))
    return out


def fit_admittance(
    data: MeasuredResponses,
    band_hz: tuple[float, float] = ADMITTANCE_BAND_HZ,
    branches: int = 3,
    seed: int = 1,
    global_evals: int = 0,
    max_nfev: int = 200,
    start: Mapping[str, float] | None = None,
) -> FitResult:
    """Fit :func:`admittance_ladder_circuit` to a measured admittance ``Yin``.

    Parameters
    ----------
    data : MeasuredResponses
        :func:`read_admittance` output (``Yin`` in S).
    band_hz : (float, float), Hz
        Fitted band (default :data:`ADMITTANCE_BAND_HZ`).
    branches : int
        Series R-L-C branches (one per admittance peak).
    seed, global_evals, max_nfev
        As for :func:`fit_unit_cube`.
    start : mapping, optional
        Starting values (default :func:`admittance_start`).

    Returns
    -------
    FitResult
        ``extra``: ``band_hz``, ``errors_db`` / ``phase_errors_deg`` over the
        band (``"band"``) and over every point of the file (``"all"``),
        ``peaks_measured_hz``, ``peaks_fitted_hz`` and ``peak_errors_percent``.
    """
    t0 = time.perf_counter()
    sel = data.select(*band_hz)
    f, y = sel.frequency_hz, sel["Yin"]
    start = dict(start or admittance_start(sel, branches))
    circuit = admittance_ladder_circuit(start, branches)
    model = ResponseModel(circuit, "p")
    params = admittance_parameter_set(start, branches)

    def residuals(U: np.ndarray) -> np.ndarray:
        z = model.evaluate(f, params.evaluate(U).overrides)["Zin"]
        return log_residuals(1.0 / z, y) / math.sqrt(f.size)

    x, cost, nfev = fit_unit_cube(residuals, params, seed, global_evals, max_nfev)
    values = {k: float(v) for k, v in params.values(x).items()}
    fitted = admittance_ladder_circuit(values, branches)
    fm = ResponseModel(fitted, "p")
    y_band = 1.0 / fm.evaluate(f)["Zin"]
    y_all = 1.0 / fm.evaluate(data.frequency_hz)["Zin"]
    fine = np.linspace(band_hz[0], band_hz[1], 20001)
    measured_peaks = admittance_peaks(f, y)
    fitted_peaks = admittance_peaks(fine, 1.0 / fm.evaluate(fine)["Zin"])
    pairs = [(m, min(fitted_peaks, key=lambda p, m=m: abs(p - m))) for m in measured_peaks] if fitted_peaks else []
    extra = {
        "band_hz": list(band_hz),
        "branches": branches,
        "errors_db": {"band": rms_db(y_band, y), "all": rms_db(y_all, data["Yin"])},
        "phase_errors_deg": {"band": rms_phase_deg(y_band, y), "all": rms_phase_deg(y_all, data["Yin"])},
        "peaks_measured_hz": measured_peaks,
        "peaks_fitted_hz": fitted_peaks,
        "peak_errors_percent": [100.0 * (p - m) / m for m, p in pairs],
    }
    return FitResult(values, start, cost, nfev, time.perf_counter() - t0, _passive(fitted, {}), extra)


# ====================================================================== short-circuit resistance
def short_circuit_resistance(
    data: Mapping[str, MeasuredResponses],
    fit: FitResult,
    skin: FitResult | None = None,
    f_low: float = 1e4,
    f_high: float = 3.5e5,
) -> dict[str, Any]:
    """Measured ``Re Z_short`` against the fitted models' resistance over frequency.

    Parameters
    ----------
    data : mapping
        :func:`read_small_transformer` output.
    fit : FitResult
        Constant-resistance fit (:func:`fit_small_transformer`).
    skin : FitResult, optional
        Skin-effect fit (:func:`fit_small_transformer_skin`); its ladder circuit is used.
    f_low, f_high : float, Hz
        Frequencies of the reported rise ``R(f_high) / R(f_low)``.

    Returns
    -------
    dict
        ``frequency_hz``, ``measured_ohm``, ``constant_r_ohm`` (and
        ``skin_ohm``) arrays over the fitted band; ``rise`` ratios
        ``{"measured", "constant_r"[, "skin"]}`` between ``f_low`` and
        ``f_high``; ``winding_r_ohm`` = ``R1 + R2 L1/L2`` of the constant fit.
    """
    band = fit.extra.get("band_hz", SMALL_BAND_HZ)
    d = data["short"].select(*band)
    f = d.frequency_hz
    curves = {"measured_ohm": d["Zin"].real,
              "constant_r_ohm": ResponseModel(small_transformer_circuit(fit.values, "short"), "p").evaluate(f)["Zin"].real}
    if skin is not None:
        curves["skin_ohm"] = ResponseModel(skin.extra["circuits"]["short"], "p").evaluate(f)["Zin"].real
    i, j = _nearest(f, f_low), _nearest(f, f_high)
    v = fit.values
    return {
        "frequency_hz": f,
        **curves,
        "f_low_hz": float(f[i]),
        "f_high_hz": float(f[j]),
        "rise": {k.removesuffix("_ohm"): float(c[j] / c[i]) for k, c in curves.items()},
        "winding_r_ohm": float(v["R1"] + v["R2"] * v["L1"] / v["L2"]),
    }


# ====================================================================== plots
def write_plots(
    out: str | os.PathLike[str],
    small: Mapping[str, MeasuredResponses] | None = None,
    small_fit: FitResult | None = None,
    skin_fit: FitResult | None = None,
    admittance: MeasuredResponses | None = None,
    admittance_fit: FitResult | None = None,
) -> list[Path]:
    """Measured against fitted magnitude and phase, and the short-circuit resistance, as PNGs.

    Parameters
    ----------
    out : str or os.PathLike
        Output directory (created).
    small, small_fit, skin_fit
        Small-transformer data and fits (``small_transformer.png``,
        ``short_circuit_resistance.png``); skipped when ``small`` or ``small_fit`` is None.
    admittance, admittance_fit
        03PK10 data and fit (``admittance_03PK10.png``).

    Returns
    -------
    list of Path
        Files written.
    """
    from pris_cosim.plotting import pyplot

    plt = pyplot()
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    if small is not None and small_fit is not None:
        fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
        for col, ld in enumerate(SMALL_LOADS):
            f, z = small[ld].frequency_hz, small[ld]["Zin"]
            zm = ResponseModel(small_transformer_circuit(small_fit.values, ld), "p").evaluate(f)["Zin"]
            curves = [("measured", z, "k-"), ("constant R", zm, "C0--")]
            if skin_fit is not None:
                curves.append(("skin ladder", ResponseModel(skin_fit.extra["circuits"][ld], "p").evaluate(f)["Zin"], "C1:"))
            for label, h, style in curves:
                axes[0, col].loglog(f, np.abs(h), style, label=label)
                axes[1, col].semilogx(f, np.degrees(np.angle(h)), style, label=label)
            for ax in axes[:, col]:
                for edge in small_fit.extra["band_hz"]:
                    ax.axvline(edge, color="0.7", lw=0.8)
            axes[0, col].set_title(f"{SMALL_LOADS[ld][0]}: {small_fit.extra['errors_db'][ld]:.2f} dB RMS in band")
            axes[1, col].set_xlabel("frequency (Hz)")
        axes[0, 0].set_ylabel("|Z| (Ohm)")
        axes[1, 0].set_ylabel("phase (deg)")
        axes[0, 0].legend(fontsize=8)
        fig.tight_layout()
        written.append(_save(fig, folder / "small_transformer.png", plt))
        sc = short_circuit_resistance(small, small_fit, skin_fit)
        fig, ax = plt.subplots(figsize=(6.5, 4.2))
        ax.loglog(sc["frequency_hz"], np.abs(sc["measured_ohm"]), "k-", label=f"measured Re Z (x{sc['rise']['measured']:.1f})")
        ax.loglog(sc["frequency_hz"], np.abs(sc["constant_r_ohm"]), "C0--",
                  label=f"constant-R model (x{sc['rise']['constant_r']:.2f})")
        ax.axhline(sc["winding_r_ohm"], color="C0", lw=0.8, label=f"fitted R1 + R2 L1/L2 = {sc['winding_r_ohm']:.3g} Ohm")
        if "skin_ohm" in sc:
            ax.loglog(sc["frequency_hz"], np.abs(sc["skin_ohm"]), "C1:", label=f"skin-effect ladder (x{sc['rise']['skin']:.1f})")
        ax.set_xlabel("frequency (Hz)")
        ax.set_ylabel("Re Z short circuit (Ohm)")
        ax.set_title(f"short-circuit resistance, rise {sc['f_low_hz']:.3g} -> {sc['f_high_hz']:.3g} Hz")
        ax.legend(fontsize=8)
        fig.tight_layout()
        written.append(_save(fig, folder / "short_circuit_resistance.png", plt))
    if admittance is not None and admittance_fit is not None:
        f, y = admittance.frequency_hz, admittance["Yin"]
        ladder = admittance_ladder_circuit(admittance_fit.values, admittance_fit.extra["branches"])
        ym = 1.0 / ResponseModel(ladder, "p").evaluate(f)["Zin"]
        fig, axes = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
        for label, h, style in (("measured", y, "k-"), ("ladder fit", ym, "C0--")):
            axes[0].semilogy(f / 1e6, np.abs(h), style, label=label)
            axes[1].plot(f / 1e6, np.degrees(np.angle(h)), style, label=label)
        for ax in axes:
            for edge in admittance_fit.extra["band_hz"]:
                ax.axvline(edge / 1e6, color="0.7", lw=0.8)
        axes[0].set_ylabel("|Y| (S)")
        axes[1].set_ylabel("phase (deg)")
        axes[1].set_xlabel("frequency (MHz)")
        axes[0].set_title(f"03PK10 admittance: {admittance_fit.extra['errors_db']['band']:.2f} dB RMS in band")
        axes[0].legend(fontsize=8)
        fig.tight_layout()
        written.append(_save(fig, folder / "admittance_03PK10.png", plt))
    return written


def _save(fig: Any, path: Path, plt: Any) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _realise_ladder(circuit: Circuit, name: str, ladder: Any) -> Circuit:
    """Replace resistor ``name`` by ``ladder`` (its series inductance stays out of the winding's couplings)."""
    from pris_cosim.circuits.freqdep import replace_with_ladder

    return replace_with_ladder(circuit, name, ladder)
