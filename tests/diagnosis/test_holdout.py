"""The held-out gain's standard error, against its spread over noise draws.

The data are the two-mode network of ``test_align`` written out in closed
form, ``Z = (R + s L + 1/(s C2)) || 1/(s C1)``, with complex log-normal noise.
Both models fit them to the noise: the network itself, and the network with a
shunt resistance at the port that the data do not need. The held-out gain of
the second over the first is zero up to its sampling error, so over many noise
draws its spread must match the standard error each draw states.
"""

import numpy as np

from estimation.diagnosis.fit import FrequencyFit
from estimation.diagnosis.holdout import held_out_gain
from pris_cosim.circuits.netlist import parse_netlist
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration

R, L, C1, C2 = 2.0, 1.0e-3, 0.5e-9, 2.0e-9
CFG = [Configuration("default", "p", (), (Response("Zin"),))]


def _z(f: np.ndarray) -> np.ndarray:
    s = 2j * np.pi * f
    return 1 / (1 / (R + s * L + 1 / (s * C2)) + s * C1)


def _fitted(net: str, f: np.ndarray, z: np.ndarray):
    fit = FrequencyFit(parse_netlist(net), CFG, f, {"Zin": z})
    return fit.fit(x0s=np.zeros(fit.nc)[None], grid=False, max_nfev=100, tol=1e-10)


def test_the_held_out_gains_standard_error_matches_its_spread_over_noise_draws():
    f = np.logspace(4, 7, 300)
    base = f"* two modes\nC1 p 0 {C1}\nR1 p a {R}\nL1 a b {L}\nC2 b 0 {C2}\n"
    extended = base + "Rp p 0 1e7\n"
    rng = np.random.default_rng(7)
    gains, errors = [], []
    for _ in range(12):
        z = _z(f) * np.exp(0.01 / np.sqrt(2) * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)))
        before, after = _fitted(base, f, z), _fitted(extended, f, z)
        gain, se = held_out_gain(before, after, CFG, f, {"Zin": z}, with_error=True, max_nfev=50)
        gains.append(gain)
        errors.append(se)
    gains, errors = np.array(gains), np.array(errors)
    assert np.all(errors > 0)
    # a model the data do not need gains nothing out of sample: zero within three of its standard errors each time
    assert np.all(np.abs(gains) < 3 * errors)
    # and the stated error is the spread's scale (12 draws: the sample spread is within a factor of about 2)
    assert 0.4 < np.std(gains, ddof=1) / np.mean(errors) < 2.5
