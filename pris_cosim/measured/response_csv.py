"""Segmented response CSV: the interfaces format and the multi-segment instrument export.

Holds :func:`read_response_csv`, :func:`write_response_csv`,
:func:`read_multisegment_csv`, :func:`write_multisegment_csv`,
:func:`segment_info` and :func:`list_segments` with their private helpers
(splitting a file at its ``<segment>`` markers, choosing a segment, mapping
the header columns). Frequencies are in Hz; the files are described in
:mod:`pris_cosim.measured.formats`.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import IO, Sequence

import numpy as np

from pris_cosim.measured.core import (_SD_SUFFIX_RE, _SUFFIX_RE, _UNIT_SCALE, MeasuredDataError, MeasuredResponses,
    PathLike, SegmentInfo, _atomic_write, _check_comment_free, _check_count, _check_nonnegative,
    _check_rows_frequency, _comment_lines, _comment_text, _fmt, _header_cells, _parse_rows, _polar, _read_text_lines,
    _responses_in_range, _split_unit, _strip_comment)

# ---------------------------------------------------------------------------
# Segmented CSV (interfaces format and instrument format)
# ---------------------------------------------------------------------------

_SEGMENT_MARK = "<segment>"


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


def _sd_columns(path: PathLike, line: int, cells: list[str], names: Sequence[str]) -> dict[str, int]:
    """The optional ``NAME_ln_sd`` columns of an interfaces-format header: ``{name: column}``."""
    out: dict[str, int] = {}
    for j, c in enumerate(cells[1:], start=1):
        m = _SD_SUFFIX_RE.fullmatch(c)
        if m is None:
            continue
        if m.group(1) not in names:
            raise MeasuredDataError(path, f"uncertainty column of no response (responses: {', '.join(names)})",
                                    line, j + 1, c)
        out[m.group(1)] = j
    return out


def _interfaces_columns(
    path: PathLike, line: int, cells: list[str]
) -> list[tuple[str, str, int, int]]:
    """Map an interfaces-format header to ``[(name, form, col_a, col_b)]`` (``NAME_ln_sd`` columns skipped)."""
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
        if _SD_SUFFIX_RE.fullmatch(c):
            continue
        m = _SUFFIX_RE.fullmatch(c)
        if not m:
            raise MeasuredDataError(
                path,
                "unknown column; expected NAME_mag + NAME_phase_deg or NAME_re + NAME_im (and optional NAME_ln_sd)",
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
        uncertainty = {}
        for rname, j in _sd_columns(path, sf.header_line, cells, [c[0] for c in cols]).items():
            bad = np.flatnonzero(~(data[:, j] > 0))
            if bad.size:
                raise MeasuredDataError(path, "uncertainty must be > 0", lines_no[int(bad[0])], j + 1, cells[j])
            uncertainty[rname] = data[:, j]
    else:
        uncertainty = {}
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
    return _responses_in_range(path, MeasuredResponses(f, responses, source=os.fspath(path), comments=comments,
                                                       segment=seg.label, uncertainty=uncertainty))


def read_response_csv(path: PathLike, segment: str | int | None = None) -> MeasuredResponses:
    """Read a frequency-response CSV in the interfaces format.

    Parameters
    ----------
    path : str or os.PathLike
        CSV file: ``#`` comment lines, header ``frequency_hz,`` followed by
        ``NAME_mag,NAME_phase_deg`` (magnitude, phase in degrees) and/or
        ``NAME_re,NAME_im`` column pairs, each optionally with a ``NAME_ln_sd``
        column (standard deviation of ``ln|H|`` and of the phase in radians,
        > 0; in :attr:`MeasuredResponses.uncertainty`), then rows of numbers.  Frequencies in
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
        ``NAME_re,NAME_im`` columns; a response with an uncertainty (in every
        segment) also gets its ``NAME_ln_sd`` column.

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
    with_sd = [n for n in names if all(n in s.uncertainty for s in segs)]
    for n in names:
        header += [f"{n}_mag", f"{n}_phase_deg"] if form == "magphase" else [f"{n}_re", f"{n}_im"]
        header += [f"{n}_ln_sd"] if n in with_sd else []
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
                if n in with_sd:
                    cols.append(s.uncertainty[n].tolist())
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
