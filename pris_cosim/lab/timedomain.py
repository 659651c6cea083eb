"""Exact time-domain simulation of linear networks with piecewise-constant inputs.

The PRIS source's H-bridge output is piecewise constant and the source RLC
plus winding network is linear, so zero-order-hold (ZOH) discretisation is
exact: over an interval of length h with constant input u,

.. math:: x(t + h) = \\Phi(h) x(t) + \\Gamma(h) u, \\qquad
          \\begin{bmatrix} \\Phi & \\Gamma \\\\ 0 & I \\end{bmatrix}
          = \\exp\\left(\\begin{bmatrix} A & B \\\\ 0 & 0 \\end{bmatrix} h\\right).

:func:`simulate_pwc` steps an arbitrary sampled input held constant per
sample; :func:`simulate_pris` runs the PRIS arrangement from zero state with
the PRBS switching instants handled exactly whatever the sampling rate, and
:func:`pris_record` gives the same waveforms in chunks of bounded size for
long records; :func:`simulate_current_injection` drives a DUT with a sampled
current (the time-domain estimation arrangement of thesis 4.2.3).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from fractions import Fraction
from functools import lru_cache

import numpy as np

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import GROUND, Circuit, Numeric
from pris_cosim.errors import CircuitError
from pris_cosim.circuits.mna import MNA, StateSpace
from pris_cosim.signals.perturbation import hbridge_waveform, lfsr_prbs

#: Samples per block of the blocked recurrence in :func:`simulate_pwc`.
_BLOCK = 64
#: Samples per chunk of a long PRIS record (about 2 MiB per column).
CHUNK_SAMPLES = 2**18
#: Largest table of per-sample powers kept for the bits of a PRIS record, bytes.
_TABLE_BYTES = 32 * 2**20


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
    from scipy.linalg import expm  # imported here: scipy.linalg costs a quarter second at start-up

    n, m = B.shape
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = A * h
    aug[:n, n:] = B * h
    e = expm(aug)
    return e[:n, :n], e[:n, n:]


def _single(ss: StateSpace) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if ss.A.shape[0] != 1:
        raise ValueError(f"time-domain simulation takes one parameter set, got {ss.A.shape[0]}")
    return ss.A[0], ss.B[0], ss.C[0], ss.D[0]


class _Stepper:
    """Blocked evaluation of ``x[k+1] = Phi x[k] + Gamma u[k]`` for one pair (Phi, Gamma).

    Inside a block of ``L`` steps the forced response is a product with the
    block-Toeplitz matrix of the Markov parameters ``Phi^j Gamma`` and the
    free response a product with the powers ``Phi^j``; only the block
    boundaries are stepped sequentially.
    """

    def __init__(self, Phi: np.ndarray, Gam: np.ndarray, block: int = _BLOCK):
        n, nu = Gam.shape
        L = max(int(block), 1)
        powers = np.empty((L + 1, n, n))  # Phi^0 .. Phi^L
        powers[0] = np.eye(n)
        for j in range(1, L + 1):
            powers[j] = Phi @ powers[j - 1]
        markov = powers[:L] @ Gam  # (L, n, nu): Phi^j Gamma
        # T[j, i] = Phi^(j-1-i) Gamma for i < j (contribution of u[i] to x[j] inside a block)
        T = np.zeros((L, L, n, nu))
        for j in range(1, L):
            T[j, :j] = markov[j - 1 :: -1][:j]
        self.Phi, self.Gam, self.L, self.n, self.nu = Phi, Gam, L, n, nu
        self._free = powers[:L].reshape(L * n, n).T  # (n, L n)
        self._forced = T.transpose(0, 2, 1, 3).reshape(L * n, L * nu).T  # (L nu, L n)
        self._PhiL = powers[L]

    def run(self, u: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States ``x[0..K-1]`` from ``x[0] = x0`` for inputs ``u`` of shape (K, nu), and ``x[K]``."""
        K, n, nu, L = u.shape[0], self.n, self.nu, self.L
        if K == 0:
            return np.empty((0, n)), np.array(x0, dtype=float)
        nblk = -(-K // L)
        if nblk * L == K:
            ub = u.reshape(nblk, L, nu)
        else:
            up = np.zeros((nblk * L, nu))
            up[:K] = u
            ub = up.reshape(nblk, L, nu)
        forced = (ub.reshape(nblk, L * nu) @ self._forced).reshape(nblk, L, n)
        end_forced = forced[:, -1] @ self.Phi.T + ub[:, -1] @ self.Gam.T  # forced part at the next block start
        starts = np.empty((nblk, n))
        x = np.asarray(x0, dtype=float)
        PhiL = self._PhiL
        for b in range(nblk):
            starts[b] = x
            x = PhiL @ x + end_forced[b]
        forced += (starts @ self._free).reshape(nblk, L, n)
        xs = forced.reshape(nblk * L, n)[:K]
        return xs, self.Phi @ xs[-1] + self.Gam @ u[-1]


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
    xs, _ = _Stepper(Phi, Gam, min(_BLOCK, max(K, 1))).run(u, x0)
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


def record_samples(settings: SourceSettings, fs: float, periods: int = 1) -> int:
    """Samples ``k / fs`` covering ``periods`` PRBS periods (as :func:`pris_cosim.signals.perturbation.hbridge_waveform`)."""
    p, q = clock_ratio(settings.fclk, fs)
    n_bits = int(periods) * (2 ** int(settings.prbs_order) - 1)
    return int(-(-n_bits * q // p))


def clock_ratio(fclk: float, fs: float) -> tuple[int, int]:
    """Integers ``(p, q)`` with ``fclk / fs = p / q`` (nearest fraction with q <= 2**31)."""
    if not (np.isfinite(fclk) and fclk > 0 and np.isfinite(fs) and fs > 0):
        raise CircuitError(f"fclk and fs must be positive (got {fclk!r} Hz, {fs!r} Hz)")
    r = (Fraction(fclk) / Fraction(fs)).limit_denominator(2**31)
    return r.numerator, r.denominator


class PrisRecord:
    """The exact PRIS waveforms of one arrangement, computed on demand in chunks.

    Made by :func:`pris_record`. ``columns`` names the arrays of every chunk
    (``time_s``, ``v_bprbs``, ``v_in``, ``i_in``, then ``v_<probe>``) and
    ``samples`` the record length; :meth:`chunks` yields consecutive pieces
    whose concatenation is :meth:`arrays`. Memory stays bounded by the chunk
    size whatever the record length, and the time is linear in it.

    Notes
    -----
    The state at the PRBS switching instants follows the one-bit recurrence
    ``x[b+1] = Phi(1/f_clk) x[b] + Gamma(1/f_clk) u[b]`` (blocked, see
    :func:`simulate_pwc`). Every sample is then ``Phi(d) x[b] + Gamma(d) u[b]``
    for its offset d from the start of its bit: the first sample of a bit
    through the binary powers ``Phi(2^i / (p f_s))``, the others through the
    powers of ``Phi(1/f_s)``. Outputs are formed directly from the bit-start
    states (``C Phi^j`` is tabulated once), so when ``f_s`` is an integer
    multiple of ``f_clk`` each output column is one matrix product.
    """

    def __init__(self, A: np.ndarray, b: np.ndarray, C: np.ndarray, D: np.ndarray, names: Sequence[str],
                 settings: SourceSettings, fs: float, periods: int, x0: np.ndarray | None = None):
        n = A.shape[0]
        self.columns: tuple[str, ...] = ("time_s", "v_bprbs") + tuple(names)
        self.fs = float(fs)
        p, q = clock_ratio(settings.fclk, fs)
        n_total = int(periods) * (2 ** int(settings.prbs_order) - 1)
        samples = record_samples(settings, fs, periods)
        if (samples - 1) * p >= 2**63 or n_total * q >= 2**63:
            raise CircuitError("fs / fclk is too irregular for exact integer timing at this length")
        self.samples = samples
        self._p, self._q = p, q
        self._unit = 1.0 / (p * float(fs))  # s; bit b spans [b q, (b + 1) q), sample k sits at k p
        self._n_bits = (self.samples - 1) * p // q + 1  # bits active at some sample instant
        self._order, self._periods, self._vdc = int(settings.prbs_order), int(periods), float(settings.vdc)
        self._A, self._b = A, b[:, None]
        self._C, self._D = np.asarray(C, float), np.asarray(D, float)
        self._x0 = np.zeros(n) if x0 is None else np.asarray(x0, dtype=float).reshape(n)
        self._cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._max_count = -(-q // p)  # most samples in one bit
        self._tabulated = self._max_count * n * max(n, 1) * 8 <= _TABLE_BYTES

    # ------------------------------------------------------------------ discretisation
    def _disc(self, length: int) -> tuple[np.ndarray, np.ndarray]:
        """``Phi``, ``Gamma`` (column) over ``length`` time units."""
        if length not in self._cache:
            self._cache[length] = zoh(self._A, self._b, length * self._unit)
        return self._cache[length]

    def _advance(self, x: np.ndarray, u: np.ndarray, d: np.ndarray) -> np.ndarray:
        """States ``x`` (m, n) advanced by ``d`` (m,) time units under constant inputs ``u`` (m,)."""
        x = x.copy()
        d = np.asarray(d, dtype=np.int64)
        top = int(d.max()).bit_length() if d.size else 0
        for i in range(top):
            sel = np.flatnonzero((d >> i) & 1)
            if sel.size:
                Phi, Gam = self._disc(1 << i)
                x[sel] = x[sel] @ Phi.T + u[sel, None] * Gam[:, 0]
        return x

    def _tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``C Phi(h)^j`` (c, no, n) and ``C Gamma_j + D`` (c, no) for the samples inside a bit."""
        if not hasattr(self, "_tab"):
            c = self._max_count if self._tabulated else 1
            Phi, g = self._disc(self._p)
            n = Phi.shape[0]
            P, G = np.empty((c, n, n)), np.empty((c, n))
            P[0], G[0] = np.eye(n), 0.0
            for j in range(1, c):
                P[j] = Phi @ P[j - 1]
                G[j] = Phi @ G[j - 1] + g[:, 0]
            self._tab = (self._C @ P, G @ self._C.T + self._D)
        return self._tab

    def _uniform_tables(self) -> np.ndarray:
        """``[C Phi^j; C Gamma_j + D]`` stacked as (no, n + 1, c): one product gives a bit's samples."""
        if not hasattr(self, "_utab"):
            CP, CG = self._tables()
            self._utab = np.ascontiguousarray(np.concatenate([CP, CG[:, :, None]], axis=2).transpose(1, 2, 0))
        return self._utab

    # ------------------------------------------------------------------ records
    def chunks(self, samples_per_chunk: int | None = CHUNK_SAMPLES) -> Iterator[dict[str, np.ndarray]]:
        """Consecutive pieces of the record.

        Parameters
        ----------
        samples_per_chunk : int or None
            About this many samples per piece (whole PRBS bits; a bit longer
            than this is split); ``None`` for one piece.

        Yields
        ------
        dict
            Column name to a 1-D float array (s, V, A), the same length for
            every column.
        """
        p, q, K = self._p, self._q, self.samples
        bits_per_chunk = self._n_bits if samples_per_chunk is None else max(1, int(samples_per_chunk) // self._max_count)
        if not self._tabulated:
            bits_per_chunk = 1
        level = _levels(self._order, self._n_bits, self._vdc)
        stepper = None
        x = self._x0
        for b0 in range(0, self._n_bits, bits_per_chunk):
            b1 = min(b0 + bits_per_chunk, self._n_bits)
            u = level[b0:b1]
            bi = np.arange(b0, b1, dtype=np.int64)
            k_first = -(-(bi * q) // p)
            k_next = np.minimum(-(-((bi + 1) * q) // p), K)
            with _one_blas_thread():  # small products: threads only contend, above all on a loaded machine
                if stepper is None:
                    stepper = _Stepper(*self._disc(q), min(_BLOCK, self._n_bits))
                xb, x = stepper.run(u[:, None], x)  # states at the bit starts b0 .. b1-1
                piece = self._piece(xb, u, bi, k_first, k_next) if self._tabulated else None
            if piece is not None:
                yield piece
            elif k_next[0] > k_first[0]:
                yield from self._long_bit(xb[0], float(u[0]), b0, int(k_first[0]), int(k_next[0]), samples_per_chunk)

    def _piece(self, xb: np.ndarray, u: np.ndarray, bi: np.ndarray, k_first: np.ndarray,
               k_next: np.ndarray) -> dict[str, np.ndarray]:
        """Samples of the bits ``bi`` from their start states ``xb`` (m, n) and levels ``u`` (m,)."""
        p, q = self._p, self._q
        counts = k_next - k_first
        k0, k1 = int(k_first[0]), int(k_next[-1])
        CP, CG = self._tables()  # (c, no, n), (c, no)
        c = CP.shape[0]
        names = self.columns[2:]
        t = np.arange(k0, k1, dtype=float)
        t /= self.fs
        out: dict[str, np.ndarray] = {"time_s": t, "v_bprbs": np.repeat(u, counts)}
        if p == 1 and np.all(counts == c):  # fs a multiple of fclk: every bit holds c samples from its start
            n = xb.shape[1]
            xu = np.empty((u.size, n + 1))
            xu[:, :n], xu[:, n] = xb, u
            M = self._uniform_tables()  # (no, n + 1, c)
            Y = np.empty((len(names), u.size * c))
            for o, name in enumerate(names):
                np.matmul(xu, M[o], out=Y[o].reshape(u.size, c))
                out[name] = Y[o]
            return out
        has = counts > 0
        xf = self._advance(xb[has], u[has], (k_first * p - bi * q)[has])  # states at each bit's first sample
        uf, kf, cf = u[has], k_first[has] - k0, counts[has]
        Y = np.empty((len(names), k1 - k0))
        for j in range(int(cf.max(initial=0))):
            sel = np.flatnonzero(cf > j)
            Y[:, kf[sel] + j] = (xf[sel] @ CP[j].T + uf[sel, None] * CG[j]).T
        for o, name in enumerate(names):
            out[name] = Y[o]
        return out

    def _long_bit(self, x_start: np.ndarray, u: float, bit: int, k_first: int, k_next: int,
                  samples_per_chunk: int | None) -> Iterator[dict[str, np.ndarray]]:
        """Samples of one bit too long for tabulated powers, stepped in pieces."""
        p, q = self._p, self._q
        x = self._advance(x_start[None, :], np.array([u]), np.array([k_first * p - bit * q]))[0]
        Phi, g = self._disc(p)
        stepper = _Stepper(Phi, g)
        step = k_next - k_first if samples_per_chunk is None else max(1, int(samples_per_chunk))
        for k in range(k_first, k_next, step):
            m = min(step, k_next - k)
            xs, x = stepper.run(np.full((m, 1), u), x)
            y = xs @ self._C.T + u * self._D
            out = {"time_s": np.arange(k, k + m, dtype=np.int64) / self.fs, "v_bprbs": np.full(m, u)}
            for o, name in enumerate(self.columns[2:]):
                out[name] = np.ascontiguousarray(y[:, o])
            yield out

    def arrays(self) -> dict[str, np.ndarray]:
        """The whole record at once: column name to a 1-D array of ``samples`` values."""
        parts = list(self.chunks(None))
        if len(parts) == 1:
            return parts[0]
        return {k: np.concatenate([c[k] for c in parts]) for k in self.columns}


def _one_blas_thread():  # noqa: ANN202
    """Context in which BLAS runs on one thread (threadpoolctl)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1, user_api="blas")


@lru_cache(maxsize=4)
def _prbs_period(order: int) -> np.ndarray:
    """One period of the PRBS of the given order (all-ones seed), read-only."""
    bits = lfsr_prbs(order, 1)
    bits.flags.writeable = False
    return bits


def _levels(order: int, n_bits: int, vdc: float) -> np.ndarray:
    """Bridge levels +-vdc (V) of the first ``n_bits`` PRBS bits (the sequence repeats every period)."""
    one = _prbs_period(order)
    reps = -(-n_bits // one.size)
    level = np.where(one == 1, vdc, -vdc)
    return np.tile(level, reps)[:n_bits] if reps > 1 else level[:n_bits]


def pris_record(
    dut: Circuit,
    port: str,
    settings: SourceSettings,
    fs: float,
    periods: int = 1,
    shorts: Sequence[str] = (),
    overrides: Mapping[str, float] | None = None,
    x0: np.ndarray | None = None,
) -> PrisRecord:
    """The exact PRIS waveforms of a DUT (thesis Fig. 2.15) as a record computed in chunks.

    Parameters are those of :func:`simulate_pris`; ``record.chunks()`` yields
    the waveforms piece by piece in bounded memory, ``record.arrays()`` all
    at once (what :func:`simulate_pris` returns).

    Raises
    ------
    NonPassiveError
        The circuit's inductance matrix is not positive definite.
    """
    if isinstance(periods, bool) or int(periods) != periods or periods < 1:
        raise CircuitError(f"periods must be a positive integer (got {periods!r})")
    circuit = pris_arrangement(dut, port, settings, shorts)
    port_node = circuit.ports[0]
    values = checked_values(circuit, overrides)
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    A, B, C, D = _single(mna.state_space(values))
    nodes = [port_node] + list(circuit.probes)
    rows = [mna.outputs.index(f"v({p})") for p in nodes]
    sense = np.zeros((1, A.shape[0]))
    sense[0, mna.states.index(f"i({SENSE_INDUCTOR})")] = 1.0
    Cout = np.vstack([C[rows[:1]], sense, C[rows[1:]]])
    Dout = np.concatenate([D[rows[:1], 0], [0.0], D[rows[1:], 0]])
    names = ["v_in", "i_in"] + [f"v_{p}" for p in circuit.probes]
    return PrisRecord(A, B[:, 0], Cout, Dout, names, settings, fs, int(periods), x0)


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
    integers in units of ``1 / (p fs)`` with ``f_clk / fs = p / q``. See
    :class:`PrisRecord` for the algorithm and :func:`pris_record` for long
    records in bounded memory.
    """
    return pris_record(dut, port, settings, fs, periods, shorts, overrides, x0).arrays()


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

    from pris_cosim.circuits import ngspice

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
