"""Exact coupling of a PRIS source FMU and a winding FMU (both linear, Model Exchange).

Each FMU supplies its linear model through ``fmi2GetDirectionalDerivative``
(``A = d der(x)/dx``, ``B = d der(x)/du``, ``C = dy/dx``, ``D = dy/du``; an
FMU without directional derivatives is probed by differences of
``fmi2GetDerivatives``, exact for a linear FMU) and its time events (the PRBS
switching instants) through ``fmi2NewDiscreteStates``. The master closes the
interface (source input ``v_in`` = winding output ``v_in``, winding input
``i_in`` = source output ``i_in``) algebraically and integrates the coupled
linear system exactly with the matrix exponential from event to event::

    z(t0 + tau) = e^{J tau} z(t0) + (int_0^tau e^{J s} ds) g

where ``J`` is the coupled state matrix and ``g`` the constant forcing
between two events, evaluated through the FMUs at each event. There is no
one-step delay and no iteration: the coupled waveforms are exact up to
rounding. At the first 16 events and at about 256 more spread over the
record, the master gives its exact state to both FMUs and compares their
interface outputs and derivatives with its own prediction; the largest
relative difference is reported as ``coupling_error`` (it exposes an FMU that
is not linear time-invariant).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from ctypes import POINTER, c_double

import numpy as np
import scipy.linalg

from pris_cosim.fmi.cosim import FmuError, FmuRunner


class _Unit:
    """One Model Exchange FMU: state vector, one input, the outputs the master needs."""

    def __init__(self, runner: FmuRunner, input_name: str, outputs: list[str]):
        md = runner.model_description
        self.runner = runner
        self.fmu = runner.instance
        self.deriv_vr = [d.variable.valueReference for d in md.derivatives]
        self.state_vr = [d.variable.derivative.valueReference for d in md.derivatives]
        self.n = len(self.state_vr)
        self.u_vr = runner.vr(input_name)
        self.y_vr = [runner.vr(o) for o in outputs]
        self.directional = bool(md.modelExchange.providesDirectionalDerivative)
        self._x = np.zeros(self.n)
        self._dx = np.zeros(self.n)

    def _ptr(self, a: np.ndarray):
        return a.ctypes.data_as(POINTER(c_double))

    def states(self) -> np.ndarray:
        self.fmu.getContinuousStates(self._ptr(self._x), self.n)
        return self._x.copy()

    def set_states(self, x: np.ndarray) -> None:
        self._x[:] = x
        self.fmu.setContinuousStates(self._ptr(self._x), self.n)

    def start(self, stop_time: float, values: Mapping[str, float] | None) -> float | None:
        """Initialise; returns the first announced event time (None if none)."""
        r = self.runner
        r.fresh()
        self.fmu.setupExperiment(startTime=0.0, stopTime=stop_time)
        r.apply(values)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        t_next = self._event_iteration()
        self.fmu.enterContinuousTimeMode()
        return t_next

    def _event_iteration(self) -> float | None:
        while True:
            need, terminate, _, _, defined, t_next = self.fmu.newDiscreteStates()
            if terminate:
                raise FmuError(f"FMU {self.runner.path.name} asked to terminate")
            if not need:
                return t_next if defined else None

    def event(self, t: float, x: np.ndarray) -> float | None:
        """Handle the time event at ``t`` with states ``x``; returns the next event time."""
        self.fmu.setTime(t)
        self.set_states(x)
        self.fmu.enterEventMode()
        t_next = self._event_iteration()
        self.fmu.enterContinuousTimeMode()
        return t_next

    def evaluate(self, x: np.ndarray, u: float) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives and outputs at states ``x`` and input ``u``."""
        self.set_states(x)
        self.fmu.setReal([self.u_vr], [u])
        self.fmu.getDerivatives(self._ptr(self._dx), self.n)
        return self._dx.copy(), np.array(self.fmu.getReal(self.y_vr))

    def linear_model(self, x: np.ndarray, u: float) -> tuple[np.ndarray, ...]:
        """``A, B, C, D`` (derivatives and outputs against states and the input)."""
        knowns = self.state_vr + [self.u_vr]
        unknowns = self.deriv_vr + self.y_vr
        cols = []
        if self.directional:
            for j in range(len(knowns)):
                seed = np.zeros(len(knowns))
                seed[j] = 1.0
                cols.append(np.array(self.fmu.getDirectionalDerivative(unknowns, knowns, seed.tolist())))
        else:  # affine FMU: differences are exact
            d0, y0 = self.evaluate(x, u)
            for j in range(len(knowns)):
                xj, uj = x.copy(), u
                if j < self.n:
                    xj[j] += 1.0
                else:
                    uj += 1.0
                d1, y1 = self.evaluate(xj, uj)
                cols.append(np.concatenate([d1 - d0, y1 - y0]))
            self.evaluate(x, u)
        M = np.column_stack(cols)
        n = self.n
        return M[:n, :n], M[:n, n:], M[n:, :n], M[n:, n:]


def cosimulate_exact(
    source: FmuRunner,
    dut: FmuRunner,
    fs: float,
    n_samples: int,
    source_values: Mapping[str, float] | None = None,
    dut_values: Mapping[str, float] | None = None,
    probes: Sequence[str] = (),
) -> tuple[dict[str, np.ndarray], float]:
    """Exact co-simulation of a source FMU and a winding FMU (both Model Exchange instances).

    Parameters
    ----------
    source : FmuRunner
        Source FMU opened as ``ModelExchange`` (input ``v_in``; outputs ``i_in``, ``v_bprbs``).
    dut : FmuRunner
        Winding FMU opened as ``ModelExchange`` (input ``i_in``; output ``v_in``).
    fs : float, Hz
        Sampling frequency: waveforms at ``k / fs``.
    n_samples : int
    source_values, dut_values : mapping, optional
        Parameter values by FMU variable name.
    probes : sequence of str
        Further outputs of the winding FMU to record (e.g. ``v_n3``), V.

    Returns
    -------
    waveforms : dict
        ``time_s``, ``v_bprbs``, ``v_in`` (V), ``i_in`` (A) and the probes.
    coupling_error : float
        Largest relative difference, at the events, between the FMUs' own
        outputs and the master's exact prediction (dimensionless).
    """
    for r in (source, dut):
        if r.fmi_type != "ModelExchange":
            raise ValueError(f"FMU {r.path.name} must be opened as ModelExchange for exact coupling")
    h = 1.0 / float(fs)
    n = int(n_samples)
    stop = (n - 1) * h
    S = _Unit(source, "v_in", ["i_in", "v_bprbs"])
    W = _Unit(dut, "i_in", ["v_in", *probes])
    try:
        t_next = S.start(stop, source_values)
        t_dut = W.start(stop, dut_values)
        if t_dut is not None:
            raise FmuError(f"FMU {dut.path.name} announces time events; the winding must be time-invariant")
        ns, nw = S.n, W.n
        z = np.concatenate([S.states(), W.states()])
        As, Bs, Cs, Ds = S.linear_model(z[:ns], 0.0)
        Aw, Bw, Cw, Dw = W.linear_model(z[ns:], 0.0)
        # interface: u_s = v_w(x_w, u_w), u_w = i_s(x_s, u_s): [1, -Dw; -Ds, 1] u = Cblk z + e
        Wm = np.array([[1.0, -Dw[0, 0]], [-Ds[0, 0], 1.0]])
        Cblk = np.zeros((2, ns + nw))
        Cblk[0, ns:] = Cw[0]
        Cblk[1, :ns] = Cs[0]
        K = np.linalg.solve(Wm, Cblk)
        J = np.zeros((ns + nw, ns + nw))
        J[:ns, :ns] = As
        J[ns:, ns:] = Aw
        J[:ns] += Bs[:, :1] @ K[:1]
        J[ns:] += Bw[:, :1] @ K[1:]
        N = ns + nw
        cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        aug = np.zeros((2 * N, 2 * N))
        aug[:N, :N] = J
        aug[:N, N:] = np.eye(N)

        def flow(tau: float) -> tuple[np.ndarray, np.ndarray]:
            key = int(round(tau / h * 2**20))
            if key not in cache:
                E = scipy.linalg.expm(aug * tau)
                cache[key] = (E[:N, :N], E[:N, N:])
            return cache[key]

        blocks: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

        def block(k0: int, k1: int, t0: float) -> tuple[np.ndarray, np.ndarray]:
            """Stacked flows to the samples k0..k1 of a segment that starts at t0 (reused per bit pattern)."""
            key = (int(round((k0 * h - t0) / h * 2**20)), k1 - k0)
            if key not in blocks:
                flows = [flow(max(j * h - t0, 0.0)) for j in range(k0, k1 + 1)]
                blocks[key] = (np.array([f[0] for f in flows]), np.array([f[1] for f in flows]))
            return blocks[key]

        Bblk = np.zeros((N, 2))
        Bblk[:ns, 0] = Bs[:, 0]
        Bblk[ns:, 1] = Bw[:, 0]
        Dblk = np.array([Ds[0, 0], Dw[0, 0]])

        def forcing(z: np.ndarray, u_guess: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
            """Interface inputs u = K z + k, the forcing g and the bridge voltage, from one FMU evaluation each.

            Both FMUs are affine in their input, so one evaluation at a guess
            ``u_guess`` gives the output offsets and the derivatives at the
            consistent interface inputs.
            """
            ds, ys = S.evaluate(z[:ns], u_guess[0])
            dw, yw = W.evaluate(z[ns:], u_guess[1])
            y = np.array([yw[0], ys[0]])  # [v_in from the winding, i_in from the source]
            e = y - Cblk @ z - Dblk[::-1] * u_guess[::-1]
            u = K @ z + np.linalg.solve(Wm, e)
            d = np.concatenate([ds, dw]) + Bblk @ (u - u_guess)
            probe_offset = yw[1:] - Cw[1:] @ z[ns:] - Dw[1:, 0] * u_guess[1]
            return u, d - J @ z, float(ys[1]), probe_offset

        out = np.empty((n, 3 + len(probes)))
        k, t0, err = 0, 0.0, 0.0
        u, g, vb, ep = forcing(z, np.zeros(2))
        check_every, event_no = 1, 0
        while k < n:
            last = t_next is None or t_next > stop * (1 + 1e-12)
            # samples strictly before the next event (the event instant belongs to the next segment)
            k_end = n - 1 if last else min(n - 1, int(np.ceil(t_next * fs * (1 - 1e-12))) - 1)
            if k_end >= k:
                offset = u - K @ z  # the interface inputs are K z + offset until the next event
                Ps, Qs = block(k, k_end, t0)
                Z = Ps @ z + Qs @ g
                U = Z @ K.T + offset
                out[k:k_end + 1, :3] = np.column_stack([np.full(U.shape[0], vb), U[:, 0], U[:, 1]])
                if probes:
                    out[k:k_end + 1, 3:] = Z[:, ns:] @ Cw[1:].T + np.outer(U[:, 1], Dw[1:, 0]) + ep
                k = k_end + 1
            if last:
                break
            P, Q = flow(t_next - t0)
            offset = u - K @ z
            z = P @ z + Q @ g
            if event_no % check_every == 0:  # the FMUs' own view of the exact state, before the event
                u_fmu, g_fmu, _, _ = forcing(z, K @ z + offset)
                du = np.abs(u_fmu - (K @ z + offset)).max() / max(np.abs(u_fmu).max(), 1e-300)
                dg = np.abs(g_fmu - g).max() / max(np.abs(J @ z + g).max(), 1e-300)
                err = max(err, float(du), float(dg))
            event_no += 1
            if event_no == 16:  # after the first events, check about 256 of them spread over the record
                check_every = max(1, int(stop / max(t_next - t0, 1e-300)) // 256)
            t0 = t_next
            t_next = S.event(t0, z[:ns])
            W.event(t0, z[ns:])
            u, g, vb, ep = forcing(z, K @ z + offset)
    except FmuError:
        raise
    except Exception as exc:
        raise FmuError(f"exact co-simulation failed: {exc}") from None
    waves = {"time_s": np.arange(n) * h, "v_bprbs": out[:, 0], "v_in": out[:, 1], "i_in": out[:, 2]}
    waves.update({p: out[:, 3 + j] for j, p in enumerate(probes)})
    return waves, err
