"""The PRIS perturbation arrangement as one circuit: H-bridge, series RLC, device under test.

Thesis Fig. 2.15 / 4.2 / 5.2 / 5.6: the H-bridge applies ``+-V_DC`` (a
voltage source ``Vbridge``), optionally behind the switches' parasitic
inductance ``Lsw`` with their capacitance ``Csw`` and an RC snubber
(``Rsnub``, ``Csnub``) across the bridge output; then ``Rpris``, ``Lpris``,
``Cpris`` in series into the DUT port. The current into the DUT is the
``Lpris`` current; the H-bridge voltage is the input.

Source nodes are prefixed ``src_`` so they never collide with DUT nodes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.errors import CircuitError

BRIDGE = "Vbridge"
#: Node of the H-bridge output (without switch parasitics; with them the bridge drives ``src_hb``).
BRIDGE_NODE = "src_h"
SENSE_INDUCTOR = "Lpris"


@dataclass(frozen=True)
class SourceSettings:
    """PRIS source settings (thesis 2.3.4, 4.1.2, 5.1).

    Attributes
    ----------
    vdc : float, V
        H-bridge DC voltage.
    prbs_order : int
        LFSR order n (period 2^n - 1).
    fclk : float, Hz
        PRBS clock frequency.
    rpris, lpris, cpris : float, Ohm, H, F
        Series RLC.
    rsnub, csnub : float, Ohm, F, optional
        RC snubber across the bridge output (0 = none).
    lsw, csw : float, H, F, optional
        Switch parasitic inductance and capacitance (0 = ideal bridge).
    """

    vdc: float = 30.0
    prbs_order: int = 12
    fclk: float = 10e3
    rpris: float = 31.8e3
    lpris: float = 2.53
    cpris: float = 10e-9
    rsnub: float = 0.0
    csnub: float = 0.0
    lsw: float = 0.0
    csw: float = 0.0

    def __post_init__(self) -> None:
        for name in ("vdc", "fclk", "rpris", "lpris", "cpris"):
            if not getattr(self, name) > 0:
                raise CircuitError(f"source setting {name!r} must be positive (got {getattr(self, name)})")
        if not 2 <= int(self.prbs_order) <= 32:
            raise CircuitError(f"source setting 'prbs_order' must be between 2 and 32 (got {self.prbs_order})")
        for name in ("rsnub", "csnub", "lsw", "csw"):
            if getattr(self, name) < 0:
                raise CircuitError(f"source setting {name!r} must not be negative (got {getattr(self, name)})")
        if (self.rsnub > 0) != (self.csnub > 0):
            raise CircuitError("snubber needs both 'rsnub' and 'csnub' (or neither)")
        if self.csw > 0 and not self.lsw > 0:
            raise CircuitError("switch capacitance 'csw' needs a switch inductance 'lsw' in series with the bridge")


def source_circuit(settings: SourceSettings, terminal: str = "dut") -> Circuit:
    """The source alone: bridge, parasitics, snubber, series RLC ending at node ``terminal``."""
    c = Circuit(title="PRIS source")
    out = BRIDGE_NODE
    if settings.lsw > 0:
        c.add(BRIDGE, "src_hb", "0", 0.0, source_spec="DC 0")
        c.add("Lsw", "src_hb", out, settings.lsw)
        if settings.csw > 0:
            c.add("Csw", out, "0", settings.csw)
    else:
        c.add(BRIDGE, out, "0", 0.0, source_spec="DC 0")
    if settings.rsnub > 0:
        c.add("Rsnub", out, "src_sn", settings.rsnub)
        c.add("Csnub", "src_sn", "0", settings.csnub)
    c.add("Rpris", out, "src_r1", settings.rpris)
    c.add(SENSE_INDUCTOR, "src_r1", "src_r2", settings.lpris)
    c.add("Cpris", "src_r2", terminal, settings.cpris)
    return c


def pris_arrangement(dut: Circuit, port: str, settings: SourceSettings, shorts: Sequence[str] = ()) -> Circuit:
    """One circuit holding the PRIS source and the device under test.

    Parameters
    ----------
    dut : Circuit
        Device under test.
    port : str
        DUT node the source drives (against ground).
    settings : SourceSettings
    shorts : sequence of str
        DUT nodes tied to ground (short-circuit test configurations).

    Returns
    -------
    Circuit
        Inputs: the voltage of ``Vbridge``; the DUT current is ``i(Lpris)``.
    """
    d = dut.shorted(shorts) if shorts else dut
    port = d.require_node(port, "port")
    if port == "0":
        raise CircuitError("the driven port cannot be ground")
    src = source_circuit(settings, terminal=port)
    clash = sorted({e.key for e in src.elements} & {e.key for e in d.elements})
    if clash:
        raise CircuitError(f"DUT element {clash[0]!r} clashes with a PRIS source element name; rename it")
    if any(n.startswith("src_") for n in d.nodes):
        raise CircuitError("DUT node names must not start with 'src_' (reserved for the PRIS source)")
    return Circuit(
        title=f"PRIS arrangement: {d.title or 'DUT'} driven at {port}",
        elements=list(d.elements) + list(src.elements),
        parameters=list(d.parameters),
        ports=[port],
        probes=[p for p in d.probes if p != port],
        comments=list(d.comments),
    )
