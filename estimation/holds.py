"""Exact discretisation of a linear network driven by a sampled input held linearly between samples.

A sampled current ``i[k] = i(k h)`` of a physical source is continuous (it
flows through the source's series inductance); replaying it as a held
(stepped) signal delays it by half a sample on average, which a capacitive
or resonant port turns into an error of several percent of the voltage
(``v = C^-1 int i dt`` sees the delay directly). Holding it linearly between
samples (first-order hold, FOH) leaves only the curvature of ``i(t)`` inside a
sample interval, an error of order ``(h f)^2`` instead of ``h f``.

For ``x' = A x + B u`` with ``u(t) = u_k + (u_{k+1} - u_k)(t - t_k)/h`` on
``[t_k, t_k + h]``, the exponential of the augmented matrix

``M = [[A h, B h, 0], [0, 0, I], [0, 0, 0]]``

gives ``expm(M) = [[Phi, Gamma0, Gamma1], [0, I, I], [0, 0, I]]`` with
``Phi = e^{A h}``, ``Gamma0 = int_0^h e^{A s} ds B`` and
``Gamma1 = int_0^h e^{A (h - s)} (s / h) ds B`` exactly, and

``x_{k+1} = Phi x_k + (Gamma0 - Gamma1) u_k + Gamma1 u_{k+1}``.

With ``z_k = x_k - Gamma1 u_k`` this is the single-input recurrence
``z_{k+1} = Phi z_k + g u_k``, ``g = Phi Gamma1 + Gamma0 - Gamma1``, and
``x_k = z_k + Gamma1 u_k``; the samples ``y_k = C x_k + D u_k`` are exact for
the piecewise-linear input.
"""

from __future__ import annotations

import numpy as np

__all__ = ["batched_expm", "batched_foh", "foh_recurrence", "decide_hold", "HOLDS", "MAX_HELD_LEVELS"]

#: Input holds of a replayed record: decided from the data, zero-order, linear.
HOLDS = ("auto", "zoh", "linear")
#: An input with at most this many distinct levels (and at most one per 8 samples) counts as held.
MAX_HELD_LEVELS = 32


_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
           10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152


def batched_expm(M: np.ndarray) -> np.ndarray:
    """Matrix exponential of a batch ``(P, n, n)``: Pade 13 with scaling and squaring (Higham 2005).

    One set of batched products and one batched solve for the whole
    population (``scipy.linalg.expm`` takes about 10 ms per 7x7 matrix of
    the PRIS arrangement here, a thousand times longer); each member gets
    its own number of squarings.
    """
    M = np.asarray(M, float)
    P, n, _ = M.shape
    norm = np.abs(M).sum(axis=1).max(axis=1) if P else np.zeros(0)
    norm = np.where(np.isfinite(norm), norm, 0.0)
    s = np.maximum(0, np.ceil(np.log2(np.maximum(norm, 1e-300) / _THETA13))).astype(int)
    A = M / (2.0 ** s)[:, None, None]
    b = _PADE13
    eye = np.broadcast_to(np.eye(n), (P, n, n))
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * eye)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * eye
    E = np.linalg.solve(V - U, V + U)
    for k in range(int(s.max(initial=0))):
        sel = s > k
        E[sel] = E[sel] @ E[sel]
    return E


def batched_foh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Phi``, ``Gamma0``, ``Gamma1`` of the first-order hold for a batch of systems.

    Parameters
    ----------
    A : numpy.ndarray
        ``(P, n, n)`` state matrices, 1/s.
    B : numpy.ndarray
        ``(P, n, m)`` input matrices.
    h : float
        Sample interval, s.

    Returns
    -------
    Phi, Gamma0, Gamma1 : numpy.ndarray
        ``(P, n, n)``, ``(P, n, m)``, ``(P, n, m)``.
    """

    A = np.asarray(A, float)
    B = np.asarray(B, float)
    P, n, _ = A.shape
    m = B.shape[2]
    M = np.zeros((P, n + 2 * m, n + 2 * m))
    M[:, :n, :n] = A * h
    M[:, :n, n:n + m] = B * h
    M[:, n:n + m, n + m:] = np.eye(m)
    E = batched_expm(M)
    return E[:, :n, :n], E[:, :n, n:n + m], E[:, :n, n + m:]


def foh_recurrence(Phi: np.ndarray, Gamma0: np.ndarray, Gamma1: np.ndarray) -> np.ndarray:
    """Input vector ``g = Phi Gamma1 + Gamma0 - Gamma1`` of the shifted single-input recurrence.

    Parameters
    ----------
    Phi : numpy.ndarray
        ``(P, n, n)``.
    Gamma0, Gamma1 : numpy.ndarray
        ``(P, n)`` (one input).

    Returns
    -------
    numpy.ndarray
        ``(P, n)``.
    """
    return np.einsum("pij,pj->pi", Phi, Gamma1) + Gamma0 - Gamma1


def decide_hold(u: np.ndarray, name: str = "input") -> tuple[str, str]:
    """The hold under which a sampled input explains its record: ``("zoh" | "linear", reason)``.

    A signal that a DAC or a digital source makes (a PRBS, a step, a few
    held levels) takes few distinct values and changes only at sample
    instants: replaying it linearly would smear every edge over a sample, so
    it is held (zero-order hold). A continuous signal (a measured current, a
    sine) takes as many values as samples and is held linearly.

    Parameters
    ----------
    u : numpy.ndarray
        ``(n,)`` input samples (any unit).
    name : str
        The input's name, for the reason.

    Returns
    -------
    hold : str
        ``"zoh"`` when ``u`` has at most :data:`MAX_HELD_LEVELS` distinct levels and at most one
        level per 8 samples; ``"linear"`` otherwise.
    reason : str
        One sentence giving the counts the choice rests on.
    """
    u = np.asarray(u, float).ravel()
    n = u.size
    span = float(np.ptp(u)) if n else 0.0
    # levels equal to 1e-9 of the span count as one (a record printed with 12 digits)
    q = np.round((u - u.min()) / span * 1e9) if span > 0 else np.zeros(n)
    levels = int(np.unique(q).size)
    changes = int(np.count_nonzero(np.diff(q)))
    if levels <= MAX_HELD_LEVELS and levels * 8 <= n:
        return "zoh", (f"{name} takes {levels} distinct level{'s' if levels != 1 else ''} over {n} samples and "
                       f"changes {changes} times, only at sample instants: a held (DAC-driven) input, "
                       "replayed with a zero-order hold")
    return "linear", (f"{name} takes {levels} distinct values over {n} samples: a continuous input, "
                      "replayed varying linearly between samples")
