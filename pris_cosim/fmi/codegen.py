"""C source of network FMUs, generated from the circuit description.

One :class:`NetworkModel` describes an FMU: which circuit, which inputs and
outputs, and the FMI variables (parameters with start values, states and
derivatives). Everything is derived from a :class:`~pris_cosim.circuits.circuit.Circuit`
and its compiled :class:`~pris_cosim.circuits.mna.MNA` topology; the generated
``model.c`` holds only tables (element nodes, the constant reduction bases
Q0/Q1, input maps, variable layout) and the parameter ties rendered with
:meth:`Expression.to_c`. The hand-written runtime in ``pris_cosim/c``
assembles G, Cn and L from element values at run time, reduces them to
state-space form exactly as :meth:`MNA.state_space` does, and steps it.

Five kinds of FMU:

``source``
    The PRIS source: PRBS-driven H-bridge, optional switch parasitics and
    snubber, series Rpris-Lpris-Cpris. Input ``v_in`` (DUT terminal voltage,
    V); outputs ``i_in`` (current into the DUT, A) and ``v_bprbs`` (V).
``dut``
    The device under test driven by a current. Input ``i_in`` (A) into the
    port; outputs ``v_in`` (port voltage) and ``v_<probe>`` (V).
``arrangement``
    Source and DUT in one network (the monolithic reference). No input;
    outputs ``v_in``, ``i_in``, ``v_bprbs`` and ``v_<probe>``.
``bridge``
    The PRBS-driven H-bridge alone (no states). No input; output
    ``v_bprbs`` (V), piecewise constant between PRBS clock instants.
``load``
    What the bridge drives: optional switch parasitics and snubber, the
    series Rpris-Lpris-Cpris and the DUT. Input ``v_bprbs`` (V); outputs
    ``v_in``, ``i_in`` and ``v_<probe>``. Coupled to a ``bridge`` FMU it is
    the arrangement cut where the only signal is the bridge voltage.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from importlib import resources

import numpy as np

from pris_cosim.circuits.arrangement import (BRIDGE, BRIDGE_NODE, SENSE_INDUCTOR, SourceSettings, pris_arrangement,
    source_circuit)
from pris_cosim.circuits.circuit import GROUND, Circuit
from pris_cosim.errors import CircuitError, ExpressionError
from pris_cosim.circuits.expressions import Expression
from pris_cosim.circuits.mna import MNA
from pris_cosim.signals.perturbation import MAX_LENGTH_TAPS
from pris_cosim.lab.timedomain import checked_values

#: Runtime files copied into every FMU's ``sources/`` (C files are compiled).
RUNTIME_FILES = (
    "prc_model.h",
    "prc_linalg.h",
    "prc_linalg.c",
    "prc_expm.h",
    "prc_expm.c",
    "prc_network.h",
    "prc_network.c",
    "prc_fmi2.h",
    "prc_fmi2.c",
)
#: Runtime files only FMI 3.0 FMUs hold (the FMI 3.0 layer over the FMI 2.0 one).
RUNTIME_FILES_FMI3 = ("prc_fmi3.c",)
GENERATED_FILE = "model.c"

#: When a variable may be set (``PRC_SET_*`` in prc_model.h).
SET_NEVER, SET_INIT, SET_ALWAYS = 0, 1, 2
#: What an output reads (``PRC_OUT_*`` in prc_model.h).
OUT_NODE, OUT_STATE, OUT_INPUT = 0, 1, 2
#: Name of the V element through which the source FMU receives the DUT terminal voltage.
SOURCE_TERMINAL_INPUT = "Vdut"

_UNITS = {"R": "Ohm", "L": "H", "C": "F", "K": "1"}
#: ``min`` / ``max`` of parameters by unit (the FMU refuses values outside at initialisation or when set).
PARAMETER_RANGES: dict[str, tuple[float, float]] = {
    "Ohm": (1e-9, 1e12),
    "H": (1e-15, 1e6),
    "F": (1e-18, 1e3),
    "1": (-1.0, 1.0),
    "V": (1e-6, 1e6),
    "Hz": (1e-3, 1e9),
}
#: Most PRBS switching instants one experiment may hold (checked at initialisation).
MAX_SWITCHES = 100_000_000
_KIND_WORDS = {"R": "resistance", "L": "inductance", "C": "capacitance", "K": "coupling coefficient"}


@dataclass
class Variable:
    """One FMI 2.0 scalar variable.

    Attributes
    ----------
    name : str
    vr : int
        Value reference (Real and Integer variables are numbered separately).
    type : {"Real", "Integer"}
    causality, variability : str
        FMI 2.0 attributes.
    initial : str or None
        FMI 2.0 ``initial`` attribute (None: omitted).
    start : float or int or None
        Start value (None for calculated variables).
    unit : str
    description : str
    settable : int
        ``SET_NEVER``, ``SET_INIT`` (fixed parameters, state start values) or
        ``SET_ALWAYS`` (inputs, tunable parameters).
    exposed : bool
        False for internal slots (tied element values) not listed in the
        model description.
    derivative_of : int or None
        For a derivative, the vr of its state.
    """

    name: str
    vr: int
    type: str
    causality: str
    variability: str
    initial: str | None
    start: float | int | None
    unit: str = ""
    description: str = ""
    settable: int = SET_NEVER
    exposed: bool = True
    derivative_of: int | None = None
    min: float | int | None = None
    max: float | int | None = None
    nominal: float | None = None


@dataclass
class Output:
    """An FMU output: a node voltage, a state or an input of the network."""

    variable: Variable
    kind: int
    index: int


@dataclass
class NetworkModel:
    """Everything needed to write an FMU's C source, model description and Modelica text.

    Attributes
    ----------
    kind : {"source", "dut", "arrangement", "bridge", "load"}
    identifier : str
        FMI model identifier (a C identifier; the shared library's name).
    circuit : Circuit
        The network actually compiled (shorts applied; for the source the
        terminal voltage enters through a V element ``Vdut``).
    mna : MNA
    description : str
    port : str or None
        Driven DUT node (None for the source).
    settings : SourceSettings or None
    real, integer : list of Variable
    outputs : list of Output
    input_vrs : list of int
        Per network input (MNA order), the Real vr of the FMU input, -1 for
        the H-bridge voltage.
    bridge_input : int
        Index of the bridge voltage in the network input vector, -1 if none.
    element_vr : dict
        Element key to the Real vr holding its value.
    ties : list of str
        C statements evaluating calculated values in dependency order.
    output_deps, derivative_deps : list of (list of int, bool)
        Per output / state derivative: the state numbers it depends on and
        whether it depends on the FMU input (direct feedthrough), from the
        structure of the state-space form at the start values.
    output_param_deps, derivative_param_deps : list of list of Variable
        Per output / state derivative: the parameters its value depends on
        (for ``InitialUnknowns``), from the state-space form and the ties.
    calculated_deps : dict
        Per calculated parameter (Real vr): the parameters its tie uses,
        directly or through other ties.
    experiment : tuple of float or None
        ``(stop_time, step_size)`` in s of the default experiment.
    """

    kind: str
    identifier: str
    circuit: Circuit
    mna: MNA
    description: str
    port: str | None
    settings: SourceSettings | None
    real: list[Variable] = field(default_factory=list)
    integer: list[Variable] = field(default_factory=list)
    outputs: list[Output] = field(default_factory=list)
    input_vrs: list[int] = field(default_factory=list)
    bridge_input: int = -1
    element_vr: dict[str, int] = field(default_factory=dict)
    ties: list[str] = field(default_factory=list)
    output_deps: list[tuple[list[int], bool]] = field(default_factory=list)
    derivative_deps: list[tuple[list[int], bool]] = field(default_factory=list)
    output_param_deps: list[list[Variable]] = field(default_factory=list)
    derivative_param_deps: list[list[Variable]] = field(default_factory=list)
    calculated_deps: dict[int, list[Variable]] = field(default_factory=dict)
    experiment: tuple[float, float] | None = None

    @property
    def state_vr0(self) -> int:
        """Value reference of the first state (states have consecutive vrs; one past the last Real without states)."""
        return next((v.vr for v in self.real if v.causality == "local" and v.variability == "continuous"
                     and v.derivative_of is None), len(self.real))

    @property
    def deriv_vr0(self) -> int:
        """Value reference of the first state derivative (one past the last Real without states)."""
        return next((v.vr for v in self.real if v.derivative_of is not None), len(self.real))


# ---------------------------------------------------------------------- circuits
def source_terminal_circuit(settings: SourceSettings) -> Circuit:
    """The PRIS source with the DUT replaced by a voltage input.

    The source loop is a series connection, so the DUT terminal voltage can
    enter as a V element ``Vdut`` in series between ``Rpris`` and ``Lpris``
    with ``Cpris`` returned to ground: the loop current ``i(Lpris)`` is the
    same as with the DUT at the end of the chain, and no voltage source
    touches a capacitor (which the exact MNA reduction requires).

    Parameters
    ----------
    settings : SourceSettings

    Returns
    -------
    Circuit
        Inputs ``Vbridge`` and ``Vdut`` (V); the DUT current is ``i(Lpris)``.
    """
    base = source_circuit(settings, terminal=GROUND)
    sense = base.element(SENSE_INDUCTOR)
    entry, exit_ = sense.nodes
    elements = [replace(e, nodes=("src_vin", exit_)) if e.key == sense.key else e for e in base.elements]
    c = Circuit(title="PRIS source, DUT terminal voltage as input", elements=elements)
    c.add(SOURCE_TERMINAL_INPUT, entry, "src_vin", 0.0, source_spec="DC 0")
    return c



# ---------------------------------------------------------------------- variable layout
class _Layout:
    """FMI variables in value-reference order (Real and Integer numbered separately)."""

    def __init__(self) -> None:
        self.real: list[Variable] = []
        self.integer: list[Variable] = []
        self._names: set[str] = set()

    def add(self, name: str, type_: str = "Real", **kw) -> Variable:
        if name in self._names:
            raise CircuitError(f"FMU variable name {name!r} is used twice; rename the parameter or element")
        self._names.add(name)
        target = self.real if type_ == "Real" else self.integer
        var = Variable(name=name, vr=len(target), type=type_, **kw)
        target.append(var)
        return var


def parameter_order(circuit: Circuit) -> list:
    """The circuit's parameters ordered so that every tie follows the parameters it uses.

    Raises
    ------
    ExpressionError
        A tie names an unknown parameter, or ties form a cycle.
    """
    known = {p.key for p in circuit.parameters}
    done: set[str] = set()
    order = []
    pending = list(circuit.parameters)
    while pending:
        rest = []
        for p in pending:
            used = p.value.names if isinstance(p.value, Expression) else frozenset()
            if used - known:
                unknown = sorted(used - known)[0]
                raise ExpressionError(f"parameter {p.name!r}: unknown name {unknown!r} in {p.value.text!r}")
            if used <= done:
                order.append(p)
                done.add(p.key)
            else:
                rest.append(p)
        if len(rest) == len(pending):
            raise ExpressionError(f"parameters {', '.join(p.name for p in rest)} depend on each other in a cycle")
        pending = rest
    return order


def _assemble(
    kind: str,
    name: str,
    description: str,
    circuit: Circuit,
    mna: MNA,
    port: str | None,
    settings: SourceSettings | None,
    ext_input: tuple[str, str, str] | None,
    outputs: Sequence[tuple[str, str, str, int, int]],
    scale: SourceSettings | None = None,
) -> NetworkModel:
    """Lay out the FMI variables of a network and collect its tie statements.

    ``ext_input`` is ``(name, unit, description)`` of the FMU input; each
    output is ``(name, unit, description, kind, index)``. With ``settings``
    the network holds the PRBS generator driving ``Vbridge``; without,
    ``Vbridge`` (if any) is the FMU input, and ``scale`` (source settings)
    gives the state nominals and the default experiment.
    """
    values = {k: float(v) for k, v in checked_values(circuit).items()}
    lay = _Layout()
    outs = [  # the bridge voltage changes only at the switching events
        Output(lay.add(n, causality="output", variability="discrete" if k == OUT_INPUT else "continuous",
                       initial="calculated", start=None, unit=u, description=d), k, i)
        for n, u, d, k, i in outputs
    ]
    input_var = None
    if ext_input is not None:
        n, u, d = ext_input
        input_var = lay.add(n, causality="input", variability="continuous", initial=None, start=0.0, unit=u,
                            description=d, settable=SET_ALWAYS)
    c_names: dict[str, str] = {}
    ties: list[str] = []
    env = circuit.parameter_values()
    for p in parameter_order(circuit):
        if isinstance(p.value, Expression):
            var = lay.add(p.name, causality="calculatedParameter", variability="tunable", initial="calculated",
                          start=None, unit=p.unit, description=p.description or f"= {p.value.text}")
            ties.append(f"    r[{var.vr}] = {p.value.to_c(c_names)};  /* {p.name} */")
        else:
            lo, hi = PARAMETER_RANGES.get(p.unit, (-1e300, 1e300))
            var = lay.add(p.name, causality="parameter", variability="tunable", initial="exact",
                          start=float(env[p.key]), unit=p.unit,
                          description=p.description or f"circuit parameter {p.name} ({p.unit or 'no unit'})",
                          settable=SET_ALWAYS, min=lo, max=hi)
        c_names[p.key] = f"r[{var.vr}]"
    slots: dict[str, int] = {}
    param_keys = {p.key for p in circuit.parameters}
    tied = [e for e in circuit.of_kind("R", "L", "C", "K") if isinstance(e.value, Expression)]
    for e in circuit.of_kind("R", "L", "C", "K"):
        if isinstance(e.value, Expression):
            continue
        lo, hi = PARAMETER_RANGES[_UNITS[e.kind]]
        var = lay.add(e.name if e.key not in param_keys else f"{e.name}_elem", causality="parameter",
                      variability="tunable", initial="exact", start=float(values[e.key]), unit=_UNITS[e.kind],
                      description=f"{_KIND_WORDS[e.kind]} of element {e.name}", settable=SET_ALWAYS, min=lo, max=hi)
        slots[e.key] = var.vr
    if settings is not None:
        lay.add("vdc", causality="parameter", variability="tunable", initial="exact", start=float(settings.vdc),
                unit="V", description="H-bridge DC voltage (levels +-vdc)", settable=SET_ALWAYS,
                min=PARAMETER_RANGES["V"][0], max=PARAMETER_RANGES["V"][1])
        lay.add("fclk", causality="parameter", variability="fixed", initial="exact", start=float(settings.fclk),
                unit="Hz", description="PRBS clock frequency", settable=SET_INIT,
                min=PARAMETER_RANGES["Hz"][0], max=PARAMETER_RANGES["Hz"][1])
        lay.add("prbs_order", "Integer", causality="parameter", variability="fixed", initial="exact",
                start=int(settings.prbs_order), description="LFSR order n (period 2^n - 1 bits)", settable=SET_INIT,
                min=2, max=32)
        lay.add("prbs_seed", "Integer", causality="parameter", variability="fixed", initial="exact", start=0,
                description="LFSR seed, first n output bits MSB first; 0 = all ones", settable=SET_INIT,
                min=0, max=2**31 - 1)
    state_vars = []
    for label in mna.states:
        unit = "A" if label.startswith("i(") else "V"
        what = f"current through inductor {label[2:-1]}" if unit == "A" else f"capacitive voltage {label}"
        state_vars.append(lay.add(label, causality="local", variability="continuous", initial="exact", start=0.0,
                                  unit=unit, description=f"state: {what}", settable=SET_INIT,
                                  nominal=_state_nominal(unit, settings or scale)))
    for sv in state_vars:
        lay.add(f"der({sv.name})", causality="local", variability="continuous", initial="calculated", start=None,
                unit=f"{sv.unit}/s", description=f"time derivative of {sv.name}", derivative_of=sv.vr)
    for e in tied:  # internal slots, not in the model description
        var = lay.add(f"__{e.key}", causality="local", variability="fixed", initial="calculated",
                      start=float(values[e.key]), exposed=False, description=f"{e.name} = {e.value.text}")
        slots[e.key] = var.vr
        ties.append(f"    r[{var.vr}] = {e.value.to_c(c_names)};  /* {e.name} = {_comment(e.value.text)} */")
    input_vrs = []
    bridge = -1
    for j, label in enumerate(mna.inputs):
        if label == f"v({BRIDGE})" and settings is not None:
            input_vrs.append(-1)
            bridge = j
        else:
            assert input_var is not None
            input_vrs.append(input_var.vr)
    out_deps, der_deps = _dependencies(mna, values, outputs, input_vrs)
    out_params, der_params, calc_deps = _parameter_deps(circuit, mna, values, outputs, lay, bridge)
    return NetworkModel(kind=kind, identifier=_identifier(name), circuit=circuit, mna=mna, description=description,
                        port=port, settings=settings, real=lay.real, integer=lay.integer, outputs=outs,
                        input_vrs=input_vrs, bridge_input=bridge, element_vr=slots, ties=ties,
                        output_deps=out_deps, derivative_deps=der_deps, output_param_deps=out_params,
                        derivative_param_deps=der_params, calculated_deps=calc_deps,
                        experiment=default_experiment(mna, values, settings or scale))


def _parameter_deps(circuit: Circuit, mna: MNA, values: Mapping[str, float],
                    outputs: Sequence[tuple[str, str, str, int, int]], lay: _Layout, bridge: int,
                    ) -> tuple[list[list[Variable]], list[list[Variable]], dict[int, list[Variable]]]:
    """The parameters behind every output, state derivative and calculated parameter (see fmu_dependencies)."""
    from pris_cosim.fmi.dependencies import parameter_dependencies, tie_closure

    by_name = {v.name: v for v in lay.real + lay.integer}
    params = {p.key: p for p in circuit.parameters}
    free: list[tuple[str, str]] = []
    free_vars: list[Variable] = []
    for p in circuit.parameters:
        if not isinstance(p.value, Expression):
            free.append(("parameter", p.key))
            free_vars.append(by_name[p.name])
    for e in circuit.of_kind("R", "L", "C", "K"):
        if not isinstance(e.value, Expression):
            free.append(("element", e.key))
            free_vars.append(by_name[e.name if e.key not in params else f"{e.name}_elem"])
    rows = [index if kind == OUT_NODE else None for _, _, _, kind, index in outputs]
    der, out, der_bridge, out_bridge = parameter_dependencies(circuit, mna, values, free, rows, bridge)
    prbs = [by_name[n] for n in ("vdc", "prbs_order", "prbs_seed") if n in by_name]

    def pick(idx: list[int], through_bridge: bool) -> list[Variable]:
        return [free_vars[j] for j in idx] + (prbs if through_bridge else [])

    out_vars = [pick(out[i], out_bridge[i] or outputs[i][3] == OUT_INPUT) for i in range(len(outputs))]
    der_vars = [pick(der[i], der_bridge[i]) for i in range(len(der))]
    closure = tie_closure(circuit)
    calc = {by_name[p.name].vr: [by_name[params[k].name] for k in sorted(closure[p.key])]
            for p in circuit.parameters if isinstance(p.value, Expression)}
    return out_vars, der_vars, calc


def _state_nominal(unit: str, settings: SourceSettings | None) -> float:
    """Nominal value of a state: the bridge voltage and its current through Rpris with a source, else 1 V, 1 mA."""
    if settings is None:
        return 1.0 if unit == "V" else 1e-3
    return float(settings.vdc) if unit == "V" else float(settings.vdc / settings.rpris)


def _dependencies(mna: MNA, values: Mapping[str, float], outputs: Sequence[tuple[str, str, str, int, int]],
                  input_vrs: Sequence[int]) -> tuple[list[tuple[list[int], bool]], list[tuple[list[int], bool]]]:
    """Structural dependencies of outputs and derivatives on states and on the FMU input.

    The FMU input enters the network through the inputs whose ``input_vrs``
    entry is not -1 (the bridge voltage is internal).
    """
    ss = mna.state_space(values)
    A, B, C, D = ss.A[0], ss.B[0], ss.C[0], ss.D[0]
    ext = [j for j, vr in enumerate(input_vrs) if vr >= 0]
    scale_a = np.abs(A).max(initial=0.0) or 1.0
    scale_c = np.abs(C).max(initial=0.0) or 1.0

    def row(a_row: np.ndarray, b_row: np.ndarray, scale: float) -> tuple[list[int], bool]:
        states = [int(i) for i in np.flatnonzero(np.abs(a_row) > 1e-14 * scale)]
        feed = bool(ext) and bool(np.any(np.abs(b_row[ext]) > 0.0))
        return states, feed

    der = [row(A[i], B[i], scale_a) for i in range(A.shape[0])]
    out = []
    for _, _, _, kind, index in outputs:
        if kind == OUT_STATE:
            out.append(([index], False))
        elif kind == OUT_INPUT:
            out.append(([], False))
        else:
            out.append(row(C[index], D[index], scale_c))
    return out, der


def whole_ns_step(step: float, fclk: float, stop: float | None = None) -> float:
    """The largest step up to ``step`` that is a whole number of nanoseconds and divides the PRBS bit.

    Masters on an integer nanosecond clock (libcosim) then hit every PRBS
    clock instant, and the FMU's switching instants fall on communication
    points as before. Without such a step (a bit that is not a whole number
    of nanoseconds, or ``stop`` not a whole number of steps) ``step`` is
    returned unchanged.

    Parameters
    ----------
    step : float, s
    fclk : float, Hz
        PRBS clock.
    stop : float, s, optional
        Stop time that must stay a whole number of steps.

    Returns
    -------
    float, s
    """
    bit_ns = 1e9 / float(fclk)
    if abs(bit_ns - round(bit_ns)) > 1e-6 * bit_ns or round(bit_ns) < 1:
        return float(step)
    bit = int(round(bit_ns))
    stop_ns = None if stop is None else float(stop) * 1e9
    for k in range(max(1, math.ceil(bit / (float(step) * 1e9) - 1e-9)), bit + 1):
        if bit % k:
            continue
        h = bit // k
        if stop_ns is not None and abs(stop_ns / h - round(stop_ns / h)) > 1e-6:
            continue
        return h / 1e9
    return float(step)


def default_experiment(mna: MNA, values: Mapping[str, float], settings: SourceSettings | None) -> tuple[float, float]:
    """``(stop_time, step_size)`` in s: one PRBS period at 100 steps per bit with a source.

    With a source the step is a whole number of nanoseconds where the bit
    allows it (:func:`whole_ns_step`). Without a source: 1000 steps of a
    tenth of the fastest time constant (from the eigenvalues of the state
    matrix at the start values), to two digits, and down to whole
    nanoseconds from 1 ns up.
    """
    if settings is not None:
        stop = (2 ** int(settings.prbs_order) - 1) / settings.fclk
        return stop, whole_ns_step(1.0 / (100.0 * settings.fclk), settings.fclk, stop)
    lam = np.abs(np.linalg.eigvals(mna.state_space(values).A[0]))
    lam = lam[lam > 0]
    step = 0.1 / float(lam.max()) if lam.size else 1e-6
    step = float(f"{step:.1e}")
    if 1e-9 <= step < 1e-8:  # on whole nanoseconds (two digits are whole from 10 ns up)
        step = math.floor(step * 1e9 + 1e-9) / 1e9
    return 1000.0 * step, step


def _identifier(name: str) -> str:
    ident = re.sub(r"\W", "_", name.strip())
    if not ident or ident[0].isdigit():
        ident = "m_" + ident
    return ident


def _comment(text: str) -> str:
    return text.replace("*/", "* /")


def _probe_outputs(circuit: Circuit, mna: MNA, port: str) -> list[tuple[str, str, str, int, int]]:
    return [(f"v_{p}", "V", f"voltage of node {p}", OUT_NODE, mna.nodes.index(p))
            for p in circuit.probes if p != port and p in mna.nodes]


def source_model(settings: SourceSettings, name: str = "pris_source") -> NetworkModel:
    """The PRIS source FMU: input ``v_in`` (V), outputs ``i_in`` (A) and ``v_bprbs`` (V).

    Parameters
    ----------
    settings : SourceSettings
        Start values of the source parameters; switch parasitics and snubber
        are part of the network when set.
    name : str
        Model identifier.
    """
    circuit = source_terminal_circuit(settings)
    mna = MNA(circuit, voltage_inputs=[BRIDGE, SOURCE_TERMINAL_INPUT])
    outputs = [
        ("i_in", "A", "current from the source RLC into the DUT terminal", OUT_STATE,
         mna.states.index(f"i({SENSE_INDUCTOR})")),
        ("v_bprbs", "V", "commanded H-bridge voltage", OUT_INPUT, mna.inputs.index(f"v({BRIDGE})")),
    ]
    return _assemble("source", name, "PRIS source: PRBS-driven H-bridge and series RLC", circuit, mna, None, settings,
                     ("v_in", "V", "DUT terminal voltage"), outputs)


def dut_model(dut: Circuit, port: str, shorts: Sequence[str] = (), name: str = "dut") -> NetworkModel:
    """The DUT FMU: input ``i_in`` (A) into ``port``; outputs ``v_in`` and probe voltages (V).

    Parameters
    ----------
    dut : Circuit
    port : str
        Driven node.
    shorts : sequence of str
        Nodes tied to ground (test configuration).
    name : str
        Model identifier.
    """
    circuit = dut.shorted(shorts) if shorts else dut
    port = circuit.require_node(port, "port")
    if port == GROUND:
        raise CircuitError("the driven port cannot be ground")
    mna = MNA(circuit, current_inputs=[port])
    outputs = [("v_in", "V", f"port voltage v({port})", OUT_NODE, mna.nodes.index(port))]
    outputs += _probe_outputs(circuit, mna, port)
    return _assemble("dut", name, f"{dut.title or 'DUT'} driven by a current at {port}", circuit, mna, port, None,
                     ("i_in", "A", f"current injected into node {port}"), outputs)


def arrangement_model(dut: Circuit, port: str, settings: SourceSettings, shorts: Sequence[str] = (),
                      name: str = "pris_arrangement") -> NetworkModel:
    """The monolithic FMU: PRIS source and DUT in one network, no input.

    Outputs ``v_in``, ``i_in``, ``v_bprbs`` and the probe voltages.
    """
    circuit = pris_arrangement(dut, port, settings, shorts)
    port = circuit.ports[0]
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    outputs = [
        ("v_in", "V", f"DUT terminal voltage v({port})", OUT_NODE, mna.nodes.index(port)),
        ("i_in", "A", "current from the source RLC into the DUT terminal", OUT_STATE,
         mna.states.index(f"i({SENSE_INDUCTOR})")),
        ("v_bprbs", "V", "commanded H-bridge voltage", OUT_INPUT, mna.inputs.index(f"v({BRIDGE})")),
    ]
    outputs += _probe_outputs(circuit, mna, port)
    return _assemble("arrangement", name, circuit.title, circuit, mna, port, settings, None, outputs)


def bridge_model(settings: SourceSettings, name: str = "pris_bridge") -> NetworkModel:
    """The H-bridge FMU: the PRBS generator and the bridge voltage alone, no state, no input.

    Output ``v_bprbs`` (V): ``+-vdc``, constant between PRBS clock instants.
    At a clock instant that ends a communication step the output already
    holds the new level, so a master that holds it over the next step feeds
    a :func:`load_model` FMU exactly the bridge voltage of that step.

    Parameters
    ----------
    settings : SourceSettings
        PRBS and ``vdc`` start values (the series RLC and parasitics belong
        to the load).
    name : str
        Model identifier.
    """
    circuit = Circuit(title="PRIS H-bridge")
    circuit.add(BRIDGE, BRIDGE_NODE, GROUND, 0.0, source_spec="DC 0")
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    outputs = [("v_bprbs", "V", "commanded H-bridge voltage", OUT_INPUT, mna.inputs.index(f"v({BRIDGE})"))]
    return _assemble("bridge", name, "PRIS H-bridge: PRBS-driven bridge voltage", circuit, mna, None, settings, None,
                     outputs)


def load_model(dut: Circuit, port: str, settings: SourceSettings, shorts: Sequence[str] = (),
               name: str = "pris_load") -> NetworkModel:
    """What the H-bridge drives: the source's passive part and the DUT, with the bridge voltage as input.

    The network is the monolithic arrangement's (:func:`arrangement_model`)
    with ``Vbridge`` set from the FMU input ``v_bprbs`` (V) instead of the
    PRBS generator. Outputs ``v_in``, ``i_in`` and the probe voltages.

    Parameters
    ----------
    dut : Circuit
    port : str
        Driven DUT node.
    settings : SourceSettings
        Element values of the series RLC and parasitics; PRBS settings give
        the default experiment and state nominals only.
    shorts : sequence of str
        DUT nodes tied to ground (test configuration).
    name : str
        Model identifier.
    """
    circuit = pris_arrangement(dut, port, settings, shorts)
    port = circuit.ports[0]
    mna = MNA(circuit, voltage_inputs=[BRIDGE])
    outputs = [
        ("v_in", "V", f"DUT terminal voltage v({port})", OUT_NODE, mna.nodes.index(port)),
        ("i_in", "A", "current from the source RLC into the DUT terminal", OUT_STATE,
         mna.states.index(f"i({SENSE_INDUCTOR})")),
    ]
    outputs += _probe_outputs(circuit, mna, port)
    title = f"series RLC and {dut.title or 'DUT'} driven at {port} by the H-bridge voltage"
    return _assemble("load", name, title, circuit, mna, port, None, ("v_bprbs", "V", "H-bridge voltage"), outputs,
                     scale=settings)


# ---------------------------------------------------------------------- C text
def _c_string(s: str | None) -> str:
    if s is None:
        return "NULL"
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_array(ctype: str, name: str, items: Sequence[str], per_line: int = 6) -> str:
    """A static const C array (one dummy entry when empty: C has no zero-length arrays)."""
    body = list(items) or ["0"]
    lines = [", ".join(body[i:i + per_line]) for i in range(0, len(body), per_line)]
    return f"static const {ctype} {name}[{len(body)}] = {{\n    " + ",\n    ".join(lines) + "\n};\n"


def _num(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise CircuitError(f"cannot write non-finite value {x!r} into C source")
    return repr(x)


def _elements_c(name: str, elements: Sequence, model: NetworkModel, nodes: Sequence[str],
                inductor_index: Mapping[str, int] | None = None) -> str:
    rows = []
    index = {n: i for i, n in enumerate(nodes)}
    for e in elements:
        if inductor_index is None:
            a, b = (index[n] if n != GROUND else -1 for n in e.nodes)
        else:
            a, b = (inductor_index[n.lower()] for n in e.nodes)
        expr = e.value.text if isinstance(e.value, Expression) else None
        rows.append(f"{{{_c_string(e.name)}, {model.element_vr[e.key]}, {a}, {b}, {_c_string(expr)}}}")
    if not rows:
        rows = ["{NULL, 0, 0, 0, NULL}"]
    return f"static const prc_elem {name}[{len(rows)}] = {{\n    " + ",\n    ".join(rows) + "\n};\n"


def generate_model_c(model: NetworkModel, guid: str) -> str:
    """The generated ``model.c`` of an FMU.

    Parameters
    ----------
    model : NetworkModel
    guid : str
        The FMU's GUID (checked by ``fmi2Instantiate``).

    Returns
    -------
    str
        C99 source defining ``PRC_MODEL`` for the runtime in ``pris_cosim/c``.
    """
    mna, circuit = model.mna, model.circuit
    nodes = mna.nodes
    inductor_index = {e.key: i for i, e in enumerate(mna.inductors)}
    real, ints = model.real, model.integer
    taps = [0] * 33
    for order, t in MAX_LENGTH_TAPS.items():
        taps[order] = sum(1 << (k - 1) for k in t)
    v_nodes = [str(nodes.index(n) if n != GROUND else -1) for v in mna.vsources for n in v.nodes]
    out = [
        f"/* Generated by pris_cosim.fmi.codegen from circuit {_comment(circuit.title or '(untitled)')!r}.",
        f" * FMU kind: {model.kind}; {len(nodes)} nodes, {mna.n_states} states. Do not edit: regenerate. */",
        "#include <math.h>",
        "#include <stddef.h>",
        "",
        '#include "prc_model.h"',
        "",
        "/* node order: " + _comment(", ".join(nodes)) + " */",
        "/* state order: " + _comment(", ".join(mna.states)) + " */",
        "",
        _c_array("double", "REAL_START", [_num(v.start) if v.start is not None else "0.0" for v in real], 4),
        _c_array("char *const", "REAL_NAMES", [_c_string(v.name) for v in real], 4),
        _c_array("unsigned char", "REAL_SETTABLE", [str(v.settable) for v in real], 16),
        _c_array("double", "REAL_MIN", [_num(v.min) if v.min is not None else "-HUGE_VAL" for v in real], 4),
        _c_array("double", "REAL_MAX", [_num(v.max) if v.max is not None else "HUGE_VAL" for v in real], 4),
        _c_array("double", "STATE_NOMINAL", [_num(v.nominal) for v in real if v.nominal is not None], 4),
        _c_array("int", "INT_START", [str(int(v.start)) for v in ints]),
        _c_array("int", "INT_MIN", [str(int(v.min if v.min is not None else -2**31 + 1)) for v in ints]),
        _c_array("int", "INT_MAX", [str(int(v.max if v.max is not None else 2**31 - 1)) for v in ints]),
        _c_array("char *const", "INT_NAMES", [_c_string(v.name) for v in ints]),
        _c_array("unsigned char", "INT_SETTABLE", [str(v.settable) for v in ints], 16),
        _elements_c("RESISTORS", mna.resistors, model, nodes),
        _elements_c("CAPACITORS", mna.capacitors, model, nodes),
        _elements_c("INDUCTORS", mna.inductors, model, nodes),
        _elements_c("COUPLINGS", circuit.of_kind("K"), model, nodes, inductor_index),
        _c_array("int", "V_NODES", v_nodes, 16),
        _c_array("double", "Q0", [_num(x) for x in mna.Q0.ravel()], 6),
        _c_array("double", "Q1", [_num(x) for x in mna.Q1.ravel()], 6),
        _c_array("double", "BI", [_num(x) for x in mna.BI.ravel()], 6),
        _c_array("double", "BV", [_num(x) for x in mna.BV.ravel()], 6),
        _c_array("int", "INPUT_VR", [str(v) for v in model.input_vrs], 16),
        _c_array("prc_output", "OUTPUTS", [f"{{{o.variable.vr}, {o.kind}, {o.index}}}" for o in model.outputs], 4),
        _c_array("unsigned int", "PRBS_TAPS", [f"{t:#x}u" for t in taps], 6),
        "/* parameter ties and tied element values, in dependency order */",
        "static void compute(double *r) {",
        *(model.ties or ["    (void)r;"]),
        "}",
        "",
        "const prc_model PRC_MODEL = {",
        f"    {_c_string(guid)},",
        f"    {len(real)}, REAL_START, REAL_NAMES, REAL_SETTABLE, REAL_MIN, REAL_MAX, STATE_NOMINAL,",
        f"    {len(ints)}, INT_START, INT_NAMES, INT_SETTABLE, INT_MIN, INT_MAX,",
        f"    {len(nodes)},",
        f"    {len(mna.resistors)}, {len(mna.capacitors)}, {len(mna.inductors)}, {len(circuit.of_kind('K'))}, "
        f"{len(mna.vsources)},",
        "    RESISTORS, CAPACITORS, INDUCTORS, COUPLINGS,",
        "    V_NODES,",
        f"    {mna.Q0.shape[1]}, {mna.Q1.shape[1]},",
        "    Q0, Q1,",
        f"    {mna.BI.shape[1]}, {mna.BV.shape[1]},",
        "    BI, BV,",
        "    INPUT_VR,",
        f"    {model.bridge_input},",
        f"    {model.state_vr0}, {model.deriv_vr0},",
        f"    {len(model.outputs)}, OUTPUTS,",
        f"    {_vr(model, 'vdc')}, {_vr(model, 'fclk')}, {_ivr(model, 'prbs_order')}, {_ivr(model, 'prbs_seed')},",
        "    PRBS_TAPS,",
        f"    {float(MAX_SWITCHES)!r},",
        "    compute,",
        "};",
        "",
    ]
    return "\n".join(out)


def _vr(model: NetworkModel, name: str) -> int:
    return next((v.vr for v in model.real if v.name == name), -1)


def _ivr(model: NetworkModel, name: str) -> int:
    return next((v.vr for v in model.integer if v.name == name), -1)


def _runtime_names(fmi_version: int) -> tuple[str, ...]:
    return RUNTIME_FILES + (RUNTIME_FILES_FMI3 if fmi_version == 3 else ())


def runtime_sources(fmi_version: int = 2) -> dict[str, str]:
    """The hand-written C runtime files of an FMI 2.0 or 3.0 FMU, by file name."""
    pkg = resources.files("pris_cosim.fmi") / "c"
    return {name: (pkg / name).read_text() for name in _runtime_names(fmi_version)}


def generate_sources(model: NetworkModel, guid: str, fmi_version: int = 2) -> dict[str, str]:
    """Every source file of the FMU (runtime plus generated ``model.c``), by file name."""
    files = runtime_sources(fmi_version)
    files[GENERATED_FILE] = generate_model_c(model, guid)
    return files


def c_source_files(fmi_version: int = 2) -> list[str]:
    """Names of the C files to compile, in build order."""
    return [f for f in _runtime_names(fmi_version) if f.endswith(".c")] + [GENERATED_FILE]
