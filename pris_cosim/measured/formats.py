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
    A response may have a third, optional column ``NAME_ln_sd``: the
    standard deviation of ``ln|H|`` (equally, of the phase in radians) at
    each frequency, > 0 (the virtual lab writes it from the coherence);
    files without it read as before. Optionally the rows are split into
    segments by lines ``<segment> LABEL # comment`` after the header.
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
    :mod:`pris_cosim.measured.touchstone` (which also reads any port count, S/Y/Z,
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

The containers and shared helpers live in :mod:`pris_cosim.measured.core`,
the formats in :mod:`pris_cosim.measured.response_csv`,
:mod:`pris_cosim.measured.instruments` and
:mod:`pris_cosim.measured.waveform_csv`; this module re-exports them all.
"""

from __future__ import annotations

import re
from pathlib import Path

from pris_cosim.measured.core import (_NONFINITE_RE, _NUM_RE, _SUFFIX_RE, MeasuredDataError, MeasuredResponses,
    PathLike, SegmentInfo, Waveforms, _header_cells, _read_text_lines, _show, _strip_comment)
from pris_cosim.measured.core import FREQUENCY_RANGE_HZ
from pris_cosim.measured.core import MAGNITUDE_RANGE
from pris_cosim.measured.core import MIN_POINTS
from pris_cosim.measured.core import TIME_STEP_RANGE_S
from pris_cosim.measured.core import WAVEFORM_DT_RTOL
from pris_cosim.measured.core import _atomic_write
from pris_cosim.measured.core import _fmt
from pris_cosim.measured.instruments import (_TS_EXT, read_e4990a, read_mag_phase_rows, read_mat, read_touchstone_z,
    write_e4990a, write_mag_phase_rows, write_mat, write_touchstone_z)
from pris_cosim.measured.response_csv import (list_segments, read_multisegment_csv, read_response_csv, segment_info,
    write_multisegment_csv, write_response_csv)
from pris_cosim.measured.waveform_csv import read_waveform_csv, write_waveform_csv

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
