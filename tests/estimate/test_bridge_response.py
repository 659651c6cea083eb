"""The sampled (zero-order hold) responses and modes of the bridge-driven stand-in, and the batched least squares.

References are independent of the code under test: ``scipy.signal.cont2discrete`` (zero-order hold)
and ``scipy.signal.dlsim`` for the sampled systems, closed forms for the folded mode frequencies and
for the least-squares minimum.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from estimation.bridge_response import (discrete_response, match_modes, model_modes, record_model,
    zoh_frequency_response, zoh_modes)
from estimation.search.local_search import batched_least_squares


def _series_rlc(r: float, l: float, c: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source voltage -> capacitor voltage of a series R-L-C (states: i_L, v_C)."""
    a = np.array([[-r / l, -1.0 / l], [1.0 / c, 0.0]])
    return a, np.array([1.0 / l, 0.0]), np.array([0.0, 1.0])


def test_zoh_response_matches_scipy_cont2discrete():
    # a resonance at 700 kHz sampled at 1 MHz: above the Nyquist frequency
    l, c = 1e-4, 1.0 / ((2 * np.pi * 7e5) ** 2 * 1e-4)
    a, b, cc = _series_rlc(5.0, l, c)
    fs = 1e6
    ad, bd, cd, dd, _ = signal.cont2discrete((a, b[:, None], cc[None], np.zeros((1, 1))), 1 / fs, method="zoh")
    f = np.linspace(1e3, 4.9e5, 50)
    z = np.exp(2j * np.pi * f / fs)
    ref = np.array([(cd @ np.linalg.solve(zi * np.eye(2) - ad, bd))[0, 0] + dd[0, 0] for zi in z])
    got = zoh_frequency_response(a[None], b[None], cc[None, None], np.zeros((1, 1)), fs, f)[0, 0]
    assert np.max(np.abs(got / ref - 1)) < 1e-9


def test_zoh_modes_fold_above_nyquist_and_keep_the_decay():
    sigma, f0, fs = 2e3, 8.86e5, 1e6
    a = np.array([[-sigma, -2 * np.pi * f0], [2 * np.pi * f0, -sigma]])
    f, s, r = zoh_modes(a[None], np.array([[1.0, 0.0]]), np.array([[0.0, 1.0]]), fs)
    assert np.allclose(np.sort(f[0]), [fs - f0, fs - f0], rtol=1e-9)
    assert np.allclose(s[0], sigma, rtol=1e-9)
    assert np.all(r[0] > 0)


def test_subspace_model_of_a_sampled_record_gives_its_response_and_modes():
    """A record made by scipy's dlsim from a held input; the identified map reproduces the generating one."""
    l, c = 1e-4, 1.0 / ((2 * np.pi * 7e5) ** 2 * 1e-4)
    a, b, cc = _series_rlc(5.0, l, c)
    fs = 1e6
    sysd = signal.cont2discrete((a, b[:, None], cc[None], np.zeros((1, 1))), 1 / fs, method="zoh")
    rng = np.random.default_rng(1)
    u = np.repeat(np.where(rng.random(400) > 0.5, 1.0, -1.0), 10)
    _, y, _ = signal.dlsim(sysd[:4] + (1 / fs,), u)
    m = record_model(u, y[:, 0], order=2, block_rows=40)
    assert m is not None
    f = np.linspace(1e4, 4.5e5, 30)
    z = np.exp(2j * np.pi * f / fs)
    ref = np.array([(sysd[2] @ np.linalg.solve(zi * np.eye(2) - sysd[0], sysd[1]))[0, 0] for zi in z])
    assert np.max(np.abs(discrete_response(*m, fs, f) / ref - 1)) < 1e-6
    fm, sm, _ = model_modes(m[0], m[1], m[2], fs, count=1, band=(1e3, fs / 2))
    lam = np.linalg.eigvals(a)
    assert abs(fm[0] - (fs - lam.imag.max() / (2 * np.pi))) < 1e-6 * fs
    assert abs(sm[0] / -lam.real[0] - 1) < 1e-6


def test_modes_are_matched_one_to_one():
    # two target modes close together and one estimate mode between them: nearest matching would use it twice
    f_t = np.array([1.0e5, 1.1e5, 2.8e5])
    f_e = np.array([[1.05e5, 1.05e5, 2.0e5, 2.0e5, 2.7e5, 2.7e5, 0.0, 0.0]])
    j = match_modes(f_t, f_e)[0]
    assert len(set(f_e[0, j])) == 3
    assert f_e[0, j[2]] == 2.7e5


def test_batched_least_squares_reaches_the_minimum_from_many_starts():
    """Rosenbrock residuals on the unit cube mapped to [-2, 2]^2: minimum at (1, 1), i.e. u = (0.75, 0.75)."""
    def residuals(U):
        x, y = 4 * U[:, 0] - 2, 4 * U[:, 1] - 2
        return np.stack([10 * (y - x ** 2), 1 - x], axis=1)

    X0 = np.random.default_rng(0).random((20, 2))
    X, cost, nfev = batched_least_squares(residuals, X0, iterations=100)
    assert nfev == 20 * (1 + 100 * 3)
    assert np.all(cost < 1e-12)
    assert np.allclose(X, 0.75, atol=1e-6)


def test_batched_least_squares_stays_on_a_face_it_is_pushed_against():
    """Minimum outside the cube (u = 1.2 in the first value): the end lies on the face, the other value free."""
    def residuals(U):
        return np.stack([U[:, 0] - 1.2, 3 * (U[:, 1] - 0.3)], axis=1)

    X, _, _ = batched_least_squares(residuals, np.array([[0.2, 0.9], [0.99, 0.1]]), iterations=50)
    assert np.allclose(X, [[1.0, 0.3], [1.0, 0.3]], atol=1e-8)
