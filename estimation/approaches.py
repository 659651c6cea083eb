"""Estimation approaches of thesis 4.1.3 and 4.2.4: how an estimate is compared with the target.

Every approach maps a population of unit-cube points ``U`` ``(P, n)`` (the
optimiser's view, see :class:`estimation.parameters.ParameterSet`) to
``(P,)`` costs with :meth:`Approach.cost_batch`, the batched objective the
optimisers of :mod:`estimation.search.optimisers` call. Each approach records the
engine it used and the wall time per evaluation (:attr:`Approach.stats`).

Approaches
----------
:class:`AnalyticFrequency` (``"frequency"``, engine ``analytic``)
    Frequency responses of the estimate from the circuit's analytic
    transfer functions (``ResponseSet.evaluate``, batched over the
    population); the thesis's case study 5 and its recommended approach.
:class:`SimulatedFrequency` (``"frequency"``, engine ``zoh-batched``)
    The thesis's Simulink-in-the-loop: every estimate is perturbed by the
    simulated PRIS source (exact zero-order-hold time stepping of the whole
    arrangement, :class:`PrisEngine`, the whole population in one pass), and
    its responses are estimated from the waveforms with Welch's H1
    (:func:`welch_h1`, same settings as the target).
:class:`TimeDomain` (``"time"``)
    The target's sampled PRIS current is injected into the estimate's DUT
    (thesis 4.2.3, :class:`InjectionEngine`) and the terminal voltages are
    compared: ``C^v_rmse`` (4.32) or ``C^v_rho`` (4.34).
:class:`EMDApproach` (``"emd"``)
    Both voltages decomposed by EMD; ``C^m_nrmse`` (4.39) or ``C^m_rho`` (4.42).
:class:`IEMDApproach` (``"iemd"``)
    Only the target decomposed; the estimate is represented by its inferred
    IMFs (4.43); ``C^i_nrmse`` (4.45) or ``C^i_rho`` (4.46).

Engines
-------
:class:`PrisEngine` reproduces :func:`pris_cosim.lab.timedomain.simulate_pris`
(to rounding) for a population at once when ``fs`` is an integer multiple of
``f_clk``: one batched matrix exponential per population, a recurrence over
PRBS bits and a vectorised fill of the samples inside each bit.
:class:`InjectionEngine` reproduces
:func:`pris_cosim.lab.timedomain.simulate_current_injection` for a population.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal as _signal

from estimation import costs as _costs
from estimation.holds import batched_expm
from estimation.parameters import ParameterSet
from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.circuits.mna import MNA
from pris_cosim.signals.perturbation import lfsr_prbs
from pris_cosim.signals.spectral import DEFAULT_OVERLAP, DEFAULT_WINDOW

#: Bytes that one chunk of a population may hold in simulated records (all arrays of the chunk together).
CHUNK_BYTES = 256 * 2**20


def rows_per_chunk(n_samples: int, arrays_per_row: int, limit: int) -> int:
    """Parameter sets simulated together so that a chunk stays within :data:`CHUNK_BYTES`.

    Parameters
    ----------
    n_samples : int
        Samples per simulated record.
    arrays_per_row : int
        ``float64`` arrays of ``n_samples`` held per parameter set (states, outputs, temporaries).
    limit : int
        Largest chunk wanted (the caller's ``chunk``).
    """
    per_row = 8 * max(1, int(n_samples)) * max(1, int(arrays_per_row))
    return max(1, min(int(limit), CHUNK_BYTES // per_row))

__all__ = [
    "ApproachError",
    "EvalStats",
    "PrisEngine",
    "InjectionEngine",
    "WelchSettings",
    "welch_h1",
    "ResponseSpec",
    "responses_from_waveforms",
    "bin_frequencies",
    "Approach",
    "AnalyticFrequency",
    "SimulatedFrequency",
    "TimeDomain",
    "EMDApproach",
    "IEMDApproach",
    "frequency_cost",
]


class ApproachError(ValueError):
    """Bad approach settings (a one-line message naming the setting)."""


# ====================================================================== engines
def _batched_zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """``Phi = expm(A h)``, ``Gamma = int_0^h expm(A s) ds B`` for a batch ``A`` (P, n, n), ``B`` (P, n, m)."""
    P, n, _ = A.shape
    m = B.shape[2]
    aug = np.zeros((P, n + m, n + m))
    aug[:, :n, :n] = A * h
    aug[:, :n, n:] = B * h
    e = batched_expm(aug)
    return e[:, :n, :n], e[:, :n, n:]


def _blocked_states(Phi: np.ndarray, g: np.ndarray, u: np.ndarray, block: int = 64,
                    x0: np.ndarray | None = None) -> np.ndarray:
    """States of ``x[k+1] = Phi x[k] + g u[k]`` from ``x[0] = x0`` (default 0) for a population.

    Parameters
    ----------
    Phi : numpy.ndarray
        ``(P, n, n)``.
    g : numpy.ndarray
        ``(P, n)``.
    u : numpy.ndarray
        ``(K,)`` input shared by the population.
    block : int
        Steps per block: inside a block the forced response is one batched
        matrix product with the block-Toeplitz matrix of ``Phi^j g``; only the
        block boundaries are stepped sequentially.
    x0 : numpy.ndarray, optional
        ``(P, n)`` initial states.

    Returns
    -------
    numpy.ndarray
        ``(P, K, n)``: ``x[0] .. x[K-1]``.
    """
    P, n, _ = Phi.shape
    K = u.size
    L = max(1, min(int(block), K))
    Pw = np.empty((L + 1, P, n, n))
    Pw[0] = np.eye(n)
    for j in range(1, L + 1):
        Pw[j] = Phi @ Pw[j - 1]
    markov = np.einsum("jpnm,pm->pjn", Pw[:L], g)  # Phi^j g, (P, L, n)
    # T[p, i, j, :] = Phi^(j-1-i) g for i < j: contribution of u[k0+i] to x[k0+j]
    T = np.zeros((P, L, L, n))
    jj, ii = np.tril_indices(L, -1)
    T[:, ii, jj] = markov[:, jj - ii - 1]
    nblk = -(-K // L)
    up = np.zeros(nblk * L)
    up[:K] = u
    ub = up.reshape(nblk, L)
    # plain 2-D products (a broadcast matmul over the population does not use BLAS well)
    forced = (ub @ T.transpose(1, 0, 2, 3).reshape(L, P * L * n)).reshape(nblk, P, L, n).transpose(1, 0, 2, 3)
    rev = np.ascontiguousarray(markov[:, ::-1, :].transpose(1, 0, 2)).reshape(L, P * n)
    end_forced = (ub @ rev).reshape(nblk, P, n).transpose(1, 0, 2)  # sum_i Phi^(L-1-i) g u_i
    PhiL = Pw[L]
    starts = np.empty((P, nblk, n))
    x = np.zeros((P, n, 1)) if x0 is None else np.array(x0, float).reshape(P, n, 1)
    for b in range(nblk):
        starts[:, b] = x[:, :, 0]
        x = PhiL @ x + end_forced[:, b, :, None]
    PwT = Pw[:L].transpose(1, 3, 0, 2).reshape(P, n, L * n)  # [p, m, (j, n')] = Phi^j[n', m]
    free = np.matmul(starts, PwT).reshape(P, nblk, L, n)
    return (free + forced).reshape(P, nblk * L, n)[:, :K]


def _values_finite(values: Mapping[str, Any], P: int) -> np.ndarray:
    ok = np.ones(P, bool)
    for v in values.values():
        a = np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) <= 1 else None
        if a is not None:
            ok &= np.isfinite(a)
    return ok


class PrisEngine:
    """Exact PRIS waveforms of the arrangement for a population of parameter sets.

    Parameters
    ----------
    dut : Circuit
        Device under test.
    port : str
        Driven DUT node.
    settings : SourceSettings
        PRIS source (H-bridge voltage, PRBS order and clock, series RLC).
    fs : float, Hz
        Sampling frequency; must be an integer multiple of ``settings.fclk``.
    n_samples : int
        Samples from ``t = 0`` (the PRBS repeats as needed, all-ones seed).
    probes : sequence of str, optional
        DUT nodes whose voltages are returned as ``v_<node>`` (default: the
        circuit's probes).
    output_filter : tuple, optional
        ``(A, B, C, D)`` of a single-input, single-output analogue filter (B, C as
        vectors; time in s) that every returned channel passes before it is
        sampled, as a measurement chain's anti-alias filter does
        (:func:`pris_cosim.lab.virtual_lab.anti_alias_ss`). Its states are appended to
        the arrangement's, so the filtered samples are exact.

    Notes
    -----
    Same conventions as :func:`pris_cosim.lab.timedomain.simulate_pris` (zero
    initial state; sample k at ``k / fs``; ``i_in`` is the ``Lpris``
    current). With ``s = fs / f_clk`` samples per bit, the state at the
    first sample of bit ``b + 1`` is ``Phi^s x_b + g_s u_b`` (one batched
    matrix-vector product per bit for the whole population); the samples
    inside a bit are ``Phi^j x_b + g_j u_b`` (one einsum).
    """

    #: the balanced output filter, or None (subclasses that build their own system keep None)
    output_filter: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None

    def __init__(self, dut: Circuit, port: str, settings: SourceSettings, fs: float, n_samples: int,
                 probes: Sequence[str] | None = None,
                 output_filter: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None):
        ratio = float(fs) / float(settings.fclk)
        spb = int(round(ratio))
        if spb < 1 or abs(ratio - spb) > 1e-9 * ratio:
            raise ApproachError(f"fs ({fs:g} Hz) must be an integer multiple of f_clk ({settings.fclk:g} Hz)")
        if int(n_samples) < 2:
            raise ApproachError(f"n_samples must be at least 2 (got {n_samples})")
        self.dut, self.settings, self.fs, self.n_samples, self.spb = dut, settings, float(fs), int(n_samples), spb
        self.circuit = pris_arrangement(dut, port, settings)
        self.port = self.circuit.ports[0]
        self.probes = list(self.circuit.probes if probes is None else [p for p in probes if p != self.port])
        self.mna = MNA(self.circuit, voltage_inputs=[BRIDGE])
        n_bits = -(-self.n_samples // spb)
        periods = -(-n_bits // (2 ** settings.prbs_order - 1))
        bits = lfsr_prbs(settings.prbs_order, periods)[:n_bits]
        self.level = np.where(bits == 1, float(settings.vdc), -float(settings.vdc))
        nodes = [self.port] + self.probes
        self._rows = [self.mna.outputs.index(f"v({p})") for p in nodes]
        self._i_state = self.mna.states.index(f"i({SENSE_INDUCTOR})")
        self.names = ["v_in"] + [f"v_{p}" for p in self.probes] + ["i_in"]
        self.output_filter = None if output_filter is None else _balanced_filter(output_filter)

    @property
    def time_s(self) -> np.ndarray:
        """Sample instants, s."""
        return np.arange(self.n_samples) / self.fs

    @property
    def v_bprbs(self) -> np.ndarray:
        """Commanded bridge voltage per sample, V."""
        return np.repeat(self.level, self.spb)[: self.n_samples]

    def simulate(self, overrides: Mapping[str, Any] | None = None) -> dict[str, np.ndarray]:
        """Waveforms ``v_in``, ``v_<probe>``, ``i_in`` as ``(P, K)`` arrays (V, A).

        Parameters
        ----------
        overrides : mapping, optional
            Parameter or element values, floats or ``(P,)`` arrays.

        Returns
        -------
        dict
            Name to ``(P, K)``; rows of non-physical or non-finite sets are NaN.
        """
        values = self.circuit.resolve(overrides, check=False)
        P = max([np.size(v) for v in values.values()] + [1])
        values = {k: np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) else v for k, v in values.items()}
        ss = self.mna.state_space(values)
        A, B, C, D = ss.A, ss.B, ss.C, ss.D
        if A.shape[0] != P:
            A, B, C, D = (np.broadcast_to(M, (P,) + M.shape[1:]) for M in (A, B, C, D))
        ok = _values_finite(values, P) & np.all(np.isfinite(A.reshape(P, -1)), axis=1)
        A = np.where(ok[:, None, None], A, 0.0)
        B = np.where(ok[:, None, None], B, 0.0)
        n = A.shape[1]
        # outputs: rows of C for the node voltages, and the inductor-current state
        Cy = np.concatenate([C[:, self._rows, :], np.broadcast_to(np.eye(n)[[self._i_state]], (P, 1, n))], axis=1)
        Dy = np.concatenate([D[:, self._rows, 0], np.zeros((P, 1))], axis=1)  # (P, ny)
        if self.output_filter is not None:
            A, B, Cy, Dy = _filtered_outputs(A, B, Cy, Dy, self.output_filter)
            n = A.shape[1]
        s = self.spb
        Phi, Gam = _batched_zoh(A, B, 1.0 / self.fs)
        g = Gam[:, :, 0]
        # powers Phi^j and accumulated inputs g_j = sum_{i<j} Phi^i g, j = 0..s
        Pw = np.empty((s + 1, P, n, n))
        G = np.empty((s + 1, P, n))
        Pw[0] = np.eye(n)
        G[0] = 0.0
        for j in range(1, s + 1):
            Pw[j] = Phi @ Pw[j - 1]
            G[j] = np.einsum("pij,pj->pi", Phi, G[j - 1]) + g
        Phi_s, g_s = Pw[s], G[s]
        nb = self.level.size
        with np.errstate(over="ignore", invalid="ignore"):
            starts = _blocked_states(Phi_s, g_s, self.level)  # (P, nb, n): state at the first sample of each bit
            out = {}
            for k, name in enumerate(self.names):
                CPk = np.einsum("pn,jpnm->pmj", Cy[:, k], Pw[:s])  # (P, n, s): (c_k Phi^j)^T
                CGk = np.einsum("pn,jpn->pj", Cy[:, k], G[:s]) + Dy[:, k, None]  # (P, s)
                Yk = np.matmul(starts, CPk)
                Yk += CGk[:, None, :] * self.level[None, :, None]
                Yk = Yk.reshape(P, nb * s)[:, : self.n_samples]
                Yk[~ok] = np.nan
                out[name] = Yk
        return out



def _balanced_filter(filt: tuple[Any, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A SISO ``(A, B, C, D)`` in a diagonally balanced realisation (a companion form of a 100 kHz filter spans
    twenty decades, which the matrix exponential of the zero-order hold does not survive)."""
    from scipy.linalg import matrix_balance

    af = np.atleast_2d(np.asarray(filt[0], float))
    bf, cf = np.ravel(np.asarray(filt[1], float)), np.ravel(np.asarray(filt[2], float))
    df = float(np.ravel(np.asarray(filt[3], float))[0])
    if af.shape[0] != af.shape[1] or bf.size != af.shape[0] or cf.size != af.shape[0]:
        raise ApproachError(f"output_filter: A must be square and B, C of its size (got A {af.shape}, "
                            f"B {bf.size}, C {cf.size})")
    ab, t = matrix_balance(af, permute=False)
    return ab, np.linalg.solve(t, bf), cf @ t, df


def _filtered_outputs(A: np.ndarray, B: np.ndarray, Cy: np.ndarray, Dy: np.ndarray,
                      filt: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Append one copy of the SISO filter ``filt = (af, bf, cf, df)`` per output channel to a batched system.

    ``A (P, n, n)``, ``B (P, n, 1)``, ``Cy (P, ny, n)``, ``Dy (P, ny)``; returns the augmented
    ``A, B, Cy, Dy`` whose outputs are the filtered channels.
    """
    af, bf, cf, df = filt
    bf, cf, df = np.ravel(bf), np.ravel(cf), float(np.ravel(df)[0])
    P, n, _ = A.shape
    ny, nf = Cy.shape[1], af.shape[0]
    m = n + ny * nf
    Aa = np.zeros((P, m, m))
    Ba = np.zeros((P, m, 1))
    Ca = np.zeros((P, ny, m))
    Aa[:, :n, :n], Ba[:, :n] = A, B
    for k in range(ny):
        sl = slice(n + k * nf, n + (k + 1) * nf)
        Aa[:, sl, sl] = af
        Aa[:, sl, :n] = bf[None, :, None] * Cy[:, k, None, :]
        Ba[:, sl, 0] = bf[None, :] * Dy[:, k, None]
        Ca[:, k, sl] = cf
        Ca[:, k, :n] = df * Cy[:, k]
    return Aa, Ba, Ca, df * Dy


class InjectionEngine:
    """DUT voltages for a sampled current injected at its port, for a population (thesis 4.2.3).

    Parameters
    ----------
    dut : Circuit
    port : str
        Node the current enters (from ground).
    i_samples : array_like, A
        Current samples ``i(k / fs)``.
    fs : float, Hz
    block : int
        Samples per block of the blocked recurrence.
    hold : {"linear", "step"}
        ``"linear"`` (default): the current varies linearly from one sample to
        the next (first-order hold, :mod:`estimation.holds`): unbiased for the
        continuous current of a physical source. ``"step"``: sample k holds
        from ``k / fs`` to ``(k + 1) / fs`` (zero-order hold, thesis 4.2.3, as
        :func:`pris_cosim.lab.timedomain.simulate_current_injection`), which
        delays the current by half a sample.

    Notes
    -----
    Exact for the piecewise-linear (or piecewise-constant) current, from zero
    state. Inside a block
    of ``L`` samples the response is a product with the block-Toeplitz matrix
    of the Markov parameters ``C Phi^j Gamma``; the state is carried from
    block to block (one batched matrix product per block).
    """

    def __init__(self, dut: Circuit, port: str, i_samples: np.ndarray, fs: float, block: int = 64,
                 hold: str = "linear"):
        if hold not in ("linear", "step"):
            raise ApproachError(f"hold must be 'linear' or 'step' (got {hold!r})")
        self.hold = hold
        self.circuit = dut
        self.port = dut.require_node(port, "port")
        if self.port == GROUND:
            raise ApproachError("the driven port cannot be ground")
        self.mna = MNA(dut, current_inputs=[self.port])
        self.i = np.asarray(i_samples, float).ravel()
        if self.i.size < 2 or not np.all(np.isfinite(self.i)):
            raise ApproachError("the injected current needs at least 2 finite samples")
        self.fs = float(fs)
        self.block = int(block)
        self._row = self.mna.outputs.index(f"v({self.port})")

    @property
    def n_samples(self) -> int:
        return self.i.size

    def simulate(self, overrides: Mapping[str, Any] | None = None) -> np.ndarray:
        """Port voltage ``(P, K)``, V (NaN rows for non-finite parameter sets)."""
        values = self.circuit.resolve(overrides, check=False)
        P = max([np.size(v) for v in values.values()] + [1])
        values = {k: np.broadcast_to(np.asarray(v, float), (P,)) if np.ndim(v) else v for k, v in values.items()}
        ss = self.mna.state_space(values)
        A, B, C, D = ss.A, ss.B, ss.C[:, [self._row]], ss.D[:, [self._row]]
        if A.shape[0] != P:
            A, B, C, D = (np.broadcast_to(M, (P,) + M.shape[1:]) for M in (A, B, C, D))
        ok = _values_finite(values, P) & np.all(np.isfinite(A.reshape(P, -1)), axis=1)
        A = np.where(ok[:, None, None], A, 0.0)
        B = np.where(ok[:, None, None], B, 0.0)
        with np.errstate(over="ignore", invalid="ignore"):
            if self.hold == "step":
                Phi, Gam = _batched_zoh(A, B, 1.0 / self.fs)
                x = _blocked_states(Phi, Gam[:, :, 0], self.i, self.block)  # (P, K, n)
                Dt = D[:, 0, 0]
            else:  # first-order hold: z_k = x_k - Gamma1 u_k, x_0 = 0
                from estimation.holds import batched_foh, foh_recurrence

                Phi, G0, G1 = batched_foh(A, B, 1.0 / self.fs)
                g1 = G1[:, :, 0]
                x = _blocked_states(Phi, foh_recurrence(Phi, G0[:, :, 0], g1), self.i, self.block,
                                    x0=-g1 * self.i[0])
                Dt = D[:, 0, 0] + np.einsum("pn,pn->p", C[:, 0, :], g1)
            y = np.matmul(x, C[:, 0, :, None])[:, :, 0] + Dt[:, None] * self.i[None, :]
        y[~ok] = np.nan
        return y


# ====================================================================== spectral estimates, batched
@dataclass(frozen=True)
class WelchSettings:
    """Welch H1 settings (thesis 4.1.2 defaults: Hann, 62.5 % overlap, half-record segments).

    Attributes
    ----------
    window : str
        scipy window name (``"hann"``, ``"boxcar"``).
    overlap : float
        Fraction of a segment shared with the next.
    nperseg : int, optional
        Samples per segment; default half the (analysed) record.
    skip : int
        Samples discarded at the start of the record (settling transient).
    """

    window: str = DEFAULT_WINDOW
    overlap: float = DEFAULT_OVERLAP
    nperseg: int | None = None
    skip: int = 0

    def segment(self, n: int) -> int:
        m = n - self.skip
        if m < 4:
            raise ApproachError(f"record of {n} samples leaves {m} after skipping {self.skip}")
        return int(self.nperseg) if self.nperseg is not None else m // 2

    def scipy_kwargs(self, n: int, fs: float) -> dict[str, Any]:
        nper = self.segment(n)
        if not 2 <= nper <= n - self.skip:
            raise ApproachError(f"nperseg {nper} does not fit a record of {n - self.skip} samples")
        return {"fs": fs, "window": self.window, "nperseg": nper, "noverlap": int(round(self.overlap * nper)),
                "detrend": "constant", "return_onesided": True, "scaling": "density"}


def welch_h1(x: np.ndarray, ys: Sequence[np.ndarray], fs: float, settings: WelchSettings,
             bins: np.ndarray | None = None) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Batched Welch H1 estimates ``Pxy / Pxx`` and coherences for one input and several outputs.

    Parameters
    ----------
    x : numpy.ndarray
        ``(..., K)`` input records (e.g. ``i_in``).
    ys : sequence of numpy.ndarray
        ``(..., K)`` output records (e.g. ``v_in``).
    fs : float, Hz
    settings : WelchSettings
    bins : numpy.ndarray of int, optional
        Keep only these frequency bins.

    Returns
    -------
    f : numpy.ndarray, Hz
    H : list of numpy.ndarray
        ``(..., F)`` complex, one per output.
    coh : list of numpy.ndarray
        ``(..., F)`` magnitude-squared coherence, one per output.
    pxx : numpy.ndarray
        ``(..., F)`` input PSD.

    Notes
    -----
    Equal (to rounding) to :func:`pris_cosim.signals.spectral.tfestimate` and
    :func:`pris_cosim.signals.spectral.coherence` record by record; here every
    record of a population is processed in one call.
    """
    x = np.asarray(x, float)[..., settings.skip:]
    kw = settings.scipy_kwargs(x.shape[-1] + settings.skip, fs)
    f, pxx = _signal.welch(x, **kw)
    pick = (lambda a: a[..., bins]) if bins is not None else (lambda a: a)
    f, pxx = pick(f), pick(pxx)
    H, coh = [], []
    for y in ys:
        y = np.asarray(y, float)[..., settings.skip:]
        _, pxy = _signal.csd(x, y, **kw)
        _, pyy = _signal.welch(y, **kw)
        pxy, pyy = pick(pxy), pick(pyy)
        with np.errstate(divide="ignore", invalid="ignore"):
            H.append(pxy / pxx)
            coh.append(np.clip(np.abs(pxy) ** 2 / (pxx * pyy), 0.0, 1.0))
    return f, H, coh, pxx


@dataclass(frozen=True)
class ResponseSpec:
    """How a response is formed from waveforms: ``H = output / input`` (names of waveforms).

    ``output`` may be ``"a-b"`` (a difference of two waveforms, e.g. the
    voltage across section 1: ``"v_in-v_mid"``).
    """

    name: str
    input: str
    output: str


#: Responses of the two-section model from PRIS waveforms (thesis 4.1.2).
TWO_SECTION_SPECS = {
    "Zin": ResponseSpec("Zin", "i_in", "v_in"),
    "R1in": ResponseSpec("R1in", "v_in", "v_in-v_mid"),
    "R2in": ResponseSpec("R2in", "v_in", "v_mid"),
}
#: Input impedance only.
ZIN_SPEC = {"Zin": ResponseSpec("Zin", "i_in", "v_in")}


def _waveform(w: Mapping[str, np.ndarray], expr: str) -> np.ndarray:
    if "-" in expr:
        a, b = expr.split("-", 1)
        return np.asarray(w[a], float) - np.asarray(w[b], float)
    return np.asarray(w[expr], float)


def responses_from_waveforms(w: Mapping[str, np.ndarray], fs: float, specs: Sequence[ResponseSpec],
                             settings: WelchSettings, bins: np.ndarray | None = None
                             ) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Welch H1 responses (and coherences) named by ``specs`` from (batched) waveforms.

    Returns
    -------
    f : numpy.ndarray, Hz
    responses : dict
        Name to ``(..., F)`` complex.
    coherence : dict
        Name to ``(..., F)``.
    """
    by_input: dict[str, list[ResponseSpec]] = {}
    for s in specs:
        by_input.setdefault(s.input, []).append(s)
    out: dict[str, np.ndarray] = {}
    coh: dict[str, np.ndarray] = {}
    f = np.empty(0)
    for inp, group in by_input.items():
        f, H, C, _ = welch_h1(_waveform(w, inp), [_waveform(w, s.output) for s in group], fs, settings, bins)
        for s, h, c in zip(group, H, C):
            out[s.name], coh[s.name] = h, c
    return f, out, coh


def bin_frequencies(fs: float, nperseg: int, fmin: float, fmax: float, points: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch bins nearest to ``points`` log-spaced frequencies in ``[fmin, fmax]`` (duplicates dropped).

    Returns
    -------
    bins : numpy.ndarray of int
    f : numpy.ndarray, Hz
        ``bins * fs / nperseg``.
    """
    df = float(fs) / int(nperseg)
    grid = np.logspace(np.log10(fmin), np.log10(fmax), int(points))
    bins = np.unique(np.clip(np.rint(grid / df).astype(int), 1, int(nperseg) // 2))
    return bins, bins * df


# ====================================================================== approaches
@dataclass
class EvalStats:
    """Evaluations of an approach: count, batches and time spent in :meth:`Approach.cost_batch`."""

    evaluations: int = 0
    batches: int = 0
    seconds: float = 0.0

    @property
    def per_eval_s(self) -> float:
        return self.seconds / self.evaluations if self.evaluations else float("nan")

    def to_dict(self) -> dict[str, float]:
        return {"evaluations": self.evaluations, "batches": self.batches, "seconds": self.seconds,
                "per_eval_s": self.per_eval_s}


class Approach:
    """Base class: ``cost_batch(U) -> (P,)`` over unit-cube points, with statistics.

    Subclasses implement :meth:`_costs` taking the ``Evaluation`` of the
    population (physical values and circuit overrides).
    """

    name = "approach"
    engine = "none"

    def __init__(self, params: ParameterSet, penalty: float | None = None):
        self.params = params
        self.penalty = penalty
        self.stats = EvalStats()

    @property
    def n(self) -> int:
        return len(self.params.varying)

    def cost_batch(self, U: np.ndarray) -> np.ndarray:
        """Costs of a population, ``U`` ``(P, n)`` in the unit cube; non-finite costs are ``inf``."""
        t0 = time.perf_counter()
        U = np.atleast_2d(np.asarray(U, float))
        ev = self.params.evaluate(U)
        c = np.asarray(self._costs(ev), float).reshape(U.shape[0])
        c = np.where(np.isfinite(c), c, np.inf)
        if self.penalty is not None:
            c = _costs.penalise(c, ev.passive, self.penalty)
        self.stats.evaluations += U.shape[0]
        self.stats.batches += 1
        self.stats.seconds += time.perf_counter() - t0
        return c

    __call__ = cost_batch

    def cost_at(self, values: Mapping[str, float]) -> float:
        """Cost of one physical parameter set (names of the varying parameters)."""
        u = self.params.to_unit({k: values[k] for k in self.params.varying})
        return float(self.cost_batch(u[None, :])[0])

    def _costs(self, ev: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def residuals(self, U: np.ndarray) -> np.ndarray:
        """Residual vectors ``(P, N)`` behind the cost (for Jacobians and identifiability)."""
        t0 = time.perf_counter()
        U = np.atleast_2d(np.asarray(U, float))
        r = self._residuals(self.params.evaluate(U))
        self.stats.evaluations += U.shape[0]
        self.stats.batches += 1
        self.stats.seconds += time.perf_counter() - t0
        return r

    def _residuals(self, ev: Any) -> np.ndarray:
        raise NotImplementedError(f"approach {self.name!r} has no residual vector")

    def describe(self) -> dict[str, Any]:
        return {"approach": self.name, "engine": self.engine, **self.stats.to_dict()}


def frequency_cost(metric: str, responses: Sequence[str], masks: Mapping[str, np.ndarray] | None = None) -> Any:
    """Frequency-domain cost object: ``"sse"`` (4.21), ``"rmse"`` (4.29), ``"correlation"`` (4.31)."""
    if metric in ("sse", "rmse"):
        return _costs.LogMagnitudeCost(metric, list(responses), masks)
    if metric in ("correlation", "rho"):
        return _costs.CorrelationCost(list(responses), "magnitude", masks)
    raise ApproachError(f"frequency cost must be 'sse', 'rmse' or 'correlation' (got {metric!r})")


class AnalyticFrequency(Approach):
    """Frequency-domain approach with the estimate's analytic responses.

    Parameters
    ----------
    params : ParameterSet
    response_set : pris_cosim.models.builtin.ResponseSet
        Compiled responses of the estimate's circuit.
    frequency_hz : array_like, Hz
        ``(F,)`` comparison frequencies.
    target : mapping
        Response name to ``(F,)`` complex target.
    cost : callable
        ``cost(target, estimate) -> (P,)`` (see :func:`frequency_cost`).
    """

    name = "frequency"
    engine = "analytic"

    def __init__(self, params: ParameterSet, response_set: Any, frequency_hz: np.ndarray,
                 target: Mapping[str, np.ndarray], cost: Any, penalty: float | None = None):
        super().__init__(params, penalty)
        self.response_set = response_set
        self.f = np.asarray(frequency_hz, float)
        self.target = {k: np.asarray(v) for k, v in target.items()}
        self.cost = cost
        for k, v in self.target.items():
            if v.shape != self.f.shape:
                raise ApproachError(f"target response {k!r} has {v.shape} points, frequencies {self.f.shape}")

    def responses(self, overrides: Mapping[str, Any]) -> dict[str, np.ndarray]:
        return self.response_set.evaluate(self.f, overrides)

    def _costs(self, ev: Any) -> np.ndarray:
        est = self.responses(ev.overrides)
        est = {k: est[k] for k in self.target}
        return self.cost(self.target, est)

    def _residuals(self, ev: Any) -> np.ndarray:
        est = self.responses(ev.overrides)
        return np.concatenate([_costs.log_magnitude_error(self.target[k], est[k]) for k in self.target], axis=-1)


class SimulatedFrequency(Approach):
    """Frequency-domain approach with responses estimated from a simulated PRIS perturbation.

    Parameters
    ----------
    params : ParameterSet
    engine : PrisEngine
        The estimate's arrangement (same settings as the target's).
    specs : sequence of ResponseSpec
        Responses to estimate.
    welch : WelchSettings
    bins : numpy.ndarray of int
        Welch bins compared (e.g. from :func:`bin_frequencies`).
    target : mapping
        Response name to ``(F,)`` complex target at those bins.
    cost : callable
    chunk : int
        Population members simulated together (memory bound).
    """

    name = "frequency"
    engine = "zoh-batched+welch"

    def __init__(self, params: ParameterSet, engine: PrisEngine, specs: Sequence[ResponseSpec], welch: WelchSettings,
                 bins: np.ndarray, target: Mapping[str, np.ndarray], cost: Any, chunk: int = 16,
                 penalty: float | None = None):
        super().__init__(params, penalty)
        self.sim = engine
        self.specs = list(specs)
        self.welch = welch
        self.bins = np.asarray(bins, int)
        self.target = {k: np.asarray(v) for k, v in target.items()}
        self.cost = cost
        self.chunk = int(chunk)

    def responses(self, overrides: Mapping[str, Any]) -> dict[str, np.ndarray]:
        w = self.sim.simulate(overrides)
        _, resp, _ = responses_from_waveforms(w, self.sim.fs, self.specs, self.welch, self.bins)
        return resp

    def _costs(self, ev: Any) -> np.ndarray:
        P = ev.unit.shape[0] if np.ndim(ev.unit) == 2 else 1
        out = np.empty(P)
        for a in range(0, P, self.chunk):
            sub = {k: (v[a:a + self.chunk] if np.ndim(v) else v) for k, v in ev.overrides.items()}
            est = self.responses(sub)
            est = {k: est[k] for k in self.target}
            out[a:a + self.chunk] = self.cost(self.target, est)
        return out

    def _residuals(self, ev: Any) -> np.ndarray:
        est = self.responses(ev.overrides)
        return np.concatenate([_costs.log_magnitude_error(self.target[k], est[k]) for k in self.target], axis=-1)


class TimeDomain(Approach):
    """Time-domain approach (thesis 4.2.3, 4.2.5.2): inject the target's sampled current, compare voltages.

    Parameters
    ----------
    params : ParameterSet
    engine : InjectionEngine
        Holds the target's sampled current.
    v_target : array_like, V
        ``(K,)`` target terminal voltage at the same instants.
    metric : {"rmse", "correlation"}
    """

    name = "time"
    engine = "zoh-injection"

    def __init__(self, params: ParameterSet, engine: InjectionEngine, v_target: np.ndarray, metric: str = "rmse",
                 chunk: int = 256, penalty: float | None = None):
        super().__init__(params, penalty)
        self.sim = engine
        self.v_target = np.asarray(v_target, float)
        if self.v_target.shape != (engine.n_samples,):
            raise ApproachError(f"target voltage has shape {self.v_target.shape}, current {engine.n_samples} samples")
        if metric not in ("rmse", "correlation", "rho", "nrmse"):
            raise ApproachError(f"metric must be 'rmse' or 'correlation' (got {metric!r})")
        self.metric = "correlation" if metric in ("correlation", "rho") else "rmse"
        self.chunk = int(chunk)

    def voltages(self, overrides: Mapping[str, Any]) -> np.ndarray:
        return self.sim.simulate(overrides)

    def _residuals(self, ev: Any) -> np.ndarray:
        return self.voltages(ev.overrides) - self.v_target

    def _compare(self, v: np.ndarray) -> np.ndarray:
        if self.metric == "rmse":
            return _costs.v_rmse(self.v_target, v)
        return _costs.v_correlation(self.v_target, v)

    def _costs(self, ev: Any) -> np.ndarray:
        P = ev.unit.shape[0] if np.ndim(ev.unit) == 2 else 1
        out = np.empty(P)
        # states (n per sample), the output, its cleaned copy and the metric's temporaries, per parameter set
        chunk = rows_per_chunk(self.v_target.size, getattr(self.sim.mna, "n_states", 8) + 6, self.chunk)
        for a in range(0, P, chunk):
            sub = {k: (v[a:a + chunk] if np.ndim(v) else v) for k, v in ev.overrides.items()}
            v = self.voltages(sub)
            bad = ~np.all(np.isfinite(v), axis=1)
            v = np.where(bad[:, None], 0.0, v)
            c = np.asarray(self._compare(v), float)
            out[a:a + chunk] = np.where(bad, np.inf, c)
        return out


class EMDApproach(TimeDomain):
    """EMD approach (thesis 4.2.5.3): both voltages decomposed; ``C^m_nrmse`` or ``C^m_rho``."""

    name = "emd"
    engine = "zoh-injection+emd"

    def __init__(self, params: ParameterSet, engine: InjectionEngine, v_target: np.ndarray, metric: str = "rmse",
                 decomposer: _costs.Decomposer | None = None, chunk: int = 256, penalty: float | None = None):
        super().__init__(params, engine, v_target, metric, chunk, penalty)
        self.cost = _costs.EMDCost("nrmse" if self.metric == "rmse" else "rho", decomposer or _costs.Decomposer())

    def _compare(self, v: np.ndarray) -> np.ndarray:
        return self.cost(self.v_target, v)


class IEMDApproach(TimeDomain):
    """Inferred-EMD approach (thesis 4.2.5.4): ``C^i_nrmse`` (4.45) or ``C^i_rho`` (4.46)."""

    name = "iemd"
    engine = "zoh-injection+iemd"

    def __init__(self, params: ParameterSet, engine: InjectionEngine, v_target: np.ndarray, metric: str = "rmse",
                 decomposer: _costs.Decomposer | None = None, chunk: int = 256, penalty: float | None = None):
        super().__init__(params, engine, v_target, metric, chunk, penalty)
        self.cost = _costs.IEMDCost("nrmse" if self.metric == "rmse" else "rho", decomposer or _costs.Decomposer())

    def _compare(self, v: np.ndarray) -> np.ndarray:
        return self.cost(self.v_target, v)


class WelchProxyFrequency(Approach):
    """Analytic responses seen through the Welch window: a cheap stand-in for :class:`SimulatedFrequency`.

    The waveforms of the PRIS arrangement are ``X(f) = T_x(f) V_b(f)`` with
    ``T_x`` the arrangement's analytic transfer function from the bridge
    voltage (``i_in = V_b / Z_arr``, ``v_in = T_in V_b`` ...) and
    ``|V_b(f)|^2 ~ sinc^2(f / f_clk)`` the PRBS spectrum. For a stationary
    excitation Welch's H1 at bin ``f_k`` is then

    ``H_k = sum_j K(f_k - f_j) conj(X_j) Y_j / sum_j K(f_k - f_j) |X_j|^2``

    with ``K`` the power kernel of the Hann segment window, evaluated on a
    fine grid around every bin. The integrands are smooth on the scale of the
    closed-loop poles (source plus winding, well damped), so a grid of a
    quarter bin suffices. This reproduces the leakage that smears sharp
    resonances in the simulated estimate (not the start-up transient), at the
    cost of an analytic evaluation; it serves as the global phase before a
    local polish with the simulated approach.

    Parameters
    ----------
    params : ParameterSet
    dut : Circuit
    port : str
    settings : SourceSettings
    fs : float, Hz
    nperseg : int
        Welch segment length (samples).
    bins : numpy.ndarray of int
    specs : sequence of ResponseSpec
    target : mapping
    cost : callable
    half_width : int
        Kernel half-width in bins.
    sub : int
        Grid points per bin.
    """

    name = "frequency"
    engine = "analytic+welch-kernel"

    def __init__(self, params: ParameterSet, dut: Circuit, port: str, settings: SourceSettings, fs: float,
                 nperseg: int, bins: np.ndarray, specs: Sequence[ResponseSpec], target: Mapping[str, np.ndarray],
                 cost: Any, half_width: int = 3, sub: int = 4, penalty: float | None = None):
        from pris_cosim.frf.response import Response, ResponseModel

        super().__init__(params, penalty)
        arr = pris_arrangement(dut, port, settings)
        circ = Circuit(title="PRIS arrangement without the bridge", elements=[e for e in arr.elements if e.name != BRIDGE],
                       parameters=list(arr.parameters), ports=["src_h"], probes=list(arr.probes))
        self.port = arr.ports[0]
        probes = [p for p in arr.probes if p != self.port]
        self.model = ResponseModel(circ, "src_h", responses=[Response("Zarr"), Response("v_in", self.port)]
                                   + [Response(f"v_{p}", p) for p in probes])
        df = float(fs) / int(nperseg)
        self.f_bins = np.asarray(bins, int) * df
        offs = np.arange(-half_width * sub, half_width * sub + 1) / sub  # in bins
        fine = self.f_bins[:, None] + offs[None, :] * df
        self.valid = fine > 0
        self.fine = np.where(self.valid, fine, df / sub)
        nu = offs
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(np.abs(np.abs(nu) - 1) < 1e-12, 0.5, np.sinc(nu) / (1 - nu ** 2))
        self.kernel = (w ** 2)[None, :] * self.valid
        self.vb = np.sinc(self.fine / float(settings.fclk))
        self.specs = list(specs)
        self.target = {k: np.asarray(v) for k, v in target.items()}
        self.cost = cost

    def _wave(self, r: Mapping[str, np.ndarray], expr: str) -> np.ndarray:
        if "-" in expr:
            a, b = expr.split("-", 1)
            return self._wave(r, a) - self._wave(r, b)
        if expr == "i_in":
            return self.vb / r["Zarr"]
        return self.vb * r[expr]

    def responses(self, overrides: Mapping[str, Any]) -> dict[str, np.ndarray]:
        F, J = self.fine.shape
        r = self.model.evaluate(self.fine.ravel(), overrides)
        r = {k: v.reshape(v.shape[:-1] + (F, J)) for k, v in r.items()}
        out = {}
        for s in self.specs:
            x, y = self._wave(r, s.input), self._wave(r, s.output)
            with np.errstate(divide="ignore", invalid="ignore"):
                out[s.name] = (np.sum(self.kernel * np.conj(x) * y, axis=-1)
                               / np.sum(self.kernel * np.abs(x) ** 2, axis=-1))
        return out

    def _costs(self, ev: Any) -> np.ndarray:
        est = self.responses(ev.overrides)
        return self.cost(self.target, {k: est[k] for k in self.target})
