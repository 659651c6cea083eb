"""The measured-noise cell: records acquired through an anti-alias filter and a 16-bit ADC, and estimated.

References here are independent of the code under test: the filter is designed in this file from its
data-sheet description (4th-order Chebyshev type I, 1 dB ripple, 100 kHz) and applied by SciPy's
``lsim`` to a finely sampled unfiltered waveform; the ADC's noise is the closed form
``sqrt(sigma^2 + LSB^2 / 12) * attenuation / sqrt(averages)``; the plateau problem is written here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from estimation import approaches as ap
from estimation.search.local_search import profile_scan, sloppiest_parameter
from estimation.studies.three_section import study as three
from pris_cosim.lab import virtual_lab as vl
from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.models.builtin import get_model

SOURCE = SourceSettings(vdc=100.0, prbs_order=6, fclk=100e3, rpris=150.0, lpris=4e-3, cpris=1e-6)


def datasheet_filter() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """4th-order Chebyshev-I low pass, 1 dB ripple, passband edge 100 kHz (analogue), as (A, B, C, D)."""
    b, a = signal.cheby1(4, 1.0, 2 * np.pi * 100e3, btype="low", analog=True)
    return signal.tf2ss(b, a)


def test_filtered_engine_agrees_with_lsim_of_the_unfiltered_waveform():
    """PrisEngine with the filter's states appended, at 1 MS/s, against SciPy's lsim of the 40 MS/s
    unfiltered port voltage, decimated."""
    circuit = get_model("three-section").circuit
    n = 630
    A, B, C, D = datasheet_filter()
    filt = ap.PrisEngine(circuit, "n1", SOURCE, 1e6, n, probes=[], output_filter=(A, B[:, 0], C[0], D[0, 0]))
    fine = ap.PrisEngine(circuit, "n1", SOURCE, 40e6, n * 40, probes=[])
    v_fine = fine.simulate({})["v_in"][0]
    t = np.arange(v_fine.size) / 40e6
    _, y, _ = signal.lsim((A, B, C, D), v_fine, t)
    ref = y[::40]
    got = filt.simulate({})["v_in"][0]
    assert np.max(np.abs(got - ref)) < 1e-4 * np.max(np.abs(ref))
    # and the unfiltered samples differ from it by far more (the filter is really applied)
    raw = ap.PrisEngine(circuit, "n1", SOURCE, 1e6, n, probes=[]).simulate({})["v_in"][0]
    assert np.std(raw - ref) > 0.1 * np.std(ref)


def test_the_lab_chain_and_the_filtered_engine_are_one_waveform_without_noise():
    circuit = get_model("three-section").circuit
    w = vl.acquire_pris(circuit, "n1", SOURCE, noise=False)
    e = ap.PrisEngine(circuit, "n1", SOURCE, 1e6, w["time_s"].size, probes=[],
                      output_filter=vl.anti_alias_ss(vl.MeasurementChain()))
    sim = e.simulate({})
    for k in ("v_in", "i_in"):
        assert np.max(np.abs(sim[k][0] - w[k])) < 1e-9 * np.max(np.abs(w[k]))


@pytest.mark.parametrize("averages", [1, 16])
def test_adc_noise_is_the_chain_s_closed_form(averages):
    circuit = get_model("three-section").circuit
    ch = vl.MeasurementChain()
    clean = vl.acquire_pris(circuit, "n1", SOURCE, noise=False)
    noisy = vl.acquire_pris(circuit, "n1", SOURCE, seed=4, averages=averages)
    att = 20.0  # the smallest probe ratio keeping the ~85 V peak within 90 % of +-10 V
    assert float(noisy["attenuation_v_in"]) == att
    expected = math.sqrt(ch.noise_rms_v ** 2 + (20.0 / 2 ** 16) ** 2 / 12) * att / math.sqrt(averages)
    got = float(np.std(noisy["v_in"] - clean["v_in"]))
    assert got == pytest.approx(expected, rel=0.08)
    assert three.chain_sigma(clean["v_in"]) / math.sqrt(averages) == pytest.approx(expected, rel=1e-9)


class _Plateau:
    """Residuals of ``y = u1 t + exp(-30 (1 - u0)) t^2`` against data made at u0 = 0.9, u1 = 0.5: the
    gradient in u0 vanishes as u0 -> 0 (a log-scaled value whose effect fades), u1 absorbs what it can."""

    n = 2

    def __init__(self):
        self.t = np.linspace(0.0, 1.0, 50)
        self.y = self.model(np.array([[0.9, 0.5]]))[0]

    def model(self, U: np.ndarray) -> np.ndarray:
        U = np.atleast_2d(U)
        return U[:, 1:2] * self.t[None, :] + np.exp(-30.0 * (1.0 - U[:, 0:1])) * self.t[None, :] ** 2

    def residuals(self, U: np.ndarray) -> np.ndarray:
        return self.model(U) - self.y[None, :]


def test_profile_scan_crosses_a_plateau_a_local_method_stops_on():
    from scipy.optimize import least_squares

    p = _Plateau()
    x0 = np.array([0.05, 0.2])
    stuck = least_squares(lambda u: p.residuals(u)[0], x0, bounds=(0, 1)).x
    assert abs(stuck[0] - 0.9) > 0.3  # the local method stays on the plateau
    assert sloppiest_parameter(p, stuck) == 0
    out = profile_scan(p, stuck, 0)
    assert out["x"][0] == pytest.approx(0.9, abs=1e-3)
    assert out["x"][1] == pytest.approx(0.5, abs=1e-3)
    assert len(out["profile"]) == 13


def test_levels_and_case_keys():
    assert three.level_of("adc") == three.ADC and three.level_of(" ADC ") == three.ADC
    assert three.level_of("none") is None and three.level_of(40) == 40.0
    with pytest.raises(three.common.StudyError):
        three.level_of("loud")
    assert three.case_key("time", "pso", "rmse", "adc") == "time/pso/rmse@adc"
    assert three.case_key("time", "pso", "rmse", 40.0) == "time/pso/rmse@40dB"
    assert three.level_tag("adc") == "adc" and three.level_tag(20.0) == "snr20"


@pytest.mark.slow
@pytest.mark.long
def test_time_path_at_the_adc_cell_reaches_the_bound_rule():
    """One seed of the time path (PSO + local, RMSE) on the record measured through the chain: every value
    within max(5 %, 3 x its Cramer-Rao bound for that record)."""
    row = three.run_one("time", "pso", "rmse", quick=True, seed=1, snr_db="adc")
    bad = {k: (round(e, 2), round(row["limit_percent"][k], 2)) for k, e in row["errors_percent"].items()
           if not abs(e) <= row["limit_percent"][k]}
    assert not bad, (bad, row["optimiser_message"])
