"""Two-port SFRA sweeps: reading, admittance form, noise estimated from the data itself."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import median_filter

__all__ = ["Sweep", "load_sweep", "estimate_noise", "RESPONSES", "MODEL_FLOOR"]

#: The fitted responses, in column order.
RESPONSES = ("Y11", "Y21", "Y22")

#: Relative model-error floor added in quadrature to the measured noise (dimensionless, ~0.26 dB / 1.7 deg).
MODEL_FLOOR = 0.03

#: Window (points) of the running median that turns second differences into a local noise level.
NOISE_WINDOW = 31


def estimate_noise(y: np.ndarray, window: int = NOISE_WINDOW) -> np.ndarray:
    """Relative noise level of a complex response at each frequency, from the data alone.

    The second difference over neighbouring points of ``log y`` removes the
    smooth response (to second order in the log-frequency step); for white
    noise of standard deviation ``s`` in ``ln|y|`` and in ``arg y`` its real and
    imaginary parts have standard deviation ``sqrt(6) s``.  A running median
    of the complex magnitude ``|d2| / sqrt(6)`` over ``window`` points (times
    1.4826) gives a local level that ignores single sharp resonances.  Taking
    the complex magnitude makes it about 1.7 times ``s`` for pure white noise;
    it also takes in the unresolved ripple of the analyser's noise floor
    above 100 kHz, which a winding model cannot follow either, so those
    points weigh less (on the shared reference fit this weighting gave a
    clearly better model than the bare white-noise level).  Phase wraps
    (jumps of 2 pi) are single outliers the median ignores.

    Parameters
    ----------
    y : numpy.ndarray
        Complex response on a dense, smooth grid (as an SFRA sweep), shape ``(F,)``.
    window : int
        Running-median window in points.

    Returns
    -------
    numpy.ndarray
        Noise standard deviation of ``ln|y|`` (= of ``arg y`` in rad), shape ``(F,)``.
    """
    with np.errstate(all="ignore"):
        ly = np.log(np.asarray(y, dtype=complex))
    d2 = ly[:-2] - 2.0 * ly[1:-1] + ly[2:]
    a = np.abs(d2) / np.sqrt(6.0)
    a = np.concatenate([[a[0]], a, [a[-1]]])
    w = int(max(3, min(window, a.size)))
    s = 1.4826 * median_filter(a, size=w, mode="nearest")
    return np.maximum(s, 1e-6)


@dataclass
class Sweep:
    """One end-to-end two-port sweep in admittance form.

    Attributes
    ----------
    frequency_hz : numpy.ndarray
        Frequencies in Hz, shape ``(F,)``.
    y : numpy.ndarray
        ``Y11, Y21, Y22`` in S, shape ``(F, 3)``.
    noise : numpy.ndarray
        Estimated relative noise (std of ``ln|Y|`` and ``arg Y``), shape ``(F, 3)``.
    source : str
        File the sweep came from.
    digest : str
        SHA-256 of the file's bytes (empty for sweeps built in memory).
    forward : numpy.ndarray or None
        The voltage ratio ``V_resp / V_ref`` an FRA instrument records driving port 1 with port 2 on its
        50 Ohm input, ``-Y21 / (Y22 + 1/50 S)`` from the unsymmetrised ``Y21`` (= ``S21 / (1 + S11)`` of a
        50 Ohm file), shape ``(F,)``; ``None`` when built from the symmetrised ``(F, 3)`` form.
    """

    frequency_hz: np.ndarray
    y: np.ndarray
    noise: np.ndarray
    source: str = ""
    digest: str = ""
    forward: np.ndarray | None = None

    @property
    def voltage_ratio(self) -> np.ndarray:
        """``V_resp / V_ref`` (dimensionless, shape ``(F,)``): :attr:`forward`, else from the symmetrised ``Y``."""
        from estimation.diagnosis.sfra.dlt911 import voltage_ratio

        return self.forward if self.forward is not None else voltage_ratio(self.y[:, 1], self.y[:, 2])

    @property
    def z_end_to_end(self) -> np.ndarray:
        """End-to-end impedance ``-1 / Y21`` in Ohm."""
        return -1.0 / self.y[:, 1]

    @classmethod
    def from_y(cls, f: np.ndarray, y: np.ndarray, source: str = "", digest: str = "") -> "Sweep":
        """Build from a ``(F, 2, 2)`` or ``(F, 3)`` admittance array (noise estimated)."""
        from estimation.diagnosis.sfra.dlt911 import voltage_ratio

        y = np.asarray(y, dtype=complex)
        forward = None
        if y.ndim == 3:
            forward = voltage_ratio(y[:, 1, 0], y[:, 1, 1])  # the forward direction, as measured
            y = np.stack([y[:, 0, 0], 0.5 * (y[:, 1, 0] + y[:, 0, 1]), y[:, 1, 1]], axis=1)
        noise = np.stack([estimate_noise(y[:, i]) for i in range(3)], axis=1)
        return cls(np.asarray(f, dtype=float), y, noise, source, digest, forward)


def load_sweep(path: str | os.PathLike) -> Sweep:
    """Read a two-port Touchstone sweep (through scikit-rf) as admittances.

    Raises
    ------
    MeasuredDataError
        One line naming the file (and line) for a bad or non-two-port file.
    """
    from pris_cosim.measured.formats import MeasuredDataError
    from pris_cosim.measured.touchstone import read_touchstone

    ts = read_touchstone(path, nports=2)
    with np.errstate(all="ignore"):
        try:
            y = ts.y()
        except np.linalg.LinAlgError:
            raise MeasuredDataError(path, "the parameter matrix is singular; no Y-parameters") from None
    if not np.all(np.isfinite(y)) or np.any(np.abs(y[:, 1, 0]) == 0):
        raise MeasuredDataError(path, "Y-parameters are not finite (or Y21 is zero) at some frequency")
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return Sweep.from_y(ts.frequency_hz, y, source=os.fspath(path), digest=digest)
