"""Which parameters an FMU's outputs and state derivatives depend on, from the network's state-space form.

An FMU's ``ModelStructure/InitialUnknowns`` lists, for every output and
state derivative, the knowns of the initialization: the FMU input, the
states (their start values are exact) and the parameters. The states and
the input come from the sparsity of ``A, B, C, D`` (see
:func:`pris_cosim.fmi.codegen._dependencies`); the parameters come from which
rows of ``[A B; C D]`` change when one parameter changes, evaluated for all
parameters at once as one population of the exact state-space reduction
(:meth:`pris_cosim.circuits.mna.MNA.state_space`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from pris_cosim.circuits.circuit import Circuit
from pris_cosim.circuits.expressions import Expression
from pris_cosim.circuits.mna import MNA

#: Relative change of a parameter for the dependency test (couplings move towards 0).
_STEP = 0.125


def tie_closure(circuit: Circuit) -> dict[str, set[str]]:
    """Per parameter key, the free (untied) parameter keys its value depends on, through ties."""
    params = {p.key: p for p in circuit.parameters}
    memo: dict[str, set[str]] = {}

    def free(key: str, seen: frozenset[str] = frozenset()) -> set[str]:
        if key in memo:
            return memo[key]
        p = params[key]
        if not isinstance(p.value, Expression):
            out = {key}
        else:
            out = set()
            for name in p.value.names:
                if name in params and name not in seen:
                    out |= free(name, seen | {key})
        memo[key] = out
        return out

    return {k: free(k) for k in params}


def parameter_dependencies(
    circuit: Circuit,
    mna: MNA,
    values: Mapping[str, float],
    free_parameters: Sequence[tuple[str, str]],
    node_rows: Sequence[int | None],
    bridge: int,
) -> tuple[list[list[int]], list[list[int]], list[bool], list[bool]]:
    """Which free parameters change each state derivative and each node output.

    Parameters
    ----------
    circuit : Circuit
        The compiled network.
    mna : MNA
    values : mapping
        Element values at the start values.
    free_parameters : sequence of (kind, key)
        ``("parameter", key)`` for a circuit parameter, ``("element", key)``
        for an element value set directly.
    node_rows : sequence of int or None
        Per output, the row of ``C, D`` (a node voltage), or None (a state or
        the bridge voltage: no parameter enters).
    bridge : int
        Column of the H-bridge voltage in ``B, D`` (-1 if none).

    Returns
    -------
    derivative_params, output_params : list of list of int
        Per state derivative / output, the indices into ``free_parameters``.
    derivative_bridge, output_bridge : list of bool
        Whether the bridge voltage (``vdc`` and the PRBS) enters.
    """
    n = len(free_parameters)
    keys = sorted(values)
    pop = {k: np.full(n + 1, float(values[k])) for k in keys}
    for j, (kind, key) in enumerate(free_parameters):
        if kind == "element":
            pop[key][j + 1] *= 1.0 - _STEP if pop[key][j + 1] < 0 else 1.0 + _STEP
            continue
        base = float(circuit.parameter_values()[key])
        factor = (1.0 - _STEP) if circuit.parameter(key).unit == "1" else (1.0 + _STEP)
        moved = circuit.resolve({key: base * factor if base != 0.0 else _STEP}, check=False)
        for k in keys:
            pop[k][j + 1] = float(moved[k])
    ss = mna.state_space(pop)
    A, B, C, D = ss.A, ss.B, ss.C, ss.D

    def changed(rows: np.ndarray) -> list[int]:
        scale = np.abs(rows[0]).max(initial=0.0) or 1.0
        diff = np.abs(rows[1:] - rows[0]).max(axis=1, initial=0.0)
        return [int(j) for j in np.flatnonzero(diff > 1e-9 * scale)]

    AB = np.concatenate([A, B], axis=2)
    CD = np.concatenate([C, D], axis=2)
    der = [changed(AB[:, i, :]) for i in range(A.shape[1])]
    out = [changed(CD[:, r, :]) if r is not None else [] for r in node_rows]
    der_bridge = [bool(bridge >= 0 and B[0, i, bridge] != 0.0) for i in range(A.shape[1])]
    out_bridge = [bool(bridge >= 0 and r is not None and D[0, r, bridge] != 0.0) for r in node_rows]
    return der, out, der_bridge, out_bridge
