"""Waveform CSV: time-domain records ``time_s,v_bprbs,v_in,i_in[,v_out]``.

Holds :func:`read_waveform_csv` and :func:`write_waveform_csv`, which read
and write a :class:`~pris_cosim.measured.core.Waveforms` record uniformly
sampled in SI units (time in s, voltages in V, current in A).
"""

from __future__ import annotations

import os
import warnings
from typing import IO, Sequence

import numpy as np

from pris_cosim.measured.core import (MIN_POINTS, MeasuredDataError, PathLike, Waveforms, _atomic_write,
    _check_count, _comment_lines, _comment_text, _fmt, _header_cells, _parse_rows, _read_text_lines, _strip_comment,
    _uniform_violation, _waveforms_in_range)

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
