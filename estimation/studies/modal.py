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

from .. import approaches as ap
from ..parameters import ParameterSet


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


def oscillatory(poles: np.ndarray, amplitudes: np.ndarray | None = None, count: int | None = None,
                f_min: float = 1e3) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies (Hz) and damping ratios of decaying oscillatory poles above ``f_min``.

    With ``amplitudes`` and ``count``, only the ``count`` strongest are kept. Returned in frequency order.
    """
    p = np.asarray(poles, complex)
    a = np.ones(p.size) if amplitudes is None else np.abs(np.asarray(amplitudes))
    keep = (p.imag > 0) & (p.imag / (2 * np.pi) > f_min) & (p.real < 0)
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

    Residuals: per target mode, ``ln(f_t / f_e)`` to the nearest estimate mode
    and ``damping_weight * ln(zeta_e / zeta_t)``; cost: their sum of squares.
    """

    name = "modal"
    engine = "eigenvalues"

    def __init__(self, params: ParameterSet, engine: ap.PrisEngine, f_target: np.ndarray, zeta_target: np.ndarray,
                 damping_weight: float = 0.1):
        super().__init__(params)
        self.sim = engine
        self.f_t = np.asarray(f_target, float)
        self.z_t = np.asarray(zeta_target, float)
        self.w = float(damping_weight)

    def _poles(self, ev: Any) -> tuple[np.ndarray, np.ndarray]:
        values = self.sim.circuit.resolve(ev.overrides, check=False)
        P = int(np.atleast_2d(ev.unit).shape[0])
        values = {k: np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) else v for k, v in values.items()}
        A = np.asarray(self.sim.mna.state_space(values).A, float)
        A = np.broadcast_to(A, (P,) + A.shape[-2:])
        ok = np.all(np.isfinite(A.reshape(P, -1)), axis=1)
        lam = np.linalg.eigvals(np.where(ok[:, None, None], A, 0.0))
        return lam, ok

    def _residuals(self, ev: Any) -> np.ndarray:
        lam, ok = self._poles(ev)
        fm = np.where(lam.imag > 0, np.abs(lam.imag) / (2 * np.pi), 1e-3)
        zm = -lam.real / np.maximum(np.abs(lam), 1e-300)
        d = np.log(self.f_t[None, :, None] / np.maximum(fm[:, None, :], 1e-3))
        j = np.argmin(np.abs(d), axis=2)[..., None]
        df = np.take_along_axis(d, j, 2)[..., 0]
        zz = np.take_along_axis(np.broadcast_to(zm[:, None, :], d.shape), j, 2)[..., 0]
        dz = self.w * np.log(np.maximum(zz, 1e-12) / np.maximum(self.z_t[None], 1e-12))
        r = np.concatenate([df, dz], axis=1)
        return np.where(ok[:, None] & np.isfinite(r), r, 10.0)

    def _costs(self, ev: Any) -> np.ndarray:
        return np.sum(self._residuals(ev) ** 2, axis=1)


def response_peaks(f: np.ndarray, h: np.ndarray, prominence: float = 0.3, count: int | None = None) -> np.ndarray:
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
    """
    from scipy.signal import find_peaks

    m = np.log10(np.maximum(np.abs(np.asarray(h)), 1e-300))
    f = np.asarray(f, float)
    k, props = find_peaks(m, prominence=prominence)
    if count is not None and k.size > count:
        k = np.sort(k[np.argsort(props["prominences"])[::-1][:count]])
    k = k[(k > 0) & (k < m.size - 1)]
    a, b, c = m[k - 1], m[k], m[k + 1]
    den = a - 2 * b + c
    shift = np.where(den != 0, 0.5 * (a - c) / np.where(den != 0, den, 1.0), 0.0)
    return f[k] + np.clip(shift, -0.5, 0.5) * (f[1] - f[0])


class ResonanceProxy(ap.Approach):
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

    def _costs(self, ev: Any) -> np.ndarray:
        r = self._residuals(ev)
        return np.sum(np.where(np.isfinite(r), r, 10.0) ** 2, axis=1)
