"""Compiled inner loops of the frequency-response paths.

Two evaluations of ``H(j w) = C (j w I - A)^{-1} b + d`` over a batch of
real state-space models and a grid of angular frequencies:

- :func:`pole_residue_sum`: the pole-residue sum with real arithmetic on
  conjugate pole pairs. A pair ``p, conj(p)`` with residues ``r, conj(r)``
  contributes ``(2 j w Re r - 2 Re(r conj p)) / (|p|^2 - w^2 - 2 j w Re p)``:
  one complex division per pair and frequency instead of two, and no
  ``(P, n, F)`` temporaries.
- :func:`hessenberg_solve`: the Hessenberg method (Laub, IEEE Trans. AC 26,
  1981): with ``A = Q H Q^T`` (``H`` upper Hessenberg, ``Q`` orthogonal) the
  response is ``(C Q) (j w I - H)^{-1} (Q^T b) + d``, one ``O(n^2)``
  Hessenberg solve with partial pivoting per frequency. No eigenvectors are
  needed, so defective or nearly defective systems are handled exactly.

Both run as numba-compiled loops when numba is installed and the batch is
large enough to repay the compilation (cached on disk after the first
call); otherwise as vectorised numpy with the same arithmetic. Importing
this module does not import numba.
"""

from __future__ import annotations

import os
import warnings
from typing import Callable

import numpy as np

#: Work (sets x frequencies x states) above which the compiled loops are used.
COMPILED_MIN_WORK = 200_000

_compiled: dict[str, Callable] = {}
_numba_missing = False


def _jit(name: str) -> Callable | None:
    """The numba-compiled kernel ``name``, or ``None`` when numba is unavailable."""
    global _numba_missing
    if name in _compiled:
        return _compiled[name]
    if _numba_missing or os.environ.get("PRIS_COSIM_NO_NUMBA"):
        return None
    try:
        import numba
    except ImportError:
        _numba_missing = True
        return None
    jit = numba.njit(cache=True, fastmath=False, nogil=True)
    _compiled["pairs"] = jit(_pairs_loop)
    _compiled["hessenberg"] = jit(_hessenberg_loop)
    return _compiled[name]


def _pairs_loop(poles, residues, direct, omega, out):  # pragma: no cover - compiled
    P, ny, n = residues.shape
    F = omega.shape[0]
    for p in range(P):
        for k in range(n):
            lam = poles[p, k]
            sig = lam.real
            beta = lam.imag
            if beta < 0.0:
                continue
            if beta > 0.0:
                g = sig * sig + beta * beta
                dd = -2.0 * sig
                for o in range(ny):
                    r = residues[p, o, k]
                    a = -2.0 * (r.real * sig + r.imag * beta)
                    b = 2.0 * r.real
                    for i in range(F):
                        w = omega[i]
                        cr = g - w * w
                        ci = dd * w
                        inv = 1.0 / (cr * cr + ci * ci)
                        bw = b * w
                        out[p, o, i] += complex((a * cr + bw * ci) * inv, (bw * cr - a * ci) * inv)
            else:
                for o in range(ny):
                    r = residues[p, o, k]
                    for i in range(F):
                        w = omega[i]
                        inv = 1.0 / (sig * sig + w * w)
                        # r / (j w - sig) = r (-sig - j w) / (sig^2 + w^2)
                        out[p, o, i] += complex((-r.real * sig + r.imag * w) * inv, (-r.imag * sig - r.real * w) * inv)
        for o in range(ny):
            d = direct[p, o]
            for i in range(F):
                out[p, o, i] += d


def _hessenberg_loop(H, bt, Ct, direct, omega, out):  # pragma: no cover - compiled
    P, n, _ = H.shape
    ny = Ct.shape[1]
    F = omega.shape[0]
    Mr = np.empty((n, n))  # real and imaginary parts of j w I - H, upper Hessenberg
    Mi = np.empty((n, n))
    xr = np.empty(n)
    xi = np.empty(n)
    for p in range(P):
        for i in range(F):
            w = omega[i]
            for r in range(n):
                lo = r - 1 if r > 0 else 0
                for c in range(lo, n):
                    Mr[r, c] = -H[p, r, c]
                    Mi[r, c] = 0.0
                Mi[r, r] = w
                xr[r] = bt[p, r]
                xi[r] = 0.0
            for k in range(n - 1):  # eliminate the sub-diagonal, partial pivoting between rows k, k+1
                if Mr[k + 1, k] ** 2 + Mi[k + 1, k] ** 2 > Mr[k, k] ** 2 + Mi[k, k] ** 2:
                    for c in range(k, n):
                        t = Mr[k, c]
                        Mr[k, c] = Mr[k + 1, c]
                        Mr[k + 1, c] = t
                        t = Mi[k, c]
                        Mi[k, c] = Mi[k + 1, c]
                        Mi[k + 1, c] = t
                    t = xr[k]
                    xr[k] = xr[k + 1]
                    xr[k + 1] = t
                    t = xi[k]
                    xi[k] = xi[k + 1]
                    xi[k + 1] = t
                ar = Mr[k, k]
                ai = Mi[k, k]
                inv = 1.0 / (ar * ar + ai * ai)
                br = Mr[k + 1, k]
                bi = Mi[k + 1, k]
                mr = (br * ar + bi * ai) * inv
                mi = (bi * ar - br * ai) * inv
                for c in range(k + 1, n):
                    ur = Mr[k, c]
                    ui = Mi[k, c]
                    Mr[k + 1, c] -= mr * ur - mi * ui
                    Mi[k + 1, c] -= mr * ui + mi * ur
                ur = xr[k]
                ui = xi[k]
                xr[k + 1] -= mr * ur - mi * ui
                xi[k + 1] -= mr * ui + mi * ur
            for r in range(n - 1, -1, -1):
                accr = xr[r]
                acci = xi[r]
                for c in range(r + 1, n):
                    accr -= Mr[r, c] * xr[c] - Mi[r, c] * xi[c]
                    acci -= Mr[r, c] * xi[c] + Mi[r, c] * xr[c]
                ar = Mr[r, r]
                ai = Mi[r, r]
                inv = 1.0 / (ar * ar + ai * ai)
                xr[r] = (accr * ar + acci * ai) * inv
                xi[r] = (acci * ar - accr * ai) * inv
            for o in range(ny):
                accr = direct[p, o]
                acci = 0.0
                for c in range(n):
                    accr += Ct[p, o, c] * xr[c]
                    acci += Ct[p, o, c] * xi[c]
                out[p, o, i] = complex(accr, acci)


def pole_residue_sum(poles: np.ndarray, residues: np.ndarray, direct: np.ndarray, omega: np.ndarray,
                     compiled: bool | None = None) -> np.ndarray:
    """``sum_k r_k / (j w - p_k) + d`` of real systems, conjugate pairs in real arithmetic.

    Parameters
    ----------
    poles : numpy.ndarray
        ``(P, n)`` complex poles, rad/s, of real matrices (non-real poles in exact conjugate pairs,
        as LAPACK returns them).
    residues : numpy.ndarray
        ``(P, ny, n)`` complex residues.
    direct : numpy.ndarray
        ``(P, ny)`` real feed-through.
    omega : numpy.ndarray
        ``(F,)`` angular frequencies, rad/s.
    compiled : bool, optional
        Use the compiled loop (when numba is installed) regardless of the batch size
        (``True``), never (``False``), or above :data:`COMPILED_MIN_WORK` (default).
        Callers that evaluate many batches repay the one-off compilation at any size.

    Returns
    -------
    numpy.ndarray
        ``(P, ny, F)`` complex responses.
    """
    P = max(poles.shape[0], residues.shape[0], direct.shape[0])  # any of them may be one set, broadcast
    _, ny, n = residues.shape
    poles = np.broadcast_to(poles, (P, n))
    residues = np.broadcast_to(residues, (P, ny, n))
    direct = np.broadcast_to(direct, (P, ny))
    omega = np.ascontiguousarray(omega, float)
    big = P * n * omega.size >= COMPILED_MIN_WORK if compiled is None else bool(compiled)
    kern = _jit("pairs") if big else None
    if kern is not None:
        out = np.zeros((P, ny, omega.size), complex)
        with warnings.catch_warnings():  # numba's cache notices (e.g. a read-only install) are not the user's business
            warnings.simplefilter("ignore")
            kern(np.ascontiguousarray(poles, complex), np.ascontiguousarray(residues, complex),
                 np.ascontiguousarray(direct.real, float), omega, out)
        return out
    return pole_sum(poles, residues, direct, 1j * omega)


def pole_sum(poles: np.ndarray, residues: np.ndarray, direct: np.ndarray, s: np.ndarray,
             chunk: int = 256) -> np.ndarray:
    """``sum_k r_k / (s - p_k) + d`` at any complex frequencies ``s`` (rad/s), plain numpy over every pole.

    Shapes as :func:`pole_residue_sum` (``s`` of shape ``(F,)``); parameter sets are taken ``chunk`` at a
    time so the ``(chunk, n, F)`` temporaries stay bounded.
    """
    P, ny, _ = residues.shape
    out = np.empty((P, ny, s.size), complex)
    for p0 in range(0, P, chunk):
        inv = 1.0 / (s[None, None, :] - poles[p0 : p0 + chunk, :, None])  # (Pc, n, F)
        out[p0 : p0 + chunk] = residues[p0 : p0 + chunk] @ inv + direct[p0 : p0 + chunk, :, None]
    return out


def hessenberg_solve(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """``C (j w I - A)^{-1} B + D`` of a batch of real single-input systems by the Hessenberg method.

    Parameters
    ----------
    A : numpy.ndarray
        ``(P, n, n)`` real state matrices, 1/s.
    B : numpy.ndarray
        ``(P, n)`` real input vectors.
    C : numpy.ndarray
        ``(P, ny, n)`` real output matrices.
    D : numpy.ndarray
        ``(P, ny)`` real feed-through.
    omega : numpy.ndarray
        ``(F,)`` angular frequencies, rad/s.

    Returns
    -------
    numpy.ndarray
        ``(P, ny, F)`` complex responses.
    """
    from scipy.linalg import hessenberg, matrix_balance

    P = max(A.shape[0], B.shape[0], C.shape[0], D.shape[0])  # any of them may be one set, broadcast
    n, ny = A.shape[1], C.shape[1]
    A = np.broadcast_to(A, (P, n, n))
    B = np.broadcast_to(B, (P, n))
    C = np.broadcast_to(C, (P, ny, n))
    D = np.broadcast_to(D, (P, ny))
    omega = np.ascontiguousarray(omega, float)
    H = np.empty((P, n, n))
    bt = np.empty((P, n))
    Ct = np.empty((P, ny, n))
    for p in range(P):
        Ab, T = matrix_balance(A[p], permute=False)  # Ab = T^-1 A T, T diagonal: no loss of accuracy
        Hp, Qp = hessenberg(Ab, calc_q=True, check_finite=False)
        H[p] = Hp
        bt[p] = Qp.T @ (B[p] / np.diag(T))
        Ct[p] = (C[p] * np.diag(T)) @ Qp
    out = np.empty((P, ny, omega.size), complex)
    kern = _jit("hessenberg") if P * n * omega.size >= COMPILED_MIN_WORK else None
    if kern is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            kern(H, bt, Ct, np.ascontiguousarray(D, float), omega, out)
        return out
    eye = np.eye(n)
    for p in range(P):
        M = 1j * omega[:, None, None] * eye - H[p][None]
        x = np.linalg.solve(M, np.broadcast_to(bt[p].astype(complex), (omega.size, n))[:, :, None])[:, :, 0]
        out[p] = (x @ Ct[p].T).T + D[p][:, None]
    return out
