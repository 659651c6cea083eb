"""Whether the diagnosis explains the data: ``none`` is a finding only when the returned model fits.

A diagnosis ends with a model (the baseline, or the baseline with the causes
named). It explains the data when

* its cost is within ``FIT_FACTOR`` times the noise floor estimated from the
  data (:func:`.evidence.noise_floor`), and
* every value it carries is within the design tolerance, or reported as
  drift (a value the data need beyond the tolerance, :mod:`.drift`).

The cost is a mean square of complex log errors over ``2 N`` real residuals;
for white noise at the floor it is ``floor * chi2(2N) / 2N``, whose spread is
``sqrt(2 / 2N)`` (7 % at 200 points, 3 % at 1000). The floor is itself an
estimate (third differences of the measured response), biased up by tens of
per cent on a sharply resonant winding and down on heavily smoothed data;
``FIT_FACTOR = 2`` covers that bias with the chi-square spread on top, so a
model that stays above it leaves a systematic misfit no estimate of the noise
accounts for.

A diagnosis that names no cause and does not explain the data answers
``unexplained``, never ``none``: with the residual bands left
(:func:`.evidence.unexplained_bands`), the best candidate tried and a
sentence on where the misfit sits and its shape (:func:`misfit_sentence`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

#: The returned model explains the data only within this factor of the noise floor (see the module docstring).
FIT_FACTOR = 2.0


def explains(cost: float, floor: float, off_design: Sequence[str]) -> bool:
    """The returned model explains the data: ``cost <= FIT_FACTOR * floor`` and no value off the design unreported.

    Parameters
    ----------
    cost : float
        Data cost of the returned model (mean square complex log error, summed over responses).
    floor : float
        Noise floor of the data on the same scale.
    off_design : sequence of str
        Values of the returned model beyond the design tolerance that the diagnosis does not report as drift.
    """
    return bool(cost <= FIT_FACTOR * floor and not off_design)


def misfit_shape(f: np.ndarray, e: np.ndarray, measured: np.ndarray | None = None) -> str:
    """A few words on the shape of the complex log error ``e`` over ``f`` (one band).

    Parameters
    ----------
    f : numpy.ndarray, Hz
    e : numpy.ndarray
        Complex log error ``ln(H_model / H_measured)`` (real: magnitude in nepers, imaginary: phase in radians).
    measured : numpy.ndarray, optional
        The measured response on ``f``: names the resonance the misfit sits on, if any.
    """
    if e.size < 3:
        return "too few points to tell its shape"
    mag, ph = e.real, e.imag
    m_rms, p_rms = float(np.sqrt(np.mean(mag ** 2))), float(np.sqrt(np.mean(ph ** 2)))
    part = "mostly in magnitude" if m_rms > 2 * p_rms else "mostly in phase" if p_rms > 2 * m_rms else \
        "in magnitude and phase"
    main = mag if m_rms >= p_rms else ph
    # sign changes of the dominant part (smoothed over 5 points): one for a resonance the model has shifted, none
    # for a level or damping difference, several for a ripple
    k = min(5, main.size)
    s = np.convolve(main, np.ones(k) / k, mode="valid")
    flips = int(np.sum(np.diff(np.sign(s[np.abs(s) > 0.2 * np.max(np.abs(s))])) != 0)) if s.size else 0
    # a trend along log f: the share of the dominant part a straight line in ln f explains
    x = np.log(f)
    A = np.vstack([np.ones_like(x), x - x.mean()]).T
    coef, *_ = np.linalg.lstsq(A, main, rcond=None)
    fit = A @ coef
    r2 = 1 - float(np.sum((main - fit) ** 2)) / max(float(np.sum((main - main.mean()) ** 2)), 1e-300)
    peak = float(f[int(np.argmax(np.abs(main)))])
    if r2 > 0.8 and flips <= 1:
        shape = f"a smooth trend {'rising' if coef[1] > 0 else 'falling'} with frequency"
    elif flips == 0:
        shape = f"a one-signed bump peaking near {peak:.4g} Hz (a level or damping difference)"
    elif flips == 1:
        shape = f"a sign change near {peak:.4g} Hz (a resonance at another frequency than the model's)"
    else:
        shape = f"a ripple ({flips} sign changes, largest near {peak:.4g} Hz: structure the model lacks)"
    if measured is not None and measured.size == f.size:
        from estimation.diagnosis.causes.unmerge import resonance_frequencies

        try:
            freqs, _ = resonance_frequencies(f, measured)
        except (ValueError, IndexError):
            freqs = np.zeros(0)
        near = [float(r) for r in freqs if f[0] <= r <= f[-1]]
        if near:
            shape += f", on the measured resonance{'s' if len(near) > 1 else ''} at " + ", ".join(
                f"{r:.4g}" for r in sorted(near)[:3]) + " Hz"
    return f"{shape}, {part}"


def misfit_sentence(f: np.ndarray, errors: Mapping[str, np.ndarray], measured: Mapping[str, np.ndarray],
                    bands: Sequence[Mapping[str, Any]], cost: float, floor: float) -> str:
    """One sentence: how far above the noise the model stays, where the misfit sits and its shape."""
    head = f"The model stays at {cost / floor:.3g} x the noise floor"
    if not bands:
        return head + ", spread over the band with no part standing out (a misfit everywhere, or noise the floor " \
                      "estimate misses)."
    b = bands[0]
    lo, hi = b["band_hz"]
    name = str(b["response"])
    sel = (f >= lo) & (f <= hi)
    shape = misfit_shape(f[sel], np.asarray(errors[name])[sel], np.asarray(measured[name])[sel]
                         if name in measured else None)
    more = f" ({len(bands) - 1} more band{'s' if len(bands) > 2 else ''} above the noise)" if len(bands) > 1 else ""
    return (f"{head}; the misfit sits in {name} between {lo:.4g} and {hi:.4g} Hz at {b['above_noise']:.3g} x the "
            f"noise RMS{more}: {shape}.")
