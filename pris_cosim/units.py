"""SPICE number syntax: SI suffixes in, exact round-trippable text out."""

from __future__ import annotations

import re

#: SPICE scale suffixes (case-insensitive). ``meg`` must be tried before ``m``.
SUFFIXES: dict[str, float] = {
    "t": 1e12,
    "g": 1e9,
    "meg": 1e6,
    "k": 1e3,
    "mil": 25.4e-6,
    "m": 1e-3,
    "u": 1e-6,
    "n": 1e-9,
    "p": 1e-12,
    "f": 1e-15,
}

_NUMBER = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_VALUE_RE = re.compile(rf"^({_NUMBER})(meg|mil|[tgkmunpf])?([a-z]*)$", re.IGNORECASE)

#: Units by element letter, for messages and documentation.
ELEMENT_UNITS: dict[str, str] = {"R": "Ohm", "L": "H", "C": "F", "K": "1", "V": "V", "I": "A"}


def parse_value(text: str) -> float:
    """Parse a SPICE number such as ``10nF``, ``4.475k``, ``1meg`` or ``2.5e-3``.

    Parameters
    ----------
    text : str
        The number with an optional scale suffix; trailing unit letters are ignored.

    Returns
    -------
    float
        The value in SI base units.

    Raises
    ------
    ValueError
        If ``text`` is not a SPICE number.
    """
    s = text.strip()
    m = _VALUE_RE.match(s)
    if not m:
        raise ValueError(f"cannot parse value {text!r}")
    number, suffix, _unit = m.groups()
    value = float(number)
    if suffix:
        value *= SUFFIXES[suffix.lower()]
    return value


def is_number(text: str) -> bool:
    """Return True when ``text`` parses as a SPICE number."""
    return _VALUE_RE.match(text.strip()) is not None


def format_value(value: float) -> str:
    """Format a float so that :func:`parse_value` gives back exactly the same float.

    Parameters
    ----------
    value : float
        Any finite float.

    Returns
    -------
    str
        Shortest ``repr`` form (``1e-09``, ``4475.0``), which SPICE reads too.
    """
    return repr(float(value))
