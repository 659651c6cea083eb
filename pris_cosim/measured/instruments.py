"""Instrument and exchange formats of measured frequency responses.

Holds the readers and writers of whitespace magnitude/phase rows
(:func:`read_mag_phase_rows`, :func:`write_mag_phase_rows`), the
Keysight/Agilent E4990A export (:func:`read_e4990a`, :func:`write_e4990a`),
Touchstone Z-parameters through :mod:`pris_cosim.measured.touchstone`
(:func:`read_touchstone_z`, :func:`write_touchstone_z`) and MATLAB ``.mat``
files (:func:`read_mat`, :func:`write_mat`). Frequencies are in Hz and
impedances in Ohm; the layouts are described in :mod:`pris_cosim.measured.formats`.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import IO

import numpy as np

from pris_cosim.measured.core import (_SUFFIX_RE, _UNIT_SCALE, MIN_POINTS, MeasuredDataError, MeasuredResponses,
    PathLike, _atomic_write, _check_count, _check_nonnegative, _check_rows_frequency, _comment_lines, _comment_text,
    _fmt, _parse_rows, _polar, _r, _read_text_lines, _responses_in_range, _show, _split_unit, _strip_comment)

# ---------------------------------------------------------------------------
# Whitespace magnitude/phase rows (03PK10 style)
# ---------------------------------------------------------------------------


def read_mag_phase_rows(
    path: PathLike,
    df: float = 25e3,
    name: str = "Yin",
    has_dc_row: bool = True,
) -> MeasuredResponses:
    """Read whitespace-separated ``magnitude phase_deg`` rows on a uniform grid.

    Parameters
    ----------
    path : str or os.PathLike
        Text file, two numbers per line; blank lines and lines starting with
        ``#``, ``!`` or ``%`` are skipped.
    df : float, optional
        Frequency step in Hz (default 25 kHz, as for ``03PK10.txt``).
    name : str, optional
        Response name (default ``"Yin"``: the 03PK10 file holds the input
        admittance of a distribution transformer, in S).
    has_dc_row : bool, optional
        True (default): data row ``k`` (0-based) is at ``k * df`` and row 0,
        the DC value, is dropped (frequencies must be > 0); its value is kept
        as a comment.  False: row ``k`` is at ``(k + 1) * df``.

    Returns
    -------
    MeasuredResponses
        Frequencies ``df, 2 df, ...`` in Hz and the complex response.

    Raises
    ------
    MeasuredDataError
        Wrong number of values on a line, non-numeric or non-finite values,
        negative magnitude, fewer than 2 points left.
    """
    df = float(df)
    if not (math.isfinite(df) and df > 0):
        raise ValueError(f"df must be a finite frequency step > 0 Hz, got {df!r}")
    lines = _read_text_lines(path)
    rows: list[tuple[int, str]] = []
    comments: list[str] = []
    for idx, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s[0] in "#!%":
            comments.append(_comment_text(line, s[0]))
            continue
        rows.append((idx + 1, s))
    if not rows:
        raise MeasuredDataError(path, "empty file: no data rows", max(len(lines), 1))
    data = _parse_rows(path, rows, ["magnitude", "phase_deg"], sep=None)
    line_no = [r[0] for r in rows]
    _check_nonnegative(path, data[:, 0], line_no, 1, "magnitude")
    k = np.arange(data.shape[0], dtype=float)
    if has_dc_row:
        comments.append(
            f"DC row (line {line_no[0]}) dropped: magnitude {_r(data[0, 0])}, "
            f"phase_deg {_r(data[0, 1])}"
        )
        data, line_no, k = data[1:], line_no[1:], k[1:]
    else:
        k = k + 1.0
    _check_count(path, data.shape[0], rows[-1][0], "data rows after the DC row" if has_dc_row else "data rows")
    f = k * df
    return _responses_in_range(path, MeasuredResponses(
        f, {name: _polar(data[:, 0], data[:, 1])}, source=os.fspath(path), comments=comments
    ))


def write_mag_phase_rows(
    path: PathLike,
    data: MeasuredResponses,
    name: str | None = None,
    dc_value: complex = 0j,
) -> float:
    """Write ``magnitude phase_deg`` rows with a leading DC row, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : MeasuredResponses
        Frequencies must be ``df, 2 df, ..., N df`` (relative tolerance 1e-9).
    name : str, optional
        Response to write; default the only one.
    dc_value : complex, optional
        Value written in row 0 (DC).

    Returns
    -------
    float
        The frequency step ``df`` in Hz (pass it to :func:`read_mag_phase_rows`).
    """
    if name is None:
        if len(data.names) != 1:
            raise ValueError(f"data has responses {data.names}; pass name=...")
        name = data.names[0]
    z = data.response(name)
    f = data.frequency_hz
    df = float(f[0])
    grid = df * np.arange(1, f.size + 1)
    if not np.allclose(f, grid, rtol=1e-9, atol=0.0):
        raise ValueError("frequencies are not the uniform grid df, 2 df, ... required by this format")
    dc = complex(dc_value)
    mags = [abs(dc)] + np.abs(z).tolist()
    phs = [math.degrees(math.atan2(dc.imag, dc.real))] + np.degrees(np.angle(z)).tolist()

    def write(fh: IO) -> None:
        for m, p in zip(mags, phs):
            fh.write(f"{_fmt(m)} {_fmt(p)}\n")

    _atomic_write(path, write)
    return df


# ---------------------------------------------------------------------------
# Keysight E4990A exports
# ---------------------------------------------------------------------------

_E4990A_QUANTITY = {
    # key: (form, response family)
    ("r", "x"): ("reim", "Z"),
    ("|z|", "theta-z"): ("magphase", "Z"),
    ("g", "b"): ("reim", "Y"),
    ("|y|", "theta-y"): ("magphase", "Y"),
}


def read_e4990a(
    path: PathLike, channel: int | None = None, name: str | None = None
) -> MeasuredResponses:
    """Read a Keysight (Agilent) E4990A impedance-analyser CSV export.

    Parameters
    ----------
    path : str or os.PathLike
        Export with ``!`` header lines, ``BEGIN CHn_DATA``, a column header
        ``Frequency(Hz), A(unit)-data, B(unit)-data``, rows and ``END``.
        Supported trace pairs: ``R``/``X`` (Ohm), ``|Z|``/``theta-z``
        (Ohm, deg or rad), ``G``/``B`` (S), ``|Y|``/``theta-y`` (S, deg or
        rad).  Frequency unit Hz, kHz, MHz or GHz.
    channel : int, optional
        Read block ``BEGIN CH<channel>_DATA``; default the first block.
    name : str, optional
        Response name; default ``"Zin"`` for impedance traces and ``"Yin"``
        for admittance traces.

    Returns
    -------
    MeasuredResponses
        ``comments`` holds the ``!`` header lines (without the ``!``).

    Raises
    ------
    MeasuredDataError
        Missing block or ``END``, unsupported columns, bad rows, bad
        frequencies, negative ``|Z|``, fewer than 2 rows.
    """
    lines = _read_text_lines(path)
    comments: list[str] = []
    blocks: list[tuple[str, int, list[tuple[int, str]], int | None]] = []
    current: list | None = None
    for idx, line in enumerate(lines):
        ln = idx + 1
        s = line.strip()
        if not s:
            continue
        if s.startswith("!"):
            comments.append(_comment_text(line, "!"))
            continue
        upper = s.upper()
        if upper.startswith("BEGIN"):
            if current is not None:
                raise MeasuredDataError(path, f"BEGIN inside block opened on line {current[1]}", ln)
            current = [s[5:].strip(), ln, [], None]
            continue
        if upper == "END":
            if current is None:
                raise MeasuredDataError(path, "END without BEGIN", ln)
            current[3] = ln
            blocks.append(tuple(current))  # type: ignore[arg-type]
            current = None
            continue
        if current is None:
            raise MeasuredDataError(path, f"unexpected text {_show(s)} outside a BEGIN/END block", ln)
        current[2].append((ln, line))
    if current is not None:
        raise MeasuredDataError(path, f"missing END for BEGIN on line {current[1]}", len(lines))
    if not blocks:
        if not any(ln.strip() for ln in lines):
            raise MeasuredDataError(path, "empty file", 1)
        raise MeasuredDataError(path, "no 'BEGIN CHn_DATA' block", len(lines))
    if channel is None:
        block = blocks[0]
    else:
        want = f"CH{int(channel)}_DATA"
        found = [b for b in blocks if b[0].upper() == want]
        if not found:
            raise MeasuredDataError(
                path, f"no block {want}; blocks: {', '.join(b[0] for b in blocks)}"
            )
        block = found[0]
    label, begin_line, body, end_line = block
    if not body:
        raise MeasuredDataError(path, "block has no column header", begin_line)
    hline, htext = body[0]
    cells = [c.strip() for c in htext.split(",")]
    if len(cells) != 3:
        raise MeasuredDataError(
            path, f"expected 3 columns (frequency and two traces), found {len(cells)}", hline
        )
    fq, funit = _split_unit(cells[0])
    if fq != "frequency" or (funit or "hz") not in _UNIT_SCALE:
        raise MeasuredDataError(path, "first column must be Frequency(Hz)", hline, 1, cells[0])
    fscale = _UNIT_SCALE[funit or "hz"]
    qa, _ua = _split_unit(cells[1])
    qb, ub = _split_unit(cells[2])
    for j, c in ((2, cells[1]), (3, cells[2])):
        if c.lower().endswith("-mem"):
            raise MeasuredDataError(path, "memory traces are not supported (use -data)", hline, j, c)
    key = (qa, qb)
    if key not in _E4990A_QUANTITY:
        raise MeasuredDataError(
            path,
            "unsupported trace pair; expected R/X, |Z|/theta-z, G/B or |Y|/theta-y",
            hline, 2, cells[1],
        )
    form, family = _E4990A_QUANTITY[key]
    pscale = 1.0
    if form == "magphase":
        if ub in ("rad", "radian", "radians"):
            pscale = 180.0 / math.pi
        elif ub not in ("deg", "", "degree", "degrees"):
            raise MeasuredDataError(path, f"unknown phase unit {ub!r}", hline, 3, cells[2])
    rows = [(ln, _strip_comment(t, "!")) for ln, t in body[1:]]
    data = _parse_rows(path, rows, cells)
    _check_count(path, data.shape[0], end_line or hline)
    line_no = [r[0] for r in rows]
    with np.errstate(over="ignore"):  # an overflow to inf is refused by the range check
        f = data[:, 0] * fscale
    _check_rows_frequency(path, f, line_no, 1, cells[0])
    if form == "magphase":
        _check_nonnegative(path, data[:, 1], line_no, 2, cells[1])
        z = _polar(data[:, 1], data[:, 2] * pscale)
    else:
        z = data[:, 1] + 1j * data[:, 2]
    rname = name if name is not None else f"{family}in"
    return _responses_in_range(path, MeasuredResponses(f, {rname: z}, source=os.fspath(path), comments=comments))


def write_e4990a(
    path: PathLike, data: MeasuredResponses, form: str = "rx", name: str | None = None
) -> None:
    """Write an impedance in the E4990A export layout (CRLF), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : MeasuredResponses
        Data holding the impedance.
    form : {"rx", "zphase"}
        ``R(Ohm)-data, X(Ohm)-data`` or ``|Z|(Ohm)-data, theta-z(deg)-data``.
    name : str, optional
        Response to write; default the only one.
    """
    if form not in ("rx", "zphase"):
        raise ValueError(f"form must be 'rx' or 'zphase', got {form!r}")
    if name is None:
        if len(data.names) != 1:
            raise ValueError(f"data has responses {data.names}; pass name=...")
        name = data.names[0]
    z = data.response(name)
    if form == "rx":
        head = "Frequency(Hz), R(Ohm)-data, X(Ohm)-data"
        a, b = z.real.tolist(), z.imag.tolist()
    else:
        head = "Frequency(Hz), |Z|(Ohm)-data, theta-z(deg)-data"
        a, b = np.abs(z).tolist(), np.degrees(np.angle(z)).tolist()
    comments = _comment_lines(data.comments) or ["pris_cosim export"]

    def write(fh: IO) -> None:
        for c in comments:
            fh.write(f"!{c}\r\n")
        fh.write("\r\nBEGIN CH1_DATA\r\n" + head + "\r\n")
        for row in zip(data.frequency_hz.tolist(), a, b):
            fh.write(", ".join([_fmt(v) for v in row]) + "\r\n")
        fh.write("END\r\n")

    _atomic_write(path, write)


# ---------------------------------------------------------------------------
# Touchstone (read and written by scikit-rf in pris_cosim.measured.touchstone)
# ---------------------------------------------------------------------------

_TWO_PORT_NAMES = ("Z11", "Z12", "Z21", "Z22")
_TS_EXT = re.compile(r"\.[a-z](\d+)p", re.IGNORECASE)  # as pris_cosim.measured.touchstone.EXTENSION_RE


def read_touchstone_z(path: PathLike, name: str = "Zin") -> MeasuredResponses:
    """Read a 1-port or 2-port Touchstone file as Z-parameters in Ohm.

    The file is read by scikit-rf through :func:`pris_cosim.measured.touchstone.read_touchstone`
    (S, Y or Z; DB, MA or RI; version 1, and version 2 where skrf reads it).

    Parameters
    ----------
    path : str or os.PathLike
        ``.s1p``/``.s2p`` (or ``.z1p``, ``.ts``, ...) file.
    name : str, optional
        Response name for 1-port data (default ``"Zin"``).

    Returns
    -------
    MeasuredResponses
        1-port: one response ``name``; 2-port: ``Z11, Z12, Z21, Z22`` (Ohm).

    Raises
    ------
    MeasuredDataError
        One line naming file and line; also for files with more than 2 ports.
    """
    from pris_cosim.measured.touchstone import read_touchstone

    ts = read_touchstone(path)
    if ts.nports not in (1, 2):
        raise MeasuredDataError(path, f"{ts.nports}-port files are not supported here (1 or 2 ports)")
    with np.errstate(all="ignore"):
        try:
            zm = ts.z()
        except np.linalg.LinAlgError:
            zm = np.full(ts.values.shape, np.nan, dtype=complex)
    bad = np.flatnonzero(~np.all(np.isfinite(zm.reshape(zm.shape[0], -1)), axis=1))
    if ts.parameter != "Z" and bad.size == 0:
        inv = ts.values if ts.parameter == "Y" else np.eye(ts.nports) - ts.values
        scale = np.max(np.abs(inv).reshape(inv.shape[0], -1), axis=1) ** ts.nports
        det = np.linalg.det(inv) if ts.nports > 1 else inv[:, 0, 0]
        bad = np.flatnonzero(~(np.abs(det) > 1e-300 + 1e-14 * scale))
    if bad.size:
        what = "Y matrix" if ts.parameter == "Y" else "I - S"
        raise MeasuredDataError(path, f"{what} is singular; cannot convert to Z (point {int(bad[0]) + 1})")
    if ts.nports == 1:
        responses = {name: zm[:, 0, 0]}
    else:
        responses = {"Z11": zm[:, 0, 0], "Z12": zm[:, 0, 1], "Z21": zm[:, 1, 0], "Z22": zm[:, 1, 1]}
    return MeasuredResponses(ts.frequency_hz, responses, source=os.fspath(path), comments=ts.comments)


def write_touchstone_z(
    path: PathLike,
    data: MeasuredResponses,
    form: str = "RI",
    unit: str = "Hz",
    r_ref: float = 50.0,
    name: str | None = None,
) -> None:
    """Write Z-parameters as a Touchstone v1 file, atomically, through scikit-rf.

    Parameters
    ----------
    path : str or os.PathLike
        Target (``.s1p``/``.s2p``/``.z1p``... or ``.ts``); a ``.?Np``
        extension must match the port count.
    data : MeasuredResponses
        ``Z11, Z12, Z21, Z22`` -> 2-port; otherwise one response (``name``
        or the only one) -> 1-port.  Ohm.
    form : {"RI", "MA", "DB"}
        Number format (case-insensitive).
    unit : {"Hz", "kHz", "MHz", "GHz"}
        Frequency unit of the file.
    r_ref : float
        Reference resistance in Ohm; values are written normalised, ``Z / r_ref``.
    name : str, optional
        1-port response to write.
    """
    from pris_cosim.measured.touchstone import write_touchstone

    if name is None and set(_TWO_PORT_NAMES) <= set(data.names):
        r = data.responses
        zm = np.stack([np.stack([r["Z11"], r["Z12"]], -1), np.stack([r["Z21"], r["Z22"]], -1)], 1)
    else:
        if name is None:
            if len(data.names) != 1:
                raise ValueError(
                    f"data has responses {data.names}; need Z11..Z22 or a single response (name=...)"
                )
            name = data.names[0]
        zm = data.response(name)[:, None, None]
    write_touchstone(path, data.frequency_hz, zm, "Z", form, unit, r_ref, _comment_lines(data.comments))


# ---------------------------------------------------------------------------
# MATLAB .mat
# ---------------------------------------------------------------------------

_MAT_META = ("comments", "segment", "source")
_MAT_NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}")


def _mat_strings(value: object) -> list[str]:
    """Turn a loaded MATLAB char array / cell array into a list of str."""
    a = np.asarray(value)
    if a.dtype.kind == "U":
        return [str(x) for x in a.ravel()]
    if a.dtype == object:
        out = []
        for el in a.ravel():
            e = np.asarray(el)
            if e.size == 0:
                out.append("")
            elif e.dtype.kind == "U":
                out.append("".join(str(x) for x in e.ravel()))
            else:
                out.append(str(e.ravel()[0]))
        return out
    return []


def read_mat(path: PathLike) -> MeasuredResponses:
    """Read frequency responses from a MATLAB ``.mat`` file (v4-v7.2).

    Parameters
    ----------
    path : str or os.PathLike
        File with a frequency vector ``frequency_hz`` (or ``f``) in Hz and,
        per response, a complex (or real) vector ``NAME``, or a pair
        ``NAME_mag`` + ``NAME_phase_deg`` or ``NAME_re`` + ``NAME_im``.
        Optional ``comments`` (cell array of char), ``segment`` (char).
        Other non-numeric variables and numeric scalars are ignored.

    Returns
    -------
    MeasuredResponses

    Raises
    ------
    MeasuredDataError
        Unreadable file, missing frequency vector, length mismatch,
        NaN/inf, non-increasing or non-positive frequencies, negative
        magnitudes, unpaired columns, fewer than 2 points.  Messages name
        the variable and the 1-based element.
    """
    import scipy.io

    try:
        raw = scipy.io.loadmat(os.fspath(path), squeeze_me=False, chars_as_strings=True)
    except NotImplementedError:
        raise MeasuredDataError(path, "MATLAB v7.3 (HDF5) files are not supported; save with -v7") from None
    except OSError as exc:
        if not Path(path).is_file():
            raise MeasuredDataError(path, f"cannot read file ({exc.strerror or exc})") from None
        raise MeasuredDataError(path, f"not a readable MATLAB file (truncated or corrupt: {exc})") from None
    except Exception as exc:  # scipy's MatReadError and the errors of corrupt streams
        raise MeasuredDataError(path, f"not a readable MATLAB file ({exc})") from None
    vars_ = {k: v for k, v in raw.items() if not k.startswith("__")}

    def err(var: str, msg: str) -> MeasuredDataError:
        return MeasuredDataError(path, f"variable {var!r}: {msg}")

    fkey = "frequency_hz" if "frequency_hz" in vars_ else ("f" if "f" in vars_ else None)
    if fkey is None:
        raise MeasuredDataError(path, "no frequency vector (variable 'frequency_hz' or 'f')")

    def vector(var: str) -> np.ndarray:
        a = np.asarray(vars_[var])
        if a.dtype.kind not in "iufc":
            raise err(var, f"not numeric (MATLAB class {a.dtype})")
        if sum(d > 1 for d in a.shape) > 1:
            raise err(var, f"must be a vector, got shape {a.shape}")
        a = a.ravel()
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            x = a[bad[0]]
            raise err(var, f"element {int(bad[0]) + 1}: non-finite value {_r(x) if np.isrealobj(x) else repr(complex(x))}")
        return a

    f = vector(fkey)
    if f.dtype.kind == "c":
        if np.any(f.imag != 0):
            raise err(fkey, "frequencies must be real")
        f = f.real
    f = f.astype(float)
    if f.size < MIN_POINTS:
        raise err(fkey, f"too few points: {f.size} (need at least {MIN_POINTS})")
    for i in range(f.size):
        if not f[i] > 0:
            raise err(fkey, f"element {i + 1}: frequency must be > 0 Hz, got {_r(f[i])}")
        if i and f[i] <= f[i - 1]:
            what = "duplicated frequency" if f[i] == f[i - 1] else "frequencies must increase strictly; got"
            raise err(fkey, f"element {i + 1}: {what} {_r(f[i])} after {_r(f[i - 1])}")

    skip = {fkey, *_MAT_META}
    if fkey == "frequency_hz":
        skip.add("f")
    pairs: dict[str, dict[str, str]] = {}
    plain: dict[str, np.ndarray] = {}
    order: list[str] = []
    for var in vars_:
        if var in skip:
            continue
        a = np.asarray(vars_[var])
        if a.dtype.kind not in "iufc":
            continue
        if a.size == 1 and f.size != 1:
            continue
        m = _SUFFIX_RE.fullmatch(var)
        base = m.group(1) if m else var
        if base not in order:
            order.append(base)
        if m:
            pairs.setdefault(base, {})[m.group(2).lower()] = var
        else:
            plain[var] = a
    responses: dict[str, np.ndarray] = {}
    for base in order:
        if base in plain and base in pairs:
            raise err(next(iter(pairs[base].values())), f"conflicts with variable {base!r}")
        if base in plain:
            v = vector(base)
            if v.size != f.size:
                raise err(base, f"length {v.size} differs from {fkey!r} length {f.size}")
            responses[base] = v.astype(complex)
            continue
        slot = pairs[base]
        if set(slot) == {"mag", "phase_deg"}:
            mag, ph = vector(slot["mag"]), vector(slot["phase_deg"])
            for var, v in ((slot["mag"], mag), (slot["phase_deg"], ph)):
                if v.size != f.size:
                    raise err(var, f"length {v.size} differs from {fkey!r} length {f.size}")
                if v.dtype.kind == "c":
                    raise err(var, "must be real")
            neg = np.flatnonzero(mag < 0)
            if neg.size:
                raise err(slot["mag"], f"element {int(neg[0]) + 1}: negative magnitude {_r(mag[neg[0]])}")
            responses[base] = _polar(mag.astype(float), ph.astype(float))
        elif set(slot) == {"re", "im"}:
            re_, im_ = vector(slot["re"]), vector(slot["im"])
            for var, v in ((slot["re"], re_), (slot["im"], im_)):
                if v.size != f.size:
                    raise err(var, f"length {v.size} differs from {fkey!r} length {f.size}")
                if v.dtype.kind == "c":
                    raise err(var, "must be real")
            responses[base] = re_.astype(float) + 1j * im_.astype(float)
        else:
            var = next(iter(slot.values()))
            raise err(var, "unpaired; expected NAME_mag + NAME_phase_deg or NAME_re + NAME_im")
    if not responses:
        raise MeasuredDataError(path, "no response variables besides the frequency vector")
    comments = _mat_strings(vars_["comments"]) if "comments" in vars_ else []
    segment = None
    if "segment" in vars_:
        seg = _mat_strings(vars_["segment"])
        segment = seg[0] if seg else None
    return _responses_in_range(path, MeasuredResponses(f, responses, source=os.fspath(path), comments=comments, segment=segment))


def write_mat(path: PathLike, data: MeasuredResponses) -> None:
    """Write responses to a MATLAB v5 ``.mat`` file, atomically.

    Variables: ``frequency_hz`` (Hz, column vector), one complex column
    vector per response, ``comments`` (cell array of char) and, if set,
    ``segment`` (char).

    Parameters
    ----------
    path : str or os.PathLike
        Target file (no extension is added).
    data : MeasuredResponses
        Data; response names must be valid MATLAB identifiers and must not be
        ``frequency_hz``, ``f``, ``comments``, ``segment`` or ``source``.
    """
    import scipy.io

    mdict: dict[str, object] = {"frequency_hz": data.frequency_hz.reshape(-1, 1)}
    for n in data.names:
        if not _MAT_NAME_RE.fullmatch(n) or n in ("frequency_hz", "f", *_MAT_META):
            raise ValueError(f"response name {n!r} cannot be a MATLAB variable name here")
        mdict[n] = data.responses[n].reshape(-1, 1)
    cm = np.empty((len(data.comments), 1), dtype=object)
    for i, c in enumerate(data.comments):
        cm[i, 0] = c
    mdict["comments"] = cm
    if data.segment is not None:
        mdict["segment"] = data.segment

    def write(fh: IO) -> None:
        scipy.io.savemat(fh, mdict, format="5", do_compression=False, oned_as="column")

    _atomic_write(path, write, binary=True)
