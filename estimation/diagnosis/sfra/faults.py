"""Fault catalogue as changes of the fitted fingerprint model, and their selection.

A new sweep is explained by changing the reference model.  What is fitted is
the *change*: the residual at each frequency and response is

    [ln(Y_fault / Y_ref_model) - ln(Y_new / Y_ref_measured)] / sigma,

so the reference model's own misfit cancels, and a sweep that differs from
the fingerprint only by noise leaves nothing to explain.  ``sigma`` combines
the noise estimated from both sweeps with a model-error floor and the drift
of the set-up (below).

Causes (each tried at every section ``k``; the location is the best fit's):

``shorted-turns``
    A closed loop in section ``k`` (:class:`~estimation.diagnosis.sfra.winding.ShortedLoop`):
    its position ``k - 1 <= p <= k`` along the winding (in sections), its
    coupling ``c`` (mutuals ``c sqrt(L_k L_j) rho**|p - j + 0.5|`` to
    section ``j``, so its reach along the winding follows the fitted
    inter-section coupling) and a loop resistance referred to the section's
    turns (bolted: small; through 10 Ohm: large).  Three parameters.
``radial-deformation``
    Factors on the series capacitance of section ``k`` and on the ground
    capacitances of its two nodes.  Two parameters.
``axial-displacement``
    A factor on the mutual couplings of section ``k`` with all the others.
    One parameter.

A short is fitted from three starts at every section (bolted, intermediate
and resistive loop resistances), the other causes from one, with further
starts only as retries of a failed fit; a fit that ends above the baseline
cost (the reference model against the new sweep) has failed and is never a
candidate.  The cause with the lowest BIC is named when it beats the
baseline by :data:`MIN_DELTA_BIC` and removes at least :data:`MIN_GAIN` of
its cost (the gain); otherwise the answer is ``none``.

Weights.  ``sigma`` has a third term besides the two sweeps' noise and the
model floor: the drift of the set-up between sweeps.  The port shunts of the
reference model (the fixture and calibration residual seen in ``Y11 + Y21``
and ``Y22 + Y21``; on the shared data about 3.6e-5 S at port 2, where the
measured ``|S22|`` exceeds 1) are not stable: over the 17 shared sweeps,
taken one after another in 86 minutes, the port-2 shunt moves steadily with
the time stamp, from about 20 % below the reference's value in the first
sweep to 14 % above in the last, and the port-1 shunt likewise.  The
sweeps were taken in tap order, so this drift runs with the tap too: it
must not be what places a short.  A drift ``d`` of a shunt ``y_p`` moves
the driving-point admittance ``Y_pp`` by ``d y_p``, so ``ln Y_pp`` is
uncertain by ``d |y_p| / |Y_pp|`` in each sweep (:data:`SHUNT_DRIFT` is
``d``, the observed scale of the drift; it was set from the drift, not
tuned on the location).  This
term is small where the winding's own admittance dominates and large where
``Y_pp`` is small, above all in the deep notches of ``Y22`` between 10 and
30 kHz, where the winding's admittance and the port-2 shunt nearly cancel
and a few per cent of drift moves the notch; unweighted, those notches
decided on which side of the winding a short was placed.

Location.  The reference model's sections are equal
(:mod:`estimation.diagnosis.sfra.fingerprint`), so a section is a stretch of the
winding.  The shorted loop has a continuous position within its section
(:attr:`~estimation.diagnosis.sfra.winding.ShortedLoop.position`): its couplings to
the other sections fall off with the distance as the fitted inter-section
coupling does.  The location is that position over ``N`` (fraction of the
winding from the port-1 end); the causes without a position report the
section's centre, ``(k - 0.5) / N``.  The end-to-end response ``Y21`` is the
same for mirror-image positions in a symmetric winding; which side the
short is on comes from ``Y11`` against ``Y22`` (above the first
anti-resonance the capacitive currents to ground of each end are split by
the inductance on either side of the short).

Severity.  Only the loop resistance referred to the section's turns is
identifiable (a loop of ``a`` times the section's turns with resistance
``R`` acts as ``R / a**2``), and the shorted fraction is reported as
``c**2``, the share of the section's flux linkage the loop cancels.  Bolted
and resistive shorts differ by two orders of magnitude in the referred
resistance; :data:`BOLTED_BELOW_OHM` separates them.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from estimation.diagnosis.fit import DiagnosisError, bic

from estimation.diagnosis.sfra.fingerprint import Fingerprint, model_y
from estimation.diagnosis.sfra.sweep import MODEL_FLOOR, Sweep
from estimation.diagnosis.sfra.winding import ShortedLoop, WindingModel

__all__ = ["Candidate", "SfraDiagnosis", "diagnose_sweep", "drift_sigma", "CAUSES", "MIN_GAIN", "MIN_DELTA_BIC",
           "SHUNT_DRIFT"]

CAUSES = ("shorted-turns", "radial-deformation", "axial-displacement")

#: Minimum fraction of the baseline cost a cause must remove to be named.
MIN_GAIN = 0.3
#: Minimum BIC improvement over the unchanged reference model.
MIN_DELTA_BIC = 10.0
#: Every ``DECIMATE``-th frequency point enters the fault fits (~100 points per decade remain).
DECIMATE = 2

#: Referred loop resistance (Ohm) below which a short is reported as bolted.
BOLTED_BELOW_OHM = 30.0

#: Relative drift of the reference model's port shunts between sweeps (see the module docstring).
SHUNT_DRIFT = 0.2


@dataclass
class Candidate:
    """One fitted fault hypothesis.

    Attributes
    ----------
    cause : str
        Catalogue name.
    section : int
        1-based section (from the port-1 end).
    params : dict
        Fitted change (names and values with units in the names).
    cost : float
        Weighted residual sum of squares.
    gain : float
        ``1 - cost / baseline cost``.
    dbic : float
        BIC improvement over the unchanged reference model (positive = better).
    model : WindingModel
        The changed model.
    position_std : float or None
        Standard deviation of the fitted loop position in sections (shorted turns only): from the
        Jacobian at the optimum, ``cov = (J^T J)^-1 cost / (n - p)`` (the residuals are weighted, the
        factor scales them to the misfit actually left).
    """

    cause: str
    section: int
    params: dict
    cost: float
    gain: float
    dbic: float
    model: WindingModel = field(repr=False, default=None)
    position_std: float | None = None

    def as_json(self) -> dict:
        """Candidate row for the JSON output."""
        return {"cause": self.cause, "section": self.section, "gain": round(self.gain, 6),
                "dBIC": round(self.dbic, 3), "params": self.params}


@dataclass
class SfraDiagnosis:
    """Outcome of :func:`diagnose_sweep` (see :meth:`as_json`)."""

    cause: str
    best: Candidate | None
    candidates: list[Candidate]
    baseline_cost: float
    n_residuals: int
    fingerprint: Fingerprint
    reference: Sweep
    measured: Sweep
    seconds: float
    by_section: dict = field(default_factory=dict)

    @property
    def gain(self) -> float:
        """Gain of the named cause (0 for ``none``)."""
        return self.best.gain if (self.best is not None and self.cause != "none") else 0.0

    @property
    def fault_model(self) -> WindingModel:
        """The model of the named cause (the reference model for ``none``)."""
        return self.best.model if (self.best is not None and self.cause != "none") else self.fingerprint.model

    def location(self) -> dict | None:
        """``{"section", "fraction", "fraction_std", "of_sections"}`` of the named cause.

        ``fraction`` is the fitted loop position over ``N`` for shorted turns,
        else the section's centre ``(k - 0.5) / N``, from the port-1 end.
        ``fraction_std`` is its standard deviation: from the fit's Jacobian
        for shorted turns, ``1 / (N sqrt(12))`` (uniform over the section)
        for the causes placed by section only.
        """
        if self.cause == "none" or self.best is None:
            return None
        n = self.fingerprint.n_sections
        pos = self.best.params.get("position_sections", self.best.section - 0.5)
        std = self.best.position_std if self.best.position_std is not None else 1.0 / np.sqrt(12.0)
        return {"section": self.best.section, "fraction": float(np.clip(pos / n, 0.0, 1.0)),
                "fraction_std": float(std / n), "of_sections": n}

    def severity(self) -> dict | None:
        """Severity of the named cause (shorted fraction and fault resistance for shorted turns)."""
        if self.cause == "none" or self.best is None:
            return None
        p = self.best.params
        if self.cause == "shorted-turns":
            r = p["resistance_ohm"]
            return {"shorted_fraction": p["coupling"] ** 2, "fault_resistance_ohm": r,
                    "kind": "bolted" if r < BOLTED_BELOW_OHM else "resistive"}
        return {"shorted_fraction": None, "fault_resistance_ohm": None, **p}

    def as_json(self) -> dict:
        """The JSON object (indices added by the caller)."""
        return {
            "cause": self.cause,
            "location": (self.location() or {}).get("fraction"),
            "location_std": (self.location() or {}).get("fraction_std"),
            "section": (self.location() or {}).get("section"),
            "severity": self.severity(),
            "gain": round(self.gain, 6),
            "candidates": [c.as_json() for c in self.candidates],
            "model_order": self.fingerprint.n_sections,
            "causes": [] if self.cause == "none" else [self.cause],
            "steps": [] if self.cause == "none" or self.best is None else
            [{"cause": self.cause, "gain": round(self.best.gain, 6), "delta_bic": round(self.best.dbic, 3)}],
            "baseline_cost": self.baseline_cost,
            "extended_cost": self.best.cost if (self.best is not None and self.cause != "none") else self.baseline_cost,
            "n_residuals": self.n_residuals,
            "reference_fit": {"rms": self.fingerprint.rms, "resonances": self.fingerprint.resonances,
                              "tried": self.fingerprint.tried, "fit_seconds": self.fingerprint.fit_seconds,
                              "cached": self.fingerprint.cached},
            "seconds": self.seconds,
        }


def _shorted(base: WindingModel, k: int) -> tuple[Callable, list, tuple, Callable]:
    def build(p):
        return base.copy(loops=[ShortedLoop(k, float(1.0 - np.exp(p[0])), float(np.exp(p[1])), float(p[2]))])

    def describe(p):
        return {"coupling": float(1.0 - np.exp(p[0])), "resistance_ohm": float(np.exp(p[1])),
                "position_sections": float(p[2])}

    c = k + 0.5
    starts = [[np.log(0.1), np.log(1.0), c], [np.log(0.01), np.log(100.0), c], [np.log(0.3), np.log(1e4), c]]
    return build, starts, ([np.log(1e-4), np.log(1e-3), float(k)], [0.0, np.log(1e7), k + 1.0]), describe


def _radial(base: WindingModel, k: int) -> tuple[Callable, list, tuple, Callable]:
    def build(p):
        cs = np.array(base.Cs, dtype=float)
        cg = np.array(base.Cg, dtype=float)
        cs[k] *= np.exp(p[0])
        cg[k:k + 2] *= np.exp(p[1])
        return base.copy(Cs=cs, Cg=cg)

    def describe(p):
        return {"series_capacitance_factor": float(np.exp(p[0])), "ground_capacitance_factor": float(np.exp(p[1]))}

    starts = [[0.0, 0.0], [0.4, -0.4], [-0.4, 0.4]]
    return build, starts, ([np.log(0.1)] * 2, [np.log(10.0)] * 2), describe


def _axial(base: WindingModel, k: int) -> tuple[Callable, list, tuple, Callable]:
    def build(p):
        g = np.ones(base.n) if base.coupling_scale is None else np.array(base.coupling_scale, dtype=float)
        g[k] = p[0]
        return base.copy(coupling_scale=g)

    def describe(p):
        return {"coupling_factor": float(p[0])}

    return build, [[0.99], [0.9], [0.7]], ([0.3], [1.02]), describe


def drift_sigma(base: WindingModel, y_ref: np.ndarray, y_new: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Add the port-shunt drift to the residual standard deviations of ``Y11`` and ``Y22``.

    Parameters
    ----------
    base : WindingModel
        Reference model (its port shunts ``g1 + j b1``, ``g2 + j b2`` in S).
    y_ref, y_new : numpy.ndarray
        Measured ``Y11, Y21, Y22`` of the two sweeps, S, shape ``(F, 3)``.
    sigma : numpy.ndarray
        Standard deviation of the log residuals without the drift, shape ``(F, 3)``.

    Returns
    -------
    numpy.ndarray
        ``sqrt(sigma**2 + (SHUNT_DRIFT |y_p|)**2 (1/|Y_pp,ref|**2 + 1/|Y_pp,new|**2))``
        for the two driving-point columns; ``Y21`` unchanged.
    """
    out = np.array(sigma, dtype=float)
    for col, shunt in ((0, base.g1 + 1j * base.b1), (2, base.g2 + 1j * base.b2)):
        e = SHUNT_DRIFT * abs(shunt)
        with np.errstate(all="ignore"):
            extra = e**2 * (1.0 / np.abs(y_ref[:, col]) ** 2 + 1.0 / np.abs(y_new[:, col]) ** 2)
        out[:, col] = np.sqrt(out[:, col] ** 2 + np.where(np.isfinite(extra), extra, 0.0))
    return out


_FACTORIES = {"shorted-turns": _shorted, "radial-deformation": _radial, "axial-displacement": _axial}

#: Starts always fitted per section (the bolted, intermediate and resistive regimes of a short); the
#: further starts of a cause, and every start after the first of the others, only retry a failed fit.
_ALL_STARTS = {"shorted-turns": 3, "radial-deformation": 1, "axial-displacement": 1}


def _position_std(jac: np.ndarray, fun: np.ndarray, active: np.ndarray, n_freq: int) -> float | None:
    """Standard deviation of the loop position (parameter 3 of a short, in sections) from the Jacobian.

    ``cov = (J^T J)^-1 s^2 n / n_eff``: ``s^2 = sum r^2 / (n - p)`` scales the weighted residuals ``r`` to
    the misfit actually left, and ``n / n_eff`` counts the residuals' correlation along the sweep (a model
    misfit is smooth in frequency, not white): ``n_eff`` is the sum over the residual series (real and
    imaginary part of each response) of Bartlett's number of independent points.  A parameter the fit left
    on a bound (``active``: scipy's ``active_mask``) is held there: its column is dropped.  The variance is
    then combined with the section's own, ``1/12`` (a position uniform over the section the fit keeps it in):
    ``1 / (1 / v + 12)``.
    """
    from estimation.diagnosis.sfra.repeatability import effective_points

    j = np.asarray(jac, dtype=float)
    r = np.asarray(fun, dtype=float)
    n, p = r.size, (j.shape[1] if j.ndim == 2 else 0)
    if p < 3 or j.shape[0] != n or n % n_freq or not (np.all(np.isfinite(j)) and np.all(np.isfinite(r))):
        return None
    series = r.reshape(2, n_freq, -1).transpose(0, 2, 1).reshape(-1, n_freq)  # [re, im] x response, along f
    n_eff = sum(effective_points(x) for x in series)
    keep = [i for i in range(p) if i == 2 or not np.asarray(active)[i]]
    jk = j[:, keep]
    cov = np.linalg.pinv(jk.T @ jk) * float(r @ r) / max(1, n - len(keep)) * n / max(n_eff, 1.0)
    v = float(cov[keep.index(2), keep.index(2)])
    if not (np.isfinite(v) and v >= 0):
        return None
    # the fit keeps the loop inside its section: a uniform position there (variance 1/12 section^2) is the
    # prior, which bounds the variance where the position trades off against the coupling (near the ends)
    return float(np.sqrt(1.0 / (1.0 / max(v, 1e-300) + 12.0)))


def _log(msg: str, progress: bool) -> None:
    if progress:
        print(f"[sfra] {msg}", file=sys.stderr, flush=True)


def diagnose_sweep(fp: Fingerprint, reference: Sweep, measured: Sweep, progress: bool = True,
                   causes: tuple[str, ...] = CAUSES, max_nfev: int = 40) -> SfraDiagnosis:
    """Find the change of the fingerprint model that explains a new sweep (see :func:`_diagnose`)."""
    with threadpool_limits(limits=1):  # small matrices: threaded BLAS only contends for the cores
        return _diagnose(fp, reference, measured, progress, causes, max_nfev)


def _diagnose(fp: Fingerprint, reference: Sweep, measured: Sweep, progress: bool = True,
                   causes: tuple[str, ...] = CAUSES, max_nfev: int = 40) -> SfraDiagnosis:
    """Find the change of the fingerprint model that explains a new sweep.

    Parameters
    ----------
    fp : Fingerprint
        The reference model.
    reference, measured : Sweep
        The healthy sweep the model was fitted to, and the new sweep (same frequencies).
    progress : bool
        Progress lines on stderr.
    causes : tuple of str
        Catalogue entries to try.
    max_nfev : int
        Function evaluations per start.

    Raises
    ------
    DiagnosisError
        If the two sweeps are not on the same frequencies.
    """
    t0 = time.perf_counter()
    f = reference.frequency_hz
    if measured.frequency_hz.shape != f.shape or not np.allclose(measured.frequency_hz, f, rtol=1e-6, atol=0):
        raise DiagnosisError(f"{measured.source or 'measured sweep'}: its {measured.frequency_hz.size} frequencies "
                             f"differ from the reference's {f.size}; sweep both on the same grid")
    base = fp.model
    sel = np.arange(0, f.size, DECIMATE)
    f = f[sel]
    y_ref_model = model_y(base, f)
    with np.errstate(all="ignore"):
        target = np.log(measured.y[sel] / reference.y[sel])
    sigma = drift_sigma(base, reference.y[sel], measured.y[sel],
                        np.sqrt(reference.noise[sel] ** 2 + measured.noise[sel] ** 2 + MODEL_FLOOR**2))

    def residuals(model: WindingModel) -> np.ndarray:
        with np.errstate(all="ignore"):
            r = (np.log(model_y(model, f) / y_ref_model) - target) / sigma
        out = np.concatenate([r.real.ravel(), r.imag.ravel()])
        return np.where(np.isfinite(out), out, 1e6)

    r0 = residuals(base)
    c0 = float(np.sum(r0**2))
    n_r = r0.size
    bic0 = bic(c0, n_r, 0)
    candidates: list[Candidate] = []
    by_section: dict[str, list] = {}
    for cause in causes:
        best = None
        rows = []
        for k in range(base.n):
            build, starts, bounds, describe = _FACTORIES[cause](base, k)
            fits = []
            for i, s in enumerate(starts):
                if i >= _ALL_STARTS.get(cause, len(starts)) and min(t[0] for t in fits) < c0:
                    break  # the remaining starts are retries of a failed fit
                x0 = np.clip(np.asarray(s, dtype=float), np.asarray(bounds[0]) + 1e-9, np.asarray(bounds[1]) - 1e-9)
                with np.errstate(all="ignore"):
                    sol = least_squares(lambda p: residuals(build(p)), x0, bounds=bounds, max_nfev=max_nfev)
                cost = float(np.sum(sol.fun**2))
                fits.append((cost if np.isfinite(cost) else np.inf, sol.x, sol.jac, sol.fun, sol.active_mask))
            cost, x, jac, fun, active = min(fits, key=lambda t: t[0])
            rows.append(cost)
            if not (np.isfinite(cost) and cost < c0):
                continue  # failed fit: not a candidate
            cand = Candidate(cause, k + 1, describe(x), cost, 1.0 - cost / c0, bic0 - bic(cost, n_r, len(x)),
                             build(x), _position_std(jac, fun, active, f.size) if cause == "shorted-turns" else None)
            if best is None or cand.cost < best.cost:
                best = cand
        by_section[cause] = [max(0.0, 1.0 - c / c0) if np.isfinite(c) else 0.0 for c in rows]
        if best is not None:
            candidates.append(best)
            _log(f"  {cause:<20} best section {best.section}/{base.n}: gain {best.gain:.3f}, dBIC {best.dbic:.0f}",
                 progress)
        else:
            _log(f"  {cause:<20} no fit below the baseline cost", progress)
    candidates.sort(key=lambda c: -c.dbic)
    top = candidates[0] if candidates else None
    named = top is not None and top.dbic >= MIN_DELTA_BIC and top.gain >= MIN_GAIN
    return SfraDiagnosis(top.cause if named else "none", top, candidates, c0, n_r, fp, reference, measured,
                         time.perf_counter() - t0, by_section)
