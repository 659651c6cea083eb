"""A fit followed from where it stands onto the design's tolerance box, the bounds closing in steps.

A model fitted under the design prior may hold an effect, or a value that is
really off, in several values moved beyond the tolerance. A local fit from
the design values does not find the other explanation (its resonances are not
aligned with the data's), and a fit from the model stays in the model's
basin. Closing the bounds of the values the prior holds onto the box in steps,
each fit started from the last, keeps the resonances aligned by the data while
the values return; what the values can no longer hold goes to the parameters
left free (an effect's, or a value freed from the prior).
"""

from __future__ import annotations

import numpy as np

from estimation.diagnosis.fit import FitResult, FrequencyFit

#: Steps of the bounds closing onto the tolerance, and evaluations per step.
ONTO_STEPS, ONTO_NFEV = 4, 40


def onto_box(fit: FrequencyFit, start: np.ndarray, tau: float, release_nfev: int | None = 60) -> FitResult:
    """``fit`` followed from ``start`` onto the tolerance box of the values its prior holds, then released.

    Every value the prior holds (:attr:`.fit.FrequencyFit.anchored_columns`)
    is bounded between its box (design value ``x exp(+-tau)``) and where it
    starts; the bounds close onto the box in ``ONTO_STEPS`` steps, each fit
    (``ONTO_NFEV`` evaluations) started from the last. From the box the fit
    is released (``release_nfev`` evaluations, the prior as everywhere else),
    unless ``release_nfev`` is None.

    Parameters
    ----------
    fit : FrequencyFit
        The fit, with its design prior.
    start : numpy.ndarray
        Parameter vector to start from (log ratios to the fit's start values, then the effects' parameters).
    tau : float
        The tolerance in log units, ``ln(1 + tolerance)``.
    release_nfev : int or None
        Evaluations of the released fit; ``None`` returns the fit within the box.

    Returns
    -------
    FitResult
        The released fit (or the fit within the box). A failed solve raises as :meth:`.fit.FrequencyFit.fit` does.
    """
    cols = fit.anchored_columns
    design = fit.design_vector(start)
    lo0, hi0 = fit.bounds()
    # how far each held value starts beyond its box, below and above (zero for a value inside it)
    below = np.minimum(0.0, start[cols] - design[cols] + tau)
    above = np.maximum(0.0, start[cols] - design[cols] - tau)
    x = np.array(start, dtype=float)
    boxed = None
    for s in np.linspace(0.0, 1.0, ONTO_STEPS + 1)[1:]:
        lo, hi = lo0.copy(), hi0.copy()
        lo[cols] = design[cols] - tau + (1 - s) * below
        hi[cols] = design[cols] + tau + (1 - s) * above
        x = np.clip(x, lo + 1e-9, hi - 1e-9)
        boxed = fit.fit(x0s=x[None], grid=False, keep_starts=1, max_nfev=ONTO_NFEV, tol=1e-6, limits=(lo, hi))
        x = boxed.x
    if release_nfev is None:
        return boxed
    return fit.fit(x0s=x[None], grid=False, keep_starts=1, max_nfev=release_nfev, tol=1e-7)


def within_box(fit: FrequencyFit, start: np.ndarray, tau: float, max_nfev: int = ONTO_STEPS * ONTO_NFEV
               ) -> FitResult:
    """``fit`` from ``start`` with every value its prior holds bounded within its tolerance box (design value
    ``x exp(+-tau)``; ``start`` clipped into it), the other parameters within their own bounds.

    Parameters
    ----------
    fit : FrequencyFit
        The fit, with its design prior.
    start : numpy.ndarray
        Parameter vector to start from.
    tau : float
        The tolerance in log units.
    max_nfev : int
        Evaluations of the fit.

    Returns
    -------
    FitResult
        The fit within the box.
    """
    cols = fit.anchored_columns
    design = fit.design_vector(start)
    lo, hi = fit.bounds()
    lo[cols], hi[cols] = design[cols] - tau, design[cols] + tau
    x = np.clip(np.asarray(start, dtype=float), lo + 1e-9, hi - 1e-9)
    return fit.fit(x0s=x[None], grid=False, keep_starts=1, max_nfev=max_nfev, tol=1e-6, limits=(lo, hi))
