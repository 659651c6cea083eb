"""Waveform records written as ``.csv``, ``.npz`` or ``.mat`` (by extension), piece by piece.

Every format holds the same columns under the same names: ``time_s`` (s),
``v_bprbs`` (V), ``v_in`` (V), ``i_in`` (A) and optionally ``v_out`` (V),
as 1-D float64 arrays (``.mat``: N x 1 columns, MATLAB v5 through
:func:`scipy.io.savemat`), plus ``comments`` (the CSV's ``#`` lines: an
array of strings in ``.npz``, a cell array in ``.mat``).

:func:`write_waveforms` takes the record as an iterable of pieces (a
:meth:`pris_cosim.lab.timedomain.PrisRecord.chunks` generator, or one dict of
whole arrays) and keeps memory bounded by the piece size whatever the
record length: CSV text is formatted by array operations
(:func:`pris_cosim.floattext.csv_rows`) and streamed; for long ``.npz`` and
``.mat`` records each column is first spooled to a scratch file beside the
target and then copied into the archive. Writes are atomic: the target
appears complete or not at all (scratch files are removed on any error,
including an interrupt).
"""

from __future__ import annotations

import os
import secrets
import shutil
import stat
import zipfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

FORMATS = (".csv", ".npz", ".mat")
#: Records up to this size (bytes of float64 columns) are gathered in memory before .npz/.mat writing.
IN_MEMORY_BYTES = 96 * 2**20
#: Largest variable MATLAB v5 files can hold, bytes.
MAT5_LIMIT = 2**31 - 1
_COPY = 4 * 2**20


def waveform_format(path: str | os.PathLike) -> str:
    """The format named by the file's extension: ``"csv"``, ``"npz"`` or ``"mat"``.

    Raises
    ------
    ValueError
        Another extension.
    """
    ext = Path(path).suffix.lower()
    if ext not in FORMATS:
        raise ValueError(f"{os.fspath(path)!r}: unknown waveform format {ext or '(no extension)'!r}; "
                         f"use {', '.join(FORMATS)}")
    return ext[1:]


def bytes_per_sample(fmt: str, columns: int) -> float:
    """Typical file bytes per sample (row) of ``columns`` float columns in format ``fmt``."""
    return columns * (8.0 if fmt in ("npz", "mat") else 20.0)


def check_target(path: str | os.PathLike) -> Path:
    """Refuse a target that cannot be written, before any work: returns it as a Path.

    Raises
    ------
    ValueError
        Unknown extension, missing or read-only directory, or a directory at ``path``.
    """
    target = Path(path)
    waveform_format(target)
    directory = target.parent if str(target.parent) else Path(".")
    if target.is_dir():
        raise ValueError(f"{os.fspath(path)!r} is a directory")
    if not directory.is_dir():
        raise ValueError(f"{os.fspath(path)!r}: directory {os.fspath(directory)!r} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise ValueError(f"{os.fspath(path)!r}: directory {os.fspath(directory)!r} is not writable")
    return target


def write_waveforms(
    path: str | os.PathLike,
    columns: Sequence[str],
    pieces: Iterable[Mapping[str, np.ndarray]],
    samples: int,
    comments: Sequence[str] = (),
    progress: Callable[[int], None] | None = None,
) -> None:
    """Write a waveform record atomically in the format of the file's extension.

    Parameters
    ----------
    path : str or os.PathLike
        Target ``.csv``, ``.npz`` or ``.mat`` file.
    columns : sequence of str
        Column names, in order (``time_s``, ``v_bprbs``, ``v_in``, ``i_in`` [, ``v_out``]).
    pieces : iterable of mapping
        Consecutive pieces of the record: column name to 1-D arrays of equal length.
    samples : int
        Total length of the record (checked against the pieces).
    comments : sequence of str
        Free text (one line each) stored with the record.
    progress : callable, optional
        Called with the number of samples written so far after every piece.

    Raises
    ------
    ValueError
        Unknown extension, pieces that do not add up to ``samples`` or lack a
        column, or a ``.mat`` column over MATLAB v5's 2 GiB variable limit.
    """
    fmt = waveform_format(path)
    columns = list(columns)
    comments = [line for c in comments for line in str(c).replace("\r", "\n").split("\n")]
    if fmt == "mat" and samples * 8 > MAT5_LIMIT:
        raise ValueError(f"{os.fspath(path)!r}: {samples} samples exceed MATLAB v5's 2 GiB per variable; "
                         "use .npz or .csv")
    counted = _Counted(pieces, columns, samples, progress)
    if fmt == "csv":
        _atomic(path, lambda fh: _write_csv(fh, columns, counted, comments))
    elif samples * 8 * len(columns) <= IN_MEMORY_BYTES:
        arrays = counted.gather()
        _atomic(path, lambda fh: _write_archive(fh, fmt, columns, arrays, comments))
    else:
        with _Spool(path, columns) as spool:
            for piece in counted:
                spool.append(piece)
            spool.close_files()
            _atomic(path, lambda fh: _write_archive(fh, fmt, columns, spool, comments))


def read_waveforms(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of a waveform record written by :func:`write_waveforms` (any of the three formats).

    Returns
    -------
    dict
        Column name to 1-D float64 array (``comments`` excluded).
    """
    fmt = waveform_format(path)
    if fmt == "npz":
        with np.load(os.fspath(path), allow_pickle=False) as z:
            return {k: np.asarray(z[k], dtype=float).ravel() for k in z.files if k != "comments"}
    if fmt == "mat":
        import scipy.io

        raw = scipy.io.loadmat(os.fspath(path))
        return {k: np.asarray(v, dtype=float).ravel() for k, v in raw.items()
                if not k.startswith("__") and k != "comments"}
    from pris_cosim.measured.formats import read_waveform_csv

    w = read_waveform_csv(path)
    return {n: getattr(w, n) for n in w.names}


# ---------------------------------------------------------------------- pieces
class _Counted:
    """Pieces checked for their columns and length, with progress reports."""

    def __init__(self, pieces: Iterable[Mapping[str, np.ndarray]], columns: list[str], samples: int,
                 progress: Callable[[int], None] | None):
        self.pieces, self.columns, self.samples, self.progress = pieces, columns, int(samples), progress

    def __iter__(self):  # noqa: ANN204
        done = 0
        for piece in self.pieces:
            missing = [c for c in self.columns if c not in piece]
            if missing:
                raise ValueError(f"record piece lacks column {missing[0]!r}")
            n = {np.size(piece[c]) for c in self.columns}
            if len(n) != 1:
                raise ValueError("record piece has columns of different lengths")
            done += n.pop()
            if done > self.samples:
                raise ValueError(f"record is longer than the {self.samples} samples announced")
            yield piece
            if self.progress is not None:
                self.progress(done)
        if done != self.samples:
            raise ValueError(f"record has {done} samples, {self.samples} announced")

    def gather(self) -> dict[str, np.ndarray]:
        parts = list(self)
        if len(parts) == 1:
            return {c: np.ascontiguousarray(parts[0][c], dtype=float).ravel() for c in self.columns}
        return {c: np.concatenate([np.asarray(p[c], dtype=float).ravel() for p in parts]) for c in self.columns}


# ---------------------------------------------------------------------- formats
def _write_csv(fh: IO[bytes], columns: list[str], pieces: Iterable[Mapping[str, np.ndarray]],
               comments: list[str]) -> None:
    from pris_cosim.floattext import csv_rows

    head = "".join(f"# {c}\n" for c in comments) + ",".join(columns) + "\n"
    fh.write(head.encode("utf-8"))
    for piece in pieces:
        fh.write(csv_rows([piece[c] for c in columns]))


def _write_archive(fh: IO[bytes], fmt: str, columns: list[str], source: Any, comments: list[str]) -> None:
    """``.npz`` or ``.mat`` from whole arrays (a dict) or from a :class:`_Spool`."""
    if fmt == "npz":
        with zipfile.ZipFile(fh, mode="w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for c in columns:
                with zf.open(f"{c}.npy", mode="w", force_zip64=True) as entry:
                    if isinstance(source, dict):
                        np.lib.format.write_array(entry, source[c], allow_pickle=False)
                    else:
                        np.lib.format.write_array_header_1_0(
                            entry, {"descr": np.lib.format.dtype_to_descr(np.dtype("<f8")),
                                    "fortran_order": False, "shape": (source.samples,)})
                        source.copy_to(c, entry)
            with zf.open("comments.npy", mode="w") as entry:
                np.lib.format.write_array(entry, np.array(comments, dtype=str), allow_pickle=False)
        return
    import scipy.io

    for c in columns:  # one variable at a time: only one column is in memory
        col = source[c] if isinstance(source, dict) else source.load(c)
        scipy.io.savemat(fh, {c: col.reshape(-1, 1)}, format="5", do_compression=False)
        del col
    cell = np.empty((len(comments), 1), dtype=object)
    for i, line in enumerate(comments):
        cell[i, 0] = line
    scipy.io.savemat(fh, {"comments": cell}, format="5", do_compression=False)


class _Spool:
    """One scratch file per column beside the target, removed on exit."""

    def __init__(self, target: str | os.PathLike, columns: list[str]):
        t = Path(target)
        token = secrets.token_hex(6)
        self.paths = {c: t.parent / f".{t.name}.{token}.{c}.spool" for c in columns}
        self.files: dict[str, IO[bytes]] = {}
        self.samples = 0

    def __enter__(self) -> "_Spool":
        try:
            for c, p in self.paths.items():
                self.files[c] = open(p, "xb")
        except BaseException:
            self.__exit__()
            raise
        return self

    def append(self, piece: Mapping[str, np.ndarray]) -> None:
        for c, fh in self.files.items():
            np.ascontiguousarray(piece[c], dtype="<f8").ravel().tofile(fh)
        self.samples += int(np.size(piece[next(iter(self.files))]))

    def close_files(self) -> None:
        for fh in self.files.values():
            fh.close()

    def copy_to(self, column: str, out: IO[bytes]) -> None:
        with open(self.paths[column], "rb") as fh:
            shutil.copyfileobj(fh, out, _COPY)

    def load(self, column: str) -> np.ndarray:
        return np.fromfile(self.paths[column], dtype="<f8")

    def __exit__(self, *exc: object) -> None:
        for fh in self.files.values():
            fh.close()
        for p in self.paths.values():
            try:
                os.unlink(p)
            except OSError:
                pass


def _atomic(path: str | os.PathLike, write: Callable[[IO[bytes]], None]) -> None:
    """Fill a scratch file beside ``path`` with ``write``, sync it, then rename it over ``path``.

    On any error (or an interrupt) the scratch file is removed and ``path`` is untouched.
    An existing target keeps its permission bits.
    """
    target = Path(path)
    tmp = target.parent / f".{target.name}.{secrets.token_hex(8)}.tmp"
    try:
        with open(tmp, "xb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        try:
            os.chmod(tmp, stat.S_IMODE(os.stat(target).st_mode))
        except OSError:
            pass
        os.replace(tmp, target)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


__all__ = ["FORMATS", "bytes_per_sample", "check_target", "read_waveforms", "waveform_format", "write_waveforms"]
