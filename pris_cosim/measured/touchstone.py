"""Touchstone files through scikit-rf (``skrf``): reading, checking, writing.

The numbers are parsed and written by scikit-rf (:class:`skrf.io.touchstone.Touchstone`,
:meth:`skrf.Network.write_touchstone`).  This module adds what a measurement
pipeline needs around it:

* a structural check of the file before skrf sees it, so that every problem
  (truncated record, wrong port count, garbage cell, non-increasing
  frequency, bad option line) is reported as one
  :class:`~pris_cosim.measured.formats.MeasuredDataError` line naming the file and
  the line, never as a traceback or a silent re-interpretation (skrf reads
  a decreasing frequency in a 2-port v1 file as the start of noise data);
* silence: skrf's warnings and prints never reach the user;
* exact parameter values: the values are taken in the file's own parameter
  (S, Y or Z; de-normalised by ``R`` for version 1), so that a Z file read
  back gives exactly the Z that was written.

Supported: any port count, S/Y/Z parameters, DB/MA/RI formats, Touchstone
version 1 (``.sNp``, ``.yNp``, ``.zNp``; other extensions with the port
count inferred from the first record) and version 2 (``[Version] 2.0``
keyword files, as far as skrf reads them).
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence, Union

import numpy as np

PathLike = Union[str, "os.PathLike[str]"]

__all__ = [
    "TouchstoneData",
    "read_touchstone",
    "touchstone_text",
    "write_touchstone",
    "ports_from_extension",
    "EXTENSION_RE",
]

#: ``.sNp``/``.yNp``/``.zNp`` (any letter) extensions, group 1 = port count.
EXTENSION_RE = re.compile(r"\.[a-z](\d+)p", re.IGNORECASE)

_UNIT_SCALE = {"hz": 1.0, "khz": 1e3, "mhz": 1e6, "ghz": 1e9}
_NUM_RE = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_NONFINITE_RE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)


def ports_from_extension(path: PathLike) -> int | None:
    """Port count from a ``.?Np`` extension, or None for other extensions."""
    m = EXTENSION_RE.fullmatch(Path(path).suffix)
    return int(m.group(1)) if m else None


@dataclass
class TouchstoneData:
    """A Touchstone file's contents.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        Frequencies in Hz, strictly increasing, shape ``(F,)``.
    parameter : {"S", "Y", "Z"}
        Parameter stored in the file.
    values : numpy.ndarray
        The file's parameter matrix in physical units (Z in Ohm, Y in S, S
        dimensionless), shape ``(F, P, P)``, ``values[:, i, j]`` = N_(i+1)(j+1).
    r_ref : float
        Reference resistance in Ohm.
    comments : list of str
        Comment lines (``!`` removed, one leading space dropped).
    network : skrf.Network
        The same data as a scikit-rf network (S-parameters referred to ``r_ref``).
    """

    frequency_hz: np.ndarray
    parameter: str
    values: np.ndarray
    r_ref: float
    comments: list[str] = field(default_factory=list)
    network: object = None

    @property
    def nports(self) -> int:
        """Port count."""
        return int(self.values.shape[1])

    def z(self) -> np.ndarray:
        """Z-parameters in Ohm, shape ``(F, P, P)`` (exact for Z files)."""
        return _convert(self.values, self.parameter, "Z", self.r_ref)

    def y(self) -> np.ndarray:
        """Y-parameters in S, shape ``(F, P, P)`` (exact for Y files)."""
        return _convert(self.values, self.parameter, "Y", self.r_ref)


@contextlib.contextmanager
def _quiet():
    """Swallow skrf's warnings and anything it prints."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            with np.errstate(all="ignore"):
                yield


def _error(path: PathLike, reason: str, line: int | None = None, column: int | None = None):
    from pris_cosim.measured.core import MeasuredDataError

    return MeasuredDataError(path, reason, line, column)


def _show(cell: str, limit: int = 40) -> str:
    s = cell.strip()
    return repr(s if len(s) <= limit else s[: limit - 3] + "...")


def _r(x: float) -> str:
    return repr(float(x))


@dataclass
class _Layout:
    unit: str = "ghz"
    param: str = "s"
    fmt: str = "ma"
    r_ref: float = 50.0
    version2: bool = False
    nports: int = 0
    comments: list[str] = field(default_factory=list)
    record_lines: list[int] = field(default_factory=list)
    raw: np.ndarray | None = None
    cells: list[list[tuple[int, int]]] = field(default_factory=list)


#: Reference resistances accepted in an option line, Ohm (analysers use 50 or 75 Ohm; the arithmetic of the
#: S/Y/Z conversions stays finite inside this range).
R_REF_RANGE = (1e-6, 1e9)


def _parse_option(path: PathLike, s: str, ln: int, lay: _Layout) -> None:
    toks = s[1:].split()
    i = 0
    while i < len(toks):
        t = toks[i].lower()
        if t in _UNIT_SCALE:
            lay.unit = t
        elif t in ("s", "y", "z"):
            lay.param = t
        elif t in ("h", "g"):
            raise _error(path, f"{t.upper()}-parameters are not supported", ln)
        elif t in ("ma", "db", "ri"):
            lay.fmt = t
        elif t == "r":
            if i + 1 >= len(toks):
                raise _error(path, "option 'R' without a value", ln)
            try:
                r = float(toks[i + 1])
            except ValueError:
                raise _error(path, f"reference resistance {_show(toks[i + 1])} is not a number", ln) from None
            if not (math.isfinite(r) and R_REF_RANGE[0] <= r <= R_REF_RANGE[1]):
                raise _error(path, f"reference resistance {r!r} Ohm is outside the physical range "
                             f"{R_REF_RANGE[0]:g} .. {R_REF_RANGE[1]:g} Ohm", ln)
            lay.r_ref = r
            i += 1
        else:
            raise _error(path, f"unknown option {_show(toks[i])}", ln)
        i += 1


def _scan(path: PathLike, lines: Sequence[str], want_ports: int | None) -> _Layout:
    """Check the file's structure and numbers, with line and column for every problem."""
    lay = _Layout()
    option_seen = False
    data: list[tuple[int, list[str]]] = []
    for idx, line in enumerate(lines):
        ln = idx + 1
        body, bang, comment = line.partition("!")
        if bang:
            lay.comments.append(comment[1:] if comment.startswith(" ") else comment)
        s = body.strip()
        if not s:
            continue
        if s.startswith("["):
            key = s.split("]")[0].lower() + "]"
            lay.version2 = True
            if key == "[number of ports]":
                try:
                    lay.nports = int(s.split("]", 1)[1].split()[0])
                except (ValueError, IndexError):
                    raise _error(path, f"bad [Number of Ports] line {_show(s)}", ln) from None
            elif key in ("[noise data]",):
                break
            continue
        if s.startswith("#"):
            if option_seen:
                continue
            if data:
                raise _error(path, "option line after data lines", ln)
            option_seen = True
            _parse_option(path, s, ln, lay)
            continue
        data.append((ln, s.split()))
    if not data:
        if not any(x.strip() for x in lines):
            raise _error(path, "empty file", 1)
        raise _error(path, "no data lines", max(len(lines), 1))
    nports = lay.nports or ports_from_extension(path)
    if nports is None:
        n0 = len(data[0][1])
        nports = {3: 1, 9: 2}.get(n0)
        if nports is None:
            raise _error(path, f"cannot infer the port count from {n0} values (expected 3 for 1-port, "
                               f"9 for 2-port)", data[0][0])
    if nports < 1:
        raise _error(path, f"bad port count {nports}")
    for ln, toks in data:
        for j, t in enumerate(toks):
            if not (_NUM_RE.fullmatch(t) or _NONFINITE_RE.fullmatch(t)):
                raise _error(path, f"not a number: {_show(t)}", ln, j + 1)
    counts = {len(toks) for _, toks in data}
    if len(counts) == 1 and not lay.version2:
        (n0,) = counts
        line_ports = {1 + 2 * p * p: p for p in range(1, 5)}.get(n0)
        if line_ports is not None and line_ports != nports and n0 < 1 + 2 * nports * nports:
            need = want_ports or nports
            raise _error(path, f"every line holds {n0} values, as in a {line_ports}-port file; a {need}-port "
                               f"file has {1 + 2 * need * need} values per frequency", data[0][0])
    lay.nports = nports
    if want_ports is not None and nports != want_ports:
        raise _error(path, f"a {nports}-port file where a {want_ports}-port file is needed")
    per = 1 + 2 * nports * nports
    records: list[list[tuple[int, int, str]]] = []
    cur: list[tuple[int, int, str]] = []
    for ln, toks in data:
        if not cur:
            records.append(cur)
            lay.record_lines.append(ln)
        if len(cur) + len(toks) > per:
            raise _error(path, f"too many values: a {nports}-port record has {per} (frequency + {per - 1})", ln)
        base = len(cur)
        cur.extend((ln, base + j + 1, t) for j, t in enumerate(toks))
        if len(cur) == per:
            cur = []
    if cur:
        raise _error(path, f"incomplete record (truncated file?): {len(cur)} of {per} values",
                     lay.record_lines[-1])
    if len(records) < 2:
        raise _error(path, f"too few frequency points: {len(records)} (need at least 2)", lay.record_lines[-1])
    raw = np.empty((len(records), per))
    for r, rec in enumerate(records):
        for k, (ln, pos, t) in enumerate(rec):
            if _NUM_RE.fullmatch(t):
                v = float(t)
                if math.isinf(v):
                    raise _error(path, f"value {_show(t)} overflows to infinity", ln, pos)
            elif _NONFINITE_RE.fullmatch(t):
                raise _error(path, f"non-finite value {_show(t)}", ln, pos)
            else:
                raise _error(path, f"not a number: {_show(t)}", ln, pos)
            raw[r, k] = v
    lay.cells = [[(ln, pos) for ln, pos, _ in rec] for rec in records]
    lay.raw = raw
    _check_values(path, lay)
    return lay


#: Largest decimal exponent of a magnitude in a data cell: products of two such values (the S/Y/Z
#: conversions) stay finite in double precision.
MAX_LOG10_MAGNITUDE = 150


def _check_values(path: PathLike, lay: _Layout) -> None:
    raw, lines = lay.raw, lay.record_lines
    with np.errstate(over="ignore"):
        f = raw[:, 0] * _UNIT_SCALE[lay.unit]
    for i in range(f.size):
        if not math.isfinite(f[i]):
            raise _error(path, f"frequency {_r(raw[i, 0])} {lay.unit} overflows in Hz", lines[i], 1)
        if not f[i] > 0:
            raise _error(path, f"frequency must be > 0 Hz, got {_r(f[i])}", lines[i], 1)
        if i and f[i] <= f[i - 1]:
            if f[i] == f[i - 1]:
                msg = f"duplicated frequency {_r(f[i])} (same as line {lines[i - 1]})"
            else:
                msg = (f"frequency {_r(f[i])} is below the previous {_r(f[i - 1])} (line {lines[i - 1]}); "
                       f"frequencies must increase strictly")
            raise _error(path, msg, lines[i], 1)
    a = raw[:, 1::2]
    if lay.fmt == "ma":
        bad = np.argwhere(a < 0)
        if bad.size:
            r, c = bad[0]
            ln, pos = lay.cells[r][1 + 2 * c]
            raise _error(path, f"negative magnitude {_r(a[r, c])}", ln, pos)
    if lay.fmt == "db":
        bad = np.argwhere(np.abs(a) > 20.0 * MAX_LOG10_MAGNITUDE)
        if bad.size:
            r, c = bad[0]
            ln, pos = lay.cells[r][1 + 2 * c]
            lim = 20 * MAX_LOG10_MAGNITUDE
            raise _error(path, f"magnitude {_r(a[r, c])} dB is outside -{lim:g} .. {lim:g} dB", ln, pos)
    else:  # RI: both parts; MA: the magnitude
        cols = raw[:, 1:] if lay.fmt == "ri" else a
        bad = np.argwhere(np.abs(cols) > 10.0 ** MAX_LOG10_MAGNITUDE)
        if bad.size:
            r, c = bad[0]
            ln, pos = lay.cells[r][1 + (c if lay.fmt == "ri" else 2 * c)]
            raise _error(path, f"value {_r(cols[r, c])} is outside +-1e{MAX_LOG10_MAGNITUDE} (the parameter "
                         "conversions would overflow)", ln, pos)


def _read_lines(path: PathLike) -> list[str]:
    from pris_cosim.measured.core import _read_text_lines

    return _read_text_lines(path)


def _convert(values: np.ndarray, src: str, dst: str, r_ref: float) -> np.ndarray:
    """Convert between S (referred to ``r_ref``), Y and Z parameter matrices."""
    src, dst = src.upper(), dst.upper()
    if src == dst:
        return values.copy()
    import skrf

    z0 = np.full(values.shape[:2], float(r_ref))
    with _quiet():
        if src == "Z" and dst == "Y" or src == "Y" and dst == "Z":
            out = np.linalg.inv(values)
        else:
            func = getattr(skrf.network, f"{src.lower()}2{dst.lower()}")
            out = func(values, z0)
    return out


def read_touchstone(path: PathLike, nports: int | None = None) -> TouchstoneData:
    """Read a Touchstone file with scikit-rf, after a structural check.

    Parameters
    ----------
    path : str or os.PathLike
        Touchstone file (v1 ``.sNp``/``.yNp``/``.zNp`` or other extension,
        or a v2 keyword file).
    nports : int, optional
        Port count the caller needs; a file with another count is refused.

    Returns
    -------
    TouchstoneData
        Frequencies in Hz, the file's parameter matrix in physical units and
        the :class:`skrf.Network`.

    Raises
    ------
    MeasuredDataError
        One line ``<file>[:<line>]: [column <k>: ]<reason>`` for any problem.
    """
    import skrf

    lines = _read_lines(path)
    lay = _scan(path, lines, nports)
    # skrf infers the port count from the name: hand it the checked text under a canonical name
    fid = io.StringIO("\n".join(lines) + "\n")
    fid.name = f"{Path(path).stem or 'data'}." + ("ts" if lay.version2 else f"{lay.param}{lay.nports}p")
    try:
        with _quiet():
            ts = skrf.io.touchstone.Touchstone(fid)
            f = np.asarray(ts.f, dtype=float)
            flat = np.asarray(ts.s_flat, dtype=complex)
            z0 = np.asarray(ts.z0)
    except Exception as exc:  # skrf's own parse errors, as one line
        text = " ".join(str(exc).split()) or type(exc).__name__
        raise _error(path, f"scikit-rf cannot read the file: {text}") from None
    p = lay.nports
    if f.size != lay.raw.shape[0] or flat.shape != (f.size, p * p):
        raise _error(path, f"scikit-rf read {f.size} points of {flat.shape[-1]} values, the file has "
                           f"{lay.raw.shape[0]} of {p * p}")
    param = str(ts.parameter).upper()
    res = np.ravel(np.real(np.asarray(ts.resistance, dtype=complex))) if ts.resistance is not None else []
    r_ref = float(res[0]) if len(res) else lay.r_ref
    if lay.version2:
        # keyword files (matrix format, data order, per-port references): take skrf's S and convert back
        s_net = np.asarray(ts.s, dtype=complex)
        m = s_net if param == "S" else _convert(s_net, "S", param, r_ref)
    else:
        m = flat.reshape(-1, p, p)
        if p == 2:
            m = m.transpose(0, 2, 1)  # v1 two-port order 11 21 12 22
        if param in ("Z", "Y"):
            m = m * r_ref if param == "Z" else m / r_ref
    if not np.all(np.isfinite(m)):
        r = int(np.argmax(~np.all(np.isfinite(m.reshape(f.size, -1)), axis=1)))
        raise _error(path, "non-finite parameter values", lay.record_lines[r])
    # the Network is built from these values: skrf's own v1 Y import scales by R instead of 1/R
    with _quiet():
        s_par = _convert(m, param, "S", r_ref) if param != "S" else m
        network = skrf.Network(frequency=skrf.Frequency.from_f(f, unit="hz"), s=s_par,
                               z0=np.full((f.size, m.shape[1]), r_ref) if not lay.version2 else z0,
                               name=Path(path).stem)
    if not np.all(np.isfinite(network.s)):
        raise _error(path, "conversion to S-parameters gives non-finite values")
    return TouchstoneData(f, param, m, r_ref, list(lay.comments), network)


def touchstone_text(
    frequency_hz: np.ndarray,
    values: np.ndarray,
    parameter: str = "Z",
    form: str = "RI",
    unit: str = "Hz",
    r_ref: float = 50.0,
    comments: Sequence[str] = (),
) -> str:
    """Touchstone v1 text for a parameter matrix, written by :meth:`skrf.Network.write_touchstone`.

    Parameters
    ----------
    frequency_hz : numpy.ndarray
        Frequencies in Hz, shape ``(F,)``.
    values : numpy.ndarray
        Parameter matrix in physical units (Z in Ohm, Y in S), shape ``(F, P, P)``.
    parameter : {"S", "Y", "Z"}
        Parameter of ``values``, written as such.
    form : {"RI", "MA", "DB"}
        Number format.
    unit : {"Hz", "kHz", "MHz", "GHz"}
        Frequency unit of the file.
    r_ref : float
        Reference resistance in Ohm (values are written normalised to it).
    comments : sequence of str
        Comment lines (without ``!``).

    Notes
    -----
    skrf's version-1 writer turns Y and Z into S and back, which costs up to
    about 1e-10 relative accuracy for values far from ``r_ref``.  To keep a
    write/read round trip exact, the normalised matrix is handed to the
    writer as its data block and the option line names the parameter.
    """
    import skrf

    parameter = parameter.upper()
    fmt = form.lower()
    if parameter not in ("S", "Y", "Z"):
        raise ValueError(f"parameter must be S, Y or Z, got {parameter!r}")
    if fmt not in ("ri", "ma", "db"):
        raise ValueError(f"form must be RI, MA or DB, got {form!r}")
    if unit.lower() not in _UNIT_SCALE:
        raise ValueError(f"unit must be Hz, kHz, MHz or GHz, got {unit!r}")
    r_ref = float(r_ref)
    if not (math.isfinite(r_ref) and r_ref > 0):
        raise ValueError(f"r_ref must be > 0 Ohm, got {r_ref!r}")
    v = np.asarray(values, dtype=complex)
    norm = {"S": 1.0, "Z": 1.0 / r_ref, "Y": r_ref}[parameter]
    data = v * norm
    if fmt == "db" and not np.all(np.abs(data) > 0):
        raise ValueError("zero magnitude cannot be written in DB format")
    freq = skrf.Frequency.from_f(np.asarray(frequency_hz, dtype=float), unit="hz")
    freq.unit = {"hz": "Hz", "khz": "kHz", "mhz": "MHz", "ghz": "GHz"}[unit.lower()]
    with _quiet():
        net = skrf.Network(frequency=freq, s=data, z0=1.0, name="model")
        lines_out = []
        for c in comments:
            lines_out.extend(str(c).replace("\r\n", "\n").replace("\r", "\n").split("\n"))
        net.comments = "\n".join(" " + c for c in lines_out) if lines_out else ""
        text = net.write_touchstone(return_string=True, form=fmt, skrf_comment=False)
    keep, seen_option = [], False
    for line in text.splitlines():
        if line.startswith("#"):
            seen_option = True
            line = f"# {freq.unit} {parameter} {fmt.upper()} R {r_ref!r}"
        elif seen_option and line.startswith("!"):
            continue  # skrf's column labels
        keep.append(line)
    return "\n".join(keep) + "\n"


def write_touchstone(
    path: PathLike,
    frequency_hz: np.ndarray,
    values: np.ndarray,
    parameter: str = "Z",
    form: str = "RI",
    unit: str = "Hz",
    r_ref: float = 50.0,
    comments: Sequence[str] = (),
) -> None:
    """Write a parameter matrix as a Touchstone v1 file, atomically.

    See :func:`touchstone_text` for the parameters; a ``.?Np`` extension of
    ``path`` must match the port count.
    """
    from pris_cosim.measured.core import _atomic_write

    v = np.asarray(values)
    ext_ports = ports_from_extension(path)
    if ext_ports is not None and ext_ports != v.shape[1]:
        raise ValueError(f"extension {Path(path).suffix!r} does not match {v.shape[1]}-port data")
    text = touchstone_text(frequency_hz, v, parameter, form, unit, r_ref, comments)
    _atomic_write(path, lambda fh: fh.write(text))
