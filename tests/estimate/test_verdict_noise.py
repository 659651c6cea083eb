"""The verdict's noise level: signal near the Nyquist frequency is not read as noise.

A record whose content reaches the Nyquist frequency (a winding's modes above it, aliased) has large
fourth differences without any noise. The Fisher information of the verdict must use the noise that
the fit leaves, not that reading; the reference is the closed-form Cramer-Rao bound of a sinusoid's
amplitude and frequency in white noise.
"""

from __future__ import annotations

import numpy as np

from estimation.parameters import Parameter, ParameterSet
from estimation.verdict import noise_floor, verdict


def test_aliased_record_is_not_called_noisy():
    n, a0, f0, sigma = 2000, 1.0, 0.45, 1e-4  # f in cycles per sample: 0.45 of the sampling rate
    k = np.arange(n)
    rng = np.random.default_rng(3)
    data = a0 * np.sin(2 * np.pi * f0 * k) + sigma * rng.standard_normal(n)
    assert noise_floor(data) > 100 * sigma  # the data's own reading counts the sinusoid as noise
    p = ParameterSet([Parameter("a", 1.0, 0.5, 2.0), Parameter("f", 0.45, 0.4, 0.49)])

    def residuals(U):
        U = np.atleast_2d(U)
        out = []
        for u in U:
            v = p.from_unit(u)
            out.append(v["a"] * np.sin(2 * np.pi * v["f"] * k) - data)
        return np.array(out)

    # the least-squares answer (the data's own amplitude and frequency, by a fine search)
    fs = np.linspace(f0 - 2e-6, f0 + 2e-6, 401)
    basis = np.sin(2 * np.pi * fs[:, None] * k)
    amps = basis @ data / np.sum(basis ** 2, axis=1)
    sse = np.sum((amps[:, None] * basis - data) ** 2, axis=1)
    j = int(np.argmin(sse))
    x = p.to_unit({"a": float(amps[j]), "f": float(fs[j])})
    v = verdict(residuals, p, x, data)
    assert v["noise_sigma"] < 2 * sigma
    assert not v["non_identifiable"]
    # Cramer-Rao of a sinusoid in white noise: sd(a) / a = sigma sqrt(2 / n) / a
    crb_a = sigma * np.sqrt(2.0 / n) / a0
    assert 0.5 * crb_a < v["uncertainty"]["a"] < 2.0 * crb_a
