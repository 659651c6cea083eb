"""The result of a frequency-response diagnosis: the causes named, the fits, the evidence and the drift."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from estimation.diagnosis.fit import FitResult


@dataclass
class DiagnosisOutcome:
    """What every diagnosis answers, from frequency responses (:class:`Diagnosis`) or waveforms
    (:class:`.waveform.WaveformDiagnosis`): one contract for the command's JSON keys.

    ``cause`` is the first cause named (``"none"``), ``causes`` all of them
    in the order named, ``steps`` the forward selection's steps, ``fits``
    every candidate's fit, ``best`` the fit with every named cause (None
    for ``none``), ``noise`` the noise floor, ``unexplained`` the bands the
    final model leaves above it, ``wall_s`` seconds.
    """

    cause: str
    baseline: Any
    best: Any | None
    fits: list[Any]
    evidence: dict[str, Any] = field(default_factory=dict, kw_only=True)
    wall_s: float = field(default=0.0, kw_only=True)
    causes: list[str] = field(default_factory=list, kw_only=True)
    steps: list[dict[str, Any]] = field(default_factory=list, kw_only=True)
    noise: dict[str, Any] = field(default_factory=dict, kw_only=True)
    unexplained: list[dict[str, Any]] = field(default_factory=list, kw_only=True)


@dataclass
class Diagnosis(DiagnosisOutcome):
    """Result of a frequency-response diagnosis (see :meth:`as_json` for the command-line keys)."""

    baseline: FitResult
    best: FitResult | None
    fits: list[FitResult]
    frequency_hz: np.ndarray
    measured: dict[str, np.ndarray]
    realisation: dict[str, Any] = field(default_factory=dict)
    failed: list[dict[str, Any]] = field(default_factory=list)
    drift: list[dict[str, Any]] = field(default_factory=list)
    baseline_drift: list[dict[str, Any]] = field(default_factory=list)
    #: Other values off the design that explain the data as well as the one reported (:func:`.drift.located_drift`).
    drift_alternatives: list[dict[str, Any]] = field(default_factory=list)
    #: Causes whose fit alone is within :data:`.causes.rivals.CAUSE_TIE_DBIC` in BIC of the first cause named, or of the
    #: drift that explains the data when none is named (``cause``, ``delta_bic``): the data do not tell them apart (a skin effect's and a lamination's impedance both grow as
    #: ``(1 + j) sqrt(f)`` well above their corners).
    cause_alternatives: list[dict[str, Any]] = field(default_factory=list)
    tolerance: float = float("inf")
    #: The returned model fits within :data:`.verdict.FIT_FACTOR` times the noise floor (:mod:`.verdict`).
    explained: bool = True
    #: Where the misfit of a model that does not explain the data sits and its shape (:func:`.verdict.misfit_sentence`).
    misfit: str = ""
    #: The candidate with the lowest BIC among those tried, for a diagnosis that does not explain the data.
    best_tried: str = ""

    @property
    def gain(self) -> float:
        """Fraction of the baseline cost removed by the model with every named cause.

        With a design prior the costs are penalised (:attr:`.fit.FitResult.objective`): a baseline that fits
        only by moving values far from the design does not count as a fit.
        """
        return 0.0 if self.best is None else max(0.0, 1 - self.best.objective / self.baseline.objective)

    def candidates(self) -> list[dict[str, Any]]:
        rows = []
        for r in self.fits:
            rows.append({
                "cause": r.cause, "cost": r.cost, "gain": max(0.0, 1 - r.objective / self.baseline.objective),
                "bic": r.cause_bic,
                "delta_bic": self.baseline.cause_bic - r.cause_bic, "n_params": r.n_params, "extra": r.extra,
                "form": r.effects[0].form if r.effects else "", "group": r.effects[0].group if r.effects else "",
                "formula": r.describe()[0]["formula"] if r.effects else r.structure, "wall_s": r.wall_s,
            })
        return rows

    def as_json(self) -> dict[str, Any]:
        ext = self.best
        return {
            "cause": self.cause,
            "causes": list(self.causes),
            "steps": list(self.steps),
            "candidates": self.candidates(),
            "baseline_cost": self.baseline.cost,
            "extended_cost": ext.cost if ext else self.baseline.cost,
            "baseline_penalty": self.baseline.penalty,
            "extended_penalty": ext.penalty if ext else self.baseline.penalty,
            "gain": self.gain,
            "tolerance": self.tolerance,
            "drift": list(self.drift),
            "baseline_drift": list(self.baseline_drift),
            "drift_alternatives": list(self.drift_alternatives),
            "cause_alternatives": list(self.cause_alternatives),
            "noise_floor": self.noise.get("cost", 0.0),
            "noise": self.noise,
            "unexplained": self.unexplained,
            "explained": self.explained,
            "misfit": self.misfit,
            "best_tried": self.best_tried,
            "failed": self.failed,
            "baseline_bic": self.baseline.bic,
            "fitted_extension": ext.describe() if ext else [],
            "structure": ext.structure if ext else "",
            "baseline_values": self.baseline.values,
            "extended_values": ext.values if ext else {},
            "evidence": self.evidence,
            "realisation": self.realisation,
            "wall_s": self.wall_s,
        }
