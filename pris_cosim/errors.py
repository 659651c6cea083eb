"""Exceptions and warnings shared by the circuit, netlist and analysis modules.

Every exception subclasses a built-in so callers can catch what they expect
(``except ValueError`` catches every input problem).
"""

from __future__ import annotations


class CircuitError(ValueError):
    """A circuit description is invalid (bad value, unknown node, unphysical element)."""


class NetlistError(CircuitError):
    """A netlist file cannot be parsed; the message names file and line."""


class ExpressionError(CircuitError):
    """A parameter expression is malformed or names an unknown parameter."""


class NonPassiveError(CircuitError):
    """The inductance matrix is not positive definite: refused for time-domain use."""


class NonPassiveWarning(UserWarning):
    """Frequency responses were computed for a circuit that is not passive."""
