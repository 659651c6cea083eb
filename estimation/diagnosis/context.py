"""What every fit of one diagnosis shares: the data, the noise floor, the design prior, and the thresholds."""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.models.builtin import Configuration

from estimation.diagnosis.causes.catalogue import Effect
from estimation.diagnosis.drift import DRIFT_MIN_DBIC, GROSS_DRIFT, design_rejected
from estimation.diagnosis.evidence import noise_variance, residuals_white
from estimation.diagnosis.fit import FitResult, FrequencyFit
from estimation.diagnosis.prior import DesignPrior
from estimation.diagnosis.verdict import FIT_FACTOR

MAX_BASELINE_RMS = 2.3  # complex-log RMS error (20 dB) beyond which the baseline "does not fit at all"
#: Selection stops once the cost is within this factor of the noise floor: about two standard deviations of a
#: perfect model's cost over the estimated floor (the estimate's spread, 0.10 on the broad draws, and the cost's own,
#: ``1/sqrt(N)`` for ``N`` complex points), a one-sided test at about 2 %.
NOISE_MARGIN = 1.25
#: Causes that add circuit elements: named only if they also pass the held-out check (:mod:`.holdout`).
STRUCTURAL = ("missing-section",)
#: A first structural cause whose fit stays this many times above the noise floor (a split of the design values, or
#: a section with its couplings free) is refused as the first cause (:func:`.diagnose._select`): with that much
#: misfit left, the new section's free values take the share of a frequency-dependent effect. (The search for a
#: missing section itself runs whenever the model does not explain the data, :meth:`Context.unfit`.)
UNMERGE_ABOVE_FLOOR = 10.0
#: Evaluations per smoothed stage of every seed of the wide split search (:func:`.unmerge.search_unmerged`, one-port
#: data that no single cause explains): 8 leaves a split of design values 10 % off hundreds of times above the noise,
#: 20 brings some seed of most such splits to it.
WIDE_SEED_NFEV = 20
#: ... and, with every measured resonance already in the model without it, named only if its fit comes within this
#: factor of ``NOISE_MARGIN`` times the noise floor.
STRUCTURAL_FLOOR = 2.0


def log(msg: str, progress: bool) -> None:
    """A progress line on stderr (when ``progress``)."""
    if progress:
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)


@dataclass
class Context:
    """What every fit of one diagnosis shares."""

    f: np.ndarray
    data: dict[str, np.ndarray]
    configs: list[Configuration]
    fixed: tuple[str, ...]
    scale: float
    one_port: bool
    progress: bool
    nominal: Circuit | None = None
    floor: float = 0.0
    #: Noise RMS of each response's log error (:func:`.evidence.noise_floor` ``per_response``).
    noise: dict[str, float] = field(default_factory=dict)
    prior: DesignPrior | None = None
    #: Per-point residual weights by response (:func:`.evidence.noise_weights`); empty: unweighted.
    weights: dict[str, np.ndarray] = field(default_factory=dict)
    #: Points quiet enough to show resonances, by response (:func:`.unmerge.resolved_points`); empty: all.
    resolved: dict[str, np.ndarray] = field(default_factory=dict)
    #: One value off the design set aside for a cause with a lower BIC, weighed again against the final answer
    #: (:func:`.causes.rivals.whole_answer`); ``answer_bic`` set on it.
    drift_aside: FitResult | None = None
    #: The best fit of each value the one-value search freed (:func:`.drift.located_drift`), by name, as a start of
    #: that value's later fits: (objective, effect labels, couplings, values, effect parameters, BIC).
    located: dict[str, tuple] = field(default_factory=dict)
    #: ``-2 ln`` of the prior share of one alternative of a cause, by cause (BIC units), added to the cause BIC of every
    #: fit naming it (:attr:`.fit.FitResult.cause_bic`): a missing section may be any of the places the search
    #: weighs (:func:`.causes.section_fits.structure_prior`), and its best fit's BIC alone counts the evidence of
    #: the best place as that of the cause.
    cause_prior: dict[str, float] = field(default_factory=dict)

    def fit(self, circuit: Circuit, effects: Sequence[Effect] = (), fixed: Sequence[str] = (),
            prior: DesignPrior | None | str = "same", couplings: Sequence[str] = ()) -> FrequencyFit:
        """The fit of ``circuit`` with ``effects`` (``couplings``: K elements fitted too, see :class:`.fit.FrequencyFit`)."""
        return FrequencyFit(circuit, self.configs, self.f, self.data, tuple(self.fixed) + tuple(fixed), effects,
                            self.scale, self.prior if isinstance(prior, str) else prior, couplings, self.weights,
                            self.cause_prior)

    def drift(self, r: FitResult, prior: DesignPrior | None = None) -> list[dict[str, Any]]:
        """Values of ``r`` moved beyond the design tolerance (none without a prior); under ``prior`` when given (a
        group's drift: its prior centred on the group's factor), else the diagnosis's."""
        prior = prior or self.prior
        if prior is None:
            return []
        anchored = prior.anchored(r.circuit)
        values = {n: v for n, v in r.values.items() if n.lower() in anchored}
        values.update(self.merged(r))
        return prior.drift(values)

    def merged(self, r: FitResult) -> dict[str, float]:
        """A section of the design split in two (:class:`.unmerge.Unmerged`): its halves merged back, by the
        design's names (empty for any other model, or without a prior).

        Merged back they are the design's section, and are held to its values like every other (a split whose
        halves add up to a resistance 3x the design's explains a drifted value, not a missing section)."""
        um = getattr(r, "unmerged", None)
        if self.prior is None or um is None:
            return {}
        try:
            merged = um.merged_back(r.fitted_circuit())
        except (KeyError, ValueError, ZeroDivisionError):
            return {}
        anchored = self.prior.anchored(r.circuit)
        return {n: float(v) for n, v in merged.items()
                if n.lower() in self.prior.design and n.lower() not in anchored and v > 0}

    def penalised(self, r: FitResult) -> float:
        """``r``'s objective with the prior's penalty on a split section's merged values added (cost units): how
        structural candidates are ranked, each held to the design as a whole."""
        if self.prior is None:
            return r.objective
        s = self.prior.scale()
        return r.objective + sum((s * math.log(v / self.prior.design[n.lower()])) ** 2
                                 for n, v in self.merged(r).items())

    def penalised_bic(self, r: FitResult) -> float:
        """``r``'s BIC on :meth:`penalised` (its parameters counted): how two fits of a missing section, from
        different values or with different couplings free, are weighed against each other."""
        return r.bic + r.n_residuals * math.log(self.penalised(r) / r.objective) if r.objective > 0 else r.bic

    def gross(self, r: FitResult, prior: DesignPrior | None = None) -> list[dict[str, Any]]:
        """The values of ``r`` more than ``GROSS_DRIFT`` tolerances from the design (under ``prior``, as
        :meth:`drift`)."""
        return [d for d in self.drift(r, prior) if d["sigmas"] > GROSS_DRIFT]

    def distorted(self, r: FitResult) -> bool:
        """``r`` moved a value more than ``GROSS_DRIFT`` tolerances from the design (never without a prior)."""
        return bool(self.gross(r))

    def explained(self, r: FitResult) -> bool:
        """``r`` fits to the noise floor without moving any value more than ``GROSS_DRIFT`` tolerances."""
        return r.objective <= NOISE_MARGIN * self.floor and not self.distorted(r)

    def unfit(self, r: FitResult) -> bool:
        """``r`` does not explain the data: its cost is above :data:`.verdict.FIT_FACTOR` times the noise floor.

        Every structure (a section split or added anywhere, from the fitted and from the design values) is sought
        for such a model: a misfit no estimate of the noise accounts for (:mod:`.verdict`).
        """
        return r.cost > FIT_FACTOR * self.floor

    def settled(self, r: FitResult) -> bool:
        """No further cause is sought after ``r``: it fits to the noise floor (at or below the data's; within
        ``NOISE_MARGIN`` of :meth:`residual_floor` with white residuals, :func:`.evidence.residuals_white`) without moving
        any value more than ``GROSS_DRIFT`` tolerances. A new section does not change this: its own values are not
        anchored to the design (:meth:`.prior.DesignPrior.anchored`), so a value of the design it leaves far off is
        one the fit moved to take another cause's share (a split beside a skin effect at the noise with a section's
        L and C moved 2-4x), and the other causes are still sought."""
        # at or below the data's own floor (an overestimate on a resonant winding) the fit is at the noise anyway;
        # within the margin above it, only if what is left looks like noise (white along frequency)
        # (one-port data only, as the residuals' floor: on several responses a few per cent of structure left in a
        # near-noise fit is the rule, and every extension of a six-response model costs tens of seconds)
        white = None if not self.one_port or self.weights else residuals_white(r.errors)
        if r.objective > self.floor and (r.objective > NOISE_MARGIN * self.residual_floor(r) or white is False):
            return False
        return not self.distorted(r) and self.within_design(r)

    def within_design(self, r: FitResult) -> bool:
        """The data do not need ``r``'s values beyond the tolerance: ``r`` followed onto the tolerance box loses less
        than ``DRIFT_MIN_DBIC`` against it with those values freed (:func:`.drift.design_rejected`, kept on ``r`` as
        ``rejected``, and the model within the box as ``boxed``). A model at the noise that needs them is not an
        explanation within the design: a cause, or a value off, is at work."""
        if getattr(r, "rejected", None) is None:
            r.rejected, r.boxed = design_rejected(self, r)
        return r.rejected < DRIFT_MIN_DBIC

    def residual_floor(self, r: FitResult) -> float:
        """The noise floor estimated from the third differences of ``r``'s residuals, if below the data's.

        The data's own third differences keep some of a sharp response's
        curvature (tens of per cent above the noise on a resonant winding);
        a model that follows the response leaves less of it in its residuals.
        One-port data without weights only (else the data's floor): measured
        on several responses, a split that leaves a few per cent of its fit
        to an effect's form was taken as that effect too.
        """
        if self.weights or not self.one_port:
            return self.floor
        return min(self.floor, sum(noise_variance(self.f, np.exp(e)) for e in r.errors.values()))
