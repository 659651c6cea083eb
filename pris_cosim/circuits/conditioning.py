"""How well the frequency-domain solve is conditioned: refuse what double precision cannot resolve.

Element values inside their accepted ranges (:data:`pris_cosim.units.ELEMENT_RANGES`)
can still combine into a system the arithmetic cannot resolve: a 1 nOhm
resistor in series with a 1 mH inductor across 1 nF puts a conductance of
1e9 S beside admittances of 1e-3 S, and the nodal solve cancels the 1e18
terms, losing the winding's damping entirely (the real part of Zin comes
out wrong by a factor of 1e7 while the imaginary part looks fine).

:func:`check_response_set` estimates, at the requested frequencies, the
condition number of the modified-nodal matrix ``K(s) = K0 + s K1`` (node
voltages and inductor currents) after row and column equilibration, which
removes the harmless disparity of units; ``eps * cond`` bounds the relative
error of the solution. Above :data:`MAX_RELATIVE_ERROR` the command refuses
with one line naming the element whose admittance dominates at the worst
frequency.
"""

from __future__ import annotations

import numpy as np

from pris_cosim.errors import CircuitError
from pris_cosim.units import ELEMENT_UNITS

#: Largest accepted estimate of the relative error of a frequency response.
MAX_RELATIVE_ERROR = 1e-5
#: Frequencies checked at most (log-spaced picks of the requested ones).
MAX_POINTS = 64


def _equilibrated_cond(K: np.ndarray) -> np.ndarray:
    """Condition numbers of ``(..., n, n)`` matrices after row then column scaling to unit max."""
    A = np.abs(K)
    r = A.max(axis=-1, keepdims=True)
    r = np.where(r > 0, r, 1.0)
    K1 = K / r
    c = np.abs(K1).max(axis=-2, keepdims=True)
    c = np.where(c > 0, c, 1.0)
    with np.errstate(all="ignore"):
        return np.linalg.cond(K1 / c)


def nodal_condition(mna, values, s: np.ndarray) -> np.ndarray:
    """``(P, F)`` equilibrated condition numbers of the modified-nodal matrix at ``s`` (rad/s)."""
    G, Cn, L = mna.matrices(values)
    P, N, m = G.shape[0], len(mna.nodes), L.shape[1]
    n = N + m
    static = np.zeros((P, n, n))
    static[:, :N, :N] = np.real(G)
    static[:, :N, N:] = mna.AL
    static[:, N:, :N] = -mna.AL.T
    dyn = np.zeros((P, n, n))
    dyn[:, :N, :N] = np.real(Cn)
    dyn[:, N:, N:] = L
    K = static[:, None] + s[None, :, None, None] * dyn[:, None]
    return _equilibrated_cond(K)


def _dominant_element(circuit, values, s: complex) -> tuple[str, str]:
    """Name and value text of the element with the largest admittance magnitude at ``s``."""
    best, text, top = "", "", -1.0
    for e in circuit.elements:
        if e.kind not in "RLC":
            continue
        v = float(np.real(np.ravel(values[e.key])[0]))
        y = abs(1 / v) if e.kind == "R" else abs(s * v) if e.kind == "C" else abs(1 / (s * v))
        if y > top:
            best, text, top = e.name, f"{v:g} {ELEMENT_UNITS[e.kind]}", y
    return best, text


def check_response_set(response_set, frequency_hz: np.ndarray, overrides=None) -> float:
    """Refuse (CircuitError, one line) when the responses cannot be computed to ``MAX_RELATIVE_ERROR``.

    Parameters
    ----------
    response_set : ResponseSet
        Compiled responses (every configuration is checked).
    frequency_hz : numpy.ndarray, Hz
    overrides : mapping, optional
        Parameter or element values.

    Returns
    -------
    float
        The largest estimated relative error (``eps * cond``) found.
    """
    f = np.asarray(frequency_hz, float).ravel()
    if f.size > MAX_POINTS:
        f = f[np.unique(np.round(np.linspace(0, f.size - 1, MAX_POINTS)).astype(int))]
    s = 2j * np.pi * f
    worst = 0.0
    eps = np.finfo(float).eps
    for m in response_set.models:
        values = m.circuit.resolve(overrides, check=False)
        if any(np.iscomplexobj(np.asarray(v)) for v in values.values()) or not hasattr(m.mna, "matrices"):
            continue  # complex (frequency-dependent) values, or a large circuit solved by sparse LU
        cond = nodal_condition(m.mna, values, s)
        err = eps * np.where(np.isfinite(cond), cond, np.inf)
        k = int(np.argmax(err.max(axis=0)))
        e = float(err.max())
        worst = max(worst, e)
        if not e <= MAX_RELATIVE_ERROR:
            name, text = _dominant_element(m.circuit, values, s[k])
            raise CircuitError(
                f"element {name!r} ({text}): the element values span a range double precision cannot resolve "
                f"(estimated relative error {e:.1e} at {f[k]:.6g} Hz); scale the circuit or change that value")
    return worst


__all__ = ["check_response_set", "nodal_condition", "MAX_RELATIVE_ERROR"]
