"""Generated PRIS waveforms with one hidden effect, for testing and benchmarking the waveform diagnosis.

The setting is the thesis's source check (3.3): the PRIS source with nominal
57.1 Ohm, 1 mH, 4 uF driving a 15.3 Ohm load, four periods of a PRBS of
order 4 at 10 kHz (6 ms). The waveforms are simulated exactly by
:func:`pris_cosim.lab.timedomain.simulate_pris` (a different code path from the
diagnosis's own simulation), then white noise of 0.3 % of each signal's RMS
is added to ``v_in`` and ``i_in``; ``v_bprbs`` stays the commanded level.

Hidden effects (``strength`` in [0, 1] scales the effect within a range
chosen to stand clearly above 0.3 % noise):

``series-resistance``
    an extra 2-15 % of ``R_pris`` in series (the thesis found 7 %: 61.2
    against 57.1 Ohm, tracks and cables).
``component-drift``
    ``L_pris`` and/or ``C_pris`` off nominal by 3-20 % each, random signs
    (the thesis measured +2.4 % and -7.3 %).
``switch-ringing``
    switch parasitics ``L_sw``, ``C_sw`` (thesis 5.1.3) ringing at
    0.8-4 MHz without a snubber, or, in about a third of the cases, damped by
    the thesis's RC snubber (55 Ohm, 10 nF), which the diagnosis is told
    about. Sampled at 20 MS/s so the ringing is resolved.
``none``
    the nominal source (clean data).

The load is drawn within +-5 % of 15.3 Ohm (the diagnosis fits it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.measured.formats import Waveforms
from pris_cosim.lab.timedomain import simulate_pris

__all__ = ["WAVEFORM_CASE_CAUSES", "NOMINAL", "THESIS_MEASURED", "WaveformCase", "waveform_case", "thesis_case",
           "simulate_source"]

WAVEFORM_CASE_CAUSES = ("none", "series-resistance", "component-drift", "switch-ringing")

#: Nominal source of the thesis's source check (3.3).
NOMINAL = {"rpris": 57.1, "lpris": 1e-3, "cpris": 4e-6}
#: Values measured in the thesis (3.3): series R with tracks and cables, LCR-meter L and C, load.
THESIS_MEASURED = {"rpris": 61.2, "lpris": 1.024e-3, "cpris": 3.707e-6, "r_load": 15.3}
R_LOAD = 15.3
VDC = 30.0
PRBS_ORDER = 4
PERIODS = 4
FCLK = 10e3
#: Sampling rates: ringing cases need the MHz ringing resolved.
FS_SLOW = 2e6
FS_FAST = 20e6
#: The thesis's snubber (5.1.3).
SNUBBER = (55.0, 10e-9)


@dataclass
class WaveformCase:
    """Measured-like waveforms with a known hidden effect.

    Attributes
    ----------
    cause : str
    strength, seed : float, int
    waveforms : Waveforms
    nominal : dict
        ``rpris``, ``lpris``, ``cpris`` to diagnose with.
    diagnose_kwargs : dict
        Extra keyword arguments for :func:`diagnose_waveforms` (a known snubber).
    truth : dict
        The hidden values (SI units).
    """

    cause: str
    strength: float
    seed: int
    waveforms: Waveforms
    nominal: dict[str, float]
    diagnose_kwargs: dict[str, Any] = field(default_factory=dict)
    truth: dict[str, Any] = field(default_factory=dict)


def simulate_source(rpris: float, lpris: float, cpris: float, r_load: float, fs: float, vdc: float = VDC,
                    prbs_order: int = PRBS_ORDER, fclk: float = FCLK, periods: int = PERIODS,
                    **parasitics: float) -> dict[str, np.ndarray]:
    """Exact noise-free waveforms of the PRIS source on a resistive load (from rest).

    ``parasitics``: ``lsw``, ``csw``, ``rsnub``, ``csnub`` of :class:`SourceSettings`.
    """
    dut = Circuit(title="resistive load")
    dut.add("Rload", "load", "0", r_load)
    s = SourceSettings(vdc=vdc, prbs_order=prbs_order, fclk=fclk, rpris=rpris, lpris=lpris, cpris=cpris, **parasitics)
    return simulate_pris(dut, "load", s, fs, periods=periods)


def _noisy(sim: dict[str, np.ndarray], noise: float, rng: np.random.Generator, comments: list[str]) -> Waveforms:
    out = {}
    for s in ("v_in", "i_in"):
        x = sim[s]
        out[s] = x + noise * float(np.sqrt(np.mean(x ** 2))) * rng.standard_normal(x.size)
    return Waveforms(sim["time_s"], sim["v_bprbs"], out["v_in"], out["i_in"], comments=comments)


def waveform_case(cause: str, seed: int, strength: float | None = None, noise: float = 0.003,
                  fs: float | None = None) -> WaveformCase:
    """One generated case with the hidden effect ``cause`` (see the module docstring).

    Parameters
    ----------
    cause : str
        One of :data:`WAVEFORM_CASE_CAUSES`.
    seed : int
    strength : float in [0, 1], optional
        Effect size within its range (drawn when omitted).
    noise : float
        Noise standard deviation relative to each signal's RMS (0.003 = 0.3 %).
    fs : float, Hz, optional
        Sampling rate (default 20 MS/s for switch-ringing, 2 MS/s for the
        others; clean cases alternate between the two with the seed).
    """
    if cause not in WAVEFORM_CASE_CAUSES:
        raise ValueError(f"unknown cause {cause!r} (known: {', '.join(WAVEFORM_CASE_CAUSES)})")
    rng = np.random.default_rng([seed, WAVEFORM_CASE_CAUSES.index(cause)])
    strength = float(rng.uniform(0, 1) if strength is None else strength)
    r_load = R_LOAD * float(rng.uniform(0.95, 1.05))
    src = dict(NOMINAL)
    par: dict[str, float] = {}
    kwargs: dict[str, Any] = {}
    truth: dict[str, Any] = {"r_load": r_load}
    if fs is None:
        fs = FS_FAST if cause == "switch-ringing" or (cause == "none" and seed % 2) else FS_SLOW
    if cause == "series-resistance":
        extra = NOMINAL["rpris"] * (0.02 + 0.13 * strength)
        src["rpris"] += extra
        truth["r_series_ohm"] = extra
    elif cause == "component-drift":
        mode = rng.integers(0, 3)  # 0: L only, 1: C only, 2: both
        size = lambda: (0.03 + 0.17 * strength * rng.uniform(0.6, 1.0)) * rng.choice([-1.0, 1.0])  # noqa: E731
        kl = 1 + size() if mode in (0, 2) else 1.0
        kc = 1 + size() if mode in (1, 2) else 1.0
        src["lpris"] *= kl
        src["cpris"] *= kc
        truth.update({"l_scale": kl, "c_scale": kc})
    elif cause == "switch-ringing":
        snubbed = rng.uniform() < 1 / 3
        z0 = float(rng.uniform(60.0, 250.0))
        if snubbed:  # ringing at 350-600 kHz through the snubber: needs a larger L_sw to show
            lsw = 15e-6 + 25e-6 * strength
            csw = lsw / z0 ** 2
            par.update(lsw=lsw, csw=csw, rsnub=SNUBBER[0], csnub=SNUBBER[1])
            kwargs.update(rsnub=SNUBBER[0], csnub=SNUBBER[1])
        else:
            f_r = 0.8e6 * 5.0 ** strength
            lsw, csw = z0 / (2 * math.pi * f_r), 1 / (2 * math.pi * f_r * z0)
            par.update(lsw=lsw, csw=csw)
        truth.update({"lsw_h": lsw, "csw_f": csw, "f_ring_hz": 1 / (2 * math.pi * math.sqrt(lsw * csw)),
                      "snubber": snubbed})
    sim = simulate_source(src["rpris"], src["lpris"], src["cpris"], r_load, fs, **par)
    truth.update({f"true_{k}": v for k, v in src.items()})
    comments = [f"generated case: cause {cause}, seed {seed}, strength {strength:.3f}, noise {noise}"]
    return WaveformCase(cause, strength, seed, _noisy(sim, noise, rng, comments), dict(NOMINAL), kwargs, truth)


def thesis_case(seed: int = 0, noise: float = 0.003, fs: float = FS_SLOW) -> WaveformCase:
    """The thesis's own numbers (3.3): data from the measured 61.2 Ohm, 1.024 mH, 3.707 uF and
    15.3 Ohm, to be diagnosed with the nominal 57.1 Ohm, 1 mH, 4 uF.

    The true discrepancy is a mix (+7.2 % R, +2.4 % L, -7.3 % C); ``cause`` is
    recorded as ``series-resistance`` (the thesis's own explanation: track and
    cable resistance), but ``component-drift`` is an acceptable answer too.
    """
    rng = np.random.default_rng([seed, 99])
    m = THESIS_MEASURED
    sim = simulate_source(m["rpris"], m["lpris"], m["cpris"], m["r_load"], fs)
    comments = ["thesis 3.3: measured source values, to be diagnosed with the nominal ones"]
    return WaveformCase("series-resistance", 1.0, seed, _noisy(sim, noise, rng, comments), dict(NOMINAL), {},
                        {"r_series_ohm": m["rpris"] - NOMINAL["rpris"], "l_scale": m["lpris"] / NOMINAL["lpris"],
                         "c_scale": m["cpris"] / NOMINAL["cpris"], "r_load": m["r_load"]})
