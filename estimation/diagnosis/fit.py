"""Least-squares fits of a circuit (and an extension) to measured frequency responses.

The residual of response ``r`` at frequency ``f_k`` is the complex log error
``e = ln(H_model / H_measured)``: its real part is the log-magnitude error,
its imaginary part the phase error in radians. Each response is weighted so
that it counts equally whatever its number of points; the cost is
``sum_r mean_k |e_rk|^2`` (dimensionless).

Circuit values are fitted in log scale relative to their starting values
(positive by construction); couplings stay at their baseline values, which
keeps the inductance matrix positive definite whatever the fit does to the
self-inductances.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from pris_cosim.circuit import Circuit
from pris_cosim.errors import NonPassiveWarning
from pris_cosim.frf import ResponseModel
from pris_cosim.models import Configuration

from .catalogue import Extension


class DiagnosisError(ValueError):
    """Input that a diagnosis cannot use (the message says why)."""


def bic(rss: float, n_residuals: int, n_params: int) -> float:
    """Bayesian information criterion ``N ln(RSS/N) + k ln N`` (Gaussian residuals)."""
    n = n_residuals
    return float(n * np.log(max(rss, 1e-300) / n) + n_params * np.log(n))


def significant(baseline_bic: float, baseline_cost: float, bic_: float, cost: float,
                min_delta_bic: float, min_gain: float) -> bool:
    """The naming rule: an extension counts only if it beats the baseline's BIC and removes enough cost."""
    return baseline_bic - bic_ >= min_delta_bic and 1 - cost / baseline_cost >= min_gain


@dataclass
class FitResult:
    """Outcome of one fit.

    Attributes
    ----------
    cause : str
        ``none`` for the baseline, else the extension's cause.
    circuit : Circuit
        The circuit that was fitted (with structural changes).
    values : dict
        Fitted free values (name -> SI value).
    extra : dict
        Fitted extension parameters.
    cost : float
        ``sum_r mean_k |e_rk|^2``.
    rss, n_residuals, n_params : float, int, int
        Unweighted residual sum of squares and counts, for the information criterion.
    predicted, errors : dict
        Model responses and complex log errors per response name.
    """

    cause: str
    circuit: Circuit
    values: dict[str, float]
    extra: dict[str, float]
    cost: float
    rss: float
    n_residuals: int
    n_params: int
    predicted: dict[str, np.ndarray] = field(repr=False)
    errors: dict[str, np.ndarray] = field(repr=False)
    nfev: int = 0
    wall_s: float = 0.0

    @property
    def bic(self) -> float:
        """Bayesian information criterion ``N ln(RSS/N) + k ln N``."""
        return bic(self.rss, self.n_residuals, self.n_params)


def coupling_names(circuit: Circuit) -> set[str]:
    """Lower-case names of K elements and of the parameters their values are built from."""
    from pris_cosim.expressions import Expression

    names: set[str] = set()
    used_by_rlc: set[str] = set()
    for e in circuit.elements:
        if isinstance(e.value, Expression):
            (names if e.kind == "K" else used_by_rlc).update(e.value.names)
        if e.kind == "K":
            names.add(e.key)
    return names - used_by_rlc


class FrequencyFit:
    """Fit a circuit's free values (plus an extension's parameters) to measured responses.

    Parameters
    ----------
    circuit : Circuit
    configurations : sequence of Configuration
        Which responses the circuit produces and how it is driven for each.
    frequency_hz : numpy.ndarray, Hz
    measured : mapping
        Response name to complex values on ``frequency_hz``.
    fixed : sequence of str
        Names kept at their values (besides every coupling).
    extension : Extension, optional
    """

    def __init__(
        self,
        circuit: Circuit,
        configurations: Sequence[Configuration],
        frequency_hz: np.ndarray,
        measured: Mapping[str, np.ndarray],
        fixed: Sequence[str] = (),
        extension: Extension | None = None,
    ):
        self.extension = extension
        self.circuit = extension.prepare(circuit) if extension else circuit
        self.f = np.asarray(frequency_hz, float)
        self.measured = dict(measured)
        self.models: list[ResponseModel] = []
        produced: list[str] = []
        for cfg in configurations:
            wanted = [r for r in cfg.responses if r.name in self.measured]
            produced += [r.name for r in cfg.responses]
            if wanted:
                self.models.append(ResponseModel(self.circuit, cfg.port, shorts=cfg.shorts, responses=wanted))
        unknown = [n for n in self.measured if n not in produced]
        if unknown:
            raise DiagnosisError(
                f"measured response {unknown[0]!r} is not a response of the model (it has: {', '.join(produced)})"
            )
        fixed_keys = {n.lower() for n in fixed} | coupling_names(self.circuit)
        self.free = [n for n in self.circuit.free_names() if n.lower() not in fixed_keys
                     and not (self.circuit.has_element(n) and self.circuit.element(n).kind == "K")]
        base = self.circuit.resolve(check=False)
        env = self.circuit.parameter_values()
        self.start = np.array([float(env[n.lower()]) if n.lower() in env else float(base[n.lower()]) for n in self.free])
        self.extra = list(extension.parameters) if extension else []
        n_points = sum(self.f.size for _ in self.measured)
        if self.f.size < 5 or n_points < 2 * (len(self.free) + len(self.extra)):
            raise DiagnosisError(
                f"too few points: {self.f.size} frequencies for {len(self.free) + len(self.extra)} parameters"
            )

    # ------------------------------------------------------------------ model
    def overrides(self, x: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.free, self.start * np.exp(x[: len(self.free)]))}

    def extra_values(self, x: np.ndarray) -> dict[str, float]:
        tail = x[len(self.free):]
        return {p.name: float(np.exp(v) if p.log else v) for p, v in zip(self.extra, tail)}

    def predict(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Model responses for one parameter vector (log-ratio base values, then extension parameters)."""
        return {k: v[0] for k, v in self.predict_batch(np.atleast_2d(x)).items()}

    def predict_batch(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Model responses for a population of parameter vectors, shape ``(P, F)`` per response."""
        P, F = X.shape[0], self.f.size
        over = {n: self.start[i] * np.exp(X[:, i]) for i, n in enumerate(self.free)}
        out: dict[str, np.ndarray] = {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NonPassiveWarning)
            if self.extension is not None and self.extra:
                tail = X[:, len(self.free):]
                extra = {p.name: (np.exp(tail[:, j]) if p.log else tail[:, j])[:, None] for j, p in enumerate(self.extra)}
                values = self.circuit.resolve(over, check=False)
                values = {k: (np.asarray(v)[:, None] if np.ndim(v) else v) for k, v in values.items()}
                pf = self.extension.per_frequency(self.circuit, values, self.f[None, :], extra)
                pf = {k: np.broadcast_to(v, (P, F)) for k, v in pf.items()}
                for m in self.models:
                    out.update(m.evaluate_grid(self.f, over, pf))
            else:
                for m in self.models:
                    res = m.evaluate(self.f, over)
                    out.update({k: np.broadcast_to(v, (P, F)) for k, v in res.items()})
        return out

    def errors(self, predicted: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {n: np.log(predicted[n] / self.measured[n]) for n in self.measured}

    def residuals_batch(self, X: np.ndarray) -> np.ndarray:
        """Weighted residual vectors, shape ``(P, n_residuals)``."""
        pred = self.predict_batch(X)
        parts = []
        for n, meas in self.measured.items():
            e = np.log(pred[n] / meas)
            parts.append(np.concatenate([e.real, e.imag], axis=1) / np.sqrt(2 * meas.size))
        r = np.concatenate(parts, axis=1)
        return np.where(np.isfinite(r), r, 1e3)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.residuals_batch(np.atleast_2d(x))[0]

    def jacobian(self, x: np.ndarray, step: float = 1e-6) -> np.ndarray:
        """Forward-difference Jacobian, all perturbed vectors evaluated as one batch."""
        X = np.vstack([x, x + step * np.eye(x.size)])
        R = self.residuals_batch(X)
        return (R[1:] - R[0]).T / step

    # ------------------------------------------------------------------ fitting
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = [-np.log(100.0)] * len(self.free) + [np.log(p.lower) if p.log else p.lower for p in self.extra]
        hi = [np.log(100.0)] * len(self.free) + [np.log(p.upper) if p.log else p.upper for p in self.extra]
        return np.array(lo), np.array(hi)

    def fit(self, extra_starts: Sequence[Mapping[str, float]] | None = None, max_nfev: int = 100,
            cause: str | None = None, keep_starts: int = 3) -> FitResult:
        """Fit from the most promising starts (extension parameter guesses, screened in one batch); keep the best."""
        t0 = time.perf_counter()
        lo, hi = self.bounds()
        starts = list(extra_starts or [{}])
        if self.extra and starts == [{}]:
            grids = np.meshgrid(*[p.starts for p in self.extra], indexing="ij")
            starts = [{p.name: float(g.flat[i]) for p, g in zip(self.extra, grids)} for i in range(grids[0].size)]
        best = None
        x0s = np.array([np.clip(np.concatenate([np.zeros(len(self.free)),
                                                [np.log(s[p.name]) if p.log else s[p.name] for p in self.extra]]),
                                lo + 1e-9, hi - 1e-9) for s in starts])
        nfev = len(x0s)
        if len(x0s) > keep_starts:  # screen all starts in one batch, fit from the most promising ones
            r = self.residuals_batch(x0s)
            x0s = x0s[np.argsort(np.sum(r * r, axis=1))[:keep_starts]]
        for x0 in x0s:
            sol = least_squares(self.residuals, x0, jac=self.jacobian, bounds=(lo, hi), x_scale="jac",
                                max_nfev=max_nfev, xtol=1e-8, ftol=1e-8)
            nfev += sol.nfev
            if best is None or sol.cost < best.cost:
                best = sol
        assert best is not None
        pred = self.predict(best.x)
        err = self.errors(pred)
        cost = float(sum(np.mean(np.abs(v) ** 2) for v in err.values()))
        rss = float(sum(np.sum(np.abs(v) ** 2) for v in err.values()))
        n_res = int(sum(2 * v.size for v in err.values()))
        return FitResult(
            cause=cause or (self.extension.cause if self.extension else "none"),
            circuit=self.circuit,
            values=self.overrides(best.x),
            extra=self.extra_values(best.x),
            cost=cost, rss=rss, n_residuals=n_res, n_params=len(self.free) + len(self.extra),
            predicted=pred, errors=err, nfev=nfev, wall_s=time.perf_counter() - t0,
        )
