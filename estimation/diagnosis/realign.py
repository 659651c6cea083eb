"""Resonances moved onto where a fitted model still misses the data, one at a time.

A winding's port impedance has sharp resonances, and some of them are
weak: a pole and a zero of ``Z`` so close together that they show in the
data only as a small blip at one or two frequencies (a mode the port
hardly excites). When a fitted model holds such a mode a few per cent
from the measured one, a local fit does not move it: the cost changes only
when the model's blip overlaps the measured one, and the resonance
alignment of :mod:`.align` does not see it either (it pairs the peaks and
dips of ``|Z|``, which a near-cancelled pair does not make). The fit then
stops well above the noise, with its misfit concentrated at the mode.

This module reads where the misfit sits and tries the nearby modes there:

1. **Misfits.** Under the noise, a point's ``|e|^2`` divided by the floor
   per point is exponential with unit mean, so it exceeds
   ``ln(N / MISFIT_FALSE)`` anywhere in a record of ``N`` points with
   probability ``MISFIT_FALSE`` (Bonferroni). Points above that, closer
   than ``MISFIT_GAP`` grid steps, form one misfit; its frequency is its
   worst point's.
2. **Modes to move.** Every pole or zero of the model's port impedance
   within the tolerance's factor (``1 + tolerance``; a resonance
   ``1 / sqrt(LC)`` of values within the tolerance stays within it) of a
   misfit, not already at it. A pole and a zero closer than the grid step
   there show in the data as one blip and move together.
3. **The move.** The values are moved (least squares on the resonance
   frequencies, as :func:`.align.aligned_start`) so that this mode sits at
   the misfit and every other resonance stays where it is; a local fit
   follows; each move is tried with the values pulled towards where they
   were and without. The best of the tries replaces the fit when it
   lowers the objective, and the round is repeated on the new misfit.

On drawn windings whose baseline fit stopped at 3-56 times the floor while
the truth's values reached it, every such fit reached the truth's level.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from estimation.diagnosis.align import PULL, _impedances, _paired, port_modes, port_roots
from estimation.diagnosis.cores import shared_map
from estimation.diagnosis.fit import FitResult, FrequencyFit

#: Probability that the noise alone marks a point of the record as a misfit.
MISFIT_FALSE = 0.05
#: Misfit points at most this many grid steps apart are one misfit.
MISFIT_GAP = 2
#: Misfits tried per round (the largest excess first), and rounds at most.
MISFITS = 4
ROUNDS = 4
#: A round counts only when it lowers the objective by this fraction (else the search stops).
MIN_GAIN = 0.02
#: Evaluations of a move's alignment, and of its local fit.
MOVE_NFEV = 200
FIT_NFEV = 200
#: Window around a misfit without a design prior (the default tolerance's factor).
WINDOW = 1.2


def misfits(fit: FrequencyFit, r: FitResult, floor: float) -> list[tuple[int, float, float]]:
    """Where ``r`` misses the data beyond the noise: ``(configuration, frequency Hz, excess)``, largest first.

    ``floor`` is the noise floor's cost (mean ``|e|^2`` per point, summed
    over the responses); each measured port impedance is read on its share.
    """
    out: list[tuple[int, float, float]] = []
    per = floor / max(1, len(fit.measured))
    if not per > 0 or not np.isfinite(per):
        return out
    n = fit.f.size
    threshold = np.log(n / MISFIT_FALSE)
    for i, name in _impedances(fit):
        e = np.asarray(r.errors[name])
        u2 = fit.weights[name] ** 2 if name in fit.weights else 1.0
        e2 = u2 * np.abs(e) ** 2 / per
        idx = np.flatnonzero(e2 > threshold)
        if idx.size == 0:
            continue
        for g in np.split(idx, np.flatnonzero(np.diff(idx) > MISFIT_GAP) + 1):
            k = int(g[np.argmax(e2[g])])
            out.append((i, float(fit.f[k]), float(np.sum(e2[g] - 1))))
    return sorted(out, key=lambda t: -t[2])


def _step(f: np.ndarray, at: float) -> float:
    """The grid's log step near ``at`` (Hz)."""
    k = int(np.clip(np.searchsorted(f, at), 1, f.size - 1))
    return float(np.log(f[k] / f[k - 1]))


def _window(fit: FrequencyFit) -> float:
    """Log half-width of the search around a misfit: the tolerance's factor (``WINDOW`` without a prior)."""
    tau = fit.prior.tau if fit.prior is not None else np.inf
    return float(tau if np.isfinite(tau) else np.log(WINDOW))


def _pair_factor(jw: np.ndarray, root: complex, shift: np.ndarray) -> np.ndarray:
    """``ln`` of ``(jw - r)(jw - r*)`` with the root ``r`` scaled by ``exp(shift)`` over the same unscaled,
    shape ``(shift.size, jw.size)`` (a root's quality factor is kept as it moves)."""
    r1 = root * np.exp(shift)[:, None]
    return (np.log((jw - r1) * (jw - np.conj(r1))) - np.log((jw - root) * (jw - np.conj(root))))


def _pair_residuals(uv: np.ndarray, e: np.ndarray, jw: np.ndarray, pole: complex, zero: complex) -> np.ndarray:
    """The log error ``e`` left with the pole shifted by ``exp(uv[0])`` and the zero by ``exp(uv[1])``
    (real and imaginary parts)."""
    d = e - _pair_factor(jw, pole, uv[:1])[0] + _pair_factor(jw, zero, uv[1:])[0]
    return np.concatenate([d.real, d.imag])


def _moves(fit: FrequencyFit, x: np.ndarray, found: list[tuple[int, float, float]], r: FitResult
           ) -> list[tuple]:
    """The mode moves to try: ``(configuration, pole index, pole target, zero index, zero target)`` (rad/s).

    For each misfit, each pole of the model within the window, with the
    zero nearest it (and each zero with its nearest pole), is shifted as a
    pair in the model's factored form: ``Z`` times
    ``(s - p)(s - p*) / ((s - p')(s - p'*))`` and the same for the zero
    the other way up, the two shifts chosen (a grid, then least squares) to
    remove most of the log error within the window. The shift that removes
    most is tried for each misfit, and every other that removes at least
    half as much.
    """
    window = _window(fit)
    lo, hi = float(fit.f[0]), float(fit.f[-1])
    grid = np.linspace(-window, window, 61)
    out: list[tuple] = []
    names = dict(_impedances(fit))
    for i, fc, _ in found[:MISFITS]:
        poles, zeros = port_roots(fit, x, i, lo, hi)
        if poles.size == 0 or zeros.size == 0:
            continue
        near = np.abs(np.log(fit.f / fc)) < window
        jw = 2j * np.pi * fit.f[near]
        e = np.asarray(r.errors[names[i]])[near]
        pairs = set()
        for k, p in enumerate(poles):
            if abs(np.log(p.imag / (2 * np.pi * fc))) < window:
                pairs.add((k, int(np.argmin(np.abs(zeros - p)))))
        for j, z in enumerate(zeros):
            if abs(np.log(z.imag / (2 * np.pi * fc))) < window:
                pairs.add((int(np.argmin(np.abs(poles - z))), j))
        scored = []
        for k, j in sorted(pairs):
            fp, fz = _pair_factor(jw, poles[k], grid), _pair_factor(jw, zeros[j], grid)
            # the model's error after the shift: e - ln(pole factor) + ln(zero factor), over the grid of both shifts
            left = np.sum(np.abs(e[None, None, :] - fp[:, None, :] + fz[None, :, :]) ** 2, axis=2)
            a, b = np.unravel_index(int(np.argmin(left)), left.shape)
            sol = least_squares(_pair_residuals, [grid[a], grid[b]], bounds=([-window] * 2, [window] * 2),
                                max_nfev=50, args=(e, jw, poles[k], zeros[j]))
            gain = float(np.sum(np.abs(e) ** 2) - 2 * sol.cost)
            scored.append((gain, (i, k, poles[k] * np.exp(sol.x[0]), j, zeros[j] * np.exp(sol.x[1]))))
        if scored:
            top = max(g for g, _ in scored)
            out += [m for g, m in sorted(scored, key=lambda t: -t[0]) if top > 0 and g >= 0.5 * top]
    return out


def moved(fit: FrequencyFit, x: np.ndarray, move: tuple, pulled: bool = True) -> np.ndarray | None:
    """``x`` with one pole and one zero of a port impedance moved and the other resonances held (``None`` if the
    alignment fails).

    ``move`` is ``(configuration, pole index, pole target, zero index,
    zero target)``: the indices in :func:`.align.port_roots`' order, the
    targets complex (rad/s; only their frequencies are aimed at). With
    ``pulled`` the values are pulled towards ``x`` as in
    :func:`.align.aligned_start`; without it they go wherever the
    resonances put them (making a near-cancelled pair visible can take
    changes the pull does not allow; the fit that follows has the prior).
    """
    i, k, p_to, j, z_to = move
    lo_f, hi_f = float(fit.f[0]), float(fit.f[-1])
    held = [m.copy() for m in port_modes(fit, x, i, lo_f, hi_f)]
    if k >= held[0].size or j >= held[1].size:
        return None
    held[0][k] = p_to.imag / (2 * np.pi)
    held[1][j] = z_to.imag / (2 * np.pi)
    start = np.asarray(x, float)[: fit.nc].copy()
    pull = np.full(fit.nc, PULL / (fit.prior.tau if fit.prior is not None else float(np.log(WINDOW))) * pulled)

    def residuals(xc: np.ndarray) -> np.ndarray:
        v = np.concatenate([xc, np.asarray(x, float)[fit.nc:]])
        parts = [_paired(want, model) for model, want in zip(port_modes(fit, v, i, lo_f, hi_f), held)]
        parts.append(pull * (xc - start))
        return np.concatenate(parts)

    lo, hi = fit.bounds()
    try:
        sol = least_squares(residuals, start, bounds=(lo[: fit.nc] + 1e-9, hi[: fit.nc] - 1e-9),
                            max_nfev=MOVE_NFEV, diff_step=1e-4)
    except (np.linalg.LinAlgError, ValueError):
        return None
    return np.concatenate([sol.x, np.asarray(x, float)[fit.nc:]]) if np.all(np.isfinite(sol.x)) else None


def _move_fitted(args: tuple[FrequencyFit, np.ndarray, tuple, bool]) -> FitResult | None:
    """One move and its local fit (a module-level function for :func:`.cores.shared_map`)."""
    fit, x, move, pulled = args
    x1 = moved(fit, x, move, pulled)
    if x1 is None:
        return None
    return fit.fit(x0s=x1[None], grid=False, keep_starts=1, max_nfev=FIT_NFEV)


def realigned(fit: FrequencyFit, r: FitResult, floor: float, good_enough: float) -> FitResult:
    """``r`` improved by moving the model's modes onto its misfits (the module's text), or ``r`` itself.

    Parameters
    ----------
    fit : FrequencyFit
        The fit ``r`` came from.
    r : FitResult
        A local optimum of ``fit``.
    floor : float
        The noise floor's cost.
    good_enough : float
        Objective at which the search stops.
    """
    best, wall, nfev = r, 0.0, 0
    for _ in range(ROUNDS):
        if best.objective <= good_enough:
            break
        moves = _moves(fit, best.x, misfits(fit, best, floor), best)
        if not moves:
            break
        tried = [t for t in shared_map(_move_fitted, [(fit, best.x, m, p) for m in moves for p in (True, False)]) if t is not None]
        wall += sum(t.wall_s for t in tried)
        nfev += sum(t.nfev for t in tried)
        top = min(tried, key=lambda t: t.objective, default=None)
        if top is None or top.objective > (1 - MIN_GAIN) * best.objective:
            break
        best = top
    if best is r:
        return r
    best.wall_s, best.nfev = r.wall_s + wall, r.nfev + nfev
    best.alternative = getattr(r, "alternative", None)
    return best
