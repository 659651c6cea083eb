"""Exact time-domain simulation of linear networks with piecewise-constant inputs.

The PRIS source's H-bridge output is piecewise constant and the source RLC
plus winding network is linear, so zero-order-hold (ZOH) discretisation is
exact: over an interval of length h with constant input u,

.. math:: x(t + h) = \\Phi(h) x(t) + \\Gamma(h) u, \\qquad
          \\begin{bmatrix} \\Phi & \\Gamma \\\\ 0 & I \\end{bmatrix}
          = \\exp\\left(\\begin{bmatrix} A & B \\\\ 0 & 0 \\end{bmatrix} h\\right).

:func:`simulate_pwc` steps an arbitrary sampled input held constant per
sample; :func:`simulate_pris` runs the PRIS arrangement from zero state with
the PRBS switching instants handled exactly whatever the sampling rate;
:func:`simulate_current_injection` drives a DUT with a sampled current (the
time-domain estimation arrangement of thesis 4.2.3).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from fractions import Fraction

import numpy as np
import scipy.linalg

from .arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from .circuit import GROUND, Circuit, Numeric
from .errors import CircuitError
from .mna import MNA, StateSpace
from .signals import hbridge_waveform, lfsr_prbs

#: Samples per block of the blocked recurrence in :func:`simulate_pwc`.
_BLOCK = 64


def zoh(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation.

    Parameters
    ----------
    A : numpy.ndarray, shape (n, n), 1/s
    B : numpy.ndarray, shape (n, m)
    h : float, s
        Step length.

    Returns
    -------
    Phi : numpy.ndarray, shape (n, n)
        ``expm(A h)``.
    Gamma : numpy.ndarray, shape (n, m)
        ``integral_0^h expm(A s) ds B``, from the augmented matrix exponential.
    """
    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = A * h
    aug[:n, n:] = B * h
    e = scipy.linalg.expm(aug)
    return e[:n, :n], e[:n, n:]


def _single(ss: StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if ss.A.shape[0] != 1:
        raise ValueError(f"time-domain simulation takes one parameter set, got {ss.A.shape[0]}")
    return ss.A[0], ss.B[0], ss.C[0], ss.D[0]


def simulate_pwc(
    ss: StateSpace, u: np.ndarray, h: float, x0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Exact response to an input held constant over each sample interval.

    ``x[k+1] = Phi x[k] + Gamma u[k]``, ``y[k] = C x[k] + D u[k]``: sample k
    of the input holds from ``k h`` to ``(k + 1) h``.

    Parameters
    ----------
    ss : StateSpace
        One parameter set (``P = 1``).
    u : numpy.ndarray, shape (K,) or (K, nu)
        Input samples in the units of ``ss.inputs``.
    h : float, s
        Sample interval.
    x0 : numpy.ndarray, optional
        Initial state (default zero).

    Returns
    -------
    x : numpy.ndarray, shape (K, n)
        States at the sample instants.
    y : numpy.ndarray, shape (K, ny)
        Outputs at the sample instants.

    Notes
    -----
    The recurrence is evaluated in blocks of 64 samples: inside a block the
    forced response is a product with the block-Toeplitz matrix of the
    Markov parameters ``Phi^j Gamma``, the free response a product with the
    powers ``Phi^j``; only the block boundaries are stepped sequentially.
    """
    A, B, C, D = _single(ss)
    n, nu = B.shape
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    if u.ndim != 2 or u.shape[1] != nu:
        raise ValueError(f"input must have shape (K, {nu}), got {u.shape}")
    if not h > 0:
        raise ValueError(f"sample interval must be positive, got {h!r} s")
    K = u.shape[0]
    x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    Phi, Gam = zoh(A, B, h)
    L = min(_BLOCK, max(K, 1))
    powers = np.empty((L + 1, n, n))  # Phi^0 .. Phi^L
    powers[0] = np.eye(n)
    for j in range(1, L + 1):
        powers[j] = Phi @ powers[j - 1]
    markov = powers[:L] @ Gam  # (L, n, nu): Phi^j Gamma
    # T[j, i] = Phi^(j-1-i) Gamma for i < j (contribution of u[i] to x[j] inside a block)
    T = np.zeros((L, L, n, nu))
    for j in range(1, L):
        T[j, :j] = markov[j - 1 :: -1][:j]
    nblk = -(-K // L)
    up = np.zeros((nblk * L, nu))
    up[:K] = u
    ub = up.reshape(nblk, L, nu)
    forced = (ub.reshape(nblk, L * nu) @ T.transpose(0, 2, 1, 3).reshape(L * n, L * nu).T).reshape(nblk, L, n)
    # state at the start of every block
    end_forced = forced[:, -1] @ Phi.T + ub[:, -1] @ Gam.T  # forced part of x at the next block start
    starts = np.empty((nblk, n))
    x = x0
    PhiL = powers[L]
    for b in range(nblk):
        starts[b] = x
        x = PhiL @ x + end_forced[b]
    xs = (starts @ powers[:L].reshape(L * n, n).T).reshape(nblk, L, n) + forced
    xs = xs.reshape(nblk * L, n)[:K]
    y = xs @ C.T + u @ D.T
    return xs, y


def checked_values(circuit: Circuit, overrides: Mapping[str, Numeric] | None = None) -> dict[str, Numeric]:
    """Element values after the positivity checks and the strict passivity check.

    Raises
    ------
    CircuitError
        An element value is not positive or a coupling is not below 1.
    NonPassiveError
        The inductance matrix is not positive definite.
    """
    values = circuit.resolve(overrides, check=True)
    circuit.check_passive(values, strict=True)
    return values


def clock_ratio(fclk: float, fs: float) -> tuple[int, int]:
    """Integers ``(p, q)`` with ``fclk / fs = p / q`` (nearest fraction with q <= 2**31)."""
    if not (np.isfinite(fclk) and fclk > 0 and np.isfinite(fs) and fs > 0):
        raise CircuitError(f"fclk and fs must be positive (got {fclk!r} Hz, {fs!r} Hz)")
    r = (Fraction(fclk) / Fraction(fs)).limit_denominator(2**31)
    return r.numerator, r.denominator


def simulate_pris(
    dut: Circuit,
    port: str,
    settings: SourceSettings,
    fs: float,
    periods: int = 1,
    shorts: Sequence[str] = (),
    overrides: Mapping[str, float] | None = None,
    x0: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Exact PRIS waveforms of a DUT in the arrangement of thesis Fig. 2.15, from zero state.

    Parameters
    ----------
    dut : Circuit
        Device under test.
    port : str
        Driven DUT node.
    settings : SourceSettings
        H-bridge voltage, PRBS order and clock, series RLC, parasitics.
    fs : float, Hz
        Sampling frequency.
    periods : int
        Number of PRBS periods (all-ones seed).
    shorts : sequence of str
        DUT nodes tied to ground (test configuration).
    overrides : mapping, optional
        Parameter or element values replacing the circuit's.
    x0 : numpy.ndarray, optional
        Initial state in the order of the arrangement's states (default zero).

    Returns
    -------
    dict
        ``time_s`` (s), ``v_bprbs`` (V, row k holds from ``time_s[k]`` to
        ``time_s[k+1]``), ``v_in`` (V, DUT port), ``i_in`` (A, ``i(Lpris)``),
        and ``v_<probe>`` (V) for every probe of the DUT.

    Raises
    ------
    NonPassiveError
        The circuit's inductance matrix is not positive definite.

    Notes
    -----
    Exact for any ``fs``: the input changes only at the PRBS clock instants
    ``j / f_clk``, and the state is carried from one switching instant to
    the next, so a sample interval that contains a switching instant is
    split there. When ``fs`` is an integer multiple of ``f_clk`` no interval
    is split and every sample uses the same ``Phi(1/fs)``. Times are kept as
    integers in units of ``1 / (p fs)`` with ``f_clk / fs = p / q``.
    """
    circuit = pris_arrangement(dut, port, settings, shorts)
    port_node = circuit.ports[0]
    values = checked_values(circuit, overrides)
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    A, B, C, D = _single(mna.state_space(values))
    t, v_bridge = hbridge_waveform(settings.prbs_order, settings.fclk, fs, settings.vdc, periods)
    x = _pris_states(A, B[:, 0], settings, fs, v_bridge.size, x0)
    nodes = [port_node] + list(circuit.probes)
    rows = [mna.outputs.index(f"v({p})") for p in nodes]
    y = x @ C[rows].T + v_bridge[:, None] @ D[rows].T
    i_in = x[:, mna.states.index(f"i({SENSE_INDUCTOR})")]
    out = {"time_s": t, "v_bprbs": v_bridge, "v_in": y[:, 0], "i_in": i_in}
    for j, p in enumerate(circuit.probes, start=1):
        out[f"v_{p}"] = y[:, j]
    return out


def _pris_states(A: np.ndarray, b: np.ndarray, settings: SourceSettings, fs: float, K: int,
                 x0: np.ndarray | None) -> np.ndarray:
    """States at the K sample instants for the PRBS-switched bridge voltage (see :func:`simulate_pris`)."""
    n = A.shape[0]
    p, q = clock_ratio(settings.fclk, fs)
    unit = 1.0 / (p * float(fs))  # s; bit b spans [b q, (b + 1) q), sample k sits at k p
    n_bits = (K - 1) * p // q + 1  # bits active at some sample instant
    periods = -(-n_bits // (2 ** settings.prbs_order - 1))
    bits = lfsr_prbs(settings.prbs_order, periods)[:n_bits]
    level = np.where(bits == 1, settings.vdc, -settings.vdc)
    cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def disc(length: int) -> tuple[np.ndarray, np.ndarray]:
        if length not in cache:
            Phi, Gam = zoh(A, b[:, None], length * unit)
            cache[length] = (Phi, Gam[:, 0])
        return cache[length]

    Phi_h, g_h = disc(p)
    b_idx = np.arange(n_bits, dtype=np.int64)
    k_first = -(-(b_idx * q) // p)  # first sample in each bit
    k_next = np.minimum(-(-((b_idx + 1) * q) // p), K)  # first sample of the next bit
    counts = k_next - k_first
    max_count = int(counts.max()) if n_bits else 0
    # powers of Phi(h) and the accumulated input response, for the samples inside a bit
    P = np.empty((max(max_count, 1), n, n))
    G = np.empty((max(max_count, 1), n))
    P[0], G[0] = np.eye(n), np.zeros(n)
    for j in range(1, max_count):
        P[j] = Phi_h @ P[j - 1]
        G[j] = Phi_h @ G[j - 1] + g_h
    first = np.zeros((n_bits, n))  # state at the first sample of each bit
    x = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float)
    for bi in range(n_bits):
        u = level[bi]
        c = int(counts[bi])
        start = bi * q
        if c <= 0:  # no sample inside this bit
            Phi, g = disc(q)
            x = Phi @ x + g * u
            continue
        d0 = int(k_first[bi]) * p - start
        if d0:
            Phi, g = disc(d0)
            x = Phi @ x + g * u
        first[bi] = x
        last = P[c - 1] @ x + G[c - 1] * u
        tail = (bi + 1) * q - (int(k_first[bi]) + c - 1) * p
        Phi, g = disc(tail)
        x = Phi @ last + g * u
    if n_bits * max_count == K and np.all(counts == max_count):  # fs a multiple of fclk: one product
        X = first @ P.reshape(max_count * n, n).T + level[:, None] * G.reshape(1, max_count * n)
        return X.reshape(K, n)
    X = np.empty((K, n))
    for j in range(max_count):
        sel = counts > j
        X[k_first[sel] + j] = first[sel] @ P[j].T + level[sel, None] * G[j]
    return X


def simulate_current_injection(
    dut: Circuit,
    port: str,
    i_samples: np.ndarray,
    fs: float,
    shorts: Sequence[str] = (),
    overrides: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """DUT voltages for a sampled current injected at its port (thesis 4.2.3).

    Sample k of the current holds from ``k / fs`` to ``(k + 1) / fs``; the
    response is exact for that piecewise-constant current, from zero state.

    Parameters
    ----------
    dut : Circuit
    port : str
        Node the current enters (from ground).
    i_samples : numpy.ndarray, A
        Current samples.
    fs : float, Hz
        Sampling frequency.
    shorts : sequence of str
        Nodes tied to ground.
    overrides : mapping, optional
        Parameter or element values replacing the circuit's.

    Returns
    -------
    dict
        ``time_s`` (s), ``i_in`` (A, the input), ``v_in`` (V, port voltage)
        and ``v_<probe>`` (V) for the DUT's probes.
    """
    circuit = dut.shorted(shorts) if shorts else dut
    port_node = circuit.require_node(port, "port")
    if port_node == GROUND:
        raise CircuitError("the driven port cannot be ground")
    values = checked_values(circuit, overrides)
    mna = MNA(circuit, current_inputs=[port_node])
    ss = mna.state_space(values)
    i = np.asarray(i_samples, dtype=float).ravel()
    _, y = simulate_pwc(ss, i, 1.0 / float(fs))
    out = {"time_s": np.arange(i.size) / float(fs), "i_in": i, "v_in": y[:, mna.outputs.index(f"v({port_node})")]}
    for p in circuit.probes:
        if p != port_node:
            out[f"v_{p}"] = y[:, mna.outputs.index(f"v({p})")]
    return out


def pris_ngspice(
    dut: Circuit,
    port: str,
    settings: SourceSettings,
    fs: float,
    periods: int = 1,
    shorts: Sequence[str] = (),
    max_step: float = 2e-9,
    rise_time: float = 1e-12,
) -> dict[str, np.ndarray]:
    """The PRIS arrangement simulated by ngspice, for cross-checking :func:`simulate_pris`.

    The bridge is a PWL voltage source switching between ``+-vdc`` at the
    PRBS clock instants (ramps of ``rise_time`` centred on them); the
    transient starts from zero state (``uic``) with the given maximum step.
    ngspice's output is interpolated linearly to the sample instants ``k / fs``.

    Parameters
    ----------
    dut, port, settings, fs, periods, shorts
        As for :func:`simulate_pris`.
    max_step : float, s
        ngspice maximum time step.
    rise_time : float, s
        Width of the PWL ramps.

    Returns
    -------
    dict
        ``time_s``, ``v_bprbs``, ``v_in``, ``i_in`` and ``v_<probe>`` as in :func:`simulate_pris`.
    """
    from dataclasses import replace

    from . import ngspice

    circuit = pris_arrangement(dut, port, settings, shorts)
    checked_values(circuit)
    port_node = circuit.ports[0]
    t, v_bridge = hbridge_waveform(settings.prbs_order, settings.fclk, fs, settings.vdc, periods)
    bits = lfsr_prbs(settings.prbs_order, periods)
    level = np.where(bits == 1, 1.0, -1.0) * float(settings.vdc)
    points = [(0.0, float(level[0]))]
    for j in np.flatnonzero(np.diff(level)) + 1:
        tj = float(j) / float(settings.fclk)
        points += [(tj - rise_time / 2, float(level[j - 1])), (tj + rise_time / 2, float(level[j]))]
    pairs = [f"{ti!r} {vi!r}" for ti, vi in points]
    spec = "PWL(" + "\n+ ".join(" ".join(pairs[i:i + 4]) for i in range(0, len(pairs), 4)) + ")"
    elements = [replace(e, source_spec=spec) if e.name == BRIDGE else e for e in circuit.elements]
    deck = replace(circuit, elements=elements)
    nodes = [port_node] + list(circuit.probes)
    res = ngspice.transient(deck, nodes, [SENSE_INDUCTOR], tstop=float(t[-1]), tstep=1.0 / fs, max_step=max_step)
    out = {"time_s": t, "v_bprbs": v_bridge, "v_in": np.interp(t, res["time"], res[f"v({port_node})"]),
           "i_in": np.interp(t, res["time"], res[f"i({SENSE_INDUCTOR})"])}
    for p in circuit.probes:
        out[f"v_{p}"] = np.interp(t, res["time"], res[f"v({p})"])
    return out
