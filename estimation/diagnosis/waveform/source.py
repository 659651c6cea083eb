"""Waveform diagnosis: measured PRIS source waveforms on a resistive load against the simulated source.

The measured record holds the commanded H-bridge voltage ``v_bprbs`` (held
from sample k to k+1), the load voltage ``v_in`` and the source current
``i_in`` (thesis 3.3: the source check on a 15 Ohm load). The baseline is
the PRIS source with its nominal ``R_pris``, ``L_pris``, ``C_pris`` driving
a resistor ``R_load`` (fitted, its exact value being unknown), simulated
exactly for the piecewise-constant ``v_bprbs`` (zero-order hold).

Cost
    ``cost = sum_s mean_k (y_s,model[k] - y_s,measured[k])^2 / var(y_s,measured)``
    over the signals ``s`` in (``v_in``, ``i_in``): the normalised mean
    squared error of each signal, summed (dimensionless; 0 = perfect, about
    1 per signal for a model that explains nothing).

Model extensions (each refitted together with ``R_load``)
    ``series-resistance``  one extra resistance in series with ``R_pris``
                           (tracks, cables, switch on-resistance), Ohm.
    ``component-drift``    scale factors of ``L_pris`` and ``C_pris``.
    ``switch-ringing``     switch parasitics of thesis 5.1.3: ``L_sw`` in
                           series with the bridge, ``C_sw`` across its output
                           (plus a known RC snubber when one is given),
                           fitted as the observed ringing frequency and the
                           characteristic impedance ``sqrt(L_sw / C_sw)``;
                           the starting frequencies come from the spectrum of
                           the baseline residual and a scan of the cost.

The initial state of the source is unknown in a real record (the scope
starts anywhere); for every parameter set it is eliminated by a linear
least-squares fit (variable projection) and counted as fitted parameters.

Selection (as :func:`estimation.diagnosis.diagnose.diagnose_frequency`):
the extension with the lowest ``BIC = N ln(RSS/N) + k ln N`` (``N`` = 2 x
samples, ``RSS`` = the sum of the normalised squared residuals) is named
only if it beats the baseline's BIC by at least 10 and removes at least
20 % of the baseline cost; otherwise the cause is ``none``.

Switching instants: by the waveform contract the commanded level of row k
holds from ``time_s[k]`` to ``time_s[k+1]``. When the sampling rate is not a
multiple of the PRBS clock the bridge really switches between samples; the
instants are then recovered from the regular bit clock (see
:func:`_switch_times`) and simulated exactly, since an error of up to one
sample would otherwise look like an inductance drift.

Speed: on records sampled much faster than the source's dynamics (ringing
cases, e.g. 20 MS/s) the baseline and the slow extensions are fitted on a
subsample that keeps every edge on its grid (at least 200 samples per bit)
and then refined on all samples; every cost and BIC is on all samples.

Simulation: each parameter set's state matrix is diagonalised, the exact ZOH
recurrence of every mode ``z[k+1] = exp(mu h) z[k] + g u[k]`` is run by a
first-order IIR filter, and the free responses (for the initial state) are
the powers ``exp(mu h k)``; parameter sets are batched (the finite-difference
Jacobian is one batch). A defective or ill-conditioned eigenbasis falls back
to :func:`pris_cosim.lab.timedomain.simulate_pwc`.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.measured.formats import Waveforms, read_waveform_csv
from pris_cosim.circuits.mna import MNA, StateSpace
from pris_cosim.lab.timedomain import simulate_pwc

from estimation.diagnosis.fit import DiagnosisError, bic, significant
from estimation.diagnosis.result import DiagnosisOutcome
from estimation.diagnosis.waveform.signals import (NOISE_LP_ORDER, SIGNALS, UNITS, _bit_samples, _decimation, _edges,
    _line_share, _localise, _residual_spectrum, _since_edge, _spectral_peaks, _switch_times, waveform_noise)

__all__ = [
    "WAVEFORM_CAUSES",
    "WaveformFit",
    "WaveformDiagnosis",
    "diagnose_waveforms",
    "load_waveforms",
]

#: Causes the waveform diagnosis can name (besides ``none``).
WAVEFORM_CAUSES = ("series-resistance", "component-drift", "switch-ringing")


#: Fewest samples accepted.
MIN_SAMPLES = 64
#: Selection stops once the cost is within this factor of the noise floor (as for frequency data).
NOISE_MARGIN = 1.25
#: A baseline whose normalised MSE exceeds this for either signal "does not fit at all" (residual RMS
#: 28 % of the signal's standard deviation; a 2x error in L or C gives about 0.06, 10x errors 0.1-0.8).
MAX_BASELINE_NMSE = 0.08
#: ... or whose fitted load differs from the direct estimate sum(v i) / sum(i^2) by more than this.
MAX_LOAD_MISMATCH = 0.2
#: Largest parameter batch simulated at once (memory: batch x samples x 2 x states doubles).
_CHUNK = 8
#: Finite-difference step of the Jacobian, in log-parameter units.
_FD_STEP = 1e-7
#: Lowest ringing frequency searched, in PRBS clock frequencies.
_RING_MIN_FCLK = 20.0
#: Highest ringing frequency searched, as a fraction of the sampling rate.
_RING_MAX_FS = 0.45
_LOAD = "load"


def _log(msg: str, progress: bool) -> None:
    if progress:
        print(f"diagnose: {msg}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------
# Circuit and exact batched simulation
# ---------------------------------------------------------------------------


class _Structure:
    """The compiled source + resistive-load circuit, with or without switch parasitics."""

    def __init__(self, rpris: float, lpris: float, cpris: float, ringing: bool,
                 rsnub: float = 0.0, csnub: float = 0.0):
        dut = Circuit(title="resistive load")
        dut.add("Rload", _LOAD, "0", 15.0)
        snub = ringing and rsnub > 0 and csnub > 0
        settings = SourceSettings(vdc=1.0, prbs_order=4, fclk=1.0, rpris=rpris, lpris=lpris, cpris=cpris,
                                  lsw=1e-6 if ringing else 0.0, csw=1e-9 if ringing else 0.0,
                                  rsnub=rsnub if snub else 0.0, csnub=csnub if snub else 0.0)
        self.circuit = pris_arrangement(dut, _LOAD, settings)
        self.mna = MNA(self.circuit, voltage_inputs=[BRIDGE])
        self.base = {k: float(v) for k, v in self.circuit.resolve(check=False).items()}
        self.out_v = self.mna.outputs.index(f"v({_LOAD})")
        self.i_state = self.mna.states.index(f"i({SENSE_INDUCTOR})")
        self.n = self.mna.n_states

    def state_space(self, overrides: Mapping[str, np.ndarray], P: int) -> StateSpace:
        values = {k: np.full(P, v) for k, v in self.base.items()}
        for k, v in overrides.items():
            values[k.lower()] = np.broadcast_to(np.asarray(v, float), (P,)).copy()
        ss = self.mna.state_space(values)
        Cy = np.zeros((P, 2, self.n))
        Dy = np.zeros((P, 2, 1))
        Cy[:, 0] = ss.C[:, self.out_v]
        Dy[:, 0] = ss.D[:, self.out_v]
        Cy[:, 1, self.i_state] = 1.0
        return StateSpace(ss.A, ss.B, Cy, Dy, list(ss.states), list(ss.inputs), list(SIGNALS))


def _small_product(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``X @ R`` for a tall ``X`` with few columns, without BLAS (whose threads stall on a busy machine)."""
    out = np.zeros((X.shape[0], R.shape[1]))
    for c in range(X.shape[1]):
        for j in range(R.shape[1]):
            if R[c, j] != 0:
                out[:, j] += X[:, c] * R[c, j]
    return out


class _Input:
    """A piecewise-constant input split into runs of constant value (for the closed-form modal response).

    ``switch``: the instants of the level changes in samples from the first
    sample (one per change in ``u``, change ``j`` in ``(k_j - 1, k_j]`` where
    ``k_j`` is the first sample at the new level); default ``k_j`` itself,
    the waveform contract's "row k holds from time_s[k] to time_s[k+1]".
    """

    def __init__(self, u: np.ndarray, switch: np.ndarray | None = None):
        self.u = np.asarray(u, float)
        K = self.u.size
        edges = np.flatnonzero(np.diff(self.u) != 0) + 1
        self.starts = np.concatenate([[0], edges])
        self.lengths = np.diff(np.concatenate([self.starts, [K]]))
        self.levels = self.u[self.starts]
        self.seg = np.repeat(np.arange(self.starts.size), self.lengths)
        self.offset = np.arange(K) - self.starts[self.seg]
        self.max_len = int(self.lengths.max())
        self.K = K
        t_sw = np.concatenate([[0.0], edges.astype(float) if switch is None else np.asarray(switch, float)])
        if t_sw.size != self.starts.size:
            raise ValueError(f"{t_sw.size - 1} switching instants for {edges.size} level changes")
        self.delay = self.starts - t_sw  # samples from each switching instant to the run's first sample, [0, 1)
        self.duration = np.diff(np.concatenate([t_sw, [float(K)]]))  # samples from one switch to the next
        self.exact_grid = switch is None


#: Above this many runs of constant input the modal response is filtered sample by sample instead.
_MAX_RUNS = 4000


def _simulate_one(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, inp: _Input, h: float,
                  want_free: bool, x0: np.ndarray | None = None
                  ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Exact ZOH outputs (K, 2) from the initial state ``x0`` (default zero), and optionally a basis
    (K, 2, n) of the free responses with the matrix (n, n) turning basis coordinates into a state.

    Modal form: ``A = V diag(mu) V^-1``; over a run of constant input ``U``
    each mode follows ``z[k0 + m] = z_ss + exp(mu h m) (z[k0] - z_ss)`` with
    ``z_ss = -b U / mu`` exactly, so only the run boundaries are stepped.
    Only one mode of each complex-conjugate pair is kept (the outputs are
    twice its real part). The free-response basis spans the responses to
    every initial state: one real column per real mode, two per complex pair.
    An ill-conditioned eigenbasis falls back to ``simulate_pwc``.
    """
    n = A.shape[0]
    K = inp.K
    u = inp.u
    mu, V = np.linalg.eig(A)
    ok = (np.all(np.isfinite(mu)) and np.all(mu.real < 0) and np.linalg.cond(V) < 1e8
          and np.all(np.abs(mu) * h > 1e-14))
    if ok:
        W = np.linalg.inv(V)
        keep = np.flatnonzero(mu.imag >= 0)
        if keep.size + np.count_nonzero(mu.imag > 0) != n:  # unpaired complex modes: should not happen
            ok = False
    if ok:
        mu_k = mu[keep]
        m = mu_k.size
        cplx = mu_k.imag > 0
        fac = np.where(cplx, 2.0, 1.0)
        bt = (W @ B[:, 0])[keep]
        CV = (C @ V)[:, keep] * fac[None, :]  # (2, m)
        z0 = np.zeros(m, complex) if x0 is None else (W @ np.asarray(x0, float))[keep]
        z_ss = -np.outer(inp.levels, (bt / mu_k).astype(complex))  # (runs, m)
        runs = inp.starts.size <= _MAX_RUNS or not inp.exact_grid
        if runs:
            pw = np.exp(np.outer(np.arange(inp.max_len + 1) * h, mu_k))  # (max_len + 1, m)
            starts = np.empty_like(z_ss)
            z = z0.copy()  # modal state at the current switching instant
            if inp.exact_grid:
                decay, lag = pw[inp.lengths], None
            else:  # switching between samples: step to the first sample and to the next switch exactly
                decay = np.exp(np.outer(inp.duration * h, mu_k))
                lag = np.exp(np.outer(inp.delay * h, mu_k))
            for j in range(inp.starts.size):
                starts[j] = z if lag is None else z_ss[j] + lag[j] * (z - z_ss[j])
                z = z_ss[j] + decay[j] * (z - z_ss[j])
            zk = z_ss[inp.seg] + pw[inp.offset] * (starts - z_ss)[inp.seg]  # (K, m)
        else:
            lam = np.exp(mu_k * h)
            g = np.expm1(mu_k * h) / mu_k * bt
            zk = np.empty((K, m), complex)
            for i in range(m):
                zk[:, i] = lfilter([0.0, g[i]], [1.0, -lam[i]], u)
            if x0 is not None:
                zk += np.exp(np.outer(np.arange(K) * h, mu_k)) * z0[None, :]
        # Re(zk @ CV.T) as a real product: interleaved (re, im) columns against (Re CV, -Im CV)
        R = np.empty((2 * m, 2))
        R[0::2] = CV.real.T
        R[1::2] = -CV.imag.T
        y = _small_product(np.ascontiguousarray(zk).view(np.float64), R) + u[:, None] * D[:, 0][None, :]
        if not want_free:
            return y, None, None
        if runs:
            lamk = np.exp(mu_k * h * inp.starts[:, None])[inp.seg] * pw[inp.offset]  # exp(mu h k)
        else:
            lamk = np.exp(np.outer(np.arange(K) * h, mu_k))
        cols = []
        to_state = np.zeros((n, n))
        Vk = V[:, keep] * fac[None, :]
        for i in range(m):
            q = lamk[:, i, None] * CV[None, :, i]  # (K, 2)
            to_state[:, len(cols)] = Vk[:, i].real  # z0_i = 1: Re(fac V_i)
            cols.append(q.real)
            if cplx[i]:  # z0_i = -1j: Re(q * -1j) = q.imag
                to_state[:, len(cols)] = (Vk[:, i] * -1j).real
                cols.append(q.imag)
        return y, np.stack(cols, axis=2), to_state
    ss = StateSpace(A[None], B[None], C[None], D[None], [], [], list(SIGNALS))
    _, y = simulate_pwc(ss, u, h, x0=None if x0 is None else np.asarray(x0, float))
    if not want_free:
        return y, None, None
    free = np.empty((K, 2, n))
    zero = np.zeros(K)
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        free[:, :, j] = simulate_pwc(ss, zero, h, x0=e)[1]
    return y, free, np.eye(n)


# ---------------------------------------------------------------------------
# Candidates
# ---------------------------------------------------------------------------


@dataclass
class _Candidate:
    """A model: baseline (cause ``none``) or baseline plus one extension."""

    cause: str
    names: tuple[str, ...]  # internal (log) parameter names of the extension
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    ringing: bool = False

    def overrides(self, th: np.ndarray, nominal: Mapping[str, float],
                  snubber: tuple[float, float]) -> dict[str, np.ndarray]:
        """Element values (P,) for extension parameters ``th`` (P, q)."""
        R, L, C = nominal["rpris"], nominal["lpris"], nominal["cpris"]
        if self.cause == "series-resistance":
            return {"rpris": R * np.exp(th[:, 0])}
        if self.cause == "component-drift":
            return {"lpris": L * np.exp(th[:, 0]), "cpris": C * np.exp(th[:, 1])}
        if self.cause == "switch-ringing":
            lsw, csw = _lc_from_ringing(np.exp(th[:, 0]), np.exp(th[:, 1]), snubber[1], L)
            return {"lsw": lsw, "csw": csw}
        return {}

    def extra(self, th: np.ndarray, nominal: Mapping[str, float], snubber: tuple[float, float]) -> dict[str, float]:
        """Fitted extension parameters, reported with their units in the names."""
        th = np.asarray(th, float)
        R, L, C = nominal["rpris"], nominal["lpris"], nominal["cpris"]
        if self.cause == "series-resistance":
            r = R * math.exp(th[0])
            return {"r_series_ohm": r - R, "r_total_ohm": r, "r_series_percent_of_nominal": 100 * (r / R - 1)}
        if self.cause == "component-drift":
            kl, kc = math.exp(th[0]), math.exp(th[1])
            return {"l_scale": kl, "c_scale": kc, "lpris_h": L * kl, "cpris_f": C * kc,
                    "l_drift_percent": 100 * (kl - 1), "c_drift_percent": 100 * (kc - 1)}
        if self.cause == "switch-ringing":
            f_obs, z0 = math.exp(th[0]), math.exp(th[1])
            lsw, csw = (float(a[0]) for a in _lc_from_ringing(np.array([f_obs]), np.array([z0]), snubber[1], L))
            out = {"lsw_h": lsw, "csw_f": csw, "z0_ohm": z0,
                   "f_ring_hz": 1 / (2 * math.pi * math.sqrt(lsw * csw)), "f_ring_observed_hz": f_obs}
            if snubber[1] > 0:
                out.update({"f_ring_snubbed_hz": 1 / (2 * math.pi * math.sqrt(lsw * (csw + snubber[1]))),
                            "rsnub_ohm": snubber[0], "csnub_f": snubber[1]})
            return out
        return {}


def _lc_from_ringing(f_obs: np.ndarray, z0: np.ndarray, csnub: float, lpris: float) -> tuple[np.ndarray, np.ndarray]:
    """``L_sw``, ``C_sw`` from the observed ringing frequency and ``z0 = sqrt(L_sw / C_sw)``.

    The ringing seen in ``v_in``, ``i_in`` is that of ``C_sw`` (plus the snubber
    capacitance) against ``L_sw`` in parallel with ``L_pris`` (the rest of the
    source is negligible at MHz): ``f_obs = 1 / (2 pi sqrt(L_e (C_sw + C_snub)))``
    with ``L_e = L_sw L_pris / (L_sw + L_pris)`` (thesis (5.1), (5.2) with the
    load of the source), solved for ``C_sw`` with ``L_sw = z0^2 C_sw``.
    """
    w2 = (2 * np.pi * f_obs) ** 2
    z2 = z0 ** 2
    a = z2 * lpris
    b = z2 * (lpris * csnub - 1.0 / w2)
    c = -lpris / w2
    csw = 2 * (-c) / (b + np.sqrt(b * b - 4 * a * c))  # the positive root, cancellation-free
    return z2 * csw, csw


class _Combined(_Candidate):
    """Several extensions together: their parameters side by side, their element values merged."""

    def __init__(self, parts: Sequence[_Candidate]):
        super().__init__("+".join(p.cause for p in parts), tuple(n for p in parts for n in p.names),
                         tuple(v for p in parts for v in p.lower), tuple(v for p in parts for v in p.upper),
                         any(p.ringing for p in parts))
        self.parts = list(parts)

    def _slices(self) -> list[slice]:
        edges = np.cumsum([0] + [len(p.names) for p in self.parts])
        return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]

    def overrides(self, th: np.ndarray, nominal: Mapping[str, float],
                  snubber: tuple[float, float]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for p, sl in zip(self.parts, self._slices()):
            out.update(p.overrides(th[:, sl], nominal, snubber))
        return out

    def extra(self, th: np.ndarray, nominal: Mapping[str, float], snubber: tuple[float, float]) -> dict[str, Any]:
        th = np.asarray(th, float)
        return {p.cause: p.extra(th[sl], nominal, snubber) for p, sl in zip(self.parts, self._slices())}


def _candidates(fmin_ring: float, fmax_ring: float) -> list[_Candidate]:
    out = [
        _Candidate("series-resistance", ("ln_r_scale",), (math.log(0.5),), (math.log(20.0),)),
        _Candidate("component-drift", ("ln_l_scale", "ln_c_scale"), (math.log(0.1),) * 2, (math.log(10.0),) * 2),
    ]
    if fmax_ring > 1.2 * fmin_ring:
        out.append(_Candidate("switch-ringing", ("ln_f_ring", "ln_z0"), (math.log(fmin_ring), math.log(1.0)),
                              (math.log(fmax_ring), math.log(1e4)), ringing=True))
    return out


# ---------------------------------------------------------------------------
# Fitting
# ---------------------------------------------------------------------------


@dataclass
class WaveformFit:
    """Outcome of one fit.

    Attributes
    ----------
    cause : str
        ``none`` for the baseline, else the extension's cause.
    values : dict
        Fitted source and load values in SI units (``r_load``, ``rpris``,
        ``lpris``, ``cpris``, ``lsw``, ``csw``, ``rsnub``, ``csnub``).
    extra : dict
        Fitted extension parameters (units in the names).
    cost : float
        Sum over ``v_in``, ``i_in`` of the normalised MSE.
    cost_per_signal : dict
        The two terms of ``cost``.
    rss, n_residuals, n_params : float, int, int
        Normalised residual sum of squares, ``2 K`` and the fitted parameter
        count (load, extension, initial states) for the information criterion.
    predicted : dict
        Model ``v_in`` (V) and ``i_in`` (A).
    x0 : numpy.ndarray
        Fitted initial condition, as coordinates in the basis of free responses.
    """

    cause: str
    values: dict[str, float]
    extra: dict[str, float]
    cost: float
    cost_per_signal: dict[str, float]
    rss: float
    n_residuals: int
    n_params: int
    predicted: dict[str, np.ndarray] = field(repr=False)
    x0: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    theta: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    nfev: int = 0
    wall_s: float = 0.0
    causes: list[str] = field(default_factory=list)

    @property
    def bic(self) -> float:
        """Bayesian information criterion ``N ln(RSS/N) + k ln N``."""
        return bic(self.rss, self.n_residuals, self.n_params)


class _Problem:
    """Measured record, nominal source and the machinery to evaluate and fit candidates."""

    def __init__(self, w: Waveforms, nominal: Mapping[str, float], u: np.ndarray, r_load: float | None,
                 snubber: tuple[float, float], fit_initial_state: bool = True, switch: np.ndarray | None = None):
        self.h = w.dt
        self.u = u
        self.inp = _Input(u, switch)
        self.K = u.size
        self.y = np.stack([w.v_in, w.i_in], axis=1)
        self.sigma = np.array([np.std(w.v_in), np.std(w.i_in)])
        self.weight = 1.0 / (self.sigma * math.sqrt(self.K))
        self.nominal = dict(nominal)
        self.snubber = snubber
        self.fit_x0 = fit_initial_state
        self.r_load_fixed = r_load
        r0 = float(np.dot(w.v_in, w.i_in) / np.dot(w.i_in, w.i_in))
        self.r_load0 = r_load if r_load is not None else r0
        self._structures: dict[bool, _Structure] = {}

    def structure(self, ringing: bool) -> _Structure:
        if ringing not in self._structures:
            n = self.nominal
            self._structures[ringing] = _Structure(n["rpris"], n["lpris"], n["cpris"], ringing, *self.snubber)
        return self._structures[ringing]

    # -- parameters: [ln R_load (unless fixed), extension...]
    def split(self, cand: _Candidate, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        th = np.atleast_2d(th)
        if self.r_load_fixed is None:
            return np.exp(th[:, 0]), th[:, 1:]
        return np.full(th.shape[0], self.r_load_fixed), th

    def evaluate(self, cand: _Candidate, thetas: np.ndarray, full: bool = False, project: bool = True,
                 x0: np.ndarray | None = None):
        """Normalised residual vectors (P, 2K) for parameter vectors ``thetas`` (P, p).

        ``project``: fit the initial state of every parameter set (variable
        projection); otherwise use ``x0`` (a state, default zero) for all.
        With ``full``, also the predictions (P, K, 2) and the initial states (P, n).
        """
        thetas = np.atleast_2d(np.asarray(thetas, float))
        P = thetas.shape[0]
        st = self.structure(cand.ringing)
        project = project and self.fit_x0
        res = np.empty((P, 2 * self.K))
        preds = np.empty((P, self.K, 2)) if full else None
        x0s = np.zeros((P, st.n))
        for c0 in range(0, P, _CHUNK):
            sl = slice(c0, min(P, c0 + _CHUNK))
            rl, ext = self.split(cand, thetas[sl])
            over = cand.overrides(ext, self.nominal, self.snubber)
            over["rload"] = rl
            ss = st.state_space(over, rl.size)
            for j in range(rl.size):
                x_init = None if (project or x0 is None) else x0
                y, free, to_state = _simulate_one(ss.A[j], ss.B[j], ss.C[j], ss.D[j], self.inp, self.h, project,
                                                  x_init)
                if project:
                    coef = np.zeros(st.n)
                    M2 = (free * self.weight[None, :, None]).reshape(2 * self.K, st.n)
                    r = ((self.y - y) * self.weight).ravel()
                    G = M2.T @ M2
                    c = M2.T @ r
                    d = np.sqrt(np.maximum(np.diag(G), 0.0))
                    live = d > 1e-9 * max(d.max(), 1e-300)
                    if live.any():
                        Gs = G[np.ix_(live, live)] / np.outer(d[live], d[live])
                        evals, evecs = np.linalg.eigh(Gs)
                        inv = np.where(evals > 1e-12 * evals.max(), 1.0 / np.where(evals > 0, evals, 1.0), 0.0)
                        coef[live] = (evecs @ (inv * (evecs.T @ (c[live] / d[live])))) / d[live]
                        y = y + _small_product(free.reshape(2 * self.K, st.n), coef[:, None]).reshape(self.K, 2)
                    x0s[c0 + j] = to_state @ coef
                elif x_init is not None:
                    x0s[c0 + j] = x_init
                res[c0 + j] = ((y - self.y) * self.weight).ravel()
                if full:
                    preds[c0 + j] = y
        if full:
            return res, preds, x0s
        return res

    def embed_state(self, x0: np.ndarray, from_ringing: bool, to_ringing: bool) -> np.ndarray:
        """An initial state of one structure in the state order of another (matched by state name)."""
        a, b = self.structure(from_ringing).mna.states, self.structure(to_ringing).mna.states
        out = np.zeros(len(b))
        for i, name in enumerate(a):
            if name in b:
                out[b.index(name)] = x0[i]
        return out

    def costs(self, cand: _Candidate, thetas: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Costs of many parameter vectors with one fixed initial state (a scan)."""
        return np.sum(self.evaluate(cand, thetas, project=False, x0=x0) ** 2, axis=1)

    def bounds(self, cand: _Candidate) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = list(cand.lower), list(cand.upper)
        if self.r_load_fixed is None:
            lo = [math.log(self.r_load0 / 10)] + lo
            hi = [math.log(self.r_load0 * 10)] + hi
        return np.array(lo), np.array(hi)

    def fit(self, cand: _Candidate, starts: Sequence[np.ndarray], max_nfev: int = 60) -> WaveformFit:
        """Least-squares fit from each start; the lowest cost wins."""
        t0 = time.perf_counter()
        lo, hi = self.bounds(cand)
        best_x, best_cost, nfev = None, np.inf, 0
        if lo.size == 0:  # nothing to fit (baseline with a given load)
            return self.result(cand, np.zeros(0), 0, time.perf_counter() - t0)
        for x0 in starts:
            x0 = np.clip(np.asarray(x0, float), lo + 1e-9, hi - 1e-9)
            cache: dict[str, Any] = {}

            def fun(x):
                e, _, xs = self.evaluate(cand, x[None], full=True)
                cache["x"], cache["e"], cache["x0"] = x.copy(), e[0], xs[0]
                return e[0]

            def jac(x):
                if not ("x" in cache and np.array_equal(cache["x"], x)):
                    fun(x)
                e0, xs = cache["e"], cache["x0"]
                steps = np.where(x + _FD_STEP <= hi, _FD_STEP, -_FD_STEP)
                pert = x[None, :] + np.diag(steps)
                # initial state held at its projection for x (its optimum): the cost gradient stays exact
                E = self.evaluate(cand, pert, project=False, x0=xs if self.fit_x0 else None)
                return ((E - e0[None, :]) / steps[:, None]).T

            sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", max_nfev=max_nfev,
                                xtol=1e-10, ftol=1e-10, gtol=1e-10)
            nfev += sol.nfev
            cost = float(np.sum(sol.fun ** 2))
            if cost < best_cost:
                best_x, best_cost = sol.x, cost
        return self.result(cand, best_x, nfev, time.perf_counter() - t0)

    def result(self, cand: _Candidate, x: np.ndarray, nfev: int = 0, wall: float = 0.0) -> WaveformFit:
        res, pred, x0 = self.evaluate(cand, np.asarray(x, float)[None], full=True)
        e = res[0].reshape(self.K, 2)
        # per-signal normalised MSE: mean(err^2) / var = sum((err w)^2) with w = 1 / (sigma sqrt K)
        per = {s: float(np.sum(e[:, j] ** 2)) for j, s in enumerate(SIGNALS)}
        cost = float(sum(per.values()))
        rl, ext = self.split(cand, np.asarray(x, float))
        values = dict(self.nominal)
        values.update({"r_load": float(rl[0]), "lsw": 0.0, "csw": 0.0, "rsnub": 0.0, "csnub": 0.0})
        for k, v in cand.overrides(ext, self.nominal, self.snubber).items():
            values[k] = float(np.asarray(v).ravel()[0])
        if cand.ringing and self.snubber[1] > 0:
            values["rsnub"], values["csnub"] = self.snubber
        n_par = len(cand.names) + (self.r_load_fixed is None) + (x0.shape[1] if self.fit_x0 else 0)
        return WaveformFit(
            causes=[p.cause for p in getattr(cand, "parts", [cand])] if cand.cause != "none" else [],
            cause=cand.cause, values=values, extra=cand.extra(ext[0], self.nominal, self.snubber) if ext.size else {},
            cost=cost, cost_per_signal=per, rss=float(np.sum(e ** 2) * self.K), n_residuals=2 * self.K,
            n_params=int(n_par), predicted={s: pred[0][:, j] for j, s in enumerate(SIGNALS)}, x0=x0[0],
            theta=np.asarray(x, float), nfev=nfev, wall_s=wall)

    def start(self, cand: _Candidate, ext: Sequence[float]) -> np.ndarray:
        head = [] if self.r_load_fixed is not None else [math.log(self.r_load0)]
        return np.array(head + list(ext), float)


# ---------------------------------------------------------------------------
# Evidence
# ---------------------------------------------------------------------------


@dataclass
class WaveformDiagnosis(DiagnosisOutcome):
    """Result of a waveform diagnosis (see :meth:`as_json` for the command-line keys)."""

    baseline: WaveformFit
    best: WaveformFit | None
    fits: list[WaveformFit]
    time_s: np.ndarray
    v_bprbs: np.ndarray
    measured: dict[str, np.ndarray]
    nominal: dict[str, float]

    @property
    def gain(self) -> float:
        """Fraction of the baseline cost removed by the named extensions (0 for ``none``)."""
        return 0.0 if self.best is None else 1 - self.best.cost / self.baseline.cost

    @property
    def extended(self) -> WaveformFit:
        """The chosen fit, or the baseline when the cause is ``none``."""
        return self.best if self.best is not None else self.baseline

    def candidates(self) -> list[dict[str, Any]]:
        return [{"cause": r.cause, "cost": r.cost, "gain": 1 - r.cost / self.baseline.cost, "bic": r.bic,
                 "delta_bic": self.baseline.bic - r.bic, "n_params": r.n_params, "extra": r.extra,
                 "wall_s": r.wall_s} for r in self.fits]

    def as_json(self) -> dict[str, Any]:
        """The keys of the ``diagnose`` command, as for frequency data (``cause``, ``causes``, ``steps``,
        ``candidates``, ``unexplained``, ``noise_floor``, ``gain``, ``baseline_cost``, ``extended_cost``) plus the
        fitted values and the evidence."""
        ext = self.extended
        return {
            "cause": self.cause,
            "causes": list(self.causes),
            "steps": list(self.steps),
            "candidates": self.candidates(),
            "unexplained": list(self.unexplained),
            "noise_floor": self.noise.get("cost", 0.0),
            "noise": self.noise,
            "baseline_cost": self.baseline.cost,
            "extended_cost": ext.cost,
            "gain": self.gain,
            "baseline_bic": self.baseline.bic,
            "fitted_extension": self.best.extra if self.best else {},
            "baseline_values": self.baseline.values,
            "extended_values": self.best.values if self.best else {},
            "evidence": self.evidence,
            "realisation": {"kind": "source-settings",
                            "note": "SourceSettings fields (rpris, lpris, cpris, lsw, csw, rsnub, csnub) and the "
                                    "load resistance that reproduce the measurement",
                            "values": ext.values},
            "wall_s": self.wall_s,
        }


def load_waveforms(data: Waveforms | Mapping[str, Any] | str | os.PathLike) -> Waveforms:
    """A :class:`Waveforms` from a record, a mapping of columns or a waveform CSV path.

    Raises
    ------
    DiagnosisError
        Missing columns, unreadable file, non-uniform sampling, NaNs.
    """
    if isinstance(data, Waveforms):
        return data
    if isinstance(data, (str, os.PathLike)):
        try:
            return read_waveform_csv(data)
        except (ValueError, OSError) as exc:
            raise DiagnosisError(" ".join(str(exc).split())) from None
    if isinstance(data, Mapping):
        missing = [c for c in ("time_s", "v_bprbs", "v_in", "i_in") if c not in data]
        if missing:
            raise DiagnosisError(f"waveform data lacks column(s) {', '.join(missing)} "
                                 "(need time_s, v_bprbs, v_in, i_in)")
        try:
            return Waveforms(data["time_s"], data["v_bprbs"], data["v_in"], data["i_in"], data.get("v_out"))
        except (ValueError, TypeError) as exc:
            raise DiagnosisError(f"bad waveform data: {' '.join(str(exc).split())}") from None
    raise DiagnosisError(f"waveform data must be a Waveforms, a mapping of columns or a CSV path, "
                         f"got {type(data).__name__}")


def _check_positive(**values: float | None) -> None:
    for name, v in values.items():
        if v is None:
            continue
        if not (isinstance(v, (int, float, np.floating)) and math.isfinite(v) and v > 0):
            raise DiagnosisError(f"{name} must be a positive number (got {v!r})")


def diagnose_waveforms(
    waveforms: Waveforms | Mapping[str, Any] | str | os.PathLike,
    rpris: float,
    lpris: float,
    cpris: float,
    vdc: float | None = None,
    r_load: float | None = None,
    rsnub: float = 0.0,
    csnub: float = 0.0,
    min_delta_bic: float = 10.0,
    min_gain: float = 0.2,
    min_step_gain: float = 0.2,
    max_causes: int = 3,
    fit_initial_state: bool = True,
    edge_timing: str = "auto",
    progress: bool = True,
) -> WaveformDiagnosis:
    """Diagnose measured PRIS waveforms of the source driving a resistive load.

    Parameters
    ----------
    waveforms : Waveforms, mapping or path
        ``time_s`` (s, uniform), ``v_bprbs`` (V, commanded bridge level held
        from row k to k+1), ``v_in`` (V, load voltage), ``i_in`` (A).
    rpris, lpris, cpris : float, Ohm, H, F
        Nominal series R, L, C of the source.
    vdc : float, V, optional
        DC-link voltage; when given the commanded levels are taken as
        ``sign(v_bprbs) * vdc`` (for records whose ``v_bprbs`` column is a
        logic level or a scaled copy).
    r_load : float, Ohm, optional
        Load resistance if known exactly (default: fitted).
    rsnub, csnub : float, Ohm, F
        RC snubber across the bridge output, if fitted to the source (used by
        the ``switch-ringing`` extension; it has no effect on an ideal bridge).
    min_delta_bic, min_gain : float
        Thresholds for naming a cause instead of ``none``.
    min_step_gain : float
        Fraction of the remaining cost a further cause must remove.
    max_causes : int
        Most causes named.
    fit_initial_state : bool
        Fit the source's initial state (default); else start from rest.
    edge_timing : ``auto`` or ``sample``
        ``sample``: the bridge switches on the samples (the waveform
        contract). ``auto`` (default): the same when the edges sit on a whole
        number of samples per bit; otherwise the switching instants between
        samples are recovered from the regular bit clock (a record whose
        sampling rate is not a multiple of the clock frequency), which the
        exact simulation then honours.
    progress : bool
        Progress lines on stderr.

    Returns
    -------
    WaveformDiagnosis

    Raises
    ------
    DiagnosisError
        Bad input (too few samples, non-uniform sampling, missing columns, no
        switching, non-positive nominal values) or a baseline that does not
        fit the data at all.
    """
    t_start = time.perf_counter()
    _check_positive(rpris=rpris, lpris=lpris, cpris=cpris, vdc=vdc, r_load=r_load)
    if edge_timing not in ("auto", "sample"):
        raise DiagnosisError(f"edge_timing must be 'auto' or 'sample' (got {edge_timing!r})")
    if rsnub < 0 or csnub < 0 or (rsnub > 0) != (csnub > 0):
        raise DiagnosisError("snubber needs both rsnub > 0 and csnub > 0 (or neither)")
    w = load_waveforms(waveforms)
    K = w.n_samples
    if K < MIN_SAMPLES:
        raise DiagnosisError(f"too few samples: {K} (need at least {MIN_SAMPLES})")
    u = np.sign(w.v_bprbs) * vdc if vdc is not None else np.array(w.v_bprbs, float)
    edges = _edges(u)
    if edges.size < 2:
        raise DiagnosisError("v_bprbs switches fewer than twice: not a PRIS record (need the commanded bridge voltage)")
    for s in SIGNALS:
        if not np.std(getattr(w, s)) > 0:
            raise DiagnosisError(f"{s} is constant: nothing to compare")
    nominal = {"rpris": float(rpris), "lpris": float(lpris), "cpris": float(cpris)}
    switch, timing = _switch_times(u) if edge_timing == "auto" else (None, {"mode": "sample", "reason": "requested"})
    if timing["mode"] == "clock":
        _log(f"switching between samples: bit clock {timing['samples_per_bit']:.4f} samples per bit", progress)
    prob = _Problem(w, nominal, u, r_load, (float(rsnub), float(csnub)), fit_initial_state, switch)
    if not prob.r_load0 > 0:
        raise DiagnosisError("v_in and i_in are not positively correlated: not a resistive load "
                             "(or i_in has the wrong sign)")
    h = w.dt
    bit_s = _bit_samples(u) * h
    fclk = 1.0 / bit_s
    fmin_ring, fmax_ring = _RING_MIN_FCLK * fclk, _RING_MAX_FS / h

    # fits of the slow effects on a subsampled record (exact: the edges stay on its grid), polished on all samples
    q, k0 = _decimation(u) if switch is None else (max(1, int(timing["samples_per_bit"] // 200)), 0)
    fast = prob
    if q > 1:
        ws = Waveforms(w.time_s[k0::q], u[k0::q], w.v_in[k0::q], w.i_in[k0::q])
        sw = None if switch is None else switch / q
        if sw is not None and _edges(u[k0::q]).size != sw.size:
            q = 1
        else:
            fast = _Problem(ws, nominal, u[k0::q], r_load, (float(rsnub), float(csnub)), fit_initial_state, sw)
    if q > 1:
        _log(f"slow effects fitted on every {q}th sample, then refined on all {K}", progress)

    def two_stage(cand: _Candidate, starts: list[np.ndarray], max_nfev: int = 60) -> WaveformFit:
        if fast is prob:
            return prob.fit(cand, starts, max_nfev)
        first = fast.fit(cand, starts, max_nfev)
        return prob.fit(cand, [first.theta], max_nfev=6)

    # ---- baseline
    base_c = _Candidate("none", (), (), ())
    baseline = two_stage(base_c, [prob.start(base_c, [])], max_nfev=40)
    _log(f"baseline fitted: cost {baseline.cost:.4g} (R_load {baseline.values['r_load']:.4g} Ohm) "
         f"in {baseline.wall_s:.1f} s", progress)
    worst = max(baseline.cost_per_signal.values())
    r_direct = prob.r_load0 if r_load is None else float(np.dot(w.v_in, w.i_in) / np.dot(w.i_in, w.i_in))
    mismatch = abs(baseline.values["r_load"] / r_direct - 1)
    if worst <= MAX_BASELINE_NMSE and mismatch > MAX_LOAD_MISMATCH:
        raise DiagnosisError(
            f"the baseline does not fit the data at all (fitted load {baseline.values['r_load']:.4g} Ohm against "
            f"v_in/i_in = {r_direct:.4g} Ohm); check the nominal R, L, C, the units and the columns")
    if worst > MAX_BASELINE_NMSE:
        bad = max(baseline.cost_per_signal, key=baseline.cost_per_signal.get)
        raise DiagnosisError(
            f"the baseline does not fit the data at all ({bad}: residual RMS {100 * math.sqrt(worst):.0f} % of the "
            f"signal's standard deviation after fitting the load); "
            "check the nominal R, L, C, the units and the columns")
    e_base = np.stack([(baseline.predicted[s] - getattr(w, s)) / prob.sigma[j] for j, s in enumerate(SIGNALS)], axis=1)
    f_grid, S = _residual_spectrum(e_base, h)

    # ---- candidates
    results: list[WaveformFit] = []
    rl0 = baseline.theta[:1] if r_load is None else np.zeros(0)
    for cand in _candidates(fmin_ring, fmax_ring):
        t = time.perf_counter()
        head = list(rl0)
        if cand.cause == "series-resistance":
            res = two_stage(cand, [np.array(head + [0.0]), np.array(head + [math.log(1.2)])])
        elif cand.cause == "component-drift":
            res = two_stage(cand, [np.array(head + [0.0, 0.0]), np.array(head + [math.log(1.2), math.log(0.8)]),
                                  np.array(head + [math.log(0.8), math.log(1.2)])])
        else:
            res = _fit_ringing(prob, cand, head, f_grid, S, fmin_ring, fmax_ring, baseline, progress)
        res.wall_s = time.perf_counter() - t
        results.append(res)
        _log(f"{cand.cause}: cost {res.cost:.4g}, gain {1 - res.cost / baseline.cost:.3f}, nfev {res.nfev}, "
             f"dBIC {baseline.bic - res.bic:.1f} ({res.wall_s:.1f} s)", progress)

    # ---- forward selection: the best cause by BIC, then each other cause refitted together with those named
    noise = waveform_noise(w)
    parts = {c.cause: c for c in _candidates(fmin_ring, fmax_ring)}
    singles = {r.cause: r for r in results}
    current, chosen, steps = baseline, None, []
    pool = dict(singles)
    while pool and len(current.causes) < max_causes:
        if current.cost <= NOISE_MARGIN * noise["cost"]:
            _log("cost at the noise floor: no further cause", progress)
            break
        best = min(pool.values(), key=lambda r: r.bic)
        need = min_gain if chosen is None else min_step_gain
        if not significant(current.bic, current.cost, best.bic, best.cost, min_delta_bic, need):
            break
        new = next(c for c in best.causes if c not in current.causes)
        steps.append({"cause": new, "gain": 1 - best.cost / current.cost, "delta_bic": current.bic - best.bic,
                      "cost": best.cost, "total_gain": 1 - best.cost / baseline.cost, "model": best.cause})
        _log(f"step {len(steps)}: {new} (gain {steps[-1]['gain']:.3f}, dBIC {steps[-1]['delta_bic']:.1f})", progress)
        current = chosen = best
        pool = {}
        if current.cost <= NOISE_MARGIN * noise["cost"] or len(current.causes) >= max_causes:
            break
        for cause, single in singles.items():
            if cause in current.causes:
                continue
            t = time.perf_counter()
            cand = _Combined([parts[c] for c in current.causes] + [parts[cause]])
            n_head = 0 if r_load is not None else 1
            start = np.concatenate([current.theta, single.theta[n_head:]])
            fitter = prob if cand.ringing else None
            res = (prob.fit(cand, [start], max_nfev=30) if fitter is not None else two_stage(cand, [start]))
            res.wall_s = time.perf_counter() - t
            _log(f"  + {cause}: cost {res.cost:.4g}, gain {1 - res.cost / current.cost:.3f}, "
                 f"dBIC {current.bic - res.bic:.1f} ({res.wall_s:.1f} s)", progress)
            if res.cost < current.cost:
                pool[cause] = res
    measured = {s: getattr(w, s) for s in SIGNALS}
    diag = WaveformDiagnosis(chosen.causes[0] if chosen else "none", baseline, chosen, results, w.time_s, u,
                             measured, nominal, causes=list(chosen.causes) if chosen else [], steps=steps, noise=noise)
    diag.unexplained = _unexplained(diag.extended, measured, noise)
    e_after = None
    if chosen is not None:
        e_after = np.stack([(chosen.predicted[s] - measured[s]) / prob.sigma[j] for j, s in enumerate(SIGNALS)], axis=1)
    rms = {}
    for j, s in enumerate(SIGNALS):
        sig_rms = float(np.sqrt(np.mean(measured[s] ** 2)))
        b = float(np.sqrt(np.mean((baseline.predicted[s] - measured[s]) ** 2)))
        a = float(np.sqrt(np.mean((diag.extended.predicted[s] - measured[s]) ** 2)))
        rms[s] = {"unit": UNITS[s], "signal_rms": sig_rms, "before": b, "after": a,
                  "before_percent_of_signal_rms": 100 * b / sig_rms, "after_percent_of_signal_rms": 100 * a / sig_rms}
    peak = _spectral_peaks(f_grid, S, fmin_ring, fmax_ring, 1) if fmax_ring > fmin_ring else []
    diag.evidence = {
        "cost_definition": "sum over v_in and i_in of mean squared error / variance of the measured signal",
        "samples": K, "fs_hz": w.fs, "bit_s": bit_s, "switching_edges": int(edges.size),
        "edge_timing": timing,
        "r_load_ohm": {"baseline": baseline.values["r_load"], "extended": diag.extended.values["r_load"],
                       "given": r_load},
        "residual_rms": rms,
        "localisation": _localise(u, h, e_base, e_after, _line_share(f_grid, S, peak[0] if peak else None),
                                  peak[0] if peak else None),
        "residual_spectrum_peak_hz": peak[0] if peak else None,
        "ringing_search_band_hz": [fmin_ring, fmax_ring] if fmax_ring > 1.2 * fmin_ring else None,
        "gain_per_signal": ({s: 1 - chosen.cost_per_signal[s] / baseline.cost_per_signal[s] for s in SIGNALS}
                            if chosen else {}),
        "criterion": (f"forward selection by BIC = N ln(RSS/N) + k ln N (N = 2 x samples, normalised residuals; k "
                      f"counts the load, the extensions and the initial states): a cause is named if dBIC >= "
                      f"{min_delta_bic} and it removes at least {min_gain} (first cause) or {min_step_gain} (further "
                      f"causes) of the cost left; stop at {NOISE_MARGIN} x the noise floor"),
    }
    if chosen is not None and "switch-ringing" in chosen.causes:
        ring = chosen.extra if chosen.cause == "switch-ringing" else chosen.extra["switch-ringing"]
        diag.evidence["ringing"] = _ringing_evidence(ring)
    diag.wall_s = time.perf_counter() - t_start
    _log(f"cause: {diag.cause} (gain {diag.gain:.3f}) in {diag.wall_s:.1f} s", progress)
    return diag


#: Order of the linear prediction that annihilates the source's own response between switching edges.
def _unexplained(fit: WaveformFit, measured: Mapping[str, np.ndarray], noise: Mapping[str, Any],
                 factor: float = 2.0) -> list[dict[str, Any]]:
    """Signals whose residual RMS still stands ``factor`` times above the noise RMS."""
    out = []
    for s in SIGNALS:
        e = fit.predicted[s] - measured[s]
        rms = float(np.sqrt(np.mean(e * e)))
        sigma = max(float(noise["per_signal"].get(s, 0.0)), 1e-300)
        if rms > factor * sigma:
            out.append({"signal": s, "unit": UNITS[s], "rms": rms, "noise_rms": sigma, "above_noise": rms / sigma})
    out.sort(key=lambda b: -b["above_noise"])
    return out


def _ringing_evidence(x: Mapping[str, float]) -> dict[str, Any]:
    out = {"f_ring_hz": x["f_ring_hz"], "lsw_h": x["lsw_h"], "csw_f": x["csw_f"],
           "relation": "f_r = 1 / (2 pi sqrt(Lsw Csw)), thesis (5.1)"}
    if "f_ring_snubbed_hz" in x:
        out["f_ring_snubbed_hz"] = x["f_ring_snubbed_hz"]
        out["relation"] += "; with the snubber f_r2 = 1 / (2 pi sqrt(Lsw (Csw + Cs))), (5.2)"
    z0 = math.sqrt(x["lsw_h"] / x["csw_f"])
    out["optimal_snubber_r_ohm"] = 0.5 * z0
    out["note"] = "optimal snubber resistance taken as sqrt(Lsw/Csw)/2 (thesis 5.1.3)"
    return out


def _fit_ringing(prob: _Problem, cand: _Candidate, head: list[float], f_grid: np.ndarray, S: np.ndarray,
                 fmin: float, fmax: float, baseline: WaveformFit, progress: bool) -> WaveformFit:
    """Ringing extension: starting frequencies from the residual spectrum and a cost scan, then least squares."""
    T = prob.K * prob.h
    t0 = time.perf_counter()
    z0s = [30.0, 150.0, 750.0]
    trials: list[np.ndarray] = []
    # fine scans (+-2 FFT bins of the unpadded record) around the residual's spectral peaks
    for fp in _spectral_peaks(f_grid, S, fmin, fmax, 2):
        for fq in fp + np.linspace(-3.0, 3.0, 25) / T:
            if fmin < fq < fmax:
                trials.append(np.array(head + [math.log(fq), math.log(z0s[1])]))
    # coarse log scan for heavily damped ringing
    for fq in np.geomspace(fmin * 1.05, fmax * 0.95, 20):
        for z in z0s:
            trials.append(np.array(head + [math.log(fq), math.log(z)]))
    x0 = prob.embed_state(baseline.x0, False, True) if prob.fit_x0 else None
    costs = prob.costs(cand, np.array(trials), x0)
    order = np.argsort(costs)
    picked: list[np.ndarray] = []
    for i in order:
        if all(abs(trials[i][-2] - p[-2]) > 0.02 or abs(trials[i][-1] - p[-1]) > 0.5 for p in picked):
            picked.append(trials[i])
        if len(picked) >= 2:
            break
    if costs[order[0]] >= baseline.cost:  # no ringing frequency in the band helps: a short refinement only
        _log(f"switch-ringing: no scan point ({len(trials)}) beats the baseline; short refinement", progress)
        return prob.fit(cand, picked[:1], max_nfev=8)
    _log(f"switch-ringing: {len(trials)} scan points in {time.perf_counter() - t0:.1f} s, starts at "
         f"{', '.join(f'{math.exp(p[-2]) / 1e6:.4g} MHz' for p in picked)}", progress)
    return prob.fit(cand, picked, max_nfev=30)


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------
