"""The FMU verdict's chi-square test against the record's own noise (no FMU: residuals made here)."""

from __future__ import annotations

import numpy as np

from estimation.fmu.verdict import NUMERIC, block_noise, chi_square


def test_white_noise_is_the_noise():
    """A residual of white noise passes at every length and level (the false-alarm rate is about 1e-3)."""
    rng = np.random.default_rng(3)
    fails = 0
    for n in (500, 4000, 20000):
        for sd in (1e-6, 5e-3):
            for _ in range(10):
                r = sd * rng.standard_normal(n)
                fails += not chi_square(r, block_noise(r, 1), 9)["consistent"]
    assert fails <= 1, fails


def test_a_misfit_above_its_own_noise_is_not():
    """A slow, structured misfit 15 times the noise (a wrong basin's residual) fails; so does a noise-free
    record's residual far above the numerical resolution."""
    rng = np.random.default_rng(4)
    t = np.arange(4088) / 1e6
    misfit = 15 * 2e-5 * np.sin(2 * np.pi * 37e3 * t) * np.exp(-t / 2e-3)
    r = 2e-5 * rng.standard_normal(t.size) + misfit
    assert not chi_square(r, block_noise(r, 1), 6)["consistent"]
    smooth = 3.2e-4 * np.sin(2 * np.pi * 90e3 * t)  # a noise-free record fitted in a wrong basin
    assert not chi_square(smooth, block_noise(smooth, 1), 6)["consistent"]


def test_noise_free_floor_and_blocks():
    """A residual at rounding level passes (the floor is the resolution sqrt(eps) of each output's RMS);
    two outputs of different noise are read apart."""
    rng = np.random.default_rng(5)
    r = 1e-13 * np.sin(np.arange(2000) / 50.0)
    s = block_noise(r, 1)
    assert s[0] == NUMERIC and chi_square(r, s, 3)["consistent"]
    two = np.concatenate([1e-3 * rng.standard_normal(3000), 1e-1 * rng.standard_normal(3000)])
    s2 = block_noise(two, 2)
    assert abs(s2[0] / 1e-3 - 1) < 0.1 and abs(s2[1] / 1e-1 - 1) < 0.1
    assert chi_square(two, s2, 3)["consistent"]
    assert not chi_square(two, np.array([1e-3, 1e-3]), 3)["consistent"]
