"""SFRA sweeps as FRA instruments export them: CSV with frequency, magnitude in dB and phase in degrees.

:func:`read_fra_csv` reads the voltage ratio ``V_resp / V_ref`` (the response
an FRA instrument records) from a text table as the instruments' software
exports it, without editing the file.  Accepted layouts:

* **preamble**: any lines before the column-name row (test object, date,
  instrument, connection ...) are kept as comments; lines starting with
  ``#``, ``!`` or ``%`` and blank lines are skipped anywhere;
* **column-name row**: the first row naming a frequency column (``Frequency``,
  ``Freq``, ``f``), a magnitude column (``Magnitude``, ``Mag``,
  ``Amplitude``, ``Gain``, ``Response``, ``dB``) and a phase column
  (``Phase``, ``Angle``); other columns (an index, a second trace) are
  ignored; the first matching column of each kind is read;
* **units**: in the column names (``Frequency (Hz)``, ``Magnitude [dB]``,
  ``Phase/deg``, ``Phase (°)``) or in a separate unit row right after the
  column names (``Hz, dB, deg``); frequency in Hz, kHz or MHz; magnitude in
  dB (also when no unit is given: the FRA convention) or linear (``V/V``,
  ``lin``, ``ratio``); phase in degrees (also when no unit is given) or
  radians (``rad``);
* **separators**: comma, semicolon or tab; with semicolon or tab a decimal
  comma (``-12,5``) is accepted; cells may be quoted; a trailing separator is
  ignored;
* **order**: frequencies strictly increasing, or strictly decreasing (a sweep
  from high to low frequency; the rows are reversed).

Anything else gives a :class:`~pris_cosim.measured.core.MeasuredDataError`
of one line naming the file, line and column.
"""

from __future__ import annotations

import os
import re

import numpy as np

from pris_cosim.measured.core import (_UNIT_SCALE, MeasuredDataError, MeasuredResponses, PathLike, _check_count,
    _check_rows_frequency, _parse_number, _read_text_lines, _responses_in_range, _show)

__all__ = ["RESPONSE", "read_fra_csv"]

#: Name of the response in the returned :class:`~pris_cosim.measured.core.MeasuredResponses`.
RESPONSE = "V_resp/V_ref"

_SEPARATORS = ("\t", ";", ",")
_FREQ_NAMES = re.compile(r"^(freq(uency)?|f)\b")
_MAG_NAMES = re.compile(r"(magnitude|\bmag\b|amplitude|gain|response|^db$|^\|h\|$)")
_PHASE_NAMES = re.compile(r"(phase|angle|^arg\b)")
_DB_UNITS = {"db"}
_LINEAR_UNITS = {"v/v", "lin", "linear", "ratio", "x"}
_DEG_UNITS = {"deg", "degree", "degrees", "°", "º"}
_RAD_UNITS = {"rad", "radian", "radians"}
_DECIMAL_COMMA = re.compile(r"[+-]?\d+,\d*(?:[eE][+-]?\d+)?")


def _cells(line: str, sep: str) -> list[str]:
    cells = [c.strip().strip('"').strip("'").strip() for c in line.split(sep)]
    while cells and cells[-1] == "":
        cells.pop()
    return cells


def _name_unit(cell: str) -> tuple[str, str]:
    """``'Magnitude (dB)'`` -> ``('magnitude', 'db')``; also ``[dB]``, ``/dB`` and a trailing unit word."""
    c = cell.strip().lower()
    m = re.fullmatch(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]", c)
    if m:
        return m.group(1).strip(), m.group(2).strip()
    if "/" in c and not c.startswith("v/v"):
        name, unit = c.split("/", 1)
        return name.strip(), unit.strip()
    parts = c.split()
    known = _DB_UNITS | _DEG_UNITS | _RAD_UNITS | set(_UNIT_SCALE) | {"v/v"}
    if len(parts) > 1 and parts[-1] in known:
        return " ".join(parts[:-1]), parts[-1]
    return c, ""


def _columns(cells: list[str]) -> dict[str, tuple[int, str]] | None:
    """Column index and unit of frequency, magnitude and phase in a column-name row, or None."""
    found: dict[str, tuple[int, str]] = {}
    for j, cell in enumerate(cells):
        name, unit = _name_unit(cell)
        if not name and not unit:
            continue
        if "freq" not in found and _FREQ_NAMES.search(name):
            found["freq"] = (j, unit)
        elif "phase" not in found and _PHASE_NAMES.search(name):
            found["phase"] = (j, unit)
        elif "mag" not in found and (_MAG_NAMES.search(name) or (name == "" and unit in _DB_UNITS)):
            found["mag"] = (j, unit)
    return found if len(found) == 3 else None


def _is_number(cell: str, sep: str) -> bool:
    try:
        _number("", cell, sep, 0, 0, "")
    except MeasuredDataError:
        return False
    return True


def _number(path: PathLike, cell: str, sep: str, line: int, col: int, name: str) -> float:
    s = cell.strip()
    if sep != "," and _DECIMAL_COMMA.fullmatch(s):
        s = s.replace(",", ".")
    return _parse_number(path, s, line, col, name)


def read_fra_csv(path: PathLike) -> MeasuredResponses:
    """Read an FRA instrument's CSV export (layouts in the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        The exported file, unchanged.

    Returns
    -------
    MeasuredResponses
        Frequencies in Hz (increasing) and the complex voltage ratio ``V_resp / V_ref``
        (dimensionless) under the name :data:`RESPONSE`; the preamble lines as comments.

    Raises
    ------
    MeasuredDataError
        One line naming the file and line: no column-name row, an unknown unit, a cell that is not a
        number, too few rows, frequencies not monotonic.
    """
    lines = _read_text_lines(path)
    header = None
    comments: list[str] = []
    for i, line in enumerate(lines):
        s = line.strip()
        if not s or s[0] in "#!%":
            continue
        for sep in _SEPARATORS:
            cols = _columns(_cells(s, sep)) if sep in s else None
            if cols:
                header = (i, sep, cols)
                break
        if header:
            break
        comments.append(s)
    if header is None:
        raise MeasuredDataError(path, "no column-name row naming frequency, magnitude and phase columns "
                                      "(e.g. 'Frequency (Hz),Magnitude (dB),Phase (deg)')", max(len(lines), 1))
    h_idx, sep, cols = header
    start = h_idx + 1
    # a unit row: the next non-blank row, with no number in the three columns
    for k in range(start, len(lines)):
        s = lines[k].strip()
        if not s:
            continue
        cells = _cells(s, sep)
        picked = [cells[j] if j < len(cells) else "" for j, _ in cols.values()]
        if not any(_is_number(c, sep) for c in picked if c):
            for key, (j, unit) in list(cols.items()):
                u = cells[j].strip().lower() if j < len(cells) else ""
                u = u.strip("[]()")
                if u:
                    cols[key] = (j, u)
            start = k + 1
        break
    fj, fu = cols["freq"]
    mj, mu = cols["mag"]
    pj, pu = cols["phase"]
    if fu not in ("", *_UNIT_SCALE):
        raise MeasuredDataError(path, f"unknown frequency unit {_show(fu)} (Hz, kHz, MHz)", h_idx + 1, fj + 1)
    if mu not in ("", *_DB_UNITS, *_LINEAR_UNITS):
        raise MeasuredDataError(path, f"unknown magnitude unit {_show(mu)} (dB, or V/V for a linear ratio)",
                                h_idx + 1, mj + 1)
    if pu not in ("", *_DEG_UNITS, *_RAD_UNITS):
        raise MeasuredDataError(path, f"unknown phase unit {_show(pu)} (deg or rad)", h_idx + 1, pj + 1)
    need = max(fj, mj, pj) + 1
    f, mag, ph, where = [], [], [], []
    for k in range(start, len(lines)):
        s = lines[k].strip()
        if not s or s[0] in "#!%":
            continue
        cells = _cells(s, sep)
        if len(cells) < need:
            raise MeasuredDataError(path, f"expected at least {need} columns separated by {sep!r}, found "
                                          f"{len(cells)}", k + 1)
        f.append(_number(path, cells[fj], sep, k + 1, fj + 1, "frequency"))
        mag.append(_number(path, cells[mj], sep, k + 1, mj + 1, "magnitude"))
        ph.append(_number(path, cells[pj], sep, k + 1, pj + 1, "phase"))
        where.append(k + 1)
    _check_count(path, len(f), len(lines), "data rows")
    f_hz = np.array(f) * _UNIT_SCALE.get(fu or "hz", 1.0)
    mag_a, ph_a = np.array(mag), np.array(ph)
    if f_hz.size > 1 and np.all(np.diff(f_hz) < 0):
        f_hz, mag_a, ph_a, where = f_hz[::-1], mag_a[::-1], ph_a[::-1], where[::-1]
    _check_rows_frequency(path, f_hz, where, fj + 1, "frequency")
    if mu in _LINEAR_UNITS:
        bad = np.flatnonzero(~(mag_a > 0))
        if bad.size:
            raise MeasuredDataError(path, f"linear magnitude must be > 0, got {mag_a[bad[0]]!r}", where[bad[0]],
                                    mj + 1, "magnitude")
        amp = mag_a
    else:
        amp = 10.0 ** (mag_a / 20.0)
    rad = ph_a if pu in _RAD_UNITS else np.radians(ph_a)
    h = amp * np.exp(1j * rad)
    if not np.all(np.isfinite(h)):
        k = int(np.flatnonzero(~np.isfinite(h))[0])
        raise MeasuredDataError(path, f"magnitude {mag_a[k]!r} dB overflows", where[k], mj + 1, "magnitude")
    unit_note = (f"columns: frequency {fu or 'hz'}, magnitude {mu or 'db (assumed)'}, "
                 f"phase {pu or 'deg (assumed)'}")
    return _responses_in_range(path, MeasuredResponses(f_hz, {RESPONSE: h}, source=os.fspath(path),
                                                       comments=comments + [unit_note]))
