"""Run the network FMUs with fmpy: single runs, PRIS waveforms, and a co-simulation master.

:class:`FmuRunner` reads an FMU's model description once, instantiates it
once and resets it before every further run (fmpy's efficient-loop pattern:
an optimiser evaluating many parameter sets reuses one instance). Log
messages of the FMU are collected; a rejected parameter set raises
:class:`FmuError` carrying the FMU's own one-line reason.

:func:`cosimulate` couples a PRIS source FMU and a DUT FMU at the sampling
rate: the source takes the DUT terminal voltage and returns the RLC current,
the DUT takes that current and returns its terminal voltage. Explicit
coupling delays each exchanged signal by up to one communication step; the
error against the monolithic FMU is measured by :func:`coupling_error`
rather than hidden.
"""

from __future__ import annotations

import itertools
import shutil
from collections import deque
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pris_cosim.circuits.arrangement import SourceSettings
from pris_cosim.errors import CircuitError


class FmuError(ValueError):
    """An FMU call failed, typically on rejected parameter values; the message holds the FMU's logged reason."""


#: FMU log messages ``(number, instance name, status, text)``, newest last (shared by all instances).
_MESSAGES: deque[tuple[int, str, int, str]] = deque(maxlen=2000)
_MESSAGE_NUMBER = itertools.count()
_CALLBACKS = None
_COUNTER = itertools.count(1)


def _log_message(component, instance_name, status, category, message) -> None:  # fmi2CallbackLogger
    name = instance_name.decode("utf-8", "replace") if instance_name else ""
    text = message.decode("utf-8", "replace") if message else ""
    _MESSAGES.append((next(_MESSAGE_NUMBER), name, int(status), text))


def _next_message_number() -> int:
    return _MESSAGES[-1][0] + 1 if _MESSAGES else 0


def _callbacks():
    """FMI 2.0 callbacks with a logger that lives as long as the process.

    fmpy formats variadic log messages through a native proxy that keeps the
    most recently registered logger in one global slot; a logger created per
    instance (fmpy's ``logger=`` argument) dangles once its instance is gone
    and crashes the next FMU that logs. One callback object for the whole
    process avoids that.
    """
    global _CALLBACKS
    if _CALLBACKS is None:
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )
        from fmpy.logging import addLoggerProxy

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(_log_message)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(cb))
        _CALLBACKS = cb
    return _CALLBACKS


class FmuRunner:
    """One FMU instance reused for many runs.

    Parameters
    ----------
    path : path
        The ``.fmu`` file (or an extracted FMU directory).
    fmi_type : {"CoSimulation", "ModelExchange"}

    Attributes
    ----------
    model_description : fmpy.model_description.ModelDescription
    name : str
        Instance name (unique in the process).
    """

    def __init__(self, path: str | Path, fmi_type: str = "CoSimulation"):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        self.path = Path(path)
        if not self.path.exists():
            raise FileNotFoundError(f"FMU {self.path} does not exist")
        if fmi_type not in ("CoSimulation", "ModelExchange"):
            raise ValueError(f"fmi_type must be 'CoSimulation' or 'ModelExchange' (got {fmi_type!r})")
        self.fmi_type = fmi_type
        md = self.model_description = read_model_description(str(self.path))
        if md.fmiVersion != "2.0":
            raise ValueError(f"FMU {self.path.name}: FMI {md.fmiVersion} is not supported (FMI 2.0 only)")
        iface = md.coSimulation if fmi_type == "CoSimulation" else md.modelExchange
        if iface is None:
            raise ValueError(f"FMU {self.path.name} does not support {fmi_type}")
        self._tmp = None if self.path.is_dir() else extract(str(self.path))
        self.unzipdir = str(self.path if self._tmp is None else self._tmp)
        self.name = f"{iface.modelIdentifier}#{next(_COUNTER)}"
        self.variables = {v.name: v for v in md.modelVariables}
        cls = FMU2Slave if fmi_type == "CoSimulation" else FMU2Model
        self.instance = cls(guid=md.guid, unzipDirectory=self.unzipdir, modelIdentifier=iface.modelIdentifier,
                            instanceName=self.name)
        self.instance.instantiate(callbacks=_callbacks())
        self._mark = _next_message_number()
        self._runs = 0

    @property
    def messages(self) -> list[str]:
        """Log messages of this instance since its last run started (``"[STATUS] text"``)."""
        labels = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]
        return [f"[{labels[s] if 0 <= s < 6 else s}] {text}" for k, name, s, text in list(_MESSAGES)
                if k >= self._mark and name == self.name]

    def vr(self, name: str) -> int:
        """Value reference of a variable by name."""
        try:
            return self.variables[name].valueReference
        except KeyError:
            raise CircuitError(f"FMU {self.path.name} has no variable {name!r}") from None

    def _error(self, exc: Exception) -> FmuError:
        errors = [m for m in self.messages if m.startswith(("[ERROR]", "[FATAL]"))]
        reason = errors[-1] if errors else str(exc)
        return FmuError(f"FMU {self.path.name}: {reason}")

    def fresh(self) -> None:
        """Reset the instance if it has run before (start values restored, state zero)."""
        if self._runs:
            self.instance.reset()
        self._mark = _next_message_number()
        self._runs += 1

    def apply(self, start_values: Mapping[str, float] | None) -> None:
        """Set start values (parameters, by FMU variable name) on the instance."""
        for name, value in (start_values or {}).items():
            var = self.variables.get(name)
            if var is None:
                raise CircuitError(f"FMU {self.path.name} has no variable {name!r}")
            if var.causality not in ("parameter", "input"):
                raise CircuitError(f"FMU {self.path.name}: {name!r} is a {var.causality}, it cannot be set")
            if var.type == "Integer":
                self.instance.setInteger([var.valueReference], [int(value)])
            else:
                self.instance.setReal([var.valueReference], [float(value)])

    def initialize(self, start_values: Mapping[str, float] | None = None, start_time: float = 0.0) -> None:
        """Reset if needed, set start values and leave initialization mode (direct stepping)."""
        self.fresh()
        try:
            self.instance.setupExperiment(startTime=start_time)
            self.apply(start_values)
            self.instance.enterInitializationMode()
            self.instance.exitInitializationMode()
        except CircuitError:
            raise
        except Exception as exc:
            raise self._error(exc) from None

    def run(self, stop_time: float, output_interval: float, output: Sequence[str] | None = None,
            start_values: Mapping[str, float] | None = None, **kwargs) -> np.ndarray:
        """One simulation with :func:`fmpy.simulate_fmu` on the reused instance.

        Parameters
        ----------
        stop_time, output_interval : float, s
        output : sequence of str, optional
            Variables to record (default: all outputs).
        start_values : mapping, optional
            Parameter values by FMU variable name.
        **kwargs
            Passed to :func:`fmpy.simulate_fmu` (``relative_tolerance``, ``input``, ...).

        Returns
        -------
        numpy.ndarray
            fmpy's structured result array (``time`` and the recorded variables).

        Raises
        ------
        FmuError
            The FMU rejected the parameters or a call failed; the message is the FMU's log.
        """
        from fmpy import simulate_fmu

        self.fresh()
        try:
            return simulate_fmu(self.unzipdir, model_description=self.model_description, fmu_instance=self.instance,
                                fmi_type=self.fmi_type, stop_time=stop_time, output_interval=output_interval,
                                output=output, start_values=dict(start_values or {}), **kwargs)
        except Exception as exc:
            raise self._error(exc) from None

    def close(self) -> None:
        """Free the instance and remove the extracted files."""
        if self.instance is not None:
            try:
                self.instance.freeInstance()
            finally:
                self.instance = None
                if self._tmp is not None:
                    shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> "FmuRunner":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ---------------------------------------------------------------------- PRIS waveforms
def _waveforms(result: np.ndarray, names: Sequence[str], fs: float, n: int) -> dict[str, np.ndarray]:
    if result.shape[0] < n:
        raise FmuError(f"FMU run returned {result.shape[0]} samples, expected {n}")
    out = {"time_s": np.arange(n) / float(fs)}
    for name in names:
        out[name] = np.asarray(result[name][:n], dtype=float)
    return out


def pris_samples(settings: SourceSettings, fs: float, periods: int) -> int:
    """Number of samples ``k / fs`` covering ``periods`` PRBS periods (as :func:`signals.hbridge_waveform`)."""
    from pris_cosim.lab.timedomain import clock_ratio

    p, q = clock_ratio(settings.fclk, fs)
    n_bits = int(periods) * (2 ** int(settings.prbs_order) - 1)
    return -(-n_bits * q // p)


def simulate_pris_fmu(
    runner: FmuRunner,
    settings: SourceSettings,
    fs: float,
    periods: int = 1,
    start_values: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """PRIS waveforms from a monolithic arrangement FMU run in fmpy (co-simulation).

    Parameters
    ----------
    runner : FmuRunner
        Instance of an arrangement FMU (see :func:`pris_cosim.fmi.codegen.arrangement_model`).
    settings : SourceSettings
        Source settings; vdc, fclk and the PRBS order are set on the FMU.
    fs : float, Hz
        Sampling (communication) frequency.
    periods : int
        PRBS periods.
    start_values : mapping, optional
        Further parameter values by FMU variable name.

    Returns
    -------
    dict
        ``time_s``, ``v_bprbs``, ``v_in``, ``i_in`` and ``v_<probe>``, as
        :func:`pris_cosim.lab.timedomain.simulate_pris`.
    """
    n = pris_samples(settings, fs, periods)
    names = [v.name for v in runner.model_description.modelVariables if v.causality == "output"]
    values = {"vdc": settings.vdc, "fclk": settings.fclk, "prbs_order": settings.prbs_order,
              "Rpris": settings.rpris, "Lpris": settings.lpris, "Cpris": settings.cpris}
    for name in ("rsnub", "csnub", "lsw", "csw"):  # parasitics exist in the FMU only when built with them
        value, element = getattr(settings, name), name.capitalize()
        if value == 0 and element in runner.variables:
            raise CircuitError(f"FMU {runner.path.name} contains {element}; settings.{name} = 0 needs an FMU "
                               "built without it")
        if value > 0:
            values[element] = value
    values.update(start_values or {})
    res = runner.run(stop_time=(n - 1) / float(fs), output_interval=1.0 / float(fs), output=names,
                     start_values=values)
    return _waveforms(res, names, fs, n)


def run_dut_fmu(
    runner: FmuRunner,
    i_samples: np.ndarray,
    fs: float,
    start_values: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """Drive a DUT FMU with a sampled current held constant per sample (co-simulation).

    The FMU counterpart of :func:`pris_cosim.lab.timedomain.simulate_current_injection`.

    Parameters
    ----------
    runner : FmuRunner
        Instance of a DUT FMU (input ``i_in``).
    i_samples : numpy.ndarray, A
        Sample k holds from ``k / fs`` to ``(k + 1) / fs``.
    fs : float, Hz
    start_values : mapping, optional
        Parameter values by FMU variable name.

    Returns
    -------
    dict
        ``time_s``, ``i_in`` and every output of the FMU (``v_in``, ``v_<probe>``).
    """
    i = np.asarray(i_samples, dtype=float).ravel()
    runner.initialize(start_values)
    outputs = [v.name for v in runner.model_description.modelVariables if v.causality == "output"]
    vr_out = [runner.vr(n) for n in outputs]
    vr_in = [runner.vr("i_in")]
    fmu = runner.instance
    h = 1.0 / float(fs)
    rec = np.empty((i.size, len(outputs)))
    try:
        for k in range(i.size):
            fmu.setReal(vr_in, [i[k]])
            rec[k] = fmu.getReal(vr_out)
            if k < i.size - 1:
                fmu.doStep(k * h, h)
    except Exception as exc:
        raise runner._error(exc) from None
    out = {"time_s": np.arange(i.size) * h, "i_in": i}
    out.update({n: rec[:, j] for j, n in enumerate(outputs)})
    return out


# ---------------------------------------------------------------------- co-simulation master
def cosimulate(
    source: FmuRunner,
    dut: FmuRunner,
    fs: float,
    n_samples: int,
    scheme: str = "gauss-seidel",
    substeps: int = 1,
    source_values: Mapping[str, float] | None = None,
    dut_values: Mapping[str, float] | None = None,
) -> dict[str, np.ndarray]:
    """Couple a PRIS source FMU and a DUT FMU (co-simulation) and record the waveforms.

    Parameters
    ----------
    source : FmuRunner
        Source FMU (input ``v_in``, outputs ``i_in``, ``v_bprbs``).
    dut : FmuRunner
        DUT FMU (input ``i_in``, outputs ``v_in`` and ``v_<probe>``).
    fs : float, Hz
        Sampling frequency: waveforms are recorded at ``k / fs``.
    n_samples : int
        Number of samples.
    scheme : {"jacobi", "gauss-seidel"}
        ``jacobi``: both FMUs step from ``t`` with the other's output at
        ``t`` held over the step. ``gauss-seidel``: the source steps first;
        the DUT then steps with the source current at the end of the step.
    substeps : int
        Communication steps per sample (the coupling error falls with the
        communication step).
    source_values, dut_values : mapping, optional
        Parameter values by FMU variable name.

    Returns
    -------
    dict
        ``time_s``, ``v_bprbs``, ``v_in``, ``i_in`` and the DUT's ``v_<probe>``.
    """
    if scheme not in ("jacobi", "gauss-seidel"):
        raise ValueError(f"scheme must be 'jacobi' or 'gauss-seidel' (got {scheme!r})")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be at least 1 (got {substeps!r})")
    source.initialize(source_values)
    dut.initialize(dut_values)
    probes = [v.name for v in dut.model_description.modelVariables
              if v.causality == "output" and v.name != "v_in"]
    s_in, s_i, s_vb = source.vr("v_in"), source.vr("i_in"), source.vr("v_bprbs")
    d_in, d_out = dut.vr("i_in"), [dut.vr("v_in")] + [dut.vr(p) for p in probes]
    S, D = source.instance, dut.instance
    n = int(n_samples)
    rec = np.empty((n, 3 + len(probes)))
    h = 1.0 / float(fs)
    H = h / int(substeps)
    gauss = scheme == "gauss-seidel"
    try:
        i_src, vb = S.getReal([s_i, s_vb])
        v_dut = D.getReal(d_out)
        for k in range(n):
            rec[k, 0], rec[k, 1], rec[k, 2] = vb, v_dut[0], i_src
            rec[k, 3:] = v_dut[1:]
            if k == n - 1:
                break
            for j in range(int(substeps)):
                t = k * h + j * H
                S.setReal([s_in], [v_dut[0]])
                if gauss:
                    S.doStep(t, H)
                    i_src = S.getReal([s_i])[0]
                    D.setReal([d_in], [i_src])
                    D.doStep(t, H)
                else:
                    D.setReal([d_in], [i_src])
                    S.doStep(t, H)
                    D.doStep(t, H)
                    i_src = S.getReal([s_i])[0]
                v_dut = D.getReal(d_out)
            vb = S.getReal([s_vb])[0]
    except CircuitError:
        raise
    except Exception as exc:
        raise FmuError(f"co-simulation failed at sample {k}: {exc}") from None
    out = {"time_s": np.arange(n) * h, "v_bprbs": rec[:, 0], "v_in": rec[:, 1], "i_in": rec[:, 2]}
    for j, p in enumerate(probes):
        out[p] = rec[:, 3 + j]
    return out


def relative_rms(a: np.ndarray, reference: np.ndarray) -> float:
    """``rms(a - reference) / rms(reference)`` (dimensionless)."""
    a, reference = np.asarray(a, float), np.asarray(reference, float)
    den = np.sqrt(np.mean(reference**2))
    return float(np.sqrt(np.mean((a - reference) ** 2)) / den) if den > 0 else float(np.sqrt(np.mean(a**2)))


def coupling_error(cosim: Mapping[str, np.ndarray], reference: Mapping[str, np.ndarray],
                   names: Sequence[str] = ("v_in", "i_in")) -> dict[str, float]:
    """Relative RMS error of co-simulated waveforms against the monolithic reference, per signal."""
    n = min(len(cosim["time_s"]), len(reference["time_s"]))
    return {k: relative_rms(cosim[k][:n], reference[k][:n]) for k in names}
