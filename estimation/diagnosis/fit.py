"""Least-squares fits of a circuit (and any effects of the catalogue) to measured frequency responses.

The residual of response ``r`` at frequency ``f_k`` is the complex log error
``e = ln(H_model / H_measured)``: its real part is the log-magnitude error,
its imaginary part the phase error in radians. Each response is weighted so
that it counts equally whatever its number of points; the cost is
``sum_r mean_k |e_rk|^2`` (dimensionless), or with per-point weights from the
data's stated uncertainty ``sum_r mean_k u_rk^2 |e_rk|^2`` (``u_rk``
inverse standard deviations scaled to a mean square of one per response).

Circuit values are fitted in log scale relative to their starting values
(positive by construction); couplings stay at their starting values, which
keeps the inductance matrix positive definite whatever the fit does to the
self-inductances, unless named in ``couplings`` (a structural change frees
the couplings of the sections it touches): those are fitted as
``ln((1 - k) / (1 - k_0))``, so ``k`` stays below 1 and a coupling near
unity moves by steps relative to its leakage ``1 - k``. A step that leaves
the inductance matrix not positive definite gets the residuals of a
non-finite response.

Speed: responses come from the pole-residue form of the constant circuit
with the effects closed around it (:mod:`.network`); a batch of parameter
vectors shares one eigen-decomposition per distinct set of circuit values,
so the Jacobian columns of the effects' own parameters (and a fit of those
alone, :meth:`FrequencyFit.fit` with ``circuit_free=False``) need none. With
:data:`ANALYTIC_JACOBIAN` the Jacobian columns of the circuit values are
analytic (:meth:`FrequencyFit.circuit_jacobian`): the adjoint of the closed
nodal system, whose solution comes from the eigen-decomposition of the same
evaluation, so a Jacobian costs no eigen-decomposition at all.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.expressions import Expression
from pris_cosim.models.builtin import Configuration

from estimation.diagnosis.causes.catalogue import Effect, Groups, winding_groups
from estimation.diagnosis.network import ProbedConfiguration
from estimation.diagnosis.prior import DesignPrior


#: Jacobian columns of the circuit values analytic (:meth:`FrequencyFit.circuit_jacobian`, about half the time of a
#: diagnosis); False: forward differences of step 1e-6, as the effects' columns.
ANALYTIC_JACOBIAN = True

#: Smoothing widths (decades of frequency) of a continued fit (:meth:`FrequencyFit.fit_continued`): the baseline's,
#: whose resonances are a few per cent off the measured ones.
CONTINUATION = (0.1, 0.03, 0.01)
#: ... and from a decade, for starts whose resonances are 10-20 % off (the seeds of a new section): their broad shape
#: is drawn together first (a schedule starting at 0.1 decade leaves such a start hundreds of times above the noise).
WIDE_CONTINUATION = (1.0, 0.5, 0.25, 0.1, 0.05)
#: ... and a second schedule from three decades: which seed reaches the noise through which schedule is erratic (the
#: paths branch at every resonance), so a seed missed by one schedule may be found by the other.
WIDER_CONTINUATION = (3.0, 1.0, 0.5, 0.25, 0.1, 0.05)


class DiagnosisError(ValueError):
    """Input that a diagnosis cannot use (the message says why)."""


def current_nc(r: FitResult) -> int:
    """Number of circuit values in a fit's parameter vector (the effects' parameters follow them)."""
    return r.x.size - sum(len(e.parameters) for e in r.effects)


#: What a fit of a candidate structure may raise (a degenerate network, a failed solve): the candidate is dropped.
CANDIDATE_FAILURES = (DiagnosisError, ValueError, CircuitError, np.linalg.LinAlgError)


def bic(rss: float, n_residuals: int, n_params: int) -> float:
    """Bayesian information criterion ``N ln(RSS/N) + k ln N`` (Gaussian residuals)."""
    n = n_residuals
    return float(n * np.log(max(rss, 1e-300) / n) + n_params * np.log(n))


def significant(baseline_bic: float, baseline_cost: float, bic_: float, cost: float,
                min_delta_bic: float, min_gain: float) -> bool:
    """The naming rule: an extension counts only if it beats the reference BIC and removes enough cost."""
    return baseline_bic - bic_ >= min_delta_bic and 1 - cost / baseline_cost >= min_gain


@dataclass
class FitResult:
    """Outcome of one fit.

    Attributes
    ----------
    cause : str
        ``none`` for the baseline, else the causes joined by ``+``.
    circuit : Circuit
        The circuit that was fitted (with structural changes).
    values : dict
        Fitted free values (name -> SI value).
    extra : dict
        Fitted effect parameters (of the one effect; by cause when several).
    cost : float
        ``sum_r mean_k |e_rk|^2``.
    rss, n_residuals, n_params : float, int, int
        Unweighted residual sum of squares and counts, for the information criterion.
    predicted, errors : dict
        Model responses and complex log errors per response name.
    causes : list of str
        The causes in the model, in the order added.
    effects : list of Effect
        The fitted effects (form and group included).
    params : list of dict
        Parameters of each effect.
    structure : str
        How the circuit was changed (missing section), else empty.
    penalty, penalty_rss : float
        The design prior's penalty in cost units and in residual-sum units
        (0 without a prior).
    cause_prior : mapping
        ``-2 ln`` of the prior share of one alternative of a cause, by cause (BIC units): added to the BIC for
        each cause in ``causes`` in :attr:`cause_bic` (:attr:`.context.Context.cause_prior`).
    """

    cause: str
    circuit: Circuit
    values: dict[str, float]
    extra: dict
    cost: float
    rss: float
    n_residuals: int
    n_params: int
    predicted: dict[str, np.ndarray] = field(repr=False)
    errors: dict[str, np.ndarray] = field(repr=False)
    nfev: int = 0
    wall_s: float = 0.0
    causes: list[str] = field(default_factory=list)
    effects: list[Effect] = field(default_factory=list, repr=False)
    params: list[dict[str, float]] = field(default_factory=list)
    structure: str = ""
    x: np.ndarray = field(default=None, repr=False)
    penalty: float = 0.0
    penalty_rss: float = 0.0
    #: Couplings (K element names) fitted with the values (:class:`FrequencyFit`'s ``couplings``).
    couplings: tuple[str, ...] = ()
    cause_prior: Mapping[str, float] = field(default_factory=dict, repr=False)

    @property
    def bic(self) -> float:
        """Bayesian information criterion ``N ln(RSS/N) + k ln N``, on the cost penalised by the design prior."""
        return bic(self.rss + self.penalty_rss, self.n_residuals, self.n_params)

    @property
    def cause_bic(self) -> float:
        """:attr:`bic` plus each named cause's prior share (``cause_prior``): how models with different causes
        are weighed against each other and against a drift (two fits of one model differ in :attr:`bic` alone)."""
        return self.bic + sum(self.cause_prior.get(c, 0.0) for c in set(self.causes))

    @property
    def objective(self) -> float:
        """What the fit minimised: the cost plus the design prior's penalty (:mod:`.prior`)."""
        return self.cost + self.penalty

    def fitted_circuit(self) -> Circuit:
        """The fitted circuit (constant values; effects not applied)."""
        return self.circuit.with_values(self.values)

    def describe(self) -> list[dict]:
        """Per effect: cause, form, group and formula with the fitted values."""
        return [{"cause": e.cause, "form": e.form, "group": e.group, "label": e.label, "parameters": p,
                 "formula": e.formula(p)} for e, p in zip(self.effects, self.params)]


def coupling_names(circuit: Circuit) -> set[str]:
    """Lower-case names of K elements and of the parameters their values are built from."""
    from pris_cosim.circuits.expressions import Expression

    names: set[str] = set()
    used_by_rlc: set[str] = set()
    for e in circuit.elements:
        if isinstance(e.value, Expression):
            (names if e.kind == "K" else used_by_rlc).update(e.value.names)
        if e.kind == "K":
            names.add(e.key)
    return names - used_by_rlc


def group_names(configurations: Sequence[Configuration]) -> dict[str, str]:
    """Port node to winding group: ``lv`` / ``hv`` from the configuration names, else the node."""
    out: dict[str, str] = {}
    for cfg in configurations:
        name = cfg.name.upper()
        if name.startswith("LV"):
            out.setdefault(cfg.port, "lv")
        elif name.startswith("HV"):
            out.setdefault(cfg.port, "hv")
    return out


def configuration_ports(configurations: Sequence[Configuration]) -> list[str]:
    return list(dict.fromkeys(cfg.port for cfg in configurations))


class FrequencyFit:
    """Fit a circuit's free values (plus the effects' parameters) to measured responses.

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
    effects : sequence of Effect
        Frequency-dependent changes fitted with the circuit.
    scale : float, Ohm
        Typical impedance of the data (places added elements such as a core-loss resistor).
    prior : DesignPrior, optional
        Log-normal prior of the circuit values around the design (:mod:`.prior`);
        its penalty is added to the residuals.
    couplings : sequence of str
        K elements (numeric values) fitted too, as ``ln((1 - k) / (1 - k_0))``
        (the others stay at their values).
    weights : mapping, optional
        Response name to per-point weights ``u_k`` (:func:`.evidence.noise_weights`):
        the residuals, the cost and the residual sum are those of ``u_k e_k``.
    cause_prior : mapping, optional
        Cause to ``-2 ln`` of one alternative's prior share (BIC units), given to every result
        (:attr:`FitResult.cause_prior`).
    """

    def __init__(
        self,
        circuit: Circuit,
        configurations: Sequence[Configuration],
        frequency_hz: np.ndarray,
        measured: Mapping[str, np.ndarray],
        fixed: Sequence[str] = (),
        effects: Sequence[Effect] = (),
        scale: float = 1.0,
        prior: DesignPrior | None = None,
        couplings: Sequence[str] = (),
        weights: Mapping[str, np.ndarray] | None = None,
        cause_prior: Mapping[str, float] | None = None,
    ):
        self.cause_prior = cause_prior if cause_prior is not None else {}
        self.effects = list(effects)
        self.configurations = list(configurations)
        self.ports = configuration_ports(self.configurations)
        self.names = group_names(self.configurations)
        groups = winding_groups(circuit, self.ports, self.names)
        for e in self.effects:
            circuit = e.prepare(circuit, groups, scale)
        self.circuit = circuit
        self.groups: Groups = winding_groups(circuit, self.ports, self.names)
        self.f = np.asarray(frequency_hz, float)
        self.s = 2j * np.pi * self.f
        self.measured = dict(measured)
        self.weights = {n: np.asarray(w, float) for n, w in (weights or {}).items() if n in self.measured}
        self.branches: list[str] = []
        for e in self.effects:
            for b in e.branches(self.circuit, self.groups):
                if b not in self.branches:
                    self.branches.append(b)
        self.index = {b.lower(): i for i, b in enumerate(self.branches)}
        self.models: list[ProbedConfiguration] = []
        produced: list[str] = []
        drives: dict[tuple, list] = {}  # configurations driven alike (an impedance and a voltage ratio) share a model
        for cfg in self.configurations:
            wanted = [r for r in cfg.responses if r.name in self.measured]
            produced += [r.name for r in cfg.responses]
            if wanted:
                drives.setdefault((cfg.port, tuple(sorted(cfg.shorts))), []).extend(wanted)
        for (port, shorts), wanted in drives.items():
            self.models.append(ProbedConfiguration(self.circuit, port, shorts, wanted, self.branches))
        unknown = [n for n in self.measured if n not in produced]
        if unknown:
            raise DiagnosisError(
                f"measured response {unknown[0]!r} is not a response of the model (it has: {', '.join(produced)})"
            )
        fixed_keys = {n.lower() for n in fixed} | coupling_names(self.circuit)
        for e in self.effects:
            fixed_keys |= {n.lower() for n in e.fixed(self.circuit, self.groups)}
        self.free = [n for n in self.circuit.free_names() if n.lower() not in fixed_keys
                     and not (self.circuit.has_element(n) and self.circuit.element(n).kind == "K")]
        base = self.circuit.resolve(check=False)
        free_k = {n.lower() for n in fixed} | {n.lower() for n in self.free}
        self.couplings = tuple(dict.fromkeys(
            self.circuit.element(n).name for n in couplings
            if self.circuit.has_element(n) and self.circuit.element(n).kind == "K" and n.lower() not in free_k
            and not isinstance(self.circuit.element(n).value, Expression) and 0 <= float(base[n.lower()]) < 1))
        self.free += list(self.couplings)
        #: Columns of the circuit values that are couplings (fitted as ln((1 - k) / (1 - k0))).
        self.is_k = np.array([i >= len(self.free) - len(self.couplings) for i in range(len(self.free))], bool)
        env = self.circuit.parameter_values()
        self.start = np.array([float(env[n.lower()]) if n.lower() in env else float(base[n.lower()]) for n in self.free])
        self._k_elements = [self.circuit.element(n) for n in self.couplings]
        self.extra = [(j, p) for j, e in enumerate(self.effects) for p in e.parameters]
        self.nc = len(self.free)
        n_points = sum(self.f.size for _ in self.measured)
        if self.f.size < 5 or n_points < 2 * (self.nc + len(self.extra)):
            raise DiagnosisError(
                f"too few points: {self.f.size} frequencies for {self.nc + len(self.extra)} parameters"
            )
        self._cache: tuple[bytes, list[np.ndarray], dict] | None = None
        self._param_keys = {p.key for p in self.circuit.parameters}
        self._branch_values = sorted({k for e in self.effects for k in e.value_names(self.circuit, self.groups)})
        #: Circuit columns of the Jacobian by the nodal derivatives (else forward differences).
        self.analytic_jacobian = ANALYTIC_JACOBIAN
        self.prior = prior
        self._kernel: np.ndarray | None = None
        self._pidx = np.zeros(0, int)
        self._plog = np.zeros(0)
        self._pscale = 0.0
        if prior is not None:
            anchored = prior.anchored(self.circuit)
            idx = [i for i, n in enumerate(self.free) if n.lower() in anchored]
            self._pidx = np.array(idx, int)
            self._plog = np.array([np.log(self.start[i] / prior.design[self.free[i].lower()]) for i in idx])
            self._pscale = prior.scale() / np.sqrt(2.0)  # the data residuals' squares sum to half the cost

    def smooth(self, decades: float) -> None:
        """Compare the log errors smoothed along log-frequency (Gaussian, ``decades`` wide; 0: not smoothed).

        A resonance of the model a few per cent away from the measured one
        gives a log error shaped like a dipole, whose cost hardly changes as
        the resonance moves until it overlaps the measured one: a local fit
        stalls. Smoothed over more than the offset, the dipole becomes
        proportional to the offset, and the fit moves the resonance onto the
        measured one. Fits from smoothed to unsmoothed errors (continuation)
        reach optima a local fit of the raw errors misses.
        """
        if not decades > 0:
            self._kernel = None
            return
        lf = np.log10(self.f)
        k = np.exp(-0.5 * ((lf[:, None] - lf[None, :]) / decades) ** 2)
        self._kernel = (k / k.sum(axis=1, keepdims=True)).T

    @property
    def anchored_columns(self) -> np.ndarray:
        """Columns of the parameter vector whose values the design prior holds (empty without a prior)."""
        return self._pidx

    def design_vector(self, x: np.ndarray) -> np.ndarray:
        """``x`` with every value the design prior holds set to its design value (effects' parameters kept)."""
        out = np.array(x, float)
        out[self._pidx] = -self._plog
        return out

    def prior_residuals(self, X: np.ndarray) -> np.ndarray:
        """The design prior's residuals, shape ``(P, n_anchored)`` (squares sum to half the penalty, as the data's
        sum to half the cost)."""
        return (self._plog + X[:, self._pidx]) * self._pscale

    # ------------------------------------------------------------------ model
    def values_of(self, Xc: np.ndarray) -> np.ndarray:
        """Circuit values (SI; couplings as ``k``) of the circuit part ``Xc`` (..., nc) of parameter vectors."""
        Xc = np.asarray(Xc, float)
        v = self.start * np.exp(Xc)
        if self.couplings:
            v = np.where(self.is_k, 1 - (1 - self.start) * np.exp(Xc), v)
        return v

    def overrides(self, x: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.free, self.values_of(x[: self.nc]))}

    def effect_params(self, X: np.ndarray) -> list[dict[str, np.ndarray]]:
        """Per effect, its parameters as arrays over the rows of ``X``."""
        out: list[dict[str, np.ndarray]] = [dict() for _ in self.effects]
        for col, (j, p) in enumerate(self.extra):
            v = X[:, self.nc + col]
            out[j][p.name] = np.exp(v) if p.log else v
        return out

    def extra_values(self, x: np.ndarray) -> list[dict[str, float]]:
        return [{k: float(v[0]) for k, v in d.items()} for d in self.effect_params(np.atleast_2d(x))]

    def _transfer(self, Xc: np.ndarray) -> tuple[list[np.ndarray], dict]:
        key = Xc.tobytes()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        V = self.values_of(Xc)
        over = {n: V[:, i] for i, n in enumerate(self.free)}
        values = self.circuit.resolve(over, check=False)
        single = Xc.shape[0] == 1
        T = [m.transfer(values, self.s, keep=single) for m in self.models]
        if self.couplings:  # a coupling step that makes the inductance matrix indefinite: no response
            bad = ~(np.atleast_1d(self.circuit.smallest_inductance_eigenvalue(values)) > 0)
            if np.any(bad):
                T = [np.where(bad.reshape((-1,) + (1,) * (t.ndim - 1)), np.nan, t) for t in T]
        if single:
            self._cache = (key, T, values)
        return T, values

    def predict_batch(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Model responses for a population of parameter vectors, shape ``(P, F)`` per response."""
        X = np.atleast_2d(np.asarray(X, float))
        P, F = X.shape[0], self.f.size
        if P == 1:
            uniq, inv = X[:, : self.nc], np.zeros(1, int)
        else:
            uniq, inv = np.unique(X[:, : self.nc], axis=0, return_inverse=True)
            inv = np.ravel(inv)
        T, values = self._transfer(uniq)
        if uniq.shape[0] != P or np.any(inv != np.arange(P)):  # np.unique sorts the rows: back to X's order
            T = [t[inv] for t in T]
            values = {k: (np.asarray(v)[inv] if np.ndim(v) else v) for k, v in values.items()}
        params = self.effect_params(X)
        dz = self._branch_dz(values, params, P) if self.branches else None
        port_effects = [(e, p) for e, p in zip(self.effects, params) if type(e).port_map is not Effect.port_map]

        def port_map(z):
            for e, p in port_effects:
                z = e.port_map(z, self.f, p)
            return z

        out: dict[str, np.ndarray] = {}
        for m, t in zip(self.models, T):
            out.update(m.responses_from(t, dz, port_map if port_effects else None))
        return {k: np.broadcast_to(v, (P, F)) for k, v in out.items()}

    def _branch_dz(self, values: Mapping[str, np.ndarray], params: list[dict[str, np.ndarray]], P: int) -> np.ndarray:
        """The effects' branch impedance changes, shape ``(P, F, k, k)``, Ohm."""
        k = len(self.branches)
        dz = np.zeros((P, self.f.size, k, k), complex)
        for e, p in zip(self.effects, params):
            for names, block in e.branch_changes(self.circuit, self.groups, values, self.f, p):
                idx = [self.index[n.lower()] for n in names]
                dz[:, :, np.array(idx)[:, None], np.array(idx)[None, :]] += block
        return dz

    def predict(self, x: np.ndarray) -> dict[str, np.ndarray]:
        """Model responses for one parameter vector (log-ratio circuit values, then effect parameters)."""
        return {k: v[0] for k, v in self.predict_batch(np.atleast_2d(x)).items()}

    def errors(self, predicted: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        with np.errstate(divide="ignore", invalid="ignore"):
            return {n: np.log(predicted[n] / self.measured[n]) for n in self.measured}

    def residuals_batch(self, X: np.ndarray) -> np.ndarray:
        """Weighted residual vectors, shape ``(P, n_residuals)``."""
        pred = self.predict_batch(X)
        parts = []
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for n, meas in self.measured.items():
                e = np.log(pred[n] / meas)
                if self._kernel is not None:
                    e = np.where(np.isfinite(e), e, 0) @ self._kernel
                if n in self.weights:
                    e = e * self.weights[n]
                parts.append(np.concatenate([e.real, e.imag], axis=1) / np.sqrt(2 * meas.size))
        if self._pidx.size:
            parts.append(self.prior_residuals(X))
        r = np.concatenate(parts, axis=1)
        return np.where(np.isfinite(r), r, 1e3)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        return self.residuals_batch(np.atleast_2d(x))[0]

    def jacobian(self, x: np.ndarray, step: float = 1e-6, columns: np.ndarray | None = None) -> np.ndarray:
        """Jacobian of :meth:`residuals`, shape ``(n_residuals, len(columns))``.

        Columns of the circuit values are analytic (:meth:`circuit_jacobian`)
        unless ``analytic_jacobian`` is False; those of the effects'
        parameters are forward differences (step ``step``), all perturbed
        vectors evaluated as one batch that shares the unperturbed circuit's
        pole-residue form (no new eigen-decomposition).
        """
        cols = np.arange(x.size) if columns is None else np.asarray(columns, int)
        circuit = cols < self.nc
        if not (self.analytic_jacobian and np.any(circuit)):
            return self.difference_jacobian(x, step, cols)
        out = np.empty((self.n_residuals, cols.size))
        out[:, circuit] = self.circuit_jacobian(x, cols[circuit])
        if not np.all(circuit):
            out[:, ~circuit] = self.difference_jacobian(x, step, cols[~circuit])
        return out

    def difference_jacobian(self, x: np.ndarray, step: float = 1e-6, columns: np.ndarray | None = None
                            ) -> np.ndarray:
        """Forward-difference Jacobian (step ``step`` in the parameter vector), one batch of perturbed vectors."""
        cols = np.arange(x.size) if columns is None else columns
        X = np.vstack([x, x + step * np.eye(x.size)[cols]])
        R = self.residuals_batch(X)
        return (R[1:] - R[0]).T / step

    @property
    def n_residuals(self) -> int:
        """Length of the residual vector (data residuals and the prior's)."""
        return 2 * sum(m.size for m in self.measured.values()) + self._pidx.size

    def value_slopes(self, x: np.ndarray, columns: np.ndarray) -> dict[str, np.ndarray]:
        """Derivatives of the resolved element values with respect to circuit columns of the parameter vector.

        Returns element name (lower case) to an array ``(len(columns),)``, SI
        units per unit of the (log-ratio) column. An element that is a free
        value itself has the closed form (``v``, or ``-(1 - k)`` for a
        coupling); a ``.param`` reaches the elements through their
        expressions, differentiated by central differences of the (cheap)
        value resolution.
        """
        cols = np.asarray(columns, int)
        v = self.values_of(x[: self.nc])
        out: dict[str, np.ndarray] = {}
        params = []
        for c, j in enumerate(cols):
            name = self.free[j].lower()
            if name in self._param_keys:
                params.append((c, j))
            else:
                out.setdefault(name, np.zeros(cols.size))[c] += -(1 - v[j]) if self.is_k[j] else v[j]
        if params:
            h, n = 1e-5, len(params)
            Xp = np.repeat(np.asarray(x[None, : self.nc], float), 2 * n, axis=0)
            for r, (_, j) in enumerate(params):
                Xp[r, j] += h
                Xp[n + r, j] -= h
            V = self.values_of(Xp)
            vals = self.circuit.resolve({name: V[:, i] for i, name in enumerate(self.free)}, check=False)
            for key, val in vals.items():
                val = np.broadcast_to(np.real(np.asarray(val, complex)), (2 * n,))
                d = (val[:n] - val[n:]) / (2 * h)
                if np.any(d != 0):
                    slot = out.setdefault(key, np.zeros(cols.size))
                    for r, (c, _) in enumerate(params):
                        slot[c] += d[r]
        return out

    def circuit_jacobian(self, x: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """Analytic Jacobian columns of the circuit values, shape ``(n_residuals, len(columns))``.

        The constant circuit's transfer functions are differentiated on the
        full nodal system (:meth:`.network.ProbedConfiguration.transfer_derivatives`,
        one factorisation per frequency for all columns), the closed loop of
        the effects' branch changes and the port effects by the chain rule
        (:meth:`.network.ProbedConfiguration.responses_tangent`). Branch
        changes that scale with circuit values (a skin-effect resistance, a
        magnetising inductance) are differentiated by a central difference
        along each column's value change, which is exact for those linear in
        the values; no eigen-decomposition beyond the unperturbed one.
        """
        cols = np.asarray(columns, int)
        J = cols.size
        xr = np.atleast_2d(np.asarray(x, float))
        T, values = self._transfer(xr[:, : self.nc])
        if any(np.isnan(t).all() for t in T):  # no response (an indefinite inductance matrix): constant residuals
            return np.zeros((self.n_residuals, J))
        slopes = self.value_slopes(xr[0], cols)
        params = self.effect_params(xr)
        dz = ddz = None
        if self.branches:
            dz = self._branch_dz(values, params, 1)
            read = [k for k in self._branch_values if k in slopes]
            moves = np.flatnonzero(np.any([slopes[k] != 0 for k in read], axis=0)) if read else np.zeros(0, int)
            if moves.size:  # columns that move a value the branch changes read
                h, n = 1e-6, moves.size
                moved = {}
                for key, v in values.items():
                    base = np.ravel(np.asarray(v))[:1]
                    d = slopes.get(key)
                    moved[key] = (np.concatenate([base + h * d[moves], base - h * d[moves]]) if d is not None
                                  else np.repeat(base, 2 * n))
                dd = self._branch_dz(moved, params, 2 * n)
                ddz = np.zeros((J,) + dz.shape[1:], complex)
                ddz[moves] = (dd[:n] - dd[n:]) / (2 * h)
        port_effects = [(e, p) for e, p in zip(self.effects, params) if type(e).port_map is not Effect.port_map]

        def port_map(z):
            slope = np.ones_like(z)
            for e, p in port_effects:
                slope = slope * e.port_slope(z, self.f, p)
                z = e.port_map(z, self.f, p)
            return z, slope

        pred: dict[str, np.ndarray] = {}
        dpred: dict[str, np.ndarray] = {}
        for m in self.models:
            z, dv = m.response_derivatives(values, slopes, self.s, dz, ddz, kept=True)
            a, b = m.responses_tangent(z, dv, port_map if port_effects else None)
            pred.update(a)
            dpred.update(b)
        parts, base = [], []
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            for n, meas in self.measured.items():
                h = np.broadcast_to(pred[n], (1, self.f.size))[0]
                e = np.log(h / meas)
                de = np.broadcast_to(dpred[n], (J, self.f.size)) / h
                if self._kernel is not None:
                    fin = np.isfinite(e)
                    de = np.where(fin, de, 0) @ self._kernel
                    e = np.where(fin, e, 0) @ self._kernel
                w = 1 / np.sqrt(2 * meas.size)
                parts.append(np.concatenate([de.real, de.imag], axis=1) * w)
                base.append(np.concatenate([e.real, e.imag]))
        if self._pidx.size:
            parts.append((self._pidx[None, :] == cols[:, None]) * self._pscale)
            base.append(np.zeros(self._pidx.size))
        D = np.concatenate(parts, axis=1)
        D[:, ~np.isfinite(np.concatenate(base))] = 0.0  # a residual replaced by a constant
        return np.where(np.isfinite(D), D, 0.0).T

    # ------------------------------------------------------------------ fitting
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the parameter vector: circuit values within a factor 100 of their start (a coupling's
        leakage ``1 - k`` too, and ``k >= 0``), the effects' parameters within theirs."""
        top = np.full(self.nc, np.log(100.0))
        if self.couplings:
            top = np.where(self.is_k, np.minimum(top, -np.log(np.maximum(1 - self.start, 1e-12))), top)
        lo = [-np.log(100.0)] * self.nc + [np.log(p.lower) if p.log else p.lower for _, p in self.extra]
        hi = list(top) + [np.log(p.upper) if p.log else p.upper for _, p in self.extra]
        return np.array(lo), np.array(hi)

    def start_vectors(self, extra_starts: Sequence[Sequence[Mapping[str, float]]] | None = None) -> np.ndarray:
        """Start vectors: the circuit at its values and every combination of the effects' start values.

        ``extra_starts``: per effect a list of parameter dicts (default: each
        effect's grid of ``starts``).
        """
        per_effect = []
        for j, e in enumerate(self.effects):
            given = extra_starts[j] if extra_starts is not None and j < len(extra_starts) and extra_starts[j] else None
            if given is None:
                grids = np.meshgrid(*[p.starts for p in e.parameters], indexing="ij")
                given = [{p.name: float(g.flat[i]) for p, g in zip(e.parameters, grids)} for i in range(grids[0].size)]
            per_effect.append([[np.log(s[p.name]) if p.log else s[p.name] for p in e.parameters] for s in given])
        lo, hi = self.bounds()
        rows = []
        for combo in (np.array(np.meshgrid(*[np.arange(len(g)) for g in per_effect], indexing="ij")).reshape(
                len(per_effect), -1).T if per_effect else [[]]):
            tail = [v for j, i in enumerate(combo) for v in per_effect[j][i]]
            rows.append(np.clip(np.concatenate([np.zeros(self.nc), tail]), lo + 1e-9, hi - 1e-9))
        return np.array(rows)

    def fit(self, extra_starts: Sequence[Sequence[Mapping[str, float]]] | None = None, max_nfev: int = 100,
            cause: str | None = None, keep_starts: int = 3, circuit_free: bool = True,
            x0s: np.ndarray | None = None, must_beat: float | None = None, tol: float = 1e-8,
            grid: bool = True, limits: tuple[np.ndarray, np.ndarray] | None = None) -> FitResult:
        """Fit from the most promising starts (screened in one batch); keep the best.

        Parameters
        ----------
        extra_starts : per effect a list of parameter dicts, optional
        max_nfev : int
            Evaluations per local fit.
        keep_starts : int
            Local fits from the best screened starts.
        circuit_free : bool
            Fit the circuit values too (else only the effects' parameters).
        x0s : numpy.ndarray, optional
            Explicit start vectors (rows), screened with the others.
        must_beat : float, optional
            A fit that ends at or above this cost has failed: the next
            screened starts are tried until one beats it or none is left.
        grid : bool
            Add the effects' start grids to ``x0s`` (always when no ``x0s``).
        limits : (lower, upper) arrays, optional
            Narrower bounds of the parameter vector than :meth:`bounds` (intersected with them).
        """
        t0 = time.perf_counter()
        lo, hi = self.bounds()
        if limits is not None:
            lo, hi = np.maximum(lo, limits[0]), np.minimum(hi, limits[1])
        if x0s is None or grid:
            starts = self.start_vectors(extra_starts)
            if x0s is not None:
                starts = np.vstack([np.atleast_2d(x0s), starts])
        else:
            starts = np.atleast_2d(np.asarray(x0s, float))
        starts = np.clip(starts, lo + 1e-9, hi - 1e-9)
        nfev = len(starts)
        order = np.arange(len(starts))
        if len(starts) > 1:
            r = self.residuals_batch(starts)
            order = np.argsort(np.sum(r * r, axis=1))
        free_idx = np.arange(lo.size) if circuit_free else np.arange(self.nc, lo.size)
        best_x, best_cost = None, np.inf
        for rank, i in enumerate(order):
            if rank >= keep_starts and (must_beat is None or best_cost < must_beat):
                break
            x_full = starts[i].copy()
            if free_idx.size:
                def fun(z, x_full=x_full):
                    x = x_full.copy()
                    x[free_idx] = z
                    return self.residuals(x)

                def jac(z, x_full=x_full):
                    x = x_full.copy()
                    x[free_idx] = z
                    return self.jacobian(x, columns=free_idx)

                sol = least_squares(fun, x_full[free_idx], jac=jac, bounds=(lo[free_idx], hi[free_idx]),
                                    x_scale="jac", max_nfev=max_nfev, xtol=tol, ftol=tol)
                nfev += sol.nfev
                x_full[free_idx] = sol.x
            cost = float(np.sum(self.residuals(x_full) ** 2))
            if cost < best_cost:
                best_x, best_cost = x_full, cost
        assert best_x is not None
        return self.result(best_x, cause, nfev, time.perf_counter() - t0)

    def fit_continued(self, x0: np.ndarray, stages: Sequence[float] = CONTINUATION, stage_nfev: int = 30,
                      max_nfev: int = 100, circuit_free: bool = True, tol: float = 1e-8,
                      prior_in_stages: bool = True) -> FitResult:
        """A local fit from ``x0`` through errors smoothed less and less (:meth:`smooth`), then the raw errors.

        Parameters
        ----------
        x0 : numpy.ndarray
            Start vector.
        stages : sequence of float
            Smoothing widths, decades, widest first.
        stage_nfev, max_nfev : int
            Evaluations per smoothed stage and of the final fit.
        prior_in_stages : bool
            Keep the design prior in the smoothed stages. Without it they
            align the resonances with the data alone: smoothed errors are
            small while a resonance is still far off, and against them the
            prior holds the values where they started.
        """
        t0 = time.perf_counter()
        x = np.asarray(x0, float)
        nfev = 0
        pscale = self._pscale
        try:
            if not prior_in_stages:
                self._pscale = 0.0
            for w in stages:
                self.smooth(w)
                r = self.fit(x0s=x[None], grid=False, keep_starts=1, max_nfev=stage_nfev, circuit_free=circuit_free,
                             tol=1e-6)
                x, nfev = r.x, nfev + r.nfev
        finally:
            self.smooth(0)
            self._pscale = pscale
        r = self.fit(x0s=x[None], grid=False, keep_starts=1, max_nfev=max_nfev, circuit_free=circuit_free, tol=tol)
        r.nfev += nfev
        r.wall_s = time.perf_counter() - t0
        return r

    def result(self, x: np.ndarray, cause: str | None = None, nfev: int = 0, wall: float = 0.0) -> FitResult:
        pred = self.predict(x)
        err = self.errors(pred)
        err = {k: np.where(np.isfinite(v), v, 1e3) for k, v in err.items()}
        u2 = {k: self.weights[k] ** 2 if k in self.weights else 1.0 for k in err}
        cost = float(sum(np.mean(u2[k] * np.abs(v) ** 2) for k, v in err.items()))
        rss = float(sum(np.sum(u2[k] * np.abs(v) ** 2) for k, v in err.items()))
        n_res = int(sum(2 * v.size for v in err.values()))
        params = self.extra_values(x)
        causes = [e.cause for e in self.effects]
        extra = params[0] if len(params) == 1 else {e.cause: p for e, p in zip(self.effects, params)}
        penalty = 2 * float(np.sum(self.prior_residuals(np.atleast_2d(x)) ** 2)) if self._pidx.size else 0.0
        return FitResult(
            cause=cause or ("+".join(causes) if causes else "none"),
            circuit=self.circuit, values=self.overrides(x), extra=extra,
            cost=cost, rss=rss, n_residuals=n_res, n_params=self.nc + len(self.extra),
            predicted=pred, errors=err, nfev=nfev, wall_s=wall, causes=causes, effects=list(self.effects),
            params=params, x=np.asarray(x, float), penalty=penalty, penalty_rss=penalty * self.f.size,
            couplings=self.couplings, cause_prior=self.cause_prior,
        )
