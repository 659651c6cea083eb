"""The compiled frequency-response loops against a plain complex solve of ``(j w I - A) x = b``."""

from __future__ import annotations

import numpy as np
import pytest

from pris_cosim.frf import kernels as K


def _random_stable(rng: np.random.Generator, P: int, n: int) -> tuple[np.ndarray, ...]:
    """Real stable systems with spread time constants (1e2 .. 1e7 rad/s), some complex pole pairs."""
    A = np.empty((P, n, n))
    for p in range(P):
        M = rng.standard_normal((n, n))
        S = np.diag(10.0 ** rng.uniform(2, 7, n))
        A[p] = (M - M.T) @ S * 0.5 - S  # skew (oscillation) plus damping, badly scaled columns
    B = rng.standard_normal((P, n))
    C = rng.standard_normal((P, 2, n))
    D = rng.standard_normal((P, 2))
    return A, B, C, D


def _direct(A, B, C, D, omega):
    n = A.shape[1]
    M = 1j * omega[None, :, None, None] * np.eye(n) - A[:, None]
    x = np.linalg.solve(M, np.broadcast_to(B[:, None, :, None], M.shape[:3] + (1,)).astype(complex))[..., 0]
    return np.einsum("pon,pfn->pof", C, x) + D[:, :, None]


@pytest.mark.parametrize("compiled", [False, True])
def test_kernels_equal_a_direct_solve(compiled, monkeypatch):
    rng = np.random.default_rng(3)
    A, B, C, D = _random_stable(rng, 40, 9)
    omega = 2 * np.pi * np.logspace(0, 7, 300)
    ref = _direct(A, B, C, D, omega)
    monkeypatch.setattr(K, "COMPILED_MIN_WORK", 0 if compiled else 10**12)
    lam, V = np.linalg.eig(A)
    w = np.linalg.solve(V, B[:, :, None].astype(complex))[:, :, 0]
    res = (C @ V) * w[:, None, :]
    pr = K.pole_residue_sum(lam, res, D, omega)
    hs = K.hessenberg_solve(A, B, C, D, omega)
    scale = np.abs(ref) + 1e-300
    assert np.max(np.abs(pr - ref) / scale) < 1e-8
    assert np.max(np.abs(hs - ref) / scale) < 1e-8


@pytest.mark.parametrize("compiled", [False, True])
def test_hessenberg_solve_handles_a_defective_matrix(compiled, monkeypatch):
    """A Jordan block (repeated pole, one eigenvector): the pole-residue form fails, the direct solve does not."""
    monkeypatch.setattr(K, "COMPILED_MIN_WORK", 0 if compiled else 10**12)
    a = 1e3
    A = np.array([[[-a, 1.0, 0.0], [0.0, -a, 1.0], [0.0, 0.0, -a]]])
    B = np.array([[0.0, 0.0, 1.0]])
    C = np.array([[[1.0, 0.0, 0.0]]])
    D = np.zeros((1, 1))
    omega = np.logspace(0, 6, 50)
    exact = 1.0 / (1j * omega + a) ** 3  # closed form of the triple pole
    got = K.hessenberg_solve(A, B, C, D, omega)[0, 0]
    assert np.max(np.abs(got - exact) / np.abs(exact)) < 1e-10


@pytest.mark.parametrize("compiled", [False, True])
def test_a_single_set_broadcasts_against_a_population(compiled, monkeypatch):
    """A feed-through (or any input) given for one set serves every set of the population, never read past its end."""
    monkeypatch.setattr(K, "COMPILED_MIN_WORK", 0 if compiled else 10**12)
    A, B, C, D = _random_stable(np.random.default_rng(5), 6, 5)
    omega = np.logspace(1, 6, 40)
    lam, V = np.linalg.eig(A)
    res = (C @ V) * np.linalg.solve(V, B[:, :, None].astype(complex))[:, :, 0][:, None, :]
    one = K.pole_residue_sum(lam, res, D[:1], omega)
    full = K.pole_residue_sum(lam, res, np.repeat(D[:1], 6, axis=0), omega)
    assert np.array_equal(one, full)
    hs = K.hessenberg_solve(A, B, C, D[:1], omega)
    assert np.allclose(hs, K.hessenberg_solve(A, B, C, np.repeat(D[:1], 6, axis=0), omega), rtol=1e-12, atol=0)
