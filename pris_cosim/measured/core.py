"""Measured-data containers and the parsing helpers every reader and writer shares.

Holds :class:`MeasuredDataError` (the one-line error of every reader),
:class:`MeasuredResponses` (frequency responses), :class:`Waveforms`
(time-domain records) and :class:`SegmentInfo`, the accepted physical ranges
(frequency in Hz, magnitude, sampling interval in s), and the low-level
helpers of the format modules: reading text lines, parsing numbers and rows,
range and count checks, comment handling, header cells and units, and the
atomic write. The formats themselves live in
:mod:`pris_cosim.measured.response_csv`, :mod:`pris_cosim.measured.instruments`
and :mod:`pris_cosim.measured.waveform_csv`; :mod:`pris_cosim.measured.formats` is
the public entry point.
"""

from __future__ import annotations

import math
import os
import re
import secrets
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Callable, Iterable, Sequence, Union

import numpy as np

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
    uncertainty : dict of str to numpy.ndarray, optional
        Standard deviation of ``ln|H|`` (and of the phase in radians) at each
        frequency, per response (a subset of ``responses``; dimensionless,
        0.01 is 1 % / 0.57 deg), e.g. from the coherence of an H1 estimate.
        Empty when the data do not say.

    Raises
    ------
    ValueError
        If the arrays are inconsistent (shape, non-finite values, frequency
        order, an uncertainty not positive or of an unknown response).
    """

    frequency_hz: np.ndarray
    responses: dict[str, np.ndarray]
    source: str = ""
    comments: list[str] = field(default_factory=list)
    segment: str | None = None
    uncertainty: dict[str, np.ndarray] = field(default_factory=dict)

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
        unc: dict[str, np.ndarray] = {}
        for name, values in dict(self.uncertainty or {}).items():
            if name not in resp:
                raise ValueError(f"uncertainty of {name!r}, which is not a response ({', '.join(resp)})")
            u = np.array(values, dtype=float)
            if u.shape != f.shape or not np.all(np.isfinite(u) & (u > 0)):
                raise ValueError(f"uncertainty of {name!r} must hold one finite positive value per frequency")
            unc[name] = u
        self.frequency_hz = f
        self.responses = resp
        self.uncertainty = unc
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
            uncertainty={k: v[keep].copy() for k, v in self.uncertainty.items()},
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
# Header cells (shared by the CSV readers)
# ---------------------------------------------------------------------------

_SUFFIX_RE = re.compile(r"(.+)_(mag|phase_deg|re|im)", re.IGNORECASE)
#: Optional uncertainty column of a response in the interfaces CSV: ``NAME_ln_sd``.
_SD_SUFFIX_RE = re.compile(r"(.+)_ln_sd", re.IGNORECASE)


def _header_cells(header: str) -> list[str]:
    return [c.strip() for c in _strip_comment(header).split(",")]


_UNIT_SCALE = {"hz": 1.0, "khz": 1e3, "mhz": 1e6, "ghz": 1e9}


def _split_unit(cell: str) -> tuple[str, str]:
    """``'FREQUENCY [Hz]'`` -> ``('frequency', 'hz')``; also ``(unit)``."""
    m = re.fullmatch(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]\s*(?:-\s*\w+)?", cell.strip())
    if m:
        return m.group(1).strip().lower(), m.group(2).strip().lower()
    return cell.strip().lower(), ""
