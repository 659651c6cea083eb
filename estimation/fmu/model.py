"""An FMU (FMI 2.0 or 3.0 Co-Simulation, ours or another tool's) as a black-box winding model.

:class:`FmuModel` instantiates the FMU once and reuses the instance: every
evaluation resets it (``fmi2Reset`` / ``fmi3Reset``), sets the parameters,
initialises and steps through the record. An FMU that refuses the parameters,
fails a call, returns NaN or infinite outputs, or diverges (an output beyond
``limit``) costs a failed evaluation (``None``, counted in
:attr:`FmuModel.failures`, by reason in :attr:`FmuModel.failure_reasons`),
never an exception: the instance is reset (``fmi2Reset``/``fmi3Reset`` are
allowed in the error state), or, when even that fails, replaced by a fresh one
(the old one is dropped without ``freeInstance``: some Python FMUs crash the
host process when freed), so an FMU left in an error state cannot poison later
runs.

Inputs
------
An input FMU takes a recorded column as its input, replayed under one of two holds:

``"zoh"`` (zero-order hold)
    the sample ``u[k]`` is held over the whole interval ``[t_k, t_k + h)``, one
    communication step per sample: exact for an input that a DAC or a digital
    source drives (a PRBS of levels that change only at sample instants).
``"linear"``
    a continuous input (e.g. a measured current that flows through the
    source's series inductance) varies linearly between samples:

- an FMU that declares ``canInterpolateInputs`` gets the slope of every
  sample interval as its first input derivative (exact first-order hold);
- otherwise every sample interval is split into ``substeps`` communication
  steps, each holding the linear interpolant's value at its midpoint (the
  mean of the linear input over the step), whose error falls as
  ``1 / substeps**2``.

A full-arrangement FMU (source and winding, e.g. ``*_pris.fmu``) has no
input: it makes its own bridge voltage and is compared as it is.
"""

from __future__ import annotations

import ctypes
import math
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FmuModel", "FmuSetupError", "fmu_variables"]

_LOG: list[str] = []
_LOG_COUNT = [0]


def _errors_only(inst: Any) -> None:
    """Let an FMI 2.0 instance log its error messages only (the reason of a failed run); logging off when
    it does not know the standard error categories."""
    cats = [c for c in ("logStatusError", "logStatusFatal")]
    try:
        inst.setDebugLogging(True, cats)
    except Exception:
        try:
            inst.setDebugLogging(False, [])
        except Exception:
            pass


def _log_mark() -> int:
    """Position in the FMUs' log messages (FMI 2.0 callback and FMI 3.0 list) before a run."""
    from pris_cosim.fmi.cosim import _MESSAGES

    return (_MESSAGES[-1][0] + 1 if _MESSAGES else 0) * 1_000_000 + _LOG_COUNT[0] % 1_000_000


def _log_since(mark: int) -> str:
    """The last error message an FMU logged since ``mark`` (status error or fatal), or ''."""
    from pris_cosim.fmi.cosim import _MESSAGES

    first, n3 = divmod(mark, 1_000_000)
    texts = [t for num, _, st, t in _MESSAGES if num >= first and st >= 3 and t.strip()]
    new = (_LOG_COUNT[0] - n3) % 1_000_000
    texts += [t for t in (_LOG[-new:] if new else []) if t.startswith(("[3]", "[4]"))]
    if not texts:
        return ""
    lines = [ln.strip() for ln in texts[-1].splitlines() if ln.strip()]
    # a Python FMU logs its traceback: the last line names the exception
    return lines[-1] if lines else ""


def _reason_key(text: str) -> str:
    """A failure's reason with its instance-specific numbers removed (runs group by it)."""
    import re

    text = re.sub(r"^\[\d\]\s*", "", str(text).strip()) or "failed"
    text = re.sub(r"^([A-Za-z_]\w*)\(['\"](.*)['\"]\)$", r"\1: \2", text)  # ValueError('...') -> ValueError: ...
    text = re.sub(r"t = [-+0-9.eE]+ s", "t = ... s", text)
    text = re.sub(r"\s+at\s+[A-Za-z_]\w*=[-+0-9.].*$", "", text)  # "... at k12=0.97, ...": values added later
    return text[:200]


class FmuSetupError(ValueError):
    """The FMU or the names given for it do not fit (one line naming the file or variable)."""


def _fmi3_log(env: Any, status: int, category: Any, message: Any) -> None:
    """FMI 3.0 log callback: messages kept (the last 200), not printed."""
    text = message.decode("utf-8", "replace") if message else ""
    _LOG.append(f"[{int(status)}] {text}")
    _LOG_COUNT[0] += 1
    del _LOG[:-200]


def fmu_variables(path: str | Path) -> tuple[Any, dict[str, Any]]:
    """Model description and variables by name of an FMU file (one-line errors)."""
    from fmpy import read_model_description

    p = Path(path)
    if not p.is_file():
        raise FmuSetupError(f"FMU file not found: {path}")
    try:
        md = read_model_description(str(p))
    except Exception as exc:  # not a zip, bad XML ...
        raise FmuSetupError(f"{path}: not a readable FMU ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    if md.fmiVersion not in ("2.0", "3.0"):
        raise FmuSetupError(f"{path}: FMI {md.fmiVersion} is not supported (FMI 2.0 or 3.0)")
    if md.coSimulation is None:
        raise FmuSetupError(f"{path}: the FMU has no Co-Simulation interface")
    return md, {v.name: v for v in md.modelVariables}


class FmuModel:
    """One reusable FMU instance that simulates a record for given parameter values.

    Parameters
    ----------
    path : str or Path
        ``.fmu`` file, FMI 2.0 or 3.0 with Co-Simulation.
    parameters : sequence of str
        FMU variables set per evaluation (causality ``parameter``).
    outputs : sequence of str
        FMU variables recorded at every sample instant.
    input : str, optional
        The FMU's current input (causality ``input``); None for an FMU with its own source.
    substeps : int
        Communication steps per sample interval for an input FMU that cannot interpolate inputs
        (linear hold).
    hold : {"linear", "zoh"}
        How the input varies between samples (see the module docstring).
    limit : float
        Outputs beyond this magnitude count as a diverged run.

    Attributes
    ----------
    simulations : int
        Runs started.
    samples : int
        Samples simulated over all runs.
    failures : int
        Runs that failed (call error, NaN, divergence).
    last_error : str
        Reason of the last failure.
    """

    def __init__(self, path: str | Path, parameters: Sequence[str], outputs: Sequence[str],
                 input: str | None = None, substeps: int = 4, limit: float = 1e12, hold: str = "linear"):
        from fmpy import extract

        self.path = Path(path)
        self.md, self.variables = fmu_variables(path)
        self.fmi3 = self.md.fmiVersion == "3.0"
        for name in parameters:
            v = self.variables.get(name)
            if v is None:
                raise FmuSetupError(f"{self.path.name} has no variable {name!r} (parameters)")
            if v.causality not in ("parameter", "input") or v.type not in ("Real", "Float64"):
                raise FmuSetupError(f"{self.path.name}: {name!r} is not a real parameter (causality {v.causality})")
        for name in outputs:
            if name not in self.variables:
                raise FmuSetupError(f"{self.path.name} has no variable {name!r} (output)")
        if input is not None:
            v = self.variables.get(input)
            if v is None or v.causality != "input":
                raise FmuSetupError(f"{self.path.name}: {input!r} is not an input of the FMU")
        if hold not in ("linear", "zoh"):
            raise FmuSetupError(f"input hold must be 'linear' or 'zoh' (got {hold!r})")
        if int(substeps) < 1:
            raise FmuSetupError(f"substeps must be at least 1 (got {substeps})")
        self.parameters, self.outputs, self.input = list(parameters), list(outputs), input
        self.substeps, self.limit, self.hold = int(substeps), float(limit), hold
        self.interpolates = bool(getattr(self.md.coSimulation, "canInterpolateInputs", False)) and not self.fmi3
        self._vr_par = [self.variables[n].valueReference for n in self.parameters]
        self._vr_out = [self.variables[n].valueReference for n in self.outputs]
        self._vr_in = [self.variables[input].valueReference] if input else []
        self._tmp = extract(str(self.path))
        self.instance: Any = None
        self._dropped: list[Any] = []
        self.simulations = 0
        self.samples = 0
        self.failures = 0
        self.last_error = ""
        #: Failed runs by reason: {reason: {"runs": count, "at": parameter values of the first such run}}.
        self.failure_reasons: dict[str, dict[str, Any]] = {}
        self._used = False
        self._instantiate()

    # ------------------------------------------------------------------ instance
    def _instantiate(self) -> None:
        from fmpy.fmi2 import FMU2Slave
        from fmpy.fmi3 import FMU3Slave

        ident = self.md.coSimulation.modelIdentifier
        if self.fmi3:
            inst = FMU3Slave(guid=self.md.guid, unzipDirectory=self._tmp, modelIdentifier=ident,
                             instanceName="pris-estimate")
            inst.instantiate(logMessage=_fmi3_log)
        else:
            from pris_cosim.fmi.cosim import _callbacks

            inst = FMU2Slave(guid=self.md.guid, unzipDirectory=self._tmp, modelIdentifier=ident,
                             instanceName="pris-estimate")
            inst.instantiate(callbacks=_callbacks(), loggingOn=True)
            _errors_only(inst)
        self.instance = inst
        self._used = False

    def _free(self) -> None:
        inst, self.instance = self.instance, None
        if inst is None:
            return
        try:
            inst.freeInstance()
        except Exception:  # an instance in error state may refuse even that
            pass

    def close(self) -> None:
        """Free the instance and remove the extracted files."""
        self._free()
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> "FmuModel":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ runs
    def simulate(self, values: Mapping[str, float], fs: float, n: int, u: np.ndarray | None = None
                 ) -> np.ndarray | None:
        """Outputs at the sample instants ``k / fs``, or None when the run failed.

        Parameters
        ----------
        values : mapping
            Parameter values by FMU variable name (SI units).
        fs : float, Hz
            Sampling frequency of the record.
        n : int
            Samples.
        u : numpy.ndarray, optional
            ``(n,)`` input samples (A) for an input FMU.

        Returns
        -------
        numpy.ndarray or None
            ``(len(outputs), n)``.
        """
        self.simulations += 1
        self.samples += int(n)
        if self.instance is None:
            self._instantiate()
        mark = _log_mark()
        try:
            y = self._run(values, float(fs), int(n), u)
        except Exception as exc:  # a refused value, a failed call: the instance may be unusable
            y, self.last_error = None, _log_since(mark) or f"{type(exc).__name__}: {exc}"
        if y is not None and not np.all(np.isfinite(y)):
            y, self.last_error = None, "non-finite outputs"
        if y is not None and np.max(np.abs(y), initial=0.0) > self.limit:
            y, self.last_error = None, f"outputs beyond {self.limit:g} (diverged)"
        if y is None:
            self.failures += 1
            key = _reason_key(self.last_error)
            row = self.failure_reasons.setdefault(key, {"runs": 0, "at": {k: float(v) for k, v in values.items()}})
            row["runs"] += 1
            self._recover()
        return y

    def _recover(self) -> None:
        """After a failed run: reset the instance (allowed in the FMI error state); when even that fails,
        a fresh instance, the old one dropped without ``freeInstance`` (some Python FMUs crash the host
        process when freed)."""
        try:
            self.instance.reset()
            self._used = False
            return
        except Exception:
            pass
        self._dropped.append(self.instance)
        self.instance = None
        self._instantiate()

    def _run(self, values: Mapping[str, float], fs: float, n: int, u: np.ndarray | None) -> np.ndarray:
        inst = self.instance
        if self._used:
            inst.reset()
        self._used = True
        f = inst._functions
        c = inst.component
        h = 1.0 / fs
        pv = [float(values[k]) for k in self.parameters]
        if self.fmi3:
            inst.enterInitializationMode(startTime=0.0)
            if self._vr_par:
                inst.setFloat64(self._vr_par, pv)
            if u is not None:
                inst.setFloat64(self._vr_in, [float(u[0])])
            inst.exitInitializationMode()
            do_step = f["fmi3DoStep"]
            get = f["fmi3GetFloat64"]
            set_ = f["fmi3SetFloat64"]
            flags = [ctypes.c_bool() for _ in range(3)]
            last = ctypes.c_double()
            step_args = (ctypes.c_bool(True), ctypes.byref(flags[0]), ctypes.byref(flags[1]),
                         ctypes.byref(flags[2]), ctypes.byref(last))

            def step(t: float, dt: float) -> int:
                return do_step(c, ctypes.c_double(t), ctypes.c_double(dt), *step_args)
        else:
            inst.setupExperiment(startTime=0.0)
            if self._vr_par:
                inst.setReal(self._vr_par, pv)
            inst.enterInitializationMode()
            if u is not None:
                inst.setReal(self._vr_in, [float(u[0])])
            inst.exitInitializationMode()
            do_step = f["fmi2DoStep"]
            get = f["fmi2GetReal"]
            set_ = f["fmi2SetReal"]

            def step(t: float, dt: float) -> int:
                return do_step(c, ctypes.c_double(t), ctypes.c_double(dt), 1)
        no = len(self._vr_out)
        vr_out = (ctypes.c_uint32 * no)(*self._vr_out)
        buf = (ctypes.c_double * no)()
        vr_in = (ctypes.c_uint32 * 1)(*(self._vr_in or [0]))
        ubuf = (ctypes.c_double * 1)()
        out = np.empty((n, no))
        extra = (no,) if self.fmi3 else ()
        one = (1,) if self.fmi3 else ()

        def put(value: float) -> None:
            ubuf[0] = value
            if set_(c, vr_in, 1, ubuf, *one) > 1:
                raise RuntimeError(f"setting {self.input} failed")

        deriv = None
        if u is not None and self.interpolates and self.hold == "linear":
            deriv = f["fmi2SetRealInputDerivatives"]
            order = (ctypes.c_int32 * 1)(1)
            dbuf = (ctypes.c_double * 1)()
        m = self.substeps
        for k in range(n):
            t = k * h
            if u is not None:
                put(float(u[k]))
            if get(c, vr_out, no, buf, *extra) > 1:
                raise RuntimeError("reading the outputs failed")
            out[k] = buf[:]
            if k == n - 1:
                break
            if u is None or self.hold == "zoh":
                if step(t, h) > 1:
                    raise RuntimeError(f"doStep at t = {t:.6g} s failed")
            elif deriv is not None:
                dbuf[0] = (float(u[k + 1]) - float(u[k])) * fs
                if deriv(c, vr_in, 1, order, dbuf) > 1:
                    raise RuntimeError("setting the input derivative failed")
                if step(t, h) > 1:
                    raise RuntimeError(f"doStep at t = {t:.6g} s failed")
            else:
                u0, du = float(u[k]), float(u[k + 1]) - float(u[k])
                for j in range(m):
                    put(u0 + du * (j + 0.5) / m)
                    if step(t + j * h / m, h / m) > 1:
                        raise RuntimeError(f"doStep at t = {t + j * h / m:.6g} s failed")
        return out.T

    def start_values(self) -> dict[str, float]:
        """Start values of the parameters declared by the FMU (NaN where none)."""
        out = {}
        for k in self.parameters:
            s = self.variables[k].start
            try:
                out[k] = float(s)
            except (TypeError, ValueError):
                out[k] = math.nan
        return out
