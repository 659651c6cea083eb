"""Estimation parameters: bounds, ties, scaling to the unit cube, physical couplings.

The object model follows the usual least-squares practice: a
:class:`Parameter` has ``value, min, max, vary, expr``; a
:class:`ParameterSet` evaluates tied parameters in dependency order and the
optimiser only sees the packed vector of *varying* parameters. Swarm and
genetic searches work on the unit cube ``[0, 1]^n``: each varying parameter
maps to it linearly or in ``log10`` (R, L, C span decades), so a uniform
sample of the cube is uniform in the chosen scale.

The thesis scales its optimisation variables by ``theta_scale`` (optimiser
value times ``theta_scale`` is the physical value; thesis (4.28), Tables
4.4, 4.8, 5.2). :meth:`ParameterSet.to_scaled` and
:meth:`ParameterSet.from_scaled` provide that view too.

Couplings: a set of coupling coefficients is physical only when the
inductance matrix ``L = D^1/2 K D^1/2`` is positive definite, i.e. when the
coupling (correlation) matrix ``K`` is. :meth:`ParameterSet.evaluate` can
repair a population by shrinking every coupling towards zero by the
smallest factor that makes ``K`` positive definite, or report a mask for a
penalty.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Union

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import ExpressionError
from pris_cosim.circuits.expressions import Expression

Numeric = Union[float, np.ndarray]
Bound = Union[float, tuple[float, float]]

SCALES = ("log", "linear")
PASSIVITY_MODES = ("repair", "penalty", "none")
#: Default upper bound of a coupling coefficient (lower bound 0).
K_MAX = 0.9999
#: Default relative bound factor for R, L, C: ``value / 10 .. value * 10`` (thesis Table 4.4).
DEFAULT_FACTOR = 10.0
_UNIT_KIND = {"ohm": "R", "h": "L", "f": "C", "1": "K"}


def _fmt(x: float) -> str:
    return f"{x:g}"


def engineering_scale(value: float) -> float:
    """Engineering prefix of ``value``: ``10**(3 m)`` with ``1 <= |value| / 10**(3 m) < 1000``.

    This reproduces the scale factors of thesis (4.28) for R, L, C
    (0.083 Ohm -> 1e-3, 970 pF -> 1e-12, 1.6 nF -> 1e-9, 181 uH -> 1e-6).

    Parameters
    ----------
    value : float
        Non-zero value in SI units.

    Returns
    -------
    float
    """
    if value == 0 or not math.isfinite(value):
        return 1.0
    return 10.0 ** (3 * math.floor(math.log10(abs(value)) / 3 + 1e-9))


# ====================================================================== Parameter
@dataclass
class Parameter:
    """One estimation parameter.

    Parameters
    ----------
    name : str
        Circuit parameter or element name (lookup is case-insensitive).
    value : float
        Current (initial or estimated) value, SI units.
    min, max : float
        Bounds, SI units. Finite bounds are required for a varying parameter
        (they define the unit cube); ``min > 0`` for ``scale="log"``.
    vary : bool
        Whether the optimiser moves the parameter. Ignored (treated as
        False) when ``expr`` is given.
    expr : str, optional
        Tie to other parameters of the set, e.g. ``"C1"`` (``C2 = C1``) or
        ``"Cg/2"``; names are case-insensitive.
    scale : {"log", "linear"}
        Mapping to the unit cube: ``log10`` for quantities spanning decades.
    theta_scale : float
        Thesis scaling factor: optimiser value * ``theta_scale`` = physical
        value (thesis (4.28), Tables 4.4, 4.8).
    unit : str
        Unit for display (``"Ohm"``, ``"H"``, ``"F"``, ``"1"``).
    description : str
        Free text.
    kind : str
        ``"R"``, ``"L"``, ``"C"``, ``"K"`` (coupling coefficient), ``"M"``
        (mutual inductance ``M`` of a coupling element ``k = M g(L...)``: its
        ``min``/``max`` and unit-cube coordinate are those of the coupling
        ``k``, so every point of the cube has ``|k| < 1``; ``value`` is ``M``
        in H) or ``""``. Coupling parameters are the ones a passivity repair
        shrinks.

    Raises
    ------
    ValueError
        Naming the parameter, for inconsistent bounds, scale or value.
    """

    name: str
    value: float
    min: float = -math.inf
    max: float = math.inf
    vary: bool = True
    expr: str | None = None
    scale: str = "linear"
    theta_scale: float = 1.0
    unit: str = ""
    description: str = ""
    kind: str = ""
    _expression: Expression | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.value = float(self.value)
        self.min, self.max = float(self.min), float(self.max)
        if self.scale not in SCALES:
            self._fail(f"scale must be 'log' or 'linear' (got {self.scale!r})")
        if not (math.isfinite(self.theta_scale) and self.theta_scale > 0):
            self._fail(f"theta_scale must be positive and finite (got {self.theta_scale!r})")
        if self.min > self.max or (self.varying and self.min >= self.max):
            self._fail(f"min {_fmt(self.min)} >= max {_fmt(self.max)}")
        if self.expr is not None:
            try:
                self._expression = Expression(self.expr)
            except ExpressionError as exc:
                self._fail(str(exc))
            return
        if self.varying:
            if not (math.isfinite(self.min) and math.isfinite(self.max)):
                self._fail(f"a varying parameter needs finite bounds (got min {_fmt(self.min)}, max {_fmt(self.max)})")
            if self.scale == "log" and self.min <= 0:
                self._fail(f"log scale needs min > 0 (got min {_fmt(self.min)})")
        if not math.isfinite(self.value):
            self._fail(f"value is not finite ({self.value!r})")
        if self.vary and self.kind != "M" and not (self.min <= self.value <= self.max):
            self._fail(f"value {_fmt(self.value)} outside [{_fmt(self.min)}, {_fmt(self.max)}]")

    def _fail(self, message: str) -> None:
        raise ValueError(f"Parameter {self.name!r}: {message}")

    @property
    def key(self) -> str:
        """Lower-case name (the name used in expressions)."""
        return self.name.lower()

    @property
    def varying(self) -> bool:
        """True when the optimiser moves this parameter (``vary`` and not tied)."""
        return self.vary and self.expr is None

    @property
    def expression(self) -> Expression | None:
        """The parsed tie, or None."""
        return self._expression

    def to_unit(self, value: Numeric) -> np.ndarray:
        """Map physical values (SI) to the unit interval (0 at ``min``, 1 at ``max``)."""
        v = np.asarray(value, dtype=float)
        if self.scale == "log":
            lo, hi = math.log10(self.min), math.log10(self.max)
            with np.errstate(divide="ignore", invalid="ignore"):
                return (np.log10(v) - lo) / (hi - lo)
        return (v - self.min) / (self.max - self.min)

    def from_unit(self, u: Numeric) -> np.ndarray:
        """Map unit-interval coordinates back to physical values (SI)."""
        u = np.asarray(u, dtype=float)
        if self.scale == "log":
            lo, hi = math.log10(self.min), math.log10(self.max)
            return 10.0 ** (lo + u * (hi - lo))
        return self.min + u * (self.max - self.min)


# ====================================================================== evaluation result
@dataclass(frozen=True)
class Evaluation:
    """Physical values of a population of unit-cube points.

    Attributes
    ----------
    values : dict
        Parameter name to value (floats for one point, ``(P,)`` arrays for a
        population), ties evaluated; coupling parameters after repair.
    overrides : dict
        Ready for ``ResponseSet.evaluate`` / ``Circuit.resolve``: ``values``
        plus, when a repair happened, every coupling element of the circuit.
    unit : numpy.ndarray
        ``(n,)`` or ``(P, n)`` unit-cube coordinates of ``values`` (equal to
        the input where nothing was repaired).
    passive : numpy.ndarray
        ``(P,)`` bool: ``lambda_min(K) >= eps`` *before* repair (all True
        when passivity is ``"none"`` or the circuit has no couplings).
    repaired : numpy.ndarray
        ``(P,)`` bool: the sets whose couplings were shrunk.
    shrink : numpy.ndarray
        ``(P,)`` shrink fraction ``t`` (couplings multiplied by ``1 - t``).
    min_eigenvalue : numpy.ndarray
        ``(P,)`` smallest eigenvalue of the coupling matrix ``K`` before
        repair (``inf`` without couplings).
    """

    values: dict[str, Numeric]
    overrides: dict[str, Numeric]
    unit: np.ndarray
    passive: np.ndarray
    repaired: np.ndarray
    shrink: np.ndarray
    min_eigenvalue: np.ndarray


# ====================================================================== couplings
def coupling_matrix(circuit: Circuit, element_values: Mapping[str, Numeric]) -> np.ndarray:
    """Coupling (correlation) matrix ``K`` of the circuit's inductors.

    ``K`` has ones on the diagonal and ``k_ij`` from every K element off it,
    so that the inductance matrix is ``L = D^1/2 K D^1/2`` with
    ``D = diag(L_i)``.

    Parameters
    ----------
    circuit : Circuit
    element_values : mapping
        Lower-case element name to value (from :meth:`Circuit.resolve`);
        floats or ``(P,)`` arrays.

    Returns
    -------
    numpy.ndarray
        ``(P, m, m)`` (``P = 1`` for scalar values), in the order of
        :meth:`Circuit.inductors`.
    """
    index = {e.key: i for i, e in enumerate(circuit.inductors())}
    ks = circuit.of_kind("K")
    kvals = [np.atleast_1d(np.asarray(element_values[k.key], float)) for k in ks]
    P = max((v.size for v in kvals), default=1)
    m = len(index)
    K = np.broadcast_to(np.eye(m), (P, m, m)).copy()
    for k, v in zip(ks, kvals):
        i, j = (index[n.lower()] for n in k.nodes)
        K[:, i, j] = v
        K[:, j, i] = v
    return K


def shrink_fraction(min_eigenvalue: Numeric, eps: float = 1e-6) -> np.ndarray:
    """Smallest ``t >= 0`` with ``lambda_min((1 - t) K + t I) >= eps``.

    Shrinking every coupling ``k' = (1 - t) k`` keeps the unit diagonal, so
    ``K' = (1 - t) K + t I`` and ``lambda_min(K') = (1 - t) lambda_min + t``,
    giving ``t = max(0, (eps - lambda_min) / (1 - lambda_min))``.

    Parameters
    ----------
    min_eigenvalue : float or numpy.ndarray
        Smallest eigenvalue of ``K`` (dimensionless, below 1).
    eps : float
        Required margin, dimensionless, ``0 < eps < 1``.

    Returns
    -------
    numpy.ndarray
    """
    lam = np.asarray(min_eigenvalue, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (eps - lam) / (1.0 - lam)
    return np.where(lam >= eps, 0.0, np.clip(t, 0.0, 1.0))


def _coupling_kind_of(circuit: Circuit, name: str) -> str:
    key = name.lower()
    for p in circuit.parameters:
        if p.key == key:
            return _UNIT_KIND.get(p.unit.strip().lower(), "")
    return circuit.element(name).kind


# ====================================================================== ParameterSet
class ParameterSet:
    """An ordered, case-insensitive collection of :class:`Parameter`.

    Parameters
    ----------
    parameters : iterable of Parameter
    circuit : Circuit, optional
        The circuit the names refer to; needed for passivity checks.
    passivity : {"repair", "penalty", "none"}
        What :meth:`evaluate` does with couplings whose matrix ``K`` is not
        positive definite: shrink them (``"repair"``), only report them in
        :attr:`Evaluation.passive` for a penalty (``"penalty"``), or skip
        the check (``"none"``).
    eps : float
        Margin on ``lambda_min(K)``, dimensionless.
    """

    def __init__(
        self,
        parameters: Iterable[Parameter] = (),
        circuit: Circuit | None = None,
        passivity: str = "repair",
        eps: float = 1e-6,
    ):
        if passivity not in PASSIVITY_MODES:
            raise ValueError(f"passivity must be one of {', '.join(PASSIVITY_MODES)} (got {passivity!r})")
        if not 0 < eps < 1:
            raise ValueError(f"eps must lie in (0, 1) (got {eps!r})")
        self._params: dict[str, Parameter] = {}
        self.circuit = circuit
        self.passivity = passivity
        self.eps = float(eps)
        self._order: list[str] | None = None
        self._mutuals: list[str] | None = None
        for p in parameters:
            self.add(p)

    # ------------------------------------------------------------------ container
    def add(self, parameter: Parameter) -> None:
        """Append a parameter (names must be unique, case-insensitively)."""
        if parameter.key in self._params:
            raise ValueError(f"Parameter {parameter.name!r}: defined twice")
        self._params[parameter.key] = parameter
        self._order = None
        self._mutuals = None

    def set(self, name: str, **changes: Any) -> Parameter:
        """Replace fields of one parameter (validated again); returns the new parameter."""
        new = replace(self[name], **changes)
        self._params[new.key] = new
        self._order = None
        self._mutuals = None
        return new

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._params[name.lower()]
        except KeyError:
            raise KeyError(f"no parameter named {name!r}") from None

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name.lower() in self._params

    def __iter__(self) -> Iterator[Parameter]:
        return iter(self._params.values())

    def __len__(self) -> int:
        return len(self._params)

    def __repr__(self) -> str:
        return f"ParameterSet({len(self)} parameters, {len(self.varying)} varying, passivity={self.passivity!r})"

    @property
    def names(self) -> list[str]:
        """All parameter names, in order."""
        return [p.name for p in self]

    @property
    def varying(self) -> list[str]:
        """Names of the varying parameters: the unit-cube coordinates, in order."""
        return [p.name for p in self if p.varying]

    @property
    def tied(self) -> list[str]:
        """Names of the parameters given by expressions."""
        return [p.name for p in self if p.expr is not None]

    @property
    def couplings(self) -> list[str]:
        """Names of coupling-coefficient parameters (``kind == "K"``)."""
        return [p.name for p in self if p.kind == "K"]

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_circuit(
        cls,
        circuit: Circuit,
        names: Sequence[str] | None = None,
        bounds: Mapping[str, Bound] | float | None = None,
        fixed: Iterable[str] = (),
        ties: Mapping[str, str] | None = None,
        passivity: str = "repair",
        eps: float = 1e-6,
    ) -> "ParameterSet":
        """Parameters for the independent values of a circuit.

        Defaults: R, L, C (and parameters in Ohm, H, F) get bounds
        ``value / 10 .. value * 10`` (thesis Table 4.4), log scaling and the
        engineering-prefix ``theta_scale`` of thesis (4.28); couplings (K
        elements, dimensionless parameters) get ``(0, 0.9999)``, linear
        scaling and ``theta_scale = 1e-2``.

        Parameters
        ----------
        circuit : Circuit
        names : sequence of str, optional
            Subset of ``circuit.free_names()`` (default all); the rest keep
            their circuit values and are not part of the set.
        bounds : mapping or float, optional
            Name to ``(lo, hi)`` (SI units) or to a relative factor ``f``
            (``value / f .. value * f``); a single float is a factor for
            every R, L, C.
        fixed : iterable of str
            Names held at their circuit value (``vary=False``), e.g.
            ``Model.fixed``.
        ties : mapping, optional
            Name to expression over other names of the set, e.g.
            ``{"Kb2c": "Kb1c"}``.
        passivity : {"repair", "penalty", "none"}
        eps : float
            Margin on the smallest eigenvalue of the coupling matrix.

        Returns
        -------
        ParameterSet
        """
        free = circuit.free_names()
        by_key = {n.lower(): n for n in free}
        chosen = [cls._circuit_name(by_key, n, "names") for n in names] if names is not None else free
        bound_map = {} if bounds is None or isinstance(bounds, (int, float)) else {k.lower(): v for k, v in bounds.items()}
        factor = float(bounds) if isinstance(bounds, (int, float)) else DEFAULT_FACTOR
        fixed_keys = {cls._circuit_name(by_key, n, "fixed").lower() for n in fixed}
        tie_map = {cls._circuit_name(by_key, k, "ties").lower(): v for k, v in (ties or {}).items()}
        for key in list(bound_map) + list(fixed_keys) + list(tie_map):
            if key not in {c.lower() for c in chosen}:
                raise ValueError(f"Parameter {by_key.get(key, key)!r}: not among the chosen names")
        current = circuit.resolve(check=False)
        current.update(circuit.parameter_values())
        params = []
        for name in chosen:
            key = name.lower()
            kind = _coupling_kind_of(circuit, name)
            value = float(current[key])
            params.append(_default_parameter(name, value, kind, bound_map.get(key), factor,
                                             vary=key not in fixed_keys, expr=tie_map.get(key)))
        out = cls(params, circuit=circuit, passivity=passivity, eps=eps)
        for name in out.mutuals():  # searched as its coupling coefficient unless bounds in H were given
            p = out[name]
            if p.key not in bound_map and p.kind != "K":
                k0 = float(p.value * out._mutual_gain(p.key, {q.key: q.value for q in out if q.expr is None}))
                lo, hi = (0.0, K_MAX) if 0 <= k0 <= K_MAX else (-K_MAX, K_MAX)
                out.set(name, kind="M", min=lo, max=hi, scale="linear", theta_scale=1e-2)
        return out

    @classmethod
    def from_model(cls, model: Any, **kwargs: Any) -> "ParameterSet":
        """:meth:`from_circuit` for a built-in model, fixing ``model.fixed`` (e.g. ``Lc``)."""
        fixed = tuple(kwargs.pop("fixed", ())) + tuple(model.fixed)
        return cls.from_circuit(model.circuit, fixed=fixed, **kwargs)

    @staticmethod
    def _circuit_name(by_key: Mapping[str, str], name: str, what: str) -> str:
        try:
            return by_key[name.lower()]
        except KeyError:
            raise ValueError(f"Parameter {name!r} (in {what}): not an independent value of the circuit") from None

    # ------------------------------------------------------------------ ties
    def tie_order(self) -> list[str]:
        """Tied parameter keys in an order where every tie's inputs come first.

        Raises
        ------
        ValueError
            Naming the parameter whose expression uses an unknown name, or
            the parameters that form a cycle.
        """
        if self._order is not None:
            return self._order
        pending = {p.key: p for p in self if p.expr is not None}
        for p in pending.values():
            unknown = sorted(p.expression.names - self._params.keys())  # type: ignore[union-attr]
            if unknown:
                raise ValueError(f"Parameter {p.name!r}: unknown name {unknown[0]!r} in expression {p.expr!r}")
        done = {p.key for p in self if p.expr is None}
        order: list[str] = []
        while pending:
            ready = [k for k, p in pending.items() if p.expression.names <= done]  # type: ignore[union-attr]
            if not ready:
                cycle = ", ".join(repr(pending[k].name) for k in sorted(pending))
                raise ValueError(f"Parameters {cycle}: tied expressions depend on each other in a cycle")
            for k in ready:
                order.append(k)
                done.add(k)
                del pending[k]
        self._order = order
        return order

    def _evaluate_ties(self, env: dict[str, np.ndarray]) -> None:
        for key in self.tie_order():
            p = self._params[key]
            env[key] = np.asarray(p.expression.evaluate(env), float)  # type: ignore[union-attr]

    # ------------------------------------------------------------------ unit cube
    def to_unit(self, values: Mapping[str, Numeric]) -> np.ndarray:
        """Unit-cube coordinates of the varying parameters.

        Parameters
        ----------
        values : mapping
            Name (case-insensitive) to physical value, SI units; floats or
            ``(P,)`` arrays. Must contain every varying parameter.

        Returns
        -------
        numpy.ndarray
            ``(n,)`` for scalar values, ``(P, n)`` for a population.
            Values outside the bounds map outside ``[0, 1]`` (no clipping).
        """
        lower = {k.lower(): v for k, v in values.items()}
        cols = []
        env = None
        for p in self:
            if not p.varying:
                continue
            if p.key not in lower:
                raise ValueError(f"Parameter {p.name!r}: missing from the values")
            if p.kind == "M":
                if env is None:
                    env = {q.key: np.asarray(lower.get(q.key, q.value), float) for q in self if q.expr is None}
                    self._evaluate_ties(env)
                cols.append(p.to_unit(np.asarray(lower[p.key], float) * self._mutual_gain(p.key, env)))
            else:
                cols.append(p.to_unit(lower[p.key]))
        if not cols:
            return np.zeros(0)
        return np.stack(np.broadcast_arrays(*cols), axis=-1)

    def from_unit(self, u: np.ndarray | Sequence[float]) -> dict[str, Numeric]:
        """Physical values of the varying parameters from unit-cube coordinates.

        Parameters
        ----------
        u : array_like
            ``(n,)`` or ``(P, n)``, in the order of :attr:`varying`.

        Returns
        -------
        dict
            Name to float (``(n,)`` input) or ``(P,)`` array.
        """
        u2, single = self._check_unit(u)
        out = {p.name: p.from_unit(u2[:, i]) for i, p in enumerate(q for q in self if q.varying)}
        return {k: float(v[0]) for k, v in out.items()} if single else out

    def _check_unit(self, u: np.ndarray | Sequence[float]) -> tuple[np.ndarray, bool]:
        arr = np.asarray(u, dtype=float)
        n = len(self.varying)
        if arr.ndim not in (1, 2) or arr.shape[-1] != n:
            raise ValueError(f"unit-cube points must have shape ({n},) or (P, {n}) (got {arr.shape})")
        return np.atleast_2d(arr), arr.ndim == 1

    def values(self, u: np.ndarray | Sequence[float] | None = None) -> dict[str, Numeric]:
        """Values of every parameter (varying, fixed, tied), without passivity handling.

        Parameters
        ----------
        u : array_like, optional
            ``(n,)`` or ``(P, n)`` unit-cube points; default the current
            ``Parameter.value`` of every parameter.

        Returns
        -------
        dict
            Name to float (one point) or ``(P,)`` array (population).
        """
        if u is None:
            env = self._environment(None, 1)
            return self._pack(env, True)
        u2, single = self._check_unit(u)
        return self._pack(self._environment(u2, u2.shape[0]), single)

    def _environment(self, u2: np.ndarray | None, P: int) -> dict[str, np.ndarray]:
        """Lower-case name to ``(P,)`` values; ``u2=None`` takes every ``Parameter.value``."""
        env: dict[str, np.ndarray] = {}
        col = 0
        coupling: dict[str, np.ndarray] = {}
        for p in self:
            if p.varying and u2 is not None:
                if p.kind == "M":
                    coupling[p.key] = p.from_unit(u2[:, col])
                    env[p.key] = np.full(P, p.value)
                else:
                    env[p.key] = p.from_unit(u2[:, col])
                col += 1
            elif p.expr is None:
                env[p.key] = np.full(P, p.value)
        for key, k in coupling.items():
            env[key] = k / self._mutual_gain(key, env)
        self._evaluate_ties(env)
        return {k: np.broadcast_to(v, (P,)).astype(float) for k, v in env.items()}

    def _pack(self, env: Mapping[str, np.ndarray], single: bool) -> dict[str, Numeric]:
        return {p.name: (float(env[p.key][0]) if single else env[p.key]) for p in self}

    # ------------------------------------------------------------------ thesis scaling
    def to_scaled(self, values: Mapping[str, Numeric]) -> np.ndarray:
        """Thesis optimiser vector: varying values divided by ``theta_scale`` ((4.27)-(4.28)).

        Returns
        -------
        numpy.ndarray
            ``(n,)`` or ``(P, n)``.
        """
        lower = {k.lower(): v for k, v in values.items()}
        cols = []
        for p in self:
            if p.varying:
                if p.key not in lower:
                    raise ValueError(f"Parameter {p.name!r}: missing from the values")
                cols.append(np.asarray(lower[p.key], float) / p.theta_scale)
        return np.stack(np.broadcast_arrays(*cols), axis=-1) if cols else np.zeros(0)

    def from_scaled(self, x: np.ndarray | Sequence[float]) -> dict[str, Numeric]:
        """Physical values of the varying parameters from the thesis's scaled vector."""
        arr = np.asarray(x, dtype=float)
        vary = [p for p in self if p.varying]
        if arr.ndim not in (1, 2) or arr.shape[-1] != len(vary):
            raise ValueError(f"scaled vector must have shape ({len(vary)},) or (P, {len(vary)}) (got {arr.shape})")
        out = {p.name: arr[..., i] * p.theta_scale for i, p in enumerate(vary)}
        return {k: float(v) for k, v in out.items()} if arr.ndim == 1 else out

    def scaled_bounds(self) -> np.ndarray:
        """``(n, 2)`` bounds of the varying parameters divided by ``theta_scale`` (Tables 4.4, 4.8)."""
        return np.array([[p.min / p.theta_scale, p.max / p.theta_scale] for p in self if p.varying]).reshape(-1, 2)

    # ------------------------------------------------------------------ physical couplings
    def evaluate(self, u: np.ndarray | Sequence[float]) -> Evaluation:
        """Values, circuit overrides and passivity report for unit-cube points.

        Parameters
        ----------
        u : array_like
            ``(n,)`` or ``(P, n)`` unit-cube points, order of :attr:`varying`.

        Returns
        -------
        Evaluation
        """
        u2, single = self._check_unit(u)
        P = u2.shape[0]
        env = self._environment(u2, P)
        inf = np.full(P, np.inf)
        no = np.zeros(P, bool)
        lam, t = inf, np.zeros(P)
        extra: dict[str, np.ndarray] = {}
        if self.passivity != "none" and self.circuit is not None and self.circuit.of_kind("K"):
            elements = self.circuit.resolve(self._pack(env, False), check=False)
            K = coupling_matrix(self.circuit, elements)
            lam = np.broadcast_to(np.linalg.eigvalsh(K)[:, 0], (P,))
            if self.passivity == "repair":
                t = np.broadcast_to(shrink_fraction(lam, self.eps), (P,))
                if np.any(t > 0):
                    extra = self._shrink(env, elements, 1.0 - t)
        repaired = t > 0
        unit = u2.copy()
        if repaired.any():
            unit[repaired] = self.to_unit({p.name: env[p.key] for p in self if p.varying})[repaired]
        values = self._pack(env, single)
        overrides = dict(values)
        self._merge(overrides, extra, single)
        return Evaluation(
            values=values,
            overrides=overrides,
            unit=unit[0] if single else unit,
            passive=(lam >= self.eps) if self.passivity != "none" else ~no,
            repaired=repaired,
            shrink=t,
            min_eigenvalue=lam,
        )

    def _mutual_gain(self, key: str, env: Mapping[str, Any]) -> np.ndarray:
        """``g`` of the coupling element ``k = M g`` that uses mutual inductance ``key``, from ``env``."""
        assert self.circuit is not None
        element = next(e for e in self.circuit.elements
                       if e.kind == "K" and isinstance(e.value, Expression) and key in e.value.names)
        full = {k.lower(): v for k, v in self.circuit.parameter_values().items()}
        full.update(env)
        full[key] = 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.asarray(element.value.evaluate(full), float)

    def mutuals(self) -> list[str]:
        """Varying parameters that are mutual inductances: a K element's value is proportional to them.

        A parameter ``M`` counts when exactly one coupling element's value is an
        expression ``k(M, ...)`` with ``k(2 M) = 2 k(M)`` (e.g. ``{M12/sqrt(L1*L2)}``)
        and no other element uses it. Shrinking that coupling by a factor is then
        the same as shrinking ``M`` by it, so a passivity repair can be written
        back into the parameter: the reported value is the one that was scored.
        """
        if self.circuit is None:
            return []
        if self._mutuals is not None:
            return list(self._mutuals)
        out = []
        for p in self:
            if p.kind == "M" and p.varying:
                out.append(p.name)
                continue
            if not p.varying or p.kind == "K":
                continue
            users = [e for e in self.circuit.elements if isinstance(e.value, Expression) and p.key in e.value.names]
            if len(users) != 1 or users[0].kind != "K":
                continue
            env = {**{k.lower(): v for k, v in self.circuit.parameter_values().items()},
                   **{q.key: q.value for q in self if q.expr is None}}
            try:
                k1 = float(users[0].value.evaluate(env))
                env2 = dict(env)
                env2[p.key] = 2.0 * env[p.key]
                k2 = float(users[0].value.evaluate(env2))
            except Exception:  # an expression that needs other names: not a plain mutual inductance
                continue
            if k1 != 0 and math.isclose(k2, 2.0 * k1, rel_tol=1e-12):
                out.append(p.name)
        self._mutuals = out
        return list(out)

    def _shrink(self, env: dict[str, np.ndarray], elements: Mapping[str, Numeric], factor: np.ndarray) -> dict[str, np.ndarray]:
        """Scale coupling parameters (and mutual inductances) in ``env``; every K element's repaired value."""
        mutual = {n.lower() for n in self.mutuals()}
        for p in self:
            if p.kind == "K" or p.key in mutual:
                env[p.key] = env[p.key] * factor
        return {k.name: np.asarray(elements[k.key], float) * factor for k in self.circuit.of_kind("K")}  # type: ignore[union-attr]

    def _merge(self, overrides: dict[str, Numeric], extra: Mapping[str, np.ndarray], single: bool) -> None:
        """Add repaired element values, replacing entries that name the same thing case-insensitively."""
        by_key = {k.lower(): k for k in overrides}
        circuit_params = {p.key for p in self.circuit.parameters} if self.circuit is not None else set()
        for name, value in extra.items():
            key = name.lower()
            if key in circuit_params:
                # resolve() reads this name as the parameter; only safe when the element is exactly it
                element = self.circuit.element(name)  # type: ignore[union-attr]
                text = element.value.text.strip("{} ").lower() if isinstance(element.value, Expression) else ""
                if text != key:
                    raise ValueError(f"Parameter {name!r}: shares its name with coupling element "
                                     f"{element.name!r} but does not define it; cannot repair")
            overrides[by_key.get(key, name)] = float(value[0]) if single else value

    def overrides(self, u: np.ndarray | Sequence[float]) -> dict[str, Numeric]:
        """Name to value for ``ResponseSet.evaluate`` / ``Circuit.resolve``, ties and repair applied.

        Parameters
        ----------
        u : array_like
            ``(n,)`` (floats out) or ``(P, n)`` (``(P,)`` arrays out).

        Returns
        -------
        dict
        """
        return self.evaluate(u).overrides

    def update(self, values: Mapping[str, float]) -> None:
        """Set ``Parameter.value`` of the named parameters (e.g. to an optimum)."""
        for name, v in values.items():
            self.set(name, value=float(v))


def _default_parameter(
    name: str, value: float, kind: str, bound: Bound | None, factor: float, vary: bool, expr: str | None
) -> Parameter:
    unit = {"R": "Ohm", "L": "H", "C": "F", "K": "1"}.get(kind, "")
    if kind == "K":
        if bound is not None and not isinstance(bound, tuple):
            raise ValueError(f"Parameter {name!r}: a coupling needs absolute bounds (lo, hi), not a factor")
        lo, hi = bound if bound is not None else ((0.0, K_MAX) if 0 <= value <= K_MAX else (-K_MAX, K_MAX))
        return Parameter(name, value, lo, hi, vary, expr, "linear", 1e-2, unit, kind=kind)
    if bound is None or not isinstance(bound, tuple):
        f = float(bound) if bound is not None else factor
        if value <= 0 or f <= 1:
            raise ValueError(f"Parameter {name!r}: relative bounds need value > 0 and factor > 1 "
                             f"(value {_fmt(value)}, factor {_fmt(f)}); give (lo, hi)")
        lo, hi = value / f, value * f
    else:
        lo, hi = (float(b) for b in bound)
    scale = "log" if lo > 0 else "linear"
    return Parameter(name, value, lo, hi, vary, expr, scale, engineering_scale(value), unit, kind=kind)


# ====================================================================== identifiability
@dataclass(frozen=True)
class Identifiability:
    """Local identifiability of parameters from a residual Jacobian.

    Attributes
    ----------
    names : list of str
        Parameter names, column order of the Jacobian.
    singular_values : numpy.ndarray
        Of the Jacobian, descending.
    groups : list of tuple of str
        For every singular value below ``rtol * s_max``: the parameters that
        carry the matching right singular vector (not separable together).
    insensitive : list of str
        Parameters whose Jacobian column is (relatively) zero.
    correlated : list of tuple
        ``(name_a, name_b, correlation)`` with ``|correlation| > threshold``.
    correlation : numpy.ndarray
        ``(n, n)`` parameter correlation matrix from the (regularised)
        Gauss-Newton covariance ``(J^T J)^-1``.
    """

    names: list[str]
    singular_values: np.ndarray
    groups: list[tuple[str, ...]]
    insensitive: list[str]
    correlated: list[tuple[str, str, float]]
    correlation: np.ndarray

    @property
    def identifiable(self) -> bool:
        """True when no group, insensitive parameter or correlated pair was found."""
        return not (self.groups or self.insensitive or self.correlated)

    def __str__(self) -> str:
        s = self.singular_values
        cond = s[0] / s[-1] if s.size and s[-1] > 0 else np.inf
        lines = [f"condition number {cond:.3g}"]
        lines += [f"not separable: {', '.join(g)}" for g in self.groups]
        lines += [f"no effect: {n}" for n in self.insensitive]
        lines += [f"correlated {a} / {b}: {c:+.4f}" for a, b, c in self.correlated]
        return "\n".join(lines)


def jacobian(
    residuals: Callable[[np.ndarray], np.ndarray], u0: np.ndarray | Sequence[float], step: float = 1e-6,
    vectorised: bool = False,
) -> np.ndarray:
    """Central-difference Jacobian of residuals w.r.t. normalised parameters.

    Parameters
    ----------
    residuals : callable
        ``u (n,) -> r (N,)`` (complex residuals are split into real and
        imaginary parts); with ``vectorised=True``, ``(P, n) -> (P, N)``.
    u0 : array_like
        ``(n,)`` point, unit-cube coordinates.
    step : float
        Difference step in unit-cube coordinates.
    vectorised : bool
        Evaluate all ``2 n`` points in one call (a population).

    Returns
    -------
    numpy.ndarray
        ``(N, n)`` (``(2N, n)`` for complex residuals).
    """
    u0 = np.asarray(u0, float)
    n = u0.size
    points = np.concatenate([u0 + step * np.eye(n), u0 - step * np.eye(n)])
    r = np.asarray(residuals(points)) if vectorised else np.stack([np.asarray(residuals(p)) for p in points])
    r = r.reshape(2 * n, -1)
    if np.iscomplexobj(r):
        r = np.concatenate([r.real, r.imag], axis=1)
    return ((r[:n] - r[n:]) / (2 * step)).T


def identifiability(
    jac: np.ndarray | Callable[[np.ndarray], np.ndarray],
    names: Sequence[str],
    u0: np.ndarray | Sequence[float] | None = None,
    rtol: float = 1e-6,
    threshold: float = 0.99,
    member: float = 0.1,
    step: float = 1e-6,
) -> Identifiability:
    """Parameters or groups of parameters that a residual cannot separate.

    Parameters
    ----------
    jac : numpy.ndarray or callable
        ``(N, n)`` Jacobian of residuals w.r.t. normalised (unit-cube)
        parameters, or a residual function ``u -> r`` (then ``u0`` is
        required and :func:`jacobian` is used).
    names : sequence of str
        Parameter names, one per column.
    u0 : array_like, optional
        Point of linearisation when ``jac`` is a function.
    rtol : float
        Singular values below ``rtol * s_max`` count as zero.
    threshold : float
        Report parameter pairs with ``|correlation| > threshold``.
    member : float
        A parameter belongs to a null direction when its component is at
        least ``member`` times the largest component.
    step : float
        Finite-difference step for a residual function.

    Returns
    -------
    Identifiability
    """
    if callable(jac):
        if u0 is None:
            raise ValueError("identifiability: u0 is required with a residual function")
        J = jacobian(jac, u0, step)
    else:
        J = np.asarray(jac, float)
    n = len(names)
    if J.ndim != 2 or J.shape[1] != n:
        raise ValueError(f"identifiability: Jacobian must have shape (N, {n}) (got {J.shape})")
    _, s, Vt = np.linalg.svd(J, full_matrices=False)
    s_full = np.zeros(n)
    s_full[: s.size] = s
    s_max = s_full.max() if s_full.size else 0.0
    if s.size < n:
        Vt = np.linalg.svd(np.vstack([J, np.zeros((n - s.size, n))]), full_matrices=True)[2]
    zero = s_full <= rtol * s_max
    col_norm = np.linalg.norm(J, axis=0)
    insensitive = [names[i] for i in range(n) if col_norm[i] <= rtol * max(col_norm.max(initial=0.0), 1e-300)]
    groups = _null_groups(Vt[zero], list(names), set(insensitive), member)
    corr = _correlation(s_full, Vt, s_max)
    pairs = [(names[i], names[j], float(corr[i, j])) for i in range(n) for j in range(i + 1, n)
             if abs(corr[i, j]) > threshold and names[i] not in insensitive and names[j] not in insensitive]
    return Identifiability(list(names), s_full, groups, insensitive, pairs, corr)


def _null_groups(null: np.ndarray, names: list[str], skip: set[str], member: float) -> list[tuple[str, ...]]:
    """Parameters joined by the null space of the Jacobian (rows of ``null`` span it).

    The projector ``P = N^T N`` onto the null space does not depend on the
    basis chosen by the SVD: parameter ``i`` takes part when ``sqrt(P_ii)``
    is at least ``member`` times the largest, and two take part together
    when ``|P_ij|`` is at least ``member`` times the largest diagonal entry.
    """
    if null.size == 0:
        return []
    proj = null.T @ null
    weight = np.sqrt(np.clip(np.diag(proj), 0.0, None))
    top = weight.max()
    part = [i for i in range(len(names)) if weight[i] >= member * top and names[i] not in skip]
    groups: list[list[int]] = []
    for i in part:
        linked = [g for g in groups if any(abs(proj[i, j]) >= member * top**2 for j in g)]
        merged = [i] + [j for g in linked for j in g]
        groups = [g for g in groups if g not in linked] + [sorted(merged)]
    return [tuple(names[i] for i in g) for g in sorted(groups) if len(g) > 1]


def _correlation(s: np.ndarray, Vt: np.ndarray, s_max: float, ridge: float = 1e-12) -> np.ndarray:
    """Correlation from ``(J^T J + ridge s_max^2 I)^-1``: finite even for singular ``J``.

    A tiny ridge keeps exactly unidentifiable directions dominant (their
    correlation tends to +-1) instead of dropping them as a pseudo-inverse would.
    """
    if s_max == 0:
        return np.eye(s.size)
    cov = (Vt.T / (s**2 + ridge * s_max**2)) @ Vt
    d = np.sqrt(np.diag(cov))
    return cov / np.outer(d, d)


__all__ = [
    "Parameter",
    "ParameterSet",
    "Evaluation",
    "Identifiability",
    "coupling_matrix",
    "shrink_fraction",
    "engineering_scale",
    "identifiability",
    "jacobian",
    "K_MAX",
    "DEFAULT_FACTOR",
]
