"""Virtual laboratory of thesis chapter 5.1: the six two-winding measurements, simulated.

A two-winding transformer model (``hv-4section`` ...) is perturbed as in the
thesis's laboratory and measured through a model of the thesis's measurement
chain, and the six frequency responses Zlvoc, Zlvsc, Zhvoc, Zhvsc, Rlvhv,
Rhvlv are estimated from the records exactly as from real data: H1 (Welch,
Hann, 62.5 % overlap, half-record segments), two clock frequencies combined
at the thesis's transition frequencies, then written on a log grid where the
records carry information (:func:`run_lab`): bins at the PRBS clock nulls
left out, each value a local line through the nearest bins, with the
standard deviation of ``ln H`` from the coherence beside it.

What is modelled (thesis 5.1.1-5.1.3; :class:`LabSettings`):

* **PRIS source.** LV terminal: V_DC = 30 V (10 V for LVHV), R/L/C =
  56 Ohm / 500 uH / 4 uF. HV terminal: 120 V, 29.7 kOhm / 30 mH / 100 nF with
  the RC snubber 55 Ohm / 10 nF across the bridge output and the switch
  parasitics that make the bridge ring (:func:`switch_parasitics`: 2.2936 MHz
  without snubber, 482.63 kHz with it). High clock PRBS16 at 20 kHz, low
  clock PRBS13 at 2 kHz (``quick``: PRBS12 and PRBS10, same clocks).
* **Anti-alias filter (Thorlabs EF502).** An *analogue* filter: 4th-order
  Chebyshev type I, 1 dB ripple to 100 kHz (about 34 dB down at 199 kHz,
  the data sheet's "30 dB at 199 kHz"), passband gain within [-1, 0] dB. Its state
  equations are appended to the circuit's and the whole system is stepped
  with the exact zero-order-hold discretisation at the 1 MS/s sampling
  instants, so the filtered voltages are exact, continuous-time filtered
  waveforms sampled at 1 MS/s (no 10 MS/s intermediate record is needed).
* **Voltage probes and ADC (NI 9223).** Each channel (``v_in``, the
  sense-resistor voltage ``v_sense = R_pris i``, and ``v_out`` for the ratio
  configurations) goes through a differential probe whose attenuation is the
  smallest of 20/50/200 that keeps the peak within 90 % of the ADC range
  (auto-ranging as the experimenter would), then the ADC: +-10 V, 16 bits
  (LSB 305 uV at the ADC input), with additive white Gaussian noise of
  ``noise_rms_v`` (default 5 mV RMS at the ADC input, about 16 LSB, i.e.
  0.1-1 V at the probe tip: probe noise plus switching interference, a stated
  assumption, not a data-sheet figure) added before quantisation, clipping at
  full scale.
* **Current.** ``i_in`` is the measured sense-resistor voltage divided by the
  nominal R_pris (thesis: the current probe lacked resolution on the HV side).

The artefacts of the thesis follow from the physics rather than being
painted on: the PRBS spectrum ``sinc^2(f/f_clk)`` vanishes at 20, 40, ...
kHz and falls off above f_clk/3, so with the additive noise the 20 kHz-clock
data are noisy above 20 kHz and (for the low-impedance LVSC and the LVHV
ratio) at low frequency, which the 2 kHz-clock data repair below the
transition frequency (666.7 Hz for the impedances, 200 Hz for the ratios).

Simulation starts in the periodic steady state of the PRBS drive by default
(the source runs continuously while the record is taken); ``start="rest"``
starts from zero state instead.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
from scipy import signal as sps

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.errors import CircuitError
from pris_cosim.measured.formats import MeasuredResponses, Waveforms, write_response_csv
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import Configuration, Model
from pris_cosim.signals.perturbation import lfsr_prbs
from pris_cosim.signals.spectral import DEFAULT_OVERLAP, FrequencyResponse, estimate_response, synthesise_two_clock
from pris_cosim.signals.uncertainty import (LOCAL_BINS, NULL_WIDTH, clock_null_mask, h1_log_sd, local_linear, pooled,
    welch_averages)
from pris_cosim.lab.timedomain import checked_values, zoh

__all__ = [
    "ALL_CONFIGS",
    "LabRecord",
    "LabResult",
    "LabSettings",
    "MeasurementChain",
    "RESPONSE_OF",
    "acquire_pris",
    "anti_alias_ss",
    "measure_response",
    "perturb",
    "plot_lab",
    "plot_record",
    "round_trip_errors",
    "run_lab",
    "switch_parasitics",
    "virtual_lab",
    "write_lab_csv",
]

#: The six configurations in thesis order and the response each yields.
ALL_CONFIGS: tuple[str, ...] = ("LVOC", "LVSC", "HVOC", "HVSC", "LVHV", "HVLV")
RESPONSE_OF: dict[str, str] = {
    "LVOC": "Zlvoc", "LVSC": "Zlvsc", "HVOC": "Zhvoc", "HVSC": "Zhvsc", "LVHV": "Rlvhv", "HVLV": "Rhvlv",
}
#: Two-clock transition frequencies (thesis 5.1.2): f_clk,low / 3 for the impedances, 200 Hz for
#: Rlvhv; Rhvlv is not stated in the thesis and is given the ratio value too.
DEFAULT_TRANSITIONS: dict[str, float] = {
    "Zlvoc": 2000.0 / 3, "Zlvsc": 2000.0 / 3, "Zhvoc": 2000.0 / 3, "Zhvsc": 2000.0 / 3,
    "Rlvhv": 200.0, "Rhvlv": 200.0,
}

Clock = Literal["high", "low"]


def switch_parasitics(f_ring: float = 2.2936e6, f_ring_snubbed: float = 482.63e3,
                      c_snub: float = 10e-9) -> tuple[float, float]:
    """Switch parasitic inductance and capacitance from the measured ringing (thesis 5.1.3).

    With ``f_r = 1/(2 pi sqrt(Lp Cp))`` and ``f_r2 = 1/(2 pi sqrt(Lp (Cp + Cs)))``:
    ``Cp = Cs / ((f_r/f_r2)**2 - 1)`` and ``Lp = 1 / ((2 pi f_r)**2 Cp)``.
    (The thesis's printed eq. 5.3 is not consistent with 5.1/5.2; this is the exact
    solution of 5.1 and 5.2.) Returns ``(Lp, Cp)`` in H, F: about 10.4 uH, 0.46 nF.
    """
    if not (f_ring > f_ring_snubbed > 0 and c_snub > 0):
        raise ValueError("need f_ring > f_ring_snubbed > 0 and c_snub > 0")
    cp = c_snub / ((f_ring / f_ring_snubbed) ** 2 - 1.0)
    lp = 1.0 / ((2 * math.pi * f_ring) ** 2 * cp)
    return lp, cp


_LP, _CP = switch_parasitics()


@dataclass(frozen=True)
class MeasurementChain:
    """Probe, anti-alias filter and ADC (thesis 5.1.1).

    Attributes
    ----------
    fs : float, Hz
        ADC sampling rate (NI 9223: 1 MS/s). Must be an integer multiple of both clocks.
    aa_cutoff_hz : float or None, Hz
        Anti-alias filter passband edge (EF502: 100 kHz); None = no filter.
    aa_order, aa_ripple_db
        Chebyshev type I order and passband ripple of the analogue filter model.
    adc_bits : int
        ADC resolution (16). ``quantise=False`` keeps the samples unquantised.
    adc_range_v : float, V
        ADC full scale, +-range at the ADC input (NI 9223: +-10 V).
    probe_attenuations : tuple of float
        Selectable probe attenuations; per channel the smallest keeping the peak
        below ``headroom * adc_range_v`` is used.
    noise_rms_v : float, V
        RMS of white Gaussian noise at the ADC input (before quantisation), per channel.
    fmax_hz : float, Hz
        Highest frequency estimated (the anti-alias passband edge).
    """

    fs: float = 1e6
    aa_cutoff_hz: float | None = 100e3
    aa_order: int = 4
    aa_ripple_db: float = 1.0
    adc_bits: int = 16
    adc_range_v: float = 10.0
    quantise: bool = True
    probe_attenuations: tuple[float, ...] = (20.0, 50.0, 200.0)
    headroom: float = 0.9
    noise_rms_v: float = 5e-3
    fmax_hz: float = 100e3

    @property
    def lsb_v(self) -> float:
        """ADC step at the ADC input, V."""
        return 2.0 * self.adc_range_v / 2 ** self.adc_bits


@dataclass(frozen=True)
class LabSettings:
    """Sources, clocks, measurement chain and estimation settings of the virtual lab.

    Defaults are the thesis's (5.1.2, 5.1.3); :meth:`quick` shortens the PRBS.
    """

    lv: SourceSettings = SourceSettings(vdc=30.0, prbs_order=16, fclk=20e3, rpris=56.0, lpris=500e-6, cpris=4e-6)
    lv_ratio_vdc: float = 10.0
    hv: SourceSettings = SourceSettings(vdc=120.0, prbs_order=16, fclk=20e3, rpris=29.7e3, lpris=30e-3,
                                        cpris=100e-9, rsnub=55.0, csnub=10e-9, lsw=_LP, csw=_CP)
    low_fclk: float = 2e3
    low_prbs_order: int = 13
    chain: MeasurementChain = MeasurementChain()
    transitions: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_TRANSITIONS))
    periods: int = 1
    start: Literal["steady", "rest"] = "steady"
    nperseg_fraction: float = 0.5

    @classmethod
    def quick(cls, high_order: int = 13, low_order: int = 11, **kw: Any) -> LabSettings:
        """Shorter PRBS (13 at 20 kHz, 11 at 2 kHz), same clocks: records of 0.41 s and 1.02 s
        instead of 3.28 s and 4.10 s, so the Welch bins (half-record segments) are 4.9 Hz and
        2.0 Hz wide instead of 0.61 Hz and 0.49 Hz: resonances narrower than a few bins are
        smoothed and the lowest decade has only a few bins per log-grid point. The PRBS
        spectral shape (set by the clock) and hence the noise artefacts are unchanged."""
        base = cls(**kw)
        return replace(base, lv=replace(base.lv, prbs_order=high_order),
                       hv=replace(base.hv, prbs_order=high_order), low_prbs_order=low_order)

    def without_noise(self) -> LabSettings:
        """The same lab with no additive noise and no quantisation (filter kept)."""
        return replace(self, chain=replace(self.chain, noise_rms_v=0.0, quantise=False))

    def source(self, config: Configuration, clock: Clock = "high") -> SourceSettings:
        """Source settings for a configuration (LV or HV terminal by its port) and clock."""
        if clock not in ("high", "low"):
            raise ValueError(f"clock must be 'high' or 'low', got {clock!r}")
        hv_side = config.port.lower().startswith("b")
        s = self.hv if hv_side else self.lv
        if not hv_side and _ratio_node(config) is not None:
            s = replace(s, vdc=self.lv_ratio_vdc)
        if clock == "low":
            s = replace(s, fclk=self.low_fclk, prbs_order=self.low_prbs_order)
        return s


def _ratio_node(config: Configuration) -> str | None:
    if len(config.responses) != 1:
        raise CircuitError(f"configuration {config.name!r} must yield exactly one response")
    return config.responses[0].node


# ---------------------------------------------------------------------------- simulation


def anti_alias_ss(chain: MeasurementChain) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """State-space ``(A, B, C, D)`` (B, C as vectors) of the anti-alias filter: gain between -1 dB and
    0 dB up to the cutoff (even order: -1 dB at DC and at the cutoff), time scaled from the unit filter."""
    z, p, k = sps.cheby1(chain.aa_order, chain.aa_ripple_db, 1.0, btype="low", analog=True, output="zpk")
    a, b, c, d = sps.zpk2ss(z, p, k)
    w = 2 * math.pi * float(chain.aa_cutoff_hz)  # type: ignore[arg-type]
    return a * w, b[:, 0] * w, c[0], float(d[0, 0])


@dataclass(eq=False)
class LabRecord:
    """One perturbation record as acquired (and, optionally, the true signals).

    ``v_in``, ``i_in``, ``v_sense``, ``v_out`` are the measured (filtered, noisy,
    quantised) samples; ``true`` holds the unfiltered noise-free circuit signals
    (``v_in``, ``i_in``, ``v_out``) when requested.
    """

    config: str
    response: str
    clock: str
    fs: float
    source: SourceSettings
    time_s: np.ndarray
    v_bprbs: np.ndarray
    v_in: np.ndarray
    i_in: np.ndarray
    v_sense: np.ndarray
    v_out: np.ndarray | None
    attenuation: dict[str, float]
    clipped: dict[str, int]
    true: dict[str, np.ndarray] = field(default_factory=dict)
    wall_s: float = 0.0

    def waveforms(self) -> Waveforms:
        """As the interfaces waveform contract (:func:`pris_cosim.measured.formats.write_waveform_csv`)."""
        return Waveforms(self.time_s, self.v_bprbs, self.v_in, self.i_in, self.v_out,
                         comments=[f"virtual lab {self.config} {self.clock} clock: PRBS{self.source.prbs_order} "
                                   f"at {self.source.fclk:g} Hz, fs {self.fs:g} Hz"])


def _simulate_outputs(A: np.ndarray, b: np.ndarray, Cout: np.ndarray, dout: np.ndarray,
                      levels: np.ndarray, M: int, h: float, x0: np.ndarray | None,
                      steady_bits: int | None, chunk: int = 2048) -> np.ndarray:
    """Exact ZOH outputs ``Cout x + dout u`` at M samples per constant-input bit.

    ``levels[k]`` holds over bit k (M samples of length h). With ``steady_bits``
    = N the start state is the periodic steady state of the N-bit periodic
    input (levels must repeat with period N).
    """
    n = A.shape[0]
    Phi, Gam = zoh(A, b[:, None], h)
    g = Gam[:, 0]
    PhiM, GamM = zoh(A, b[:, None], M * h)
    gM = GamM[:, 0]
    P = np.empty((M, n, n))
    G = np.empty((M, n))
    P[0], G[0] = np.eye(n), 0.0
    for j in range(1, M):
        P[j] = Phi @ P[j - 1]
        G[j] = Phi @ G[j - 1] + g
    nb = levels.size

    def starts(x: np.ndarray, count: int) -> np.ndarray:
        xs = np.empty((count + 1, n))
        xs[0] = x
        PhiMT = PhiM
        for k in range(count):
            x = PhiMT @ x + gM * levels[k]
            xs[k + 1] = x
        return xs

    if steady_bits is not None:
        r = starts(np.zeros(n), steady_bits)[-1]
        PhiT = np.linalg.matrix_power(PhiM, steady_bits)
        x0 = np.linalg.solve(np.eye(n) - PhiT, r)
    xs = starts(np.zeros(n) if x0 is None else np.asarray(x0, float), nb)[:-1]
    nout = Cout.shape[0]
    CP = np.einsum("kn,jnm->jkm", Cout, P).reshape(M * nout, n)
    CG = (G @ Cout.T + dout[None, :]).reshape(M * nout)
    out = np.empty((nb, M * nout))
    for s in range(0, nb, chunk):
        e = min(s + chunk, nb)
        out[s:e] = xs[s:e] @ CP.T + levels[s:e, None] * CG[None, :]
    return out.reshape(nb * M, nout)


def _noise_rng(seed: int | None, config: str, clock: str) -> np.random.Generator:
    key = [ALL_CONFIGS.index(config) if config in ALL_CONFIGS else sum(map(ord, config)), 0 if clock == "high" else 1]
    return np.random.default_rng(None if seed is None else [int(seed), *key])


def _chain_system(circuit: Any, port: str, src: SourceSettings, ch: MeasurementChain, node_out: str | None,
                  keep_true: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """State space of a PRIS arrangement seen through the chain: ``(A, b, C, d, names)``.

    Outputs: the measured channels ``v_in``, ``v_sense`` (= R_pris i) [, ``v_out``], each
    through its own anti-alias filter (state equations appended), then, with
    ``keep_true``, the same channels unfiltered.
    """
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    ss = mna.state_space(checked_values(circuit))
    A, B, C, D = ss.A[0], ss.B[0][:, 0], ss.C[0], ss.D[0][:, 0]
    n = A.shape[0]
    rows_c = [C[mna.outputs.index(f"v({port})")]]
    rows_d = [D[mna.outputs.index(f"v({port})")]]
    e_i = np.zeros(n)
    e_i[mna.states.index(f"i({SENSE_INDUCTOR})")] = 1.0
    rows_c.append(src.rpris * e_i)
    rows_d.append(0.0)
    names = ["v_in", "v_sense"]
    if node_out is not None:
        onode = circuit.require_node(node_out, "output")
        rows_c.append(C[mna.outputs.index(f"v({onode})")])
        rows_d.append(D[mna.outputs.index(f"v({onode})")])
        names.append("v_out")
    Cr, dr = np.array(rows_c), np.array(rows_d, dtype=float)
    nch = len(names)
    if ch.aa_cutoff_hz:
        af, bf, cf, df = anti_alias_ss(ch)
        nf = af.shape[0]
        Aa = np.zeros((n + nch * nf, n + nch * nf))
        ba = np.zeros(n + nch * nf)
        Aa[:n, :n], ba[:n] = A, B
        Co = np.zeros((nch, n + nch * nf))
        do = np.zeros(nch)
        for k in range(nch):
            sl = slice(n + k * nf, n + (k + 1) * nf)
            Aa[sl, sl] = af
            Aa[sl, :n] = np.outer(bf, Cr[k])
            ba[sl] = bf * dr[k]
            Co[k, sl] = cf
            Co[k, :n] = df * Cr[k]
            do[k] = df * dr[k]
    else:
        Aa, ba = A, B
        Co, do = Cr, dr
    if keep_true:  # append the unfiltered channels as extra outputs
        pad = np.zeros((nch, Aa.shape[0]))
        pad[:, :n] = Cr
        Co, do = np.vstack([Co, pad]), np.concatenate([do, dr])
    return Aa, ba, Co, do, names


def _digitise(y: np.ndarray, ch: MeasurementChain, rng: np.random.Generator, noise: bool, averages: int = 1
              ) -> tuple[np.ndarray, float, int]:
    """One channel through probe, noise and ADC: ``(samples at the probe tip, attenuation, clipped count)``.

    The probe's attenuation is the smallest keeping the peak within the headroom; with
    ``averages`` above 1 that many acquisitions, each with its own noise and
    quantisation, are averaged (an oscilloscope's averaging mode).
    """
    peak = float(np.max(np.abs(y)))
    a = next((x for x in sorted(ch.probe_attenuations) if peak / x <= ch.headroom * ch.adc_range_v),
             max(ch.probe_attenuations))
    acc = np.zeros(y.size)
    clipped = 0
    for _ in range(max(int(averages), 1)):
        v = y / a
        if noise and ch.noise_rms_v > 0:
            v = v + rng.normal(0.0, ch.noise_rms_v, y.size)
        if noise and ch.quantise:
            top = 2 ** (ch.adc_bits - 1)
            q = np.round(v / ch.lsb_v)
            clipped += int(np.count_nonzero((q < -top) | (q > top - 1)))
            v = np.clip(q, -top, top - 1) * ch.lsb_v
        acc += v
    return acc / max(int(averages), 1) * a, a, clipped


def _chain_run(circuit: Any, port: str, src: SourceSettings, ch: MeasurementChain, node_out: str | None,
               keep_true: bool, periods: int, start: str) -> tuple[np.ndarray, np.ndarray, list[str], int]:
    ratio = ch.fs / src.fclk
    M = int(round(ratio))
    if abs(ratio - M) > 1e-9 * ratio or M < 1:
        raise ValueError(f"fs = {ch.fs:g} Hz must be an integer multiple of the clock {src.fclk:g} Hz")
    if start not in ("steady", "rest"):
        raise ValueError(f"start must be 'steady' or 'rest', got {start!r}")
    Aa, ba, Co, do, names = _chain_system(circuit, port, src, ch, node_out, keep_true)
    bits = lfsr_prbs(src.prbs_order, periods)
    levels = np.where(bits == 1, src.vdc, -src.vdc).astype(float)
    Y = _simulate_outputs(Aa, ba, Co, do, levels, M, 1.0 / ch.fs, None,
                          2 ** src.prbs_order - 1 if start == "steady" else None)
    return Y, np.repeat(levels, M), names, M


def acquire_pris(dut: Any, port: str, source: SourceSettings, chain: MeasurementChain | None = None,
                 periods: int = 1, start: Literal["steady", "rest"] = "rest", seed: int | None = 0,
                 noise: bool = True, averages: int = 1) -> dict[str, np.ndarray]:
    """A PRIS record of any one-port winding ``dut`` at ``port``, acquired through the measurement chain.

    The arrangement (:func:`pris_cosim.circuits.arrangement.pris_arrangement`) with the
    anti-alias filter's states appended is stepped exactly (zero-order hold at
    the ADC's instants, where the bridge switches); each channel then passes the
    probe, the additive noise and the ADC (:class:`MeasurementChain`).

    Parameters
    ----------
    dut : Circuit
        The winding.
    port : str
        Its driven node.
    source : SourceSettings
        PRIS source; the ADC rate must be an integer multiple of its clock.
    chain : MeasurementChain, optional
        Default :class:`MeasurementChain` (1 MS/s, 100 kHz Chebyshev-I, 16 bit, 5 mV RMS).
    periods : int
        PRBS periods recorded.
    start : {"rest", "steady"}
        Zero initial state, or the periodic steady state of the drive.
    seed : int or None
        Noise seed.
    noise : bool
        False: no noise and no quantisation (filter and probes kept).
    averages : int
        Acquisitions averaged (each with its own noise and quantisation).

    Returns
    -------
    dict
        ``time_s`` (s), ``v_bprbs``, ``v_in``, ``v_sense`` (V), ``i_in`` (A, ``v_sense / R_pris``),
        and ``attenuation_v_in``, ``attenuation_v_sense`` (probe ratios, as 0-d arrays).
    """
    ch = chain or MeasurementChain()
    circuit = pris_arrangement(dut, port, source)
    Y, vb, names, _ = _chain_run(circuit, circuit.ports[0], source, ch, None, False, periods, start)
    rng = np.random.default_rng(seed)
    out: dict[str, np.ndarray] = {"time_s": np.arange(Y.shape[0]) / ch.fs, "v_bprbs": vb}
    for k, name in enumerate(names):
        out[name], a, _ = _digitise(Y[:, k], ch, rng, noise, averages)
        out[f"attenuation_{name}"] = np.asarray(a)
    out["i_in"] = out["v_sense"] / source.rpris
    return out


def perturb(model: Model, config: str, clock: Clock = "high", settings: LabSettings | None = None,
            seed: int | None = 0, noise: bool = True, keep_true: bool = False) -> LabRecord:
    """Perturb one test configuration and acquire its waveforms through the measurement chain.

    Parameters
    ----------
    model : Model
        Two-winding model (any model whose configurations yield one impedance or ratio).
    config : str
        ``LVOC`` ... ``HVLV``.
    clock : {"high", "low"}
        20 kHz clock (PRBS16, or the quick order) or 2 kHz clock (PRBS13).
    settings : LabSettings, optional
        Default :class:`LabSettings` (full thesis lengths).
    seed : int or None
        Noise seed (the stream also depends on the configuration and clock).
    noise : bool
        False: no additive noise and no quantisation (filter and probes kept).
    keep_true : bool
        Also return the unfiltered noise-free ``v_in``, ``i_in`` (, ``v_out``).

    Returns
    -------
    LabRecord
    """
    t0 = time.perf_counter()
    st = settings or LabSettings()
    ch = st.chain
    cfg = model.configuration(config)
    node_out = _ratio_node(cfg)
    src = st.source(cfg, clock)
    circuit = pris_arrangement(model.circuit, cfg.port, src, cfg.shorts)
    Y, vb, names, _ = _chain_run(circuit, circuit.ports[0], src, ch, node_out, keep_true, st.periods, st.start)
    nch = len(names)
    K = Y.shape[0]
    rng = _noise_rng(seed, cfg.name, clock)
    measured: dict[str, np.ndarray] = {}
    atten: dict[str, float] = {}
    clipped: dict[str, int] = {}
    for k, name in enumerate(names):
        measured[name], atten[name], clipped[name] = _digitise(Y[:, k], ch, rng, noise)
    true: dict[str, np.ndarray] = {}
    if keep_true:
        true = {"v_in": Y[:, nch].copy(), "i_in": Y[:, nch + 1] / src.rpris}
        if node_out is not None:
            true["v_out"] = Y[:, nch + 2].copy()
    return LabRecord(
        config=cfg.name, response=cfg.responses[0].name, clock=clock, fs=ch.fs, source=src,
        time_s=np.arange(K) / ch.fs, v_bprbs=vb, v_in=measured["v_in"],
        i_in=measured["v_sense"] / src.rpris, v_sense=measured["v_sense"], v_out=measured.get("v_out"),
        attenuation=atten, clipped=clipped, true=true, wall_s=time.perf_counter() - t0,
    )


# ---------------------------------------------------------------------------- estimation


def measure_response(record: LabRecord, fmin: float | None = None, fmax: float | None = None,
                     nperseg: int | None = None, nperseg_fraction: float = 0.5) -> FrequencyResponse:
    """H1 estimate (with coherence) of the record's response.

    Impedances: ``Z = V_in / I_in``; ratios: ``R = V_out / V_in``. Welch with the
    thesis defaults (Hann, 62.5 % overlap) and segments of ``nperseg_fraction``
    of the record unless ``nperseg`` is given; ``fmax`` defaults to min(100 kHz, fs/2).
    """
    x, y = (record.i_in, record.v_in) if record.v_out is None else (record.v_in, record.v_out)
    seg = nperseg if nperseg is not None else max(16, int(record.time_s.size * nperseg_fraction))
    hi = min(record.fs / 2, 100e3) if fmax is None else fmax
    return estimate_response(x, y, record.fs, fmin=fmin, fmax=hi, nperseg=seg, name=record.response)


@dataclass(eq=False)
class LabResult:
    """Everything a virtual-lab run produced.

    ``measured`` holds the six synthesised responses on the log grid; ``high``,
    ``low`` and ``synthesised`` the raw Welch-grid estimates per response name;
    ``records`` the waveforms (only when kept); ``wall_s`` per configuration.
    """

    measured: MeasuredResponses
    high: dict[str, FrequencyResponse]
    low: dict[str, FrequencyResponse]
    synthesised: dict[str, FrequencyResponse]
    settings: LabSettings
    records: dict[tuple[str, str], LabRecord] = field(default_factory=dict)
    wall_s: dict[str, float] = field(default_factory=dict)


#: Lowest frequency written: at least this many Welch bins above DC (the Hann window's main lobe is
#: two bins wide on each side; below, the estimate mixes in the record's mean and its trend).
MIN_BINS_ABOVE_DC = 4


def _informative(resp: FrequencyResponse, fclk: float, n_averages: int) -> tuple[FrequencyResponse, np.ndarray]:
    """The bins of an H1 estimate away from the PRBS nulls, and the standard deviation of ``ln H`` at each (from the
    coherence pooled over neighbouring bins)."""
    keep = ~clock_null_mask(resp.frequency_hz, fclk)
    coh = resp.coherence if resp.coherence is not None else np.ones(resp.frequency_hz.size)
    sd = h1_log_sd(pooled(coh[keep]), n_averages)
    return FrequencyResponse(resp.frequency_hz[keep], resp.values[keep], coh[keep], resp.name), sd


def run_lab(model: Model, configs: Sequence[str] | None = None, seed: int | None = 0, noise: bool = True,
            quick: bool = False, settings: LabSettings | None = None, fmin: float = 10.0,
            fmax: float = 100e3, points_per_decade: int = 100, keep_records: bool | Sequence[str] = False,
            ) -> LabResult:
    """Run the virtual lab; see :func:`virtual_lab` (this also returns the intermediate results).

    ``keep_records``: True keeps every record, or a list of configuration names to keep.
    """
    st = settings or (LabSettings.quick() if quick else LabSettings())
    names = list(configs) if configs else list(ALL_CONFIGS)
    keep = set(names) if keep_records is True else set(keep_records or ())
    high: dict[str, FrequencyResponse] = {}
    low: dict[str, FrequencyResponse] = {}
    synth: dict[str, FrequencyResponse] = {}
    records: dict[tuple[str, str], LabRecord] = {}
    wall: dict[str, float] = {}
    points = int(round(points_per_decade * math.log10(fmax / fmin))) + 1
    centres = np.geomspace(fmin, fmax, points)
    centres[0], centres[-1] = fmin, fmax
    grid_vals: dict[str, np.ndarray] = {}
    grid_sd: dict[str, np.ndarray] = {}
    supported = np.ones(points, bool)
    lowest = fmin
    for c in names:
        t0 = time.perf_counter()
        cfg = model.configuration(c)
        rname = cfg.responses[0].name
        ft = float(st.transitions.get(rname, 2000.0 / 3))
        estimates = []
        for clock, top in (("high", min(st.chain.fs / 2, 1.1 * fmax)), ("low", min(fmax, 3 * ft))):
            rec = perturb(model, cfg.name, clock, st, seed, noise)
            resp = measure_response(rec, fmax=top, nperseg_fraction=st.nperseg_fraction)
            seg = max(16, int(rec.time_s.size * st.nperseg_fraction))
            n_avg = welch_averages(rec.time_s.size, seg, DEFAULT_OVERLAP)
            if clock == "low":  # the estimate the lowest frequencies come from
                lowest = max(lowest, MIN_BINS_ABOVE_DC * rec.fs / seg)
            estimates.append((resp, *_informative(resp, rec.source.fclk, n_avg)))
            if cfg.name in keep:
                records[(cfg.name, clock)] = rec
            del rec
        (rh, rh_used, sd_h), (rl, rl_used, sd_l) = estimates
        rs = synthesise_two_clock(rh_used, rl_used, ft, name=rname)
        sd = np.concatenate((sd_l[rl_used.frequency_hz < ft], sd_h[rh_used.frequency_hz >= ft]))
        if sd.size != rs.frequency_hz.size:
            raise AssertionError("two-clock synthesis changed the bins")  # pragma: no cover
        grid_vals[rname], grid_sd[rname], m = local_linear(rs.frequency_hz, rs.values, sd, centres)
        supported &= m > 0
        high[rname], low[rname], synth[rname] = rh, rl, rs
        wall[cfg.name] = time.perf_counter() - t0
    rows = supported & (centres >= lowest * (1 - 1e-9))
    if np.count_nonzero(rows) < 2:
        raise CircuitError(f"virtual lab: fewer than 2 frequencies in [{fmin:g}, {fmax:g}] Hz hold an estimate")
    ch = st.chain
    comments = [
        f"virtual lab (thesis 5.1) of model {model.name!r}: {'noisy' if noise else 'noise-free'}, seed {seed}",
        f"high clock PRBS{st.lv.prbs_order} at {st.lv.fclk:g} Hz, low clock PRBS{st.low_prbs_order} at "
        f"{st.low_fclk:g} Hz; fs {ch.fs:g} Hz; anti-alias {ch.aa_cutoff_hz} Hz Chebyshev-I order {ch.aa_order}",
        f"ADC {ch.adc_bits} bit +-{ch.adc_range_v:g} V, noise {ch.noise_rms_v:g} V RMS at ADC input",
        "transitions: " + ", ".join(f"{synth_name} {st.transitions.get(synth_name, 2000 / 3):.1f} Hz"
                                    for synth_name in grid_vals),
        (f"{points_per_decade} points per decade, each a local straight line through the (at most {LOCAL_BINS}) "
         f"nearest bins; frequencies whose band holds no bin away from the PRBS clock nulls "
         f"(+-{100 * NULL_WIDTH:g} % of the clock) are left out, and those below {MIN_BINS_ABOVE_DC} bins above "
         f"DC ({lowest:.3g} Hz)"),
        "NAME_ln_sd: standard deviation of ln|H| and of the phase (rad) from the coherence",
    ]
    measured = MeasuredResponses(centres[rows], {k: v[rows] for k, v in grid_vals.items()}, comments=comments,
                                 uncertainty={k: v[rows] for k, v in grid_sd.items()})
    return LabResult(measured, high, low, synth, st, records, wall)


def virtual_lab(model: Model, configs: Sequence[str] | None = None, seed: int | None = 0, noise: bool = True,
                quick: bool = False, settings: LabSettings | None = None, fmin: float = 10.0,
                fmax: float = 100e3, points_per_decade: int = 100) -> MeasuredResponses:
    """The six measured responses of thesis 5.1, from a model.

    Each configuration is perturbed with the 20 kHz and the 2 kHz clock,
    measured (:func:`perturb`, :func:`measure_response`), combined at the
    transition frequency (:func:`pris_cosim.signals.spectral.synthesise_two_clock`)
    and written at those of ``points_per_decade`` log-spaced points over [fmin, fmax]
    whose band holds a bin of every response away from the PRBS clock nulls
    (from four bins above DC), each value a straight line through the (at
    most five) nearest bins, with the standard deviation of ``ln H`` from the
    coherence in ``uncertainty``.

    Parameters
    ----------
    model : Model
    configs : sequence of str, optional
        Default all six (LVOC, LVSC, HVOC, HVSC, LVHV, HVLV).
    seed : int or None
    noise : bool
        False: noise-free and unquantised (the anti-alias filter stays).
    quick : bool
        PRBS12/PRBS10 instead of PRBS16/PRBS13 (same clocks), see :meth:`LabSettings.quick`.
    settings : LabSettings, optional
        Overrides ``quick``.

    Returns
    -------
    MeasuredResponses
        Responses named Zlvoc ... Rhvlv, on the common log grid.
    """
    return run_lab(model, configs, seed, noise, quick, settings, fmin, fmax, points_per_decade).measured


def write_lab_csv(path: str | Path, measured: MeasuredResponses) -> None:
    """Write the responses in the interfaces CSV format (``NAME_mag,NAME_phase_deg``), atomically."""
    write_response_csv(path, measured, form="magphase")


def round_trip_errors(measured: MeasuredResponses, model: Model, fmin: float = 10.0,
                      fmax: float = 10e3) -> dict[str, tuple[float, float]]:
    """``{name: (max |dB error|, max |phase error| in degrees)}`` against the model's analytic responses."""
    f = measured.frequency_hz
    sel = (f >= fmin * (1 - 1e-9)) & (f <= fmax * (1 + 1e-9))
    configs = [c for c, r in RESPONSE_OF.items() if r in measured.responses and c in model.configurations]
    ref = model.response_set(configs).evaluate(f[sel])
    out = {}
    for name, h in ref.items():
        ratio = measured.responses[name][sel] / h
        out[name] = (float(np.max(np.abs(20 * np.log10(np.abs(ratio))))),
                     float(np.max(np.abs(np.angle(ratio, deg=True)))))
    return out


# ---------------------------------------------------------------------------- plots


def _figure(rows: int, cols: int, size: tuple[float, float]) -> tuple[Any, Any]:
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    return fig, fig.subplots(rows, cols, squeeze=False)


def plot_lab(result: LabResult | MeasuredResponses, model: Model | None, out_dir: str | Path,
             stem: str = "virtual_lab") -> list[Path]:
    """Thesis Figs. 5.5 (LV: Zlvoc, Zlvsc, Rlvhv) and 5.9 (HV: Zhvoc, Zhvsc, Rhvlv) analogues.

    Magnitude and phase of the measured responses against the analytic model;
    with a :class:`LabResult` also the raw 20 kHz and 2 kHz clock estimates and
    the transition frequency. Writes ``<stem>_lv.png`` and ``<stem>_hv.png``.
    """
    meas = result.measured if isinstance(result, LabResult) else result
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    f = meas.frequency_hz
    ref = {}
    if model is not None:
        cfgs = [c for c, r in RESPONSE_OF.items() if r in meas.responses]
        ref = model.response_set(cfgs).evaluate(f)
    paths = []
    for side, group in (("lv", ("Zlvoc", "Zlvsc", "Rlvhv")), ("hv", ("Zhvoc", "Zhvsc", "Rhvlv"))):
        group = [g for g in group if g in meas.responses]
        if not group:
            continue
        fig, ax = _figure(2, len(group), (4.2 * len(group), 6))
        for j, name in enumerate(group):
            am, ap = ax[0, j], ax[1, j]
            if isinstance(result, LabResult):
                for resp, lab, col in ((result.high.get(name), "20 kHz clock", "0.75"),
                                       (result.low.get(name), "2 kHz clock", "tab:orange")):
                    if resp is not None:
                        am.loglog(resp.frequency_hz, resp.mag, color=col, lw=0.6, label=lab)
                        ap.semilogx(resp.frequency_hz, resp.phase_deg, color=col, lw=0.6)
                ft = result.settings.transitions.get(name)
                if ft:
                    for a in (am, ap):
                        a.axvline(ft, color="k", ls=":", lw=0.8)
            am.loglog(f, np.abs(meas.responses[name]), "b.", ms=3, label="virtual lab")
            ap.semilogx(f, np.angle(meas.responses[name], deg=True), "b.", ms=3)
            if name in ref:
                am.loglog(f, np.abs(ref[name]), "r-", lw=1, label="model (analytic)")
                ap.semilogx(f, np.angle(ref[name], deg=True), "r-", lw=1)
            am.set_title(name)
            am.set_ylabel("|Z| (Ohm)" if name.startswith("Z") else "ratio")
            ap.set_ylabel("phase (deg)")
            ap.set_xlabel("frequency (Hz)")
            am.set_xlim(f[0], f[-1])
            ap.set_xlim(f[0], f[-1])
            am.grid(True, which="both", lw=0.3)
            ap.grid(True, which="both", lw=0.3)
        ax[0, 0].legend(fontsize=7)
        p = out / f"{stem}_{side}.png"
        fig.savefig(p, dpi=110)
        paths.append(p)
    return paths


def plot_record(record: LabRecord, out_dir: str | Path, stem: str | None = None,
                t_window: float = 2e-3) -> list[Path]:
    """Waveforms (first ``t_window`` s) and Welch spectra of one record: ``<stem>_waveforms.png``,
    ``<stem>_spectra.png``."""
    from pris_cosim.signals.spectral import welch_psd

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or f"virtual_lab_{record.config.lower()}_{record.clock}"
    n = min(record.time_s.size, max(2, int(t_window * record.fs)))
    chans = [("v_bprbs", record.v_bprbs, "V"), ("v_in", record.v_in, "V"), ("i_in", record.i_in, "A")]
    if record.v_out is not None:
        chans.append(("v_out", record.v_out, "V"))
    fig, ax = _figure(len(chans), 1, (7, 1.8 * len(chans)))
    t_ms = record.time_s[:n] * 1e3
    for k, (name, x, unit) in enumerate(chans):
        a = ax[k, 0]
        if name == "v_bprbs":
            a.step(t_ms, x[:n], where="post", lw=0.8)
        else:
            a.plot(t_ms, x[:n], lw=0.8)
        a.set_ylabel(f"{name} ({unit})")
        a.grid(True, lw=0.3)
    ax[-1, 0].set_xlabel("time (ms)")
    ax[0, 0].set_title(f"{record.config}, PRBS{record.source.prbs_order} at {record.source.fclk:g} Hz")
    p1 = out / f"{stem}_waveforms.png"
    fig.savefig(p1, dpi=110)
    fig, ax = _figure(1, 1, (7, 4))
    a = ax[0, 0]
    seg = max(256, record.time_s.size // 16)
    for name, x, unit in chans:
        f, pxx = welch_psd(x, record.fs, nperseg=seg)
        a.loglog(f[1:], pxx[1:] / np.max(pxx[1:]), lw=0.7, label=name)
    a.axvline(record.source.fclk, color="k", ls=":", lw=0.8)
    a.set_xlabel("frequency (Hz)")
    a.set_ylabel("PSD (normalised)")
    a.set_title(f"Spectra, {record.config}, clock {record.source.fclk:g} Hz (dotted)")
    a.grid(True, which="both", lw=0.3)
    a.legend(fontsize=7)
    p2 = out / f"{stem}_spectra.png"
    fig.savefig(p2, dpi=110)
    return [p1, p2]
