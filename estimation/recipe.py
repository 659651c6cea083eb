"""The staged estimation recipe that every model kind runs: starts, local descent, restarts, verdict.

One recipe serves a built-in model or netlist scored by an approach of
:mod:`estimation.approaches` (:class:`estimation.estimate.ApproachKind`) and
an FMU in the loop (:class:`estimation.fmu.estimate.FmuKind`). A *model kind*
supplies the stages; :func:`run_recipe` owns the order and the rules:

1. **start** (``kind.start(k)``): a unit-cube point for restart ``k`` from a
   cheap stand-in of the cost (a global search on the analytic or sampled
   responses; for an FMU, a Latin-hypercube design ranked on the record's
   responses and screened on short windows); ``None`` when the kind has no
   further start worth descending;
2. **descend** (``kind.descend(starts)``): least squares on the approach's own
   residuals from each start (a polish; for an FMU, the window continuation up
   to the whole record). A kind may descend a batch at once (worker
   processes, a Dask cluster);
3. **restarts**: ``restarts`` starts are descended first; more (up to
   ``max_restarts``) while fewer than two ends have brought the residual RMS
   down to the level that explains the data (three times its noise floor, or,
   when the best fit shows the data's noise reading to be signal, the larger
   of 1.5 times the best RMS and three times its residual's own noise,
   :func:`estimation.verdict.residual_noise`); a kind with ``explains(r)``
   (an FMU: :func:`estimation.fmu.verdict.chi_square` against the record's
   noise read at that end) decides instead which ends explain the data;
4. **verdict** (:func:`estimation.verdict.verdict`, or the kind's own
   ``judge(x, ends)``, e.g. :func:`estimation.fmu.verdict.judge`) on the lowest own cost,
   with the other ends telling whether the answer is unique; when the verdict
   finds it short of its minimum, the kind's ``polish`` runs once more.

Every stage reports its runs (model evaluations: a batch row, an FMU run of
any window); the outcome lists them per restart (``runs_per_stage``).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from estimation.parameters import ParameterSet
from estimation.verdict import agreement_tolerance, residual_noise, residual_tolerance, verdict

__all__ = ["End", "ModelKind", "Outcome", "Start", "run_recipe"]


@dataclass
class Start:
    """Stage 1's answer for one restart.

    Attributes
    ----------
    x : numpy.ndarray
        ``(n,)`` unit-cube point.
    cost : float
        Stand-in cost at ``x``.
    runs : dict
        Model runs per stage of the start, in order (``{"stand-in search": 12000, ...}``).
    message : str
        What the stage did.
    info : dict
        Kind-specific fields carried into the restart's row (e.g. the seed).
    """

    x: np.ndarray
    cost: float
    runs: dict[str, int]
    message: str
    info: dict[str, Any] = field(default_factory=dict)


@dataclass
class End:
    """Stage 2's answer for one restart: the start, descended on the approach's own residuals.

    Attributes
    ----------
    x : numpy.ndarray
        ``(n,)`` unit-cube end point.
    cost : float
        The approach's own cost there.
    runs : dict
        Model runs per stage of the whole restart (start and descent).
    message : str
    info : dict
        Kind-specific fields for the restart's row.
    """

    x: np.ndarray
    cost: float
    runs: dict[str, int]
    message: str
    info: dict[str, Any] = field(default_factory=dict)


class ModelKind(Protocol):
    """The stages a model kind supplies to :func:`run_recipe`."""

    params: ParameterSet
    #: Keyword options of :func:`estimation.verdict.verdict` (e.g. ``step_within_sigma``).
    verdict_options: dict[str, Any]

    def start(self, k: int) -> Start | None:
        """Stage 1 of restart ``k`` (0-based), or ``None`` when no further start is worth descending."""

    def descend(self, starts: Sequence[tuple[int, Start]]) -> list[End]:
        """Stage 2 from each ``(k, start)``, in the same order."""

    def residuals(self, U: np.ndarray) -> np.ndarray:
        """``(P, N)`` residuals of the approach at unit-cube points ``U`` ``(P, n)``."""

    def data(self) -> np.ndarray:
        """The compared data (noise floor and scale of the verdict)."""

    def polish(self, x: np.ndarray) -> tuple[np.ndarray, float, int, str] | None:
        """A further local descent of ``x``: ``(x, cost, runs, message)``, or ``None`` when the kind has none."""


@dataclass
class Outcome:
    """Result of :func:`run_recipe`.

    Attributes
    ----------
    x : numpy.ndarray
        Best unit-cube point.
    cost : float
        Its own cost.
    nfev : int
        Model runs of every stage (and of the verdict's end-point residuals).
    message : str
        The best restart's stage messages.
    verdict : dict
        :func:`estimation.verdict.verdict`.
    ends : list of (x, residual RMS)
        Every restart's end.
    stages : list of dict
        One row per restart: ``restart``, ``stage1_cost``, ``cost``, ``residual_rms``, ``evaluations``,
        ``runs_per_stage`` and the kind's own fields.
    """

    x: np.ndarray
    cost: float
    nfev: int
    message: str
    verdict: dict[str, Any]
    ends: list[tuple[np.ndarray, float]] = field(default_factory=list)
    stages: list[dict[str, Any]] = field(default_factory=list)


def _rms(r: np.ndarray) -> float:
    r = np.asarray(r, float).ravel()
    return float(np.sqrt(np.mean(r ** 2))) if r.size and np.all(np.isfinite(r)) else math.inf


def run_recipe(kind: ModelKind, restarts: int, max_restarts: int | None = None, noise: float | None = None,
               time_limit_s: float | None = None, progress: bool = True, label: str = "estimate") -> Outcome:
    """Run the staged recipe (module docstring) on a model kind.

    Parameters
    ----------
    kind : ModelKind
        The stages.
    restarts : int
        Starts descended first (fewer when the kind runs out of starts).
    max_restarts : int, optional
        At most this many restarts in all (default ``restarts``).
    noise : float, optional
        Known noise standard deviation of the residuals (``0`` for an exact target).
    time_limit_s : float, optional
        No further restart starts after this wall time, s.
    progress : bool
        One line per restart on stderr.
    label : str
        Prefix of the progress lines.

    Returns
    -------
    Outcome
    """
    t0 = time.perf_counter()
    restarts = max(1, int(restarts))
    more = max(restarts, int(max_restarts if max_restarts is not None else restarts))
    noise0, scale0, floor = residual_tolerance(kind.data(), noise)  # the verdict's "explains the data" level
    reach = floor
    ends: list[End] = []
    rows: list[dict[str, Any]] = []
    points: list[tuple[np.ndarray, float]] = []
    nfev = 0
    # a kind may judge its ends itself (an FMU: the residual against the record's own noise, a chi-square test)
    explains = getattr(kind, "explains", None)
    judge = getattr(kind, "judge", None)
    consistent: list[bool] = []

    def enough() -> bool:
        if explains is not None:
            return sum(consistent) >= 2
        return sum(p[1] <= reach for p in points) >= 2

    def take(batch: list[tuple[int, Start]]) -> None:
        nonlocal reach, nfev
        for (k, s), e in zip(batch, kind.descend(batch)):
            r = np.asarray(kind.residuals(np.asarray(e.x, float)[None]), float)[0]
            rms = _rms(r)
            nfev += sum(e.runs.values()) + 1
            if noise is None and rms <= min([p[1] for p in points] + [math.inf]):
                # the data's noise reading may be signal (modes above the Nyquist frequency): the best fit's tells
                sigma = residual_noise(noise0, r)
                reach = floor if not sigma < noise0 else max(1.5 * rms, agreement_tolerance(floor, noise0, sigma,
                                                                                            scale0))
            ends.append(e)
            points.append((np.asarray(e.x, float), rms))
            if explains is not None:
                consistent.append(bool(explains(r)))
            rows.append({"restart": k + 1, **s.info, "stage1_cost": float(s.cost), "cost": float(e.cost),
                         "residual_rms": rms, "evaluations": int(sum(e.runs.values())) + 1,
                         "runs_per_stage": dict(e.runs), **e.info})
            if progress:
                total = restarts if k < restarts else more
                print(f"{label}: restart {k + 1}/{total}: cost {e.cost:.4g} (residual RMS {rms:.3g}), "
                      f"{time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)

    first = []
    for k in range(restarts):
        if time_limit_s is not None and k > 0 and time.perf_counter() - t0 > time_limit_s:
            break
        s = kind.start(k)
        if s is None:
            break
        first.append((k, s))
    if not first:
        raise ValueError("the model kind gave no start to descend")
    take(first)
    k = len(first)
    while k < more and not enough():
        if time_limit_s is not None and time.perf_counter() - t0 > time_limit_s:
            break
        s = kind.start(k)
        if s is None:
            break
        take([(k, s)])
        k += 1
    best = min(range(len(ends)), key=lambda j: ends[j].cost)
    best_x, best_c, message = np.asarray(ends[best].x, float), float(ends[best].cost), ends[best].message
    opts = dict(getattr(kind, "verdict_options", {}) or {})
    def decide() -> dict[str, Any]:
        if judge is not None:
            return judge(best_x, points)
        return verdict(kind.residuals, kind.params, best_x, kind.data(), points, noise=noise, **opts)

    v = decide()
    if not v["converged"] and "not at a minimum" in v["convergence_reason"] \
            and (time_limit_s is None or time.perf_counter() - t0 < time_limit_s):
        # the best restart stopped short of its minimum (a flat direction): polish it once more
        pol = kind.polish(best_x)
        if pol is not None:
            x, c, runs, note = pol
            nfev += int(runs) + 1
            rows[best]["runs_per_stage"]["final polish"] = int(runs)
            if c <= best_c:
                points[best] = (np.asarray(x, float), _rms(kind.residuals(np.asarray(x, float)[None])))
                best_x, best_c = np.asarray(x, float), float(c)
                message += f"; final least squares: {note}"
                v = decide()
    return Outcome(best_x, best_c, nfev, message, v, points, rows)
