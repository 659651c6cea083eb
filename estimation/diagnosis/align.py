"""Resonance alignment: a start for a baseline fit with the model's resonances moved onto the measured ones.

A winding's driving-point impedance has sharp parallel (peaks of ``|Z|``)
and series (dips) resonances. With every value of a design a few per cent
off, each resonance of the model sits a few per cent from the measured one,
and a least-squares fit of the log errors from there often stalls: moving a
resonance across the measured one first makes the errors larger. The
resonance frequencies themselves are smooth functions of the values, as in
the sensitivity-based updating of finite-element models against measured
natural frequencies. This module moves the values so that the model's
resonances (the poles of the port impedance, parallel; its zeros, series)
fall on the measured ones, each measured resonance paired with one model
resonance of its kind by least total log distance, with a weak pull
towards the start values; the fit of the log errors then starts there.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg as sla
from scipy.optimize import least_squares, linear_sum_assignment

from scipy.special import ndtri

from estimation.diagnosis.evidence import noise_variance
from estimation.diagnosis.fit import FrequencyFit
from estimation.resonances import find_resonances, refine_resonances

#: Pull towards the start values: a value moved by ``tau`` (one tolerance, or ``ln 1.2`` without a prior) weighs
#: as much as a resonance 1 % off.
PULL = 0.01
#: The pull within the tolerance box (:func:`aligned_start` with ``box``): a value moved by one tolerance weighs like
#: a resonance 0.1 % off. The measured resonances are placed to about 1e-5 (:func:`refined_modes`) and a mode of
#: quality factor 1000 is 0.1 % wide, so an alignment that leaves the modes 1 % off (:data:`PULL`) leaves each many
#: bandwidths from its measured place; within the box the bounds keep the values near the design.
BOXED_PULL = 1e-3
#: Residual of a measured resonance that no model resonance is paired with (not differentiable: a constant).
UNPAIRED = 0.5
#: Evaluations of the alignment (each is one eigen-decomposition per configuration: cheap).
ALIGN_NFEV = 60
#: Model resonances counted: those within this factor of the measured band.
BAND_MARGIN = 1.5
#: False-alarm probability of a measured resonance over all the points of a response: a peak or dip counts when its
#: prominence exceeds what the noise of two neighbouring points reaches this rarely (:func:`measured_modes`).
MODE_ALPHA = 1e-3


def port_roots(fit: FrequencyFit, x: np.ndarray, index: int, f_lo: float, f_hi: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Poles and zeros (rad/s, complex, ascending in frequency) of configuration ``index``'s port impedance.

    The poles of ``Z(s)`` (a current driven into the port) and its
    invariant zeros (the finite generalised eigenvalues of the Rosenbrock
    pencil ``[[A, B], [C, D]]``), those with positive imaginary part whose
    ``Im / 2 pi`` is within ``f_lo / BAND_MARGIN .. f_hi * BAND_MARGIN``.
    """
    values = fit.circuit.resolve(fit.overrides(x), check=False)
    A, B, C, D = fit.models[index].port_system(values)
    n = A.shape[0]
    if n == 0:
        return np.zeros(0, complex), np.zeros(0, complex)
    poles = np.linalg.eigvals(A)
    pencil = np.zeros((n + 1, n + 1))
    pencil[:n, :n] = np.eye(n)
    with np.errstate(all="ignore"):
        zeros = sla.eigvals(np.block([[A, B], [C, D]]), pencil)
    zeros = zeros[np.isfinite(zeros)]

    def band(v: np.ndarray) -> np.ndarray:
        v = v[v.imag > 0]
        fr = v.imag / (2 * np.pi)
        v = v[(fr > f_lo / BAND_MARGIN) & (fr < f_hi * BAND_MARGIN)]
        return v[np.argsort(v.imag)]

    return band(poles), band(zeros)


def port_modes(fit: FrequencyFit, x: np.ndarray, index: int, f_lo: float, f_hi: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Parallel and series resonance frequencies (Hz, ascending) of configuration ``index``'s port impedance:
    the imaginary parts of :func:`port_roots` over ``2 pi``."""
    return tuple(v.imag / (2 * np.pi) for v in port_roots(fit, x, index, f_lo, f_hi))


def _impedances(fit: FrequencyFit) -> list[tuple[int, str]]:
    """(configuration index, response name) of every measured port impedance."""
    out = []
    for i, m in enumerate(fit.models):
        for r in m.responses:
            if r.node is None and r.name in fit.measured:
                out.append((i, r.name))
                break
    return out


def _paired(measured: np.ndarray, model: np.ndarray) -> np.ndarray:
    """Log distance of each measured resonance to the model resonance paired with it (``UNPAIRED`` if none)."""
    out = np.full(measured.size, UNPAIRED)
    if measured.size and model.size:
        rows, cols = linear_sum_assignment(np.abs(np.log(model[None, :] / measured[:, None])))
        out[rows] = np.log(model[cols] / measured[rows])
    return out


def measured_modes(f: np.ndarray, h: np.ndarray, alpha: float = MODE_ALPHA) -> tuple[np.ndarray, np.ndarray]:
    """Peaks and dips of ``|h|`` (Hz) that stand above the response's own noise.

    A mode weakly observable at the port (a pole almost cancelled by a zero)
    leaves a wiggle of a fraction of a dB over a few points, narrower than
    any smoothing; a local fit does not move a model's mode across more than
    its width, so such a mode must be aligned too. Unsmoothed, a peak or dip
    counts when its prominence exceeds ``z`` standard deviations of the
    difference of two points' ``20 log10 |h|`` (the noise estimated from the
    data, :func:`.evidence.noise_variance`, half of it in ``ln |h|``), ``z``
    the normal quantile of ``1 - alpha / N`` over the ``N`` points.
    """
    sd_db = 20 / np.log(10) * np.sqrt(noise_variance(f, h) / 2)
    z = float(ndtri(1 - alpha / max(f.size, 1)))
    found = find_resonances(f, h, min_prominence_db=max(z * np.sqrt(2) * sd_db, 1e-6), smooth_decades=0.0)
    freq = np.array([r.frequency_hz for r in found])
    parallel = np.array([r.kind == "parallel" for r in found], bool)
    return (freq[parallel], freq[~parallel]) if freq.size else (freq, freq)


#: Measured resonances of the responses seen (:func:`_targets`), keyed by the data's bytes: the rational fit
#: behind them takes a fraction of a second, and every start of every candidate aligns onto the same data.
_MEASURED: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def refined_modes(f: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`measured_modes`, each peak moved onto a pole and each dip onto a zero of a rational fit of ``h``.

    A winding's resonances are far sharper than a logarithmic grid: at a
    quality factor of 1000 the half-power band is 0.1 % wide, while 500
    points over three decades are 1.4 % apart, and a sampled peak sits up to
    half a step (0.7 %, seven bandwidths) from its pole. A model aligned
    onto the sampled peaks is that far off each mode, and a local fit does
    not move a mode across more than its width. Vector fitting of the
    impedance (for the peaks) and of the admittance (for the dips) places
    each pole to about ``1e-5`` relative
    (:func:`estimation.resonances.refine_resonances`).
    """
    key = np.asarray(f, float).tobytes() + np.asarray(h, complex).tobytes()
    if key not in _MEASURED:
        peaks, dips = measured_modes(f, h)
        with np.errstate(all="ignore"):
            out = (refine_resonances(f, h, peaks) if peaks.size else peaks,
                   refine_resonances(f, 1.0 / np.asarray(h), dips) if dips.size else dips)
        if len(_MEASURED) > 64:
            _MEASURED.clear()
        _MEASURED[key] = out
    return _MEASURED[key]


def _targets(fit: FrequencyFit) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(configuration index, measured peaks, measured dips) of every measured port impedance with resonances, Hz
    (:func:`refined_modes`)."""
    targets = []
    for i, name in _impedances(fit):
        peaks, dips = refined_modes(fit.f, fit.measured[name])
        if peaks.size + dips.size:
            targets.append((i, peaks, dips))
    return targets


def resonance_mismatch(fit: FrequencyFit, X: np.ndarray) -> np.ndarray:
    """Sum of squared log distances between the measured resonances and the model's, per row of ``X``.

    Each measured peak (dip) of a port impedance is paired with a pole
    (zero) of the model's port impedance (``UNPAIRED`` when there is none to
    pair); rows with a singular model give ``inf``. Zeros when no measured
    resonance is found.
    """
    X = np.atleast_2d(np.asarray(X, float))
    targets = _targets(fit)
    out = np.zeros(X.shape[0])
    f_lo, f_hi = float(fit.f[0]), float(fit.f[-1])
    for k, x in enumerate(X):
        try:
            for i, peaks, dips in targets:
                poles, zeros = port_modes(fit, x, i, f_lo, f_hi)
                out[k] += float(np.sum(_paired(peaks, poles) ** 2) + np.sum(_paired(dips, zeros) ** 2))
        except (np.linalg.LinAlgError, ValueError):
            out[k] = np.inf
    return out


def aligned_start(fit: FrequencyFit, x0: np.ndarray, max_nfev: int = ALIGN_NFEV, free: Sequence[int] = (),
                  box: float | None = None) -> np.ndarray | None:
    """``x0`` with its circuit values moved so that the port impedances' resonances fall on the measured ones.

    Parameters
    ----------
    fit : FrequencyFit
        The fit (its measured port impedances give the resonances).
    x0 : numpy.ndarray
        Start vector (log ratios to ``fit.start``; effect parameters kept).
    max_nfev : int
        Evaluations of the alignment.
    free : sequence of int
        Circuit columns not pulled towards ``x0`` (a value tried as off the
        design).
    box : float, optional
        Tolerance (log units): the values the prior holds, besides ``free``,
        stay within ``box`` of their design values, and the pull weighs one
        tolerance like a resonance ``BOXED_PULL`` off (the box, not the
        pull, keeps them near the design).

    Returns
    -------
    numpy.ndarray or None
        The aligned vector; ``None`` when no measured resonance is found or
        the alignment moves no resonance closer.
    """
    f = fit.f
    targets = _targets(fit)
    if not targets or fit.nc == 0:
        return None
    start = np.asarray(x0, float)[: fit.nc].copy()
    # the pull towards x0 weighs one tolerance (the design prior's, else ln 1.2) like a resonance PULL off
    tau = box if box is not None else fit.prior.tau if fit.prior is not None else float(np.log(1.2))
    pull = np.full(fit.nc, (PULL if box is None else BOXED_PULL) / tau)
    pull[np.asarray(free, int)] = 0.0

    def residuals(xc: np.ndarray) -> np.ndarray:
        x = np.concatenate([xc, np.asarray(x0, float)[fit.nc:]])
        parts = []
        for i, peaks, dips in targets:
            poles, zeros = port_modes(fit, x, i, float(f[0]), float(f[-1]))
            parts += [_paired(peaks, poles), _paired(dips, zeros)]
        parts.append(pull * (xc - start))
        return np.concatenate(parts)

    lo, hi = fit.bounds()
    lo, hi = lo[: fit.nc] + 1e-9, hi[: fit.nc] - 1e-9
    if box is not None:
        held = np.setdiff1d(fit.anchored_columns, np.asarray(free, int))
        design = fit.design_vector(np.asarray(x0, float))
        lo[held] = np.maximum(lo[held], design[held] - box + 1e-9)
        hi[held] = np.minimum(hi[held], design[held] + box - 1e-9)
    try:
        r0 = residuals(start)
        sol = least_squares(residuals, np.clip(start, lo, hi), bounds=(lo, hi), max_nfev=max_nfev, diff_step=1e-4)
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.isfinite(sol.cost) or sol.cost >= 0.5 * float(r0 @ r0):
        return None
    return np.concatenate([sol.x, np.asarray(x0, float)[fit.nc:]])

