"""Run ngspice as an independent reference (AC and transient analyses).

Used by the cross-check tests and benchmarks, and by users who want a second
opinion on a netlist. Needs the ``ngspice`` executable on ``PATH``.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.circuits.netlist import format_netlist


class NgspiceError(RuntimeError):
    """ngspice is missing or failed."""


def available() -> bool:
    """True when an ``ngspice`` executable is on PATH."""
    return shutil.which("ngspice") is not None


def _run(deck: str, workdir: Path, timeout: float) -> None:
    (workdir / "deck.cir").write_text(deck)
    try:
        proc = subprocess.run(["ngspice", "-b", "deck.cir"], cwd=workdir, capture_output=True, text=True, timeout=timeout)
    except FileNotFoundError:
        raise NgspiceError("ngspice is not installed (apt-get install ngspice)") from None
    if not (workdir / "out.txt").exists():
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise NgspiceError(f"ngspice failed: {' | '.join(tail)}")


def _body(circuit: Circuit) -> str:
    return format_netlist(circuit).replace("\n.end\n", "\n")


def ac_analysis(
    circuit: Circuit,
    port: str,
    nodes: Sequence[str],
    fmin: float,
    fmax: float,
    points_per_decade: int = 20,
    timeout: float = 120.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Node voltages for a 1 A AC current injected at ``port`` (ngspice ``.ac dec``).

    Parameters
    ----------
    circuit : Circuit
        The network (sources in it keep their own AC settings, normally none).
    port : str
        Node driven by the current source (from ground).
    nodes : sequence of str
        Nodes whose complex voltages are returned (V per A).
    fmin, fmax : float, Hz
    points_per_decade : int

    Returns
    -------
    frequency : numpy.ndarray, Hz
        The frequencies ngspice used.
    voltages : numpy.ndarray
        Complex, shape ``(len(nodes), F)``.
    """
    vecs = " ".join(f"v({n})" for n in nodes)
    deck = (
        _body(circuit)
        + f"Ixxprobe 0 {port} DC 0 AC 1\n.options gmin=1e-30\n.control\nset wr_singlescale\nset wr_vecnames\n"
        + "option numdgt=16\n"
        + f"ac dec {int(points_per_decade)} {fmin!r} {fmax!r}\nwrdata out.txt {vecs}\n.endc\n.end\n"
    )
    with tempfile.TemporaryDirectory(prefix="ngspice-") as tmp:
        _run(deck, Path(tmp), timeout)
        data = np.loadtxt(Path(tmp) / "out.txt", skiprows=1, ndmin=2)
    f = data[:, 0]
    volts = np.array([data[:, 1 + 2 * k] + 1j * data[:, 2 + 2 * k] for k in range(len(nodes))])
    return f, volts


def transient(
    circuit: Circuit,
    nodes: Sequence[str],
    currents: Sequence[str],
    tstop: float,
    tstep: float,
    max_step: float,
    timeout: float = 600.0,
) -> dict[str, np.ndarray]:
    """Transient analysis from zero state (``uic``) with a maximum time step.

    Parameters
    ----------
    circuit : Circuit
        The network including its sources (e.g. a PWL H-bridge voltage).
    nodes : sequence of str
        Node voltages to return.
    currents : sequence of str
        V elements whose currents to return (ngspice convention: into n+).
    tstop, tstep, max_step : float, s

    Returns
    -------
    dict
        ``time`` and ``v(node)`` / ``i(V)`` arrays, at ngspice's own time points.
    """
    vecs = [f"v({n})" for n in nodes] + [f"i({v})" for v in currents]
    deck = (
        _body(circuit)
        + ".control\nset wr_singlescale\nset wr_vecnames\noption numdgt=16\n"
        + f"tran {tstep!r} {tstop!r} 0 {max_step!r} uic\nwrdata out.txt {' '.join(vecs)}\n.endc\n.end\n"
    )
    with tempfile.TemporaryDirectory(prefix="ngspice-") as tmp:
        _run(deck, Path(tmp), timeout)
        data = np.loadtxt(Path(tmp) / "out.txt", skiprows=1, ndmin=2)
    out = {"time": data[:, 0]}
    for k, name in enumerate(vecs):
        out[name] = data[:, 1 + k]
    return out
