"""Stand-in cost of a record replayed by its bridge voltage: the sampled arrangement's own frequency response.

When the record holds the bridge voltage ``v_bprbs`` and the source's R, L, C
are known, the samples of every recorded voltage are *exactly* the output of a
discrete-time system driven by the samples of the bridge voltage (the bridge
output is held between sample instants: zero-order hold). For the
arrangement's state space ``x' = A x + b u``, ``y = c x + d u`` sampled every
``h = 1 / fs``:

``H_d(z) = c (z I - Phi)^-1 Gamma + d``, ``Phi = e^{A h}``, ``Gamma = int_0^h e^{A s} ds b``,

and with ``A = V diag(lambda) V^-1`` this is the sum over the modes

``H_d(z) = sum_i (c v_i)(w_i b) (e^{lambda_i h} - 1) / lambda_i / (z - e^{lambda_i h}) + d``.

Modes above the Nyquist frequency appear in ``H_d`` at their aliases, as they
do in the record. The record's own map from ``v_bprbs`` to ``v_in`` (and to
every probe voltage) is therefore compared without the bias that an H1 of
``v_in / i_in`` suffers when the current's ringing lies above the Nyquist
frequency (the sampled current is then not the input of any sampled map; its
aliased ringing enters both spectra). The target is the record's Welch H1 at
the bins whose coherence is at least 0.99, replaced by the response of a
subspace model of the record (:func:`record_model`, as many states as the
arrangement) where the two agree: one record's H1 carries the leakage of its
window (0.4 % RMS on the three-section winding at 1 MHz), the identified map
does not.

The winding's ringing modes are far sharper than the compared bins, and a
mode above the Nyquist frequency is known from the samples only up to its
alias branch (``f`` and ``k fs +- f`` ring alike): the stand-in adds, per mode
of the subspace model that the record shows (:func:`model_modes`), the log
errors of its folded frequency (weight 100), decay rate and residue (weight 1)
against the estimate's mode paired with it (:func:`match_modes`, one to one).
The decay rates and residues tell the branches apart; each branch is a basin
of its own, which :func:`estimation.estimate.run_plan` searches with
least-squares descents from scattered starts besides the global search
(:attr:`DiscreteBridgeResponse.least_squares_starts`).

Measured on the three-section winding of thesis Table 4.7 (ngspice record,
one PRBS9 period): at 1 MHz the earlier stand-in (analytic ``Zin`` against the
record's H1 of ``v_in / i_in``) scored an alias-branch circuit (Cs -99.6 %) below
the truth; this one scores the truth 1e-10 against at least 5e-4 elsewhere.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation.parameters import ParameterSet

__all__ = ["DiscreteBridgeResponse", "bridge_response_proxy", "discrete_response", "may_alias", "model_modes", "record_model",
           "zoh_frequency_response", "zoh_modes"]


def zoh_frequency_response(A: np.ndarray, b: np.ndarray, C: np.ndarray, d: np.ndarray, fs: float,
                           f: np.ndarray) -> np.ndarray:
    """Frequency responses of continuous-time systems sampled with a zero-order hold on their input.

    Parameters
    ----------
    A : numpy.ndarray
        ``(P, n, n)`` state matrices, 1/s.
    b : numpy.ndarray
        ``(P, n)`` input vectors (one input).
    C : numpy.ndarray
        ``(P, m, n)`` output rows.
    d : numpy.ndarray
        ``(P, m)`` feed-through.
    fs : float, Hz
        Sampling rate (hold interval ``1 / fs``).
    f : numpy.ndarray, Hz
        ``(F,)`` frequencies, below ``fs / 2``.

    Returns
    -------
    numpy.ndarray
        ``(P, m, F)`` complex ``H_d(e^{j 2 pi f / fs})``; NaN for a system whose
        modes cannot be separated (a defective state matrix).
    """
    A = np.asarray(A, float)
    h = 1.0 / float(fs)
    lam, V = np.linalg.eig(A)
    with np.errstate(all="ignore"):
        ok = np.isfinite(np.linalg.cond(V)) & (np.linalg.cond(V) < 1e12)
        Vs = np.where(ok[:, None, None], V, np.eye(A.shape[1]))
        W = np.linalg.inv(Vs)
        cv = np.einsum("pmn,pni->pmi", np.asarray(C, float).astype(complex), Vs)  # (P, m, n)
        wb = np.einsum("pin,pn->pi", W, np.asarray(b, float).astype(complex))  # (P, n)
        mu = np.exp(lam * h)
        hold = np.where(np.abs(lam * h) > 1e-12, np.expm1(lam * h) / np.where(lam == 0, 1.0, lam), h)
        z = np.exp(2j * np.pi * np.asarray(f, float) * h)  # (F,)
        H = np.einsum("pmi,pif->pmf", cv * (wb * hold)[:, None, :], 1.0 / (z[None, None, :] - mu[:, :, None]))
        H = H + np.asarray(d, float)[:, :, None]
    H[~ok] = np.nan
    return H


def zoh_modes(A: np.ndarray, b: np.ndarray, c: np.ndarray, fs: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Modes of continuous-time systems sampled with a zero-order hold, as the samples see them.

    Parameters
    ----------
    A : numpy.ndarray
        ``(P, n, n)`` state matrices, 1/s.
    b, c : numpy.ndarray
        ``(P, n)`` input vector and output row.
    fs : float, Hz

    Returns
    -------
    f : numpy.ndarray, Hz
        ``(P, n)`` frequency of each sampled pole ``mu = e^{lambda / fs}`` folded into
        ``[0, fs / 2]`` (``|arg mu| fs / 2 pi``: a mode above the Nyquist frequency at its alias).
    sigma : numpy.ndarray, 1/s
        ``(P, n)`` decay rate ``-ln |mu| fs``.
    residue : numpy.ndarray
        ``(P, n)`` ``|residue|`` of the pole in ``H_d(z) = sum_i r_i / (z - mu_i) + d``.
    """
    h = 1.0 / float(fs)
    with np.errstate(all="ignore"):
        lam, V = np.linalg.eig(np.asarray(A, float))
        W = np.linalg.inv(V)
        cv = np.einsum("pn,pni->pi", np.asarray(c, float).astype(complex), V)
        wb = np.einsum("pin,pn->pi", W, np.asarray(b, float).astype(complex))
        hold = np.where(np.abs(lam * h) > 1e-12, np.expm1(lam * h) / np.where(lam == 0, 1.0, lam), h)
        mu = np.exp(lam * h)
    return np.abs(np.angle(mu)) * fs / (2 * np.pi), -np.log(np.abs(mu)) * fs, np.abs(cv * wb * hold)


def record_model(u: np.ndarray, y: np.ndarray, order: int, block_rows: int = 100, max_samples: int = 50_000
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """The record's own sampled map from ``u`` to ``y``: a subspace model ``(A, b, c, d)`` of ``order`` states.

    A PO-MOESP model (:func:`estimation.modal.subspace_model`) of the
    first ``max_samples`` samples; for a held bridge voltage the sampled map
    is exact, and the model is consistent under white output noise. None when
    the record is too short for ``order`` states.
    """
    from estimation import modal

    u = np.asarray(u, float)[:max_samples]
    y = np.asarray(y, float)[:max_samples]
    s = int(min(block_rows, u.size // 4 - 1))
    if not order < s:
        return None
    return modal.subspace_model(u, y, order, s)


def model_modes(A: np.ndarray, b: np.ndarray, c: np.ndarray, fs: float, count: int, band: tuple[float, float],
                height_ratio: float = 0.1, max_damping: float = 0.05) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ringing modes of a discrete-time model (:func:`record_model`) that a record shows.

    Oscillatory poles with folded frequency in ``band`` and damping ratio
    below ``max_damping``, ranked by their resonance height ``|r| / (sigma / fs)``;
    the strongest ``count`` are kept while each is at least ``height_ratio``
    times the one before (the first two always).

    Returns
    -------
    f, sigma, residue : numpy.ndarray
        Folded frequencies (Hz), decay rates (1/s), ``|residues|`` (as :func:`zoh_modes`), in frequency order.
    """
    mu, V = np.linalg.eig(A)
    r = np.abs((c @ V) * (np.linalg.inv(V) @ b))
    with np.errstate(all="ignore"):
        f = np.angle(mu) * fs / (2 * np.pi)
        sigma = -np.log(np.abs(mu)) * fs
        zeta = sigma / np.hypot(sigma, 2 * np.pi * f)
        height = r / np.maximum(np.abs(sigma) / fs, 1e-300)
    cand = np.flatnonzero((f > band[0]) & (f < band[1]) & (sigma > 0) & (zeta < max_damping) & np.isfinite(height))
    keep: list[int] = []
    for i in cand[np.argsort(height[cand])[::-1]][:max(count, 0)]:
        if len(keep) >= 2 and height[i] < height_ratio * height[keep[-1]]:
            break
        keep.append(int(i))
    if not keep:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    sel = np.array(keep)[np.argsort(f[keep])]
    return f[sel], sigma[sel], r[sel]


def discrete_response(A: np.ndarray, b: np.ndarray, c: np.ndarray, d: float, fs: float, f: np.ndarray) -> np.ndarray:
    """``c (z I - A)^-1 b + d`` at ``z = e^{j 2 pi f / fs}`` (``(F,)`` complex)."""
    z = np.exp(2j * np.pi * np.asarray(f, float) / float(fs))
    n = A.shape[0]
    rhs = np.broadcast_to(np.asarray(b, complex)[None, :, None], (z.size, n, 1))
    x = np.linalg.solve(z[:, None, None] * np.eye(n)[None] - A[None], rhs)[:, :, 0]
    return x @ c + d


def match_modes(f_t: np.ndarray, f_e: np.ndarray) -> np.ndarray:
    """One estimate mode per target mode, each used once: ``(P, T)`` column indices into ``f_e``.

    The assignment minimises the summed squared log-frequency distances; the
    estimate's modes are its oscillatory poles (``f_e`` holds each conjugate
    pair twice, and the real poles at 0 Hz: one of each pair counts, a real
    pole never). A target mode paired with the nearest estimate mode alone
    could share that mode with a neighbour: two target modes near one
    estimate mode would then form a minimum of their own.
    """
    from itertools import permutations

    from scipy.optimize import linear_sum_assignment

    f_t = np.asarray(f_t, float)
    P, n = f_e.shape
    with np.errstate(all="ignore"):
        fe = np.where(np.isfinite(f_e) & (f_e > 0), f_e, np.nan)
    # one column per conjugate pair: the sorted values pair up
    order = np.argsort(np.where(np.isnan(fe), -np.inf, fe), axis=1)[:, ::-1]
    slots = order[:, 0:2 * (n // 2):2]  # (P, m): the first of each equal pair, largest first
    m, t = slots.shape[1], f_t.size
    if t == 0:
        return np.zeros((P, 0), int)
    with np.errstate(all="ignore"):
        d = np.log(f_t[None, :, None] / np.take_along_axis(fe, slots, 1)[:, None, :]) ** 2  # (P, T, m)
    d = np.where(np.isfinite(d), d, 1e6)
    if m < t:
        return np.take_along_axis(slots, np.argmin(d, axis=2), 1)
    perms = list(permutations(range(m), t)) if np.prod(range(m - t + 1, m + 1)) <= 720 else None
    if perms is not None:
        pa = np.array(perms)  # (K, T)
        cost = d[:, np.arange(t)[None, :], pa].sum(axis=2)  # (P, K)
        best = pa[np.argmin(cost, axis=1)]  # (P, T)
    else:
        best = np.array([linear_sum_assignment(d[p])[1] for p in range(P)])
    return np.take_along_axis(slots, best, 1)


class DiscreteBridgeResponse(ap.Approach):
    """Stage-1 stand-in: the replayed arrangement's zero-order-hold responses against the record's H1.

    Parameters
    ----------
    params : ParameterSet
    engine : estimation.drives.RecordBridgeEngine
        The replay (its arrangement, state-space builder and sampling rate).
    frequency_hz : numpy.ndarray, Hz
        ``(F,)`` compared frequencies (Welch bins, below ``fs / 2``).
    target : numpy.ndarray
        ``(m, F)`` complex response of each compared voltage over the bridge voltage (V/V).
    mask : numpy.ndarray
        ``(m, F)`` bool: bins that count.
    outputs : sequence of str
        Names of the compared voltages (``v_in``, ``v_<node>``), ``v_in`` first.
    mode_target : tuple of numpy.ndarray, optional
        Folded frequencies (Hz), decay rates (1/s) and ``|residues|`` of the record's ringing
        modes in its map to ``v_in`` (:func:`model_modes`).
    mode_weights : tuple of float
        Weights of the log errors of those frequencies, decay rates and residues.

    Residuals: ``ln(H_d / target)`` at the kept bins, real part (log magnitude, nepers)
    and imaginary part (phase, rad, wrapped to ``(-pi, pi]``), then the weighted mode
    errors; cost: their sum of squares.
    """

    name = "bridge-response"
    engine = "zoh-bridge-response"
    #: Stage 1 also descends the residuals from this many scattered starts
    #: (:func:`estimation.estimate.run_plan`): one basin per alias branch of the ringing modes.
    #: :func:`bridge_response_proxy` sets 0 when no circuit of the search space rings above ``fs / 2``.
    least_squares_starts = 100

    def __init__(self, params: ParameterSet, engine: Any, frequency_hz: np.ndarray, target: np.ndarray,
                 mask: np.ndarray, outputs: Sequence[str],
                 mode_target: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 mode_weights: tuple[float, float, float] = (100.0, 1.0, 1.0)):
        super().__init__(params)
        self.mode_target = None if mode_target is None else tuple(np.asarray(a, float) for a in mode_target)
        self.mode_weights = tuple(float(w) for w in mode_weights)
        self.sim = engine
        self.f = np.asarray(frequency_hz, float)
        self.target = np.asarray(target, complex)
        self.mask = np.asarray(mask, bool)
        self.outputs = list(outputs)
        if self.target.shape != (len(self.outputs), self.f.size) or self.mask.shape != self.target.shape:
            raise ap.ApproachError(f"bridge-response target {self.target.shape} does not match "
                                   f"{len(self.outputs)} outputs x {self.f.size} frequencies")
        names = list(engine.names)
        self._rows = [engine._rows[names.index(o)] for o in self.outputs]

    def _state_space(self, overrides: Any) -> tuple[np.ndarray, ...]:
        values = self.sim.circuit.resolve(overrides, check=False)
        P = max([np.size(v) for v in values.values()] + [1])
        values = {k: np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) else v for k, v in values.items()}
        ss = self.sim.mna.state_space(values)
        n = np.shape(ss.A)[-1]
        A = np.broadcast_to(np.asarray(ss.A, float), (P, n, n))
        ok = np.all(np.isfinite(A.reshape(P, -1)), axis=1)
        A = np.where(ok[:, None, None], A, -np.eye(n))
        b = np.broadcast_to(np.asarray(ss.B, float), (P,) + np.shape(ss.B)[-2:])[:, :, 0]
        C = np.broadcast_to(np.asarray(ss.C, float), (P,) + np.shape(ss.C)[-2:])[:, self._rows, :]
        d = np.broadcast_to(np.asarray(ss.D, float), (P,) + np.shape(ss.D)[-2:])[:, self._rows, 0]
        return A, b, C, d, ok

    def responses(self, overrides: Any) -> np.ndarray:
        """``(P, m, F)`` zero-order-hold responses of the replayed arrangement (V/V)."""
        A, b, C, d, ok = self._state_space(overrides)
        H = zoh_frequency_response(A, b, C, d, self.sim.fs, self.f)
        H[~ok] = np.nan
        return H

    def modes(self, overrides: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sampled modes of the replayed arrangement, ``(P, n)`` each (:func:`zoh_modes`, map to ``v_in``)."""
        A, b, C, _, ok = self._state_space(overrides)
        f, sigma, r = zoh_modes(A, b, C[:, 0, :], self.sim.fs)
        f[~ok], sigma[~ok], r[~ok] = np.nan, np.nan, np.nan
        return f, sigma, r

    def _residuals(self, ev: Any) -> np.ndarray:
        H = self.responses(ev.overrides)
        with np.errstate(all="ignore"):
            e = np.log(H[:, self.mask] / self.target[self.mask][None, :])
        parts = [e.real, e.imag]
        if self.mode_target is not None:
            parts.append(self._mode_residuals(ev))
        r = np.concatenate(parts, axis=1)
        return np.where(np.isfinite(r), r, 10.0)

    def _mode_residuals(self, ev: Any) -> np.ndarray:
        f_t, s_t, r_t = self.mode_target  # type: ignore[misc]
        f_e, s_e, r_e = self.modes(ev.overrides)
        j = match_modes(f_t, f_e)
        with np.errstate(all="ignore"):
            pick = (lambda a: np.take_along_axis(a, j, 1))
            df = np.log(f_t[None] / pick(f_e))
            ds = np.log(pick(s_e) / s_t[None])
            dr = np.log(pick(r_e) / r_t[None])
        w_f, w_s, w_r = self.mode_weights
        return np.concatenate([w_f * df, w_s * ds, w_r * dr], axis=1)

    def _costs(self, ev: Any) -> np.ndarray:
        return np.sum(self._residuals(ev) ** 2, axis=1)


def bridge_response_proxy(params: ParameterSet, engine: Any, channels: dict[str, np.ndarray], fmin: float,
                          fmax: float, points: int = 200, coherence_min: float = 0.99,
                          nyquist_fraction: float = 0.45, with_modes: bool = True,
                          exact_target: bool = True, agreement: float = 0.1) -> DiscreteBridgeResponse | None:
    """The stand-in of a bridge-driven record: its own map from ``v_bprbs`` to its voltages, and its ringing modes.

    Parameters
    ----------
    params : ParameterSet
    engine : estimation.approaches.PrisEngine
        The replay (:class:`estimation.drives.RecordBridgeEngine`, or the commanded PRBS of a
        simulated target); its ``v_bprbs`` is the bridge voltage per sample.
    channels : dict
        ``v_in`` and any ``v_<node>`` probe voltages of the record (V), each ``(N,)``.
    fmin, fmax : float, Hz
        Band of the model (:func:`estimation.estimate.default_band`); the compared band is
        ``max(fmin, 2 fs / nperseg)`` to ``min(fmax, nyquist_fraction fs)``.
    points : int
        Log-spaced frequencies (nearest Welch bins, duplicates dropped).
    coherence_min : float
        Smallest coherence of a kept bin (quarter-record segments).
    nyquist_fraction : float
        Upper end of the band as a fraction of ``fs``.
    with_modes : bool
        Add the ringing modes of the record's subspace model (:func:`model_modes`; at most as
        many as the arrangement has oscillatory modes at the model's own values).
    exact_target : bool
        Compare with the subspace model's responses where they agree with the H1.
    agreement : float
        ``|ln(H_model / H1)|`` below which they agree.

    Returns
    -------
    DiscreteBridgeResponse or None
        None when fewer than 10 bins remain.
    """
    u = np.asarray(engine.v_bprbs, float)
    n, fs = u.size, float(engine.fs)
    welch = ap.WelchSettings()
    nper = welch.segment(n)
    lo, hi = max(fmin, 2 * fs / nper), min(fmax, nyquist_fraction * fs)
    if not hi > lo:
        return None
    bins, f = ap.bin_frequencies(fs, nper, lo, hi, points)
    names = [k for k in ["v_in"] + [f"v_{p}" for p in engine.probes] if k in channels]
    ys = [np.asarray(channels[k], float) for k in names]
    _, H, _, _ = ap.welch_h1(u, ys, fs, welch, bins)
    f_c, _, coh, _ = ap.welch_h1(u, ys, fs, ap.WelchSettings(nperseg=max(8, n // 4)))
    target = np.array(H)
    mask = np.array([(np.interp(f, f_c, c) >= coherence_min) & np.isfinite(t) & (np.abs(t) > 0)
                     for c, t in zip(coh, target)])
    if mask.sum() < 10:
        return None
    proxy = DiscreteBridgeResponse(params, engine, f, np.where(mask, target, 1.0), mask, names)
    if not exact_target and not with_modes:
        return proxy
    # the record's own sampled maps (as many states as the arrangement): their responses replace the H1
    # where the two agree (the H1 of one record carries the leakage of its window), and the ringing modes
    A0 = proxy._state_space({})[0]
    order = A0.shape[1]
    count = int(np.sum(np.linalg.eigvals(A0[0]).imag > 0))
    for i, y in enumerate(ys):
        m = record_model(u, y, order)
        if m is None:
            continue
        A, b, c, d = m
        if exact_target:
            h = discrete_response(A, b, c, d, fs, f)
            agree = mask[i] & (np.abs(np.log(h / np.where(mask[i], target[i], 1.0))) < agreement)
            proxy.target[i, agree] = h[agree]
            proxy.mask[i] = agree
        if with_modes and i == 0:
            modes = model_modes(A, b, c, fs, count, (lo, 0.5 * fs))
            proxy.mode_target = modes if modes[0].size else None
    if proxy.mask.sum() < 10:
        return None
    proxy.least_squares_starts = (DiscreteBridgeResponse.least_squares_starts
                                  if may_alias(proxy, params, fs) else 0)
    return proxy


def may_alias(proxy: DiscreteBridgeResponse, params: ParameterSet, fs: float, points: int = 256,
              max_damping: float = 0.05) -> bool:
    """Whether the search space holds circuits that ring above the Nyquist frequency (alias branches).

    The arrangement's modes at ``points`` Latin-hypercube points of the unit cube (and at its
    centre): True when any lightly damped one (damping ratio below ``max_damping``) lies above
    ``fs / 2``. Only then does a mode seen in the samples have several branches, each a basin of
    the stand-in, and stage 1 needs its least-squares starts.
    """
    from estimation.search.population import _latin_hypercube

    n = len(params.varying)
    U = np.vstack([np.full((1, n), 0.5), _latin_hypercube(np.random.default_rng(0), points, n)])
    A, _, _, _, ok = proxy._state_space(params.evaluate(U).overrides)
    with np.errstate(all="ignore"):
        lam = np.linalg.eigvals(A[ok])
        zeta = -lam.real / np.abs(lam)
    return bool(np.any((lam.imag / (2 * np.pi) > 0.5 * fs) & (zeta < max_damping)))
