"""Measured frequency responses and waveforms: readers, writers, validation.

All readers return a :class:`MeasuredResponses` (frequency responses) or a
:class:`Waveforms` (time-domain records).  Every problem found in an input
file raises :class:`MeasuredDataError`, a :class:`ValueError` whose message
is one line of the form ``<file>:<line>: column <k> '<name>': <reason>``
(the line and column parts are left out where they do not apply, e.g. for
MATLAB files, which name the variable instead).

Formats
-------
Interfaces CSV (:func:`read_response_csv`, :func:`write_response_csv`)
    ``#`` comment lines, then a header ``frequency_hz,NAME_mag,NAME_phase_deg``
    or ``frequency_hz,NAME_re,NAME_im`` (any number of responses, each as a
    pair of columns), then one row per frequency in Hz, strictly increasing.
    Optionally the rows are split into segments by lines
    ``<segment> LABEL # comment`` after the header.
Multi-segment instrument CSV (:func:`read_multisegment_csv`)
    Header ``FREQUENCY [Hz],MAG [O],PHASE [deg]`` (one response, named
    ``Zin`` by default) and segments introduced by ``<segment> LABEL #
    comment`` lines, as in ``small_transformer_3_loads.csv``.
Whitespace magnitude/phase rows (:func:`read_mag_phase_rows`)
    Two numbers per line, ``magnitude phase_deg``; row ``k`` (0-based) is at
    ``k * df`` and row 0 is DC, as in ``03PK10.txt``.  Response name ``Yin``
    by default (that file is an admittance).
Keysight/Agilent E4990A export (:func:`read_e4990a`)
    ``!`` header lines, ``BEGIN CH1_DATA``, a column header such as
    ``Frequency(Hz), R(Ohm)-data, X(Ohm)-data`` or
    ``Frequency(Hz), |Z|(Ohm)-data, theta-z(deg)-data``, data rows, ``END``.
Touchstone (:func:`read_touchstone_z`, :func:`write_touchstone_z`)
    1-port and 2-port files, read and written by scikit-rf through
    :mod:`pris_cosim.touchstone` (which also reads any port count, S/Y/Z,
    DB/MA/RI, version 1 and 2).  S- and Y-parameter files are converted to Z.
MATLAB ``.mat`` (:func:`read_mat`, :func:`write_mat`)
    Variable ``frequency_hz`` (or ``f``) plus one complex array per response,
    or ``NAME_mag``/``NAME_phase_deg`` or ``NAME_re``/``NAME_im`` pairs.
Waveform CSV (:func:`read_waveform_csv`, :func:`write_waveform_csv`)
    ``time_s,v_bprbs,v_in,i_in[,v_out]``, uniformly sampled, SI units.

:func:`load_measured` picks the reader from the file extension and content.

Writers replace their target atomically: the data go to a temporary file in
the same directory that is renamed over the target only once complete, so an
error while writing never leaves a half-written or truncated file behind.
Numbers are written with Python's shortest round-trip representation, so a
write followed by a read gives back the same binary values (up to the
rounding of the polar/dB conversions where those forms are used).
"""

from __future__ import annotations

import math
import os
import re
import secrets
import stat
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Callable, Iterable, Sequence, Union

import numpy as np

__all__ = [
    "MeasuredDataError",
    "MeasuredResponses",
    "Waveforms",
    "SegmentInfo",
    "read_response_csv",
    "write_response_csv",
    "read_multisegment_csv",
    "write_multisegment_csv",
    "list_segments",
    "segment_info",
    "read_mag_phase_rows",
    "write_mag_phase_rows",
    "read_e4990a",
    "write_e4990a",
    "read_touchstone_z",
    "write_touchstone_z",
    "read_mat",
    "write_mat",
    "read_waveform_csv",
    "write_waveform_csv",
    "detect_format",
    "load_measured",
]

PathLike = Union[str, "os.PathLike[str]"]

#: Minimum number of frequency points a reader accepts.
MIN_POINTS = 2

#: Relative tolerance on the sampling-interval jitter of waveform files.
WAVEFORM_DT_RTOL = 1e-6


# ---------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------


def _one_line(text: str, limit: int = 400) -> str:
    """Collapse ``text`` to a single line of at most ``limit`` characters."""
    s = " ".join(str(text).split())
    return s if len(s) <= limit else s[: limit - 3] + "..."


def _show(cell: str, limit: int = 40) -> str:
    """Quote a cell's text for an error message (single line, truncated)."""
    s = cell.strip()
    if len(s) > limit:
        s = s[: limit - 3] + "..."
    return repr(s)


class MeasuredDataError(ValueError):
    """A measured-data file is malformed or inconsistent.

    The message is always one line: ``<path>[:<line>]: [column ...: ]<reason>``.

    Parameters
    ----------
    path : str or os.PathLike
        File being read (as given by the caller).
    reason : str
        What is wrong.
    line : int, optional
        1-based line number in the file.
    column : int, optional
        1-based column index.
    column_name : str, optional
        Column (or header cell) name.

    Attributes
    ----------
    path, reason, line, column, column_name
        As given.
    """

    def __init__(
        self,
        path: PathLike,
        reason: str,
        line: int | None = None,
        column: int | None = None,
        column_name: str | None = None,
    ) -> None:
        self.path = os.fspath(path) if not isinstance(path, str) else path
        self.reason = _one_line(reason)
        self.line = line
        self.column = column
        self.column_name = column_name
        loc = _one_line(self.path, 300)
        if line is not None:
            loc += f":{line}"
        col = ""
        if column is not None or column_name is not None:
            parts = ["column"]
            if column is not None:
                parts.append(str(column))
            if column_name is not None:
                parts.append(repr(_one_line(column_name, 60)))
            col = " ".join(parts) + ": "
        super().__init__(f"{loc}: {col}{self.reason}")

    def __reduce__(self):  # keep picklable (e.g. across dask workers)
        return (
            self.__class__,
            (self.path, self.reason, self.line, self.column, self.column_name),
        )


# ---------------------------------------------------------------------------
# Data containers
# ---------------------------------------------------------------------------


def _check_frequency(f: np.ndarray, what: str = "frequency_hz") -> None:
    if f.ndim != 1:
        raise ValueError(f"{what} must be 1-D, got shape {f.shape}")
    if f.size < 1:
        raise ValueError(f"{what} is empty")
    if not np.all(np.isfinite(f)):
        raise ValueError(f"{what} contains NaN or infinite values")
    if f[0] <= 0:
        raise ValueError(f"{what} must be > 0 Hz, got {_r(f[0])}")
    if f.size > 1 and not np.all(np.diff(f) > 0):
        k = int(np.argmin(np.diff(f) > 0))
        raise ValueError(
            f"{what} must increase strictly: element {k + 1} = {_r(f[k + 1])} "
            f"after {_r(f[k])}"
        )


@dataclass(eq=False)
class MeasuredResponses:
    """A set of complex frequency responses on a common frequency grid.

    Parameters
    ----------
    frequency_hz : numpy.ndarray
        Frequencies in Hz, 1-D, finite, > 0, strictly increasing.
    responses : dict of str to numpy.ndarray
        Complex responses (impedance in Ohm, admittance in S, or dimensionless
        voltage ratios), each of the same length as ``frequency_hz``.
        Conventional names: ``Zin``, ``Yin``, ``Zlvoc``, ``Zlvsc``, ``Zhvoc``,
        ``Zhvsc``, ``Rlvhv``, ``Rhvlv``, ``V_<node>``, ``Z11`` ... ``Z22``.
    source : str, optional
        Path of the file the data came from (empty when built in memory).
    comments : list of str, optional
        Free comment lines from the file, without their comment markers.
    segment : str, optional
        Segment label for data taken from a multi-segment file.

    Raises
    ------
    ValueError
        If the arrays are inconsistent (shape, non-finite values, frequency
        order).
    """

    frequency_hz: np.ndarray
    responses: dict[str, np.ndarray]
    source: str = ""
    comments: list[str] = field(default_factory=list)
    segment: str | None = None

    def __post_init__(self) -> None:
        f = np.array(self.frequency_hz, dtype=float)
        _check_frequency(f)
        resp: dict[str, np.ndarray] = {}
        for name, values in dict(self.responses).items():
            if not isinstance(name, str) or not name:
                raise ValueError(f"response name must be a non-empty str, got {name!r}")
            a = np.array(values, dtype=complex)
            if a.shape != f.shape:
                raise ValueError(
                    f"response {name!r} has shape {a.shape}, frequency_hz has {f.shape}"
                )
            if not np.all(np.isfinite(a)):
                raise ValueError(f"response {name!r} contains NaN or infinite values")
            resp[name] = a
        self.frequency_hz = f
        self.responses = resp
        self.source = "" if self.source is None else str(self.source)
        self.comments = [str(c) for c in self.comments]
        if self.segment is not None:
            self.segment = str(self.segment)

    # -- access ---------------------------------------------------------
    @property
    def names(self) -> list[str]:
        """Response names, in file order."""
        return list(self.responses)

    def __len__(self) -> int:
        return int(self.frequency_hz.size)

    def __contains__(self, name: object) -> bool:
        return name in self.responses

    def response(self, name: str) -> np.ndarray:
        """Complex response ``name`` (same units as stored).

        Raises
        ------
        KeyError
            If there is no such response; the message lists the names.
        """
        try:
            return self.responses[name]
        except KeyError:
            raise KeyError(f"no response {name!r}; available: {self.names}") from None

    __getitem__ = response

    def mag(self, name: str) -> np.ndarray:
        """Magnitude ``|H|`` of response ``name`` (units of the response)."""
        return np.abs(self.response(name))

    def phase_deg(self, name: str) -> np.ndarray:
        """Phase of response ``name`` in degrees, in (-180, 180]."""
        return np.degrees(np.angle(self.response(name)))

    def select(self, fmin: float | None = None, fmax: float | None = None) -> "MeasuredResponses":
        """Points with ``fmin <= f <= fmax`` (Hz, inclusive; None = unbounded).

        Returns
        -------
        MeasuredResponses
            A new object holding copies of the selected points.

        Raises
        ------
        ValueError
            If ``fmin > fmax`` or no point lies in the band.
        """
        lo = -math.inf if fmin is None else float(fmin)
        hi = math.inf if fmax is None else float(fmax)
        if lo > hi:
            raise ValueError(f"fmin {lo!r} Hz is above fmax {hi!r} Hz")
        keep = (self.frequency_hz >= lo) & (self.frequency_hz <= hi)
        if not np.any(keep):
            raise ValueError(
                f"no frequency point in [{lo!r}, {hi!r}] Hz; data span "
                f"{_r(self.frequency_hz[0])} to {_r(self.frequency_hz[-1])} Hz"
            )
        return MeasuredResponses(
            self.frequency_hz[keep].copy(),
            {k: v[keep].copy() for k, v in self.responses.items()},
            source=self.source,
            comments=list(self.comments),
            segment=self.segment,
        )


@dataclass(eq=False)
class Waveforms:
    """Uniformly sampled PRIS waveforms (the waveform CSV contract).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sample times in s, uniform spacing (relative jitter <= 1e-6 of the
        mean step), strictly increasing, at least 2 samples.
    v_bprbs : numpy.ndarray
        Commanded H-bridge voltage in V (value of row k holds from
        ``time_s[k]`` to ``time_s[k+1]``).
    v_in : numpy.ndarray
        DUT terminal voltage in V.
    i_in : numpy.ndarray
        Current from the source RLC into the DUT terminal in A.
    v_out : numpy.ndarray, optional
        Output-terminal voltage in V.
    source : str, optional
        File the data came from.
    comments : list of str, optional
        Comment lines from the file.
    """

    time_s: np.ndarray
    v_bprbs: np.ndarray
    v_in: np.ndarray
    i_in: np.ndarray
    v_out: np.ndarray | None = None
    source: str = ""
    comments: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        t = np.array(self.time_s, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise ValueError(f"time_s must be 1-D with at least 2 samples, got shape {t.shape}")
        cols = {}
        for name in ("v_bprbs", "v_in", "i_in", "v_out"):
            v = getattr(self, name)
            if v is None:
                if name != "v_out":
                    raise ValueError(f"{name} is required")
                cols[name] = None
                continue
            a = np.array(v, dtype=float)
            if a.shape != t.shape:
                raise ValueError(f"{name} has shape {a.shape}, time_s has {t.shape}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{name} contains NaN or infinite values")
            cols[name] = a
        if not np.all(np.isfinite(t)):
            raise ValueError("time_s contains NaN or infinite values")
        bad = _uniform_violation(t)
        if bad is not None:
            raise ValueError(bad[1])
        self.time_s = t
        for name, a in cols.items():
            setattr(self, name, a)
        self.source = "" if self.source is None else str(self.source)
        self.comments = [str(c) for c in self.comments]

    @property
    def dt(self) -> float:
        """Mean sampling interval in s."""
        return float((self.time_s[-1] - self.time_s[0]) / (self.time_s.size - 1))

    @property
    def fs(self) -> float:
        """Sampling rate in Hz (``1 / dt``)."""
        return 1.0 / self.dt

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)

    def __len__(self) -> int:
        return self.n_samples

    @property
    def names(self) -> list[str]:
        """Column names present, in the order written to CSV."""
        base = ["time_s", "v_bprbs", "v_in", "i_in"]
        return base + (["v_out"] if self.v_out is not None else [])


def _uniform_violation(t: np.ndarray) -> tuple[int, str] | None:
    """Check uniform, strictly increasing sampling.

    Returns ``None`` if fine, else ``(i, reason)`` where sample ``i`` (0-based)
    is the first offending one.
    """
    d = np.diff(t)
    if not np.all(d > 0):
        i = int(np.argmin(d > 0)) + 1
        return i, (
            f"time {_r(t[i])} s does not increase (previous sample {_r(t[i - 1])} s); "
            "time_s must increase strictly"
        )
    dt = (t[-1] - t[0]) / (t.size - 1)
    dev = np.abs(d - dt)
    tol = WAVEFORM_DT_RTOL * dt
    if np.any(dev > tol):
        i = int(np.argmax(dev > tol)) + 1
        return i, (
            f"non-uniform sampling: step {_r(d[i - 1])} s before this sample differs from "
            f"the mean step {_r(dt)} s by more than {WAVEFORM_DT_RTOL:g} relative"
        )
    return None


@dataclass(frozen=True)
class SegmentInfo:
    """One ``<segment>`` of a multi-segment CSV file.

    Attributes
    ----------
    label : str
        Text after ``<segment>`` up to any ``#`` (the segment's name).
    comment : str
        Text after ``#`` on the marker line ('' if none).
    aliases : tuple of str
        Extra lower-case names accepted when selecting the segment: words in
        parentheses in the comment (e.g. ``open``, ``short``).
    line : int
        1-based line number of the marker.
    n_rows : int
        Number of data rows in the segment.
    """

    label: str
    comment: str
    aliases: tuple[str, ...]
    line: int
    n_rows: int


# ---------------------------------------------------------------------------
# Low-level text helpers
# ---------------------------------------------------------------------------

_NUM_RE = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
_NONFINITE_RE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)


def _r(x: float) -> str:
    """repr of a number as a plain Python float (for messages)."""
    return repr(float(x))


def _fmt(x: float) -> str:
    """Shortest text that reads back as exactly the same float."""
    return repr(float(x))


def _read_text_lines(path: PathLike) -> list[str]:
    """Read a text file as a list of lines (line ``i`` is line number ``i+1``).

    Line ends ``\\n`` and ``\\r\\n`` are accepted; a UTF-8 byte-order mark is
    dropped.  Non-UTF-8 or binary content raises :class:`MeasuredDataError`.
    """
    raw = Path(path).read_bytes()
    if b"\x00" in raw:
        line = raw.count(b"\n", 0, raw.index(b"\x00")) + 1
        raise MeasuredDataError(path, "binary content (NUL byte); expected a text file", line)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise MeasuredDataError(path, f"not UTF-8 text ({exc.reason} at byte {exc.start})", line) from None
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def _parse_number(
    path: PathLike, cell: str, line: int, column: int | None, name: str | None
) -> float:
    """Parse one numeric cell strictly (finite decimal numbers only)."""
    s = cell.strip()
    if _NUM_RE.fullmatch(s):
        v = float(s)
        if math.isinf(v):
            raise MeasuredDataError(path, f"value {_show(s)} overflows to infinity", line, column, name)
        return v
    if _NONFINITE_RE.fullmatch(s):
        raise MeasuredDataError(path, f"non-finite value {_show(s)}", line, column, name)
    if not s:
        raise MeasuredDataError(path, "empty cell; expected a number", line, column, name)
    raise MeasuredDataError(path, f"not a number: {_show(s)}", line, column, name)


def _parse_rows(
    path: PathLike,
    rows: Sequence[tuple[int, str]],
    names: Sequence[str],
    sep: str | None = ",",
) -> np.ndarray:
    """Parse data rows into an ``(n, len(names))`` float array.

    Parameters
    ----------
    rows : sequence of (line number, text)
        Data lines, comments already removed.
    names : sequence of str
        Column names, for messages.
    sep : str or None
        Cell separator; None splits on whitespace.
    """
    ncol = len(names)
    out = np.empty((len(rows), ncol), dtype=float)
    for i, (ln, text) in enumerate(rows):
        cells = text.split(sep)
        if len(cells) != ncol:
            raise MeasuredDataError(
                path, f"expected {ncol} columns ({', '.join(names)}), found {len(cells)}", ln
            )
        for j, c in enumerate(cells):
            out[i, j] = _parse_number(path, c, ln, j + 1, names[j])
    return out


#: Frequencies accepted in measured data, Hz.
FREQUENCY_RANGE_HZ = (1e-6, 1e12)
#: Magnitudes accepted for a response value (any unit): outside, the arithmetic of fits overflows.
MAGNITUDE_RANGE = (1e-30, 1e30)
#: Sampling intervals accepted in waveform data, s.
TIME_STEP_RANGE_S = (1e-15, 1e3)


def _responses_in_range(path: PathLike, data: "MeasuredResponses") -> "MeasuredResponses":
    """Refuse frequencies and response magnitudes outside the accepted physical ranges (one line)."""
    lo, hi = FREQUENCY_RANGE_HZ
    f = data.frequency_hz
    bad = np.flatnonzero((f < lo) | (f > hi))
    if bad.size:
        raise MeasuredDataError(path, f"frequency {_r(f[bad[0]])} Hz (point {int(bad[0]) + 1}) is outside the "
                                      f"accepted range {lo:g} .. {hi:g} Hz")
    mlo, mhi = MAGNITUDE_RANGE
    for name, v in data.responses.items():
        mag = np.abs(v)
        bad = np.flatnonzero(~((mag >= mlo) & (mag <= mhi)))
        if bad.size:
            k = int(bad[0])
            raise MeasuredDataError(path, f"response {name!r} at {_r(f[k])} Hz (point {k + 1}): magnitude "
                                          f"{_r(mag[k])} is outside the accepted range {mlo:g} .. {mhi:g}")
    return data


def _waveforms_in_range(path: PathLike, w: "Waveforms") -> "Waveforms":
    """Refuse sampling intervals and values outside the accepted physical ranges (one line)."""
    lo, hi = TIME_STEP_RANGE_S
    if w.time_s.size > 1 and not lo <= w.dt <= hi:
        raise MeasuredDataError(path, f"sampling interval {_r(w.dt)} s is outside the accepted range "
                                      f"{lo:g} .. {hi:g} s", column_name="time_s")
    if np.max(np.abs(w.time_s)) > 1e9:
        raise MeasuredDataError(path, "time_s values beyond 1e9 s", column_name="time_s")
    for name in w.names[1:]:
        v = getattr(w, name)
        big = np.flatnonzero(np.abs(v) > MAGNITUDE_RANGE[1])
        if big.size:
            raise MeasuredDataError(path, f"sample {int(big[0]) + 1}: value {_r(v[big[0]])} beyond "
                                          f"{MAGNITUDE_RANGE[1]:g}", column_name=name)
    return w


def _check_rows_frequency(
    path: PathLike, f: np.ndarray, lines: Sequence[int], col: int = 1, name: str = "frequency_hz"
) -> None:
    """Frequencies > 0 and strictly increasing, with line-numbered errors."""
    for i in range(f.size):
        if not f[i] > 0:
            raise MeasuredDataError(
                path, f"frequency must be > 0 Hz, got {_r(f[i])}", lines[i], col, name
            )
        if i and f[i] <= f[i - 1]:
            if f[i] == f[i - 1]:
                msg = f"duplicated frequency {_r(f[i])} (same as line {lines[i - 1]})"
            else:
                msg = (
                    f"frequency {_r(f[i])} is below the previous {_r(f[i - 1])} (line "
                    f"{lines[i - 1]}); frequencies must increase strictly"
                )
            raise MeasuredDataError(path, msg, lines[i], col, name)


def _check_nonnegative(
    path: PathLike, values: np.ndarray, lines: Sequence[int], col: int, name: str
) -> None:
    neg = np.flatnonzero(values < 0)
    if neg.size:
        i = int(neg[0])
        raise MeasuredDataError(path, f"negative magnitude {_r(values[i])}", lines[i], col, name)


def _check_count(path: PathLike, n: int, line: int, what: str = "data rows") -> None:
    if n < MIN_POINTS:
        raise MeasuredDataError(
            path, f"too few {what}: {n} (need at least {MIN_POINTS})", line
        )


def _polar(mag: np.ndarray, phase_deg: np.ndarray) -> np.ndarray:
    return mag * np.exp(1j * np.radians(phase_deg))


def _strip_comment(text: str, marker: str = "#") -> str:
    i = text.find(marker)
    return text if i < 0 else text[:i]


def _comment_text(line: str, marker: str) -> str:
    s = line.lstrip()[len(marker):]
    return s[1:] if s.startswith(" ") else s


# ---------------------------------------------------------------------------
# Atomic writing
# ---------------------------------------------------------------------------


def _atomic_write(path: PathLike, write: Callable[[IO], None], binary: bool = False) -> None:
    """Write a file atomically.

    ``write(fh)`` fills a temporary file in the target's directory, which is
    then flushed, synced and renamed over ``path`` with :func:`os.replace`.
    On any error the temporary file is removed and ``path`` is untouched.
    An existing target's permission bits are kept.
    """
    target = Path(path)
    directory = target.parent
    tmp = directory / f".{target.name}.{secrets.token_hex(8)}.tmp"
    try:
        if binary:
            fh = open(tmp, "xb")
        else:
            fh = open(tmp, "x", encoding="utf-8", newline="")
        with fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        try:
            mode = stat.S_IMODE(os.stat(target).st_mode)
        except OSError:
            mode = None
        if mode is not None:
            os.chmod(tmp, mode)
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _check_comment_free(text: str, what: str, forbid: str = "") -> None:
    if "\n" in text or "\r" in text:
        raise ValueError(f"{what} {text!r} must not contain line breaks")
    for ch in forbid:
        if ch in text:
            raise ValueError(f"{what} {text!r} must not contain {ch!r}")


def _comment_lines(comments: Iterable[str]) -> list[str]:
    out: list[str] = []
    for c in comments:
        out.extend(str(c).replace("\r\n", "\n").replace("\r", "\n").split("\n"))
    return out


# ---------------------------------------------------------------------------
# Segmented CSV (interfaces format and instrument format)
# ---------------------------------------------------------------------------

_SEGMENT_MARK = "<segment>"
_SUFFIX_RE = re.compile(r"(.+)_(mag|phase_deg|re|im)", re.IGNORECASE)


@dataclass
class _RawSegment:
    label: str | None
    comment: str
    line: int
    comments: list[str] = field(default_factory=list)
    rows: list[tuple[int, str]] = field(default_factory=list)


@dataclass
class _SegmentedFile:
    header_line: int
    header: str
    comments: list[str]
    segments: list[_RawSegment]


def _is_marker(line: str) -> bool:
    return line.lstrip().lower().startswith(_SEGMENT_MARK)


def _split_segmented(path: PathLike, lines: list[str]) -> _SegmentedFile:
    """Split a CSV with optional ``<segment>`` markers into its parts."""
    file_comments: list[str] = []
    header_line = 0
    header = ""
    segments: list[_RawSegment] = []
    current: _RawSegment | None = None
    for idx, line in enumerate(lines):
        ln = idx + 1
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            text = _comment_text(line, "#")
            (current.comments if current is not None else file_comments).append(text)
            continue
        if _is_marker(s):
            if not header_line:
                raise MeasuredDataError(
                    path, "'<segment>' line before the header line", ln
                )
            rest = s[len(_SEGMENT_MARK):]
            label, _, comment = rest.partition("#")
            label = label.strip()
            if not label:
                raise MeasuredDataError(path, "'<segment>' line without a label", ln)
            if current is not None and current.label is None and current.rows:
                raise MeasuredDataError(
                    path,
                    "data rows before the first '<segment>' line",
                    current.rows[0][0],
                )
            current = _RawSegment(label, comment.strip(), ln)
            segments.append(current)
            continue
        if not header_line:
            header_line, header = ln, line
            continue
        if current is None:
            current = _RawSegment(None, "", header_line)
            segments.append(current)
        current.rows.append((ln, _strip_comment(line)))
    if not header_line:
        if not any(ln.strip() for ln in lines):
            raise MeasuredDataError(path, "empty file: no header line", 1)
        raise MeasuredDataError(path, "no header line (only comments)", len(lines))
    if not segments:
        segments.append(_RawSegment(None, "", header_line))
    return _SegmentedFile(header_line, header, file_comments, segments)


def _aliases(comment: str) -> tuple[str, ...]:
    words = []
    for w in re.findall(r"\(([^()]*)\)", comment):
        w = " ".join(w.split()).lower()
        if w and w not in words:
            words.append(w)
    return tuple(words)


_SI = {"f": 1e-15, "p": 1e-12, "n": 1e-9, "u": 1e-6, "µ": 1e-6, "μ": 1e-6, "m": 1e-3,
       "k": 1e3, "meg": 1e6, "g": 1e9, "t": 1e12}


def _label_value(text: str) -> float | None:
    """Numeric value of a label such as ``49.5``, ``49.5R``, ``5 mOhm``, ``5e-3``."""
    s = "".join(text.split()).lower()
    s = re.sub(r"(ohms?|[ωΩ]|r)$", "", s)
    m = re.fullmatch(r"([+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[+-]?\d+)?)(meg|[fpnuµμmkgt])?", s)
    if not m:
        return None
    v = float(m.group(1))
    if m.group(2):
        v *= _SI[m.group(2)]
    return v


def _describe_segments(segs: Sequence[_RawSegment]) -> str:
    parts = []
    for s in segs:
        al = _aliases(s.comment)
        parts.append(repr(s.label) + (f" ({', '.join(al)})" if al else ""))
    return "; ".join(parts)


def _select_segment(
    path: PathLike, segs: list[_RawSegment], selector: str | int | None
) -> _RawSegment:
    named = [s for s in segs if s.label is not None]
    if selector is None:
        if len(segs) == 1:
            return segs[0]
        raise MeasuredDataError(
            path,
            f"{len(segs)} segments; choose one with segment=...: {_describe_segments(segs)}",
        )
    if not named:
        raise MeasuredDataError(path, f"no '<segment>' lines; cannot select segment {selector!r}")
    if isinstance(selector, (int, np.integer)) and not isinstance(selector, bool):
        i = int(selector)
        if not -len(named) <= i < len(named):
            raise MeasuredDataError(path, f"segment index {i} out of range (file has {len(named)})")
        return named[i]
    sel = str(selector)
    key = "".join(sel.split()).lower()
    stages: list[list[_RawSegment]] = [
        [s for s in named if "".join(s.label.split()).lower() == key],
        [s for s in named if " ".join(sel.split()).lower() in _aliases(s.comment)],
    ]
    val = _label_value(sel)
    if val is not None:
        stages.append(
            [
                s
                for s in named
                if (lv := _label_value(s.label)) is not None
                and math.isclose(lv, val, rel_tol=1e-12, abs_tol=0.0)
            ]
        )
    for found in stages:
        if len(found) == 1:
            return found[0]
        if len(found) > 1:
            raise MeasuredDataError(
                path, f"segment {sel!r} is ambiguous: {_describe_segments(found)}"
            )
    raise MeasuredDataError(
        path, f"no segment {sel!r}; available: {_describe_segments(named)}"
    )


def _header_cells(header: str) -> list[str]:
    return [c.strip() for c in _strip_comment(header).split(",")]


def _interfaces_columns(
    path: PathLike, line: int, cells: list[str]
) -> list[tuple[str, str, int, int]]:
    """Map an interfaces-format header to ``[(name, form, col_a, col_b)]``."""
    if cells[0].lower() != "frequency_hz":
        raise MeasuredDataError(
            path, "first column must be 'frequency_hz'", line, 1, cells[0]
        )
    seen: dict[str, int] = {}
    pairs: dict[str, dict[str, int]] = {}
    order: list[str] = []
    for j, c in enumerate(cells[1:], start=1):
        if not c:
            raise MeasuredDataError(path, "empty column name", line, j + 1)
        if c in seen:
            raise MeasuredDataError(
                path, f"duplicated column (also column {seen[c] + 1})", line, j + 1, c
            )
        seen[c] = j
        m = _SUFFIX_RE.fullmatch(c)
        if not m:
            raise MeasuredDataError(
                path,
                "unknown column; expected NAME_mag + NAME_phase_deg or NAME_re + NAME_im",
                line, j + 1, c,
            )
        name, kind = m.group(1), m.group(2).lower()
        if c.lower() == "frequency_hz" or name.lower() == "frequency":
            raise MeasuredDataError(path, "frequency column must be first", line, j + 1, c)
        slot = pairs.setdefault(name, {})
        if name not in order:
            order.append(name)
        if kind in slot:
            raise MeasuredDataError(
                path, f"second '{kind}' column for response {name!r}", line, j + 1, c
            )
        slot[kind] = j
    if not order:
        raise MeasuredDataError(path, "no response columns after 'frequency_hz'", line)
    out = []
    partner = {"mag": "phase_deg", "phase_deg": "mag", "re": "im", "im": "re"}
    for name in order:
        slot = pairs[name]
        kinds = set(slot)
        if kinds == {"mag", "phase_deg"}:
            out.append((name, "magphase", slot["mag"], slot["phase_deg"]))
        elif kinds == {"re", "im"}:
            out.append((name, "reim", slot["re"], slot["im"]))
        else:
            polar, cart = kinds & {"mag", "phase_deg"}, kinds & {"re", "im"}
            if polar and cart:
                j = max(slot.values())
                raise MeasuredDataError(
                    path,
                    f"response {name!r} mixes mag/phase and re/im columns",
                    line, j + 1, cells[j],
                )
            (kind,) = kinds
            j = slot[kind]
            raise MeasuredDataError(
                path,
                f"no matching column '{name}_{partner[kind]}'",
                line, j + 1, cells[j],
            )
    return out


_UNIT_SCALE = {"hz": 1.0, "khz": 1e3, "mhz": 1e6, "ghz": 1e9}


def _split_unit(cell: str) -> tuple[str, str]:
    """``'FREQUENCY [Hz]'`` -> ``('frequency', 'hz')``; also ``(unit)``."""
    m = re.fullmatch(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*(?:-\s*\w+)?", cell.strip())
    if m:
        return m.group(1).strip().lower(), m.group(2).strip().lower()
    return cell.strip().lower(), ""


def _instrument_columns(
    path: PathLike, line: int, cells: list[str]
) -> tuple[float, str, float]:
    """Interpret ``FREQUENCY [Hz],MAG [O],PHASE [deg]`` style headers.

    Returns ``(freq_scale, form, phase_scale_to_deg)``.
    """
    if len(cells) != 3:
        raise MeasuredDataError(
            path, f"expected 3 columns (frequency, magnitude, phase), found {len(cells)}", line
        )
    fname, funit = _split_unit(cells[0])
    if not fname.startswith("freq"):
        raise MeasuredDataError(path, "first column must be the frequency", line, 1, cells[0])
    if funit and funit not in _UNIT_SCALE:
        raise MeasuredDataError(path, f"unknown frequency unit {funit!r}", line, 1, cells[0])
    fscale = _UNIT_SCALE.get(funit or "hz")
    a, _ = _split_unit(cells[1])
    b, bunit = _split_unit(cells[2])
    if a in ("mag", "magnitude", "|z|", "abs") and (b.startswith("phase") or b.startswith("theta")):
        if bunit in ("", "deg", "degree", "degrees", "°"):
            return fscale, "magphase", 1.0
        if bunit in ("rad", "radian", "radians"):
            return fscale, "magphase", 180.0 / math.pi
        raise MeasuredDataError(path, f"unknown phase unit {bunit!r}", line, 3, cells[2])
    if a in ("re", "real") and b in ("im", "imag", "imaginary"):
        return fscale, "reim", 1.0
    raise MeasuredDataError(
        path,
        "unsupported columns; expected magnitude + phase or real + imaginary",
        line, 2, cells[1],
    )


def _read_segmented(
    path: PathLike, segment: str | int | None, mode: str, name: str = "Zin"
) -> MeasuredResponses:
    lines = _read_text_lines(path)
    sf = _split_segmented(path, lines)
    cells = _header_cells(sf.header)
    is_interfaces = cells[0].lower() == "frequency_hz"
    if mode == "interfaces" and not is_interfaces:
        raise MeasuredDataError(
            path, "first column must be 'frequency_hz'", sf.header_line, 1, cells[0]
        )
    seg = _select_segment(path, sf.segments, segment)
    rows = seg.rows
    last_line = rows[-1][0] if rows else seg.line
    if is_interfaces:
        cols = _interfaces_columns(path, sf.header_line, cells)
        data = _parse_rows(path, rows, cells)
        _check_count(path, data.shape[0], last_line)
        lines_no = [r[0] for r in rows]
        f = data[:, 0]
        _check_rows_frequency(path, f, lines_no, 1, cells[0])
        responses = {}
        for rname, form, ja, jb in cols:
            if form == "magphase":
                _check_nonnegative(path, data[:, ja], lines_no, ja + 1, cells[ja])
                responses[rname] = _polar(data[:, ja], data[:, jb])
            else:
                responses[rname] = data[:, ja] + 1j * data[:, jb]
    else:
        fscale, form, pscale = _instrument_columns(path, sf.header_line, cells)
        data = _parse_rows(path, rows, cells)
        _check_count(path, data.shape[0], last_line)
        lines_no = [r[0] for r in rows]
        with np.errstate(over="ignore"):  # an overflow to inf is refused by the range check
            f = data[:, 0] * fscale
        _check_rows_frequency(path, f, lines_no, 1, cells[0])
        if form == "magphase":
            _check_nonnegative(path, data[:, 1], lines_no, 2, cells[1])
            responses = {name: _polar(data[:, 1], data[:, 2] * pscale)}
        else:
            responses = {name: data[:, 1] + 1j * data[:, 2]}
    comments = list(sf.comments)
    if seg.comment:
        comments.append(seg.comment)
    comments.extend(seg.comments)
    return _responses_in_range(path, MeasuredResponses(f, responses, source=os.fspath(path), comments=comments, segment=seg.label))


def read_response_csv(path: PathLike, segment: str | int | None = None) -> MeasuredResponses:
    """Read a frequency-response CSV in the interfaces format.

    Parameters
    ----------
    path : str or os.PathLike
        CSV file: ``#`` comment lines, header ``frequency_hz,`` followed by
        ``NAME_mag,NAME_phase_deg`` (magnitude, phase in degrees) and/or
        ``NAME_re,NAME_im`` column pairs, then rows of numbers.  Frequencies in
        Hz, > 0, strictly increasing, at least 2 rows.  Optional
        ``<segment> LABEL # comment`` lines after the header split the rows
        into segments.  Trailing ``# ...`` text on a data row is ignored.
    segment : str or int, optional
        Segment to read: its label (case and spaces ignored), a word in
        parentheses in its marker comment, a numeric value equal to a numeric
        label (``49.5R`` matches ``49.5``), or a 0-based index.  Required
        when the file has more than one segment.

    Returns
    -------
    MeasuredResponses
        Complex responses; ``comments`` holds the file's comment lines
        (then the segment's marker comment and comment lines).

    Raises
    ------
    MeasuredDataError
        Empty file, bad header (missing/unknown/unpaired/duplicated columns),
        wrong number of cells in a row, non-numeric, NaN or infinite cells,
        negative magnitudes, frequencies not > 0 or not strictly increasing,
        fewer than 2 rows, unknown segment.
    """
    return _read_segmented(path, segment, "interfaces")


def read_multisegment_csv(
    path: PathLike, segment: str | int | None = None, name: str = "Zin"
) -> MeasuredResponses:
    """Read one segment of a multi-segment CSV.

    The file has a header ``FREQUENCY [Hz],MAG [O],PHASE [deg]`` (frequency
    unit Hz/kHz/MHz/GHz; phase in deg or rad; ``RE``/``IM`` columns also
    accepted) or an interfaces-format header, and segments introduced by
    ``<segment> LABEL # comment`` lines, e.g. ``small_transformer_3_loads.csv``
    whose labels are ``1/(j*w*.2e-12)`` (comment "(open)"), ``5e-3``
    ("(short)") and ``49.5`` ("(measured)").

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    segment : str or int, optional
        Label, alias or index as for :func:`read_response_csv`; e.g. ``"open"``,
        ``"short"``, ``"49.5"`` or ``"49.5R"`` for the real file.  Required
        when there is more than one segment.
    name : str, optional
        Response name for instrument-style headers (default ``"Zin"``).

    Returns
    -------
    MeasuredResponses
        With ``segment`` set to the segment label and the marker comment as
        the last comment.
    """
    return _read_segmented(path, segment, "any", name)


def segment_info(path: PathLike) -> list[SegmentInfo]:
    """Describe the ``<segment>`` parts of a CSV file (empty if none)."""
    lines = _read_text_lines(path)
    sf = _split_segmented(path, lines)
    return [
        SegmentInfo(s.label, s.comment, _aliases(s.comment), s.line, len(s.rows))
        for s in sf.segments
        if s.label is not None
    ]


def list_segments(path: PathLike) -> list[str]:
    """Labels of the segments of a multi-segment CSV, in file order.

    For ``small_transformer_3_loads.csv`` this is
    ``['1/(j*w*.2e-12)', '5e-3', '49.5']``; see :func:`segment_info` for the
    aliases (``open``, ``short``, ``measured``).
    """
    return [s.label for s in segment_info(path)]


def _as_segments(data: MeasuredResponses | Sequence[MeasuredResponses]) -> list[MeasuredResponses]:
    if isinstance(data, MeasuredResponses):
        return [data]
    segs = list(data)
    if not segs:
        raise ValueError("no data to write")
    for s in segs:
        if not isinstance(s, MeasuredResponses):
            raise TypeError(f"expected MeasuredResponses, got {type(s).__name__}")
    if len(segs) > 1:
        labels = [s.segment for s in segs]
        if any(lb is None for lb in labels):
            raise ValueError("every segment needs a .segment label to write several segments")
        keys = ["".join(str(lb).split()).lower() for lb in labels]
        if len(set(keys)) != len(keys):
            raise ValueError(f"segment labels are not unique: {labels}")
    return segs


def _check_label(label: str) -> str:
    lab = str(label)
    _check_comment_free(lab, "segment label", "#")
    if lab != lab.strip() or not lab:
        raise ValueError(f"segment label {lab!r} must be non-empty without outer spaces")
    return lab


def write_response_csv(
    path: PathLike,
    data: MeasuredResponses | Sequence[MeasuredResponses],
    form: str = "magphase",
) -> None:
    """Write responses in the interfaces CSV format, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Target file (replaced atomically).
    data : MeasuredResponses or sequence of MeasuredResponses
        One data set, or several segments (each with a ``segment`` label and
        the same response names), written with ``<segment> LABEL`` lines.
        A single data set with a ``segment`` label also gets its marker.
    form : {"magphase", "reim"}
        ``NAME_mag,NAME_phase_deg`` (magnitude, degrees) or
        ``NAME_re,NAME_im`` columns.

    Notes
    -----
    Comments are written as ``# `` lines (a single data set's before the
    header, each segment's after its marker).  Numbers use the shortest
    round-trip representation, so ``reim`` round trips are exact and
    ``magphase`` ones are exact to a few units in the last place.
    """
    if form not in ("magphase", "reim"):
        raise ValueError(f"form must be 'magphase' or 'reim', got {form!r}")
    segs = _as_segments(data)
    names = segs[0].names
    for s in segs[1:]:
        if s.names != names:
            raise ValueError(f"segments have different responses: {names} vs {s.names}")
    for n in names:
        _check_comment_free(n, "response name", ",#")
        if n != n.strip():
            raise ValueError(f"response name {n!r} has outer spaces")
    header = ["frequency_hz"]
    for n in names:
        header += [f"{n}_mag", f"{n}_phase_deg"] if form == "magphase" else [f"{n}_re", f"{n}_im"]
    single = len(segs) == 1

    def write(fh: IO) -> None:
        if single:
            for c in _comment_lines(segs[0].comments):
                fh.write(f"# {c}\n")
        fh.write(",".join(header) + "\n")
        for s in segs:
            if s.segment is not None:
                fh.write(f"{_SEGMENT_MARK} {_check_label(s.segment)}\n")
            if not single:
                for c in _comment_lines(s.comments):
                    fh.write(f"# {c}\n")
            cols = [s.frequency_hz.tolist()]
            for n in names:
                z = s.responses[n]
                if form == "magphase":
                    cols += [np.abs(z).tolist(), np.degrees(np.angle(z)).tolist()]
                else:
                    cols += [z.real.tolist(), z.imag.tolist()]
            for row in zip(*cols):
                fh.write(",".join([_fmt(v) for v in row]) + "\n")

    _atomic_write(path, write)


def write_multisegment_csv(
    path: PathLike,
    data: MeasuredResponses | Sequence[MeasuredResponses],
    name: str | None = None,
) -> None:
    """Write segments in the instrument multi-segment CSV format, atomically.

    Header ``FREQUENCY [Hz],MAG [O],PHASE [deg]``, then for each segment a line
    ``<segment> LABEL # comment`` (comment = the segment's comments joined by
    ``"; "``) and its rows.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : MeasuredResponses or sequence of MeasuredResponses
        Segments, each with a ``segment`` label.
    name : str, optional
        Response to write; default the only response of each segment.
    """
    segs = _as_segments(data)

    def pick(s: MeasuredResponses) -> np.ndarray:
        if name is not None:
            return s.response(name)
        if len(s.names) != 1:
            raise ValueError(f"segment has responses {s.names}; pass name=...")
        return s.responses[s.names[0]]

    zs = [pick(s) for s in segs]
    for s in segs:
        if s.segment is None:
            raise ValueError("every segment needs a .segment label")

    def write(fh: IO) -> None:
        fh.write("FREQUENCY [Hz],MAG [O],PHASE [deg]\n")
        for s, z in zip(segs, zs):
            comment = "; ".join(_comment_lines(s.comments))
            marker = f"{_SEGMENT_MARK} {_check_label(s.segment)}"
            fh.write(marker + (f"     # {comment}" if comment else "") + "\n")
            for row in zip(s.frequency_hz.tolist(), np.abs(z).tolist(),
                           np.degrees(np.angle(z)).tolist()):
                fh.write(",".join([_fmt(v) for v in row]) + "\n")

    _atomic_write(path, write)


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
# Touchstone (read and written by scikit-rf in pris_cosim.touchstone)
# ---------------------------------------------------------------------------

_TWO_PORT_NAMES = ("Z11", "Z12", "Z21", "Z22")
_TS_EXT = re.compile(r"\.[a-z](\d+)p", re.IGNORECASE)  # as pris_cosim.touchstone.EXTENSION_RE


def read_touchstone_z(path: PathLike, name: str = "Zin") -> MeasuredResponses:
    """Read a 1-port or 2-port Touchstone file as Z-parameters in Ohm.

    The file is read by scikit-rf through :func:`pris_cosim.touchstone.read_touchstone`
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
    from .touchstone import read_touchstone

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
    from .touchstone import write_touchstone

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


# ---------------------------------------------------------------------------
# Waveform CSV
# ---------------------------------------------------------------------------

_WAVE_REQUIRED = ("time_s", "v_bprbs", "v_in", "i_in")
_WAVE_OPTIONAL = ("v_out",)


def read_waveform_csv(path: PathLike) -> Waveforms:
    """Read a waveform CSV ``time_s,v_bprbs,v_in,i_in[,v_out]``.

    Parameters
    ----------
    path : str or os.PathLike
        CSV with ``#`` comment lines, a header naming the columns (any order,
        ``v_out`` optional, no others) and numeric rows in SI units
        (s, V, A).  Sampling must be uniform: every step within 1e-6
        (relative) of the mean step.

    Returns
    -------
    Waveforms

    Raises
    ------
    MeasuredDataError
        Empty file, bad header, bad rows (column count, non-numeric, NaN,
        inf), time not strictly increasing or not uniform, < 2 samples.
    """
    lines = _read_text_lines(path)
    comments: list[str] = []
    header_idx = None
    for idx, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            comments.append(_comment_text(line, "#"))
            continue
        header_idx = idx
        break
    if header_idx is None:
        if not any(ln.strip() for ln in lines):
            raise MeasuredDataError(path, "empty file: no header line", 1)
        raise MeasuredDataError(path, "no header line (only comments)", len(lines))
    hline = header_idx + 1
    cells = _header_cells(lines[header_idx])
    seen: dict[str, int] = {}
    for j, c in enumerate(cells):
        if c not in _WAVE_REQUIRED + _WAVE_OPTIONAL:
            raise MeasuredDataError(
                path, "unknown column; expected time_s, v_bprbs, v_in, i_in [, v_out]", hline, j + 1, c
            )
        if c in seen:
            raise MeasuredDataError(path, f"duplicated column (also column {seen[c] + 1})", hline, j + 1, c)
        seen[c] = j
    missing = [c for c in _WAVE_REQUIRED if c not in seen]
    if missing:
        raise MeasuredDataError(path, f"missing column(s): {', '.join(missing)}", hline)
    body = lines[header_idx + 1:]
    data = None
    try:  # fast path for large files; the strict parser below finds errors
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            arr = np.loadtxt(body, delimiter=",", comments="#", ndmin=2, dtype=float)
        if arr.shape[1] == len(cells) and arr.shape[0] >= MIN_POINTS and np.all(np.isfinite(arr)):
            data = arr
    except (ValueError, UserWarning, TypeError):
        data = None
    rows_cache: list[tuple[int, str]] | None = None

    def rows() -> list[tuple[int, str]]:
        nonlocal rows_cache
        if rows_cache is None:
            rows_cache = []
            for k, line in enumerate(body):
                s = _strip_comment(line)
                if s.strip():
                    rows_cache.append((hline + 1 + k, s))
        return rows_cache

    if data is None:
        data = _parse_rows(path, rows(), cells)
        last = rows()[-1][0] if rows() else hline
        _check_count(path, data.shape[0], last, "samples")
    t = data[:, seen["time_s"]]
    bad = _uniform_violation(t)
    if bad is not None:
        i, reason = bad
        raise MeasuredDataError(path, reason, rows()[i][0], seen["time_s"] + 1, "time_s")
    col = {c: data[:, j].copy() for c, j in seen.items()}
    return _waveforms_in_range(path, Waveforms(
        col["time_s"], col["v_bprbs"], col["v_in"], col["i_in"], col.get("v_out"),
        source=os.fspath(path), comments=comments,
    ))


def write_waveform_csv(
    path: PathLike,
    data: Waveforms | np.ndarray | Sequence[float],
    v_bprbs: np.ndarray | None = None,
    v_in: np.ndarray | None = None,
    i_in: np.ndarray | None = None,
    v_out: np.ndarray | None = None,
    comments: Sequence[str] | None = None,
) -> None:
    """Write a waveform CSV ``time_s,v_bprbs,v_in,i_in[,v_out]``, atomically.

    Call either ``write_waveform_csv(path, waveforms)`` or
    ``write_waveform_csv(path, time_s, v_bprbs, v_in, i_in[, v_out])``.

    Parameters
    ----------
    path : str or os.PathLike
        Target file.
    data : Waveforms or array_like
        A :class:`Waveforms`, or the sample times in s.
    v_bprbs, v_in, i_in, v_out : array_like, optional
        Columns in V, V, A, V when ``data`` is the time vector.
    comments : sequence of str, optional
        Comment lines (default: those of a :class:`Waveforms`).

    Raises
    ------
    ValueError
        Inconsistent or non-uniform data (checked by :class:`Waveforms`).
    """
    if isinstance(data, Waveforms):
        if any(x is not None for x in (v_bprbs, v_in, i_in, v_out)):
            raise TypeError("pass either a Waveforms object or the separate arrays, not both")
        w = data
    else:
        w = Waveforms(data, v_bprbs, v_in, i_in, v_out)  # type: ignore[arg-type]
    com = _comment_lines(w.comments if comments is None else comments)
    names = w.names
    cols = [getattr(w, n).tolist() for n in names]

    def write(fh: IO) -> None:
        for c in com:
            fh.write(f"# {c}\n")
        fh.write(",".join(names) + "\n")
        fmt = _fmt
        for row in zip(*cols):
            fh.write(",".join([fmt(v) for v in row]) + "\n")

    _atomic_write(path, write)


# ---------------------------------------------------------------------------
# Dispatch
# ---------------------------------------------------------------------------


def detect_format(path: PathLike) -> str:
    """Guess a file's format from its extension and first lines.

    Returns
    -------
    str
        One of ``"mat"``, ``"touchstone"``, ``"e4990a"``, ``"response_csv"``,
        ``"multisegment_csv"``, ``"waveform_csv"``, ``"mag_phase_rows"``.

    Raises
    ------
    MeasuredDataError
        If the format cannot be recognised (including empty files).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".mat":
        return "mat"
    if _TS_EXT.fullmatch(ext) or ext == ".ts":
        return "touchstone"
    lines = _read_text_lines(p)
    first = None
    for idx, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("!"):
            if any(x.strip().upper().startswith("BEGIN") for x in lines):
                return "e4990a"
            if ext != ".csv":
                return "touchstone"
            continue
        if s.upper().startswith("BEGIN"):
            return "e4990a"
        if s.startswith("#"):
            if ext != ".csv" and re.match(r"#\s*(hz|khz|mhz|ghz|s|y|z|ma|db|ri)\b", s, re.I):
                return "touchstone"
            continue
        first = (idx + 1, s)
        break
    if first is None:
        if not any(x.strip() for x in lines):
            raise MeasuredDataError(p, "empty file: no header line", 1)
        raise MeasuredDataError(p, "no header line (only comments)", len(lines))
    ln, s = first
    cell0 = _strip_comment(s).split(",")[0].strip().lower()
    if cell0 == "frequency_hz":
        return "response_csv"
    if cell0 == "time_s":
        return "waveform_csv"
    if cell0.startswith("freq"):
        others = _header_cells(s)[1:]
        if any(_SUFFIX_RE.fullmatch(c) for c in others):
            return "response_csv"  # interfaces layout with a wrong first column
        return "multisegment_csv"
    toks = s.split()
    if len(toks) == 2 and all(_NUM_RE.fullmatch(t) or _NONFINITE_RE.fullmatch(t) for t in toks):
        return "mag_phase_rows"
    raise MeasuredDataError(p, f"unrecognised format; first line {_show(s)}", ln)


def load_measured(
    path: PathLike, segment: str | int | None = None
) -> MeasuredResponses | Waveforms:
    """Load measured data of any supported format.

    Parameters
    ----------
    path : str or os.PathLike
        ``.mat`` -> :func:`read_mat`; ``.s1p``/``.s2p``/``.?Np``/``.ts`` ->
        :func:`read_touchstone_z`; otherwise by content: ``!``/``BEGIN`` ->
        :func:`read_e4990a`; header ``frequency_hz,...`` ->
        :func:`read_response_csv`; ``time_s,...`` -> :func:`read_waveform_csv`;
        ``FREQUENCY [Hz],...`` -> :func:`read_multisegment_csv`; two numbers
        per line -> :func:`read_mag_phase_rows` (25 kHz step, ``Yin``).
    segment : str or int, optional
        Segment of a segmented CSV (see :func:`read_response_csv`).

    Returns
    -------
    MeasuredResponses or Waveforms
        Waveforms for waveform CSVs, frequency responses otherwise.

    Raises
    ------
    MeasuredDataError
        Unrecognised or malformed file, or ``segment`` given for a format
        without segments.
    """
    kind = detect_format(path)
    if kind == "response_csv":
        return read_response_csv(path, segment)
    if kind == "multisegment_csv":
        return read_multisegment_csv(path, segment)
    if segment is not None:
        raise MeasuredDataError(path, f"segment {segment!r} given but a {kind} file has no segments")
    if kind == "mat":
        return read_mat(path)
    if kind == "touchstone":
        return read_touchstone_z(path)
    if kind == "e4990a":
        return read_e4990a(path)
    if kind == "waveform_csv":
        return read_waveform_csv(path)
    return read_mag_phase_rows(path)
