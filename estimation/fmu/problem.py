"""What an FMU estimate is compared on: the record, the approach's residuals and cost.

:class:`FmuProblem` is built from a JSON-ready *setup* (see
:func:`estimation.fmu.estimate.make_setup`) in every worker process, once
(:func:`problem`): the FMU is instantiated there and reused for every
evaluation the process makes.

Residuals of a unit-cube point ``x`` (the parameters in log or linear scale),
fixed length, dimensionless; the reported cost is their RMS:

``time``
    ``(y_o - t_o) / rms(t_o)`` for every compared output ``o``: the cost is
    the RMS error relative to the signal RMS (thesis (4.32) normalised).
``iemd``
    ``(v - t) sum_r 1/psi_r`` on the voltage output: its RMS is exactly
    ``C^i_nrmse`` (4.45) (:func:`estimation.costs.iemd_nrmse`).
``emd``
    ``(gamma_r - gamma~_r) / psi_r`` over the target's IMFs (the estimate's
    decomposition folded to the target's number of IMFs); the reported cost
    is ``C^m_nrmse`` (4.39) (:func:`estimation.costs.emd_nrmse`).
``frequency``
    ``log10 |H / H_t|`` of the Welch H1 response voltage / current of the
    simulated and recorded waveforms (:mod:`pris_cosim.signals.spectral` settings,
    half-record Hann segments) at the bins where the record's coherence is
    at least 0.99, in decades.

``response`` (ranks the design points)
    ``log10 |H / H_t|`` of the Welch H1 responses from the record's input (or
    recorded current) to every compared output, Hann segments of ``window``
    samples over the record's first ``2 window`` samples (the model run over
    that span only: :meth:`FmuProblem.response_span`), at the bins up to
    ``0.45 fs`` where the input has power and the record's coherence is at
    least 0.9 (:meth:`FmuProblem.response_target`).

A failed run (:class:`estimation.fmu.model.FmuModel` returns None) gives the
residual vector ``PENALTY`` everywhere: a cost far above any fit's.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from estimation import costs as _costs
from estimation.fmu.model import FmuModel, FmuSetupError
from estimation.parameters import Parameter, ParameterSet

__all__ = ["FmuProblem", "problem", "read_record", "parameter_set", "APPROACHES", "PENALTY"]

APPROACHES = ("time", "emd", "iemd", "frequency")
#: Residual value of a failed run (the cost of a failed run is this, dimensionless).
PENALTY = 1e3
#: A response stage compares this many segment lengths of the record (three half-overlapping Hann segments).
RESPONSE_SPAN_SEGMENTS = 2
COHERENCE_MIN = 0.99


def read_record(path: str | Path, columns: Sequence[str]) -> dict[str, np.ndarray]:
    """Columns ``time_s`` and ``columns`` of a waveform record (CSV, .npz, .mat).

    The project's reader (:func:`pris_cosim.measured.waveform_io.read_waveforms`) reads
    records with the standard columns; a CSV with other column names (another
    tool's FMU) is read as a header line of names and numeric rows.

    Raises
    ------
    FmuSetupError
        Missing file or column, non-numeric or non-uniform data (one line naming the file).
    """
    from pris_cosim.measured.waveform_io import read_waveforms

    p = Path(path)
    if not p.is_file():
        raise FmuSetupError(f"target file not found: {path}")
    try:
        data = read_waveforms(p)
    except ValueError:
        data = _read_plain_csv(p)
    need = ["time_s"] + [c for c in columns if c]
    for c in need:
        if c not in data:
            raise FmuSetupError(f"{path}: no column {c!r} (columns: {', '.join(data)})")
    t = np.asarray(data["time_s"], float)
    if t.size < 16:
        raise FmuSetupError(f"{path}: at least 16 samples needed (got {t.size})")
    dt = np.diff(t)
    if not (np.all(dt > 0) and np.ptp(dt) <= 1e-6 * np.mean(dt)):
        raise FmuSetupError(f"{path}: time_s must be uniformly sampled")
    return {c: np.asarray(data[c], float) for c in need}


def _read_plain_csv(p: Path) -> dict[str, np.ndarray]:
    lines = [ln for ln in p.read_text(encoding="utf-8", errors="replace").splitlines()
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise FmuSetupError(f"{p}: empty file")
    names = [c.strip() for c in lines[0].split(",")]
    try:
        rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]], float)
    except ValueError:
        raise FmuSetupError(f"{p}: non-numeric data row") from None
    if rows.ndim != 2 or rows.shape[1] != len(names) or not np.all(np.isfinite(rows)):
        raise FmuSetupError(f"{p}: every row needs {len(names)} finite numbers")
    return {n: rows[:, k] for k, n in enumerate(names)}


def parameter_set(spec: Mapping[str, Any], ties: Mapping[str, str] | None = None) -> ParameterSet:
    """Parameters of an FMU estimate: ``{name: [min, max, scale]}`` (log scale when both bounds are positive)."""
    params = []
    for name, (lo, hi, scale) in spec.items():
        value = float(np.sqrt(lo * hi)) if scale == "log" else 0.5 * (lo + hi)
        params.append(Parameter(name, value, lo, hi, scale=scale))
    for name, expr in (ties or {}).items():
        params.append(Parameter(name, 0.0, vary=False, expr=expr))
    return ParameterSet(params, circuit=None, passivity="none")


class FmuProblem:
    """Residuals and cost of unit-cube points for one FMU, record and approach (one per process)."""

    def __init__(self, setup: Mapping[str, Any]):
        self.setup = dict(setup)
        self.params = parameter_set({k: tuple(v) for k, v in setup["parameters"].items()}, setup.get("ties"))
        self.approach = setup["approach"]
        self.output = setup["output"]
        self.outputs = [self.output] + [o for o in setup.get("extra_outputs", []) if o != self.output]
        self.input = setup.get("input")
        self.current = self.input or setup.get("current")
        cols = self.outputs + ([self.current] if self.current else [])
        rec = read_record(setup["target"], cols)
        t = rec["time_s"]
        self.fs = float((t.size - 1) / (t[-1] - t[0]))
        self.n = int(t.size)
        self.targets = {o: rec[o] for o in self.outputs}
        self.i_target = rec[self.current] if self.current else None
        fmu_out = list(self.outputs)
        if self.input is None and self.current:
            fmu_out.append(self.current)
        elif self.approach == "frequency" and self.input is None:
            raise FmuSetupError("approach 'frequency' with an FMU without input needs 'current' (its current output)")
        self.has_frequency = self.current is not None
        from estimation.fmu.model import fmu_variables

        fmu_names = fmu_variables(setup["fmu"])[1]
        names = [k for k in self.params.names if k in fmu_names]  # helpers (e.g. couplings) only feed ties
        self.fixed = {k: float(v) for k, v in dict(setup.get("values") or {}).items()}
        names += [k for k in self.fixed if k not in names]
        self.model = FmuModel(setup["fmu"], names, fmu_out, input=self.input, substeps=int(setup.get("substeps", 2)),
                              hold=setup.get("input_hold") or "linear",
                              limit=1e6 * max(float(np.max(np.abs(v))) for v in self.targets.values()) + 1.0)
        self.simulations = 0
        self.seconds = 0.0
        self._last: tuple[bytes, np.ndarray | None] | None = None
        self._prepare()

    # ------------------------------------------------------------------ targets of each approach
    def _prepare(self) -> None:
        v = self.targets[self.output]
        self.scale = {o: float(np.sqrt(np.mean(x ** 2))) or 1.0 for o, x in self.targets.items()}
        if self.approach in ("emd", "iemd"):
            self.decomposer = _costs.Decomposer()
            self.gamma = self.decomposer.cached(v)
            self.psi = _costs.imf_ranges(self.gamma)
        if self.has_frequency:
            from estimation.approaches import WelchSettings, bin_frequencies, welch_h1

            fr = self.setup.get("frequency", {})
            self.welch = WelchSettings()
            nper = self.welch.segment(self.n)
            fmin = max(float(fr.get("fmin", 2 * self.fs / nper)), 2 * self.fs / nper)
            fmax = min(float(fr.get("fmax", self.fs / 4)), self.fs / 2)
            if not fmax > fmin:
                raise FmuSetupError(f"frequency band {fmin:g}..{fmax:g} Hz is empty for this record")
            bins, self.f = bin_frequencies(self.fs, nper, fmin, fmax, int(fr.get("points", 200)))
            _, H, coh, _ = welch_h1(self.i_target, [v], self.fs, self.welch, bins)
            keep = (coh[0] >= float(fr.get("coherence", COHERENCE_MIN))) & np.isfinite(H[0]) & (np.abs(H[0]) > 0)
            if keep.sum() < 5:
                if self.approach == "frequency":
                    raise FmuSetupError("fewer than 5 frequency bins of the record have coherence >= 0.99")
                self.has_frequency = False
                return
            self.bins, self.f, self.H_target = bins[keep], self.f[keep], H[0][keep]
            self._welch_h1 = welch_h1

    # ------------------------------------------------------------------ the response stage
    def response_target(self, nper: int) -> dict[str, Any] | None:
        """Welch H1 responses of the record from its reference signal to every compared output.

        The reference is the input column (input FMU) or the recorded current
        (own-drive FMU with ``current``). Kept: bins up to ``0.45 fs`` where the
        reference's PSD is at least 1e-4 of its peak and the coherence at
        least 0.9. None when the record has no reference or fewer than 5 bins
        are kept.

        Parameters
        ----------
        nper : int
            Samples per Hann segment (half overlapping).
        """
        if self.i_target is None:
            return None
        key = int(min(max(nper, 16), self.n))
        cache = self.__dict__.setdefault("_responses", {})
        if key in cache:
            return cache[key]
        from estimation.approaches import WelchSettings, welch_h1

        ws = WelchSettings(window="hann", overlap=0.5, nperseg=key)
        outs = [o for o in self.outputs if o != self.current]
        span = self.response_span(key)
        f, H, coh, pxx = welch_h1(self.i_target[:span], [self.targets[o][:span] for o in outs], self.fs, ws)
        keep = (f > 0) & (f <= 0.45 * self.fs) & (pxx >= 1e-4 * np.max(pxx))
        for h, c in zip(H, coh):
            keep &= (c >= 0.9) & np.isfinite(h) & (np.abs(h) > 0)
        if keep.sum() < 5:
            cache[key] = None
            return None
        bins = np.flatnonzero(keep)
        cache[key] = {"settings": ws, "bins": bins, "f": f[bins], "outputs": outs, "span": span,
                      "log": [np.log10(np.abs(h[bins])) for h in H]}
        return cache[key]

    def response_span(self, nper: int) -> int:
        """Samples of the record (from its start) whose responses a response stage compares.

        Three half-overlapping Hann segments (``2 nper`` samples), or the whole record when shorter. The
        model's responses and the record's come from the same input over the same segments, so an exact
        model matches them exactly (the transient and leakage of the segments are common to both); the
        frequency resolution is the segments' and each design point costs a run of that span only.

        Parameters
        ----------
        nper : int
            Samples per Hann segment.
        """
        return int(min(self.n, RESPONSE_SPAN_SEGMENTS * nper))

    def _response_residual(self, y: np.ndarray, nper: int) -> np.ndarray:
        from estimation.approaches import welch_h1

        tg = self.response_target(nper)
        span = tg["span"]
        ref = self.i_target[:span] if self.input else y[len(self.outputs)][:span]
        ys = [y[self.outputs.index(o)][:span] for o in tg["outputs"]]
        _, H, _, _ = welch_h1(ref, ys, self.fs, tg["settings"], tg["bins"])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.concatenate([np.log10(np.abs(h)) - t for h, t in zip(H, tg["log"])])

    def size(self, which: str | None = None, window: int | None = None) -> int:
        """Length of the residual vector of ``which`` (default: the approach)."""
        if which == "response":
            tg = self.response_target(int(window or self.n // 2))
            return int(tg["bins"].size * len(tg["outputs"])) if tg else 1
        if (which or self.approach) == "frequency":
            return int(self.bins.size)
        if self.approach == "emd":
            return int(self.gamma.size)
        if self.approach == "iemd":
            return self.n
        return self.n * len(self.outputs)

    def data(self) -> np.ndarray:
        """The compared data in the residuals' units (noise floor and scale of the verdict)."""
        if self.approach == "frequency":
            return np.log10(np.abs(self.H_target))
        if self.approach == "emd":
            return (self.gamma / self.psi[:, None]).ravel()
        if self.approach == "iemd":
            return self.targets[self.output] * float(np.sum(1.0 / self.psi))
        return np.concatenate([self.targets[o] / self.scale[o] for o in self.outputs])

    def values(self, x: np.ndarray) -> dict[str, float]:
        """Parameter values (SI) of one unit-cube point, ties included."""
        ev = self.params.evaluate(np.clip(np.asarray(x, float), 0.0, 1.0))
        return {**self.fixed, **{k: float(v) for k, v in ev.values.items()}}

    def simulate(self, x: np.ndarray, window: int | None = None) -> np.ndarray | None:
        """Outputs ``(n_outputs, window)`` of one unit-cube point over the first ``window`` samples (default
        all), None for a failed run (the last run is reused)."""
        w = self.n if window is None else int(min(window, self.n))
        key = np.clip(np.asarray(x, float), 0.0, 1.0).tobytes() + str(w).encode()
        if self._last is not None and self._last[0] == key:
            return self._last[1]
        t0 = time.perf_counter()
        y = self.model.simulate(self.values(x), self.fs, w, self.i_target[:w] if self.input else None)
        self.simulations += 1
        self.seconds += time.perf_counter() - t0
        self._last = (key, y)
        return y

    @property
    def stand_in(self) -> str:
        """Residuals of the first local stage: ``"frequency"`` when the record has a current, else the approach."""
        return "frequency" if self.has_frequency else self.approach

    def windows(self) -> list[int]:
        """Record lengths of the continuation stages (samples): doubling from ``first_window`` to the whole record.

        The time residual of a resonant network over a long record is a needle: a
        parameter a few percent off puts the late oscillations out of phase. Over a
        short first window it is smooth; each stage starts from the previous answer
        and doubles the window, so the basin narrows only as the start improves.
        """
        first = int(self.setup.get("first_window", 0) or max(32, self.n // 256))
        growth = float(self.setup.get("window_growth", 2.0))
        out: list[int] = []
        w = float(min(first, self.n))
        while growth * w <= self.n:
            if not out or int(w) > out[-1]:
                out.append(int(w))
            w *= growth
        return out

    def residual(self, x: np.ndarray, which: str | None = None, window: int | None = None
                 ) -> tuple[np.ndarray, float]:
        """Residual vector and cost of one unit-cube point for ``which`` (default: the approach).

        ``window`` (time residuals only): compare the first ``window`` samples. A failed run
        gives ``PENALTY`` everywhere.
        """
        which = which or self.approach
        if which == "response":
            nper = int(window or self.n // 2)
            tg = self.response_target(nper)
            y = self.simulate(x, tg["span"] if tg is not None else None)
            if y is None:
                return np.full(self.size(which, nper), PENALTY), PENALTY
            r = self._response_residual(y, nper)
            c = float(np.sqrt(np.mean(r ** 2)))
            return (r, c) if np.isfinite(c) else (np.full(r.size, PENALTY), PENALTY)
        if window is not None and which == "time" and window < self.n:
            y = self.simulate(x, window)
            if y is None:
                return np.full(window * len(self.outputs), PENALTY), PENALTY
            with np.errstate(over="ignore", invalid="ignore"):
                r = np.concatenate([(y[k] - self.targets[o][:window]) / self.scale[o]
                                    for k, o in enumerate(self.outputs)])
            c = float(np.sqrt(np.mean(r ** 2)))
            return (r, c) if np.isfinite(c) else (np.full(r.size, PENALTY), PENALTY)
        y = self.simulate(x)
        if y is None:
            return np.full(self.size(which), PENALTY), PENALTY
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            r, c = self._residual(y, which)
        if not (np.all(np.isfinite(r)) and np.isfinite(c)):
            return np.full(self.size(which), PENALTY), PENALTY
        return r, c

    def _residual(self, y: np.ndarray, which: str) -> tuple[np.ndarray, float]:
        v = y[0]
        vt = self.targets[self.output]
        if which == "time":
            r = np.concatenate([(y[k] - self.targets[o]) / self.scale[o] for k, o in enumerate(self.outputs)])
            return r, float(np.sqrt(np.mean(r ** 2)))
        if which == "iemd":
            r = (v - vt) * float(np.sum(1.0 / self.psi))
            return r, float(_costs.iemd_nrmse(self.gamma, v))
        if which == "emd":
            est = self.decomposer(v)
            nr = self.gamma.shape[0]
            if est.shape[0] > nr:  # fold the estimate's slowest extra IMFs into its last row
                est = np.vstack([est[:nr - 1], est[nr - 1:].sum(axis=0, keepdims=True)])
            elif est.shape[0] < nr:
                est = np.vstack([est[:-1], np.zeros((nr - est.shape[0], self.n)), est[-1:]])
            r = ((est - self.gamma) / self.psi[:, None]).ravel()
            return r, float(_costs.emd_nrmse(self.gamma, est))
        current = self.i_target if self.input else y[len(self.outputs)]
        _, H, _, _ = self._welch_h1(current, [v], self.fs, self.welch, self.bins)
        r = _costs.log_magnitude_error(self.H_target, H[0])
        return np.asarray(r, float), float(np.sqrt(np.mean(np.asarray(r, float) ** 2)))

    def residuals(self, U: np.ndarray) -> np.ndarray:
        """``(P, N)`` residuals of the approach at unit-cube points (the verdict's callable)."""
        U = np.atleast_2d(np.asarray(U, float))
        return np.array([self.residual(u)[0] for u in U])

    def stats(self) -> dict[str, Any]:
        return {"simulations": self.simulations, "failures": self.model.failures, "seconds": self.seconds,
                "samples": self.model.samples, "last_error": self.model.last_error,
                "failure_reasons": {k: dict(v) for k, v in self.model.failure_reasons.items()}}

    def reset_stats(self) -> None:
        """Counts from zero for a new estimate, and no run reused from the one before (a run's count does not
        depend on what the process ran earlier)."""
        self.simulations, self.seconds = 0, 0.0
        self._last = None
        self.model.failures = self.model.samples = 0
        self.model.failure_reasons = {}


_PROBLEMS: dict[str, FmuProblem] = {}


def problem(setup: Mapping[str, Any]) -> FmuProblem:
    """The process's :class:`FmuProblem` for ``setup`` (built, and the FMU instantiated, once per process)."""
    key = json.dumps(setup, sort_keys=True)
    if key not in _PROBLEMS:
        for old in _PROBLEMS.values():
            old.model.close()
        _PROBLEMS.clear()
        _PROBLEMS[key] = FmuProblem(setup)
    p = _PROBLEMS[key]
    p.reset_stats()
    return p
