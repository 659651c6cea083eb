"""SPICE number syntax: SI suffixes in, exact round-trippable text out; accepted physical ranges."""

from __future__ import annotations

import math
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

#: Accepted value range ``(low, high)`` by element letter, in :data:`ELEMENT_UNITS`.
#: R, L and C must lie within the range (so they are positive); ``|k|`` of a K
#: must be below 1; ``|value|`` of a source at most ``high``. The limits span
#: every physical winding, insulation and instrument value (a nano-ohm contact
#: to a peta-ohm insulation, a femto-henry lead to a mega-henry core, an
#: atto-farad stray capacitance to a kilo-farad bank) while keeping the
#: per-frequency arithmetic far from overflow and underflow.
ELEMENT_RANGES: dict[str, tuple[float, float]] = {
    "R": (1e-9, 1e15),
    "L": (1e-15, 1e6),
    "C": (1e-18, 1e3),
    "K": (-1.0, 1.0),
    "V": (-1e9, 1e9),
    "I": (-1e6, 1e6),
}

_KIND_NAMES = {"R": "resistance", "L": "inductance", "C": "capacitance", "K": "coupling", "V": "source value",
               "I": "source value"}


def range_problem(kind: str, value: float) -> str | None:
    """Why ``value`` is outside the accepted range of an element of ``kind``, or None when it is inside.

    Parameters
    ----------
    kind : str
        Element letter (R, L, C, K, V, I).
    value : float
        Value in SI base units (Ohm, H, F, 1, V, A).

    Returns
    -------
    str or None
        One-line reason naming the quantity, the value and the accepted range.
    """
    low, high = ELEMENT_RANGES[kind]
    unit = "" if kind == "K" else f" {ELEMENT_UNITS[kind]}"
    what = _KIND_NAMES[kind]
    if not math.isfinite(value):
        return f"{what} {value!r} is not a finite number"
    if kind == "K":
        if not -1.0 < value < 1.0:
            return f"coupling k = {value:.6g} is outside the accepted range -1 < k < 1"
        return None
    if kind in "VI":
        if abs(value) > high:
            return f"{what} {value:.6g}{unit} is outside the accepted range |value| <= {high:g}{unit}"
        return None
    if not low <= value <= high:
        return f"{what} {value:.6g}{unit} is outside the accepted range {low:g} .. {high:g}{unit}"
    return None


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
        If ``text`` is not a SPICE number, or its value is not a finite float
        (``1e400``) or underflows to zero from a nonzero mantissa (``1e-400``).
    """
    s = text.strip()
    m = _VALUE_RE.match(s) if len(s) <= 400 else None
    if not m:
        raise ValueError(f"cannot parse value {_short(text)!r}")
    number, suffix, _unit = m.groups()
    value = float(number)
    if suffix:
        value *= SUFFIXES[suffix.lower()]
    if not math.isfinite(value) or (value == 0.0 and re.search(r"[1-9]", number.split("e")[0].split("E")[0])):
        raise ValueError(f"value {_short(text)!r} is outside the range of double-precision numbers")
    return value


def _short(text: str, limit: int = 40) -> str:
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


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
