"""How a recorded waveform drives the estimate: the recorded bridge voltage, or the sampled current.

Two unbiased ways to replay a PRIS record (``time_s``, ``v_bprbs``, ``i_in``,
``v_in``) into a candidate winding model:

``"bridge"`` (:class:`RecordBridgeEngine`)
    The whole arrangement (H-bridge, source ``Rpris``-``Lpris``-``Cpris``,
    winding) driven by the recorded bridge voltage. The H-bridge output is
    exactly piecewise constant and switches on the PRBS clock; when the
    clock instants fall on sample instants (``fs`` a multiple of ``f_clk``,
    as in every record the project makes), the zero-order hold of the
    samples *is* the true input and the replay is exact whatever the
    winding's resonances. Needs the source's R, L, C.
``"current"`` (:class:`estimation.approaches.InjectionEngine`, ``hold="linear"``)
    The sampled current injected at the port, varying linearly between
    samples (:mod:`estimation.holds`). Needs nothing about the source, but
    is exact only when the current is linear within a sample: fine when
    the sampling rate is well above the winding's fastest mode (two-section
    record at 1 MHz: 1.8e-4 of the signal RMS), biased when modes lie
    above the Nyquist frequency (three-section at 1 MHz: the current's ripple
    at those modes is aliased and no interpolation can recover it).

:func:`choose_drive` picks ``"bridge"`` when the source is known and the
record holds ``v_bprbs``, else ``"current"``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from pris_cosim.circuits.arrangement import BRIDGE, SENSE_INDUCTOR, SourceSettings, pris_arrangement
from pris_cosim.circuits.circuit import Circuit
from pris_cosim.circuits.mna import MNA

from estimation.approaches import ApproachError, PrisEngine

DRIVES = ("auto", "bridge", "current")


class RecordBridgeEngine(PrisEngine):
    """:class:`~estimation.approaches.PrisEngine` driven by a recorded bridge voltage instead of the PRBS.

    Parameters
    ----------
    dut : Circuit
    port : str
        Driven DUT node.
    settings : SourceSettings
        The source's ``rpris``, ``lpris``, ``cpris`` (and parasitics); ``vdc``,
        the PRBS order and clock are not used.
    fs : float, Hz
        Sampling frequency of the record.
    v_bprbs : array_like, V
        Bridge voltage; sample k holds from ``k / fs`` to ``(k + 1) / fs``.
    probes : sequence of str, optional
        DUT nodes whose voltages are returned as ``v_<node>``.
    """

    def __init__(self, dut: Circuit, port: str, settings: SourceSettings, fs: float, v_bprbs: np.ndarray,
                 probes: Sequence[str] | None = None):
        vb = np.asarray(v_bprbs, float).ravel()
        if vb.size < 2 or not np.all(np.isfinite(vb)):
            raise ApproachError("the bridge voltage needs at least 2 finite samples")
        self.dut, self.settings, self.fs, self.n_samples, self.spb = dut, settings, float(fs), vb.size, 1
        self.circuit = pris_arrangement(dut, port, settings)
        self.port = self.circuit.ports[0]
        self.probes = list(self.circuit.probes if probes is None else [p for p in probes if p != self.port])
        self.mna = MNA(self.circuit, voltage_inputs=[BRIDGE])
        self.level = vb
        nodes = [self.port] + self.probes
        self._rows = [self.mna.outputs.index(f"v({p})") for p in nodes]
        self._i_state = self.mna.states.index(f"i({SENSE_INDUCTOR})")
        self.names = ["v_in"] + [f"v_{p}" for p in self.probes] + ["i_in"]


def choose_drive(drive: str, source_known: bool, has_bridge: bool) -> str:
    """The drive to use: ``"bridge"`` or ``"current"``.

    Parameters
    ----------
    drive : {"auto", "bridge", "current"}
    source_known : bool
        The config gives the source's R, L, C (``"source"``).
    has_bridge : bool
        The record holds the bridge voltage ``v_bprbs``.

    Raises
    ------
    ApproachError
        ``"bridge"`` asked for without the source or without ``v_bprbs``; an unknown drive.
    """
    if drive not in DRIVES:
        raise ApproachError(f"drive must be one of {', '.join(DRIVES)} (got {drive!r})")
    if drive == "auto":
        return "bridge" if source_known and has_bridge else "current"
    if drive == "bridge" and not (source_known and has_bridge):
        raise ApproachError("drive 'bridge' needs the source's R, L, C (config key 'source') and a v_bprbs column")
    return drive


__all__ = ["RecordBridgeEngine", "choose_drive", "DRIVES"]
