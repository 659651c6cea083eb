"""A user's netlist as the estimation model: one configuration driven at a named port."""

from __future__ import annotations

from pathlib import Path

from pris_cosim.frf.response import Response
from pris_cosim.models.builtin import Configuration, Model
from pris_cosim.circuits.netlist import read_netlist


def model_from_netlist(path: str | Path, port: str) -> Model:
    """Wrap the netlist at ``path`` as a :class:`~pris_cosim.models.builtin.Model` driven at ``port``.

    Parameters
    ----------
    path : str or Path
        SPICE-style netlist file (see ``pris_cosim.circuits.netlist``).
    port : str
        Node driven against ground 0; the configuration's response is ``Zin`` (ohm).

    Returns
    -------
    Model
        Named after the file stem, with the single configuration ``default``.

    Raises
    ------
    CircuitError
        For a netlist that does not load (file, line and column named) or a port that is not a node.
    """
    from pris_cosim.errors import CircuitError

    circuit = read_netlist(path)
    if port not in circuit.nodes:
        raise CircuitError(f"{path}: port {port!r} is not a node of the netlist (nodes: {', '.join(sorted(circuit.nodes))})")
    conf = Configuration("default", port, (), (Response("Zin"),))
    return Model(Path(path).stem, f"netlist {path}", circuit, {"default": conf})
