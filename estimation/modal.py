"""Modal first stage of the time-domain estimation paths: match the arrangement's ringing modes first.

The PRIS arrangement of the three-section winding has two modes near
723 kHz and 886 kHz with damping ratios of 3-4e-4. They ring through the
whole time record, so the time-domain costs have a hole at the true
parameters only about ``1 / T`` (0.2 %) wide in each mode frequency, inside a
wide valley where the ringing is not matched; global optimisers on the time
cost end in the valley.

This stage reads the modes off the target itself: in the longest interval
where the commanded bridge voltage does not switch, the terminal voltage is
a free response (a sum of damped exponentials), and the matrix-pencil
method (Hua and Sarkar, 1990) returns their poles. The estimate's modes are
the eigenvalues of its arrangement's state matrix. :class:`ModalGuide`
compares them (log frequency and, with a small weight, log damping ratio);
its minima form a low-dimensional set through the truth, from which the
time-domain cost is polished.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from estimation import approaches as ap
from estimation.parameters import ParameterSet


def free_segment(v_bprbs: np.ndarray, skip: int = 5) -> tuple[int, int]:
    """Longest run of samples without a bridge-voltage switch: ``(start, stop)`` sample indices.

    ``skip`` samples after the switch are left out (the sample holding the edge).
    """
    v = np.asarray(v_bprbs, float)
    edges = np.flatnonzero(np.diff(v) != 0) + 1
    bounds = np.concatenate([[0], edges, [v.size]])
    k = int(np.argmax(np.diff(bounds)))
    return int(bounds[k]) + skip, int(bounds[k + 1])


def matrix_pencil(y: np.ndarray, order: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time poles (1/s) and complex amplitudes of ``order`` damped exponentials fitting ``y``.

    Parameters
    ----------
    y : numpy.ndarray
        ``(N,)`` uniformly sampled free response.
    order : int
        Number of exponentials kept from the SVD (signal subspace; larger than
        the true count under noise, the weakest are then dropped by amplitude).
    fs : float, Hz

    Returns
    -------
    poles, amplitudes : numpy.ndarray
        ``y[k] ~ sum_i amplitudes[i] * exp(poles[i] * k / fs)``.
    """
    y = np.asarray(y, float)
    n = y.size
    L = n // 2
    Y = np.lib.stride_tricks.sliding_window_view(y, L + 1)
    _, _, vt = np.linalg.svd(Y, full_matrices=False)
    V = vt[:order].T
    z = np.linalg.eigvals(np.linalg.pinv(V[:-1]) @ V[1:]).astype(complex)
    Z = z[None, :] ** np.arange(n)[:, None]
    amp = np.linalg.lstsq(Z, y.astype(complex), rcond=None)[0]
    return np.log(z) * fs, amp


def subspace_model(u: np.ndarray, y: np.ndarray, order: int, block_rows: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Discrete-time state-space model ``(A, b, c, d)`` from ``u`` to ``y`` over the whole record (PO-MOESP).

    The past-output MOESP subspace method (Verhaegen, 1994): block Hankel
    matrices of the past and future input and output samples, an LQ
    factorisation (here the Cholesky factor of the Gram matrix), and the SVD
    of the part of the future outputs that the past (the instruments)
    explains; the leading ``order`` left singular vectors span the extended
    observability matrix, whose shift invariance gives ``A`` and whose first
    row gives ``c``. White output noise is uncorrelated with the
    instruments, so the model is consistent under noise, and every sample of
    the record counts (unlike a window of free ringing). ``b``, ``d`` and the
    initial state then follow from linear least squares on the record.

    Parameters
    ----------
    u, y : numpy.ndarray
        ``(N,)`` input (e.g. the commanded bridge voltage, V) and output (V) samples.
    order : int
        State dimension kept.
    block_rows : int
        Block rows ``s`` of the Hankel matrices (``order < s < N / 4``; more rows
        average more noise out, at ``O(N s^2)`` cost).

    Returns
    -------
    A : numpy.ndarray
        ``(order, order)``.
    b, c : numpy.ndarray
        ``(order,)`` input and output vectors.
    d : float
        Feed-through.
    """
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    s = int(block_rows)
    if u.shape != y.shape or u.ndim != 1:
        raise ValueError(f"u and y must be 1-D records of one length (got {u.shape} and {y.shape})")
    if not order < s < u.size // 4:
        raise ValueError(f"block_rows must lie between order ({order}) and a quarter of the record ({u.size // 4})")
    j = u.size - 2 * s + 1
    hu = np.lib.stride_tricks.sliding_window_view(u, j)
    hy = np.lib.stride_tricks.sliding_window_view(y, j)
    M = np.vstack([hu[s:2 * s], hu[:s], hy[:s], hy[s:2 * s]]) / np.sqrt(j)
    # the LQ factor of M is the Cholesky factor of M M^T (a small ridge keeps noise-free data positive definite)
    gram = M @ M.T
    gram[np.diag_indices_from(gram)] += 1e-12 * np.trace(gram) / gram.shape[0]
    L = np.linalg.cholesky(gram)
    left, _, _ = np.linalg.svd(L[3 * s:4 * s, s:3 * s])
    G = left[:, :order]
    A = np.linalg.pinv(G[:-1]) @ G[1:]
    c = G[0].copy()
    # y[k] = c A^k x0 + sum_{i<k} c A^(k-1-i) b u[i] + d u[k]: linear in (x0, b, d)
    n, N = order, u.size
    X0 = np.empty((N, n))  # c A^k
    XB = np.zeros((N, n))  # response to each component of b
    row = c.copy()
    state = np.zeros((n, n))  # column m: state driven by e_m
    for k in range(N):
        X0[k] = row
        XB[k] = c @ state
        state = A @ state + np.eye(n) * u[k]
        row = row @ A
    theta = np.linalg.lstsq(np.hstack([X0, XB, u[:, None]]), y, rcond=None)[0]
    return A, theta[n:2 * n], c, float(theta[-1])


def discrete_modes(A: np.ndarray, b: np.ndarray, c: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Continuous-time poles (1/s) and residues ``(c v_i)(w_i b)`` of a discrete-time model's modes."""
    z, V = np.linalg.eig(A)
    W = np.linalg.inv(V)
    return np.log(z.astype(complex)) * float(fs), (c @ V) * (W @ b)


def subspace_poles(u: np.ndarray, y: np.ndarray, order: int, block_rows: int, fs: float) -> np.ndarray:
    """Continuous-time poles (1/s) of :func:`subspace_model` (``ln(z) fs``)."""
    A, _, _, _ = subspace_model(u, y, order, block_rows)
    return np.log(np.linalg.eigvals(A).astype(complex)) * float(fs)


def oscillatory(poles: np.ndarray, amplitudes: np.ndarray | None = None, count: int | None = None,
                f_min: float = 1e3, f_max: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and damping ratios of decaying oscillatory poles between ``f_min`` and ``f_max``.

    With ``amplitudes`` and ``count``, only the ``count`` strongest are kept (without
    amplitudes: the ``count`` least damped). Returned in frequency order.
    """
    p = np.asarray(poles, complex)
    with np.errstate(divide="ignore"):
        a = 1.0 / np.maximum(-p.real / np.maximum(np.abs(p), 1e-300), 1e-300) if amplitudes is None \
            else np.abs(np.asarray(amplitudes))
    fp = p.imag / (2 * np.pi)
    keep = (p.imag > 0) & (fp > f_min) & (fp < f_max) & (p.real < 0)
    p, a = p[keep], a[keep]
    if count is not None:
        strongest = np.argsort(a)[::-1][:count]
        p = p[strongest]
    f = p.imag / (2 * np.pi)
    order = np.argsort(f)
    return f[order], (-p.real / np.abs(p))[order]


class ModalGuide(ap.Approach):
    """Mismatch between the target's measured modes and the estimate's (the first stage's cost).

    Parameters
    ----------
    params : ParameterSet
    engine : PrisEngine
        The estimate's arrangement (its state matrix gives the modes).
    f_target, zeta_target : numpy.ndarray
        Modes read off the target (:func:`matrix_pencil`, :func:`oscillatory`).
    damping_weight : float
        Weight of the log damping-ratio errors against the log frequency errors.
    residue_target : numpy.ndarray, optional
        ``|residue|`` of each target mode in the discrete-time (zero-order hold at
        ``fs``) transfer function from the bridge voltage to ``v_in``
        (:func:`subspace_model`, :func:`discrete_modes`).
    residue_weight : float
        Weight of the log residue-magnitude errors.
    fs : float, Hz
        Sampling rate of the residues.

    Residuals: per target mode, ``ln(f_t / f_e)`` to the nearest estimate mode,
    ``damping_weight * ln(zeta_e / zeta_t)`` and (with residues)
    ``residue_weight * ln(|r_e| / |r_t|)``; cost: their sum of squares.
    """

    name = "modal"
    engine = "eigenvalues"

    def __init__(self, params: ParameterSet, engine: ap.PrisEngine, f_target: np.ndarray, zeta_target: np.ndarray,
                 damping_weight: float = 0.1, residue_target: np.ndarray | None = None, residue_weight: float = 0.0,
                 fs: float | None = None):
        super().__init__(params)
        self.sim = engine
        self.f_t = np.asarray(f_target, float)
        self.z_t = np.asarray(zeta_target, float)
        self.w = float(damping_weight)
        self.r_t = None if residue_target is None else np.abs(np.asarray(residue_target, float))
        self.w_r = float(residue_weight)
        self.fs = fs
        if self.r_t is not None and (fs is None or self.r_t.shape != self.f_t.shape):
            raise ValueError("residue_target needs fs and one residue per target mode")

    def _state_space(self, ev: Any) -> tuple[Any, np.ndarray, int]:
        values = self.sim.circuit.resolve(ev.overrides, check=False)
        P = int(np.atleast_2d(ev.unit).shape[0])
        values = {k: np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) else v for k, v in values.items()}
        ss = self.sim.mna.state_space(values)
        A = np.broadcast_to(np.asarray(ss.A, float), (P,) + np.shape(ss.A)[-2:])
        ok = np.all(np.isfinite(A.reshape(P, -1)), axis=1)
        return ss, ok, P

    def _poles(self, ev: Any) -> tuple[np.ndarray, np.ndarray]:
        ss, ok, P = self._state_space(ev)
        A = np.broadcast_to(np.asarray(ss.A, float), (P,) + np.shape(ss.A)[-2:])
        lam = np.linalg.eigvals(np.where(ok[:, None, None], A, 0.0))
        return lam, ok

    def _poles_residues(self, ev: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Poles and ``|residues|`` of the zero-order-hold transfer function from the bridge voltage to ``v_in``."""
        ss, ok, P = self._state_space(ev)
        n = np.shape(ss.A)[-1]
        A = np.where(ok[:, None, None], np.broadcast_to(np.asarray(ss.A, float), (P, n, n)), -np.eye(n))
        b = np.broadcast_to(np.asarray(ss.B, float), (P,) + np.shape(ss.B)[-2:])[:, :, 0]
        row = self.sim.mna.outputs.index(f"v({self.sim.port})")
        c = np.broadcast_to(np.asarray(ss.C, float), (P,) + np.shape(ss.C)[-2:])[:, row, :]
        lam, V = np.linalg.eig(A)
        Winv = np.linalg.inv(V)
        cv = np.einsum("pn,pnm->pm", c.astype(complex), V)
        wb = np.einsum("pmn,pn->pm", Winv, b.astype(complex))
        h = 1.0 / float(self.fs)  # type: ignore[arg-type]
        with np.errstate(divide="ignore", invalid="ignore"):
            zoh = np.where(np.abs(lam) > 0, np.expm1(lam * h) / lam, h)
        return lam, np.abs(cv * wb * zoh), ok

    def _residuals(self, ev: Any) -> np.ndarray:
        if self.r_t is not None:
            lam, res, ok = self._poles_residues(ev)
        else:
            lam, ok = self._poles(ev)
        fm = np.where(lam.imag > 0, np.abs(lam.imag) / (2 * np.pi), 1e-3)
        zm = -lam.real / np.maximum(np.abs(lam), 1e-300)
        d = np.log(self.f_t[None, :, None] / np.maximum(fm[:, None, :], 1e-3))
        j = np.argmin(np.abs(d), axis=2)[..., None]
        df = np.take_along_axis(d, j, 2)[..., 0]
        zz = np.take_along_axis(np.broadcast_to(zm[:, None, :], d.shape), j, 2)[..., 0]
        dz = self.w * np.log(np.maximum(zz, 1e-12) / np.maximum(self.z_t[None], 1e-12))
        parts = [df, dz]
        if self.r_t is not None:
            rr = np.take_along_axis(np.broadcast_to(res[:, None, :], d.shape), j, 2)[..., 0]
            parts.append(self.w_r * np.log(np.maximum(rr, 1e-300) / np.maximum(self.r_t[None], 1e-300)))
        r = np.concatenate(parts, axis=1)
        return np.where(ok[:, None] & np.isfinite(r), r, 10.0)

    def _costs(self, ev: Any) -> np.ndarray:
        return np.sum(self._residuals(ev) ** 2, axis=1)


def response_peaks(f: np.ndarray, h: np.ndarray, prominence: float = 0.3, count: int | None = None,
                   noise_factor: float = 0.0, noise_window: int = 201) -> np.ndarray:
    """Frequencies (Hz) of the resonance peaks of ``|h|`` on a fine grid (parabolic refinement in log-magnitude).

    Parameters
    ----------
    f : numpy.ndarray, Hz
        ``(F,)`` uniformly spaced frequencies (e.g. every Welch bin in a band).
    h : numpy.ndarray
        ``(F,)`` complex response.
    prominence : float, decades
        Smallest prominence of a peak of ``log10 |h|``.
    count : int, optional
        Keep only the ``count`` most prominent peaks.
    noise_factor : float
        A peak's prominence must also reach ``noise_factor`` times the local noise
        of ``log10 |h|`` (robust spread of its second differences over
        ``noise_window`` bins, :func:`local_noise`): under measurement noise the
        noise-dominated bins form peaks of their own.
    noise_window : int
    """
    from scipy.signal import find_peaks

    m = np.log10(np.maximum(np.abs(np.asarray(h)), 1e-300))
    f = np.asarray(f, float)
    k, props = find_peaks(m, prominence=prominence)
    if noise_factor > 0 and k.size:
        ok = props["prominences"] >= noise_factor * local_noise(m, noise_window)[k]
        k, props = k[ok], {"prominences": props["prominences"][ok]}
    if count is not None and k.size > count:
        k = np.sort(k[np.argsort(props["prominences"])[::-1][:count]])
    k = k[(k > 0) & (k < m.size - 1)]
    a, b, c = m[k - 1], m[k], m[k + 1]
    den = a - 2 * b + c
    shift = np.where(den != 0, 0.5 * (a - c) / np.where(den != 0, den, 1.0), 0.0)
    return f[k] + np.clip(shift, -0.5, 0.5) * (f[1] - f[0])


def local_noise(m: np.ndarray, window: int = 201, lag: int = 4) -> np.ndarray:
    """Local noise standard deviation of a sequence (e.g. ``log10 |H|`` on consecutive bins).

    ``1.4826 median |m_k - (m_(k-g) + m_(k+g)) / 2| / sqrt(1.5)`` over a sliding
    window of ``window`` samples, ``g = lag``: the second differences cancel a
    smooth response and leave the scatter (exact for independent samples; the
    lag skips the correlation of neighbouring bins of a windowed Welch estimate).
    """
    from scipy.ndimage import median_filter

    m = np.asarray(m, float)
    g = int(lag)
    d = np.zeros_like(m)
    if m.size > 2 * g:
        d[g:-g] = np.abs(m[g:-g] - 0.5 * (m[:-2 * g] + m[2 * g:]))
        d[:g], d[-g:] = d[g], d[-g - 1]
    return 1.4826 * median_filter(d, size=int(window), mode="nearest") / np.sqrt(1.5)


class _SumOfSquares(ap.Approach):
    """An approach whose cost is the sum of squares of its ``_residuals`` (non-finite ones count as 10)."""

    def _costs(self, ev: Any) -> np.ndarray:
        r = self._residuals(ev)
        return np.sum(np.where(np.isfinite(r), r, 10.0) ** 2, axis=1)


class ResonanceProxy(_SumOfSquares):
    """First-stage cost of the frequency path: analytic log-magnitude residuals plus resonance-frequency residuals.

    Parameters
    ----------
    proxy : Approach
        The estimate's analytic response against the target (its residuals are log-magnitude errors).
    guide : ModalGuide
        Target resonance frequencies against the estimate's open-port modes (eigenvalues of the
        current-driven winding: the poles of its input impedance).
    weight : float
        Weight of the log-frequency residuals.
    """

    name = "resonance-proxy"
    engine = "analytic+eigenvalues"

    def __init__(self, proxy: ap.Approach, guide: ModalGuide, weight: float = 100.0):
        super().__init__(proxy.params)
        self.proxy, self.guide, self.weight = proxy, guide, float(weight)

    def _residuals(self, ev: Any) -> np.ndarray:
        r_m = self.guide._residuals(ev)[:, : self.guide.f_t.size]
        return np.concatenate([self.proxy._residuals(ev), self.weight * r_m], axis=1)


class ModeConstrained(_SumOfSquares):
    """An approach's residuals with the modal frequency residuals appended (a soft constraint on the modes).

    Least squares on these stays near the measured mode frequencies while the
    rest of the response (amplitudes, damping, slow modes) is fitted: the
    time-domain cost alone, started on the modal manifold, can slide to a
    neighbouring minimum where a mode has moved by several percent.

    Parameters
    ----------
    own : Approach
        Approach with ``_residuals`` (e.g. the terminal-voltage residuals, V).
    guide : ModalGuide
    scale : float
        The own residuals are divided by this (e.g. ``sqrt(N)`` times the expected RMS).
    weight : float
        Weight of the log-frequency residuals.
    """

    name = "mode-constrained"
    engine = "own+eigenvalues"

    def __init__(self, own: ap.Approach, guide: ModalGuide, scale: float, weight: float):
        super().__init__(own.params)
        self.own, self.guide, self.scale, self.weight = own, guide, float(scale), float(weight)

    def _residuals(self, ev: Any) -> np.ndarray:
        r_f = self.guide._residuals(ev)[:, : self.guide.f_t.size]
        return np.concatenate([self.own._residuals(ev) / self.scale, self.weight * r_f], axis=1)


class Weighted(_SumOfSquares):
    """An approach's residuals multiplied by fixed weights (weighted least squares).

    Parameters
    ----------
    inner : Approach
        Approach with ``_residuals`` of shape ``(P, F)``.
    weights : numpy.ndarray
        ``(F,)`` weights (e.g. the inverse noise standard deviation of each bin).
    """

    name = "weighted"
    engine = "weighted"

    def __init__(self, inner: ap.Approach, weights: np.ndarray):
        super().__init__(inner.params)
        self.inner = inner
        self.weights = np.asarray(weights, float)

    def _residuals(self, ev: Any) -> np.ndarray:
        return self.inner._residuals(ev) * self.weights


class Shifted(_SumOfSquares):
    """An approach's residuals plus a fixed offset (the output space-mapping correction of a proxy).

    A cheap proxy (the analytic ``Zin``) and the fine model it stands for (the
    simulated Welch estimate) differ by a smooth, slowly varying term: the
    window's smoothing of the resonances. Adding the difference measured at
    one point, ``r_fine(x_c) - r_proxy(x_c)``, makes the proxy agree with the
    fine model there and close to it nearby (Bandler et al., "Space mapping:
    the state of the art", IEEE Trans. MTT 52(1), 2004).

    Parameters
    ----------
    inner : Approach
        Approach with ``_residuals`` of shape ``(P, F)``.
    offset : numpy.ndarray
        ``(F,)`` added to every row of the residuals.
    """

    name = "shifted"
    engine = "shifted"

    def __init__(self, inner: ap.Approach, offset: np.ndarray):
        super().__init__(inner.params)
        self.inner = inner
        self.offset = np.asarray(offset, float)

    def _residuals(self, ev: Any) -> np.ndarray:
        return self.inner._residuals(ev) + self.offset[None, :]


class Box:
    """A box ``[x0 - h, x0 + h]`` (clipped to the unit cube) mapped onto the unit cube, for a local refinement.

    Parameters
    ----------
    x0 : numpy.ndarray
        ``(n,)`` centre in the unit cube.
    half_width : float
        ``h`` in unit-cube units.
    """

    def __init__(self, x0: np.ndarray, half_width: float):
        x0 = np.asarray(x0, float)
        self.lo = np.clip(x0 - half_width, 0.0, 1.0)
        self.hi = np.clip(x0 + half_width, 0.0, 1.0)
        self.span = np.maximum(self.hi - self.lo, 1e-12)

    def to_outer(self, U: np.ndarray) -> np.ndarray:
        """Inner unit-cube points to the outer unit cube."""
        return self.lo + np.clip(np.atleast_2d(U), 0.0, 1.0) * self.span

    def to_inner(self, x: np.ndarray) -> np.ndarray:
        return np.clip((np.asarray(x, float) - self.lo) / self.span, 0.0, 1.0)
