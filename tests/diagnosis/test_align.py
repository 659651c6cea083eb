"""Resonance alignment: the port impedance's poles and zeros, and a start with them on the measured resonances.

The reference is a two-mode network whose impedance is written out here:
``Z = (R + s L + 1/(s C2)) || 1/(s C1)``, a series branch (L, C2, small R)
shunted by C1 at the port. Its series resonance is the zero of the branch,
``s^2 L C2 + s R C2 + 1 = 0``; its parallel resonance the zero of the
admittance's numerator, ``s^2 L C1 C2 + s R C1 C2 + C1 + C2 = 0``.
"""

import numpy as np
import pytest

from estimation.diagnosis.align import aligned_start, port_modes
from estimation.diagnosis.fit import FrequencyFit
from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration
from pris_cosim.circuits.netlist import parse_netlist

R, L, C1, C2 = 2.0, 1.0e-3, 0.5e-9, 2.0e-9


def _net(l: float, c1: float, c2: float) -> str:
    return f"* two modes\nC1 p 0 {c1}\nR1 p a {R}\nL1 a b {l}\nC2 b 0 {c2}\n"


def _closed_form(f: np.ndarray, l: float, c1: float, c2: float) -> np.ndarray:
    s = 2j * np.pi * f
    branch = R + s * l + 1 / (s * c2)
    return 1 / (1 / branch + s * c1)


def _roots_hz(coeffs: list[float]) -> float:
    r = np.roots(coeffs)
    return float(r[r.imag > 0][0].imag / (2 * np.pi))


def _fit(l: float, c1: float, c2: float, f: np.ndarray, z: np.ndarray) -> FrequencyFit:
    cfg = [Configuration("default", "p", (), (Response("Zin"),))]
    return FrequencyFit(parse_netlist(_net(l, c1, c2)), cfg, f, {"Zin": z})


def test_port_poles_and_zeros_are_the_closed_form_resonances():
    f = np.logspace(4, 7, 300)
    fit = _fit(L, C1, C2, f, _closed_form(f, L, C1, C2))
    poles, zeros = port_modes(fit, np.zeros(fit.nc), 0, f[0], f[-1])
    series = _roots_hz([L * C2, R * C2, 1.0])
    parallel = _roots_hz([L * C1 * C2, R * C1 * C2, C1 + C2])
    assert zeros.size == 1 and zeros[0] == pytest.approx(series, rel=1e-9)
    assert poles.size == 1 and poles[0] == pytest.approx(parallel, rel=1e-9)


def test_aligned_start_puts_the_resonances_on_the_measured_ones():
    f = np.logspace(4, 7, 400)
    z = _closed_form(f, L, C1, C2)
    # the design 9 % high in L, 6 % high in C2 and 6 % low in C1: both resonances several per cent off
    fit = _fit(1.09 * L, 0.94 * C1, 1.06 * C2, f, z)
    series = _roots_hz([L * C2, R * C2, 1.0])
    parallel = _roots_hz([L * C1 * C2, R * C1 * C2, C1 + C2])
    x0 = np.zeros(fit.nc)
    p0, z0 = port_modes(fit, x0, 0, f[0], f[-1])
    assert abs(z0[0] / series - 1) > 0.03 and abs(p0[0] / parallel - 1) > 0.02
    x = aligned_start(fit, x0)
    assert x is not None
    p, zz = port_modes(fit, x, 0, f[0], f[-1])
    # the measured resonances are read off the sampled magnitude (1.7 % between points; 0.3-0.5 % off here), and
    # the pull towards the start values weighs a tolerance like 1 %: within 1 % of the closed form
    assert zz[0] == pytest.approx(series, rel=1e-2)
    assert p[0] == pytest.approx(parallel, rel=1e-2)


def test_no_measured_resonance_gives_no_start():
    f = np.logspace(1, 2.5, 50)  # far below both resonances: a capacitive slope only
    z = _closed_form(f, L, C1, C2)
    fit = _fit(L, C1, C2, f, z)
    assert aligned_start(fit, np.zeros(fit.nc)) is None


def _tank_and_blip(f: np.ndarray, blip: bool = True) -> np.ndarray:
    """A strong parallel resonance at 10 kHz (1 mH || 253.3 nF || 20 kOhm, 2 uH in series) and, with ``blip``, a
    weak one at 50 kHz (0.1 uH || its capacitance || 1.5 Ohm): a wiggle of about 0.8 dB over a few points."""
    s = 2j * np.pi * f
    z = 1 / (1 / 2e4 + 1 / (s * 1e-3) + s * 253.3e-9) + s * 2e-6
    if blip:
        c2 = 1 / ((2 * np.pi * 50e3) ** 2 * 1e-7)
        z = z + 1 / (1 / 1.5 + 1 / (s * 1e-7) + s * c2)
    return z


def _noisy(z: np.ndarray, noise: float, rng: np.random.Generator) -> np.ndarray:
    return z * np.exp(noise / np.sqrt(2) * (rng.standard_normal(z.size) + 1j * rng.standard_normal(z.size)))


def test_a_weak_mode_above_the_noise_is_a_measured_resonance():
    from estimation.diagnosis.align import measured_modes

    f = np.logspace(3, 6, 600)
    rng = np.random.default_rng(11)
    found = 0
    for _ in range(40):
        peaks, _dips = measured_modes(f, _noisy(_tank_and_blip(f), 0.01, rng))
        found += bool(np.any(np.abs(peaks / 50e3 - 1) < 0.02))
    # 0.8 dB over 1 % noise (0.06 dB per point in ln|Z|): found in nearly every record
    assert found >= 36


def test_noise_on_a_smooth_response_makes_no_measured_resonance():
    from estimation.diagnosis.align import MODE_ALPHA, measured_modes

    f = np.logspace(3, 6, 600)
    rng = np.random.default_rng(12)
    extra = 0
    for _ in range(200):
        peaks, dips = measured_modes(f, _noisy(_tank_and_blip(f, blip=False), 0.01, rng))
        extra += peaks.size + dips.size - 2  # the tank's peak and the dip where the series inductance takes over
    # peaks and dips each at most MODE_ALPHA per record: about 0.4 expected in 200 records
    assert MODE_ALPHA <= 1e-3 and extra <= 3


def test_refined_modes_place_sharp_resonances_between_the_samples():
    from estimation.diagnosis.align import measured_modes, refined_modes

    # R 0.5 Ohm: quality factors near 1400 and 3200, half-power bands 0.07 % and 0.03 % wide; samples 1.7 % apart
    f = np.logspace(4, 7, 400)
    rng = np.random.default_rng(5)
    l, c1, c2, r = L, C1, C2, 0.5
    s = 2j * np.pi * f
    z = 1 / (1 / (r + s * l + 1 / (s * c2)) + s * c1)
    z = _noisy(z, 0.005, rng)
    series = _roots_hz([l * c2, r * c2, 1.0])
    parallel = _roots_hz([l * c1 * c2, r * c1 * c2, c1 + c2])
    peaks, dips = measured_modes(f, z)
    fine_peaks, fine_dips = refined_modes(f, z)
    assert fine_peaks.size == 1 and fine_dips.size == 1
    # sampled: off by a fraction of the step (here 0.1-0.8 %); refined: within 1e-4
    assert abs(peaks[0] / parallel - 1) > 1e-3 or abs(dips[0] / series - 1) > 1e-3
    assert fine_peaks[0] == pytest.approx(parallel, rel=1e-4)
    assert fine_dips[0] == pytest.approx(series, rel=1e-4)


def test_alignment_within_the_box_keeps_the_held_values_in_it():
    from estimation.diagnosis.prior import DesignPrior

    f = np.logspace(4, 7, 400)
    z = _closed_form(f, L, C1, C2)
    net = parse_netlist(_net(L, 0.94 * C1, 1.06 * C2))
    cfg = [Configuration("default", "p", (), (Response("Zin"),))]
    # the design: L 30 % high; C1 and C2 within 6 %. Only L moves both resonances back by its own ratio
    design = {"r1": R, "l1": 1.3 * L, "c1": 0.94 * C1, "c2": 1.06 * C2}
    prior = DesignPrior(design, 0.1, 1e-4)
    fit = FrequencyFit(net, cfg, f, {"Zin": z}, prior=prior)
    x0 = fit.design_vector(np.zeros(fit.nc))
    tau = prior.tau
    x = aligned_start(fit, x0, box=tau, max_nfev=200)
    assert x is not None
    held = fit.anchored_columns
    assert np.all(np.abs(x[held] - x0[held]) <= tau + 1e-9)
    # freed from the box, L returns to the truth and both resonances fall on the closed form's
    column = fit.free.index("L1")
    x = aligned_start(fit, x0, free=[column], box=tau, max_nfev=200)
    p, zz = port_modes(fit, x, 0, f[0], f[-1])
    assert zz[0] == pytest.approx(_roots_hz([L * C2, R * C2, 1.0]), rel=2e-3)
    assert p[0] == pytest.approx(_roots_hz([L * C1 * C2, R * C1 * C2, C1 + C2]), rel=2e-3)
