"""Source and winding values fitted together to a PRIS record replayed from its bridge voltage.

One fit's model is the PRIS source (``R``, ``L``, ``C`` and, with
``switch-ringing``, the bridge's ``L_sw`` and ``C_sw``) in closed form,
driving the winding's port impedance: the netlist's or model's circuit with
the catalogue's effects (:mod:`.catalogue`, evaluated by
:class:`.fit.FrequencyFit` on the alias grid of :mod:`.replay_record`). The
record's spectra are compared with the sampled responses times the bridge
voltage's spectrum.

Residuals (a negative log posterior, in units of the noise)
    ``(Y_model - Y) / sigma`` of ``v_in`` and of ``i_in`` at every bin, real
    and imaginary parts each with unit variance: both channels carry noise
    (the bridge voltage does not), and each is weighted by its own. The
    source's values held by the instrument's tolerance add
    ``ln(v / v_nominal) / ln(1 + source_tolerance)``, the winding's design
    values ``ln(v / d) / ln(1 + tolerance)`` (log-normal priors).

Parameter vector
    ``[ln R/R0, ln L/L0, ln C/C0, (ln L_sw, ln C_sw), x]`` where ``x`` is the
    winding fit's (log-ratio circuit values, then the effects' parameters).
    ``series-resistance`` frees ``R`` from its prior, ``component-drift``
    frees ``L`` and ``C``, ``switch-ringing`` adds ``L_sw`` and ``C_sw``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.circuits.mna import MNA
from pris_cosim.models.builtin import Configuration

from estimation.diagnosis.causes.catalogue import Effect, StrayCapacitance
from estimation.diagnosis.fit import FrequencyFit, bic
from estimation.diagnosis.waveform.record_spectra import PeriodicRecord, alias_grid, sampled_response, source_responses
from estimation.diagnosis.waveform.signals import SIGNALS

#: The source's causes and the source values each frees from the instrument's tolerance.
SOURCE_FREES = {"series-resistance": ("r",), "component-drift": ("l", "c"), "switch-ringing": ()}
_SRC = ("r", "l", "c")
#: Forward-difference step of the Jacobian (parameter units).
_FD_STEP = 1e-6
#: Modes whose free response over the dropped first period falls below this factor have decayed: no transient term.
SLOW_MODE = 1e-6
#: Points per decade of the log scan of a new effect's first parameter among the starts (screened in one batch).
SCAN_PER_DECADE = 4
#: ... then refined on each side of the best point (a cause that moves sharp resonances fits from a narrow basin).
FINE_POINTS = 4


@dataclass
class Part:
    """One candidate of the arrangement's catalogue: a source cause, one form of a winding cause, or a
    structure of the winding (``circuit``: a winding with one section more, :mod:`.replay_sections`).

    Attributes
    ----------
    cause : str
    effect : Effect, optional
        The form of a winding cause.
    circuit : Circuit, optional
        The winding replacing the design's (a structural cause).
    how : str
        What the structure is (e.g. "section 2 of the winding at n1 is two sections").
    couplings : tuple of str
        K elements of ``circuit`` fitted with its values.
    values : dict
        Lower-case name to value (SI) of the structure's own values as last fitted: the start of a refit
        from a fit of another structure.
    """

    cause: str
    effect: Effect | None = None
    circuit: Circuit | None = field(default=None, repr=False)
    how: str = ""
    couplings: tuple[str, ...] = ()
    values: dict[str, float] = field(default_factory=dict, repr=False)

    @property
    def label(self) -> str:
        if self.circuit is not None:
            return self.how
        return self.effect.label if self.effect is not None else f"{self.cause} [source]"


@dataclass
class ReplayFit:
    """Outcome of one fit (see :class:`ReplayProblem`)."""

    parts: list[Part]
    theta: np.ndarray = field(repr=False)
    rss: float
    penalty: float
    n_residuals: int
    n_params: int
    cost: float
    cost_per_signal: dict[str, float]
    source: dict[str, float]
    winding: dict[str, float]
    extra: list[dict[str, float]]
    predicted: np.ndarray = field(repr=False)
    nfev: int = 0
    wall_s: float = 0.0
    #: The winding's structure ("" for the design's, else the structural part's ``how``).
    structure: str = ""
    #: Lower-case names of the winding values the design prior holds in this structure.
    held: frozenset[str] = frozenset()

    @property
    def causes(self) -> list[str]:
        return list(dict.fromkeys(p.cause for p in self.parts))

    @property
    def cause(self) -> str:
        return "+".join(self.causes) or "none"

    @property
    def objective(self) -> float:
        """Negative log posterior times two: the weighted residuals' and the priors' squares."""
        return self.rss + self.penalty

    @property
    def bic(self) -> float:
        return bic(self.objective, self.n_residuals, self.n_params)


class ReplayProblem:
    """The record, the nominal source, the winding's design and one set of parts (causes) to fit.

    Parameters
    ----------
    rec : PeriodicRecord
    circuit : Circuit
        The winding (design values).
    configs : sequence of Configuration
        Its one test configuration (the port the source drives).
    response : str
        The configuration's impedance response name.
    fixed : sequence of str
        Values kept at the design.
    nominal : mapping
        ``rpris``, ``lpris``, ``cpris`` (Ohm, H, F).
    source_tolerance, tolerance : float
        Relative widths of the source's and the winding's priors (``inf``: free).
    parts : sequence of Part
    scale : float, Ohm
        Typical impedance of the winding (places the effects' elements).
    design : mapping
        Lower-case winding value name to design value (the values the prior holds).
    anchored : set of str or callable, optional
        Lower-case names of the winding values the prior holds in this structure (or a function of the
        structure's circuit giving them; default every design value).
    """

    def __init__(self, rec: PeriodicRecord, circuit: Circuit, configs: Sequence[Configuration], response: str,
                 fixed: Sequence[str], nominal: Mapping[str, float], source_tolerance: float, tolerance: float,
                 parts: Sequence[Part], scale: float, design: Mapping[str, float], anchored: Any = None):
        self.rec = rec
        self.parts = list(parts)
        self.W = alias_grid(rec.f, rec.h)
        self.neg = self.W < 0
        fgrid = np.abs(self.W).ravel() / (2 * np.pi)
        effects = [p.effect for p in self.parts if p.effect is not None]
        shape = next((p for p in self.parts if p.circuit is not None), None)
        self.structure = shape.how if shape is not None else ""
        self.ff = FrequencyFit(shape.circuit if shape is not None else circuit, configs, fgrid,
                               {response: np.ones(fgrid.size, complex)}, fixed, effects, scale=scale,
                               couplings=shape.couplings if shape is not None else ())
        self.response = response
        self.nominal = np.array([nominal["rpris"], nominal["lpris"], nominal["cpris"]], float)
        freed = {v for p in self.parts for v in SOURCE_FREES.get(p.cause, ())}
        self.ring = any(p.cause == "switch-ringing" for p in self.parts)
        self.src_held = np.array([k not in freed for k in _SRC])
        self.tau_s = math.log1p(source_tolerance) if math.isfinite(source_tolerance) else math.inf
        self.tau_w = math.log1p(tolerance) if math.isfinite(tolerance) else math.inf
        self.n_src = 3 + (2 if self.ring else 0)
        names = [n.lower() for n in self.ff.free]
        anchored = set(design) if anchored is None else (anchored(self.ff.circuit) if callable(anchored) else anchored)
        idx = [i for i, n in enumerate(names) if n in anchored and n in design]
        self.held = frozenset(names[i] for i in idx)
        #: Circuit values with no prior (a structure's own, freed couplings, or every one with an infinite
        #: tolerance): they count as parameters of the fit.
        self.n_unheld = len(names) - (len(idx) if math.isfinite(self.tau_w) else 0)
        self.w_idx = np.array(idx, int)
        self.w_log = np.array([math.log(self.ff.start[i] / design[names[i]]) for i in idx])
        self.design = dict(design)
        self.scale_y = np.sqrt(2.0) / rec.sigma  # (B, 2)
        self.n_data = 4 * rec.f.size
        self.power = np.sum(np.abs(rec.Y) ** 2, axis=0)
        self.port = configs[0].port
        settings = SourceSettings(vdc=1.0, prbs_order=4, fclk=1.0, rpris=float(self.nominal[0]),
                                  lpris=float(self.nominal[1]), cpris=float(self.nominal[2]),
                                  lsw=1e-6 if self.ring else 0.0, csw=1e-9 if self.ring else 0.0)
        # a stray admittance at the port as an element for the slow modes: C || R (its value at the top of the band)
        tcirc = self.ff.circuit
        self.lumped: list[tuple[int, Effect]] = []
        for j, eff in enumerate(self.ff.effects):
            if isinstance(eff, StrayCapacitance):
                tcirc = tcirc.copy()
                tcirc.add("Ct_stray", self.port, "0", 1e-12)
                tcirc.add("Rt_stray", self.port, "0", 1e12)
                self.lumped.append((j, eff))
        self.arr = pris_arrangement(tcirc, self.port, settings)
        self.mna = MNA(self.arr, voltage_inputs=[BRIDGE])
        self.arr_base = {k: float(v) for k, v in self.arr.resolve(check=False).items()}
        self.out_v = self.mna.outputs.index(f"v({self.arr.ports[0]})")
        self.i_state = self.mna.states.index(f"i({SENSE_INDUCTOR})")
        self.z = np.exp(2j * np.pi * rec.f * rec.h)
        self.L = int(rec.info.get("period_samples", 0))
        self.n_transient = 0

    # ------------------------------------------------------------------ layout
    @property
    def size(self) -> int:
        return self.n_src + self.ff.nc + len(self.ff.extra)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo_w, hi_w = self.ff.bounds()
        lo = [math.log(0.5) if h else math.log(0.05) for h in self.src_held]
        hi = [math.log(2.0) if h else math.log(20.0) for h in self.src_held]
        if self.ring:
            lo += [math.log(1e-4 * self.nominal[1]), math.log(1e-13)]
            hi += [math.log(1e-1 * self.nominal[1]), math.log(1e-5)]
        return np.concatenate([lo, lo_w]), np.concatenate([hi, hi_w])

    def vector(self, source: Mapping[str, float] | None = None, winding: Mapping[str, float] | None = None,
               extra: Sequence[Mapping[str, float]] | None = None) -> np.ndarray:
        """A parameter vector from values by name (defaults: nominal source, design winding, effects' first start)."""
        th = np.zeros(self.size)
        src = dict(source or {})
        for j, k in enumerate(_SRC):
            if k in src:
                th[j] = math.log(src[k] / self.nominal[j])
        if self.ring:
            th[3] = math.log(src.get("lsw", 1e-3 * self.nominal[1]))
            th[4] = math.log(src.get("csw", 1e-10))
        start = self.ff.start_vectors()[0]
        x = start.copy()
        for i, n in enumerate(self.ff.free):
            v = (winding or {}).get(n.lower())
            if v is not None and v > 0 and not self.ff.is_k[i]:
                x[i] = math.log(v / self.ff.start[i])
        # effects' parameters by (effect label, name)
        given = {}
        for p in extra or []:
            given.update(p)
        col = self.ff.nc
        for j, p in self.ff.extra:
            key = (self.ff.effects[j].label, p.name)
            if key in given:
                v = given[key]
                x[col] = math.log(v) if p.log else v
            col += 1
        th[self.n_src:] = x
        lo, hi = self.bounds()
        return np.clip(th, lo + 1e-9, hi - 1e-9)

    # ------------------------------------------------------------------ model
    def source_values(self, TH: np.ndarray) -> tuple[np.ndarray, ...]:
        v = self.nominal[None, :] * np.exp(TH[:, :3])
        if self.ring:
            return v[:, 0], v[:, 1], v[:, 2], np.exp(TH[:, 3]), np.exp(TH[:, 4])
        return v[:, 0], v[:, 1], v[:, 2], None, None

    def predict(self, TH: np.ndarray) -> np.ndarray:
        """Model spectra ``(P, B, 2)`` of ``v_in`` and ``i_in`` for parameter vectors ``(P, p)``."""
        TH = np.atleast_2d(TH)
        X = TH[:, self.n_src:]
        with np.errstate(all="ignore"):
            zw = self.ff.predict_batch(X)[self.response].reshape((TH.shape[0],) + self.W.shape)
            zw = np.where(self.neg[None], np.conj(zw), zw)
            r, l, c, lsw, csw = self.source_values(TH)
            v, i = source_responses(zw, self.W[None], r, l, c, lsw, csw)
            out = np.stack([sampled_response(v, self.W, self.rec.h), sampled_response(i, self.W, self.rec.h)],
                           axis=2)
        return out * self.rec.U[None, :, None]

    def transient_basis(self, TH: np.ndarray) -> list[np.ndarray]:
        """Per parameter vector the free-response columns ``(B, q)`` of the slow modes, with their output
        weights ``(2, q)`` folded in: column ``j`` of output ``o`` is ``basis[:, j] * gain[o, j]``."""
        P = TH.shape[0]
        Xc = TH[:, self.n_src:self.n_src + self.ff.nc]
        V = self.ff.values_of(Xc)
        over = {n: V[:, i] for i, n in enumerate(self.ff.free)}
        vals = self.ff.circuit.resolve(over, check=False)
        values = {k: np.full(P, v) for k, v in self.arr_base.items()}
        for k, v in vals.items():
            if k in values:
                values[k] = np.broadcast_to(np.asarray(v, float), (P,)).copy()
        r, l, c, lsw, csw = self.source_values(TH)
        values.update(rpris=r, lpris=l, cpris=c)
        if self.lumped:
            params = self.ff.effect_params(TH[:, self.n_src:])
            for j, eff in self.lumped:
                p = params[j]
                w0 = 2 * math.pi * eff.f_ref
                values["ct_stray"] = p["c"] * np.sin(p["alpha"] * math.pi / 2)
                values["rt_stray"] = 1 / np.maximum(w0 * p["c"] * np.cos(p["alpha"] * math.pi / 2), 1e-15)
        if self.ring:
            values.update(lsw=lsw, csw=csw)
        ss = self.mna.state_space(values)
        out = []
        for p in range(P):
            lam = np.linalg.eigvals(ss.A[p])
            mu = np.exp(lam * self.rec.h)
            slow = np.flatnonzero((np.abs(mu) ** self.L > SLOW_MODE) & (lam.imag >= 0) & np.isfinite(mu))
            cols = []
            for i in slow:
                b = self.z / (self.z - mu[i])
                if lam[i].imag > 0:
                    b2 = self.z / (self.z - np.conj(mu[i]))
                    cols += [b + b2, 1j * (b - b2)]
                else:
                    cols.append(b)
            out.append(np.stack(cols, axis=1) if cols else np.zeros((self.z.size, 0), complex))
        return out

    def residuals(self, TH: np.ndarray, shared: bool = False) -> np.ndarray:
        """Weighted residuals ``(P, n)``: the data's (real, imaginary) after the slow modes' free response
        (fitted linearly), then the priors'. ``shared``: every row uses the first row's slow modes (the
        rows of a finite-difference Jacobian)."""
        TH = np.atleast_2d(TH)
        e = (self.predict(TH) - self.rec.Y[None]) * self.scale_y[None]
        groups = []
        if self.L:
            # rows with the same circuit, source and lumped port values share their slow modes
            cols = list(range(self.n_src + self.ff.nc)) + [self.n_src + self.ff.nc + c for c, (j, _) in
                                                            enumerate(self.ff.extra) if j in dict(self.lumped)]
            if shared:
                inv, uniq = np.zeros(TH.shape[0], int), TH[:1]
            else:
                _, first, inv = np.unique(TH[:, cols], axis=0, return_index=True, return_inverse=True)
                uniq, inv = TH[first], np.ravel(inv)
            with np.errstate(all="ignore"):
                basis = self.transient_basis(uniq)
            groups = [(np.flatnonzero(inv == u), Bm) for u, Bm in enumerate(basis)]
        for rows, Bm in groups:
            if not Bm.shape[1]:
                continue
            self.n_transient = 2 * Bm.shape[1]
            for o in range(2):
                Bw = Bm * self.scale_y[:, o, None]
                Q, _ = np.linalg.qr(np.concatenate([Bw.real, Bw.imag]))
                Er = np.concatenate([e[rows, :, o].real, e[rows, :, o].imag], axis=1)  # (p, 2B)
                ok = np.all(np.isfinite(Er), axis=1)
                Er[ok] -= (Er[ok] @ Q) @ Q.T
                nb = Bm.shape[0]
                e[rows, :, o] = Er[:, :nb] + 1j * Er[:, nb:]
        parts = [e.real.reshape(TH.shape[0], -1), e.imag.reshape(TH.shape[0], -1)]
        if math.isfinite(self.tau_s) and self.src_held.any():
            parts.append(TH[:, :3][:, self.src_held] / self.tau_s)
        if math.isfinite(self.tau_w) and self.w_idx.size:
            parts.append((self.w_log[None, :] + TH[:, self.n_src + self.w_idx]) / self.tau_w)
        r = np.concatenate(parts, axis=1)
        return np.where(np.isfinite(r), r, 1e6)

    # ------------------------------------------------------------------ fit
    def fit(self, starts: Sequence[np.ndarray], max_nfev: int = 40, screen: int = 2) -> ReplayFit:
        """Least squares from the ``screen`` best of ``starts`` (their costs in one batch); the best wins."""
        t0 = time.perf_counter()
        lo, hi = self.bounds()
        S = np.array([np.clip(s, lo + 1e-9, hi - 1e-9) for s in starts])
        if S.shape[0] > screen:
            cost = np.sum(self.residuals(S) ** 2, axis=1)
            groups = getattr(self, "start_groups", None)
            groups = groups if groups is not None and groups.size == S.shape[0] else np.zeros(S.shape[0], int)
            picked = []
            for g in np.unique(groups):  # the best start from each set of values (fitted; nominal and design)
                idx = np.flatnonzero(groups == g)
                best, best_cost = S[idx[np.argmin(cost[idx])]], float(np.min(cost[idx]))
                for col, step in getattr(self, "scan_cols", []):  # the scanned parameter refined around it
                    fine = np.repeat(best[None], 2 * FINE_POINTS + 1, axis=0)
                    fine[:, col] += np.linspace(-step, step, 2 * FINE_POINTS + 1)
                    fine = np.clip(fine, lo + 1e-9, hi - 1e-9)
                    fc = np.sum(self.residuals(fine) ** 2, axis=1)
                    if fc.min() < best_cost:
                        best, best_cost = fine[np.argmin(fc)], float(fc.min())
                picked.append((best_cost, best))
            picked.sort(key=lambda x: x[0])
            S = np.array([b for _, b in picked[:max(screen, 1)]])
        best, nfev = None, 0
        for x0 in S:
            cache: dict[str, Any] = {}

            def fun(x, cache=cache):
                R = self.residuals(np.vstack([x, x + np.diag(np.where(x + _FD_STEP <= hi, _FD_STEP, -_FD_STEP))]),
                                   shared=True)
                cache["x"], cache["R"] = x.copy(), R
                return R[0]

            def jac(x, cache=cache):
                if "x" not in cache or not np.array_equal(cache["x"], x):
                    fun(x)
                R = cache["R"]
                st = np.where(x + _FD_STEP <= hi, _FD_STEP, -_FD_STEP)
                return ((R[1:] - R[0]) / st[:, None]).T

            sol = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=max_nfev,
                                xtol=1e-10, ftol=1e-10, gtol=1e-10)
            nfev += sol.nfev
            if best is None or np.sum(sol.fun ** 2) < np.sum(best.fun ** 2):
                best = sol
        return self.result(best.x, nfev, time.perf_counter() - t0)

    def result(self, x: np.ndarray, nfev: int = 0, wall: float = 0.0) -> ReplayFit:
        x = np.asarray(x, float)
        r = self.residuals(x[None])[0]
        nd = self.n_data
        pred = self.predict(x[None])[0]
        err = pred - self.rec.Y
        per = {s: float(np.sum(np.abs(err[:, j]) ** 2) / self.power[j]) for j, s in enumerate(SIGNALS)}
        rr, ll, cc, lsw, csw = self.source_values(x[None])
        source = {"r": float(rr[0]), "l": float(ll[0]), "c": float(cc[0])}
        if self.ring:
            source.update(lsw=float(lsw[0]), csw=float(csw[0]))
        xc = x[self.n_src:][None, :self.ff.nc]
        winding = {n.lower(): float(v) for n, v in zip(self.ff.free, self.ff.values_of(xc)[0])}
        extra = self.ff.extra_values(x[self.n_src:])
        n_par = (int((~self.src_held).sum()) + (2 if self.ring else 0) + len(self.ff.extra) + self.n_transient
                 + self.n_unheld)
        return ReplayFit(self.parts, x, float(np.sum(r[:nd] ** 2)), float(np.sum(r[nd:] ** 2)), nd, n_par,
                         float(sum(per.values())), per, source, winding, extra, pred, nfev, wall, self.structure,
                         self.held)

    def start_from(self, fit: ReplayFit | None) -> list[np.ndarray]:
        """Start vectors: the values of ``fit`` (nominal and design without one) with every start of the new
        parts' parameters."""
        src = fit.source if fit is not None else {}
        wnd = fit.winding if fit is not None else {}
        if fit is not None and fit.structure != self.structure:
            # another structure: only the values both hold alike, the structure's own as it was last fitted
            wnd = {k: v for k, v in wnd.items() if k in self.held and k in fit.held}
            for p in self.parts:
                wnd.update(p.values)
        given = {}
        if fit is not None:
            labels = [p.effect.label for p in fit.parts if p.effect is not None]
            for lab, vals in zip(labels, fit.extra):
                given.update({(lab, k): v for k, v in vals.items()})
        base = self.vector(src, wnd, [given])
        out = [base]
        new = [j for j, e in enumerate(self.ff.effects) if all((e.label, p.name) not in given for p in e.parameters)]
        if new:
            # from the fitted values and from the nominal and design ones (a fit without the new cause may have
            # absorbed it into distorted values)
            S = self.ff.start_vectors()
            cols = [self.ff.nc + c for c, (j, _) in enumerate(self.ff.extra) if j in new]
            # and a scan of each new port effect's first parameter (with every start of its others): an element
            # at the port moves every sharp resonance at once, and its cost has many local minima along its size
            scan = []
            self.scan_cols = []
            for j in new:
                eff = self.ff.effects[j]
                c0 = self.ff.nc + [c for c, (jj, _) in enumerate(self.ff.extra) if jj == j][0]
                p0 = eff.parameters[0]
                if p0.log and type(eff).port_map is not Effect.port_map:
                    n = int(math.ceil(SCAN_PER_DECADE * math.log10(p0.upper / p0.lower / 9))) + 1
                    self.scan_cols.append((self.n_src + c0, math.log(p0.upper / p0.lower / 9) / (n - 1)))
                    others = {tuple(np.delete(r, c0)): r for r in S}  # every start of the other parameters
                    for v in np.geomspace(p0.lower * 3, p0.upper / 3, n):
                        for r in others.values():
                            row = r.copy()
                            row[c0] = math.log(v)
                            scan.append(row)
            groups = [0]
            for g, b in enumerate((base, self.vector(None, None, [given])) if fit is not None else (base,)):
                for s in list(S) + scan:
                    th = b.copy()
                    th[self.n_src + np.array(cols)] = s[cols]
                    out.append(th)
                    groups.append(g)
            self.start_groups = np.array(groups)
        if self.ring and "lsw" not in src:
            out = [self._ring_start(th, fr, z0) for th in out[:1]
                   for fr in np.geomspace(self.rec.f[-1] / 10, 0.45 / self.rec.h, 10) for z0 in (30.0, 150.0, 750.0)]
        return out

    def _ring_start(self, th: np.ndarray, f_ring: float, z0: float) -> np.ndarray:
        w = 2 * math.pi * f_ring
        t = th.copy()
        t[3], t[4] = math.log(z0 / w), math.log(1 / (w * z0))
        return t
