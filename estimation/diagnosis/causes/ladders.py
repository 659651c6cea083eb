"""Passive R-C networks that follow an admittance over a band (the R-L ladders live in :mod:`pris_cosim.circuits.freqdep`)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from pris_cosim.circuits.freqdep import relative_nnls


def fit_admittance_rc(y_of_f: Callable[[np.ndarray], np.ndarray], fmin: float, fmax: float,
                      n_branches: int = 10) -> list[tuple[float, float]]:
    """Parallel branches ``(R_k, C_k)`` (series R-C; ``R = 0`` a plain capacitor) whose admittance follows ``y_of_f``.

    Each branch ``G_k (s/w_k) / (1 + s/w_k)`` has its corner ``w_k`` fixed on a
    log grid around the band, so real and imaginary parts are linear in
    ``G_k``; non-negative least squares relative to ``|Y|`` keeps every
    element positive (the network is passive by construction).

    Parameters
    ----------
    y_of_f : callable
        Target admittance (S, complex, non-negative real part) against frequency (Hz).
    fmin, fmax : float, Hz
    n_branches : int

    Returns
    -------
    list of (float, float)
        ``(R, C)`` in Ohm and F.
    """
    f = np.logspace(np.log10(fmin), np.log10(fmax), 200)
    target = np.asarray(y_of_f(f), complex)
    wk = 2 * np.pi * np.logspace(np.log10(fmin) - 0.5, np.log10(fmax) + 0.5, n_branches)
    s = 2j * np.pi * f[:, None]
    basis = np.column_stack([s[:, 0], (s / wk) / (1 + s / wk)])
    coef = relative_nnls(basis, target)
    out = []
    if coef[0] > 0:
        out.append((0.0, float(coef[0])))
    for g, w in zip(coef[1:], wk):
        if g > 1e-12 * max(coef[1:].max(initial=0.0), 1e-300):
            out.append((float(1 / g), float(g / w)))
    return out
