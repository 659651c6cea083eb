"""Vectorised text of float64 arrays that reads back as exactly the same numbers.

:func:`csv_rows` turns columns of floats into CSV lines with numpy array
operations only (no Python formatting per value or per row), which is what
makes writing millions of waveform samples as text cheap.

Every finite value is written in scientific notation with the fewest of 15,
16 or 17 significant digits that reads back as the same double (17 always
do), trailing zeros dropped: ``1e-07``, ``-1e+02``, ``4.0949e-02``,
``8.369831735335166e-02``. Zero is ``0.0``. Values outside 1e-280..1e280
and non-finite values are written by Python's ``repr`` (rare; one call each).

Method: with ``e = floor(log10 |x|)`` and ``k = d - 1 - e``, the scaled value
``|x| 10^k`` is formed as a double-double (``10^k`` tabulated as a sum of
two doubles, the product split exactly by Dekker's algorithm), rounded to
the integer mantissa ``m``; the residual decides whether ``m 10^-k`` is
within half a unit in the last place of ``x`` (then it reads back exactly).
Digits come from integer division.
"""

from __future__ import annotations

from collections.abc import Sequence
from fractions import Fraction
from functools import lru_cache

import numpy as np

_EXP_LIMIT = 280  # decimal exponents handled by the array path
_SPLIT = 134217729.0  # 2**27 + 1, Dekker's splitter
_FIELD = 24  # sign, digit, '.', 16 digits, 'e', sign, 3 exponent digits
_ZERO = np.frombuffer(b"0.0", np.uint8)
_ROWS = 16384  # rows per block (larger blocks amortise the per-operation overhead)


@lru_cache(maxsize=1)
def _powers_of_ten() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """``10^k`` as hi + lo doubles and the Dekker halves of hi, for k in -300..300 (offset returned)."""
    lo_k, hi_k = -300, 300
    ks = range(lo_k, hi_k + 1)
    hi = np.array([float(Fraction(10) ** k) for k in ks])
    lo = np.array([float(Fraction(10) ** k - Fraction(h)) for k, h in zip(ks, hi)])
    with np.errstate(over="ignore", invalid="ignore"):
        c = _SPLIT * hi
        h1 = c - (c - hi)
    h1 = np.where(np.isfinite(h1), h1, hi)
    return hi, lo, h1, hi - h1, -lo_k


def _scaled(a: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a 10^k`` as an unevaluated sum ``hi + lo`` accurate to about 1e-30 relative."""
    P, Plo, Ph, Pl, off = _powers_of_ten()
    ph, pl, p_hi, p_lo = Ph[k + off], Pl[k + off], P[k + off], Plo[k + off]
    c = _SPLIT * a
    ah = c - (c - a)
    al = a - ah
    hi = a * p_hi
    err = ((ah * ph - hi) + ah * pl + al * ph) + al * pl
    return hi, err + a * p_lo


def _mantissa(a: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest integer ``m`` to ``a 10^k`` (int64) and the residual ``a 10^k - m``."""
    hi, lo = _scaled(a, k)
    r = np.rint(hi)
    frac = hi - r
    frac += lo
    adj = np.rint(frac)
    frac -= adj
    m = r.astype(np.int64)
    m += adj.astype(np.int64)
    return m, frac


def _fields(x: np.ndarray, out: np.ndarray) -> None:
    """Text of every value of ``x`` into ``out``, a (N, 24) uint8 array of zeros (NUL = no character)."""
    x = np.asarray(x, dtype=np.float64)
    a = np.abs(x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        e = np.floor(np.log10(a))
    fast = (e >= -_EXP_LIMIT) & (e <= _EXP_LIMIT)  # excludes zero, nan, inf
    if fast.all():
        _fill_fast(out, x, a, e.astype(np.int64))
    elif fast.any():
        idx = np.flatnonzero(fast)
        f = np.zeros((idx.size, _FIELD), np.uint8)
        _fill_fast(f, x[idx], a[idx], e[idx].astype(np.int64))
        out[idx] = f
    zero = np.flatnonzero(a == 0)
    if zero.size:
        out[zero, 1:4] = _ZERO
        out[zero[np.signbit(x[zero])], 0] = ord("-")
    for i in np.flatnonzero(~fast & (a != 0)):  # huge, tiny or non-finite: rare
        text = np.frombuffer(repr(float(x[i])).encode(), np.uint8)[:_FIELD]
        out[i, : text.size] = text


def _fill_fast(f: np.ndarray, x: np.ndarray, a: np.ndarray, e: np.ndarray) -> None:
    # 17 significant digits: 10^16 <= a 10^(16 - e) < 10^17 after correcting e
    m, r = _mantissa(a, 16 - e)
    off_decade = (m < 10**16) | (m >= 10**17)
    if off_decade.any():
        e = e - (m < 10**16) + (m >= 10**17)
        m, r = _mantissa(a, 16 - e)
    carry = m >= 10**17  # rounded up into the next decade
    if carry.any():
        m = np.where(carry, 10**16, m)
        e = e + carry
    # 16 or 15 digits when they read back exactly: |residual| below half the spacing of x
    P, _, _, _, off = _powers_of_ten()
    half_ulp = np.minimum(np.spacing(a), a - np.nextafter(a, 0.0))
    half_ulp *= (0.5 - 1e-12) * P[16 - e + off]  # in units of the 17th digit (margin for rounding)
    for step in (10, 100):
        q, rem = np.divmod(m, step)
        t = rem + r  # position between q and q + 1, in 17th-digit units
        up = t >= step / 2
        t -= up * step
        ok = np.abs(t) < half_ulp
        if ok.any():
            m = np.where(ok, (q + up) * step, m)
            r = np.where(ok, t, r)
    carry = m >= 10**17  # rounded up into the next decade
    if carry.any():
        m = np.where(carry, 10**16, m)
        e = e + carry
    # digits, least significant first, from uint32 halves of 8 and 9 digits
    rev = np.empty((a.size, 17), np.uint8)
    hi, lo = np.divmod(m, 10**8)
    for part, cols in ((lo.astype(np.uint32), range(0, 8)), (hi.astype(np.uint32), range(8, 17))):
        for j in cols:
            part, dj = np.divmod(part, np.uint32(10))
            rev[:, j] = dj
    keep = np.logical_or.accumulate(rev[:, :16] != 0, axis=1)  # not a trailing zero
    rev += ord("0")
    f[:, 0] = np.signbit(x) * np.uint8(ord("-"))
    f[:, 1] = rev[:, 16]
    f[:, 2] = keep[:, 15] * np.uint8(ord("."))
    f[:, 3:19] = (rev[:, 15::-1] * keep[:, ::-1]).astype(np.uint8)
    f[:, 19] = ord("e")
    f[:, 20] = np.where(e < 0, ord("-"), ord("+"))
    ae = np.abs(e)
    f[:, 21] = np.where(ae >= 100, ae // 100 + ord("0"), 0)
    f[:, 22] = (ae // 10) % 10 + ord("0")
    f[:, 23] = ae % 10 + ord("0")


def csv_rows(columns: Sequence[np.ndarray], delimiter: str = ",") -> bytes:
    """CSV lines of equal-length float columns, one line per index, ``\\n``-terminated.

    Parameters
    ----------
    columns : sequence of numpy.ndarray
        1-D arrays of the same length (any float or integer dtype).
    delimiter : str
        One ASCII character between fields.

    Returns
    -------
    bytes
        ASCII text; every value reads back (``float``) as the same double.
    """
    cols = [np.asarray(c, dtype=np.float64).ravel() for c in columns]
    if not cols:
        return b""
    N = cols[0].size
    if any(c.size != N for c in cols):
        raise ValueError("columns must have the same length")
    width = _FIELD + 1
    parts = []
    buf = np.empty((min(N, _ROWS), len(cols) * width), np.uint8)
    for r0 in range(0, N, _ROWS):  # blocks small enough for the temporaries to stay in cache
        r1 = min(r0 + _ROWS, N)
        b = buf[: r1 - r0]
        b.fill(0)
        for j, c in enumerate(cols):
            _fields(c[r0:r1], b[:, j * width : j * width + _FIELD])
            b[:, j * width + _FIELD] = ord(delimiter) if j < len(cols) - 1 else ord("\n")
        flat = b.reshape(-1)
        parts.append(flat[flat != 0].tobytes())
    return b"".join(parts)


__all__ = ["csv_rows"]
